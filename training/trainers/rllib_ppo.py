"""RLlib's PPO (new API stack) trains one shared, action-masked policy at control level ``move``.

Every module is an agent of one RLlib multi-agent episode and maps to the single policy
``"shared"``. At ``control="move"`` an agent chooses only its move (``Discrete(13)``); the
task's hand-coded rules fill in the other fields. Each agent's observation is given to RLlib as

==================== ============================ =========================================
key                  space                        content
==================== ============================ =========================================
``observations``     ``Box(-1, 1, (D,), float32)`` the project's encoding of the observation
                                                  (:class:`~proteo_env.adapters.flatten.ObservationEncoder`, ``D = encoder.size``)
``action_mask``      ``Box(0, 1, (13,), float32)`` 1 for each move that is legal now
==================== ============================ =========================================

:class:`MaskedPPOModule` (a torch RLModule) computes logits ``(B, 13)`` with an MLP on
``observations`` and sets illegal moves to the smallest float, so that they are never sampled
and take no part in the loss; a second MLP gives the value ``(B,)``. Env runners sample in
parallel (``--env-runners``, each a Ray actor with one CPU), the learner updates in the driver.

Checkpoints: every ``checkpoint_every`` iterations and at the end, ``checkpoints/step_<N>/`` and
``final/`` hold ``proteo.json`` (algorithm ``rllib-ppo``, control ``move``) and ``policy.pt``
(the policy MLP's ``state_dict``, the layout of :func:`~training.machinery.policies.torch_mlp`), which
``proteo eval`` loads like every other checkpoint; ``final/rllib/`` is RLlib's own checkpoint
of the algorithm (``Algorithm.from_checkpoint``).

    python -m training.trainers.rllib_ppo --config configs/train/rllib_ppo_chain_move.yaml
    python -m training.trainers.rllib_ppo --iterations 2 --env-runners 2 --address 10.0.0.5:6379
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import proteo_env
from proteo_env.adapters.flatten import ObservationEncoder
from proteo_env.config import ConfigError
from proteo_env.registry import task_name
from proteo_env.spaces import N_MOVES
from training.machinery.checkpoints import mlp_meta, write_checkpoint_meta
from training.machinery.distributed import connect
from training.machinery.policies import torch_mlp
from training.machinery.runs import (
    ProgressLog,
    RunArgs,
    checkpoint_folder,
    make_run_dir,
    parse_args,
    save_args,
    seed_everything,
)

SHARED = "shared"
"""The one policy (RLModule id) every module maps to."""


@dataclass(frozen=True)
class Args(RunArgs):
    """RLlib PPO with one shared action-masked policy at control level move (training/trainers/rllib_ppo.py)."""

    task: str = "chain-v1"
    """The task: a registered id such as chain-v1 (a bare name such as chain: its newest version)."""
    env: dict = field(default_factory=lambda: {"n_modules": 12, "max_cycles": 300, "motion_model": "sphere"})
    """Overrides passed to ``proteo_env.make`` (``control`` is always ``move``)."""
    control: str = "move"
    """The control level the policy acts at (only ``move``: one Discrete(13) action per module)."""
    iterations: int = 50
    """PPO iterations (each samples ``train_batch_size`` cycles, then updates)."""
    env_runners: int = 2
    """Ray actors sampling episodes in parallel (one CPU each)."""
    train_batch_size: int = 1000
    """Cycles (env steps) sampled per iteration; each gives one agent-step per module."""
    minibatch_size: int = 500
    """Agent-steps per minibatch of the update (RLlib's ``minibatch_size``)."""
    n_epochs: int = 4
    """Passes over each iteration's train batch (RLlib's ``num_epochs``)."""
    learning_rate: float = 3e-4
    """Adam's learning rate (constant)."""
    gamma: float = 0.99
    """Discount factor per cycle."""
    hidden: tuple[int, ...] = (64, 64)
    """Widths of the tanh hidden layers of the policy MLP and of the separate value MLP."""
    checkpoint_every: int = 10
    """PPO iterations between checkpoints (checkpoints/step_<N>/ in the run folder)."""
    address: str | None = None
    """A running Ray cluster (``HOST:PORT`` or ``auto``); default: a local Ray instance."""


def _rllib_env_class():
    """:class:`ProteoMultiAgentEnv`, defined when RLlib is imported (it subclasses RLlib's MultiAgentEnv)."""
    from ray.rllib.env.multi_agent_env import MultiAgentEnv

    class ProteoMultiAgentEnv(MultiAgentEnv):
        """One proteo episode at control level ``move`` as an RLlib multi-agent env.

        ``config``: ``{"task": id, "env": overrides}``. Observations per agent as in the module
        docstring; rewards are the team reward each module receives; an episode ends for all
        agents at once (success: ``terminated``, cycle limit: ``truncated``).
        """

        def __init__(self, config=None):
            super().__init__()
            config = dict(config or {})
            self.env = proteo_env.make(config["task"], **{**config.get("env", {}), "control": "move"})
            self.encoder = ObservationEncoder.for_env(self.env)
            self.possible_agents = list(self.env.possible_agents)
            self.agents = list(self.possible_agents)
            space = gym.spaces.Dict(
                {
                    "observations": gym.spaces.Box(-1.0, 1.0, (self.encoder.size,), np.float32),
                    "action_mask": gym.spaces.Box(0.0, 1.0, (N_MOVES,), np.float32),
                }
            )
            self.observation_spaces = {a: space for a in self.possible_agents}
            self.action_spaces = {a: gym.spaces.Discrete(N_MOVES) for a in self.possible_agents}

        def _encode(self, observations: dict) -> dict:
            if not observations:
                return {}
            features = self.encoder.encode_observations(observations)
            return {
                a: {"observations": features[i], "action_mask": np.asarray(o["action_mask"], dtype=np.float32)}
                for i, (a, o) in enumerate(observations.items())
            }

        def reset(self, *, seed=None, options=None):
            observations, infos = self.env.reset(seed=seed, options=options)
            self.agents = list(self.env.agents)
            return self._encode(observations), {a: {} for a in observations}

        def step(self, action_dict):
            observations, rewards, terminated, truncated, _ = self.env.step({a: int(m) for a, m in action_dict.items()})
            done = not self.env.agents
            self.agents = list(self.env.agents)
            terminated = {**{a: bool(v) for a, v in terminated.items()}, "__all__": done and any(terminated.values())}
            truncated = {**{a: bool(v) for a, v in truncated.items()}, "__all__": done and not terminated["__all__"]}
            return (
                self._encode(observations),
                {a: float(r) for a, r in rewards.items()},
                terminated,
                truncated,
                {a: {} for a in observations},
            )

    return ProteoMultiAgentEnv


def _masked_module_class():
    """:class:`MaskedPPOModule`, defined when RLlib is imported (it subclasses RLlib's TorchRLModule)."""
    import torch
    from ray.rllib.core.columns import Columns
    from ray.rllib.core.rl_module.apis.value_function_api import ValueFunctionAPI
    from ray.rllib.core.rl_module.torch.torch_rl_module import TorchRLModule

    class MaskedPPOModule(TorchRLModule, ValueFunctionAPI):
        """Policy MLP ``(B, D) -> (B, 13)`` logits, illegal moves masked; value MLP ``(B, D) -> (B,)``.

        ``model_config``: ``{"hidden": [64, 64]}``.
        """

        def setup(self):
            size = self.observation_space["observations"].shape[0]
            hidden = tuple(self.model_config.get("hidden", (64, 64)))
            self.pi = torch_mlp(size, self.action_space.n, hidden)
            self.vf = torch_mlp(size, 1, hidden, out_gain=1.0)

        def _forward(self, batch, **kwargs):
            obs = batch[Columns.OBS]
            logits = self.pi(obs["observations"])
            masked = torch.where(obs["action_mask"] > 0.5, logits, torch.finfo(logits.dtype).min)
            return {Columns.ACTION_DIST_INPUTS: masked}

        def compute_values(self, batch, embeddings=None):
            return self.vf(batch[Columns.OBS]["observations"]).squeeze(-1)

    return MaskedPPOModule


def build_config(args: Args):
    """The RLlib ``PPOConfig``: our env, one shared masked module, ``args.env_runners`` env runners."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    return (
        PPOConfig()
        .environment(_rllib_env_class(), env_config={"task": args.task, "env": dict(args.env)})
        .env_runners(num_env_runners=args.env_runners, num_envs_per_env_runner=1, num_cpus_per_env_runner=1)
        .multi_agent(policies={SHARED}, policy_mapping_fn=lambda agent_id, *a, **k: SHARED)
        .rl_module(
            rl_module_spec=MultiRLModuleSpec(
                rl_module_specs={
                    SHARED: RLModuleSpec(
                        module_class=_masked_module_class(), model_config={"hidden": list(args.hidden)}
                    )
                }
            )
        )
        .training(
            train_batch_size_per_learner=args.train_batch_size,
            minibatch_size=args.minibatch_size,
            num_epochs=args.n_epochs,
            lr=args.learning_rate,
            gamma=args.gamma,
        )
        .debugging(seed=args.seed)
    )


def save_checkpoint(
    algo, args: Args, folder: Path, *, run_dir: Path, agent_steps: int, iteration: int, rllib: bool = False
) -> Path:
    """Write the proteo checkpoint (``proteo.json``, ``policy.pt``) into ``folder``; with ``rllib``
    also RLlib's own checkpoint into ``folder/rllib``."""
    import torch

    env = proteo_env.make(args.task, **{**args.env, "control": "move"})
    module = algo.get_module(SHARED)
    folder.mkdir(parents=True, exist_ok=True)
    torch.save({k: v.detach().cpu() for k, v in module.pi.state_dict().items()}, folder / "policy.pt")
    write_checkpoint_meta(
        folder,
        algorithm="rllib-ppo",
        task=env.task.task_id(),
        env_overrides=dict(args.env),
        encoder_spec=ObservationEncoder.for_env(env).spec(),
        nvec=env.control_nvec,
        agent_steps=agent_steps,
        seed=args.seed,
        extra={
            "label": "rllib-ppo",
            **mlp_meta("move", args.hidden),
            "run_dir": str(run_dir),
            "iteration": iteration,
            "args": asdict(args),
        },
    )
    env.close()
    if rllib:
        algo.save_to_path(str((folder / "rllib").resolve()))
    return folder


def main(argv=None) -> Path:
    args = parse_args(Args, argv)

    if args.control != "move":
        raise ConfigError(f"control={args.control!r} is not allowed; allowed: move")
    if args.env_runners < 0 or args.iterations < 1:
        raise ConfigError(
            f"env_runners={args.env_runners!r}, iterations={args.iterations!r} are not allowed; "
            "allowed: env_runners >= 0, iterations >= 1"
        )
    seed_everything(args.seed, threads=args.threads)
    run_dir = make_run_dir(args.run_dir, f"rllib_ppo_{task_name(args.task)}_s{args.seed}", resume=False)
    save_args(args, run_dir)
    import ray

    started_ray = not ray.is_initialized()
    connect(address=args.address, workers=None if args.address else max(1, args.env_runners) + 1)

    algo = build_config(args).build_algo()
    n_agents = len(_rllib_env_class()({"task": args.task, "env": dict(args.env)}).possible_agents)
    log = ProgressLog(run_dir, tensorboard=args.tensorboard)
    agent_steps, iteration = 0, 0
    bar = tqdm(total=args.iterations, unit="iteration", desc="rllib-ppo", disable=not args.progress_bar)
    try:
        while iteration < args.iterations:
            result = algo.train()
            iteration += 1
            bar.update(1)
            runners = result.get("env_runners", {})
            agent_steps = int(sum(runners.get("num_agent_steps_sampled_lifetime", {}).values()))
            learner = result.get("learners", {}).get(SHARED, {})
            log.log(
                agent_steps,
                {  # RLlib's episode return sums every agent's; each module gets the team reward
                    "episode/return": _finite(runners.get("episode_return_mean", np.nan) / n_agents),
                    "episode/cycles": _finite(runners.get("episode_len_mean")),
                    "loss/policy": _finite(learner.get("policy_loss")),
                    "loss/value": _finite(learner.get("vf_loss")),
                    "loss/entropy": _finite(learner.get("entropy")),
                    "rllib/iteration": float(iteration),
                },
            )
            if iteration % args.checkpoint_every == 0:
                save_checkpoint(
                    algo,
                    args,
                    checkpoint_folder(run_dir, agent_steps),
                    run_dir=run_dir,
                    agent_steps=agent_steps,
                    iteration=iteration,
                )
            if args.time_limit_minutes and log.seconds > 60 * args.time_limit_minutes:
                break
        final = save_checkpoint(
            algo, args, run_dir / "final", run_dir=run_dir, agent_steps=agent_steps, iteration=iteration, rllib=True
        )
    finally:
        bar.close()
        algo.stop()
        log.close()
        if started_ray:
            ray.shutdown()
    print(f"final checkpoint: {final}  ({iteration} iterations, {agent_steps} agent-steps, {log.seconds:.0f} s)")
    return final


def _finite(value) -> float | None:
    """A float for the log, ``None`` for a missing or non-finite value (no episode finished yet)."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return value if np.isfinite(value) else None


if __name__ == "__main__":
    from training.machinery.runs import run_script

    raise SystemExit(run_script(main))

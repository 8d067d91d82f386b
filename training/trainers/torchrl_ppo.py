"""IPPO or MAPPO with TorchRL: one actor shared by every module, masked actions at any control level.

The environment is :class:`~proteo_env.adapters.torchrl.ProteoTorchRLEnv`, a native TorchRL
``EnvBase`` over the array API (``n_envs`` worlds batched, the modules of a world form the
group ``"agents"``). The actor maps one module's flattened observation to logits of every
action field of the control level (``control``): at ``move`` TorchRL's ``MaskedCategorical`` over
the 13 moves, otherwise :class:`MaskedMultiCategorical`; both mask illegal moves. The critic is TorchRL's
``MultiAgentMLP``: per module (``variant: ippo``) or over all modules' observations
(``variant: mappo``, centralised). Losses: TorchRL's ``ClipPPOLoss`` with GAE.
``total_steps`` counts agent-steps (module-cycles).

    python -m training.trainers.torchrl_ppo --config configs/train/torchrl_ippo_chain.yaml
    python -m training.trainers.torchrl_ppo --config configs/train/torchrl_ippo_chain.yaml --variant mappo --run-dir runs/mappo
    python -m training.trainers.torchrl_ppo --resume runs/mappo/checkpoints/step_0000049152 --total-steps 100000

Writes ``runs/<name>/`` (see :mod:`training.machinery.runs`); ``proteo eval --checkpoint runs/<name>``
evaluates the result.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from proteo_env.config import ConfigError
from proteo_env.control import check_level
from proteo_env.registry import task_name
from training.machinery.checkpoints import mlp_meta, read_meta, write_checkpoint_meta
from training.machinery.policies import torch_mlp
from training.machinery.runs import (
    PPOArgs,
    ProgressLog,
    checkpoint_folder,
    episode_stats,
    finish_run,
    make_run_dir,
    parse_args,
    save_args,
    seed_everything,
)

ALGORITHM = "torchrl-ppo"


@dataclass(frozen=True)
class Args(PPOArgs):
    """IPPO/MAPPO with TorchRL (arguments of training/trainers/torchrl_ppo.py)."""

    control: str = "full"
    """Control level (``move``, ``move+mode``, ``full``): at ``move`` the actor picks one masked
    move per module (TorchRL's ``MaskedCategorical``) and the rules' autopilot does the rest."""
    variant: str = "ippo"
    """``ippo`` (critic sees one module) or ``mappo`` (critic sees all modules of the world)."""
    max_grad_norm: float = 0.5
    """Gradient norm limit of the actor's and the critic's parameters together (one optimiser for both)."""
    hidden: tuple[int, ...] = (64, 64)
    """Widths of the actor's tanh hidden layers; the critic has as many, each ``hidden[0]`` wide (MultiAgentMLP)."""


def make_distribution_class(nvec):
    """A torch ``Distribution`` over MultiDiscrete actions with a move mask (built lazily: torch import)."""
    import torch
    from torch.distributions import Categorical, Distribution

    sizes = [int(n) for n in nvec]

    class MaskedMultiCategorical(Distribution):
        """Independent categoricals, one per action field; moves masked by ``mask[..., :13]``."""

        arg_constraints = {}

        def __init__(self, logits, mask):
            logits = logits.masked_fill(~mask.bool(), -1e9)
            self.heads = [Categorical(logits=part) for part in torch.split(logits, sizes, dim=-1)]
            super().__init__(batch_shape=logits.shape[:-1], validate_args=False)

        def sample(self, sample_shape=()):
            return torch.stack([h.sample(sample_shape) for h in self.heads], dim=-1)

        def log_prob(self, value):
            return sum(h.log_prob(value[..., k]) for k, h in enumerate(self.heads))

        def entropy(self):
            return sum(h.entropy() for h in self.heads)

        @property
        def deterministic_sample(self):
            return torch.stack([h.probs.argmax(-1) for h in self.heads], dim=-1)

        @property
        def mode(self):
            return self.deterministic_sample

    return MaskedMultiCategorical


def actor_critic(env, args: Args):
    """``(actor_net, actor, critic_net, loss)``: the shared policy MLP from the flat observation
    to every field's logits and its masked sampling actor, the critic (per module; ``mappo``: over
    every module's observation), and TorchRL's clipped PPO loss over both with GAE."""
    import torch
    from tensordict.nn import TensorDictModule
    from torchrl.modules import MaskedCategorical, MultiAgentMLP, ProbabilisticActor
    from torchrl.objectives import ClipPPOLoss, ValueEstimators

    n_agents, obs_size, nvec = env.n_agents, env.encoder.size, env.nvec
    actor_net = torch_mlp(obs_size, int(nvec.sum()), args.hidden)
    actor = ProbabilisticActor(
        TensorDictModule(actor_net, in_keys=[("agents", "observation")], out_keys=[("agents", "logits")]),
        in_keys={"logits": ("agents", "logits"), "mask": ("agents", "action_mask")},
        out_keys=[("agents", "action")],
        distribution_class=MaskedCategorical if env.single else make_distribution_class(nvec),
        return_log_prob=True,
        log_prob_key=("agents", "sample_log_prob"),
    )
    critic_net = MultiAgentMLP(
        n_agent_inputs=obs_size,
        n_agent_outputs=1,
        n_agents=n_agents,
        centralised=args.variant == "mappo",
        share_params=True,
        depth=len(args.hidden),
        num_cells=args.hidden[0],
        activation_class=torch.nn.Tanh,
    )
    critic = TensorDictModule(critic_net, in_keys=[("agents", "observation")], out_keys=[("agents", "state_value")])
    loss = ClipPPOLoss(
        actor_network=actor,
        critic_network=critic,
        clip_epsilon=args.clip_range,
        entropy_coeff=args.ent_coef,
        normalize_advantage=True,
    )
    loss.set_keys(
        reward=("agents", "reward"),
        action=("agents", "action"),
        value=("agents", "state_value"),
        sample_log_prob=("agents", "sample_log_prob"),
        done=("agents", "done"),
        terminated=("agents", "terminated"),
    )
    loss.make_value_estimator(ValueEstimators.GAE, gamma=args.gamma, lmbda=args.gae_lambda)
    return actor_net, actor, critic_net, loss


def finished_episodes(data, running_return: np.ndarray, running_cycles: np.ndarray) -> list[dict]:
    """The episodes that ended in a collected batch (``data`` is [world, time]), each ``{"r", "l",
    "success"}``; ``running_return`` and ``running_cycles`` (worlds,) carry unfinished ones over."""
    rewards = data.get(("next", "agents", "reward"))[..., 0, 0].numpy()
    done = data.get(("next", "done"))[..., 0].numpy()
    terminated = data.get(("next", "terminated"))[..., 0].numpy()
    episodes = []
    for c in range(rewards.shape[0]):
        for t in range(rewards.shape[1]):
            running_return[c] += rewards[c, t]
            running_cycles[c] += 1
            if done[c, t]:
                episodes.append({"r": running_return[c], "l": running_cycles[c], "success": terminated[c, t]})
                running_return[c], running_cycles[c] = 0.0, 0
    return episodes


def ppo_update(loss, optimizer, buffer, data, args: Args) -> dict:
    """One PPO update on a collected batch: advantages by the loss's estimator, then ``n_epochs``
    passes over minibatches of the batch; returns the last minibatch's loss terms."""
    import torch

    with torch.no_grad():
        loss.value_estimator(data, params=loss.critic_network_params, target_params=loss.target_critic_network_params)
    buffer.extend(data.reshape(-1))
    for _ in range(args.n_epochs):
        for _ in range(max(1, len(buffer) // buffer._batch_size)):
            parts = loss(buffer.sample())
            total = parts["loss_objective"] + parts["loss_critic"] + parts["loss_entropy"]
            optimizer.zero_grad()
            total.backward()
            torch.nn.utils.clip_grad_norm_(loss.parameters(), args.max_grad_norm)
            optimizer.step()
    return parts


def main(argv=None) -> Path:
    args = parse_args(Args, argv)
    if args.variant not in ("ippo", "mappo"):
        raise ConfigError(f"variant={args.variant!r} is not allowed; allowed: ippo, mappo")
    check_level(args.control)
    seed_everything(args.seed, threads=args.threads)

    import torch
    from torchrl.collectors import Collector
    from torchrl.data import LazyTensorStorage, ReplayBuffer
    from torchrl.data.replay_buffers.samplers import SamplerWithoutReplacement

    from proteo_env.adapters.torchrl import ProteoTorchRLEnv

    # ------------------------------------------------------------------ environment
    resume_meta = read_meta(args.resume) if args.resume else None
    run_dir = make_run_dir(
        args.run_dir or (resume_meta or {}).get("run_dir"),
        f"torchrl_{args.variant}_{task_name(args.task)}_s{args.seed}",
        resume=resume_meta is not None,
    )
    save_args(args, run_dir)
    env = ProteoTorchRLEnv(args.task, n_copies=args.n_envs, seed=args.seed, control=args.control, **args.env)
    n_agents, nvec = env.n_agents, env.nvec

    actor_net, actor, critic_net, loss = actor_critic(env, args)
    optimizer = torch.optim.Adam(loss.parameters(), lr=args.learning_rate)
    agent_steps = 0
    if resume_meta is not None:
        state = torch.load(Path(resume_meta["dir"]) / "trainer.pt", map_location="cpu", weights_only=True)
        actor_net.load_state_dict(state["actor"])
        critic_net.load_state_dict(state["critic"])
        optimizer.load_state_dict(state["optimizer"])
        agent_steps = int(state["agent_steps"])

    def save(folder: Path) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        torch.save(actor_net.state_dict(), folder / "policy.pt")
        torch.save(
            {
                "actor": actor_net.state_dict(),
                "critic": critic_net.state_dict(),
                "optimizer": optimizer.state_dict(),
                "agent_steps": agent_steps,
            },
            folder / "trainer.pt",
        )
        write_checkpoint_meta(
            folder,
            algorithm=ALGORITHM,
            task=env.task_id,
            env_overrides=dict(args.env),
            encoder_spec=env.encoder.spec(),
            nvec=nvec,
            agent_steps=agent_steps,
            seed=args.seed,
            extra={
                **mlp_meta(args.control, args.hidden),
                "label": f"torchrl-{args.variant}",
                "run_dir": str(run_dir),
                "args": asdict(args),
            },
        )

    # ------------------------------------------------------------------ data
    steps_per_batch = args.n_steps * args.n_envs * n_agents
    collector = Collector(
        env,
        actor,
        frames_per_batch=args.n_steps * args.n_envs,
        total_frames=-1,
        device="cpu",
        auto_register_policy_transforms=False,
    )
    buffer = ReplayBuffer(
        storage=LazyTensorStorage(args.n_steps * args.n_envs),
        sampler=SamplerWithoutReplacement(),
        batch_size=max(1, args.minibatch_size // n_agents),
    )
    log = ProgressLog(
        run_dir, tensorboard=args.tensorboard, resumed_at=agent_steps if resume_meta is not None else None
    )
    running_return = np.zeros(args.n_envs)
    running_cycles = np.zeros(args.n_envs, dtype=np.int64)
    bar = tqdm(
        total=args.total_steps,
        initial=agent_steps,
        unit="agent-step",
        desc=f"torchrl-{args.variant}",
        disable=not args.progress_bar,
    )
    next_checkpoint = (agent_steps // args.checkpoint_every + 1) * args.checkpoint_every
    collect_started = time.perf_counter()
    env_seconds = env.step_seconds
    for data in collector:
        collect_s = time.perf_counter() - collect_started
        env_s = env.step_seconds - env_seconds
        update_started = time.perf_counter()
        # shared done flags, expanded to every module as the value estimator needs them
        reward_shape = data.get(("next", "agents", "reward")).shape
        for key in ("done", "terminated"):
            data.set(("next", "agents", key), data.get(("next", key)).unsqueeze(-1).expand(reward_shape))

        episodes = finished_episodes(data, running_return, running_cycles)

        parts = ppo_update(loss, optimizer, buffer, data, args)
        collector.update_policy_weights_()
        update_s = time.perf_counter() - update_started

        agent_steps += steps_per_batch
        bar.update(steps_per_batch)
        log.log(
            agent_steps,
            {
                **episode_stats(episodes),
                "loss/objective": parts["loss_objective"].item(),
                "loss/critic": parts["loss_critic"].item(),
                "loss/entropy": parts["loss_entropy"].item(),
                "time/env_seconds": env_s,
                "time/policy_seconds": collect_s - env_s,
                "time/update_seconds": update_s,
                "throughput/collect_agent_steps_per_s": steps_per_batch / collect_s,
                "throughput/env_agent_steps_per_s": steps_per_batch / env_s if env_s else None,
            },
        )
        if agent_steps >= next_checkpoint:
            save(checkpoint_folder(run_dir, agent_steps))
            next_checkpoint += args.checkpoint_every
        if agent_steps >= args.total_steps or (args.time_limit_minutes and log.seconds > 60 * args.time_limit_minutes):
            break
        collect_started = time.perf_counter()
        env_seconds = env.step_seconds
    bar.close()
    collector.shutdown()
    return finish_run(run_dir, save, log, agent_steps)


if __name__ == "__main__":
    from training.machinery.runs import run_script

    raise SystemExit(run_script(main))

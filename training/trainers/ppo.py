"""PPO with one policy shared by every module, over the batched array API (no per-agent dicts).

Every module of ``n_envs`` worlds is one sample: the worlds run as one batch
(:class:`~training.trainers.worlds.TrainingEnvs`), one forward pass of the
:class:`~training.machinery.networks.ActorCritic` gives every module's logits and value, illegal moves are
masked out, and the sampled ``(B, A, F)`` actions go back into ``step_arrays``. One categorical
head per field of the control level (``control``). Every module receives the team reward (plus
its own ``join_bonus``); the critic is one parameter-shared value per module. ``total_steps``
counts agent-steps (module-cycles) that enter an update.

    python -m training.trainers.ppo --config configs/train/ppo_chain_move.yaml
    python -m training.trainers.ppo --config configs/train/ppo_chain_move.yaml --total-steps 2000000 --run-dir runs/try
    python -m training.trainers.ppo --resume runs/try/checkpoints/step_0001001472 --total-steps 4000000
    python -m training.trainers.ppo --config configs/train/kickstart_grasp_move.yaml --init runs/bc_grasp
    tensorboard --logdir runs

Kickstarting (``init``, ``distill_*``), curricula and module credit (``join_bonus``):
docs/guides/learning.md. A world's episode ends at success (terminal) or at ``max_cycles``
(the value of its last observation is bootstrapped: the observation holds no clock), and the
world starts its next episode at once, so every sample of every cycle enters the update.

Writes ``runs/<name>/`` (:mod:`training.machinery.runs`); a checkpoint holds ``policy.pt`` (the network),
``trainer.pt`` (optimiser and random state) and ``args.yaml`` (for ``--resume``), and ``proteo eval
--checkpoint runs/<name>`` evaluates it at the control level it was trained at.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch
from tqdm import tqdm

import proteo_env
from proteo_env.config import ConfigError
from proteo_env.registry import task_name
from proteo_env.spaces import N_MOVES
from training.machinery.checkpoints import network_weights
from training.machinery.networks import (
    ActorCritic,
    ReturnScale,
    check_activation,
    check_arch,
    entropy,
    joint_log_prob,
    masked_log_probs,
    network_meta,
    sample,
    sampled_fields,
    teacher_cross_entropy,
)
from training.machinery.policies import check_memory, check_sampled
from training.machinery.runs import (
    PPOArgs,
    ProgressLog,
    check_integers,
    check_numbers,
    checkpoint_folder,
    episode_stats,
    finish_run,
    load_trainer_state,
    load_worlds_state,
    make_run_dir,
    parse_args,
    read_resume,
    save_args,
    save_network_checkpoint,
    save_worlds_state,
    seed_everything,
    torch_device,
    torch_threads,
    trainer_state,
)
from training.trainers.curriculum import Curriculum
from training.trainers.worlds import JOIN_FROM, TrainingEnvs, check_workers, run_settings

ALGORITHM = "ppo"

RETIRED = {"n_groups": 1, "recurrent": 0, "ent_coef_final": None, "learning_rate_final": None}
"""Options of earlier versions, with the value at which they did nothing (checkpoints saved before
they went still resume; see :func:`training.machinery.runs.parse_args`)."""


@dataclass(frozen=True)
class Args(PPOArgs):
    """Native PPO with parameter sharing over all modules (arguments of training/trainers/ppo.py)."""

    # this trainer's defaults of the shared options (what each means: PPOArgs)
    total_steps: int = 10_000_000
    n_envs: int = 64
    n_steps: int = 32
    minibatch_size: int = 8192
    n_epochs: int = 1
    learning_rate: float = 1e-3
    checkpoint_every: int = 1_000_000
    control: str = "move"
    """Control level: move, move+mode or full (the fields the policy chooses)."""
    vf_coef: float = 0.5
    """Weight of the value loss in the loss."""
    value_norm: bool = False
    """Train the critic on returns scaled by their running mean and spread (:class:`~training.machinery.networks.ReturnScale`)."""
    max_grad_norm: float = 0.5
    """Gradient norm limit (of the actor and of the critic separately at arch=mlp)."""
    message_encoding: str = "compact"
    """How the features encode the messages received: compact or per_direction (proteo_env.adapters.flatten)."""
    arch: str = "shared"
    """Network: shared (one trunk for the policy and the value) or mlp (separate MLPs)."""
    hidden: tuple[int, ...] = (64, 64)
    """Widths of the hidden layers: of the shared trunk (arch=shared) or of the actor's and of the
    critic's MLP each (arch=mlp)."""
    activation: str = "tanh"
    """The hidden layers' activation: tanh or relu (training/machinery/networks.py: ACTIVATIONS)."""
    update_threads: int = 1
    """Torch threads of the update (the rollouts keep ``threads``): 2 runs the update on both cores of a
    machine with nothing else to do, the same run bit for bit at the same count (docs/speed/ppo_throughput.md)."""
    memory: str = "none"
    """What the network remembers between cycles: none, last_move or last_action (training/machinery/policies.py)."""
    sampled: str = "all"
    """Which fields the rollouts draw at random: all, or move (the others take their arg-max); the
    entropy bonus counts the fields drawn."""
    device: str = "cpu"
    """Where the network runs: cpu, cuda, cuda:N or mps; the worlds stay on the CPU."""
    workers: int = 1
    """Processes that step the worlds, each its share at the same time (training/trainers/worlds.py: WorkerEnvs);
    the same run on any number. Not with a checkpoint as the teacher, nor with a curriculum."""
    init: str | None = None
    """Start from this checkpoint's network (training/trainers/imitate.py or training/trainers/ppo.py, the same shape)."""
    teacher: str = "rules"
    """The policy of the distillation term: rules, the task's name, or a checkpoint (training/trainers/teachers.py)."""
    distill_coef: float = 0.0
    """Weight of the cross-entropy to the teacher's action at the start (0: off)."""
    distill_steps: int = 0
    """Agent-steps over which that weight falls linearly to distill_final (0: it stays)."""
    distill_final: float = 0.0
    """The distillation weight after distill_steps (at most distill_coef)."""
    curriculum: dict = field(default_factory=dict)
    """Stages of env overrides promoted by success (training/trainers/curriculum.py): {stages: [...], promote_at, window}."""
    join_bonus: float = 0.0
    """Module credit: reward of a module on the cycle its mode leaves the join_from modes (0: off)."""
    join_from: tuple[str, ...] = JOIN_FROM
    """The task's modes of a module not yet in the structure."""

    def __post_init__(self):
        positive = ("n_envs", "n_steps", "minibatch_size", "n_epochs", "checkpoint_every", "workers", "update_threads")
        check_integers(self, {"total_steps": 0, **dict.fromkeys(positive, 1), "distill_steps": 0})
        check_arch(self.arch)
        check_activation(self.activation)
        check_memory(self.memory)
        check_sampled(self.sampled)
        if not 0.0 <= self.distill_final <= self.distill_coef:
            raise ConfigError(
                f"distill_final={self.distill_final!r} is not allowed with distill_coef={self.distill_coef!r}; "
                "allowed: a number in [0, distill_coef]"
            )
        teacher = self.teacher if self.distill_coef > 0 else None
        check_workers(self.workers, self.n_envs, teacher=teacher, curriculum=self.curriculum)
        bounds = {"learning_rate": (0.0, None), "gamma": (0.0, 1.0), "gae_lambda": (0.0, 1.0)}
        loss_terms = ("clip_range", "ent_coef", "vf_coef", "max_grad_norm", "distill_coef")
        check_numbers(self, {**bounds, **dict.fromkeys((*loss_terms, "time_limit_minutes", "join_bonus"), (0.0, None))})

    def distill_weight(self, agent_steps: int) -> float:
        """The distillation weight after ``agent_steps`` agent-steps: linear from ``distill_coef``
        to ``distill_final`` over ``distill_steps``, then ``distill_final`` (``distill_steps`` 0:
        ``distill_coef``)."""
        if self.distill_steps <= 0:
            return self.distill_coef
        done = max(0.0, 1.0 - agent_steps / self.distill_steps)
        return self.distill_final + (self.distill_coef - self.distill_final) * done


# ---------------------------------------------------------------------- rollout
@dataclass
class Rollout:
    """The tensors of one rollout of ``T`` cycles, on the CPU: ``(T, N, ...)`` per module (``N``
    modules of all worlds, world-major), ``(T, n_envs)`` per world."""

    obs: torch.Tensor  # (T, N, D) float32: every module's features (TrainingEnvs.encode)
    mask: torch.Tensor  # (T, N, 13) bool: its legal moves
    actions: torch.Tensor  # (T, N, F) int64: the actions played
    labels: torch.Tensor  # (T, N, F) int64: the teacher's actions (distillation only)
    logp: torch.Tensor  # (T, N): the log-probability of the fields drawn at random
    values: torch.Tensor  # (T, N): the critic's values, in return units
    bootstrap: torch.Tensor  # (T, N): the value of the last observation of an episode truncated there
    joined: torch.Tensor  # (T, N): 1 where a module joined the structure (module credit only)
    rewards: torch.Tensor  # (T, n_envs) float32: the team reward
    terminal: torch.Tensor  # (T, n_envs) bool: the episode succeeded
    truncated: torch.Tensor  # (T, n_envs) bool: the episode hit max_cycles

    @classmethod
    def allocate(cls, t_steps: int, worlds: TrainingEnvs) -> Rollout:
        n, per_world = worlds.n_envs * worlds.n_agents, (t_steps, worlds.n_envs)
        fields = (t_steps, n, len(worlds.nvec))
        return cls(
            obs=torch.zeros((t_steps, n, worlds.size)),
            mask=torch.zeros((t_steps, n, N_MOVES), dtype=torch.bool),
            actions=torch.zeros(fields, dtype=torch.int64),
            labels=torch.zeros(fields, dtype=torch.int64),
            logp=torch.zeros((t_steps, n)),
            values=torch.zeros((t_steps, n)),
            bootstrap=torch.zeros((t_steps, n)),
            joined=torch.zeros((t_steps, n)),
            rewards=torch.zeros(per_world),
            terminal=torch.zeros(per_world, dtype=torch.bool),
            truncated=torch.zeros(per_world, dtype=torch.bool),
        )

    def samples(self, advantages: torch.Tensor, returns: torch.Tensor) -> Samples:
        """Every module-cycle of the rollout as one sample of the update, with its advantage and return."""
        columns = (self.obs, self.mask, self.actions, self.logp, advantages, returns, self.labels)
        return Samples(*(column.reshape(-1, *column.shape[2:]) for column in columns))


class Samples(NamedTuple):
    """A rollout's module-cycles flattened to rows for the update (:meth:`Rollout.samples`)."""

    obs: torch.Tensor
    mask: torch.Tensor
    actions: torch.Tensor
    logp: torch.Tensor
    advantages: torch.Tensor
    returns: torch.Tensor
    labels: torch.Tensor

    def rows(self, index: torch.Tensor, device) -> Samples:
        """The samples at ``index`` (a minibatch), on ``device`` (``index_select``: the same rows as
        ``column[index]``, five times as fast on a CPU)."""
        return Samples(*(torch.index_select(column, 0, index).to(device) for column in self))


def collect_rollout(
    rollout: Rollout, worlds: TrainingEnvs, net: ActorCritic, scale: ReturnScale, teachers, distill: float, args: Args
) -> tuple[torch.Tensor, list[dict]]:
    """Fill ``rollout`` with ``n_steps`` cycles of every world; returns the value of the
    observation after the last cycle ``(N,)`` and the episodes that ended."""
    device, finished = next(net.parameters()).device, []
    for t in range(args.n_steps):
        worlds.encode(rollout.obs[t].numpy(), rollout.mask[t].numpy())
        if distill > 0:
            rollout.labels[t] = torch.from_numpy(worlds.teacher_labels(teachers))
        logits, values = net(rollout.obs[t].to(device))
        actions, logp = sample(masked_log_probs(logits, rollout.mask[t].to(device), net.nvec), args.sampled)
        rollout.actions[t], rollout.logp[t], rollout.values[t] = actions.cpu(), logp.cpu(), scale.value(values).cpu()
        played = rollout.actions[t].numpy().reshape(args.n_envs, worlds.n_agents, -1)
        reward, terminal, truncated = worlds.step(played, finished)
        rollout.rewards[t] = torch.from_numpy(reward)
        rollout.terminal[t], rollout.truncated[t] = torch.from_numpy(terminal), torch.from_numpy(truncated)
        if args.join_bonus:
            rollout.joined[t] = torch.from_numpy(worlds.joined.astype(np.float32))
        if distill > 0:
            teachers.restart(terminal | truncated)
        if len(worlds.final_rows):  # the value at max_cycles, bootstrapped
            final_values = net.value(torch.from_numpy(worlds.final_features).to(device))
            rollout.bootstrap[t, worlds.final_rows] = scale.value(final_values).cpu()
    last = torch.zeros(rollout.obs.shape[1:])
    worlds.encode(last.numpy(), np.zeros((len(last), N_MOVES), dtype=bool))
    return scale.value(net.value(last.to(device))).cpu(), finished


def advantages_and_returns(
    rollout: Rollout, last_value: torch.Tensor, n_agents: int, args: Args
) -> tuple[torch.Tensor, torch.Tensor]:
    """Advantages ``(T, N)`` by GAE over cycles, per module, and the returns: the join bonus is
    added to the rewards, the value after an episode truncated at ``max_cycles`` is that of its
    last observation (``bootstrap``) and after success zero, and the recursion does not carry
    across the end of an episode."""
    terminal, truncated, rewards = (
        per_world.repeat_interleave(n_agents, dim=1)
        for per_world in (rollout.terminal, rollout.truncated, rollout.rewards)
    )
    if args.join_bonus:
        rewards = rewards + args.join_bonus * rollout.joined
    values = rollout.values
    next_values = torch.where(truncated, rollout.bootstrap, torch.cat([values[1:], last_value[None]]))
    terminal, done = terminal.float(), (terminal | truncated).float()
    advantages = torch.zeros_like(values)
    carry = torch.zeros_like(values[0])
    for t in reversed(range(len(values))):
        delta = rewards[t] + args.gamma * next_values[t] * (1.0 - terminal[t]) - values[t]
        carry = delta + args.gamma * args.gae_lambda * (1.0 - done[t]) * carry
        advantages[t] = carry
    return advantages, advantages + values


def update(
    net: ActorCritic, optimiser: torch.optim.Optimizer, samples: Samples, scale: ReturnScale, distill: float, args: Args
) -> dict[str, list[float]]:
    """``n_epochs`` passes of clipped PPO (plus the distillation term) over the rollout's samples,
    in minibatches of ``minibatch_size``; returns each loss term per minibatch."""
    device = next(net.parameters()).device
    stats = {f"loss/{k}": [] for k in ("policy", "value", "entropy", "approx_kl", "clip_fraction", "distill")}
    for _ in range(args.n_epochs):
        order = torch.randperm(len(samples.obs))
        for start in range(0, len(order), args.minibatch_size):
            mb = samples.rows(order[start : start + args.minibatch_size], device)
            adv = (mb.advantages - mb.advantages.mean()) / (mb.advantages.std() + 1e-8)
            logits, values = net(mb.obs)
            log_probs = masked_log_probs(logits, mb.mask, net.nvec)
            drawn = sampled_fields(log_probs, args.sampled)
            ratio = torch.exp(joint_log_prob(drawn, mb.actions) - mb.logp)
            policy_loss = -torch.min(ratio * adv, ratio.clamp(1 - args.clip_range, 1 + args.clip_range) * adv).mean()
            value_loss = 0.5 * (values - scale.target(mb.returns)).pow(2).mean()
            ent = entropy(drawn).mean()
            loss = policy_loss + args.vf_coef * value_loss - args.ent_coef * ent
            if distill > 0:
                distill_loss = teacher_cross_entropy(log_probs, mb.labels, mb.mask)
                loss = loss + distill * distill_loss
                stats["loss/distill"].append(distill_loss.item())
            optimiser.zero_grad(set_to_none=True)
            loss.backward()
            net.clip_gradients(args.max_grad_norm)
            optimiser.step()
            with torch.no_grad():
                stats["loss/policy"].append(policy_loss.item())
                stats["loss/value"].append(value_loss.item())
                stats["loss/entropy"].append(ent.item())
                stats["loss/approx_kl"].append(((ratio - 1) - torch.log(ratio)).mean().item())
                stats["loss/clip_fraction"].append(((ratio - 1).abs() > args.clip_range).float().mean().item())
    return stats


def make_teachers(args: Args, worlds: TrainingEnvs, agent_steps: int):
    """The teachers of the distillation term for ``worlds`` (``None`` when it is off)."""
    if args.distill_coef <= 0:
        return None
    return worlds.make_teachers(args.teacher, seed=args.seed + agent_steps, n_fields=len(worlds.nvec))


def keeps_worlds(args: Args) -> bool:
    """Whether the run's checkpoints keep its worlds (:func:`~training.machinery.runs.save_worlds_state`),
    so that a run resumed from one goes on bit for bit as if never stopped (with as many
    ``workers``): without a curriculum (which rebuilds them) and without a teacher (the rules'
    compiled state does not pickle)."""
    return not args.curriculum and args.distill_coef <= 0


def main(argv=None) -> Path:
    """Parse the arguments and train. ``--resume CHECKPOINT`` without ``--config`` starts from the
    arguments the checkpoint was trained with (its ``args.yaml``); flags given override them."""
    return train(parse_args(Args, argv, retired=RETIRED, saved_args=True))


def train(args: Args) -> Path:
    """Train; returns the final checkpoint's folder."""
    seed_everything(args.seed, threads=args.threads)
    device = torch_device(args.device)
    resume = read_resume(args.resume, ALGORITHM, "proteo train ppo", needs=("trainer.pt",))
    agent_steps = int(resume["agent_steps"]) if resume else 0
    curriculum = None
    if args.curriculum:
        curriculum = Curriculum(
            args.curriculum,
            lambda stage: proteo_env.make_batched(args.task, 1, control=args.control, **{**args.env, **stage}),
            stage=int((resume or {}).get("curriculum_stage", 0)),
        )
    env = args.env if curriculum is None else curriculum.overrides(args.env)
    fingerprint = {k: v for k, v in run_settings(args, env, 0).items() if k != "env_seed"}
    kept = load_worlds_state(resume, fingerprint) if resume is not None and keeps_worlds(args) else None
    worlds = TrainingEnvs.for_run(args, env, agent_steps, kept)
    net = ActorCritic(worlds.encoder, worlds.nvec, args.arch, args.hidden, args.memory, args.activation)
    if args.init and resume is None:
        weights = network_weights(
            args.init, worlds.task_id, network_meta(args), worlds.encoder.spec(), where=f"init={args.init!r}"
        )
        net.load_state_dict(weights)
    # written only once the arguments, the worlds and the init checkpoint are known to be good
    run_dir = make_run_dir(
        args.run_dir or (resume or {}).get("run_dir"),
        f"ppo_{task_name(args.task)}_{args.control.replace('+', '-')}_s{args.seed}",
        resume=resume is not None,
    )
    save_args(args, run_dir)
    net.to(device)
    optimiser = torch.optim.Adam(net.parameters(), lr=args.learning_rate, eps=1e-5)
    teachers = make_teachers(args, worlds, agent_steps)
    scale = ReturnScale(args.value_norm)
    if resume is not None:
        state = load_trainer_state(resume, net, optimiser, learning_rate=args.learning_rate, device=device)
        if "return_scale" in state:
            scale.load_state_dict(state["return_scale"])

    def save(folder: Path) -> None:
        if keeps_worlds(args):  # before proteo.json, which records every file's digest
            folder.mkdir(parents=True, exist_ok=True)
            save_worlds_state(folder, fingerprint, worlds.shares())
        save_network_checkpoint(
            folder,
            net,
            args,
            run_dir,
            trainer=trainer_state(optimiser, return_scale=scale.state_dict()),
            algorithm=ALGORITHM,
            task=worlds.task_id,
            env_overrides=env,
            encoder_spec=worlds.encoder.spec(),
            nvec=net.nvec,
            agent_steps=agent_steps,
            seed=args.seed,
            extra={
                "label": f"ppo-{args.arch}",
                **network_meta(args),
                "sampled": args.sampled,
                "run_dir": str(run_dir),
                "args": asdict(args),
                **({"curriculum_stage": curriculum.stage} if curriculum else {}),
            },
        )

    rollout = Rollout.allocate(args.n_steps, worlds)
    log = ProgressLog(run_dir, tensorboard=args.tensorboard, resumed_at=agent_steps if resume is not None else None)
    bar = tqdm(
        total=args.total_steps, initial=agent_steps, unit="agent-step", desc=ALGORITHM, disable=not args.progress_bar
    )
    saved_interval = agent_steps // args.checkpoint_every  # checkpoint_every intervals done at the last save
    while agent_steps < args.total_steps:
        if args.time_limit_minutes and log.seconds > 60 * args.time_limit_minutes:
            break
        started = time.perf_counter()
        env_s, enc_s = worlds.env_seconds, worlds.encode_seconds
        distill = args.distill_weight(agent_steps) if teachers is not None else 0.0
        with torch.no_grad():
            last_value, finished = collect_rollout(rollout, worlds, net, scale, teachers, distill, args)
        collected = time.perf_counter()
        advantages, returns = advantages_and_returns(rollout, last_value, worlds.n_agents, args)
        scale.update(returns)
        with torch_threads(args.update_threads):
            stats = update(net, optimiser, rollout.samples(advantages, returns), scale, distill, args)
        updated = time.perf_counter()
        agent_steps += returns.numel()
        bar.update(returns.numel())
        env_time, enc_time = worlds.env_seconds - env_s, worlds.encode_seconds - enc_s
        v, r = rollout.values.reshape(-1), returns.reshape(-1)
        log.log(
            agent_steps,
            {
                **episode_stats(finished),
                **{k: float(np.mean(x)) for k, x in stats.items() if x},
                "loss/distill_weight": distill,
                **({"curriculum/stage": curriculum.stage} if curriculum else {}),
                "loss/explained_variance": float(1 - (r - v).var() / (r.var() + 1e-8)),
                "time/env_seconds": env_time,
                "time/encode_seconds": enc_time,
                "time/forward_seconds": collected - started - env_time - enc_time,
                "time/update_seconds": updated - collected,
                "throughput/agent_steps_per_s": returns.numel() / (updated - started),
            },
        )
        if curriculum is not None and curriculum.record(finished):  # the next stage's worlds replace these
            env = curriculum.overrides(args.env)
            worlds = TrainingEnvs.for_run(args, env, agent_steps)
            teachers = make_teachers(args, worlds, agent_steps)
            rollout = Rollout.allocate(args.n_steps, worlds)
        if agent_steps // args.checkpoint_every > saved_interval:
            saved_interval = agent_steps // args.checkpoint_every
            save(checkpoint_folder(run_dir, agent_steps))
    bar.close()
    final = finish_run(run_dir, save, log, agent_steps)
    worlds.close()
    return final


if __name__ == "__main__":
    from training.machinery.runs import run_script

    raise SystemExit(run_script(main))

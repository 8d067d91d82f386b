"""PPO with one policy shared by every module, over the batched array API (no per-agent dicts).

Every module of ``n_envs`` worlds is one sample: the worlds run as one
:class:`~proteo_env.batched.BatchedEnv` (``proteo_env.make_batched(task, n_envs,
control=level)``; ``n_groups`` splits them into several), the observation arrays of all modules are encoded at once
(:class:`~proteo_env.adapters.flatten.ObservationEncoder`, the encoding every learner here
uses), one forward pass gives every module's logits and value, illegal moves are masked out
of the move logits (``action_mask``), and the sampled ``(B, A, F)`` action array goes back into
``step_arrays``. ``total_steps`` counts agent-steps (module-cycles) that enter an update.

    python -m training.ppo --config configs/train/ppo_chain_move.yaml
    python -m training.ppo --config configs/train/ppo_chain_move.yaml --total-steps 2000000 --run-dir runs/try
    python -m training.ppo --resume runs/try/checkpoints/step_0001001472 --total-steps 4000000
    python -m training.ppo --config configs/train/kickstart_grasp_move.yaml --init runs/bc_grasp
    tensorboard --logdir runs

Actions. One categorical head per controlled field of the control level (``control``):
``move`` only at ``move``, ``move`` and ``mode`` at ``move+mode``, every field at ``full``.

Networks (``arch``):

- ``mlp``: a tanh MLP from the flat features to the logits of every head.
- ``shared``: one tanh MLP trunk feeding both the policy's logits and the value (the critic
  shares the actor's layers: one pass instead of two, in the rollout and the update).
- ``lattice``: one small encoder shared by the 12 neighbour directions. Direction ``k``'s
  token is what the module sees there (the site's kind, mode and scent blocks, the message
  received from it, whether the move towards it is legal) and the direction's unit vector;
  the tokens' embeddings are mean- and max-pooled and joined with the module's own features
  (mode, scent, contact, load, hint) into a context; the logit of "move towards ``k``" is a
  shared head on (token ``k``, context), the other heads read the context.

The critic (at ``mlp`` and ``lattice``) is a separate tanh MLP on the same local features: one
parameter-shared value per module estimating the team's return (every module receives the
team reward).

Kickstarting. ``init`` starts from the network of another checkpoint (a clone from
:mod:`training.imitate`, or a PPO run) of the same task, level, encoding and network shape.
``distill_coef > 0`` adds to the loss the cross-entropy between the policy and the teacher's
action (:mod:`training.teachers`, the task's rules by default) on the learner's own states,
weighted by ``distill_coef``, which falls linearly to ``distill_final`` (default zero) over
the first ``distill_steps`` agent-steps (0: it stays); at zero the teacher is no longer
consulted and the learner is free to leave it behind, while a small ``distill_final`` keeps
it near the teacher.

Module credit. Every module earns the team reward, so one module's move gets little signal of
its own. ``join_bonus > 0`` adds, to the reward of each module alone, ``join_bonus`` on the cycle
its own mode leaves the ``join_from`` modes (SLEEP and SEARCH by default) for another: the cycle it
joined the structure (at ``move`` the autopilot makes that change when the module reaches a spot
the structure offers). :attr:`TrainingEnvs.joined` holds those modules.

Schedules. ``learning_rate_final`` and ``ent_coef_final`` make the learning rate and the entropy
coefficient fall (or rise) linearly from their start values to these by ``total_steps``;
unset, they stay constant.

Memory. ``memory`` feeds each module's previous action, and with ``clock`` the cycles it has
been in its mode, back as inputs (:data:`training.policies.MEMORIES`); ``recurrent: R`` (at
``arch: shared``) adds a GRU whose state ``(R,)`` each module carries from cycle to cycle and
that restarts at zero with its world's episode (:class:`~training.networks.ActorCritic`). The
rollout keeps every module's state; the update replays each minibatch of modules through the
rollout's ``n_steps`` cycles from their state at its start (back-propagation through those
cycles), so a minibatch is ``minibatch_size // n_steps`` modules' whole sequences. ``--init``
from a feed-forward checkpoint of the same shape starts the GRU fresh and its heads at zero:
the network first acts exactly as the checkpoint.

Curricula. ``curriculum: {stages: [...], promote_at, window}`` trains on stages of env
overrides in turn, each promoted when the success rate of its last ``window`` episodes reaches
``promote_at`` (:mod:`training.curriculum`); the stage is logged and saved with checkpoints.

Episode ends. A world's episode ends at success or at ``max_cycles``, and the world starts
its next episode at once (``BatchedEnv.reset_worlds``) while the others run on, so every
sample of every cycle enters the update. At ``max_cycles`` the value of the last observation
is bootstrapped (the observation holds no clock); success is terminal.

Writes ``runs/<name>/`` (see :mod:`training.common`): ``progress.csv``, TensorBoard logs,
checkpoints every ``checkpoint_every`` agent-steps and ``final/`` (``policy.pt``: the network's
weights; ``trainer.pt``: optimiser and random state, ``args.yaml``: the arguments, for
``--resume``); ``proteo eval
--checkpoint runs/<name>`` evaluates the result at the control level it was trained at.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

import proteo_env
from proteo_env.adapters.flatten import ObservationEncoder
from proteo_env.config import ConfigError, world_seeds
from proteo_env.registry import task_name
from proteo_env.spaces import N_MOVES, ObservationBuffers
from training.common import (
    ProgressLog,
    check_integers,
    checkpoint_folder,
    episode_stats,
    make_run_dir,
    parse_args,
    save_args,
    seed_everything,
    torch_device,
    write_checkpoint_meta,
)
from training.networks import ARCHS, ActorCritic
from training.policies import check_memory, check_sampled, clock_step, with_memory

ALGORITHM = "ppo"


@dataclass(frozen=True)
class Args:
    """Native PPO with parameter sharing over all modules (arguments of training/ppo.py)."""

    task: str = "chain-v0"
    control: str = "move"
    """Control level: move, move+mode or full (the fields the policy chooses)."""
    env: dict = field(default_factory=lambda: {"n_modules": 12, "max_cycles": 300})
    """Overrides passed to ``proteo_env.make_batched`` (size, cycle limit, physics, task parameters)."""
    seed: int = 0
    total_steps: int = 10_000_000
    """Agent-steps (module-cycles used for learning) to train for."""
    n_envs: int = 64
    """Worlds stepped together; samples per cycle = n_envs * modules."""
    n_groups: int = 1
    """BatchedEnvs the worlds are split into (1 is fastest: one engine call per cycle for all worlds)."""
    n_steps: int = 32
    """Cycles per world in one rollout."""
    minibatch_size: int = 8192
    n_epochs: int = 2
    learning_rate: float = 1e-3
    learning_rate_final: float | None = None
    """The learning rate at ``total_steps``, reached linearly from ``learning_rate`` (None: it stays)."""
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.01
    ent_coef_final: float | None = None
    """The entropy coefficient at ``total_steps``, reached linearly from ``ent_coef`` (None: it stays)."""
    vf_coef: float = 0.5
    value_norm: bool = False
    """Train the critic on returns scaled by their running mean and standard deviation
    (:class:`ReturnScale`); for tasks whose returns are far from 1 (table's reach hundreds)."""
    max_grad_norm: float = 0.5
    """Gradient norm limit, applied to the actor and to the critic separately (to all weights at arch=shared)."""
    message_encoding: str = "per_direction"
    """How the features encode the messages received: per_direction or compact (proteo_env.adapters.flatten)."""
    arch: str = "mlp"
    """Actor network: mlp or lattice (see the module docstring)."""
    hidden: tuple[int, ...] = (64, 64)
    """Hidden sizes of the MLPs (actor at arch=mlp, critic always; lattice: embedding, head)."""
    memory: str = "none"
    """What the network remembers between cycles: none, last_move or last_action, each optionally
    with +clock (the cycles in its mode), or clock alone (training/policies.py MEMORIES)."""
    recurrent: int = 0
    """The state size of a GRU each module carries from cycle to cycle (arch=shared only); 0: feed-forward."""
    sampled: str = "all"
    """Which fields the rollouts draw at random: all, or move (mode, roles and messages take their arg-max,
    as a clone of training/imitate.py acts; the policy gradient and the entropy bonus then see the move
    alone, and the other fields learn from the distillation term only). Saved with the checkpoint."""
    checkpoint_every: int = 1_000_000
    run_dir: str | None = None
    resume: str | None = None
    """A checkpoint of this script to continue from (its run folder is reused unless run_dir is set)."""
    time_limit_minutes: float = 0.0
    """Stop early (with a final checkpoint) after this much wall-clock time; 0: no limit."""
    threads: int = 1
    """Threads for torch and numba (1 is fastest on a busy 2-core machine)."""
    device: str = "cpu"
    """Where the network runs: cpu (the default), cuda, cuda:N or mps; the worlds stay on the CPU."""
    tensorboard: bool = True
    progress_bar: bool = True
    init: str | None = None
    """Start from this checkpoint's network (training/imitate.py or training/ppo.py; same task, level,
    encoding, arch and hidden): kickstarting from a clone."""
    teacher: str = "rules"
    """The policy of the distillation term: rules (the task's hand-coded policy), the task's name, or a
    checkpoint of the task at this control level (training/teachers.py)."""
    distill_coef: float = 0.0
    """Weight of the cross-entropy to the teacher's action on the learner's states at the start (0: off)."""
    distill_steps: int = 0
    """Agent-steps over which the weight falls linearly from distill_coef to distill_final (0: it stays)."""
    distill_final: float = 0.0
    """The distillation weight after distill_steps (0: the teacher is let go; at most distill_coef)."""
    curriculum: dict = field(default_factory=dict)
    """Stages of env overrides promoted by success (training/curriculum.py): {stages: [...], promote_at, window}."""
    join_bonus: float = 0.0
    """Module credit: what a module earns, on top of the team reward, on the cycle its own mode leaves the
    ``join_from`` modes for another (it joined the structure); 0: off, every module earns the team reward alone."""
    join_from: tuple[str, ...] = ("SLEEP", "SEARCH")
    """The task's modes of a module not yet in the structure (names from the task's ``modes``)."""

    def __post_init__(self):
        check_integers(
            self,
            {
                "total_steps": 0,
                "n_envs": 1,
                "n_groups": 1,
                "n_steps": 1,
                "minibatch_size": 1,
                "n_epochs": 1,
                "checkpoint_every": 1,
                "distill_steps": 0,
                "recurrent": 0,
            },
        )
        check_sampled(self.sampled)
        if not 0.0 <= self.distill_final <= self.distill_coef:
            raise ConfigError(
                f"distill_final={self.distill_final!r} is not allowed with distill_coef={self.distill_coef!r}; "
                "allowed: a number in [0, distill_coef]"
            )
        if self.recurrent and self.arch != "shared":
            raise ConfigError(
                f"recurrent={self.recurrent!r} is not allowed with arch={self.arch!r}; allowed: "
                "recurrent=0, or arch='shared'"
            )
        for name, low, high in (
            ("learning_rate", 0.0, None),
            ("gamma", 0.0, 1.0),
            ("gae_lambda", 0.0, 1.0),
            ("clip_range", 0.0, None),
            ("ent_coef", 0.0, None),
            ("learning_rate_final", 0.0, None),
            ("ent_coef_final", 0.0, None),
            ("vf_coef", 0.0, None),
            ("max_grad_norm", 0.0, None),
            ("distill_coef", 0.0, None),
            ("time_limit_minutes", 0.0, None),
            ("join_bonus", 0.0, None),
        ):
            value = getattr(self, name)
            if value is None and name.endswith("_final"):
                continue
            if not isinstance(value, (int, float)) or value < low or (high is not None and value > high):
                allowed = f"a number in [{low}, {high}]" if high is not None else f"a number >= {low}"
                raise ConfigError(f"{name}={value!r} is not allowed; allowed: {allowed}")

    def annealed(self, name: str, agent_steps: int) -> float:
        """``learning_rate`` or ``ent_coef`` after ``agent_steps`` agent-steps: linear to its ``_final`` value
        at ``total_steps`` when that is set, else constant."""
        final = getattr(self, name + "_final")
        if final is None:
            return getattr(self, name)
        return linear(getattr(self, name), final, agent_steps, self.total_steps)

    def distill_weight(self, agent_steps: int) -> float:
        """The distillation weight after ``agent_steps`` agent-steps."""
        return linear(self.distill_coef, self.distill_final, agent_steps, self.distill_steps)


def linear(start: float, final: float, agent_steps: int, over: int) -> float:
    """``start`` moved linearly to ``final`` over the first ``over`` agent-steps, then ``final`` (``over`` 0: ``start``)."""
    if over <= 0:
        return start
    return final + (start - final) * max(0.0, 1.0 - agent_steps / over)


# ---------------------------------------------------------------------- actions
def masked_log_probs(logits: torch.Tensor, move_mask: torch.Tensor, nvec: list[int]) -> list[torch.Tensor]:
    """Per field, log-probabilities ``(N, nvec[k])``; illegal moves (``move_mask`` False) get ~zero probability."""
    out, start = [], 0
    for k, n in enumerate(nvec):
        part = logits[:, start : start + n]
        if k == 0:
            part = part.masked_fill(~move_mask, -1e8)
        out.append(torch.log_softmax(part, dim=1))
        start += n
    return out


def sample(log_probs: list[torch.Tensor], sampled: str = "all") -> tuple[torch.Tensor, torch.Tensor]:
    """Actions ``(N, F)`` (Gumbel-max, torch's generator) and the joint log-probability ``(N,)`` of
    the fields drawn at random. ``sampled="move"`` (:data:`training.policies.SAMPLED`): the fields
    after the move take their arg-max and the log-probability is the move's; the generator is
    drawn from the same either way."""
    noisy = [lp - torch.log(-torch.log(torch.rand_like(lp))) for lp in log_probs]
    actions = torch.stack(
        [
            (noise if k == 0 or sampled == "all" else lp).argmax(dim=1)
            for k, (lp, noise) in enumerate(zip(log_probs, noisy))
        ],
        1,
    )
    return actions, joint_log_prob(sampled_fields(log_probs, sampled), actions)


def sampled_fields(log_probs: list[torch.Tensor], sampled: str) -> list[torch.Tensor]:
    """The fields that :func:`sample` draws at random (every field, or the move alone): the ones the
    policy gradient and the entropy bonus act on."""
    return log_probs if sampled == "all" else log_probs[:1]


def joint_log_prob(log_probs: list[torch.Tensor], actions: torch.Tensor) -> torch.Tensor:
    return sum(lp.gather(1, actions[:, k : k + 1])[:, 0] for k, lp in enumerate(log_probs))


def teacher_cross_entropy(log_probs: list[torch.Tensor], labels: torch.Tensor, move_mask: torch.Tensor) -> torch.Tensor:
    """Mean over samples of ``-log pi(label)`` summed over fields, for labels ``(N, F)``; samples
    whose labelled move is illegal under ``move_mask (N, 13)`` count zero."""
    legal = move_mask.gather(1, labels[:, :1])[:, 0].float()
    return -(joint_log_prob(log_probs, labels) * legal).sum() / legal.sum().clamp(min=1.0)


def entropy(log_probs: list[torch.Tensor]) -> torch.Tensor:
    """Sum over fields of each field's entropy ``(N,)``."""
    return sum(-(lp.exp() * lp).sum(dim=1) for lp in log_probs)


# ---------------------------------------------------------------------- environment side
def join_modes(task, names) -> np.ndarray:
    """The mode numbers of ``names`` (``join_from``) in ``task``'s modes, refused unless each is one."""
    for name in names:
        if name not in task.modes:
            raise ConfigError(
                f"join_from={list(names)!r} is not allowed for {task.task_id()}: {name!r} is not one of its modes; "
                f"allowed: names from {', '.join(task.modes)}"
            )
    return np.array([task.modes.index(name) for name in names], dtype=np.int64)


def training_worlds_seed(seed: int, agent_steps: int) -> np.random.SeedSequence:
    """The seed of a run's worlds built after ``agent_steps`` (a resumed run or a curriculum's next
    stage does not replay its first episodes): ``SeedSequence([seed, agent_steps])``, which at
    ``agent_steps = 0`` is ``SeedSequence(seed)`` and never another training seed's."""
    return np.random.SeedSequence([seed, agent_steps])


class TrainingEnvs:
    """``n_envs`` worlds as ``n_groups`` BatchedEnvs, each world restarted as soon as its episode ends.

    Rows are world-major across groups: sample ``w * A + i`` is module ``i`` of world ``w``,
    world ``w`` is world ``w % b`` of group ``w // b`` (``b = n_envs // n_groups``). World ``w``
    is seeded with child ``w`` of ``SeedSequence(env_seed)`` (:func:`proteo_env.config.world_seeds`;
    ``env_seed`` an integer or a seed sequence), so no two worlds of a run, or of runs with other
    seeds, share a stream; its later episodes continue its own generator
    (:meth:`~proteo_env.batched.BatchedEnv.reset_worlds`).
    """

    def __init__(self, args: Args, env_seed: int):
        if args.n_groups < 1 or args.n_envs % args.n_groups:
            raise ConfigError(
                f"n_groups={args.n_groups!r} is not allowed with n_envs={args.n_envs}; allowed: a divisor of n_envs"
            )
        overrides = dict(args.env)
        self.b = args.n_envs // args.n_groups
        self.groups = [
            proteo_env.make_batched(args.task, self.b, control=args.control, **overrides) for _ in range(args.n_groups)
        ]
        first = self.groups[0]
        self.task_id = first.task.task_id()
        self.n_envs, self.n_agents = args.n_envs, first.n_agents
        self.nvec = first.control_nvec
        self.encoder = ObservationEncoder(
            n_sites=first.n_sites,
            n_channels=first.task.n_channels,
            n_modes=len(first.task.modes),
            n_message_values=first.task.n_message_values,
            scent_max=first.config.physics.scent_max,
            message_encoding=args.message_encoding,
        )
        self.memory = getattr(args, "memory", "none")
        self.size = self.encoder.size + check_memory(self.memory, self.nvec)
        """Features per sample: the encoding, then the memory's inputs."""
        self.previous_actions = np.zeros((self.n_envs * self.n_agents, len(self.nvec)), dtype=np.int64)
        """``(N, F)``: each module's action in the last cycle (zeros at an episode's start), the memory's source."""
        seeds = world_seeds(env_seed, self.n_envs)
        self.buffers = [g.reset(world_seeds=seeds[k * self.b : (k + 1) * self.b]) for k, g in enumerate(self.groups)]
        self.clocked = self.memory.endswith("clock")
        """Whether the memory has a clock (only then are the modes followed, cycle by cycle)."""
        self.clock_mode = self._own_modes()
        """``(N,)``: each module's observed mode, the ``clock`` memory's reference."""
        self.clock = np.zeros(len(self.clock_mode), dtype=np.int64)
        """``(N,)``: each module's cycles in that mode (:func:`training.policies.clock_step`)."""
        self.join_bonus = getattr(args, "join_bonus", 0.0)
        self.outside = join_modes(first.task, args.join_from) if self.join_bonus else np.zeros(0, dtype=np.int64)
        """Mode numbers of a module not yet in the structure (module credit; empty when off)."""
        self.joined = np.zeros(self.n_envs * self.n_agents, dtype=bool)
        """``(N,)``: which modules joined the structure in the last :meth:`step` (module credit only)."""
        self.episode_return = np.zeros(self.n_envs)
        self.final_rows = np.zeros(0, dtype=np.int64)
        """Sample rows of the worlds truncated in the last :meth:`step` (their episodes hit ``max_cycles``)."""
        self.final_features = np.zeros((0, self.size), dtype=np.float32)
        """``(len(final_rows), D)`` features of those rows' last observation (the value there is bootstrapped)."""
        self.env_seconds = 0.0
        self.encode_seconds = 0.0

    def encode(self, features: np.ndarray, move_mask: np.ndarray) -> None:
        """Write every module's features ``(N, size)`` (with the memory's inputs) and legal moves
        ``(N, 13)`` into the given arrays (one encoding call over the observation fields of all groups)."""
        started = time.perf_counter()
        if len(self.buffers) == 1:
            fields = {name: getattr(self.buffers[0], name) for name in ObservationBuffers.FIELDS}
        else:
            fields = {
                name: np.concatenate([getattr(b, name) for b in self.buffers]) for name in ObservationBuffers.FIELDS
            }
        features[:] = with_memory(
            self.encoder.encode_fields(fields), self.previous_actions, self.memory, self.nvec, self.clock
        )
        move_mask[:] = fields["action_mask"]
        self.encode_seconds += time.perf_counter() - started

    def _own_modes(self) -> np.ndarray:
        """``(N,)``: every module's own mode in the current observations."""
        return np.concatenate([np.asarray(b.own_mode).reshape(-1) for b in self.buffers]).astype(np.int64)

    def step(self, actions: np.ndarray, finished: list[dict]):
        """One cycle of every world from ``(n_envs, A, F)`` actions.

        Returns ``(reward, terminal, truncated)`` per world (``(n_envs,)`` each): ``terminal`` at
        success, ``truncated`` at ``max_cycles`` without success. Ended episodes are appended to
        ``finished`` and their worlds restarted; :attr:`final_rows` and :attr:`final_features`
        hold the truncated worlds' last observation.
        """
        started = time.perf_counter()
        a = self.n_agents
        outside = np.isin(self._own_modes(), self.outside) if self.join_bonus else None
        reward = np.zeros(self.n_envs)
        terminal = np.zeros(self.n_envs, dtype=bool)
        truncated = np.zeros(self.n_envs, dtype=bool)
        cycles = np.zeros(self.n_envs, dtype=np.int64)
        for k, group in enumerate(self.groups):
            worlds = slice(k * self.b, (k + 1) * self.b)
            result = group.step_arrays(actions[worlds])
            reward[worlds], terminal[worlds], truncated[worlds] = result.reward, result.terminated, result.truncated
            cycles[worlds] = group.cycles
        ended = terminal | truncated
        self.episode_return += reward
        played = actions.reshape(len(self.previous_actions), -1)
        self.previous_actions = np.where(np.repeat(ended, a)[:, None], 0, played)
        for w in np.flatnonzero(ended):
            finished.append({"r": self.episode_return[w], "success": bool(terminal[w]), "l": int(cycles[w])})
        self.episode_return[ended] = 0.0
        self.buffers = [group.observe_arrays() for group in self.groups]
        if self.join_bonus:
            self.joined = outside & ~np.isin(self._own_modes(), self.outside)
        if self.clocked:
            modes = self._own_modes()
            self.clock = clock_step(self.clock_mode, self.clock, modes)
        rows, features = [], []
        for k, group in enumerate(self.groups):
            restart = ended[k * self.b : (k + 1) * self.b]
            for j in np.flatnonzero(truncated[k * self.b : (k + 1) * self.b]):
                world = np.arange((k * self.b + j) * a, (k * self.b + j + 1) * a)
                rows.append(world)
                features.append(
                    with_memory(
                        self.encoder.encode_buffers(self.buffers[k].rows(j * a, (j + 1) * a)),
                        actions[k * self.b + j],
                        self.memory,
                        self.nvec,
                        self.clock[world],
                    )
                )
            if restart.any():
                self.buffers[k] = group.reset_worlds(restart)
        if self.clocked:
            restarted = np.repeat(ended, a)
            self.clock_mode = np.where(restarted, self._own_modes(), modes)
            self.clock[restarted] = 0
        self.final_rows = np.concatenate(rows) if rows else self.final_rows[:0]
        self.final_features = np.concatenate(features) if features else self.final_features[:0]
        self.env_seconds += time.perf_counter() - started
        return reward, terminal, truncated


# ---------------------------------------------------------------------- training
def gae(rewards, values, next_values, terminal, done, gamma: float, lam: float) -> torch.Tensor:
    """Advantages ``(T, N)`` by GAE over cycles, per module.

    All arguments ``(T, N)``: ``values`` at each step, ``next_values`` of the observation after
    it (the bootstrap at ``max_cycles``; ignored where ``terminal``), ``done`` where an episode
    ended (success or ``max_cycles``): the recursion does not carry across it.
    """
    advantages = torch.zeros_like(values)
    carry = torch.zeros_like(values[0])
    for t in reversed(range(values.shape[0])):
        delta = rewards[t] + gamma * next_values[t] * (1.0 - terminal[t]) - values[t]
        carry = delta + gamma * lam * (1.0 - done[t]) * carry
        advantages[t] = carry
    return advantages


class ReturnScale:
    """Running mean and variance of the returns (Chan et al.'s parallel update, float64). With
    ``value_norm`` the critic predicts ``(G - mean) / std`` and :meth:`value` maps its output
    back, so that a value loss on the scaled returns stays near 1 whatever the reward's scale:
    on a shared trunk an unscaled value loss of returns in the hundreds swamps the policy's
    gradient under the joint norm clip. Disabled, every method is the identity."""

    def __init__(self, enabled: bool):
        self.enabled, self.mean, self.var, self.count = enabled, 0.0, 1.0, 0

    def update(self, returns: torch.Tensor) -> None:
        if not self.enabled:
            return
        x = returns.double()
        n, mean, var = x.numel(), x.mean().item(), x.var(unbiased=False).item()
        total = self.count + n
        delta = mean - self.mean
        self.var = (self.var * self.count + var * n + delta * delta * self.count * n / total) / total
        self.mean, self.count = self.mean + delta * n / total, total

    @property
    def std(self) -> float:
        return max(self.var, 1e-8) ** 0.5

    def value(self, output: torch.Tensor) -> torch.Tensor:
        """The critic's output ``(N,)`` in return units."""
        return output * self.std + self.mean if self.enabled else output

    def target(self, returns: torch.Tensor) -> torch.Tensor:
        """Returns ``(N,)`` on the critic's scale."""
        return (returns - self.mean) / self.std if self.enabled else returns

    def state_dict(self) -> dict:
        return {"mean": self.mean, "var": self.var, "count": self.count}

    def load_state_dict(self, state: dict) -> None:
        self.mean, self.var, self.count = state["mean"], state["var"], state["count"]


def initial_weights(args: Args, task_id: str, encoder: ObservationEncoder, net: ActorCritic) -> dict:
    """The weights for ``net`` from checkpoint ``args.init``, after checking that it was trained by
    training/imitate.py or training/ppo.py on the same task, control level, observation encoding
    and network shape; a :class:`~training.common.CheckpointError` naming what differs. A
    feed-forward checkpoint may start a recurrent ``net`` (whose GRU keeps its own weights)."""
    from training.common import CheckpointError, read_meta

    meta = read_meta(args.init)
    where = f"init={args.init!r}"
    if meta["algorithm"] not in ("imitation", ALGORITHM):
        raise CheckpointError(
            f"{where} is a {meta['algorithm']!r} checkpoint; allowed: a checkpoint of "
            "training/imitate.py or training/ppo.py"
        )
    wanted = {
        "task": task_name(task_id),
        "control": args.control,
        "arch": args.arch,
        "hidden": list(args.hidden),
        "memory": args.memory,
        "encoder": encoder.spec(),
    }
    found = {
        "task": task_name(meta["task"]),
        "control": meta.get("control"),
        "arch": meta.get("arch"),
        "hidden": meta.get("hidden"),
        "memory": meta.get("memory", "none"),
        "encoder": meta.get("encoder"),
    }
    for key, value in wanted.items():
        if found[key] != value:
            raise CheckpointError(
                f"{where} was trained with {key}={found[key]!r}; this run has {key}={value!r}; "
                f"allowed: a checkpoint with {key}={value!r}"
            )
    recurrent = int(meta.get("recurrent", 0))
    if recurrent not in (0, args.recurrent):
        raise CheckpointError(
            f"{where} is recurrent (recurrent={recurrent}); this run has "
            f"recurrent={args.recurrent}; allowed: a feed-forward checkpoint or one with "
            f"recurrent={args.recurrent}"
        )
    weights = torch.load(Path(meta["dir"]) / "policy.pt", map_location="cpu", weights_only=True)
    if args.recurrent and not recurrent:  # the GRU keeps its fresh weights, its heads zero
        weights = {**net.state_dict(), **weights}
    return weights


def minibatches(args: Args, t_steps: int, n: int):
    """The update's minibatches over the rollout's ``t_steps * n`` samples (flat index ``t * n +
    i``), ``n_epochs`` passes in random order: ``(indices, None)`` of ``minibatch_size`` samples
    for a feed-forward network; for a recurrent one ``(indices, modules)``: the whole sequences
    of ``minibatch_size // t_steps`` modules (at least one), indices ordered cycle-major."""
    for _ in range(args.n_epochs):
        if not args.recurrent:
            order = torch.randperm(t_steps * n)
            for start in range(0, len(order), args.minibatch_size):
                yield order[start : start + args.minibatch_size], None
            continue
        order, width = torch.randperm(n), max(1, args.minibatch_size // t_steps)
        for start in range(0, n, width):
            modules = order[start : start + width]
            yield (torch.arange(t_steps)[:, None] * n + modules[None, :]).reshape(-1), modules


def main(argv=None) -> Path:
    """Parse the arguments and train. ``--resume CHECKPOINT`` without ``--config`` starts from the
    arguments the checkpoint was trained with (its ``args.yaml``); flags given override them."""
    argv = list(sys.argv[1:] if argv is None else argv)
    given = argparse.ArgumentParser(add_help=False)
    given.add_argument("--resume")
    given.add_argument("--config")
    known, _ = given.parse_known_args(argv)
    if known.resume and not known.config:
        from training.common import checkpoint_dir

        argv = ["--config", str(checkpoint_dir(known.resume) / "args.yaml"), *argv]
    return train(parse_args(Args, argv))


def train(args: Args) -> Path:
    """Train; returns the final checkpoint's folder."""
    from training.common import CheckpointError, read_meta

    seed_everything(args.seed, threads=args.threads)
    device = torch_device(args.device)
    if args.arch not in ARCHS:
        raise ConfigError(f"arch={args.arch!r} is not allowed; allowed: {', '.join(ARCHS)}")
    resume_meta = read_meta(args.resume) if args.resume else None
    if resume_meta is not None and resume_meta["algorithm"] != ALGORITHM:
        raise CheckpointError(
            f"resume={args.resume!r} is a {resume_meta['algorithm']!r} checkpoint; "
            f"allowed: a checkpoint of training/ppo.py"
        )
    agent_steps = int(resume_meta["agent_steps"]) if resume_meta else 0
    curriculum = None
    if args.curriculum:
        from training.curriculum import Curriculum

        curriculum = Curriculum(
            args.curriculum,
            lambda stage: proteo_env.make_batched(args.task, 1, control=args.control, **{**args.env, **stage}),
            stage=int((resume_meta or {}).get("curriculum_stage", 0)),
        )

    def stage_args() -> Args:
        return args if curriculum is None else dataclasses.replace(args, env=curriculum.overrides(args.env))

    worlds = TrainingEnvs(stage_args(), env_seed=training_worlds_seed(args.seed, agent_steps))
    enc, a, nvec = worlds.encoder, worlds.n_agents, [int(n) for n in worlds.nvec]
    net = ActorCritic(enc, nvec, args.arch, args.hidden, args.memory, args.recurrent)
    if args.init and resume_meta is None:
        net.load_state_dict(initial_weights(args, worlds.task_id, enc, net))
    # written only once the arguments, the worlds and the init checkpoint are known to be good
    run_dir = make_run_dir(
        args.run_dir or (resume_meta or {}).get("run_dir"),
        f"ppo_{task_name(args.task)}_{args.control.replace('+', '-')}_s{args.seed}",
        resume=resume_meta is not None,
    )
    save_args(args, run_dir)
    net.to(device)
    optimiser = torch.optim.Adam(net.parameters(), lr=args.learning_rate, eps=1e-5)

    def make_teachers():
        if args.distill_coef <= 0:
            return None
        from training.teachers import Teachers

        return Teachers(worlds.groups[0], worlds.n_envs, args.teacher, seed=args.seed + agent_steps, n_fields=len(nvec))

    teachers = make_teachers()
    scale = ReturnScale(args.value_norm)
    if resume_meta is not None:
        folder = Path(resume_meta["dir"])
        net.load_state_dict(torch.load(folder / "policy.pt", map_location=device, weights_only=True))
        state = torch.load(folder / "trainer.pt", map_location="cpu", weights_only=False)
        optimiser.load_state_dict(state["optimiser"])
        torch.set_rng_state(state["torch_rng"])
        if "return_scale" in state:
            scale.load_state_dict(state["return_scale"])

    t_steps = args.n_steps

    def allocate():
        """Rollout storage for the current worlds: ``(T, N, ...)`` with ``N`` modules of all worlds."""
        n = args.n_envs * worlds.n_agents
        features = np.zeros((t_steps, n, worlds.size), dtype=np.float32)
        move_mask = np.zeros((t_steps, n, N_MOVES), dtype=bool)
        return (
            n,
            features,
            move_mask,
            torch.from_numpy(features),
            torch.from_numpy(move_mask),
            *(torch.zeros((t_steps, n, len(nvec)), dtype=torch.int64) for _ in range(2)),
            *(torch.zeros((t_steps, n)) for _ in range(4)),
        )

    n, features, move_mask, obs_t, mask_t, actions_t, labels_t, logp_t, values_t, bootstrap_t, joined_t = allocate()
    state = net.initial_state(n)
    """Every module's recurrent state ``(n, R)`` before the next cycle (``None`` when feed-forward)."""
    rewards_w, terminal_w, truncated_w = (np.zeros((t_steps, args.n_envs), dtype=d) for d in (np.float32, bool, bool))
    log = ProgressLog(run_dir, tensorboard=args.tensorboard)

    def save(folder: Path) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        torch.save({k: v.cpu() for k, v in net.state_dict().items()}, folder / "policy.pt")
        torch.save(
            {
                "optimiser": optimiser.state_dict(),
                "torch_rng": torch.get_rng_state(),
                "return_scale": scale.state_dict(),
            },
            folder / "trainer.pt",
        )
        save_args(dataclasses.replace(args, resume=None, run_dir=str(run_dir)), folder)
        write_checkpoint_meta(
            folder,
            algorithm=ALGORITHM,
            task=worlds.task_id,
            env_overrides=stage_args().env,
            encoder_spec=enc.spec(),
            nvec=nvec,
            agent_steps=agent_steps,
            seed=args.seed,
            extra={
                "label": f"ppo-{args.arch}",
                "control": args.control,
                "arch": args.arch,
                "hidden": list(args.hidden),
                "memory": args.memory,
                "recurrent": args.recurrent,
                "sampled": args.sampled,
                "run_dir": str(run_dir),
                "args": asdict(args),
                **({"curriculum_stage": curriculum.stage} if curriculum else {}),
            },
        )

    bar = tqdm(
        total=args.total_steps, initial=agent_steps, unit="agent-step", desc=ALGORITHM, disable=not args.progress_bar
    )
    next_checkpoint = (agent_steps // args.checkpoint_every + 1) * args.checkpoint_every
    finished: list[dict] = []
    while agent_steps < args.total_steps:
        if args.time_limit_minutes and log.seconds > 60 * args.time_limit_minutes:
            break
        started = time.perf_counter()
        env_s, enc_s = worlds.env_seconds, worlds.encode_seconds
        distill = args.distill_weight(agent_steps) if teachers is not None else 0.0
        ent_coef, learning_rate = args.annealed("ent_coef", agent_steps), args.annealed("learning_rate", agent_steps)
        for group in optimiser.param_groups:
            group["lr"] = learning_rate
        # ---- rollout: t_steps cycles of every world
        first_state = state
        with torch.no_grad():
            for t in range(t_steps):
                worlds.encode(features[t], move_mask[t])
                if distill > 0:
                    labels_t[t] = torch.from_numpy(teachers.labels(worlds.buffers))
                logits, values, state = net(obs_t[t].to(device), state)
                actions, logp = sample(masked_log_probs(logits, mask_t[t].to(device), nvec), args.sampled)
                actions_t[t], logp_t[t], values_t[t] = actions.cpu(), logp.cpu(), scale.value(values).cpu()
                reward, terminal, truncated = worlds.step(actions_t[t].numpy().reshape(args.n_envs, a, -1), finished)
                rewards_w[t], terminal_w[t], truncated_w[t] = reward, terminal, truncated
                if args.join_bonus:
                    joined_t[t] = torch.from_numpy(worlds.joined.astype(np.float32))
                if distill > 0:
                    teachers.restart(terminal | truncated)
                if len(worlds.final_rows):  # the value at max_cycles, bootstrapped
                    final_values = net.value(
                        torch.from_numpy(worlds.final_features).to(device),
                        None if state is None else state[worlds.final_rows],
                    )
                    bootstrap_t[t, worlds.final_rows] = scale.value(final_values).cpu()
                if state is not None:  # a world's next episode starts from zero state
                    state = state * torch.from_numpy(~np.repeat(terminal | truncated, a)).to(state)[:, None]
            last = np.zeros((n, worlds.size), dtype=np.float32)
            worlds.encode(last, np.zeros((n, N_MOVES), dtype=bool))
            last_value = scale.value(net.value(torch.from_numpy(last).to(device), state)).cpu()
        collected = time.perf_counter()
        terminal, truncated, rewards = (
            torch.from_numpy(np.repeat(w, a, axis=1)) for w in (terminal_w, truncated_w, rewards_w)
        )
        if args.join_bonus:
            rewards = rewards + args.join_bonus * joined_t
        next_values = torch.where(truncated, bootstrap_t, torch.cat([values_t[1:], last_value[None]]))
        advantages = gae(
            rewards,
            values_t,
            next_values,
            terminal.float(),
            (terminal | truncated).float(),
            args.gamma,
            args.gae_lambda,
        )
        returns = advantages + values_t
        scale.update(returns)
        # ---- update
        used = t_steps * n
        flat = (
            mask_t.reshape(-1, N_MOVES),
            actions_t.reshape(-1, len(nvec)),
            logp_t.reshape(-1),
            advantages.reshape(-1),
            returns.reshape(-1),
            labels_t.reshape(-1, len(nvec)),
        )
        stats = {
            "loss/policy": [],
            "loss/value": [],
            "loss/entropy": [],
            "loss/approx_kl": [],
            "loss/clip_fraction": [],
            "loss/distill": [],
        }
        for mb, modules in minibatches(args, t_steps, n):
            m, act, old_logp, adv, ret, labels = (v[mb].to(device) for v in flat)
            adv = (adv - adv.mean()) / (adv.std() + 1e-8)
            if modules is None:
                logits, values, _ = net(obs_t.reshape(-1, worlds.size)[mb].to(device))
            else:  # whole sequences of these modules, from their state at the rollout's start
                logits, values = net.unroll(
                    obs_t[:, modules].to(device), first_state[modules], (terminal | truncated)[:, modules].to(device)
                )
                logits, values = logits.reshape(len(mb), -1), values.reshape(-1)
            log_probs = masked_log_probs(logits, m, nvec)
            drawn = sampled_fields(log_probs, args.sampled)
            ratio = torch.exp(joint_log_prob(drawn, act) - old_logp)
            policy_loss = -torch.min(ratio * adv, ratio.clamp(1 - args.clip_range, 1 + args.clip_range) * adv).mean()
            value_loss = 0.5 * (values - scale.target(ret)).pow(2).mean()
            ent = entropy(drawn).mean()
            loss = policy_loss + args.vf_coef * value_loss - ent_coef * ent
            if distill > 0:
                distill_loss = teacher_cross_entropy(log_probs, labels, m)
                loss = loss + distill * distill_loss
                stats["loss/distill"].append(distill_loss.item())
            optimiser.zero_grad(set_to_none=True)
            loss.backward()
            if args.arch == "shared":
                nn.utils.clip_grad_norm_(net.parameters(), args.max_grad_norm)
            else:
                nn.utils.clip_grad_norm_(net.actor.parameters(), args.max_grad_norm)
                nn.utils.clip_grad_norm_(net.critic.parameters(), args.max_grad_norm)
            optimiser.step()
            with torch.no_grad():
                stats["loss/policy"].append(policy_loss.item())
                stats["loss/value"].append(value_loss.item())
                stats["loss/entropy"].append(ent.item())
                stats["loss/approx_kl"].append(((ratio - 1) - torch.log(ratio)).mean().item())
                stats["loss/clip_fraction"].append(((ratio - 1).abs() > args.clip_range).float().mean().item())
        updated = time.perf_counter()
        agent_steps += used
        bar.update(used)
        env_time, enc_time = worlds.env_seconds - env_s, worlds.encode_seconds - enc_s
        seconds = updated - started
        v, r = values_t.reshape(-1), returns.reshape(-1)
        log.log(
            agent_steps,
            {
                **episode_stats(finished),
                **{k: float(np.mean(x)) for k, x in stats.items() if x},
                "loss/distill_weight": distill,
                **({"loss/learning_rate": learning_rate} if args.learning_rate_final is not None else {}),
                **({"loss/ent_coef": ent_coef} if args.ent_coef_final is not None else {}),
                **({"curriculum/stage": curriculum.stage} if curriculum else {}),
                "loss/explained_variance": float(1 - (r - v).var() / (r.var() + 1e-8)),
                "time/env_seconds": env_time,
                "time/encode_seconds": enc_time,
                "time/forward_seconds": collected - started - env_time - enc_time,
                "time/update_seconds": updated - collected,
                "throughput/agent_steps_per_s": used / seconds,
            },
        )
        if curriculum is not None and curriculum.record(finished):  # the next stage's worlds replace these
            worlds = TrainingEnvs(stage_args(), env_seed=training_worlds_seed(args.seed, agent_steps))
            a, teachers = worlds.n_agents, make_teachers()
            n, features, move_mask, obs_t, mask_t, actions_t, labels_t, logp_t, values_t, bootstrap_t, joined_t = (
                allocate()
            )
            state = net.initial_state(n)
        finished = []
        if agent_steps >= next_checkpoint:
            save(checkpoint_folder(run_dir, agent_steps))
            next_checkpoint = (agent_steps // args.checkpoint_every + 1) * args.checkpoint_every
    bar.close()
    save(run_dir / "final")
    log.close()
    print(f"final checkpoint: {run_dir / 'final'}  ({agent_steps} agent-steps, {log.seconds:.0f} s)")
    return run_dir / "final"


if __name__ == "__main__":
    from training.common import run_script

    raise SystemExit(run_script(main))

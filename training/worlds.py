"""The training worlds of :mod:`training.ppo` and :mod:`training.imitate`: ``n_envs`` worlds of one
task as one :class:`~proteo_env.batched.BatchedEnv`, each restarted as soon as its episode ends,
with every module's observation encoded into one row of features."""

from __future__ import annotations

import time

import numpy as np

import proteo_env
from proteo_env.adapters.flatten import ObservationEncoder
from proteo_env.config import ConfigError
from proteo_env.spaces import ObservationBuffers
from training.policies import check_memory, with_memory

JOIN_FROM = ("SLEEP", "SEARCH")
"""The modes of a module not yet in the structure, by default (module credit, :class:`TrainingEnvs`)."""


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
    """``n_envs`` worlds of ``task`` at control level ``control``, each restarted as soon as its episode ends.

    Sample ``w * A + i`` is module ``i`` of world ``w``. World ``w`` is seeded with child ``w`` of
    ``SeedSequence(env_seed)`` (:func:`proteo_env.config.world_seeds`; ``env_seed`` an integer or
    a seed sequence), so no two worlds of a run, or of runs with other seeds, share a stream; its
    later episodes continue its own generator (:meth:`~proteo_env.batched.BatchedEnv.reset_worlds`).

    Args:
        task, control, env: the task, its control level and the overrides of ``proteo_env.make_batched``.
        n_envs: worlds stepped together.
        env_seed: the seed of the worlds.
        message_encoding: how the features encode the messages received (proteo_env.adapters.flatten).
        memory: the inputs appended to the features (:data:`training.policies.MEMORIES`).
        join_bonus: when above zero, :attr:`joined` marks the modules whose mode left ``join_from``.
        join_from: the names of the modes of a module not yet in the structure.
    """

    def __init__(
        self,
        task: str,
        control: str,
        env: dict,
        n_envs: int,
        env_seed,
        *,
        message_encoding: str = "compact",
        memory: str = "none",
        join_bonus: float = 0.0,
        join_from: tuple[str, ...] = JOIN_FROM,
    ):
        self.batch = proteo_env.make_batched(task, n_envs, control=control, **dict(env))
        """The worlds, one BatchedEnv."""
        self.task_id = self.batch.task.task_id()
        self.n_envs, self.n_agents = n_envs, self.batch.n_agents
        self.nvec = self.batch.control_nvec
        self.encoder = ObservationEncoder(
            n_sites=self.batch.n_sites,
            n_channels=self.batch.task.n_channels,
            n_modes=len(self.batch.task.modes),
            n_message_values=self.batch.task.n_message_values,
            scent_max=self.batch.config.physics.scent_max,
            message_encoding=message_encoding,
        )
        self.memory = memory
        self.size = self.encoder.size + check_memory(memory, self.nvec)
        """Features per sample: the encoding, then the memory's inputs."""
        self.previous_actions = np.zeros((n_envs * self.n_agents, len(self.nvec)), dtype=np.int64)
        """``(N, F)``: each module's action in the last cycle (zeros at an episode's start), the memory's source."""
        self.buffers = self.batch.reset(seed=env_seed)
        self.join_bonus = join_bonus
        self.outside = join_modes(self.batch.task, join_from) if join_bonus else np.zeros(0, dtype=np.int64)
        """Mode numbers of a module not yet in the structure (module credit; empty when off)."""
        self.joined = np.zeros(n_envs * self.n_agents, dtype=bool)
        """``(N,)``: which modules joined the structure in the last :meth:`step` (module credit only)."""
        self.episode_return = np.zeros(n_envs)
        self.final_rows = np.zeros(0, dtype=np.int64)
        """Sample rows of the worlds truncated in the last :meth:`step` (their episodes hit ``max_cycles``)."""
        self.final_features = np.zeros((0, self.size), dtype=np.float32)
        """``(len(final_rows), D)`` features of those rows' last observation (the value there is bootstrapped)."""
        self.env_seconds = 0.0
        self.encode_seconds = 0.0

    @classmethod
    def for_run(cls, args, env: dict, agent_steps: int = 0) -> TrainingEnvs:
        """The worlds of a run with arguments ``args`` (task, control, n_envs, seed, message_encoding,
        memory, and join_bonus and join_from where it has them) and env overrides ``env``, built after
        ``agent_steps`` (seeded by :func:`training_worlds_seed`)."""
        return cls(
            args.task,
            args.control,
            env,
            args.n_envs,
            training_worlds_seed(args.seed, agent_steps),
            message_encoding=args.message_encoding,
            memory=args.memory,
            join_bonus=getattr(args, "join_bonus", 0.0),
            join_from=getattr(args, "join_from", JOIN_FROM),
        )

    def encode(self, features: np.ndarray, move_mask: np.ndarray) -> None:
        """Write every module's features ``(N, size)`` (with the memory's inputs) and legal moves
        ``(N, 13)`` into the given arrays."""
        started = time.perf_counter()
        fields = {name: getattr(self.buffers, name) for name in ObservationBuffers.FIELDS}
        features[:] = with_memory(self.encoder.encode_fields(fields), self.previous_actions, self.memory, self.nvec)
        move_mask[:] = fields["action_mask"]
        self.encode_seconds += time.perf_counter() - started

    def own_modes(self) -> np.ndarray:
        """``(N,)``: every module's own mode in the current observations."""
        return np.asarray(self.buffers.own_mode).reshape(-1).astype(np.int64)

    def step(self, actions: np.ndarray, finished: list[dict]):
        """One cycle of every world from ``(n_envs, A, F)`` actions.

        Returns ``(reward, terminal, truncated)`` per world (``(n_envs,)`` each): ``terminal`` at
        success, ``truncated`` at ``max_cycles`` without success. Ended episodes are appended to
        ``finished`` and their worlds restarted; :attr:`final_rows` and :attr:`final_features`
        hold the truncated worlds' last observation.
        """
        started = time.perf_counter()
        a = self.n_agents
        outside = np.isin(self.own_modes(), self.outside) if self.join_bonus else None
        result = self.batch.step_arrays(actions)
        reward = np.array(result.reward, dtype=np.float64)
        terminal = np.array(result.terminated, dtype=bool)
        truncated = np.array(result.truncated, dtype=bool)
        cycles = np.array(self.batch.cycles, dtype=np.int64)
        ended = terminal | truncated
        self.episode_return += reward
        played = actions.reshape(len(self.previous_actions), -1)
        self.previous_actions = np.where(np.repeat(ended, a)[:, None], 0, played)
        for w in np.flatnonzero(ended):
            finished.append({"r": self.episode_return[w], "success": bool(terminal[w]), "l": int(cycles[w])})
        self.episode_return[ended] = 0.0
        self.buffers = self.batch.observe_arrays()
        if self.join_bonus:
            self.joined = outside & ~np.isin(self.own_modes(), self.outside)
        truncated_worlds = np.flatnonzero(truncated)
        self.final_rows = (np.arange(a) + a * truncated_worlds[:, None]).reshape(-1)
        self.final_features = np.zeros((0, self.size), dtype=np.float32)
        if len(truncated_worlds):
            self.final_features = np.concatenate(
                [
                    with_memory(
                        self.encoder.encode_buffers(self.buffers.rows(w * a, (w + 1) * a)),
                        actions[w],
                        self.memory,
                        self.nvec,
                    )
                    for w in truncated_worlds
                ]
            )
        if ended.any():
            self.buffers = self.batch.reset_worlds(ended)
        self.env_seconds += time.perf_counter() - started
        return reward, terminal, truncated

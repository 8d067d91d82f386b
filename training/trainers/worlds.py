"""The training worlds of :mod:`training.trainers.ppo` and :mod:`training.trainers.imitate`: ``n_envs`` worlds of one
task as one :class:`~proteo_env.batched.BatchedEnv`, each restarted as soon as its episode ends,
with every module's observation encoded into one row of features; or the same worlds split over
worker processes (:class:`WorkerEnvs`), which step, observe and encode their shares at once."""

from __future__ import annotations

import multiprocessing
import time
import traceback
import weakref
from multiprocessing import shared_memory

import numpy as np

import proteo_env
from proteo_env.adapters.flatten import ObservationEncoder
from proteo_env.config import ConfigError, world_seeds
from proteo_env.spaces import ObservationBuffers
from training.machinery.policies import check_memory, with_memory
from training.machinery.runs import limit_threads
from training.trainers.teachers import Teachers, is_checkpoint

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
        env_seed: the seed of the worlds, or one seed per world (world ``w`` is then seeded exactly as
            a single env reset with ``env_seed[w]``: how :class:`WorkerEnvs` gives each worker its
            share of one run's worlds).
        message_encoding: how the features encode the messages received (proteo_env.adapters.flatten).
        memory: the inputs appended to the features (:data:`training.machinery.policies.MEMORIES`).
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
        self.control_fields = self.batch.control_fields
        """The names of the action fields the trainer chooses (the control level's)."""
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
        per_world = isinstance(env_seed, (list, tuple))
        self.buffers = self.batch.reset(**{"world_seeds" if per_world else "seed": env_seed})
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
    def for_run(cls, args, env: dict, agent_steps: int = 0, kept=None) -> TrainingEnvs | WorkerEnvs:
        """The worlds of a run with arguments ``args`` (task, control, n_envs, seed, message_encoding,
        memory, and join_bonus, join_from and workers where it has them) and env overrides ``env``,
        built after ``agent_steps`` (seeded by :func:`training_worlds_seed`); split over
        ``args.workers`` processes (:class:`WorkerEnvs`) when that is above 1.

        ``kept``: the worlds a checkpoint kept (:meth:`shares`, one :class:`TrainingEnvs` per
        process; a checkpoint of before workers kept theirs holds the one), which go on in the
        middle of their episodes instead, each share in a process of its own, where they were
        kept in as many processes as ``args.workers``; otherwise fresh worlds, said on stdout."""
        settings = run_settings(args, env, agent_steps)
        workers = getattr(args, "workers", 1)
        if kept is not None:
            shares = [kept] if isinstance(kept, TrainingEnvs) else list(kept)
            if len(shares) == workers:
                return WorkerEnvs(settings, workers, shares) if workers > 1 else shares[0]
            print(
                f"the worlds were kept in {len(shares)} process(es), the run has {workers}: it goes on from fresh worlds"
            )
        return WorkerEnvs(settings, workers) if workers > 1 else cls(**settings)

    def shares(self) -> list[TrainingEnvs]:
        """The worlds as a checkpoint keeps them: one :class:`TrainingEnvs` per process (here, this one)."""
        return [self]

    def encode(self, features: np.ndarray, move_mask: np.ndarray) -> None:
        """Write every module's features ``(N, size)`` (with the memory's inputs) and legal moves
        ``(N, 13)`` into the given arrays."""
        started = time.perf_counter()
        fields = {name: getattr(self.buffers, name) for name in ObservationBuffers.FIELDS}
        if self.memory == "none":
            self.encoder.encode_fields(fields, out=features)
        else:
            features[:] = with_memory(self.encoder.encode_fields(fields), self.previous_actions, self.memory, self.nvec)
        move_mask[:] = fields["action_mask"]
        self.encode_seconds += time.perf_counter() - started

    def make_teachers(self, name: str, seed: int, n_fields: int, first_world: int = 0):
        """The teachers of these worlds (:class:`training.trainers.teachers.Teachers`, arguments as there)."""
        return Teachers(self.batch, self.n_envs, name, seed=seed, n_fields=n_fields, first_world=first_world)

    def teacher_labels(self, teachers) -> np.ndarray:
        """``(N, n_fields)``: the teachers' action for every module's present observation."""
        return teachers.labels([self.buffers])

    def close(self) -> None:
        """Nothing to release (:meth:`WorkerEnvs.close` stops its workers)."""

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


def run_settings(args, env: dict, agent_steps: int) -> dict:
    """The keyword arguments of :class:`TrainingEnvs` for a run (see :meth:`TrainingEnvs.for_run`)."""
    return {
        "task": args.task,
        "control": args.control,
        "env": dict(env),
        "n_envs": args.n_envs,
        "env_seed": training_worlds_seed(args.seed, agent_steps),
        "message_encoding": args.message_encoding,
        "memory": args.memory,
        "join_bonus": getattr(args, "join_bonus", 0.0),
        "join_from": tuple(getattr(args, "join_from", JOIN_FROM)),
    }


def check_workers(workers: int, n_envs: int, *, teacher: str | None = None, curriculum=None) -> None:
    """Refuse ``workers`` (of :class:`WorkerEnvs`) other than an integer from 1 to ``n_envs``, or above 1 with a checkpoint as
    the ``teacher`` (its draws span every world; ``None``: no teacher) or with a ``curriculum``
    (it rebuilds the worlds in the trainer's process): one :class:`ConfigError` naming both."""
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= n_envs:
        raise ConfigError(f"workers={workers!r} is not allowed with n_envs={n_envs}; allowed: 1 to n_envs")
    learned = teacher if teacher is not None and is_checkpoint(teacher) else None
    for name, value in (("teacher", learned), ("curriculum", curriculum)):
        if workers > 1 and value:
            raise ConfigError(
                f"workers={workers!r} is not allowed with {name}={value!r}; allowed: workers=1 "
                "(a learned teacher draws its labels over every world at once; the curriculum rebuilds "
                "the worlds in this process)"
            )


class WorkerEnvs:
    """The worlds of :class:`TrainingEnvs` split over ``workers`` processes (this one and
    ``workers - 1`` started here), each stepping, observing and encoding its share (consecutive
    worlds) at the same time as the others.

    The same worlds as one process: world ``w`` is seeded with child ``w`` of the run's seed
    whichever process holds it, and the features, masks, rewards and ended episodes come back in
    world order, so a trainer that draws its actions from them in one process makes the same run
    on any number of workers, bit for bit. It offers what :func:`training.trainers.ppo.collect_rollout` reads of
    :class:`TrainingEnvs`: :meth:`encode`, :meth:`step`, ``final_rows``, ``final_features``,
    ``joined``, ``encoder``, ``nvec``, ``size``, ``task_id``, ``n_envs`` and ``n_agents``, and
    the hand-coded rules as teachers (:meth:`make_teachers`: each process teaches its share,
    teacher ``w`` seeded as in one process); not the observation ``buffers`` (most stay in the
    workers), nor a checkpoint as the teacher (its draws span every world).
    ``env_seconds`` counts the wall-clock of each parallel step (the encoding included),
    ``encode_seconds`` the copying of the features. Features, masks, actions and per-world
    results travel in shared memory; a process waiting for the others polls for a moment before
    it sleeps (a sleeping process wakes a fraction of a millisecond late), so give it a core
    each. Call :meth:`close` (or let it be collected) to stop the workers.

    Args:
        settings: :class:`TrainingEnvs`'s keyword arguments for all the worlds (:func:`run_settings`).
        workers: processes, 1 to ``n_envs``.
        kept: ``workers`` :class:`TrainingEnvs` that :meth:`shares` gave (a checkpoint's), each
            process's share in the middle of its episodes, instead of fresh worlds.
    """

    def __init__(self, settings: dict, workers: int, kept: list[TrainingEnvs] | None = None):
        n_envs = settings["n_envs"]
        check_workers(workers, n_envs)
        seeds = world_seeds(settings["env_seed"], n_envs)
        self.ranges = [(int(s[0]), int(s[-1]) + 1) for s in np.array_split(np.arange(n_envs), workers)]
        """``(first, end)`` world of each process, this one's first."""
        shares = [{**settings, "n_envs": end - first, "env_seed": seeds[first:end]} for first, end in self.ranges]
        shares = list(kept) if kept is not None else shares
        self.local = shares[0] if kept is not None else TrainingEnvs(**shares[0])
        """This process's share of the worlds."""
        self.task_id, self.n_agents, self.nvec = self.local.task_id, self.local.n_agents, self.local.nvec
        self.control_fields = self.local.control_fields
        self.encoder, self.size = self.local.encoder, self.local.size
        self.n_envs = n_envs
        layout = (n_envs, self.n_agents, self.size, len(self.nvec))
        self._memory = shared_memory.SharedMemory(create=True, size=_shared_size(*layout))
        self._views = _shared_views(self._memory.buf, *layout)
        context = multiprocessing.get_context("spawn")  # no fork of a process that runs torch's threads
        self._pipes, self._processes = [], []
        for (first, _), share in zip(self.ranges[1:], shares[1:]):
            mine, theirs = context.Pipe()
            process = context.Process(
                target=_serve, args=(theirs, share, self._memory.name, layout, first), daemon=True
            )
            process.start()
            self._pipes.append(mine)
            self._processes.append(process)
        self._finalizer = weakref.finalize(self, _stop, self._pipes, self._processes, self._memory)
        _encode_share(self.local, self._views, 0)
        self._gather()
        self.joined = np.zeros(n_envs * self.n_agents, dtype=bool)
        self.final_rows = np.zeros(0, dtype=np.int64)
        self.final_features = np.zeros((0, self.size), dtype=np.float32)
        self.env_seconds = 0.0
        self.encode_seconds = 0.0

    def make_teachers(self, name: str, seed: int, n_fields: int) -> WorkerTeachers:
        """The rules as teachers of every world, each process teaching its own share
        (:class:`training.trainers.teachers.Teachers` with its first world; arguments as there)."""
        check_workers(len(self.ranges), self.n_envs, teacher=name)
        self._teacher_fields = n_fields
        self._command(("teachers", (name, seed, n_fields)))
        self._local_teachers = self.local.make_teachers(name, seed, n_fields)
        self._gather()
        return WorkerTeachers(self.n_envs)

    def teacher_labels(self, teachers: WorkerTeachers) -> np.ndarray:
        """``(N, n_fields)``: the teachers' action for every module's present observation, each
        process's teachers first restarted for the episodes that ended since the last labels."""
        restart, teachers.ended = teachers.ended, np.zeros(self.n_envs, dtype=bool)
        self._command(("label", restart))
        _label_share(self.local, self._local_teachers, self._views, 0, restart)
        self._gather()
        return self._views["labels"][:, : self._teacher_fields].copy()

    def _command(self, command: tuple) -> None:
        for pipe in self._pipes:
            pipe.send(command)

    def encode(self, features: np.ndarray, move_mask: np.ndarray) -> None:
        """Write every module's features ``(N, size)`` and legal moves ``(N, 13)`` (encoded by
        each process after the last step) into the given arrays."""
        started = time.perf_counter()
        features[:] = self._views["features"]
        move_mask[:] = self._views["mask"]
        self.encode_seconds += time.perf_counter() - started

    def step(self, actions: np.ndarray, finished: list[dict]):
        """One cycle of every world from ``(n_envs, A, F)`` actions, as :meth:`TrainingEnvs.step`."""
        started = time.perf_counter()
        self._views["actions"][:] = actions
        self._command(("step", None))
        answers = [_step_share(self.local, self._views, 0), *self._gather()]
        rows, features = [], []
        for (first, _), (ended, final_rows, final_features) in zip(self.ranges, answers):
            finished.extend(ended)
            rows.append(final_rows + first * self.n_agents)
            features.append(final_features)
        self.final_rows, self.final_features = np.concatenate(rows), np.concatenate(features)
        views = self._views
        self.joined = views["joined"].copy()
        self.env_seconds += time.perf_counter() - started
        return views["reward"].copy(), views["terminal"].copy(), views["truncated"].copy()

    def shares(self) -> list[TrainingEnvs]:
        """The worlds as a checkpoint keeps them: each process's :class:`TrainingEnvs`, in order."""
        self._command(("share", None))
        return [self.local, *self._gather()]

    def _gather(self) -> list:
        """Every worker's answer, in order; a worker's error is raised here with its traceback."""
        answers = []
        for pipe, process in zip(self._pipes, self._processes):
            try:
                _wait(pipe)
                kind, answer = pipe.recv()
            except EOFError:
                self.close()
                raise RuntimeError(f"a worker of the training worlds died (exit code {process.exitcode})") from None
            if kind == "error":
                self.close()
                if isinstance(answer, ConfigError):
                    raise answer
                raise RuntimeError(f"a worker of the training worlds failed:\n{answer}")
            answers.append(answer)
        return answers

    def close(self) -> None:
        """Stop the workers and free the shared memory (again: nothing)."""
        self._finalizer()


class WorkerTeachers:
    """The teachers of a :class:`WorkerEnvs` as the trainer holds them: :meth:`restart` notes the
    worlds whose episodes ended, and the next :meth:`WorkerEnvs.teacher_labels` restarts their
    teachers in their processes before it labels (as :meth:`training.trainers.teachers.Teachers.restart`
    would have, in between)."""

    def __init__(self, n_envs: int):
        self.ended = np.zeros(n_envs, dtype=bool)

    def restart(self, worlds) -> None:
        """New episodes for the teachers of ``worlds`` (``(n_envs,)`` bool), at the next labels."""
        self.ended |= np.asarray(worlds, dtype=bool)


POLL_SECONDS = 0.002
"""How long a process of :class:`WorkerEnvs` polls for the others' message before it sleeps."""


def _wait(pipe) -> None:
    """Return when ``pipe`` has a message: poll for :data:`POLL_SECONDS`, then sleep until one comes."""
    deadline = time.perf_counter() + POLL_SECONDS
    while not pipe.poll():
        if time.perf_counter() > deadline:
            pipe.poll(None)
            return


def _shared_fields(n_envs: int, n_agents: int, size: int, n_fields: int) -> list[tuple[str, tuple, type]]:
    n = n_envs * n_agents
    return [
        ("features", (n, size), np.float32),
        ("mask", (n, 13), np.bool_),
        ("actions", (n_envs, n_agents, n_fields), np.int64),
        ("reward", (n_envs,), np.float64),
        ("terminal", (n_envs,), np.bool_),
        ("truncated", (n_envs,), np.bool_),
        ("joined", (n,), np.bool_),
        ("labels", (n, n_fields), np.int64),
    ]


def _aligned(nbytes: int) -> int:
    return -(-nbytes // 64) * 64


def _shared_size(*layout: int) -> int:
    return sum(_aligned(int(np.prod(shape)) * np.dtype(dtype).itemsize) for _, shape, dtype in _shared_fields(*layout))


def _shared_views(buffer, *layout: int) -> dict[str, np.ndarray]:
    """The arrays :class:`WorkerEnvs` shares with its workers, one after another in ``buffer``;
    ``layout``: worlds, modules per world, features per module, action fields."""
    views, offset = {}, 0
    for name, shape, dtype in _shared_fields(*layout):
        views[name] = np.ndarray(shape, dtype=dtype, buffer=buffer, offset=offset)
        offset += _aligned(int(np.prod(shape)) * np.dtype(dtype).itemsize)
    return views


def _encode_share(worlds: TrainingEnvs, views: dict, first: int) -> None:
    """Encode the share of ``worlds`` (its first world is world ``first``) into the shared features."""
    rows = slice(first * worlds.n_agents, (first + worlds.n_envs) * worlds.n_agents)
    worlds.encode(views["features"][rows], views["mask"][rows])


def _step_share(worlds: TrainingEnvs, views: dict, first: int) -> tuple:
    """Step the share of ``worlds`` with its shared actions, write its results and features, and
    return what does not fit the shared arrays: ``(ended episodes, final_rows, final_features)``."""
    end = first + worlds.n_envs
    ended = []
    reward, terminal, truncated = worlds.step(views["actions"][first:end], ended)
    for name, value in (("reward", reward), ("terminal", terminal), ("truncated", truncated)):
        views[name][first:end] = value
    views["joined"][first * worlds.n_agents : end * worlds.n_agents] = worlds.joined
    _encode_share(worlds, views, first)
    return ended, worlds.final_rows, worlds.final_features


def _label_share(worlds: TrainingEnvs, teachers, views: dict, first: int, restart: np.ndarray) -> None:
    """Restart the share's ``teachers`` of the worlds ``restart`` (``(n_envs,)`` of all worlds)
    marks, then write their labels of the share's present observation into the shared labels."""
    end = first + worlds.n_envs
    teachers.restart(restart[first:end])
    labels = worlds.teacher_labels(teachers)
    views["labels"][first * worlds.n_agents : end * worlds.n_agents, : labels.shape[1]] = labels


def _serve(pipe, share, memory_name: str, layout: tuple, first: int) -> None:
    """A worker of :class:`WorkerEnvs`: the worlds ``first ..``, built from ``share`` (the keyword
    arguments of :class:`TrainingEnvs`) or ``share`` itself (kept worlds); on each command
    ``("step", None)``, ``("teachers", (name, seed, n_fields))``, ``("label", restart)`` or
    ``("share", None)`` (the worlds themselves, pickled through the pipe) it answers ``("ok", ...)``
    or ``("error", ...)``, until ``("close", None)``."""
    limit_threads(1)
    memory = None
    try:
        worlds = share if isinstance(share, TrainingEnvs) else TrainingEnvs(**share)
        memory = shared_memory.SharedMemory(name=memory_name)
        views = _shared_views(memory.buf, *layout)
        _encode_share(worlds, views, first)
        pipe.send(("ok", None))
        while True:
            _wait(pipe)
            command, arguments = pipe.recv()
            if command == "step":
                pipe.send(("ok", _step_share(worlds, views, first)))
            elif command == "teachers":
                name, seed, n_fields = arguments
                teachers = worlds.make_teachers(name, seed, n_fields, first_world=first)
                pipe.send(("ok", None))
            elif command == "label":
                _label_share(worlds, teachers, views, first, arguments)
                pipe.send(("ok", None))
            elif command == "share":
                pipe.send(("ok", worlds))
            else:
                break
    except ConfigError as error:
        pipe.send(("error", error))
    except Exception:  # noqa: BLE001 - the trainer raises it with this traceback
        pipe.send(("error", traceback.format_exc()))
    finally:
        views = None
        if memory is not None:
            memory.close()


def _stop(pipes, processes, memory) -> None:
    for pipe in pipes:
        try:
            pipe.send(("close", None))
        except (BrokenPipeError, OSError):
            pass
    for process in processes:
        process.join(timeout=10)
        if process.is_alive():
            process.terminate()
    try:
        memory.close()
    except BufferError:  # views of it are still alive here; the mapping goes with the process
        pass
    memory.unlink()

"""Many episodes at the engine's speed: every (controller, world) episode of a list in batches of worlds.

:func:`run_episodes` takes :class:`Episode` records (task, settings, control level, a
:class:`Controller`, a world seed) and returns one :class:`~proteo_env.rollout.EpisodeResult`
per record (``history`` left empty): the same cycles, success, return and final metrics, bit for
bit, as :func:`~proteo_env.rollout.run_episode` gives for that controller on that seed
(``tests/test_evaluator.py`` holds the two to each other on every task).

How: the episodes of one task, settings and level run as rows of one batched environment
(:func:`proteo_env.make_batched`, ``batch_size`` worlds); a row whose episode ends starts the
next episode of the queue on its own seed (:meth:`~proteo_env.batched.BatchedEnv.reset_worlds`),
so the batch stays full. Each cycle the controllers of every row act together:

- kernel policies (the hand-coded rules with any parameters, programs) in one kernel call over
  every world, each world with its own rule parameters (:class:`~baselines.base.PolicyBatch`);
- a network checkpoint without memory in one forward pass over every agent of every world, then
  each world's actions drawn from its own episode's generator (the forward pass over ``B * A``
  rows can differ from one over ``A`` rows in the last bits of a logit, and so, rarely, in a
  sampled action: ``docs/guides/evaluator.md`` gives the agreement measured);
- anything else (random, networks with memory) world by world, with the policy's own ``act``.

A long episode (:data:`LONG_EPISODE_MODULE_CYCLES`: a scale split's) is a batch of its own. The
batches are spread over ``workers`` processes (default: every core), or over a Ray cluster
(``ray``); each episode depends only on its own record, so the results do not depend on the
number of workers, the batch size or the order of the records.

Example::

    from training.machinery.evaluator import Controller, evaluate

    programs = [Controller.program(text) for text in texts]
    results = evaluate("chain-v1", programs, seeds=range(100), env={"n_modules": 12})
    successes = [[r.success for r in row] for row in results]  # one row per controller
"""

from __future__ import annotations

import copy
import functools
import hashlib
import importlib
import importlib.util
import json
import math
import os
import sys
from dataclasses import dataclass

import numpy as np

import proteo_env
from baselines import POLICIES, make_policy
from baselines.base import KernelPolicy
from proteo_env import TASKS, batched
from proteo_env.config import ConfigError
from proteo_env.core.world import gib, machine_memory, world_bytes
from proteo_env.rollout import EpisodeResult
from training.machinery.checkpoints import load_policy
from training.machinery.distributed import run_jobs
from training.machinery.entrants import EntrantPolicy, entrant_policy
from training.machinery.policies import N_MOVES, LogitsPolicy, sample_actions
from training.machinery.runs import limit_threads

DEFAULT_BATCH = 64
"""Worlds stepped together in one process (``tests`` and ``benchmarks/research_loop.py``
measure the choice)."""


@dataclass(frozen=True)
class Controller:
    """What acts in an episode (picklable; the same record on every worker).

    Attributes:
        policy: a registered policy name (``"chain"``, ``"program"``, ``"random"``...) or, with
            ``checkpoint``, a checkpoint's path.
        params: the policy's keyword parameters as ``(name, value)`` pairs (a program's text as
            ``("program", text)``; evolved rule parameters).
        checkpoint: ``policy`` is a checkpoint (:func:`training.machinery.checkpoints.load_policy`).
        deterministic: a network checkpoint takes each field's arg-max.
        entrant: ``policy`` is an entrant from outside: an ``entrant.yaml`` or a factory
            ``module:function`` (:mod:`training.machinery.entrants`); ``params`` holds its
            ``training_seed``.
    """

    policy: str
    params: tuple = ()
    checkpoint: bool = False
    deterministic: bool = False
    entrant: bool = False

    @classmethod
    def rules(cls, name: str, **params) -> Controller:
        """A registered policy (a task's hand-coded rules, ``random``) with keyword parameters."""
        return cls(name, tuple(sorted(params.items())))

    @classmethod
    def program(cls, text: str) -> Controller:
        """A program of the paper's primitives (:mod:`baselines.program`), by its text, name or path."""
        return cls("program", (("program", text),))

    @classmethod
    def from_checkpoint(cls, path, *, deterministic: bool = False) -> Controller:
        return cls(str(path), checkpoint=True, deterministic=deterministic)

    @classmethod
    def from_entrant(cls, source, *, training_seed: int | None = None) -> Controller:
        """An entrant (an ``entrant.yaml``, its folder, or a factory ``module:function``), with the
        file of ``training_seed`` where its ``entrant.yaml`` names one per training seed."""
        return cls(str(source), (("training_seed", training_seed),), entrant=True)

    def build(self, env, seed: int, settings: dict | None = None):
        """This controller's policy for ``env`` (an env of the episode's task, ``settings`` and level), reset with ``seed``."""
        if self.entrant:
            policy = entrant_policy(self.policy, env, seed=seed, settings=settings, **dict(self.params))
        elif self.checkpoint:
            policy = load_policy(self.policy, env, seed=seed, deterministic=self.deterministic)
        else:
            policy = make_policy(self.policy, env, seed=seed, **dict(self.params))
        policy.reset(seed)
        return policy

    def fresh(self, env, key, seed: int):
        """:meth:`build`, from a policy built once per process and ``key`` (the env's settings) and
        copied: a program is parsed and a checkpoint read once, not once per episode."""
        if (key, self) not in _BUILT:
            _BUILT[(key, self)] = self.build(env, 0, json.loads(key[1]))
        prototype = _BUILT[(key, self)]
        # a network or an entrant is shared, not copied (its reset makes the generator and memory its own; an
        # entrant's object is told each world's seed by the batch, _Actors)
        shared = isinstance(prototype, LogitsPolicy) or self.entrant
        policy = copy.copy(prototype) if shared else copy.deepcopy(prototype)
        policy.reset(seed)
        return policy


@dataclass(frozen=True)
class Episode:
    """One episode: everything its result depends on.

    Attributes:
        task: a registered task id.
        overrides: the JSON of the :func:`proteo_env.make` settings (sorted keys).
        level: the control level (``full``, ``move+mode``, ``move``).
        controller: what acts.
        seed: the world seed; the controller's policy is reset with it too, as
            :func:`~proteo_env.rollout.run_episode` does.
    """

    task: str
    overrides: str
    level: str
    controller: Controller
    seed: int


def settings_json(overrides: dict) -> str:
    """The canonical JSON of env overrides (the :attr:`Episode.overrides` form)."""
    return json.dumps(dict(overrides), sort_keys=True)


# ---------------------------------------------------------------------- checking
_CHECKED: dict = {}
"""A single env per (task, settings, level), built once per process."""
_BUILT: dict = {}
"""A policy per ((task, settings, level), controller), built once per process (:meth:`Controller.fresh`)."""


def _template(task: str, overrides: str, level: str):
    """A single env of these settings (cached per process), for building policies and checking them."""
    key = (task, overrides, level)
    if key not in _CHECKED:
        _CHECKED[key] = proteo_env.make(
            task, **json.loads(overrides), **({} if level == "full" else {"control": level})
        )
    return _CHECKED[key]


def check_episodes(episodes, *, workers=None, batch_size: int = DEFAULT_BATCH) -> None:
    """Refuse what cannot run, before any episode runs: one ``ConfigError`` (or the controller's own
    ``ValueError``/``CheckpointError``) naming the field, the value and what is allowed."""
    episodes = list(episodes) if not isinstance(episodes, list) else episodes
    if not episodes:
        raise ConfigError("episodes=[] is not allowed; allowed: at least one (controller, world) episode")
    for name, value in (("workers", workers), ("batch_size", batch_size)):
        if value is None and name == "workers":
            continue
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ConfigError(f"{name}={value!r} is not allowed; allowed: an integer >= 1")

    built = set()
    for i, e in enumerate(episodes):
        if isinstance(e.seed, bool) or not isinstance(e.seed, (int, np.integer)) or e.seed < 0:
            raise ConfigError(f"episodes[{i}].seed={e.seed!r} is not allowed; allowed: an integer >= 0 (a world seed)")
        if not isinstance(e.controller, Controller):
            raise ConfigError(f"episodes[{i}].controller={e.controller!r} is not allowed; allowed: a Controller")
        key = (e.task, e.overrides, e.level, e.controller)
        if key in built:
            continue
        env = _template(e.task, e.overrides, e.level)
        policy = e.controller.fresh(env, key[:3], 0)
        # (a checkpoint is checked against the env when it loads)
        if not e.controller.checkpoint and isinstance(policy, KernelPolicy) and not policy.runs_on(env.task):
            raise ConfigError(
                f"episodes[{i}].controller={e.controller.policy!r} is not allowed on task {e.task!r}; "
                f"allowed: a controller written for {env.task.name!r} (its rules, a program for it, random, "
                "a checkpoint of it)"
            )
        built.add(key)


# ---------------------------------------------------------------------- one batch
def batch_kind(policy) -> str:
    """How ``policy`` acts in a batch: ``kernel:<class>`` (its rule kernel, over every world in
    one call), ``network`` (a network without memory: one forward pass per network and cycle),
    ``entrant:<label>`` (an entrant's object, once a cycle over every world) or ``alone`` (its own
    ``act``, world by world). Policies of one kind share a batch."""
    if isinstance(policy, EntrantPolicy):
        return f"entrant:{policy.label}"
    if isinstance(policy, KernelPolicy):
        return f"kernel:{type(policy).__qualname__}"
    if isinstance(policy, LogitsPolicy) and policy.memory == "none":
        return "network"
    return "alone"


_KERNEL_WORLD_CYCLES: dict = {}
"""World-cycles this process has run with each kernel policy class world by world."""


class _Actors:
    """The policies of a batch's rows acting together (see :func:`batch_kind`).

    Kernel policies act world by world (each policy's own cached kernel) until this process has
    run :data:`proteo_env.batched.ONE_CALL_AFTER` world-cycles with their class, then in one
    call over every world (:class:`~baselines.base.PolicyBatch`, the same actions, draw for
    draw): the one call compiles once per process and class (seconds), which only longer
    evaluations win back."""

    def __init__(self, policies: list, n_agents: int):
        self.policies, self.n_agents = policies, n_agents
        kinds = {batch_kind(p) for p in policies}
        self.kind = kinds.pop() if len(kinds) == 1 else "alone"
        self.kernels = None
        if self.kind.startswith("entrant:"):
            for b, p in enumerate(policies):
                p.entrant.reset(b, p.seed)

    def replace(self, b: int, policy) -> None:
        self.policies[b] = policy
        if self.kernels is not None:
            self.kernels.replace(b, policy)
        if self.kind.startswith("entrant:"):
            policy.entrant.reset(b, policy.seed)

    def act(self, buffers, cycles, playing) -> np.ndarray:
        """``(B * A, F)`` actions of every row's agents (``cycles``: each row's cycle; ``playing``:
        ``(B,)`` bool, False for a row whose last episode has ended: its actions are legal but no
        network's choice)."""
        a = self.n_agents
        if self.kind.startswith("entrant:"):
            rows = len(self.policies)
            fields = {f: getattr(buffers, f).reshape(rows, a, *getattr(buffers, f).shape[1:]) for f in buffers.FIELDS}
            seeds = [p.seed for p in self.policies]
            return self.policies[0].act_batch(fields, seeds, list(cycles)).reshape(rows * a, -1)
        if self.kind.startswith("kernel:"):
            if self.kernels is None and _KERNEL_WORLD_CYCLES.get(self.kind, 0) >= batched.ONE_CALL_AFTER:
                self.kernels = type(self.policies[0]).batch(self.policies)
            if self.kernels is not None:
                return self.kernels.act_arrays(buffers)
            _KERNEL_WORLD_CYCLES[self.kind] = _KERNEL_WORLD_CYCLES.get(self.kind, 0) + len(self.policies)
            return np.concatenate([p.act_arrays(buffers.rows(b * a, (b + 1) * a)) for b, p in enumerate(self.policies)])
        if self.kind == "network":
            return self._sample(buffers, playing)
        names = [f"module_{i}" for i in range(a)]
        out = []
        for b, p in enumerate(self.policies):
            actions = p.act(buffers.rows(b * a, (b + 1) * a).per_agent(names))
            out.append(np.stack([np.asarray(actions[name]).reshape(-1) for name in names]))
        return np.concatenate(out)

    def _sample(self, buffers, playing) -> np.ndarray:
        """Each network's forward pass over the rows of the worlds it plays, then every world's
        actions drawn with its own generator (Gumbel-max, as :func:`~training.machinery.policies.sample_actions`
        draws them for one world).

        When the move is the only field (control level ``move``), a row with one legal move takes
        it whatever its logits, so the networks see only the rows with a choice (many modules have
        none: four in five over a 120-module chain's episode, a third in the first 1,500 cycles at
        1,200 modules). The draws are made for every row as before, and a network's rows do not
        depend on which others it sees (one thread), so every episode is the same, draw for draw.
        Nor do the rows of a world whose last episode has ended (it waits for the batch's slowest)."""
        a, first = self.n_agents, self.policies[0]
        features = first.encoder.encode_buffers(buffers)
        networks: dict = {}
        for b, p in enumerate(self.policies):
            networks.setdefault(id(p.logits_fn), (p.logits_fn, []))[1].append(b)
        mask = np.asarray(buffers.action_mask, dtype=bool)
        choosing = mask.sum(axis=1) > 1 if len(first.nvec) == 1 else np.ones(len(features), dtype=bool)
        choosing &= np.repeat(playing, a)
        logits = np.zeros((len(features), int(np.sum(first.nvec))), dtype=np.float32)
        for logits_fn, worlds in networks.values():
            rows = (np.asarray(worlds)[:, None] * a + np.arange(a)).reshape(-1)
            rows = rows[choosing[rows]]
            if len(rows):
                logits[rows] = logits_fn(features[rows])
        noise = np.zeros(logits.shape)
        for b, p in enumerate(self.policies):
            if not p.deterministic:
                noise[b * a : (b + 1) * a] = p.rng.gumbel(size=(a, logits.shape[1]))
                if p.sampled == "move":
                    noise[b * a : (b + 1) * a, N_MOVES:] = 0.0
        return sample_actions(logits, first.nvec, buffers.action_mask, None, noise=noise)


def run_batch(episodes: list[Episode], batch_size: int = DEFAULT_BATCH) -> list[dict]:
    """Every episode of ``episodes`` (one task, settings and level; controllers of one :func:`batch_kind`) in one
    batched env of up to ``batch_size`` worlds: ``{"return", "success", "cycles", "metrics"}`` each
    (JSON-ready), in order."""
    limit_threads(1)
    first = episodes[0]
    env = _template(first.task, first.overrides, first.level)
    rows = min(batch_size, len(episodes))
    control = {} if first.level == "full" else {"control": first.level}
    batch = proteo_env.make_batched(first.task, rows, **json.loads(first.overrides), **control)
    a = batch.n_agents
    buffers = batch.reset(world_seeds=[e.seed for e in episodes[:rows]])
    key = (first.task, first.overrides, first.level)
    actors = _Actors([e.controller.fresh(env, key, e.seed) for e in episodes[:rows]], a)
    playing = list(range(rows))
    """The episode each row plays (-1: none left)."""
    returns = np.zeros(rows)
    out: list = [None] * len(episodes)
    following = rows
    while any(i >= 0 for i in playing):
        actions = actors.act(buffers, batch.cycles, np.asarray(playing) >= 0)
        result = batch.step_arrays(actions.reshape(rows, a, -1))
        returns += result.reward
        ended = np.flatnonzero(result.terminated | result.truncated)
        restart, seeds = [], []
        for b in ended.tolist():
            i = playing[b]
            if i < 0:
                continue
            metrics = batch.tasks[b].metrics(batch.worlds[b])
            out[i] = {
                "return": float(returns[b]),
                "success": bool(result.terminated[b]),
                "cycles": int(batch.cycles[b]),
                "metrics": {k: float(v) for k, v in metrics.items()},
            }
            returns[b] = 0.0
            if following < len(episodes):
                e = episodes[following]
                playing[b] = following
                following += 1
                actors.replace(b, e.controller.fresh(env, key, e.seed))
                restart.append(b)
                seeds.append(e.seed)
            else:
                playing[b] = -1
        if restart:
            buffers = batch.reset_worlds(np.array(restart, dtype=np.int64), world_seeds=seeds)
        else:
            buffers = batch.observe_arrays()
    return out


def _run_chunk(chunk: tuple) -> list[dict]:
    """A worker's job: ``(episodes, batch_size, plugins)`` run as one batch, after importing the
    modules that registered tasks or policies from outside the project (:func:`plugin_modules`)."""
    episodes, batch_size, plugins = chunk
    import_plugins(plugins)
    return run_batch(list(episodes), batch_size)


PROJECT_PACKAGES = ("proteo_env", "baselines", "training")


def plugin_modules() -> tuple[tuple[str, str], ...]:
    """``(module name, file)`` of every module outside the project that registered a task or a
    policy in this process (a behaviour of one's own, ``docs/guides/adding_a_behaviour.md``):
    a worker process imports them before it runs a batch, so that it knows them too."""
    out = set()
    for cls in [*TASKS.values(), *POLICIES.values()]:
        module = sys.modules.get(cls.__module__)
        if cls.__module__.split(".")[0] not in PROJECT_PACKAGES and getattr(module, "__file__", None):
            out.add((cls.__module__, module.__file__))
    return tuple(sorted(out))


def import_plugins(plugins) -> None:
    """Import each ``(name, file)`` of :func:`plugin_modules` not imported yet: by name where this
    process can, else from its file."""
    for name, file in plugins:
        if name in sys.modules:
            continue
        try:
            importlib.import_module(name)
        except ImportError:
            spec = importlib.util.spec_from_file_location(name, file)
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            spec.loader.exec_module(module)


# ---------------------------------------------------------------------- many batches
WORKERS_VARIABLE = "PROTEO_WORKERS"
"""An environment variable that sets the default number of worker processes (a test runner that
runs tests in parallel already sets it to 1)."""


def default_workers() -> int:
    """``$PROTEO_WORKERS`` when set (an integer >= 1), else every core this process may use."""
    value = os.environ.get(WORKERS_VARIABLE)
    if value is not None:
        if not value.isdigit() or int(value) < 1:
            raise ConfigError(f"{WORKERS_VARIABLE}={value!r} is not allowed; allowed: an integer >= 1")
        return int(value)
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def run_episodes(
    episodes,
    *,
    workers: int | None = None,
    batch_size: int = DEFAULT_BATCH,
    ray: dict | None = None,
    journal=None,
    keys=None,
    desc: str = "episodes",
    progress: bool = False,
) -> list[EpisodeResult]:
    """The result of every episode, in order (see the module's docstring).

    Args:
        episodes: :class:`Episode` records (at least one).
        workers: processes (default: :func:`default_workers`, every core; 1: this process); with
            ``ray``, the Ray CPUs.
        batch_size: worlds stepped together in one process.
        ray: ``None`` (local) or ``{"address", "workers"}`` (:func:`training.machinery.distributed.ray_options`):
            each batch a Ray task.
        journal: a :class:`training.machinery.distributed.Journal`: each finished episode is recorded
            under its key as its batch lands, and the episodes it holds already are not run again.
        keys: the episodes' names in the journal (default: :func:`episode_key`).
        desc, progress: a progress bar counting episodes.

    Raises:
        ConfigError: no episodes, a seed that is not an integer >= 0, a controller of another
            task, ``workers`` or ``batch_size`` < 1; a program that fails its checks raises its
            own error. All before any episode runs.
    """
    episodes = list(episodes)
    check_episodes(episodes, workers=workers, batch_size=batch_size)
    workers = default_workers() if workers is None else int(workers)
    keys = [episode_key(e) for e in episodes] if keys is None else list(keys)
    first_of: dict = {}  # an episode listed twice runs once
    for i, k in enumerate(keys):
        first_of.setdefault(k, i)
    out: list = [None] * len(episodes)

    def land(i: int, result: dict) -> None:
        out[i] = EpisodeResult(
            cycles=result["cycles"], success=result["success"], total_reward=result["return"], metrics=result["metrics"]
        )

    done = journal.done if journal is not None else {}
    todo = [i for k, i in first_of.items() if k not in done]
    if journal is not None and journal.resumed and len(todo) < len(episodes):
        print(
            f"resuming {journal.path}: {len(episodes) - len(todo)} of {len(episodes)} {desc} already done",
            file=sys.stderr,
        )
    plugins = plugin_modules()
    groups: dict = {}
    for i in todo:
        e = episodes[i]
        kind = batch_kind(_BUILT[((e.task, e.overrides, e.level), e.controller)])
        groups.setdefault((e.task, e.overrides, e.level, kind), []).append(i)
    # One batch a chunk: every worker kept busy, each batch full, and the journal written as each batch lands
    # (an interrupted run loses at most the batches in flight), whatever the number of workers.
    chunks, members = [], []
    for indices in groups.values():
        per_chunk = worlds_per_batch(episodes[indices[0]], batch_size, workers)
        for part in np.array_split(np.array(indices), chunk_count(len(indices), per_chunk, workers)):
            members.append(part.tolist())
            chunks.append((tuple(episodes[i] for i in part), per_chunk, plugins))

    def landed(c: int, results: list) -> None:
        if journal is not None:
            journal.add_many((keys[i], result) for i, result in zip(members[c], results))
        for i, result in zip(members[c], results):
            land(i, result)

    if chunks:
        run_jobs(
            _run_chunk,
            chunks,
            [_chunk_key(chunk[0]) for chunk in chunks],
            ray=ray,
            workers=None if ray else workers,
            desc=desc,
            progress=progress,
            sizes=[len(m) for m in members],
            on_result=landed,
        )
    for i, k in enumerate(keys):  # from the journal, or a repeat of an episode listed before
        if out[i] is None:
            if k in done:
                land(i, done[k])
            else:
                out[i] = out[first_of[k]]
    return out


def chunk_count(n_episodes: int, per_chunk: int, workers: int | None) -> int:
    """Batches to split ``n_episodes`` of one kind into: as few as hold them ``per_chunk`` a batch, but
    no fewer than the workers (or the episodes), so that a few long episodes (a scale split's) keep
    every worker busy rather than filling one batch."""
    return max(math.ceil(n_episodes / per_chunk), min(workers or 1, n_episodes))


BATCH_MEMORY_SHARE = 0.5
"""The part of a worker's share of the memory available that its batch of worlds may take (the
rest: the policy, observations, the process itself and whatever else runs on the machine)."""


LONG_EPISODE_MODULE_CYCLES = 10**7
"""Modules times cycle limit from which an episode is a batch of its own (chain's ``x100``: 1,200
modules and 21,000 cycles): its cycle is work enough for a process (the engine steps so large a
world alone even in a batch), its result lands, in the journal and the progress bar, when it ends,
and no world waits in a batch for a slower one."""


def worlds_per_batch(episode: Episode, batch_size: int, workers: int) -> int:
    """How many worlds of ``episode``'s task and settings one batch steps together: ``batch_size``,
    or fewer where :data:`BATCH_MEMORY_SHARE` of each of ``workers`` processes' share of the memory
    available holds fewer (:func:`proteo_env.core.world.world_bytes` of its world, drawn once, over
    its cycle limit), or one for a long episode (:data:`LONG_EPISODE_MODULE_CYCLES`); a world larger
    than that share is one :class:`ConfigError` before any episode runs."""
    need, size, n_modules, cycles = _world_need(episode.task, episode.overrides, int(episode.seed))
    share = int(machine_memory() * BATCH_MEMORY_SHARE) // max(1, workers)
    if need > share:
        raise ConfigError(
            f"{episode.task} with {episode.overrides}: a world needs up to about {gib(need)} (a box of "
            f"{' x '.join(map(str, size))} sites, {n_modules} modules, {cycles} cycles); allowed: worlds "
            f"that fit in each worker's share of the memory available ({gib(share)} for {workers} worker(s)): "
            "fewer workers, or a split of fewer modules or cycles"
        )
    if n_modules * cycles >= LONG_EPISODE_MODULE_CYCLES:
        return 1
    return int(max(1, min(batch_size, share // need)))


@functools.lru_cache(maxsize=64)
def _world_need(task: str, overrides: str, seed: int) -> tuple:
    """``(bytes, box size, modules, cycle limit)`` of the world ``seed`` of ``task`` with ``overrides``
    (:func:`proteo_env.core.world.world_bytes`; drawn once per process)."""
    env = proteo_env.make(task, **json.loads(overrides))
    env.reset(seed=seed)
    shape, n_modules, cycles = env.engine.shape, env.engine.n_modules, env.max_cycles
    env.close()
    return world_bytes(shape.size, shape.extent, n_modules, cycles), shape.size, n_modules, cycles


def episode_key(episode: Episode) -> str:
    """An episode's stable name: a hash of its controller and settings, and its seed."""
    what = repr((episode.task, episode.overrides, episode.level, episode.controller))
    return f"{hashlib.sha256(what.encode()).hexdigest()[:16]}|{episode.seed}"


def _chunk_key(episodes) -> str:
    """A stable name of a batch: a hash of its episodes."""
    text = "\n".join(repr(e) for e in episodes)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def evaluate(
    task: str,
    controllers,
    seeds,
    *,
    env: dict | None = None,
    level: str = "full",
    workers: int | None = None,
    batch_size: int = DEFAULT_BATCH,
    progress: bool = False,
) -> list[list[EpisodeResult]]:
    """Every controller on every world seed of ``task`` (settings ``env``, control ``level``):
    ``results[c][s]`` for ``controllers[c]`` on ``seeds[s]`` (see :func:`run_episodes`)."""
    for name, value in (("controllers", controllers), ("seeds", seeds)):
        if isinstance(value, str | bytes | dict) or not hasattr(value, "__iter__"):
            raise ConfigError(f"{name}={value!r} is not allowed; allowed: a non-empty list (seeds: range(100), say)")
    controllers, seeds = list(controllers), list(seeds)
    for name, value in (("controllers", controllers), ("seeds", seeds)):
        if not value:
            raise ConfigError(f"{name}=[] is not allowed; allowed: a non-empty list")
    overrides = settings_json(env or {})
    episodes = [Episode(task, overrides, level, c, s) for c in controllers for s in seeds]
    results = run_episodes(episodes, workers=workers, batch_size=batch_size, progress=progress)
    return [results[c * len(seeds) : (c + 1) * len(seeds)] for c in range(len(controllers))]


__all__ = [
    "Controller",
    "Episode",
    "check_episodes",
    "episode_key",
    "evaluate",
    "run_batch",
    "run_episodes",
    "settings_json",
]

"""``proteo eval --benchmark VERSION``: judge a controller on every split of a versioned protocol.

The protocol (what is judged, on which worlds, and how many) and its loader are
:mod:`training.judging.protocol` (:func:`~training.judging.protocol.load_protocol`).

:func:`judge` plans its rows and episodes as ``proteo eval`` does, as a
:class:`~training.judging.episodes.Plan` (batches of worlds on every core or as Ray tasks,
recorded in ``OUT/episodes.jsonl`` so that an interrupted run resumes), and writes
``OUT/benchmark.json`` and ``OUT/benchmark.md`` (the table). Everything is checked (the
protocol, the checkpoints' task and control level, the flags) before anything is written::

    proteo eval --benchmark v1 --checkpoint checkpoints/v1/grasp/kickstart_move/seed_0 --out out/bench
    proteo eval --benchmark v1 --checkpoint runs/s0 --checkpoint runs/s1 ...   # one recipe, its training seeds
    proteo eval --benchmark v1 --policy rules --tasks chain --level full --out docs/benchmark/v1/chain/rules_full
    proteo eval --benchmark v7 --entrant my_policy/entrant.yaml --out out/mine    # an entrant from outside

``benchmark.json`` and ``benchmark.md`` are the one file format and table of every judgement,
``proteo eval``'s included (:mod:`training.judging.record`). See docs/guides/benchmark.md.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import proteo_env
from proteo_env.config import CONTROL_LEVELS, ConfigError, load_yaml
from proteo_env.registry import task_class
from training.judging import record
from training.judging.episodes import Plan
from training.judging.evaluate import refuse_flags
from training.judging.protocol import REFERENCE_POLICIES, Protocol, TaskProtocol, load_protocol
from training.judging.record import document
from training.judging.report import Result, Run
from training.machinery.checkpoints import checkpoint_kind, read_meta
from training.machinery.distributed import ray_options
from training.machinery.entrants import ENTRANT_FILE, check_factory_name, file_digests, load_entrant
from training.machinery.evaluator import Controller, episode_key, settings_json
from training.machinery.runs import out_folder


@dataclass
class Candidate:
    """One policy judged on one task: the rules or random at one level, a recipe's checkpoints, or
    an entrant from outside (:mod:`training.machinery.entrants`)."""

    task: TaskProtocol
    label: str
    kind: str
    level: str
    policy: str
    """The registered policy name (the rules, random), or "" for checkpoints and entrants."""
    checkpoints: list = field(default_factory=list)
    """``[(path, meta)]``: one per training seed."""
    recipe: str | None = None
    entrant: object = None
    """The checked ``entrant.yaml`` (:class:`~training.machinery.entrants.EntrantFile`), or a factory's
    ``module:function`` (a string) for an entrant without one."""

    @property
    def training(self) -> str:
        """How its training is known: ``reference`` (the rules, random), ``protocol`` (a recipe's
        checkpoints, checked against the protocol), ``declared`` (an entrant's ``entrant.yaml``),
        ``undeclared`` (a bare factory) or ``unchecked`` (checkpoints that are not a recipe's)."""
        if self.entrant is not None:
            return "undeclared" if isinstance(self.entrant, str) else "declared"
        if not self.checkpoints:
            return "reference"
        return "protocol" if self.recipe else "unchecked"

    def runs(self) -> list[tuple]:
        """``(source, training seed, agent_steps, sha256, Controller)`` of every run judged: one per
        training seed (one for the rules and random, and for a bare factory)."""
        if isinstance(self.entrant, str):
            return [(self.entrant, None, None, None, Controller.from_entrant(self.entrant))]
        if self.entrant is not None:
            digests, steps = file_digests(self.entrant), self.entrant.budget.get("agent_steps")
            return [
                (
                    file or self.entrant.factory,
                    seed,
                    steps,
                    digests[seed],
                    Controller.from_entrant(self.entrant.path, training_seed=seed),
                )
                for seed, file in sorted(self.entrant.seeds.items())
            ]
        if self.checkpoints:
            return [
                (path, meta.get("seed"), meta.get("agent_steps"), None, Controller.from_checkpoint(path))
                for path, meta in self.checkpoints
            ]
        return [(f"baselines.{self.policy}", None, None, None, Controller.rules(self.policy))]


RUN_OPTIONS = frozenset(
    {"seed", "run_dir", "resume", "init", "time_limit_minutes", "checkpoint_every", "progress_bar", "tensorboard",
     "threads", "workers", "ray", "address", "device", "total_steps"}
)  # fmt: skip
"""Config keys that say how a run ran, not what it trained (``total_steps``: the budget is the
protocol's ``agent_steps``)."""
BUDGET_OVERSHOOT = 0.05
"""A run may end past its ``agent_steps`` by its last batch: at most this share."""


def check_recipe_run(protocol: Protocol, task: TaskProtocol, recipe: str, path: str, meta: dict) -> None:
    """That the checkpoint at ``path`` is a run of ``recipe`` as ``protocol`` fixes it, else one
    :class:`ConfigError`: a training seed among the protocol's (``0 .. training_seeds - 1``); the
    recipe config's settings (every key the checkpoint recorded as well, except
    :data:`RUN_OPTIONS` and the task, whose version the protocol's ``trained_on`` fixes: a study
    for a protocol trains the config on the protocol's task id); and the budget: ``agent_steps`` from the protocol's up to
    :data:`BUDGET_OVERSHOOT` more, or, where the protocol leaves the budget to the config
    (``agent_steps`` null), every generation or round the config asks for."""
    where = f"--checkpoint {path!r} ({task.name} / {recipe})"
    seed = meta.get("seed")
    if seed not in range(protocol.training_seeds):
        raise ConfigError(
            f"{where}: training seed = {seed!r} is not allowed; allowed: the training seeds benchmark "
            f"{protocol.version} fixes, 0 to {protocol.training_seeds - 1}"
        )
    entry = task.recipes[recipe]
    config = load_yaml(protocol.path.parents[2] / entry["config"], "recipe config") or {}
    recorded = meta.get("args") or {}
    for key, value in config.items():
        if key in RUN_OPTIONS or key == "task" or key not in recorded:  # the task: ``trained_on``, checked above
            continue
        if json.dumps(recorded[key], sort_keys=True) != json.dumps(value, sort_keys=True):
            raise ConfigError(
                f"{where}: {key} = {recorded[key]!r} is not allowed; allowed: {value!r}, as the recipe's config "
                f"{entry['config']} sets it"
            )
    steps = meta.get("agent_steps")
    if entry["agent_steps"] is not None:
        budget = entry["agent_steps"]
        if not isinstance(steps, int) or not budget <= steps <= budget * (1 + BUDGET_OVERSHOOT):
            raise ConfigError(
                f"{where}: agent_steps = {steps!r} is not allowed; allowed: the protocol's budget, {budget} to "
                f"{int(budget * (1 + BUDGET_OVERSHOOT))} (the last batch may overshoot)"
            )
        return
    for done, asked, unit in (
        (meta.get("generation"), recorded.get("generations"), "generations"),
        ((meta.get("last_round") or {}).get("round"), recorded.get("rounds"), "rounds"),
    ):
        if asked is not None and done is not None and done != asked:
            raise ConfigError(
                f"{where}: {done} {unit} is not allowed; allowed: the {asked} {unit} of its config (a run stopped "
                "early, by its time limit for example, is not the recipe)"
            )


def _checkpoint_candidate(protocol: Protocol, paths, tasks) -> Candidate:
    """The :class:`Candidate` of ``paths`` (the training seeds of one recipe), checked."""
    metas = []
    for path in paths:
        try:
            metas.append(read_meta(path))
        except (OSError, ValueError) as err:
            raise ConfigError(f"--checkpoint {str(path)!r} is not allowed: {err}") from None
    held = {tid: name for name, t in protocol.tasks.items() for tid in t.trained_on}
    for path, meta in zip(paths, metas):
        if meta["task"] not in held:
            raise ConfigError(
                f"--checkpoint {str(path)!r}: task = {meta['task']!r} is not allowed; allowed: checkpoints of the "
                f"tasks benchmark {protocol.version} holds ({', '.join(sorted(held))})"
            )
    names = {held[m["task"]] for m in metas}
    if len(names) > 1:
        raise ConfigError(
            f"--checkpoint: checkpoints of tasks {', '.join(sorted(names))} are not allowed together; allowed: the "
            "training seeds of one recipe on one task (run the benchmark once per recipe)"
        )
    task = protocol.tasks[names.pop()]
    if tasks and task.name not in tasks:
        raise ConfigError(
            f"--tasks {','.join(tasks)!r} is not allowed with a checkpoint of {task.name}; allowed: --tasks {task.name} or none"
        )
    levels = {m.get("control", "full") for m in metas}
    for path, meta in zip(paths, metas):
        level, kind = meta.get("control", "full"), checkpoint_kind(meta)
        if level not in task.levels[kind]:
            raise ConfigError(
                f"--checkpoint {str(path)!r}: control level = {level!r} is not allowed; allowed: the levels "
                f"benchmark {protocol.version} judges {kind} {task.name} controllers at "
                f"({', '.join(task.levels[kind])})"
            )
    if len(levels) > 1:
        raise ConfigError(
            f"--checkpoint: control levels {', '.join(sorted(levels))} are not allowed together; allowed: the "
            "training seeds of one recipe (one level)"
        )
    resolved = [str(Path(p)) for p in paths]
    if len(set(resolved)) != len(resolved):
        raise ConfigError(f"--checkpoint {resolved!r} is not allowed: a checkpoint given twice; allowed: each once")
    seeds = [m.get("seed") for m in metas]
    if len(paths) > 1 and len(set(seeds)) != len(seeds):
        raise ConfigError(
            f"--checkpoint: training seeds {seeds!r} are not allowed; allowed: checkpoints of distinct training seeds"
        )
    kinds = {checkpoint_kind(m) for m in metas}
    recorded = {m.get("recipe") for m in metas}
    if len(recorded) > 1:
        raise ConfigError(
            f"--checkpoint: checkpoints of recipes {', '.join(sorted(map(str, recorded)))} are not allowed together; "
            "allowed: the training seeds of one recipe"
        )
    named = recorded.pop()  # the recipe its checkpoint records (training/trainers/study.py writes it), or none
    parents = {Path(p).resolve().parent.name for p in paths}
    folder = parents.pop() if len(parents) == 1 and len(paths) > 1 else Path(paths[0]).resolve().name
    if folder.startswith("seed_"):
        folder = Path(paths[0]).resolve().parent.name
    recipe = named if named in task.recipes else None
    if recipe is not None:
        for path, meta in zip(paths, metas):
            check_recipe_run(protocol, task, recipe, str(path), meta)
    return Candidate(
        task=task,
        label=named or folder,
        kind=kinds.pop() if len(kinds) == 1 else "learned",
        level=levels.pop(),
        policy="",
        checkpoints=list(zip([str(p) for p in paths], metas)),
        recipe=recipe,
    )


def _entrant_candidate(protocol: Protocol, source, tasks, level) -> Candidate:
    """The :class:`Candidate` of an entrant: an ``entrant.yaml`` (its task, level and training
    seeds declared in it) or a bare factory ``module:function`` (``tasks``: one task, and ``level``)."""
    held = {tid: name for name, t in protocol.tasks.items() for tid in t.trained_on}
    text = str(source)
    if ":" in text and not Path(text).exists():
        check_factory_name(text)
        if not tasks or len(tasks) != 1 or level is None:
            raise ConfigError(
                f"--entrant {text!r} (a factory without an entrant.yaml) with --tasks {','.join(tasks or []) or None} "
                f"and --level {level} is not allowed; allowed: --tasks TASK (one) and --level LEVEL, or an "
                "entrant.yaml that names them"
            )
        task, entry, kind, lv = protocol.tasks[tasks[0]], text, "learned", level
    else:
        entry = load_entrant(source)
        if entry.task not in held:
            raise ConfigError(
                f"entrant {str(entry.path)!r}: task = {entry.task!r} is not allowed; allowed: the tasks benchmark "
                f"{protocol.version} holds ({', '.join(sorted(held))})"
            )
        task, kind, lv = protocol.tasks[held[entry.task]], entry.kind, entry.level
        for flag, value, allowed in (("--tasks", tasks, [task.name]), ("--level", level, lv)):
            if value is not None and value != allowed:
                raise ConfigError(
                    f"{flag} {value!r} is not allowed with entrant {str(entry.path)!r}; allowed: none (its "
                    f"{ENTRANT_FILE} says {allowed!r})"
                )
    levels = task.levels["rules" if kind == "hand-coded" else kind]
    if lv not in levels:
        raise ConfigError(
            f"entrant {text!r}: control level = {lv!r} is not allowed; allowed: the levels benchmark "
            f"{protocol.version} judges {kind} {task.name} controllers at ({', '.join(levels)})"
        )
    label = entry if isinstance(entry, str) else entry.name
    taken = {*task.recipes, "rules", "random", *(f"{p}-{lv}" for p in REFERENCE_POLICIES for lv in CONTROL_LEVELS)}
    if label in taken:
        raise ConfigError(
            f"entrant {text!r}: name = {label!r} is not allowed; allowed: a name that is not one of the protocol's "
            f"recipes or references ({', '.join(sorted(taken))})"
        )
    return Candidate(task=task, label=label, kind=kind, level=lv, policy="", entrant=entry)


def candidates(
    protocol: Protocol, *, checkpoints=(), policy=None, level=None, tasks=None, entrant=None
) -> list[Candidate]:
    """The policies to judge, per task: the training seeds of one recipe (``checkpoints``), an
    entrant from outside (``entrant``), or the rules or random (``policy``) on every task of the
    protocol (or of ``tasks``) at every level the protocol judges them at (or at ``level``). Bad
    input: a :class:`ConfigError`."""
    if tasks is not None:
        tasks = list(tasks)
        for t in tasks:
            if t not in protocol.tasks:
                raise ConfigError(
                    f"--tasks {t!r} is not allowed; allowed: tasks of benchmark {protocol.version} "
                    f"({', '.join(protocol.tasks)})"
                )
    given = [
        flag for flag, value in (("--checkpoint", checkpoints), ("--policy", policy), ("--entrant", entrant)) if value
    ]
    if len(given) != 1:
        raise ConfigError(
            f"--benchmark {protocol.version} with {' and '.join(given) or 'none of --checkpoint, --policy, --entrant'} "
            "is not allowed; allowed: one of --checkpoint PATH (repeatable: one recipe's training seeds), "
            "--entrant PATH/entrant.yaml (or a factory module:function) and --policy rules|random"
        )
    if entrant:
        return [_entrant_candidate(protocol, entrant, tasks, level)]
    if checkpoints:
        if level is not None:
            raise ConfigError(f"--level {level!r} is not allowed with --checkpoint; allowed: --level with --policy")
        return [_checkpoint_candidate(protocol, list(checkpoints), tasks)]
    if policy not in REFERENCE_POLICIES:
        raise ConfigError(f"--policy {policy!r} is not allowed; allowed: {', '.join(REFERENCE_POLICIES)}")
    out = []
    for name, task in protocol.tasks.items():
        if tasks is not None and name not in tasks:
            continue
        levels = task.levels[policy]
        if level is not None and level not in levels:
            raise ConfigError(
                f"--level {level!r} is not allowed for --policy {policy} on {name}; allowed: {', '.join(levels)} "
                f"(the levels benchmark {protocol.version} judges it at)"
            )
        for lv in [level] if level is not None else levels:
            registered = task_class(task.task_id).default_policy if policy == "rules" else policy
            out.append(
                Candidate(
                    task=task,
                    label=policy if lv == levels[0] else f"{policy}-{lv}",
                    kind="hand-coded" if policy == "rules" else "random",
                    level=lv,
                    policy=registered,
                )
            )
    return out


def judge(
    version: str = "v1",
    *,
    checkpoints=(),
    entrant=None,
    policy: str | None = None,
    level: str | None = None,
    tasks=None,
    out="out/benchmark",
    ray: dict | None = None,
    workers: int | None = None,
    worlds_cap: int | None = None,
    splits=None,
    fresh: bool = False,
    progress: bool = True,
    root=None,
) -> dict:
    """Judge a controller on every split of its task(s) under protocol ``version``; write
    ``out/benchmark.json`` and ``out/benchmark.md`` (:mod:`training.judging.record`) and return the
    document. In four steps: check (:func:`candidates`, :func:`check_loads`), plan
    (:func:`plan_protocol`), run (:meth:`~training.judging.episodes.Plan.execute`), write
    (:func:`training.judging.record.document`, :func:`training.judging.record.write`).

    Args:
        checkpoints: the training seeds of one recipe (checkpoint folders), or
        entrant: an entrant from outside: an ``entrant.yaml`` (or its folder), or a factory
            ``module:function`` with one task in ``tasks`` and ``level`` (docs/guides/entering.md), or
        policy: ``"rules"`` or ``"random"`` (every task of the protocol, or ``tasks``), at every
            level the protocol judges it at, or at ``level``.
        ray: ``None`` (this machine) or ``{"address", "workers"}``.
        workers: processes on this machine (default: every core; the results do not depend on it).
        worlds_cap: judge on at most this many worlds per split and training seed (the first
            ones). For quick checks only: the file records it and is not ``complete``.
        splits: judge these splits of the task(s) only (default: every split), such as the
            splits a protocol adds to the one it extends.
        fresh: discard the episodes of an interrupted run in ``out`` instead of resuming it.

    Everything is checked before anything is written (a :class:`ConfigError` otherwise).
    """
    protocol = load_protocol(version, root)
    out_folder(out)
    if worlds_cap is not None:
        if isinstance(worlds_cap, bool) or not isinstance(worlds_cap, int) or worlds_cap < 1:
            raise ConfigError(
                f"--worlds-cap = {worlds_cap!r} is not allowed; allowed: an integer >= 1 (worlds per split and "
                "training seed: a success rate needs at least one)"
            )
    judged = candidates(protocol, checkpoints=checkpoints, policy=policy, level=level, tasks=tasks, entrant=entrant)
    check_splits(protocol, judged, splits)
    check_loads(protocol, judged)
    plan = plan_protocol(protocol, judged, worlds_cap, splits)
    fingerprint = {
        "protocol": protocol.version,
        "sha256": protocol.sha256,
        "worlds_cap": worlds_cap,
        "jobs": [episode_key(episode) for _, episode, _ in plan.jobs],
    }
    out_dir = Path(out)

    def write(seconds: float) -> dict:
        notes = notes_on(protocol, judged, worlds_cap)
        doc = document(plan.rows, judgement="benchmark", protocol=protocol, worlds_cap=worlds_cap, notes=notes,
                       seconds=seconds)  # fmt: skip
        return record.write(doc, out_dir)

    return plan.execute(
        out_dir, fingerprint=fingerprint, fresh=fresh, what="benchmark run", ray=ray, workers=workers,
        progress=progress, write=write,
    )  # fmt: skip


def check_splits(protocol: Protocol, judged: list[Candidate], splits) -> None:
    """Every name in ``splits`` (``None``: every split) is a split of every task judged, else one
    :class:`ConfigError` naming it and the task's splits."""
    for name in splits or ():
        for e in judged:
            names = [s.name for s in e.task.splits]
            if name not in names:
                raise ConfigError(
                    f"--splits {name!r} is not allowed for {e.task.name}; allowed: its splits under benchmark "
                    f"{protocol.version} ({', '.join(names)}), or --tasks with the tasks that have it"
                )


def check_loads(protocol: Protocol, judged: list[Candidate]) -> None:
    """Every checkpoint and entrant of ``judged`` loads on its task's first split (a
    :class:`ConfigError` naming what does not), before anything is written."""
    for e in judged:
        if e.training == "reference":
            continue
        split = e.task.splits[0]
        env = proteo_env.make(e.task.task_id, **split.env, control=e.level)
        try:
            for *_, controller in e.runs():
                controller.build(env, protocol.first_seed, split.env)
        finally:
            env.close()


def plan_protocol(protocol: Protocol, judged: list[Candidate], worlds_cap: int | None, splits=None):
    """The :class:`~training.judging.episodes.Plan` of a protocol: for each candidate and split of
    its task (those named in ``splits`` only, where given), one row whose runs (one per training
    seed) play the split's world seeds for its kind (the first ``worlds_cap`` of them where given)."""
    plan = Plan()
    for e in judged:
        for split in e.task.splits:
            if splits is not None and split.name not in splits:
                continue
            seeds = protocol.world_seeds(protocol.worlds(e.kind, worlds_cap, split))
            result = Result(
                task=e.task.task_id,
                policy=e.label,
                kind=e.kind,
                level=e.level,
                group=e.training != "reference",
                split=split.name,
                about=split.about,
                env=split.env,
                recipe=e.recipe,
                complete=worlds_cap is None and (not e.checkpoints or len(e.checkpoints) >= protocol.training_seeds),
                training=e.training,
                declared=e.entrant.declared() if e.training == "declared" else None,
            )
            for source, training_seed, agent_steps, sha256, controller in e.runs():
                run = Run(source=source, training_seed=training_seed, agent_steps=agent_steps, sha256=sha256)
                result.runs.append(run)
                plan.add_run(run, controller, e.task.task_id, settings_json(split.env), e.level, seeds)
            plan.rows.append(result)
    return plan


def notes_on(protocol: Protocol, judged: list[Candidate], worlds_cap: int | None) -> list[str]:
    """Why the rows of ``judged`` are not complete, if they are not: a worlds cap, fewer training
    seeds than the protocol asks."""
    notes = []
    if worlds_cap is not None:
        notes.append(
            f"--worlds-cap {worlds_cap}: judged on at most {worlds_cap} worlds per split and training seed, "
            "fewer than the protocol asks (a quick check, not a benchmark result)"
        )
    for e in judged:
        if e.checkpoints and len(e.checkpoints) < protocol.training_seeds:
            notes.append(
                f"{e.task.name} / {e.label}: {len(e.checkpoints)} training seed(s); protocol {protocol.version} "
                f"asks for at least {protocol.training_seeds} (the rows are not complete)"
            )
    return notes


def main(args) -> int:
    """``proteo eval --benchmark VERSION ...`` (arguments parsed in :mod:`training.cli`)."""
    conflicting = {
        "--config": args.config,
        "--seeds": args.seeds is not None,
        "--deterministic": args.deterministic,
        "--publish": args.publish,
        "--pictures": args.pictures,
        "--from-results": args.from_results,
    }
    refuse_flags(
        "--benchmark",
        conflicting,
        "the protocol fixes the worlds and settings",
        "--checkpoint, --entrant, --policy, --level, --tasks, --splits, --out, --worlds-cap, --fresh, --ray, --workers, "
        "--address, --no-plots",
    )
    document = judge(
        args.benchmark,
        checkpoints=args.checkpoint or (),
        entrant=args.entrant,
        policy=args.policy,
        level=args.level,
        tasks=args.tasks.split(",") if args.tasks else None,
        out=args.out,
        ray=ray_options(args),
        workers=None if args.ray else args.workers,
        worlds_cap=args.worlds_cap,
        splits=args.splits.split(",") if args.splits else None,
        fresh=args.fresh,
    )
    print(record.markdown(document))
    print(f"benchmark {document['protocol']}: {Path(args.out).resolve()}/benchmark.json, benchmark.md")
    return 0


def check_flags(args) -> None:
    """``--policy``, ``--entrant``, ``--level`` and ``--worlds-cap`` belong to ``--benchmark``: without
    it, a :class:`ConfigError` (so that a flag is never silently ignored)."""
    flags = ("--policy", args.policy), ("--entrant", args.entrant), ("--level", args.level), ("--splits", args.splits)
    for flag, value in (*flags, ("--worlds-cap", args.worlds_cap)):
        if value is not None:
            raise ConfigError(
                f"{flag} {value!r} without --benchmark is not allowed; allowed: --benchmark VERSION {flag} ..."
            )

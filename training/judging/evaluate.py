"""``proteo eval``: hand-coded, random, learned and evolved policies on every task, over seeds.

For each registered task with a reward (every task but ``sandbox``), the task's hand-coded
policy (``default_policy``), the random policy and every checkpoint given for that task run
one episode per seed (the same seeds for every policy: ``env.reset(seed=s)`` and
``policy.reset(s)``). Reported per policy, each with a 95 % interval (the interval code is
:mod:`training.judging.statistics`):

- mean episode return (one run: Student t over its episodes);
- success rate, episodes ending in task success (one run: Wilson);
- cycles to success: the mean over the successful episodes (one run: Student t, its lower end
  cut at 0).

A ``runs`` group (one configuration trained with several seeds) is one row whose measures are
pooled over every episode of every training seed (successes over episodes, the mean return,
the mean cycles over the successful episodes), each with the percentile interval of a
stratified bootstrap (:func:`training.judging.statistics.group_bootstrap`: training seeds drawn with
replacement, then each drawn seed's episodes with replacement; 2,000 resamples, generator seed
0, so a table is reproduced exactly). The success interval is widened to at least the pooled
Wilson interval, because a percentile bootstrap collapses to a point where every episode agrees
(30/30 would read 1.00–1.00). Each run's own row is in a second table.

Every table prints a measure as ``value (low–high)``, its 95 % interval (``low to high`` where
``low`` is negative; the value alone where the interval is undefined, such as cycles to success
from one successful episode): success as ``24/30 (0.63–0.93)``, cycles to success as
``120 (100–142)``, ``–`` without a success. The compact summary (:func:`~training.judging.report.summary_table`, what
``--publish`` writes into README.md) has one cell per task and policy:
``24/30 (0.63–0.93), 120 (100–142)``. :data:`~training.judging.report.INTERVALS` says this under every table but the
summary, whose first column's head is ``task (95 % CI)``.

Settings per task and the checkpoints to compare come from a YAML file (``configs/eval.yaml``)::

    seeds: 10            # episodes per policy: seeds first_seed .. first_seed + seeds - 1
    first_seed: 0
    tasks:
      chain:
        env: {n_modules: 12, max_cycles: 300}
        checkpoints:
          - checkpoints/v2/chain/cma_full/seed_0                       # one checkpoint
          - {label: ppo, runs: [runs/ppo_s0, runs/ppo_s1, runs/ppo_s2]}   # one per training seed
      branch:
        task: branch-v0      # a version of the task (default: the newest)

A task not named there runs with its newest version, its defaults and no checkpoints; a name,
key or value that is not allowed is one :class:`~proteo_env.config.ConfigError` before anything
runs (:func:`load_config`). ``--checkpoint PATH`` adds a checkpoint to the task it was trained
on. Each checkpoint runs at the control level it was trained at (``control`` in its
``proteo.json``; ``full`` for older ones), and for every level other than ``full`` that a
checkpoint uses, the random policy runs at that level too (random moves under the task's rules
at ``move``). Writes ``results.md`` (the tables), ``results.json`` (every episode) and
``eval.png`` (the three measures per task) into ``--out``; ``--publish PAGE.md`` also puts the
tables into a page between its markers (:func:`~training.judging.report.publish_evaluation`). ``--from-results RESULTS.json`` runs
no episode: it writes the tables of an earlier ``results.json`` again, in the current format,
into ``--out`` and the ``--publish`` pages (:func:`~training.judging.record.rerender`), e.g.::

    proteo eval --from-results docs/eval/study/results.json --out docs/eval/study \\
        --publish README.md --publish docs/guides/learning.md

Each episode is one :class:`training.machinery.evaluator.Episode`, run in batches of worlds on every core
(``--workers N`` processes); ``--ray`` runs the batches as Ray tasks, on a local Ray instance
(``--workers N`` CPUs) or a cluster (``--address``), with results identical to the serial run. Finished episodes go to ``--out``/``episodes.jsonl`` as they arrive; rerunning
an interrupted evaluation with the same settings runs only the missing episodes
(``--fresh`` starts over). See docs/guides/distributed.md.
"""

from __future__ import annotations

import difflib
import hashlib
from pathlib import Path

import proteo_env
from baselines import make_policy
from proteo_env.config import ConfigError, load_yaml
from proteo_env.registry import TASKS, newest_tasks, task_class, task_name
from training.judging import record
from training.judging.episodes import Plan
from training.judging.report import Result, Run, markdown_table, publish_evaluation
from training.machinery.checkpoints import META_FILE, checkpoint_dir, checkpoint_kind, load_policy, read_meta
from training.machinery.distributed import ray_options
from training.machinery.evaluator import Controller, settings_json
from training.machinery.runs import out_folder

DEFAULT_CONFIG = "configs/eval.yaml"
"""The config ``proteo eval`` reads when run from the repository root without ``--config``."""


EXCLUDED_TASKS = ("sandbox",)
"""Task names left out of the evaluation (no reward, no success)."""


CONFIG_KEYS = ("first_seed", "seeds", "tasks")
"""The keys of an eval config."""


CONFIG_TASK_KEYS = ("checkpoints", "env", "task")
"""The keys of a task's entry under ``tasks``."""


GROUP_KEYS = ("label", "runs")
"""The keys of a training-seed group under a task's ``checkpoints``."""


def load_config(path) -> dict:
    """The eval config as ``{"seeds", "first_seed", "tasks": {name: {"task", "env", "checkpoints"}}}``
    (``task``: an optional version of the name, such as ``branch-v0``; without it the newest).

    Bad input is one :class:`ConfigError` naming the field, the value and what is allowed, raised
    before anything runs or is written: an unknown key at the top (:data:`CONFIG_KEYS`), a name
    under ``tasks`` that is not an evaluated task, an unknown key in a task's entry
    (:data:`CONFIG_TASK_KEYS`) or in a training-seed group (:data:`GROUP_KEYS`), and values of the
    wrong kind."""
    if path is None:
        return {"seeds": 10, "first_seed": 0, "tasks": {}}
    p = Path(path)
    where = f"eval config {str(p)!r}"
    data = load_yaml(p, "eval config", "a YAML file such as configs/eval.yaml")
    data = {} if data is None else data

    def unknown(field: str, keys, allowed, what: str = "key") -> None:
        bad = [k for k in keys if k not in allowed]
        if bad:
            close = difflib.get_close_matches(str(bad[0]), list(allowed), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ConfigError(f"{where}: {field}: unknown {what} {bad[0]!r}{hint}; allowed: {', '.join(allowed)}")

    if not isinstance(data, dict):
        raise ConfigError(f"{where}: {data!r} is not allowed; allowed: a mapping with keys {', '.join(CONFIG_KEYS)}")
    unknown("top level", data, CONFIG_KEYS)
    numbers = {}
    for key, default, least in (("seeds", 10, 1), ("first_seed", 0, 0)):
        value = data.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise ConfigError(f"{where}: {key} = {value!r} is not allowed; allowed: an integer >= {least}")
        numbers[key] = value
    tasks = data.get("tasks") or {}
    if not isinstance(tasks, dict):
        raise ConfigError(f"{where}: tasks = {tasks!r} is not allowed; allowed: a mapping of task names to settings")
    names = sorted({cls.name for cls in TASKS.values()} - set(EXCLUDED_TASKS))
    unknown("tasks", tasks, names, "task")
    for name, entry in tasks.items():
        entry = {} if entry is None else entry
        if not isinstance(entry, dict):
            raise ConfigError(
                f"{where}: tasks.{name} = {entry!r} is not allowed; allowed: a mapping with keys {', '.join(CONFIG_TASK_KEYS)}"
            )
        unknown(f"tasks.{name}", entry, CONFIG_TASK_KEYS)
        pinned = entry.get("task")
        versions = sorted(tid for tid, cls in TASKS.items() if cls.name == name)
        if pinned is not None and pinned not in versions:
            raise ConfigError(
                f"{where}: tasks.{name}.task = {pinned!r} is not allowed; "
                f"allowed: {', '.join(versions) or 'a version of a registered task'}"
            )
        if not isinstance(entry.get("env") or {}, dict):
            raise ConfigError(
                f"{where}: tasks.{name}.env = {entry['env']!r} is not allowed; "
                "allowed: a mapping of proteo_env.make settings"
            )
        items = entry.get("checkpoints") or []
        if not isinstance(items, list):
            raise ConfigError(
                f"{where}: tasks.{name}.checkpoints = {items!r} is not allowed; allowed: a list of checkpoints"
            )
        for k, item in enumerate(items):
            if isinstance(item, dict):
                unknown(f"tasks.{name}.checkpoints[{k}]", item, GROUP_KEYS)
            ok = isinstance(item, str) or (
                isinstance(item, dict)
                and set(item) == set(GROUP_KEYS)
                and isinstance(item["label"], str)
                and isinstance(item["runs"], list)
                and item["runs"]
                and all(isinstance(r, str) for r in item["runs"])
            )
            if not ok:
                raise ConfigError(
                    f"{where}: tasks.{name}.checkpoints[{k}] = {item!r} is not allowed; "
                    "allowed: a checkpoint path, or {label: NAME, runs: [PATH, ...]} (one path per "
                    "training seed)"
                )
    return {"seeds": numbers["seeds"], "first_seed": numbers["first_seed"], "tasks": tasks}


def _name_apart(results: list[Result]) -> None:
    """Give policies that share a name (two checkpoints of one algorithm) their checkpoint
    folder's name in brackets, so that the table tells them apart."""
    names = [r.policy for r in results]
    for r in results:
        if names.count(r.policy) > 1 and not r.runs[0].source.startswith("baselines."):
            r.policy = f"{r.policy} ({Path(r.runs[0].source).name})"


def _checkpoint_identity(path) -> str:
    """A hash of a checkpoint's ``proteo.json`` (it changes whenever the checkpoint is written again)."""
    return hashlib.sha256((checkpoint_dir(path) / META_FILE).read_bytes()).hexdigest()[:16]


def run_evaluation(
    *,
    config=None,
    tasks=None,
    seeds: int | None = None,
    checkpoints=(),
    out="out/eval",
    deterministic: bool = False,
    progress: bool = True,
    plots: bool = True,
    pictures: bool = False,
    ray: dict | None = None,
    workers: int | None = None,
    fresh: bool = False,
) -> list:
    """Run the comparison and write ``results.md``, ``results.json`` and ``eval.png`` into ``out``.

    Every episode is one :class:`training.machinery.evaluator.Episode`, run in batches of worlds on
    ``workers`` processes (default: every core) or as Ray tasks (``ray``), and recorded in ``out/episodes.jsonl`` as it finishes; rerunning an interrupted evaluation with
    the same settings resumes it (see :class:`training.machinery.distributed.Journal`). The tables are
    written only when every episode has finished.

    Args:
        config: path of the YAML settings (see the module docstring) or ``None``.
        tasks: task names or ids to evaluate (default: every registered task but ``sandbox``); a
            bare name is the config's ``task`` for it where one is given, else its newest version.
        seeds: episodes per policy (overrides the config's ``seeds``).
        checkpoints: extra checkpoint paths; each goes to the task it was trained on.
        out: output folder.
        deterministic: learned and evolved neural policies take arg-max actions.
        pictures: draw the end of each policy's first episode (what it builds) into
            ``out/pictures/<task>_<policy>.png`` (the first run of a training-seed group).
        ray: ``None`` (this machine) or ``{"address", "workers"}`` (:func:`training.machinery.distributed.ray_options`).
        workers: processes on this machine (default: every core; the results do not depend on it).
        fresh: discard the episodes of an unfinished earlier run in ``out`` instead of resuming it.

    Returns:
        one :class:`~training.judging.report.Result` per policy or training-seed group.

    It chooses the tasks and checkpoints, then plans every episode (:func:`plan_episodes`), runs
    them (:meth:`~training.judging.episodes.Plan.execute`) and writes them
    (:func:`training.judging.record.document`, :func:`training.judging.record.write`).
    """
    out_folder(out)
    cfg = load_config(config)
    n_seeds = seeds if seeds is not None else cfg["seeds"]
    if n_seeds < 1:
        raise ConfigError(f"seeds={n_seeds!r} is not allowed; allowed: an integer >= 1")
    seed_list = list(range(cfg["first_seed"], cfg["first_seed"] + n_seeds))
    pinned = {name: entry["task"] for name, entry in cfg["tasks"].items() if entry and entry.get("task")}
    if tasks:
        classes = [task_class(pinned.get(t, t)) for t in tasks]
    else:
        names = sorted(cls.name for cls in newest_tasks().values() if cls.name not in EXCLUDED_TASKS)
        classes = [task_class(pinned.get(name, name)) for name in names]
    by_task: dict[str, list[tuple[str, str]]] = {c.name: [] for c in classes}
    """(path, training-seed group label or "") of every checkpoint, per task name."""
    for c in classes:
        for item in (cfg["tasks"].get(c.name) or {}).get("checkpoints") or []:
            by_task[c.name] += [(item, "")] if isinstance(item, str) else [(r, item["label"]) for r in item["runs"]]
    for path in checkpoints:
        name = task_name(read_meta(path)["task"])
        if name not in by_task:
            raise ConfigError(
                f"checkpoint {str(path)!r} was trained on task {name!r}, which is not evaluated; "
                f"allowed: checkpoints of {', '.join(by_task)}"
            )
        by_task[name].append((str(path), ""))

    plan = plan_episodes(cfg, classes, by_task, seed_list, deterministic=deterministic, pictures=pictures)
    settings = {c.name: (cfg["tasks"].get(c.name) or {}).get("env") or {} for c in classes}
    fingerprint = {
        "seeds": seed_list,
        "settings": settings,
        "deterministic": deterministic,
        "pictures": pictures,
        "jobs": len(plan.jobs),
        "checkpoints": {p: _checkpoint_identity(p) for ps in by_task.values() for p, _ in ps},
    }

    def write(seconds: float) -> list[Result]:
        doc = record.document(plan.rows, judgement="evaluation", deterministic=deterministic, seconds=seconds)
        record.write(doc, out, plots=plots)
        return plan.rows

    return plan.execute(
        Path(out), fingerprint=fingerprint, fresh=fresh, what="evaluation", ray=ray, workers=workers,
        progress=progress, write=write,
    )  # fmt: skip


def plan_episodes(cfg: dict, classes, by_task: dict, seed_list: list, *, deterministic: bool, pictures: bool) -> Plan:
    """The :class:`~training.judging.episodes.Plan` of an evaluation: every policy's (or
    training-seed group's) row and its episodes. Policies are built here once, so that a bad
    checkpoint fails before any episode runs.

    Args:
        cfg: the eval config (:func:`load_config`); classes: the task classes evaluated;
        by_task: ``{task name: [(checkpoint path, training-seed group label or "")]}``;
        seed_list: the episodes' seeds; deterministic, pictures: as for :func:`evaluate`.
    """
    plan = Plan()
    results = plan.rows
    for cls in classes:
        overrides = dict((cfg["tasks"].get(cls.name) or {}).get("env") or {})
        envs = {"full": proteo_env.make(cls.task_id(), **overrides)}
        levels = {path: read_meta(path).get("control", "full") for path, _ in by_task[cls.name]}
        for level in dict.fromkeys(levels.values()):
            envs.setdefault(level, proteo_env.make(cls.task_id(), **{**overrides, "control": level}))
        # the rules at every level a checkpoint acts at: below full, their own moves (and fields)
        # under the level's autopilot, the reference a learned controller of that level is held to
        entries = [("hand-coded", envs["full"].task.default_policy, None, level, "") for level in envs]
        entries += [("random", "random", None, level, "") for level in envs]
        entries += [(None, None, path, levels[path], group) for path, group in by_task[cls.name]]
        first_task_row = len(results)
        for kind, name, path, level, group in entries:
            env = envs[level]
            if path is None:
                policy = make_policy(name, env, seed=seed_list[0])
                run = Run(source=f"baselines.{name}")
            else:
                meta = read_meta(path)
                policy = load_policy(path, env, seed=seed_list[0], deterministic=deterministic)
                kind = checkpoint_kind(meta)
                run = Run(source=str(path), training_seed=meta.get("seed"), agent_steps=meta.get("agent_steps"))
            result = next(
                (r for r in results if group and r.group and r.task == cls.task_id() and r.policy == group), None
            )
            first_of_group = result is None
            if result is None:
                result = Result(
                    task=cls.task_id(), policy=group or policy.name, kind=kind, level=level, group=bool(group),
                    env=overrides,
                )  # fmt: skip
                results.append(result)
            result.runs.append(run)
            label = group or (policy.name if path is None else Path(path).name)
            controller = (
                Controller.rules(name)
                if path is None
                else Controller.from_checkpoint(path, deterministic=deterministic)
            )
            picture = label if pictures and first_of_group else ""
            plan.add_run(run, controller, cls.task_id(), settings_json(overrides), level, seed_list, picture=picture)
        for env in envs.values():
            env.close()
        _name_apart([r for r in results[first_task_row:] if not r.group])
    return plan


def refuse_flags(mode: str, flags: dict, why: str, allowed: str) -> None:
    """One :class:`~proteo_env.config.ConfigError` naming the first of ``flags`` (``{flag: value}``)
    that was given with ``mode``, why it is refused and what ``mode`` allows."""
    given = [flag for flag, value in flags.items() if value]
    if given:
        raise ConfigError(f"{mode} with {given[0]} is not allowed ({why}); allowed with {mode}: {allowed}")


def main(args) -> int:
    """Entry point of ``proteo eval`` (arguments parsed in :mod:`training.cli`)."""
    if getattr(args, "from_results", None):
        running = {
            "--config": args.config,
            "--tasks": args.tasks,
            "--seeds": args.seeds is not None,
            "--checkpoint": args.checkpoint,
            "--deterministic": args.deterministic,
            "--pictures": args.pictures,
            "--fresh": args.fresh,
        }
        refuse_flags("--from-results", running, "no episode runs", "--out, --publish, --no-plots")
        results = record.rerender(args.from_results, args.out, plots=not args.no_plots, pages=args.publish or ())
        print(markdown_table(results))
        print(f"\nre-rendered {args.from_results} into {Path(args.out).resolve()}")
        return 0
    config = args.config
    if config is None and Path(DEFAULT_CONFIG).is_file():
        config = DEFAULT_CONFIG

    results = run_evaluation(
        config=config,
        tasks=args.tasks.split(",") if args.tasks else None,
        seeds=args.seeds,
        checkpoints=args.checkpoint or (),
        out=args.out,
        deterministic=args.deterministic,
        plots=not args.no_plots,
        pictures=args.pictures,
        ray=ray_options(args),
        workers=None if args.ray else args.workers,
        fresh=args.fresh,
    )
    if args.publish:
        publish_evaluation(results, args.out, args.publish)
    print(markdown_table(results))
    print(f"\nresults: {Path(args.out).resolve()}/results.md, results.json" + ("" if args.no_plots else ", eval.png"))
    return 0

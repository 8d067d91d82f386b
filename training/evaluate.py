"""``proteo eval``: hand-coded, random, learned and evolved policies on every task, over seeds.

For each registered task with a reward (every task but ``sandbox``), the task's hand-coded
policy (``default_policy``), the random policy and every checkpoint given for that task run
one episode per seed (the same seeds for every policy: ``env.reset(seed=s)`` and
``policy.reset(s)``). Reported per policy, each with a 95 % interval (the interval code is
:mod:`training.statistics`):

- mean episode return (one run: Student t over its episodes);
- success rate, episodes ending in task success (one run: Wilson);
- cycles to success: the mean over the successful episodes (one run: Student t, its lower end
  cut at 0).

A ``runs`` group (one configuration trained with several seeds) is one row whose measures are
pooled over every episode of every training seed (successes over episodes, the mean return,
the mean cycles over the successful episodes), each with the percentile interval of a
stratified bootstrap (:func:`training.statistics.group_bootstrap`: training seeds drawn with
replacement, then each drawn seed's episodes with replacement; 2,000 resamples, generator seed
0, so a table is reproduced exactly). The success interval is widened to at least the pooled
Wilson interval, because a percentile bootstrap collapses to a point where every episode agrees
(30/30 would read 1.00–1.00). Each run's own row is in a second table.

Every table prints a measure as ``value (low–high)``, its 95 % interval (``low to high`` where
``low`` is negative; the value alone where the interval is undefined, such as cycles to success
from one successful episode): success as ``24/30 (0.63–0.93)``, cycles to success as
``120 (100–142)``, ``–`` without a success. The compact summary (:func:`summary_table`, what
``--publish`` writes into README.md) has one cell per task and policy:
``24/30 (0.63–0.93), 120 (100–142)``. :data:`INTERVALS` says this under every table but the
summary, whose first column's head is ``task (95 % CI)``.

Settings per task and the checkpoints to compare come from a YAML file (``configs/eval.yaml``)::

    seeds: 10            # episodes per policy: seeds first_seed .. first_seed + seeds - 1
    first_seed: 0
    tasks:
      chain:
        env: {n_modules: 12, max_cycles: 300}
        checkpoints:
          - checkpoints/chain/sb3_ppo                       # one checkpoint
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
tables into a page between its markers (:func:`publish`). ``--from-results RESULTS.json`` runs
no episode: it writes the tables of an earlier ``results.json`` again, in the current format,
into ``--out`` and the ``--publish`` pages (:func:`rerender`), e.g.::

    proteo eval --from-results docs/eval/study/results.json --out docs/eval/study \\
        --publish README.md --publish docs/guides/learning.md

Each episode is one job (:class:`EpisodeJob`): ``--ray`` runs them as Ray tasks, on a local
Ray instance (``--workers N`` CPUs) or a cluster (``--address``), with results identical to
the serial run. Finished episodes go to ``--out``/``episodes.jsonl`` as they arrive; rerunning
an interrupted evaluation with the same settings runs only the missing episodes
(``--fresh`` starts over). See docs/guides/distributed.md.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from proteo_env.registry import task_name
from training.statistics import group_bootstrap, mean_ci, wilson

DEFAULT_CONFIG = "configs/eval.yaml"
"""The config ``proteo eval`` reads when run from the repository root without ``--config``."""

EXCLUDED_TASKS = ("sandbox",)
"""Task names left out of the evaluation (no reward, no success)."""

INTERVALS = (
    "95 % intervals. One run: Wilson for success, Student t over episodes for return and cycles "
    "to success (its lower end cut at 0). A group of training seeds: a stratified bootstrap "
    "(training seeds, then each seed's episodes, drawn with replacement; 2,000 resamples, "
    "generator seed 0), the percentile interval of the pooled measure; the success interval is "
    "at least the pooled Wilson interval."
)
"""What the intervals of every table are (written under the tables and in published pages)."""


@dataclass
class PolicyResult:
    """Every episode of one policy on one task, and the summary measures."""

    task: str
    policy: str
    kind: str
    source: str
    level: str = "full"
    """The control level the policy acted at."""
    group: str = ""
    """The label of the group of training seeds this run belongs to ("" when none)."""
    returns: list = field(default_factory=list)
    successes: list = field(default_factory=list)
    cycles: list = field(default_factory=list)
    seeds: list = field(default_factory=list)
    metrics: list = field(default_factory=list)
    """The task's metrics at the end of each episode."""
    seconds: float = 0.0

    @property
    def n(self) -> int:
        return len(self.returns)

    def summary(self) -> dict:
        """The measures over this run's episodes, with 95 % intervals: Wilson for the success
        rate, Student t for the mean return and the mean cycles to success (over the successful
        episodes; the interval's lower end cut at 0). ``*_ci`` are the t half-widths."""
        mean, half = mean_ci(self.returns)
        k = int(sum(self.successes))
        lo, hi = wilson(k, self.n)
        won = [c for c, s in zip(self.cycles, self.successes) if s]
        c_mean, c_half = mean_ci(won)
        return {
            "task": self.task,
            "policy": self.policy,
            "kind": self.kind,
            "level": self.level,
            "training_seeds": 1 if self.kind in ("learned", "evolved") else 0,
            "episodes": self.n,
            "interval": "wilson, t",
            "return_mean": mean,
            "return_ci": half,
            "return_lo": mean - half,
            "return_hi": mean + half,
            "successes": k,
            "success_rate": k / self.n if self.n else 0.0,
            "success_lo": lo,
            "success_hi": hi,
            "cycles_to_success": c_mean,
            "cycles_ci": c_half,
            "cycles_lo": float(np.maximum(0.0, c_mean - c_half)),
            "cycles_hi": c_mean + c_half,
            "mean_cycles": float(np.mean(self.cycles)) if self.cycles else float("nan"),
            "seconds": self.seconds,
        }


@dataclass
class GroupResult:
    """The runs of one configuration trained with several seeds, summarised across them."""

    runs: list
    """The :class:`PolicyResult` of each training seed."""
    label: str

    @property
    def task(self) -> str:
        return self.runs[0].task

    @property
    def kind(self) -> str:
        return self.runs[0].kind

    @property
    def level(self) -> str:
        return self.runs[0].level

    @property
    def n(self) -> int:
        return sum(r.n for r in self.runs)

    def summary(self) -> dict:
        """The measures pooled over every episode of every training seed, with the intervals of
        a stratified bootstrap (:func:`training.statistics.group_bootstrap`: training seeds, then
        their episodes, drawn with replacement): success rate (successes over episodes; the
        interval widened to at least the pooled Wilson interval, as a percentile bootstrap
        collapses to a point where every episode agrees), mean return and mean cycles to success
        (over the successful episodes). A group of one run is summarised as that run."""
        per_run = [r.summary() for r in self.runs]
        if len(self.runs) == 1:
            return {**per_run[0], "policy": self.label}
        boot = group_bootstrap(
            [r.successes for r in self.runs], [r.cycles for r in self.runs], [r.returns for r in self.runs]
        )
        k = sum(s["successes"] for s in per_run)
        lo, hi = wilson(k, self.n)
        return {
            "task": self.task,
            "policy": self.label,
            "kind": self.kind,
            "level": self.level,
            "training_seeds": len(self.runs),
            "episodes": self.n,
            "interval": "stratified bootstrap",
            "return_mean": boot["return_mean"],
            "return_ci": float("nan"),
            "return_lo": boot["return_lo"],
            "return_hi": boot["return_hi"],
            "successes": k,
            "success_rate": boot["success_rate"],
            "success_lo": min(lo, boot["success_lo"]),
            "success_hi": max(hi, boot["success_hi"]),
            "cycles_to_success": boot["cycles_to_success"],
            "cycles_ci": float("nan"),
            "cycles_lo": boot["cycles_lo"],
            "cycles_hi": boot["cycles_hi"],
            "mean_cycles": float(np.mean([c for r in self.runs for c in r.cycles])),
            "seconds": sum(s["seconds"] for s in per_run),
        }


def grouped(results: list[PolicyResult]) -> list:
    """The results with the runs of each training-seed group replaced by one :class:`GroupResult`
    (at the place of the group's first run)."""
    out, seen = [], {}
    for r in results:
        if not r.group:
            out.append(r)
        elif (r.task, r.group) in seen:
            seen[(r.task, r.group)].runs.append(r)
        else:
            seen[(r.task, r.group)] = GroupResult(runs=[r], label=r.group)
            out.append(seen[(r.task, r.group)])
    return out


def _fmt(x: float, digits: int = 3) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def _finite(*xs) -> bool:
    return all(x is not None and np.isfinite(x) for x in xs)


def interval(value: float, lo: float, hi: float, digits: int = 3) -> str:
    """``value (lo–hi)``, e.g. ``120 (95–150)``; ``lo to hi`` where ``lo`` is negative; the value
    alone without a finite interval; ``–`` without a value."""
    if not _finite(value):
        return "–"
    if not _finite(lo, hi):
        return _fmt(value, digits)
    a, b = _fmt(lo, digits), _fmt(hi, digits)
    return f"{_fmt(value, digits)} ({a}{' to ' if a.startswith('-') else '–'}{b})"


def success_cell(s: dict) -> str:
    """Successes over episodes and the 95 % interval of the rate: ``24/30 (0.63–0.90)``."""
    return f"{s['successes']}/{s['episodes']} ({_fmt(s['success_lo'], 2)}–{_fmt(s['success_hi'], 2)})"


def cycles_cell(s: dict) -> str:
    """Mean cycles to success and its 95 % interval (``–`` without a success): ``120 (95–150)``."""
    return "–" if not s["successes"] else interval(s["cycles_to_success"], s["cycles_lo"], s["cycles_hi"], 0)


def markdown_table(results: list) -> str:
    """The results as one markdown table (one row per task and policy or training-seed group).

    Every measure is ``value (low–high)``, its 95 % interval (see :data:`INTERVALS`): return and
    cycles to success are means, success is successes over episodes then the interval of the rate.
    A group's values are pooled over its training seeds and its intervals come from the
    stratified bootstrap.
    """
    head = [
        "task",
        "policy",
        "kind",
        "level",
        "training seeds",
        "episodes",
        "return (95 % CI)",
        "success (95 % CI)",
        "cycles to success (95 % CI)",
        "seconds",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in results:
        s = r.summary()
        ret = interval(s["return_mean"], s["return_lo"], s["return_hi"], 3)
        lines.append(
            f"| {s['task']} | {s['policy']} | {s['kind']} | {s['level']} | {s['training_seeds'] or '–'} | "
            f"{s['episodes']} | {ret} | {success_cell(s)} | {cycles_cell(s)} | {s['seconds']:.1f} |"
        )
    return "\n".join(lines)


def plot(results: list[PolicyResult], path: Path) -> None:
    """One row per task: mean return, success rate and cycles to success per policy, with 95 % intervals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def errors(values, summaries, lo, hi):
        """Asymmetric error bars (0 where an interval is undefined)."""
        return np.array(
            [
                [v - s[lo] if _finite(v, s[lo]) else 0.0, s[hi] - v if _finite(v, s[hi]) else 0.0]
                for v, s in zip(values, summaries)
            ]
        ).T

    tasks = list(dict.fromkeys(r.task for r in results))
    fig, axes = plt.subplots(len(tasks), 3, figsize=(13, 2.8 * len(tasks) + 0.6), squeeze=False)
    for row, task in zip(axes, tasks):
        rs = [r.summary() for r in results if r.task == task]
        names = [s["policy"] for s in rs]
        y = np.arange(len(rs))
        colours = [
            {"hand-coded": "tab:green", "random": "tab:gray", "learned": "tab:blue", "evolved": "tab:orange"}.get(
                s["kind"], "tab:purple"
            )
            for s in rs
        ]
        ret = [s["return_mean"] for s in rs]
        row[0].barh(y, ret, xerr=errors(ret, rs, "return_lo", "return_hi"), color=colours)
        row[0].set_title(f"{task}: mean return")
        rate = [s["success_rate"] for s in rs]
        row[1].barh(y, rate, xerr=errors(rate, rs, "success_lo", "success_hi"), color=colours)
        row[1].set_xlim(0, 1.05)
        row[1].set_title(f"{task}: success rate")
        cyc = [s["cycles_to_success"] if s["successes"] else 0.0 for s in rs]
        err = errors(cyc, rs, "cycles_lo", "cycles_hi") * np.array([[s["successes"] > 0 for s in rs]])
        row[2].barh(y, cyc, xerr=err, color=colours)
        row[2].set_title(f"{task}: cycles to success (0: none)")
        for ax in row:
            ax.set_yticks(y, names if ax is row[0] else [""] * len(y))
            ax.invert_yaxis()
            ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


CONFIG_KEYS = ("first_seed", "seeds", "tasks")
"""The keys of an eval config."""
TASK_KEYS = ("checkpoints", "env", "task")
"""The keys of a task's entry under ``tasks``."""
GROUP_KEYS = ("label", "runs")
"""The keys of a training-seed group under a task's ``checkpoints``."""


def load_config(path) -> dict:
    """The eval config as ``{"seeds", "first_seed", "tasks": {name: {"task", "env", "checkpoints"}}}``
    (``task``: an optional version of the name, such as ``branch-v0``; without it the newest).

    Bad input is one :class:`ConfigError` naming the field, the value and what is allowed, raised
    before anything runs or is written: an unknown key at the top (:data:`CONFIG_KEYS`), a name
    under ``tasks`` that is not an evaluated task, an unknown key in a task's entry
    (:data:`TASK_KEYS`) or in a training-seed group (:data:`GROUP_KEYS`), and values of the
    wrong kind."""
    import difflib

    from proteo_env.config import ConfigError, load_yaml
    from proteo_env.registry import TASKS

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
                f"{where}: tasks.{name} = {entry!r} is not allowed; allowed: a mapping with keys {', '.join(TASK_KEYS)}"
            )
        unknown(f"tasks.{name}", entry, TASK_KEYS)
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


def _name_apart(results: list[PolicyResult]) -> None:
    """Give policies that share a name (two checkpoints of one algorithm) their checkpoint
    folder's name in brackets, so that the table tells them apart."""
    names = [r.policy for r in results]
    for r in results:
        if names.count(r.policy) > 1 and not r.source.startswith("baselines."):
            r.policy = f"{r.policy} ({Path(r.source).name})"


def _picture_png(env, caption: str) -> str:
    """The world of ``env`` as it is now, as a base64-encoded PNG."""
    import base64
    import tempfile

    from proteo_env.render.renderer import Renderer
    from proteo_env.render.scene import Scene

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "picture.png"
        renderer = Renderer()
        renderer.savefig(Scene.from_world(env.world, caption=caption), path)
        renderer.close()
        return base64.b64encode(path.read_bytes()).decode()


@dataclass(frozen=True)
class EpisodeJob:
    """One episode: everything its result depends on (picklable; sent to Ray workers as it is).

    ``policy`` is a registered policy name (``checkpoint=False``) or a checkpoint path;
    ``overrides`` is the JSON of the ``proteo_env.make`` overrides; ``picture`` a caption: when
    not empty the end of the episode is drawn and returned.
    """

    task_id: str
    overrides: str
    level: str
    policy: str
    checkpoint: bool
    seed: int
    policy_seed: int
    deterministic: bool = False
    picture: str = ""

    @property
    def key(self) -> str:
        """The job's name in a journal: task, settings, level, policy and seed."""
        return f"{self.task_id}|{self.overrides}|{self.level}|{self.policy}|{self.seed}"


_BUILT: dict = {}
"""(env, policy) per (task, overrides, level, policy): built once per process, reused across episodes."""


def built(job: EpisodeJob):
    """The environment and policy ``job`` runs (cached per process; at most 4 kept)."""
    spec = (job.task_id, job.overrides, job.level, job.policy, job.checkpoint, job.policy_seed, job.deterministic)
    if spec not in _BUILT:
        import proteo_env
        from baselines import make_policy
        from training.checkpoints import load_policy
        from training.common import limit_threads

        limit_threads(1)
        while len(_BUILT) >= 4:
            _BUILT.pop(next(iter(_BUILT)))[0].close()
        overrides = json.loads(job.overrides)
        env = proteo_env.make(job.task_id, **overrides, **({} if job.level == "full" else {"control": job.level}))
        policy = (
            load_policy(job.policy, env, seed=job.policy_seed, deterministic=job.deterministic)
            if job.checkpoint
            else make_policy(job.policy, env, seed=job.policy_seed)
        )
        _BUILT[spec] = (env, policy)
    return _BUILT[spec]


def run_episode_job(job: EpisodeJob) -> dict:
    """Run one episode: ``{"return", "success", "cycles", "metrics", "seconds", "picture"}`` (JSON-ready)."""
    from proteo_env.rollout import run_episode

    env, policy = built(job)
    started = time.perf_counter()
    episode = run_episode(env, policy, seed=job.seed)
    out = {
        "return": float(episode.total_reward),
        "success": bool(episode.success),
        "cycles": int(episode.cycles),
        "metrics": {k: float(v) for k, v in episode.metrics.items()},
        "seconds": time.perf_counter() - started,
        "picture": None,
    }
    if job.picture:
        out["picture"] = _picture_png(
            env, f"{job.picture} · seed {job.seed} · cycle {episode.cycles}{' · success' if episode.success else ''}"
        )
    return out


def _checkpoint_identity(path) -> str:
    """A hash of a checkpoint's ``proteo.json`` (it changes whenever the checkpoint is written again)."""
    import hashlib

    from training.common import META_FILE, checkpoint_dir

    return hashlib.sha256((checkpoint_dir(path) / META_FILE).read_bytes()).hexdigest()[:16]


def evaluate(
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
    fresh: bool = False,
) -> list:
    """Run the comparison and write ``results.md``, ``results.json`` and ``eval.png`` into ``out``.

    Every episode is one :class:`EpisodeJob`, run serially or as a Ray task (``ray``), and
    recorded in ``out/episodes.jsonl`` as it finishes; rerunning an interrupted evaluation with
    the same settings resumes it (see :class:`training.distributed.Journal`). The tables are
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
        ray: ``None`` (serial) or ``{"address", "workers"}`` (:func:`training.distributed.ray_options`).
        fresh: discard the episodes of an unfinished earlier run in ``out`` instead of resuming it.

    Returns:
        one :class:`PolicyResult` per policy, or :class:`GroupResult` per training-seed group.

    It chooses the tasks and checkpoints, then plans every episode (:func:`plan_episodes`), runs
    them (:func:`run_episodes`) and writes the tables (:func:`write_results`).
    """
    from proteo_env.config import ConfigError
    from proteo_env.registry import newest_tasks, task_class
    from training.checkpoints import read_meta
    from training.distributed import Journal

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

    results, jobs = plan_episodes(cfg, classes, by_task, seed_list, deterministic=deterministic, pictures=pictures)

    out_dir = Path(out)
    settings = {c.name: (cfg["tasks"].get(c.name) or {}).get("env") or {} for c in classes}
    fingerprint = {
        "seeds": seed_list,
        "settings": settings,
        "deterministic": deterministic,
        "pictures": pictures,
        "jobs": len(jobs),
        "checkpoints": {p: _checkpoint_identity(p) for ps in by_task.values() for p, _ in ps},
    }
    journal = Journal(out_dir / "episodes.jsonl", fingerprint, fresh=fresh, what="evaluation")
    run_episodes(results, jobs, out_dir, ray=ray, journal=journal, progress=progress)
    rows = write_results(
        results, out_dir, seed_list=seed_list, settings=settings, deterministic=deterministic, plots=plots
    )
    journal.complete()
    return rows


def plan_episodes(cfg: dict, classes, by_task: dict, seed_list: list, *, deterministic: bool, pictures: bool):
    """Every policy's result row and its episodes as jobs: ``(results, jobs)``, ``jobs`` a list of
    ``(row in results, EpisodeJob)``. Policies are built here once, so that a bad checkpoint fails
    before any episode runs.

    Args:
        cfg: the eval config (:func:`load_config`); classes: the task classes evaluated;
        by_task: ``{task name: [(checkpoint path, training-seed group label or "")]}``;
        seed_list: the episodes' seeds; deterministic, pictures: as for :func:`evaluate`.
    """
    import proteo_env
    from baselines import make_policy
    from training.checkpoints import load_policy, read_meta

    results: list[PolicyResult] = []
    jobs: list[tuple[int, EpisodeJob]] = []
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
                source = f"baselines.{name}"
            else:
                meta = read_meta(path)
                policy = load_policy(path, env, seed=seed_list[0], deterministic=deterministic)
                kind = "evolved" if meta["algorithm"].startswith("cma") else "learned"
                source = str(path)
            first_of_group = not group or not any(r.group == group and r.task == cls.task_id() for r in results)
            label = group or (policy.name if path is None else Path(path).name)
            results.append(
                PolicyResult(task=cls.task_id(), policy=policy.name, kind=kind, source=source, level=level, group=group)
            )
            for seed in seed_list:
                picture = (
                    f"{cls.task_id()} · {label} ({level})"
                    if pictures and seed == seed_list[0] and first_of_group
                    else ""
                )
                jobs.append(
                    (
                        len(results) - 1,
                        EpisodeJob(
                            task_id=cls.task_id(),
                            overrides=json.dumps(overrides, sort_keys=True),
                            level=level,
                            policy=name if path is None else str(path),
                            checkpoint=path is not None,
                            seed=seed,
                            policy_seed=seed_list[0],
                            deterministic=deterministic,
                            picture=picture,
                        ),
                    )
                )
        for env in envs.values():
            env.close()
        _name_apart([r for r in results[first_task_row:] if not r.group])
    return results, jobs


def run_episodes(results: list, jobs: list, out_dir: Path, *, ray, journal, progress: bool) -> None:
    """Run the planned ``jobs`` (serially or on Ray, recorded in ``journal``) and add each
    episode to its row of ``results``; pictures go to ``out_dir/pictures``."""
    import base64

    from training.distributed import run_jobs

    episodes = run_jobs(
        run_episode_job,
        [j for _, j in jobs],
        [j.key for _, j in jobs],
        ray=ray,
        journal=journal,
        desc="episodes",
        progress=progress,
    )
    for (row, job), episode in zip(jobs, episodes):
        result = results[row]
        result.returns.append(episode["return"])
        result.successes.append(episode["success"])
        result.cycles.append(episode["cycles"])
        result.seeds.append(job.seed)
        result.metrics.append(episode["metrics"])
        result.seconds += episode["seconds"]
        if episode["picture"]:
            file = (
                out_dir
                / "pictures"
                / (
                    f"{task_name(job.task_id)}_"
                    f"{result.group or (result.policy if not job.checkpoint else Path(job.policy).name)}"
                    f"_{job.level}.png"
                ).replace("+", "-")
            )
            file.parent.mkdir(parents=True, exist_ok=True)
            file.write_bytes(base64.b64decode(episode["picture"]))


def write_results(
    results: list, out_dir: Path, *, seed_list: list, settings: dict, deterministic: bool, plots: bool
) -> list:
    """Write ``results.md``, ``results.json`` and (``plots``) ``eval.png`` into ``out_dir``;
    returns the rows (training-seed groups summarised)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = grouped(results)
    table = markdown_table(rows)
    runs = [r for r in results if r.group]
    per_run = (
        ""
        if not runs
        else (
            "\n\nEach training seed on its own (the rows the groups above summarise):\n\n"
            + markdown_table([dataclasses.replace(r, policy=f"{r.group} ({Path(r.source).name})") for r in runs])
        )
    )
    (out_dir / "results.md").write_text(
        f"{table}{per_run}\n\n{INTERVALS}\n\n"
        f"Seeds {seed_list[0]}..{seed_list[-1]}; settings per task: {json.dumps(settings)}\n"
    )
    (out_dir / "results.json").write_text(
        json.dumps(
            {
                "seeds": seed_list,
                "settings": settings,
                "deterministic": deterministic,
                "results": [{**asdict(r), "summary": r.summary()} for r in results],
                "groups": [
                    {"label": g.label, "task": g.task, "runs": [r.source for r in g.runs], "summary": g.summary()}
                    for g in rows
                    if isinstance(g, GroupResult)
                ],
            },
            indent=1,
            default=float,
        )
    )
    if plots:
        plot(rows, out_dir / "eval.png")
    return rows


def load_results(path) -> tuple[list[PolicyResult], dict]:
    """The episodes of a ``results.json`` that :func:`write_results` wrote:
    ``(results, {"seed_list", "settings", "deterministic"})``, one :class:`PolicyResult` per row
    (its ``summary`` left out: it is computed again). Files from before control levels and
    training-seed groups read with ``level="full"`` and no group. A file that is not such a
    ``results.json`` is a :class:`ConfigError` naming it."""
    from proteo_env.config import ConfigError

    p = Path(path)
    fields = {f.name for f in dataclasses.fields(PolicyResult)}
    try:
        data = json.loads(p.read_text())
        results = [PolicyResult(**{k: v for k, v in row.items() if k in fields}) for row in data["results"]]
        context = {
            "seed_list": list(data["seeds"]),
            "settings": data["settings"],
            "deterministic": data["deterministic"],
        }
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ConfigError(
            f"--from-results={str(p)!r} is not allowed ({type(error).__name__}: {error}); "
            "allowed: a results.json written by proteo eval"
        ) from None
    for r in results:
        lengths = {len(r.returns), len(r.successes), len(r.cycles)}
        if len(lengths) != 1 or not r.returns:
            raise ConfigError(
                f"--from-results={str(p)!r}: the row {r.task} / {r.policy} has returns, successes and cycles of "
                f"lengths {len(r.returns)}, {len(r.successes)}, {len(r.cycles)}; allowed: one of each per episode"
            )
    return results, context


def rerender(path, out, *, plots: bool = True, pages=()) -> list:
    """Write ``results.md``, ``results.json`` and (``plots``) ``eval.png`` into ``out`` from the
    episodes of the ``results.json`` at ``path`` (:func:`load_results`), without running an
    episode, and publish the tables into ``pages`` (:func:`publish`): the tables of an earlier
    evaluation in the current format. Every page is checked before anything is written.
    Returns the rows."""
    results, context = load_results(path)
    texts = published(grouped(results), out, pages)
    rows = write_results(results, Path(out), plots=plots, **context)
    for f, text in texts.items():
        f.write_text(text)
    return rows


PUBLISH_BEGIN = "<!-- proteo eval --out {out} -->"
"""Where the whole table goes (:func:`markdown_table`)."""
PUBLISH_SUMMARY_BEGIN = "<!-- proteo eval --out {out} --summary -->"
"""Where the one-row-per-task summary goes (:func:`summary_table`)."""
PUBLISH_END = "<!-- end of proteo eval table -->"


def summary_table(results: list) -> str:
    """The results as one row per task and one column per policy (the random floor left out;
    the hand-coded policy is the column ``rules``, and ``rules-move`` at the ``move`` level).
    A cell is successes over episodes with the 95 % interval of the success rate, then the mean
    cycles to success with its 95 % interval (where there is a success), e.g.
    ``24/30 (0.63–0.93), 120 (100–142)``; the intervals are those of :func:`markdown_table`
    (the first column's head says so: the summary goes into pages that have no room for
    :data:`INTERVALS`)."""
    columns: dict[str, None] = {}
    cells: dict[str, dict[str, str]] = {}
    for r in results:
        s = r.summary()
        if s["kind"] == "random":
            continue
        column = s["policy"] if s["kind"] != "hand-coded" else "rules" if r.level == "full" else f"rules-{r.level}"
        columns.setdefault(column)
        cycles = f", {cycles_cell(s)}" if s["successes"] else ""
        cells.setdefault(s["task"], {})[column] = f"{success_cell(s)}{cycles}"
    head = ["task (95 % CI)", *columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join([task, *(row.get(c, "–") for c in columns)]) + " |" for task, row in cells.items()]
    return "\n".join(lines)


def publish(results: list, out, files) -> None:
    """Put the results of ``proteo eval --out OUT`` into each of ``files`` (markdown pages):
    the whole table (:func:`markdown_table`) between :data:`PUBLISH_BEGIN` and
    :data:`PUBLISH_END`, the summary (:func:`summary_table`) between
    :data:`PUBLISH_SUMMARY_BEGIN` and :data:`PUBLISH_END`, wherever a page has those markers
    (naming ``OUT``); the whole table is followed by :data:`INTERVALS`. A page with neither is an
    error that says what to add, and nothing is written."""
    for f, text in published(results, out, files).items():
        f.write_text(text)


def published(results: list, out, files) -> dict:
    """``{path: new text}``: what :func:`publish` writes, without writing it (``ValueError``
    for a page without markers)."""
    tables = {
        PUBLISH_BEGIN.format(out=Path(out).as_posix()): f"{markdown_table(results)}\n\n{INTERVALS}",
        PUBLISH_SUMMARY_BEGIN.format(out=Path(out).as_posix()): summary_table(results),
    }
    texts = {}
    for f in map(Path, files):
        text = f.read_text() if f.is_file() else ""
        found = [begin for begin in tables if begin in text and PUBLISH_END in text.split(begin, 1)[1]]
        for begin in found:
            head, rest = text.split(begin, 1)
            text = f"{head}{begin}\n{tables[begin]}\n{PUBLISH_END}{rest.split(PUBLISH_END, 1)[1]}"
        if not found:
            raise ValueError(
                f"--publish {str(f)!r}: no {' or '.join(map(repr, tables))} ... {PUBLISH_END!r} markers; "
                "allowed: a markdown file that has them where the table goes"
            )
        texts[f] = text
    return texts


def refuse_flags(mode: str, flags: dict, why: str, allowed: str) -> None:
    """One :class:`~proteo_env.config.ConfigError` naming the first of ``flags`` (``{flag: value}``)
    that was given with ``mode``, why it is refused and what ``mode`` allows."""
    from proteo_env.config import ConfigError

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
        results = rerender(args.from_results, args.out, plots=not args.no_plots, pages=args.publish or ())
        print(markdown_table(results))
        print(f"\nre-rendered {args.from_results} into {Path(args.out).resolve()}")
        return 0
    config = args.config
    if config is None and Path(DEFAULT_CONFIG).is_file():
        config = DEFAULT_CONFIG
    from training.distributed import ray_options

    results = evaluate(
        config=config,
        tasks=args.tasks.split(",") if args.tasks else None,
        seeds=args.seeds,
        checkpoints=args.checkpoint or (),
        out=args.out,
        deterministic=args.deterministic,
        plots=not args.no_plots,
        pictures=args.pictures,
        ray=ray_options(args),
        fresh=args.fresh,
    )
    if args.publish:
        publish(results, args.out, args.publish)
    print(markdown_table(results))
    print(f"\nresults: {Path(args.out).resolve()}/results.md, results.json" + ("" if args.no_plots else ", eval.png"))
    return 0

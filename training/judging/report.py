"""The results of ``proteo eval`` and their pages: rows, tables, plots and published regions.

:class:`PolicyResult` is one policy (or checkpoint) on one task over its episodes;
:class:`GroupResult` pools the training seeds of one configuration (:func:`grouped`). Every
table prints a measure as ``value (low–high)``, its 95 % interval (:data:`INTERVALS` says
which; the interval code is :mod:`training.judging.statistics`). :func:`write_results` writes
``results.md``, ``results.json`` (every episode) and ``eval.png``; :func:`load_results` and
:func:`rerender` read a ``results.json`` back; :func:`publish` puts the tables into a page
between its markers (:data:`PUBLISH_BEGIN` or :data:`PUBLISH_SUMMARY_BEGIN`, then
:data:`PUBLISH_END`). See :mod:`training.judging.evaluate` for the command.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from training.judging.pages import filled
from training.judging.pages import publish as publish_pages
from training.judging.statistics import group_bootstrap, mean_ci, wilson

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
        a stratified bootstrap (:func:`training.judging.statistics.group_bootstrap`: training seeds, then
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
    tables = page_tables(grouped(results), out)
    texts = {Path(f): filled(f, tables, PUBLISH_END) for f in pages}
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
    """Put the results of ``proteo eval --out OUT`` into each of ``files`` (markdown pages,
    :mod:`training.judging.pages`): the whole table (:func:`markdown_table`, followed by
    :data:`INTERVALS`) between :data:`PUBLISH_BEGIN` and :data:`PUBLISH_END`, the summary
    (:func:`summary_table`) between :data:`PUBLISH_SUMMARY_BEGIN` and :data:`PUBLISH_END`, wherever
    a page has those markers (naming ``OUT``). A page with neither is an error that says what to
    add, and nothing is written."""
    publish_pages(files, page_tables(results, out), PUBLISH_END)


def page_tables(results: list, out) -> dict:
    """``{begin marker: table}`` of the results of ``proteo eval --out OUT``."""
    return {
        PUBLISH_BEGIN.format(out=Path(out).as_posix()): f"{markdown_table(results)}\n\n{INTERVALS}",
        PUBLISH_SUMMARY_BEGIN.format(out=Path(out).as_posix()): summary_table(results),
    }

"""The results of ``proteo eval`` and their pages: rows, tables, plots and published regions.

:class:`Result` is one policy, or one recipe's training seeds, on one task (and split): its
:class:`Run` of episodes per training seed (one for a policy without training seeds) and the
summary measures; ``proteo eval``, the judge and the results page read and write the same
record (its file format is :mod:`training.judging.record`). Every table prints a measure as
``value (low–high)``, its 95 % interval (:data:`INTERVALS` says which; the interval code is
:mod:`training.judging.statistics`); :func:`plot` draws ``eval.png``; :func:`publish_evaluation`
puts the tables into a page between its markers (:data:`PUBLISH_BEGIN` or
:data:`PUBLISH_SUMMARY_BEGIN`, then :data:`PUBLISH_END`). See :mod:`training.judging.evaluate`
for the command.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

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
class Run:
    """The episodes of one policy, or of one checkpoint (one training seed), in the order played."""

    source: str
    """``baselines.<name>`` for a baseline, else the checkpoint's path."""
    training_seed: int | None = None
    """The checkpoint's training seed (``None`` for a baseline)."""
    agent_steps: int | None = None
    """The agent-steps the checkpoint was trained for (``None`` for a baseline)."""
    sha256: str | None = None
    """The SHA-256 of an entrant's file (:mod:`training.machinery.entrants`; ``None`` otherwise)."""
    returns: list = field(default_factory=list)
    successes: list = field(default_factory=list)
    cycles: list = field(default_factory=list)
    seeds: list = field(default_factory=list)
    """The world seed of each episode."""
    metrics: list = field(default_factory=list)
    """The task's metrics at the end of each episode."""
    seconds: float = 0.0

    @property
    def n(self) -> int:
        return len(self.returns)

    @property
    def cycles_to_success(self) -> list:
        """The cycles of the episodes that succeeded, in the order played."""
        return [c for c, s in zip(self.cycles, self.successes) if s]

    def add(self, seed: int, episode: dict) -> None:
        """Add one finished episode played on world ``seed``: ``{"return", "success", "cycles",
        "metrics", "seconds"}`` (:func:`training.judging.episodes.run_alone`)."""
        self.returns.append(episode["return"])
        self.successes.append(episode["success"])
        self.cycles.append(episode["cycles"])
        self.seeds.append(seed)
        self.metrics.append(episode["metrics"])
        self.seconds += episode["seconds"]


@dataclass
class Result:
    """One policy on one task (and, under a benchmark protocol, one split): its runs and the
    summary measures, the one record of ``proteo eval``, ``proteo eval --benchmark`` and the
    results page.

    A policy without training seeds (the rules, random, one checkpoint) has one run; a recipe's
    training seeds (a ``{label, runs}`` group of an eval config, a protocol's entrant) have one
    run each, summarised together (:meth:`summary`).
    """

    task: str
    policy: str
    """The row's name: the policy's, a group's label, or a protocol's entrant."""
    kind: str
    """``hand-coded``, ``random``, ``learned`` or ``evolved``."""
    level: str = "full"
    """The control level the policy acted at."""
    runs: list = field(default_factory=list)
    """``[Run]``: one per training seed, or the single run."""
    group: bool = False
    """Whether the runs are the training seeds of one configuration, named :attr:`policy` (a group
    of one run included; ``results.md`` lists them one by one under the groups)."""
    split: str = ""
    """The protocol split (``""`` outside a benchmark)."""
    about: str = ""
    """What the split asks (``""`` outside a benchmark)."""
    env: dict = field(default_factory=dict)
    """The :func:`proteo_env.make` settings of its episodes (an evaluation: its config's settings)."""
    recipe: str | None = None
    """The protocol recipe its checkpoints ran (``None``: not a recipe's)."""
    complete: bool = True
    """Judged on every world and training seed its protocol asks for."""
    recorded: dict | None = None
    """The summary a written row holds, as it was judged; :meth:`summary` returns it rather than
    computing it again."""
    training: str | None = None
    """Under a benchmark protocol, how its training is known (a ``benchmark.json`` row's
    ``training``: ``reference``, ``protocol``, ``declared``, ``undeclared`` or ``unchecked``);
    ``None`` outside one."""
    declared: dict | None = None
    """An entrant's declared training (``name``, ``training_seeds``, ``budget``, ``code``)."""

    @property
    def max_cycles(self) -> int | None:
        """The episodes' cycle limit where its settings give it: a failure's time in a paired
        comparison."""
        value = self.env.get("max_cycles")
        return None if value is None else int(value)

    @property
    def entered(self) -> bool:
        """Whether it is an entrant or a checkpoint whose training the protocol did not check (the
        results page lists these apart from the recipes)."""
        return self.training in ("declared", "undeclared", "unchecked")

    @property
    def n(self) -> int:
        return sum(r.n for r in self.runs)

    @property
    def world_seeds(self) -> list:
        """The world seed of each episode (every run plays the same worlds)."""
        return self.runs[0].seeds

    @property
    def rates(self) -> np.ndarray:
        """``(runs,)``: each run's success rate."""
        return np.array([np.mean(r.successes) for r in self.runs])

    def rates_on_first(self, n: int) -> np.ndarray:
        """``(runs,)``: each run's success rate on its first ``n`` worlds."""
        return np.array([np.mean(r.successes[:n]) for r in self.runs])

    def each_run(self) -> list[Result]:
        """One result per run, named ``policy (checkpoint folder)``: a group's training seeds one by one."""
        return [
            dataclasses.replace(self, policy=f"{self.policy} ({Path(r.source).name})", runs=[r], recorded=None)
            for r in self.runs
        ]

    def summary(self) -> dict:
        """The measures with 95 % intervals (:data:`INTERVALS`).

        One run: Wilson for the success rate, Student t for the mean return and the mean cycles
        to success (over the successful episodes; the interval's lower end cut at 0); ``*_ci``
        are the t half-widths. Several runs: pooled over every episode of every run, with the
        intervals of a stratified bootstrap (:func:`training.judging.statistics.group_bootstrap`:
        training seeds, then their episodes, drawn with replacement); the success interval is
        widened to at least the pooled Wilson interval, as a percentile bootstrap collapses to a
        point where every episode agrees.
        """
        if self.recorded is not None:
            return self.recorded
        k = int(sum(sum(r.successes) for r in self.runs))
        lo, hi = wilson(k, self.n)
        head = {"task": self.task, "policy": self.policy, "kind": self.kind, "level": self.level}
        if len(self.runs) == 1:
            (run,) = self.runs
            mean, half = mean_ci(run.returns)
            won = run.cycles_to_success
            c_mean, c_half = mean_ci(won)
            return {
                **head,
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
                "mean_cycles": float(np.mean(run.cycles)) if run.cycles else float("nan"),
                "seconds": run.seconds,
            }
        boot = group_bootstrap(
            [r.successes for r in self.runs], [r.cycles for r in self.runs], [r.returns for r in self.runs]
        )
        return {
            **head,
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
            "seconds": sum(r.seconds for r in self.runs),
        }


def _fmt(x: float, digits: int = 3) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def _finite(*xs) -> bool:
    return all(x is not None and np.isfinite(x) for x in xs)


def span(lo: float, hi: float, digits: int = 3, dash: str = "–") -> str:
    """An interval ``lo–hi`` (``lo to hi`` where ``lo`` is negative); ``dash`` alone where it is
    not finite. The results page and the README write ``dash="-"``."""
    if not _finite(lo, hi):
        return dash
    a, b = _fmt(lo, digits), _fmt(hi, digits)
    return f"{a}{' to ' if a.startswith('-') else dash}{b}"


def interval(value: float, lo: float, hi: float, digits: int = 3) -> str:
    """``value (lo–hi)``, e.g. ``120 (95–150)``; ``lo to hi`` where ``lo`` is negative; the value
    alone without a finite interval; ``–`` without a value."""
    if not _finite(value):
        return "–"
    if not _finite(lo, hi):
        return _fmt(value, digits)
    return f"{_fmt(value, digits)} ({span(lo, hi, digits)})"


def success_cell(s: dict, dash: str = "–") -> str:
    """Successes over episodes and the 95 % interval of the rate: ``24/30 (0.63–0.90)``."""
    return f"{s['successes']}/{s['episodes']} ({span(s['success_lo'], s['success_hi'], 2, dash)})"


def cycles_cell(s: dict) -> str:
    """Mean cycles to success and its 95 % interval (``–`` without a success): ``120 (95–150)``."""
    return "–" if not s["successes"] else interval(s["cycles_to_success"], s["cycles_lo"], s["cycles_hi"], 0)


def row_label(r: Result) -> str:
    """A row's name: an entrant's (or an unchecked checkpoint's) with how its training is known after it."""
    return f"{r.policy} ({r.training})" if r.entered else r.policy


def _worlds_cell(r: Result) -> str:
    seeds = r.world_seeds
    return f"{len(seeds)} ({seeds[0]}..{seeds[-1]})" if seeds else "0"


COLUMNS = {
    "task": lambda r, s: r.task,
    "split": lambda r, s: r.split,
    "policy": lambda r, s: row_label(r),
    "kind": lambda r, s: r.kind,
    "level": lambda r, s: r.level,
    "training seeds": lambda r, s: str(len(r.runs)) if r.kind in ("learned", "evolved") else "–",
    "worlds": lambda r, s: _worlds_cell(r),
    "episodes": lambda r, s: str(s["episodes"]),
    "return (95 % CI)": lambda r, s: interval(s["return_mean"], s["return_lo"], s["return_hi"], 3),
    "success (95 % CI)": lambda r, s: success_cell(s),
    "cycles to success (95 % CI)": lambda r, s: cycles_cell(s),
    "seconds": lambda r, s: f"{s['seconds']:.1f}",
}
"""Every column a table of results may have: its head and its cell of a row ``r`` with summary ``s``."""
EVALUATION_COLUMNS = ("task", "policy", "kind", "level", "training seeds", "episodes", "return (95 % CI)",
                      "success (95 % CI)", "cycles to success (95 % CI)", "seconds")  # fmt: skip
"""The columns of ``proteo eval``'s tables (``results.md``, the published regions)."""
BENCHMARK_COLUMNS = ("task", "split", "policy", "kind", "level", "training seeds", "worlds", "success (95 % CI)",
                     "cycles to success (95 % CI)", "return (95 % CI)")  # fmt: skip
"""The columns of a judgement's table (``benchmark.md``)."""


def markdown_table(results: list, columns=EVALUATION_COLUMNS) -> str:
    """The results as one markdown table (one row per :class:`Result`), the ``columns`` of
    :data:`COLUMNS`: every table of ``proteo eval`` and ``proteo eval --benchmark``.

    Every measure is ``value (low–high)``, its 95 % interval (see :data:`INTERVALS`): return and
    cycles to success are means, success is successes over episodes then the interval of the rate.
    A group's values are pooled over its training seeds and its intervals come from the
    stratified bootstrap.
    """
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in results:
        s = r.summary()
        lines.append("| " + " | ".join(COLUMNS[c](r, s) for c in columns) + " |")
    return "\n".join(lines)


def plot(results: list[Result], path: Path) -> None:
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


def publish_evaluation(results: list, out, files) -> None:
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

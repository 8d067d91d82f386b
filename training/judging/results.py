"""The results page: every controller judged under a benchmark protocol, on one page.

    python -m training.judging.results --benchmark v9 --publish README.md --marl-eval docs/results/marl_eval.json  # make results
    python -m training.judging.results --benchmark v6 --root docs/benchmark --out docs/benchmark/v6/results.md

It reads every ``benchmark.json`` that ``proteo eval --benchmark VERSION`` wrote under
``ROOT/VERSION/`` (one folder per task and policy, :mod:`training.judging.judge`) and the training
progress of the protocol's learned runs (``ROOT/VERSION/learning/progress/<recipe>_<task>_<level>_s<k>.csv``,
written by ``python -m training.trainers.study --keep-dir checkpoints/VERSION --docs-dir ROOT/VERSION/learning``),
and writes ``OUT`` (markdown) with its figures in ``OUT``'s folder under ``results/``:

- a short answer at the top, in sentences that say only what a paired comparison supports:
  each recipe against the rules at its own control level (``rules-move`` for ``move``) on the
  same worlds (:func:`paired`), the difference in success rate with the 95 % interval of a
  bootstrap over training seeds and worlds jointly; a difference is claimed only where that
  interval excludes 0, otherwise "no detectable difference" with the interval; cycles are
  compared on the worlds where both succeeded;
- where one more training seed of each recipe should land on each split: the prediction
  intervals of its success rate and its mean cycles to success from its seeds' values
  (:func:`new_seed_lines`), what a rerun on seeds nobody used is held to;
- per task, one table: a row per policy, a column per split, each cell the successes with the
  95 % interval of the success rate and the mean cycles to success with its interval (Wilson
  and Student t for one run, the stratified bootstrap over training seeds and worlds for a
  learned recipe: :mod:`training.judging.statistics`);
- where the protocol has scale splits (``x10``, ``x100``), success and cycles against size, task by
  task, with each recipe's paired difference from the rules at each size and a log-scale figure
  (``results/scale.png``, :func:`scale_section`);
- the aggregate per task (every recipe of a task over the same splits; never over a recipe's
  own mix of tasks), after rliable: the interquartile mean of the normalised score (rules at
  ``full`` = 1, random = 0, on the 100 reference worlds) over training seeds x splits with its
  bootstrap interval; the probability that a training seed beats the rules at its level on the
  same worlds (the worlds the recipe played), ties reported apart; performance
  profiles per task (``results/profiles.png``); the bootstraps draw whole training seeds, since
  a seed's splits share its checkpoint;
- learning curves: the training success rate against agent-steps, the mean over training seeds
  with a 95 % t band (``results/curves_<task>.png``).

Every number comes from the files; nothing is typed in.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import re
from collections import defaultdict
from pathlib import Path

import numpy as np

from proteo_env.config import ConfigError
from training.judging import record
from training.judging import statistics as st
from training.judging.pages import filled
from training.judging.pages import publish as publish_pages
from training.judging.plots import plot_mean_band, read_progress
from training.judging.protocol import load_protocol
from training.judging.report import Result, row_label, span, success_cell
from training.machinery.checkpoints import RULES

RULES_MOVE, RANDOM = "rules-move", "random"
"""The policy names of the reference rows in ``benchmark.json`` besides :data:`RULES` (the rules at the
task's own level)."""
REFERENCE_NAMES = {RULES: "the rules", RULES_MOVE: "the rules at move"}
DEFAULT_OUT = "docs/results.md"
"""The published results page (``make results``)."""
"""How a sentence names each reference."""


def read_rows(root: Path, lineage) -> tuple[list[Result], list[dict]]:
    """Every row of every ``benchmark.json`` below ``root/<version>`` for each ``(version,
    sha256)`` of a protocol's :attr:`~training.judging.protocol.Protocol.lineage`, and each file's
    header. A file judged under another protocol, or under a protocol file that has changed
    since (its ``protocol_sha256``), or one that is not complete (fewer training seeds or worlds
    than the protocol asks, a ``--worlds-cap``), or a row judged in two files (the same task, split
    and policy), is a :class:`ConfigError`: nothing is published from it."""
    rows, headers, judged_in = [], [], {}
    shas = dict(lineage)
    files = [f for version in shas for f in sorted((root / version).rglob("benchmark.json"))]
    if not files:
        raise ConfigError(
            f"benchmark folders {', '.join(str(root / v) for v in shas)} hold no benchmark.json; allowed: folders "
            "written by proteo eval --benchmark VERSION --out ROOT/VERSION/<task>/<policy>"
        )
    for file in files:
        data = record.load(file, field="benchmark file")
        judged_by = (data.get("protocol"), data.get("protocol_sha256"))
        if shas.get(judged_by[0]) != judged_by[1]:
            raise ConfigError(
                f"{file}: protocol {judged_by[0]!r} with sha256 {str(judged_by[1])[:12]} is not allowed; allowed: "
                + ", ".join(f"{v} with sha256 {h[:12]}" for v, h in shas.items())
                + " (the protocol files as they are now: judge it again)"
            )
        if data.get("complete") is not True or data.get("worlds_cap") is not None:
            raise ConfigError(
                f"{file}: complete = {data.get('complete')!r}, worlds_cap = {data.get('worlds_cap')!r} is not allowed; "
                "allowed: a complete judgement (every training seed the protocol asks for, on every world, no "
                f"--worlds-cap; its notes: {'; '.join(data.get('notes') or []) or 'none'})"
            )
        headers.append({k: v for k, v in data.items() if k != "rows"} | {"file": str(file)})
        for r, row in zip(record.results_of(data), data["rows"]):
            key = (row["task_name"], r.split, r.policy)
            if key in judged_in:
                raise ConfigError(
                    f"{file}: the row {' / '.join(key)} is not allowed: {judged_in[key]} holds it already; allowed: each "
                    "task, split and policy judged once (judge a protocol's added splits alone, with --splits)"
                )
            judged_in[key] = file
            rows.append(dataclasses.replace(r, task=row["task_name"]))
    return rows, headers


def _interval(lo: float, hi: float, digits: int = 2) -> str:
    return span(lo, hi, digits, dash="-")


def _successes(s: dict) -> str:
    """``k/n (lo-hi)``: a summary's successes with the interval of the rate."""
    return success_cell(s, dash="-")


def cell(row: Result) -> str:
    """``k/n (lo-hi), c (lo-hi)``: successes with the interval of the rate, cycles with theirs."""
    s = row.summary()
    text = _successes(s)
    if s["successes"]:
        text += f", {s['cycles_to_success']:.0f} ({_interval(s['cycles_lo'], s['cycles_hi'], 0)})"
    return text


def reference_of(row: Result, by_key: dict) -> Result | None:
    """The rules at ``row``'s control level on its task and split: ``rules-move`` for a
    controller at ``move`` where it was judged, else the rules (``full``); None without one."""
    for name in (RULES_MOVE, RULES) if row.level == "move" else (RULES,):
        if (row.task, row.split, name) in by_key:
            return by_key[(row.task, row.split, name)]
    return None


def paired(row: Result, reference: Result, margin: float | None = None) -> dict | None:
    """``row`` against ``reference`` on the worlds both played (each training seed of ``row`` on
    the same worlds; the reference judged once, on those and more): ``{"success", "cycles",
    "time", "worlds", "rate", "reference_rate"}``, each of the first three a
    :func:`training.judging.statistics.paired_difference` (bootstrap over training seeds and worlds
    jointly): the success rate; cycles to success on the pairs where both succeeded; and the time
    to success counting a failure at the cycle limit. With a ``margin`` (the protocol's
    ``equivalence_margin``) also ``"equivalence"``: two one-sided tests that the success rates
    differ by less than it (:func:`training.judging.statistics.equivalence`). None when ``row`` played a
    world the reference did not."""
    column = {seed: i for i, seed in enumerate(reference.world_seeds)}
    if any(seed not in column for seed in row.world_seeds):
        return None
    at = [column[seed] for seed in row.world_seeds]
    n = len(at)
    won = np.array([run.successes[:n] for run in row.runs], dtype=bool)
    cycles = np.array([run.cycles[:n] for run in row.runs], dtype=float)
    won_ref = np.asarray(reference.runs[0].successes, dtype=bool)[at]
    cycles_ref = np.asarray(reference.runs[0].cycles, dtype=float)[at]
    return {
        "equivalence": None if margin is None else st.equivalence(won, won_ref, margin),
        "success": st.paired_difference(won, won_ref),
        "cycles": st.paired_difference(cycles, cycles_ref, won & won_ref[None, :]),
        "time": st.paired_difference(
            np.where(won, cycles, row.max_cycles), np.where(won_ref, cycles_ref, reference.max_cycles)
        ),
        "worlds": n,
        "rate": float(won.mean()),
        "reference_rate": float(won_ref.mean()),
    }


def _difference(d: dict, digits: int = 2) -> str:
    return f"{d['difference']:+.{digits}f} ({d['lo']:+.{digits}f} to {d['hi']:+.{digits}f})"


def detectable(d: dict) -> bool:
    """Whether a :func:`~training.judging.statistics.paired_difference`'s interval excludes 0."""
    return bool(d["pairs"]) and (d["lo"] > 0 or d["hi"] < 0)


def matches(pair: dict) -> bool:
    """Whether the two one-sided tests of a :func:`paired` comparison say the success rates match."""
    return pair["equivalence"] is not None and pair["equivalence"]["equivalent"]


def compare(name: str, row: Result, reference: Result, margin: float | None = None) -> str:
    """One sentence comparing a learned or evolved recipe with the rules at its level on a split,
    from the paired differences (:func:`paired`; "matches" only within the protocol's
    equivalence ``margin``)."""
    return _sentence(name, reference, paired(row, reference, margin), margin)


def _sentence(name: str, reference: Result, pair: dict | None, margin: float | None) -> str:
    """:func:`compare`'s sentence from the :func:`paired` comparison ``pair`` with ``reference``."""
    if pair is None:
        return f"{name}: not judged on the reference's worlds"
    against = f"{REFERENCE_NAMES.get(reference.policy, reference.policy)} on the same {pair['worlds']} worlds"
    rates = f"{pair['rate']:.2f} against {pair['reference_rate']:.2f}"
    success = pair["success"]
    if detectable(success):
        verdict = "above" if success["difference"] > 0 else "below"
        text = f"{name} succeeds {verdict} {against}: {rates}, difference {_difference(success)}"
    elif matches(pair):
        tost = pair["equivalence"]
        text = (
            f"{name} matches the success of {against} within the protocol's margin of {margin:.2f}: {rates}, "
            f"difference {_difference(success)}; 90 % interval {tost['lo']:+.2f} to {tost['hi']:+.2f} "
            "(two one-sided tests)"
        )
    else:
        text = f"{name}: no detectable difference in success from {against}: {rates}, difference {_difference(success)}"
    cycles = pair["cycles"]
    if cycles["pairs"] >= 2 and detectable(cycles):
        faster = "fewer" if cycles["difference"] < 0 else "more"
        text += f"; in {faster} cycles where both succeed, {_difference(cycles, 0)}"
    time = pair["time"]
    if detectable(time):
        sooner = "sooner" if time["difference"] < 0 else "later"
        text += f"; done {sooner} counting a failure at the cycle limit, {_difference(time, 0)} cycles"
    return text


def verdicts(task: str, recipe: str, by_key: dict, splits: list[str], margin: float | None = None) -> str:
    """Where a recipe's success lies detectably above or below the rules' at its level on
    ``splits`` (paired, :func:`paired`), where it matches them within the equivalence ``margin``,
    and where no difference is detectable, in a few words."""
    above, below, match, same = [], [], [], []
    for split in splits:
        row = by_key.get((task, split, recipe))
        reference = reference_of(row, by_key) if row is not None else None
        pair = paired(row, reference, margin) if reference is not None else None
        if pair is None:
            continue
        success = pair["success"]
        if detectable(success):
            text = f"{split} ({success['difference']:+.2f}, {success['lo']:+.2f} to {success['hi']:+.2f})"
            (above if success["difference"] > 0 else below).append(text)
        elif matches(pair):
            match.append(split)
        else:
            same.append(split)
    parts = [f"above the rules on {', '.join(above)}"] if above else []
    parts += [f"below them on {', '.join(below)}"] if below else []
    parts += [f"matching them within {margin:.2f} on {', '.join(match)}"] if match else []
    parts += [f"no detectable difference on {', '.join(same)}"] if same else []
    return "; ".join(parts)


SCALE_SPLIT = re.compile(r"x\d+")
"""The names of scale splits: ``x10``, ``x100`` (the factor over the training size)."""


def aggregate(rows: list[Result]) -> dict[tuple[str, str], dict]:
    """Per learned or evolved recipe and task, over the task's splits but the scale splits (every
    recipe of the task is judged on those, so recipes of one task are compared over the same set;
    the scale splits have their own section, :func:`scale_section`): normalised scores
    ``(training seeds, splits)``, their IQM, and the probability that a training seed beats the
    rules at its level on the same worlds (the worlds the recipe played), ties apart. The
    bootstraps draw whole training seeds (a seed's splits share its checkpoint)."""
    by_key = {(r.task, r.split, r.policy): r for r in rows}
    out = {}
    for recipe in sorted({r.policy for r in rows if r.kind in ("learned", "evolved")}):
        for task in dict.fromkeys(r.task for r in rows if r.policy == recipe):
            splits = [r.split for r in rows if r.task == task and r.policy == recipe]
            splits = [
                s
                for s in splits
                if not SCALE_SPLIT.fullmatch(s) and (task, s, RULES) in by_key and (task, s, RANDOM) in by_key
            ]
            if not splits:
                continue
            learned = [by_key[(task, s, recipe)] for s in splits]
            references = [reference_of(row, by_key) for row in learned]
            n_runs = min(len(r.runs) for r in learned)
            rates = np.stack([r.rates[:n_runs] for r in learned], axis=1)  # (runs, splits)
            rules = np.array([by_key[(task, s, RULES)].rates[0] for s in splits])
            random = np.array([by_key[(task, s, RANDOM)].rates[0] for s in splits])
            same_worlds = np.array([ref.rates_on_first(len(r.world_seeds))[0] for r, ref in zip(learned, references)])[
                None, :
            ]
            entry = {
                "splits": splits,
                "scores": st.normalized_score(rates, random, rules),
                "training_seeds": n_runs,
                "reference": references[0].policy,
            }
            try:
                entry["iqm"] = st.iqm_ci(entry["scores"], joint=True)
                entry["improvement"] = st.probability_of_improvement_ci(rates, same_worlds, ties=0.0, joint=True)
                entry["ties"] = st.probability_of_improvement(rates, same_worlds, ties=1.0) - entry["improvement"][0]
            except ValueError as error:  # no split where the rules and random differ
                entry["error"] = str(error)
            out[(recipe, task)] = entry
    return out


def _profiles(agg: dict, tasks: list[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    taus = np.linspace(-0.25, 1.5, 71)
    fig, axes = plt.subplots(1, len(tasks), figsize=(3.2 * len(tasks), 3.4), sharey=True, squeeze=False)
    for ax, task in zip(axes[0], tasks):
        for (recipe, of), entry in agg.items():
            if of != task:
                continue
            profile, lo, hi = st.performance_profile(entry["scores"], taus, joint=True)
            ax.plot(taus, profile, label=recipe)
            ax.fill_between(taus, lo, hi, alpha=0.2)
        ax.axvline(1.0, color="grey", linestyle="--", linewidth=0.8)
        ax.set_title(task)
        ax.set_xlabel("normalised score tau")
        ax.legend(fontsize=6)
    axes[0][0].set_ylabel("fraction of seeds x splits above tau")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def curves(progress: Path, task: str) -> dict[str, list[np.ndarray]]:
    """Per recipe of ``task``: the training seeds' ``(agent_steps, success)`` arrays."""
    found = defaultdict(list)
    for csv in sorted(progress.glob(f"*_{task}_*_s*.csv")):
        recipe = csv.stem.split(f"_{task}_")[0]
        data = read_progress(csv)
        keep = np.isfinite(data["episode/success"])
        found[recipe].append(np.stack([data["agent_steps"][keep], data["episode/success"][keep]]))
    return dict(found)


SMOOTH_ROWS = 5
"""Log rows each point of a learning curve averages (a row's success rate is over few episodes)."""


def _smooth(y: np.ndarray, rows: int) -> np.ndarray:
    """The trailing mean of ``y`` over ``rows`` entries (fewer at the start)."""
    cumulative = np.cumsum(np.insert(y, 0, 0.0))
    counts = np.minimum(np.arange(1, len(y) + 1), rows)
    return (cumulative[1:] - cumulative[np.arange(1, len(y) + 1) - counts]) / counts


def _curve_figure(task: str, found: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.0, 3.4))
    for recipe, runs in sorted(found.items()):
        end = min(r[0, -1] for r in runs)
        grid = np.linspace(max(r[0, 0] for r in runs), end, 60)
        ys = np.stack([np.interp(grid, r[0], _smooth(r[1], SMOOTH_ROWS)) for r in runs])
        plot_mean_band(ax, grid / 1e6, ys, f"{recipe} ({len(runs)} seeds)", clip=(0, 1))
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("agent-steps (millions)")
    ax.set_ylabel(f"training success rate ({SMOOTH_ROWS}-row mean)")
    ax.set_title(task)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def new_seed_lines(rows: list[Result], tasks: list[str]) -> list[str]:
    """The page's section on one more training seed: for every recipe with several training seeds
    and every split, its seeds' success rates and mean cycles to success, and the intervals a new
    seed's should land in (:func:`~training.judging.statistics.new_seed_interval`; a seed that
    never succeeds has no cycles to success and counts only in the success rates)."""
    table = []
    for task in tasks:
        for row in sorted((r for r in rows if r.task == task), key=lambda r: r.policy):  # splits as judged
            if row.kind not in ("learned", "evolved") or len(row.runs) < 2:
                continue
            rates = row.rates
            mean, lo, hi = st.new_seed_interval(rates)
            cycles = [float(np.mean(run.cycles_to_success)) for run in row.runs if any(run.successes)]
            c_mean, c_lo, c_hi = st.new_seed_interval(cycles, bounds=(0.0, np.inf))
            speed = (
                f"{min(cycles):.0f}-{max(cycles):.0f} ({len(cycles)}) | {c_mean:.0f} | {_interval(c_lo, c_hi, 0)}"
                if len(cycles) >= 2
                else "- | - | -"
            )
            table.append(
                f"| {task} | {row.split} | {row.policy} | {len(rates)} | {min(rates):.2f}-{max(rates):.2f} | "
                f"{mean:.2f} | {_interval(lo, hi)} | {speed} |"
            )
    if not table:
        return []
    return [
        "## One more training seed",
        "",
        "The intervals above are about a recipe's seeds taken together and narrow as seeds are added. A rerun "
        "with one training seed nobody used varies as the seeds do: on the same worlds of a split, its success "
        "rate and its mean cycles to success should land in the 95 % prediction intervals below (Student t over "
        "the seeds' values; rates clipped to 0-1; cycles over the seeds that succeed at least once, how many in "
        "brackets).",
        "",
        "| task | split | recipe | training seeds | their success rates | mean | one new seed (95 %) "
        "| their mean cycles to success | mean | one new seed (95 %) |",
        "|---|---|---|---|---|---|---|---|---|---|",
        *table,
        "",
    ]


def _policy_order(policies) -> list[str]:
    first = [p for p in (RULES, RULES_MOVE, RANDOM) if p in policies]
    return first + sorted(p for p in policies if p not in first)


def entrant_lines(entrants: list[Result], rows: list[Result], protocol) -> list[str]:
    """The page's section on the entrants (:attr:`Result.entered`): per entrant and task, its cell on
    every split and its paired difference in success from the rules at its level on the same worlds,
    beside what it declares of its training."""
    if not entrants:
        return []
    by_key = {(r.task, r.split, r.policy): r for r in rows}
    lines = [
        "## Entrants: training declared, not verified",
        "",
        "Policies entered from outside ([entering the benchmark](guides/entering.md)): judged on the same worlds as "
        "the rules, by the same judge; their training seeds, budget and code are as they declare them, and each "
        "judged file's SHA-256 is in its `benchmark.json`. Each cell: successes / worlds (95 % interval), mean cycles "
        "to success; then the difference in success rate from the rules at its level on the same worlds (95 % "
        "interval, training seeds and worlds drawn jointly).",
        "",
        "| entrant | task | level | training | declared budget | code | split | result | minus the rules at its level |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name in sorted({r.policy for r in entrants}):
        for task in dict.fromkeys(r.task for r in entrants if r.policy == name):
            splits = [s.name for s in protocol.tasks[task].splits if (task, s.name, name) in by_key]
            for split in splits:
                row = by_key[(task, split, name)]
                declared = row.declared or {}
                budget = ", ".join(f"{k} {v:,}" for k, v in (declared.get("budget") or {}).items()) or "-"
                reference = reference_of(row, by_key)
                pair = paired(row, reference) if reference is not None else None
                versus = f"{_difference(pair['success'])} ({reference.policy})" if pair else "-"
                head = (
                    [
                        f"{name} ({row.training})",
                        task,
                        row.level,
                        f"{len(row.runs)} seeds",
                        budget,
                        declared.get("code", "-"),
                    ]
                    if split == splits[0]
                    else [""] * 6
                )
                lines.append("| " + " | ".join([*head, split, cell(row), versus]) + " |")
    return [*lines, ""]


def render(rows: list[Result], headers: list[dict], version: str, root: Path, out: Path, protocol) -> str:
    """The page's markdown (figures written beside ``out``); ``protocol`` a
    :class:`training.judging.protocol.Protocol`. Entrants (:attr:`Result.entered`) have a section
    of their own; every other section is the recipes' and references'. In order: the header,
    the short answer and the comparisons with the rules (:func:`short_answer`), the seeds nobody
    trained on, a section per task (:func:`task_section`), the aggregates
    (:func:`aggregate_section`), the entrants and the commits that judged."""
    entrants = [r for r in rows if r.entered]
    everything, rows = rows, [r for r in rows if not r.entered]
    figures = out.parent / "results"
    figures.mkdir(parents=True, exist_ok=True)
    tasks = [t for t in protocol.tasks if any(r.task == t for r in rows)]
    by_key = {(r.task, r.split, r.policy): r for r in rows}
    usable = {k: v for k, v in aggregate(rows).items() if "error" not in v}
    answer, details = short_answer(rows, tasks, by_key, usable, protocol)
    commits = sorted({h.get("commit") or "unknown" for h in headers})
    lines = [
        *header_lines(version, out, protocol),
        "## The short answer",
        "",
        *(answer or ["- No learned or evolved recipe has been judged under this protocol yet."]),
        "",
        "Each recipe is compared with the rules at its own control level (`rules-move` for `move`, the rules "
        "at `full` otherwise) on the same worlds: the difference in success rate (recipe minus rules) with the "
        "95 % interval of a bootstrap that draws training seeds and worlds jointly; a difference is stated "
        "where that interval excludes 0, and cycles are compared on the worlds where both succeeded.",
        "",
        *(["## Against the rules, task by task", "", *details, ""] if details else []),
        *new_seed_lines(rows, tasks),
    ]
    for task in tasks:
        lines += task_section(task, rows, by_key, protocol, root, figures)
    lines += scale_section(rows, by_key, protocol, figures)
    if usable:
        lines += aggregate_section(usable, tasks, figures)
    lines += entrant_lines(entrants, everything, protocol)
    lines += [f"Judged by commit(s): {', '.join(c[:10] for c in commits)}.", ""]
    return "\n".join(lines)


def header_lines(version: str, out: Path, protocol) -> list[str]:
    """The page's title and what it holds: the protocol's files, its worlds, how to regenerate it."""

    def link(path: str) -> str:  # a link from the page to ``path`` (relative to the repository's root)
        return Path(os.path.relpath(Path(path).resolve(), out.resolve().parent)).as_posix()

    files = " extended by ".join(
        f"[configs/benchmark/{v}.yaml]({link(f'configs/benchmark/{v}.yaml')})" for v, _ in protocol.lineage
    )
    return [
        "# Results",
        "",
        f"Every controller judged under benchmark protocol **{version}** ({files}, "
        f"[the guide]({link('docs/guides/benchmark.md')})): the rules and random on "
        f"{protocol.reference} worlds per split, a learned or evolved recipe on {protocol.per_training_seed} worlds per "
        f"split for each of its independent training seeds (the protocol asks for {protocol.training_seeds}); "
        f"every policy on the same world seeds from {protocol.first_seed}. Intervals are 95 %. "
        f"Regenerate: `python -m training.judging.results --benchmark {version} --out {out.as_posix()}`"
        + (" (`make results`)." if out == Path(DEFAULT_OUT) else "."),
        "",
    ]


def short_answer(rows, tasks, by_key, usable, protocol) -> tuple[list[str], list[str]]:
    """``(answer, details)``: a line per recipe (its IQM per task) and the held-out verdict over all
    of them; a line per task and recipe comparing it with the rules at its level on the same worlds."""
    answer, details, above, below = [], [], [], []
    for recipe in sorted({recipe for recipe, _ in usable}):
        per_task = [(task, usable[(recipe, task)]) for task in tasks if (recipe, task) in usable]
        seeds = min(entry["training_seeds"] for _, entry in per_task)
        answer.append(
            f"- **{recipe}** ({seeds} training seeds): IQM normalised score over each task's splits (rules = 1) "
            + ", ".join(f"{task} {e['iqm'][0]:.2f} ({_interval(*e['iqm'][1:])})" for task, e in per_task)
            + "."
        )
    for task in tasks:
        for recipe in sorted({r.policy for r in rows if r.task == task and r.kind in ("learned", "evolved")}):
            row = by_key.get((task, "heldout", recipe))
            reference = reference_of(row, by_key) if row is not None else None
            if reference is None:
                continue
            margin = protocol.equivalence_margin
            pair = paired(row, reference, margin)
            if pair is not None and detectable(pair["success"]):
                (above if pair["success"]["difference"] > 0 else below).append(f"{task} {recipe}")
            others = verdicts(task, recipe, by_key, [s.name for s in protocol.tasks[task].splits[1:]], margin)
            details.append(
                f"- {task}, held-out worlds: "
                + _sentence(recipe, reference, pair, margin)
                + (f"; on the other splits {others}" if others else "")
                + "."
            )
    if details:
        answer.append(
            "- On the held-out worlds, success detectably above the rules: "
            + (", ".join(above) or "none")
            + "; below them: "
            + (", ".join(below) or "none")
            + "; every other recipe and task: no detectable difference"
            + (" (matching them within the protocol's margin where said)" if protocol.equivalence_margin else "")
            + " (each with its interval below)."
        )
    return answer, details


def task_section(task: str, rows, by_key, protocol, root: Path, figures: Path) -> list[str]:
    """A task's table (policies x splits), what each split is, and its learning curves (the figure
    written into ``figures``)."""
    about = {split.name: split.about for split in protocol.tasks[task].splits}
    splits = [s for s in about if any(r.task == task and r.split == s for r in rows)]
    policies = _policy_order({r.policy for r in rows if r.task == task})
    lines = [f"## {task} ({protocol.tasks[task].task_id})", ""]
    lines += ["| policy | " + " | ".join(splits) + " |", "|---|" + "---|" * len(splits)]
    for policy in policies:
        some = next(r for r in rows if r.task == task and r.policy == policy)
        seeds = f", {len(some.runs)} seeds" if some.kind in ("learned", "evolved") else ""
        cells = [cell(by_key[(task, s, policy)]) if (task, s, policy) in by_key else "-" for s in splits]
        lines.append(f"| {policy} ({some.level}{seeds}) | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Each cell: successes / worlds (95 % interval of the success rate), mean cycles to success (its interval).",
        "",
    ]
    lines += [f"- `{s}`: {about[s]}" for s in splits]
    lines.append("")
    found = {}
    for earlier, _ in protocol.lineage:
        found.update(curves(root / earlier / "learning" / "progress", task))
    if found:
        picture = figures / f"curves_{task}.png"
        _curve_figure(task, found, picture)
        lines += [
            f"![Training success of {task}: mean over training seeds with a 95 % band](results/{picture.name})",
            "",
        ]
    return lines


def split_size(env: dict) -> int:
    """The size of a split's worlds: its board's area in sites where it has a board, else its modules."""
    return int(env["board_size"]) ** 2 if "board_size" in env else int(env["n_modules"])


def scale_section(rows, by_key, protocol, figures: Path) -> list[str]:
    """Success and cycles against size, task by task, on the training size, ``larger`` and the scale
    splits (:data:`SCALE_SPLIT`): a table per task (each learned or evolved row with its paired
    difference from the rules at its level on the same worlds) and one figure, success against size
    on a log scale (written into ``figures``). Empty without a judged scale split."""
    sized = {}
    for task, entry in protocol.tasks.items():
        splits = [s for s in entry.splits if s.name in ("heldout", "larger") or SCALE_SPLIT.fullmatch(s.name)]
        if any(
            SCALE_SPLIT.fullmatch(s.name) and any(r.task == task and r.split == s.name for r in rows) for s in splits
        ):
            sized[task] = sorted(splits, key=lambda s: split_size(s.env))
    if not sized:
        return []
    lines = [
        "## Scale: trained small, judged at ten and a hundred times the size",
        "",
        "Every controller runs on each module's own neighbourhood, so it runs on a robot of any size. Each cell: "
        "successes / worlds (95 % interval), mean cycles to success; for a learned or evolved recipe then its "
        "difference in success rate from the rules at its level on the same worlds (95 % interval, training seeds "
        "and worlds drawn jointly). Sizes in modules (table: the board's sites). The scale splits take fewer worlds "
        "where their episodes are long (the protocol says how many).",
        "",
    ]
    for task, splits in sized.items():
        unit = "board sites" if "board_size" in splits[0].env else "modules"
        head = [f"{s.name} ({split_size(s.env):,})" for s in splits]
        lines += [f"**{task}** ({unit})", "", "| policy | " + " | ".join(head) + " |", "|---|" + "---|" * len(head)]
        for policy in _policy_order({r.policy for r in rows if r.task == task}):
            cells = []
            for split in splits:
                row = by_key.get((task, split.name, policy))
                if row is None:
                    cells.append("-")
                    continue
                text = cell(row)
                reference = reference_of(row, by_key) if row.kind in ("learned", "evolved") else None
                pair = paired(row, reference) if reference is not None else None
                cells.append(text + (f"; {_difference(pair['success'])}" if pair else ""))
            some = next(r for r in rows if r.task == task and r.policy == policy)
            lines.append(f"| {policy} ({some.level}) | " + " | ".join(cells) + " |")
        lines.append("")
    _scale_figure(sized, rows, by_key, figures / "scale.png")
    lines += ["![Success against size per task, every policy, with 95 % intervals](results/scale.png)", ""]
    return lines


def _scale_figure(sized: dict, rows, by_key, path: Path) -> None:
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(sized), figsize=(3.4 * len(sized), 3.4), squeeze=False)
    for ax, (task, splits) in zip(axes[0], sized.items()):
        for policy in _policy_order({r.policy for r in rows if r.task == task}):
            points = [(split_size(s.env), by_key[(task, s.name, policy)].summary()) for s in splits
                      if (task, s.name, policy) in by_key]  # fmt: skip
            if not points:
                continue
            x = np.array([size for size, _ in points], dtype=float)
            y = np.array([s["success_rate"] for _, s in points])
            err = np.array(
                [[s["success_rate"] - s["success_lo"], s["success_hi"] - s["success_rate"]] for _, s in points]
            ).T
            style = "--" if policy.startswith(RULES) else "-"
            ax.errorbar(x, y, yerr=err, fmt=f"o{style}", markersize=3, capsize=2, label=policy, linewidth=1)
        ax.set_xscale("log")
        sizes = [split_size(s.env) for s in splits]
        ax.set_xticks(sizes, [f"{v:,}" for v in sizes], fontsize=6)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_ylim(-0.05, 1.05)
        ax.set_title(task)
        ax.set_xlabel("board sites" if "board_size" in splits[0].env else "modules")
        ax.legend(fontsize=5)
    axes[0][0].set_ylabel("success rate")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def aggregate_section(usable: dict, tasks: list[str], figures: Path) -> list[str]:
    """Each recipe's IQM of normalised scores and its probability of beating the rules, task by task,
    with the performance profiles' figure (written into ``figures``)."""
    with_scores = [t for t in tasks if any(task == t for _, task in usable)]
    _profiles(usable, with_scores, figures / "profiles.png")
    lines = [
        "## Aggregate, task by task",
        "",
        "Normalised score per training seed and split: (rate - random) / (rules - random) on the "
        "reference worlds; IQM: the mean of the middle half of training seeds x splits of the task (every "
        "recipe of a task over the same splits; the scale splits apart, in their own section); P(beats): the probability that a training seed's success on "
        "the first worlds of a split exceeds that of the rules at its level on the same worlds, averaged over "
        "splits, ties apart (P(tie)). Bootstrap intervals that draw whole training seeds.",
        "",
    ]
    for task in with_scores:
        lines += [
            f"**{task}**",
            "",
            "| recipe | training seeds | IQM (95 % interval) | P(beats the rules) (95 % interval) | P(tie) |",
            "|---|---|---|---|---|",
        ]
        for (recipe, of), entry in usable.items():
            if of != task:
                continue
            m, lo, hi = entry["iqm"]
            p, plo, phi = entry["improvement"]
            lines.append(
                f"| {recipe} (against {entry['reference']}) | {entry['training_seeds']} | {m:.2f} ({_interval(lo, hi)}) "
                f"| {p:.2f} ({_interval(plo, phi)}) | {entry['ties']:.2f} |"
            )
        lines.append("")
    lines += ["![Performance profiles per task with bootstrap bands](results/profiles.png)", ""]
    return lines


def marl_eval_layout(rows: list[Result]) -> dict:
    """The learned and evolved recipes' episodes in the raw-data layout of InstaDeep's marl-eval
    (Gorsane et al. 2022): ``{environment: {task: {algorithm: {"run_<training seed>": {"step_1":
    {"step_count": agent-steps, metric: [one value per world]}, "absolute_metrics": {metric:
    [...]}}}}}}``. An environment is a proteo task (``proteo-chain``), a marl-eval task one of its
    splits, an algorithm a recipe; every recipe of a task has the same splits and training seeds,
    as marl-eval requires. The one evaluation step is the final checkpoint on the protocol's worlds,
    which is also the absolute metric (proteo judges only the final checkpoint). Metrics:
    ``success_rate`` (1 or 0 per world), ``cycles``, ``return`` (to 4 decimals); the rules and random, judged as one
    run, are left out (they are in ``benchmark.json``). An entrant's algorithm is its name with its
    training after it, ``"<name> (declared)"``: its training was not checked."""
    out: dict = {}
    for row in rows:
        if row.kind not in ("learned", "evolved"):
            continue
        name = row_label(row)
        runs = out.setdefault(f"proteo-{row.task}", {}).setdefault(row.split, {}).setdefault(name, {})
        for run in row.runs:
            metrics = {
                "success_rate": [int(v) for v in run.successes],
                "cycles": [int(v) for v in run.cycles],
                "return": [round(float(v), 4) for v in run.returns],
            }
            runs[f"run_{run.training_seed}"] = {
                "step_1": {"step_count": int(run.agent_steps or 0), **metrics},
                "absolute_metrics": metrics,
            }
    return out


TABLE_BEGIN = "<!-- make results: the held-out table -->"
TABLE_END = "<!-- end of the results table -->"
"""The markers between which ``--publish FILE`` writes :func:`heldout_table` (the README's)."""


def publish_table(path, table: str) -> None:
    """Put ``table`` between :data:`TABLE_BEGIN` and :data:`TABLE_END` in the page ``path``
    (:mod:`training.judging.pages`)."""
    publish_pages([path], {TABLE_BEGIN: table}, TABLE_END)


def short_cell(row: Result) -> str:
    """``k/n (lo-hi), c``: successes with the interval of the rate, and mean cycles to success."""
    s = row.summary()
    return _successes(s) + (f", {s['cycles_to_success']:.0f}" if s["successes"] else "")


def heldout_table(rows: list[Result], protocol) -> str:
    """One row per policy, one column per task: each policy's ``heldout`` cell (:func:`short_cell`)."""
    by_key = {(r.task, r.split, r.policy): r for r in rows}
    tasks = [t for t in protocol.tasks if any(r.task == t for r in rows)]
    lines = ["| policy | " + " | ".join(protocol.tasks[t].task_id for t in tasks) + " |", "|---|" + "---|" * len(tasks)]
    labels = {r.policy: row_label(r) for r in rows}
    for policy in _policy_order({r.policy for r in rows}):
        cells = [short_cell(by_key[(t, "heldout", policy)]) if (t, "heldout", policy) in by_key else "-" for t in tasks]
        lines.append(f"| {labels[policy]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m training.judging.results", description=__doc__.splitlines()[0])
    parser.add_argument("--benchmark", default="v1", help="protocol version (configs/benchmark/<version>.yaml)")
    parser.add_argument("--root", default="docs/benchmark", help="folder holding <version>/<task>/<policy>/")
    parser.add_argument("--out", default=DEFAULT_OUT, help=f"the page to write (default {DEFAULT_OUT})")
    parser.add_argument(
        "--publish", action="append", default=[], help="also write the held-out table between its markers in FILE"
    )
    parser.add_argument(
        "--marl-eval", default="", help="also write the recipes' episodes in marl-eval's raw-data JSON layout to FILE"
    )
    args = parser.parse_args(argv)
    protocol = load_protocol(args.benchmark)
    root, out = Path(args.root), Path(args.out)
    rows, headers = read_rows(root, protocol.lineage)
    for page in args.publish:  # checked before anything is written
        filled(page, {TABLE_BEGIN: ""}, TABLE_END)
    text = render(rows, headers, args.benchmark, root, out, protocol)
    out.write_text(text)
    for page in args.publish:
        publish_table(page, heldout_table(rows, protocol))
    if args.marl_eval:
        Path(args.marl_eval).write_text(json.dumps(marl_eval_layout(rows), separators=(",", ":")) + "\n")
    print(
        f"wrote {out}" + "".join(f", {page}" for page in [*args.publish, *([args.marl_eval] if args.marl_eval else [])])
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Learning curves judged on a protocol's worlds: every checkpoint of some training runs, played
on one task's split at one control level, each checkpoint on the same worlds.

    python benchmarks/learning_curve.py --task table --runs runs/budget/ppo_table-v2_move_s0 \\
        runs/budget/ppo_table-v2_move_s1 --out docs/learning/curves/ppo160_table_move

For each run folder (a trainer's ``--run-dir``: ``checkpoints/step_<N>/`` and ``progress.csv``)
it plays every checkpoint (``--every N`` keeps those at multiples of ``N`` agent-steps, and the
last) on the protocol's first ``--worlds`` world seeds of the split (v7's held-out table-v2
worlds by default, as ``proteo eval`` deals them; sampled actions,
:func:`training.machinery.evaluator.evaluate`), and writes one row per checkpoint to
``<out>.csv``: the run, its agent-steps, the training's wall-clock there (``progress.csv``), the
successes, the mean cycles of the successes and, per world, whether it succeeded (so that two
checkpoints can be paired on the same worlds). A rerun skips the rows already written, so that
a curve grows as its runs go on. ``--rules`` adds the task's hand-coded rules at the same level
on the same worlds as the reference row. ``<out>.md`` is the table, and where every run has a
checkpoint at the same agent-steps, their success together, paired on the same worlds (the
runs as training seeds; :func:`training.judging.statistics.paired_difference`) with the first
such checkpoint and with the rules.

The judge (``proteo eval``) refuses a checkpoint trained for another budget than the
protocol's; this script is how such runs (the budget study) are judged on the protocol's worlds.
"""

from __future__ import annotations

import argparse
import csv
import json
import re
import sys
from pathlib import Path

import numpy as np

from training.judging.protocol import load_protocol
from training.judging.statistics import paired_difference
from training.machinery.checkpoints import read_meta
from training.machinery.evaluator import Controller, evaluate

FIELDS = ("run", "agent_steps", "seconds", "successes", "worlds", "mean_cycles", "won")
STEP = re.compile(r"step_(\d+)$")


def checkpoints(run: Path, every: int) -> list[tuple[int, Path]]:
    """``(agent_steps, folder)`` of the run's checkpoints (``checkpoints/step_<N>/``, and ``final/``
    where it is later), oldest first: those at multiples of ``every`` (the first past each
    multiple) and the last."""
    found = sorted((int(m.group(1)), p) for p in (run / "checkpoints").glob("step_*") if (m := STEP.search(p.name)))
    if (run / "final").is_dir() and (steps := int(read_meta(run / "final")["agent_steps"])) > max(
        (s for s, _ in found), default=-1
    ):
        found.append((steps, run / "final"))  # a run stopped by its time limit ends between checkpoints
    if not found:
        raise SystemExit(f"run={str(run)!r} has no checkpoints/step_<N>/ folders; allowed: a trainer's --run-dir")
    if every <= 0:
        return found
    kept, mark = [], 0
    for steps, path in found:
        if steps >= mark:
            kept.append((steps, path))
            mark = (steps // every + 1) * every
    return kept if kept[-1] == found[-1] else [*kept, found[-1]]


def seconds_at(run: Path) -> dict[int, float]:
    """The training's wall-clock at each logged agent-step count (``progress.csv``; empty without one)."""
    path = run / "progress.csv"
    if not path.exists():
        return {}
    with open(path) as f:
        return {int(r["agent_steps"]): float(r["seconds"]) for r in csv.DictReader(f)}


def wall_clock(logged: dict[int, float], steps: int) -> float | None:
    """The wall-clock of the last log row at or before ``steps`` (a checkpoint is written after its update)."""
    before = [s for s in logged if s <= steps]
    return logged[max(before)] if before else None


def row(run: str, steps: int, seconds, results) -> dict:
    won = [bool(r.success) for r in results]
    cycles = [r.cycles for r in results if r.success]
    return {
        "run": run,
        "agent_steps": steps,
        "seconds": "" if seconds is None else f"{seconds:.0f}",
        "successes": sum(won),
        "worlds": len(won),
        "mean_cycles": f"{np.mean(cycles):.0f}" if cycles else "",
        "won": json.dumps([int(w) for w in won]),
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", nargs="+", required=True, type=Path, help="run folders (--run-dir of a trainer)")
    parser.add_argument("--out", required=True, type=Path, help="<out>.csv and <out>.md are written")
    parser.add_argument("--protocol", default="v7")
    parser.add_argument("--task", default="table", help="a task of the protocol (its name: chain, table, ...)")
    parser.add_argument("--split", default="heldout")
    parser.add_argument("--level", default="move")
    parser.add_argument("--worlds", type=int, default=100)
    parser.add_argument("--every", type=int, default=0, help="agent-steps between kept checkpoints; 0: all")
    parser.add_argument("--rules", action="store_true", help="also play the task's rules at the level")
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args(argv)

    protocol = load_protocol(args.protocol)
    if args.task not in protocol.tasks:
        raise SystemExit(f"task={args.task!r} is not allowed; allowed: {', '.join(protocol.tasks)}")
    task = protocol.tasks[args.task]
    splits = {s.name: s for s in task.splits}
    if args.split not in splits:
        raise SystemExit(f"split={args.split!r} is not allowed; allowed: {', '.join(splits)}")
    if args.worlds < 1:
        raise SystemExit(f"worlds={args.worlds!r} is not allowed; allowed: an integer >= 1")
    env, seeds = splits[args.split].env, protocol.world_seeds(args.worlds)

    csv_path, md_path = args.out.with_suffix(".csv"), args.out.with_suffix(".md")
    rows = []
    if csv_path.exists():
        with open(csv_path) as f:
            rows = [r for r in csv.DictReader(f) if int(r["worlds"]) == args.worlds]
    done = {(r["run"], int(r["agent_steps"])) for r in rows}
    todo = []
    if args.rules and ("rules", 0) not in done:
        todo.append(("rules", 0, None, Controller.rules(task.task_id.split("-")[0])))
    for run in args.runs:
        logged = seconds_at(run)
        for steps, path in checkpoints(run, args.every):
            if (str(run), steps) not in done:
                todo.append((str(run), steps, wall_clock(logged, steps), Controller.from_checkpoint(path)))
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    for name, steps, seconds, controller in todo:  # one controller at a time, each row kept as it ends
        (results,) = evaluate(task.task_id, [controller], seeds, env=env, level=args.level, workers=args.workers)
        rows.append(row(name, steps, seconds, results))
        print(name, steps, rows[-1]["successes"], "/", args.worlds, flush=True)
        with open(csv_path, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=FIELDS)
            writer.writeheader()
            writer.writerows(rows)
    lines = [
        f"# Learning curves: {task.task_id} ({args.protocol}'s `{args.split}` split, {args.worlds} worlds, `{args.level}`)",
        "",
        f"`{' '.join(['python benchmarks/learning_curve.py', *(argv if argv is not None else sys.argv[1:])])}`",
        "",
        "| run | agent-steps | training wall-clock (s) | successes | mean cycles to success |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['run']} | {int(r['agent_steps']):,} | {r['seconds']} | {r['successes']}/{r['worlds']} | {r['mean_cycles']} |"
        )
    md_path.write_text("\n".join(lines + paired_lines(rows)) + "\n")


def paired_lines(rows: list[dict]) -> list[str]:
    """The table of the runs together at every agent-step count they all reached (see the module docstring)."""
    won = {(r["run"], int(r["agent_steps"])): np.array(json.loads(r["won"]), dtype=float) for r in rows}
    runs = sorted({run for run, _ in won if run != "rules"})
    common = sorted(set.intersection(*({s for r, s in won if r == run} for run in runs))) if runs else []
    if not common:
        return []
    first = np.stack([won[(run, common[0])] for run in runs])
    rules = won.get(("rules", 0))
    lines = [
        "",
        f"The {len(runs)} runs together, paired on the same worlds (difference in success, 95 % interval):",
        "",
        f"| agent-steps | successes | against {common[0]:,} | against the rules |",
        "|---|---|---|---|",
    ]
    for steps in common:
        x = np.stack([won[(run, steps)] for run in runs])
        cells = [f"{steps:,}", f"{int(x.sum())}/{x.size}"]
        for reference in (first, None if rules is None else np.broadcast_to(rules, x.shape)):
            if reference is None or (steps == common[0] and reference is first):
                cells.append("")
                continue
            d = paired_difference(x - reference, np.zeros(x.shape[1]))
            cells.append(f"{d['difference']:+.2f} ({d['lo']:+.2f} to {d['hi']:+.2f})")
        lines.append("| " + " | ".join(cells) + " |")
    return lines


if __name__ == "__main__":
    main()

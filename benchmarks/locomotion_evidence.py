"""Evidence for the locomotion task: success, cycles and speed over seeds, step heights, a
tunnel, robot sizes and motion models, with the hand-coded policy in compiled rollouts.

Writes ``docs/evidence/locomotion.md`` (the tables) and ``docs/figures/locomotion_evidence.png``
(success and speed against step height).

Usage::

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/locomotion_evidence.py --seeds 8
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from evidence import add_workers, machine, run_jobs, write_tables

ROOT = Path(__file__).resolve().parents[1]

HEIGHTS = (0, 1, 2, 3)
SIZES = (20, 40)
MODELS = ("minimal", "sphere")
COURSES = [("flat" if h == 0 else f"step h={h}", {"step_height": h}) for h in HEIGHTS] + [
    ("tunnel, 2 free layers", {"step_height": 0, "tunnel_height": 2})
]


def run_one(job: dict) -> dict:
    """One episode of the hand-coded policy (``job``: ``n``, ``overrides``, ``model``, ``seed``,
    ``max_cycles``): success, cycles, centroid advance and speed."""
    from baselines import make_policy
    from baselines.compiled import compiled_rollout
    from proteo_env import make

    env = make(
        "locomotion-v0", n_modules=job["n"], motion_model=job["model"], max_cycles=job["max_cycles"], **job["overrides"]
    )
    env.reset(seed=job["seed"])
    start = env.world.positions[:, 0].mean()
    result = compiled_rollout(env, make_policy("locomotion", env, seed=job["seed"]))
    distance = float(result.positions[:, 0].mean() - start)
    return {
        **job,
        "success": result.success,
        "cycles": result.cycles,
        "distance": distance,
        "speed": distance / max(result.cycles, 1),
        "beyond": float((result.positions[:, 0] >= env.task.finish).mean()),
    }


def summary(rows: list[dict]) -> dict:
    wins = [r for r in rows if r["success"]]
    return {
        "success": f"{len(wins)}/{len(rows)}",
        "rate": len(wins) / len(rows),
        "cycles": f"{np.median([r['cycles'] for r in wins]):.0f}" if wins else "-",
        "speed": float(np.mean([r["speed"] for r in rows])),
        "beyond": float(np.mean([r["beyond"] for r in rows])),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--max-cycles", type=int, default=3000)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "evidence" / "locomotion.md")
    parser.add_argument("--figure", type=Path, default=ROOT / "docs" / "figures" / "locomotion_evidence.png")
    add_workers(parser, default=1)
    args = parser.parse_args(argv)
    started = time.perf_counter()
    jobs = [
        dict(model=model, n=n, label=label, overrides=overrides, seed=s, max_cycles=args.max_cycles)
        for model in MODELS
        for n in SIZES
        for label, overrides in COURSES
        for s in range(args.seeds)
    ]
    groups: dict = {}
    for row in run_jobs(run_one, jobs, args.workers):
        groups.setdefault((row["model"], row["n"], row["label"]), []).append(row)
    table = {}
    for key, rows in groups.items():
        table[key] = summary(rows)
        print(*key, table[key], flush=True)
    lines = [
        "| motion model | modules | course | successes | median cycles to success | mean speed (sites/cycle) "
        "| mean share beyond the line |",
        "|---|---|---|---|---|---|---|",
    ]
    for (model, n, label), s in table.items():
        lines.append(
            f"| {model} | {n} | {label} | {s['success']} | {s['cycles']} | {s['speed']:.3f} | {s['beyond']:.2f} |"
        )
    write_tables(
        args.out,
        f"{args.seeds} seeds per row (seeds 0..{args.seeds - 1}), at most {args.max_cycles} cycles, `distance` 3, "
        f"defaults otherwise; `python benchmarks/locomotion_evidence.py --seeds {args.seeds}` "
        f"({machine(seconds=time.perf_counter() - started)}).\n\n" + "\n".join(lines),
    )
    plot(table, args.figure)
    return 0


def plot(table: dict, path: Path) -> None:
    """Success rate and mean speed against step height, one line per motion model and size."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.4))
    labels = [label for label, _ in COURSES if label.startswith(("flat", "step"))]
    for model in MODELS:
        for n in SIZES:
            style = "-" if model == "minimal" else "--"
            left.plot(
                HEIGHTS,
                [table[model, n, label]["rate"] for label in labels],
                style,
                marker="o",
                label=f"{model}, {n} modules",
            )
            right.plot(HEIGHTS, [table[model, n, label]["speed"] for label in labels], style, marker="o")
    left.set(xlabel="step height (sites)", ylabel="share of seeds beyond the step", ylim=(-0.05, 1.05), xticks=HEIGHTS)
    right.set(xlabel="step height (sites)", ylabel="mean speed (sites per cycle)", xticks=HEIGHTS)
    left.legend(fontsize=8)
    fig.suptitle("locomotion-v0, hand-coded policy")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    raise SystemExit(main())

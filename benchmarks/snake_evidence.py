"""Evidence for the snake task: the composed chain-then-crawl behaviour against locomotion's tread
rule on the same courses (tunnels of 2 and 3 free layers and lengths 4-10, steps, a narrow slot),
both in compiled rollouts.

Writes the tables of ``docs/evidence/snake.md`` (between its ``<!-- tables -->`` markers).

Usage::

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/snake_evidence.py --seeds 16 --first-seed 200
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from evidence import add_workers, machine, run_jobs, write_tables

ROOT = Path(__file__).resolve().parents[1]

FLAT = {"tunnel_height": 0, "step_height": 0}
HOLE = {"step_height": 0, "closed_above": True}
COURSES = (
    [(f"tunnel, 2 free layers, length {n}", {**HOLE, "tunnel_height": 2, "tunnel_length": n}) for n in (4, 6, 8, 10)]
    + [(f"tunnel, 3 free layers, length {n}", {**HOLE, "tunnel_height": 3, "tunnel_length": n}) for n in (4, 6, 10)]
    + [(f"step h={h}", {**FLAT, "step_height": h}) for h in (1, 2)]
    + [(f"slot {w} wide, length 6", {**FLAT, "slot_width": w}) for w in (2, 3)]
)
"""(label, task overrides) of every course, 3 sites ahead of the robot; a tunnel is a hole through
a wall (``closed_above``) for both rules."""
RULES = (("snake-v0", "snake"), ("locomotion-v0", "locomotion"))
"""(task id, policy) of the composed behaviour and of the tread rule."""


def run_one(job: dict) -> dict:
    """One episode (``job``: ``task_id``, ``policy``, ``n``, ``overrides``, ``seed``, ``max_cycles``):
    success and cycles of ``policy`` on ``task_id`` with ``overrides``."""
    from baselines import make_policy
    from baselines.compiled import compiled_rollout
    from proteo_env import make

    env = make(job["task_id"], n_modules=job["n"], max_cycles=job["max_cycles"], **job["overrides"])
    env.reset(seed=job["seed"])
    result = compiled_rollout(env, make_policy(job["policy"], env, seed=job["seed"]))
    return {
        **job,
        "success": bool(result.success),
        "cycles": int(result.cycles),
        "beyond": float((result.positions[:, 0] >= env.task.finish).mean()),
    }


def summary(rows: list[dict]) -> str:
    """``wins/runs, median cycles of the wins`` as one table cell."""
    wins = [r["cycles"] for r in rows if r["success"]]
    cycles = f"{np.median(wins):.0f}" if wins else "-"
    return f"{len(wins)}/{len(rows)} | {cycles} | {np.mean([r['beyond'] for r in rows]):.2f}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=16)
    parser.add_argument("--first-seed", type=int, default=200)
    parser.add_argument("--sizes", type=int, nargs="+", default=[20])
    parser.add_argument("--max-cycles", type=int, default=3000)
    add_workers(parser, default=2)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "evidence" / "snake.md")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    jobs = [
        dict(label=label, task_id=task_id, policy=policy, n=n, overrides=overrides, seed=s, max_cycles=args.max_cycles)
        for label, overrides in COURSES
        for n in args.sizes
        for task_id, policy in RULES
        for s in seeds
    ]
    results = {}
    for row in run_jobs(run_one, jobs, args.workers):
        results.setdefault((row["label"], row["n"], row["task_id"]), []).append(row)
    lines = [
        "| course | modules | snake: successes | median cycles | share beyond | locomotion's tread: successes "
        "| median cycles | share beyond |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for label, _ in COURSES:
        for n in args.sizes:
            cells = " | ".join(summary(results[label, n, task_id]) for task_id, _ in RULES)
            lines.append(f"| {label} | {n} | {cells} |")
            print(lines[-1], flush=True)
    command = f"python benchmarks/snake_evidence.py --seeds {args.seeds} --first-seed {args.first_seed}" + (
        f" --sizes {' '.join(map(str, args.sizes))}" if args.sizes != [20] else ""
    )
    write_tables(
        args.out,
        f"{args.seeds} robots per row (seeds {seeds.start}..{seeds.stop - 1}), at most {args.max_cycles} cycles, "
        f"`minimal`, every obstacle 3 sites ahead of the robot; `{command}` "
        f"({machine(args.workers, time.perf_counter() - started)}).\n\n" + "\n".join(lines),
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

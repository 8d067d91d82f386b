"""Evidence for the snake task: the composed chain-then-crawl behaviour against locomotion's tread
rule on the same courses (tunnels of 2 and 3 free layers and lengths 4-10, steps, a narrow slot),
both in compiled rollouts.

Writes the tables of ``docs/evidence/snake.md`` (between its ``<!-- tables -->`` markers).

Usage::

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/snake_evidence.py --seeds 16 --first-seed 200
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

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


def run_one(task_id: str, policy: str, n_modules: int, overrides: dict, seed: int, max_cycles: int) -> dict:
    """One episode: success and cycles of ``policy`` on ``task_id`` with ``overrides``."""
    from baselines import make_policy
    from baselines.compiled import compiled_rollout
    from proteo_env import make

    env = make(task_id, n_modules=n_modules, max_cycles=max_cycles, **overrides)
    env.reset(seed=seed)
    result = compiled_rollout(env, make_policy(policy, env, seed=seed))
    return {
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
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "evidence" / "snake.md")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    jobs = {
        (label, n, task_id): [(task_id, policy, n, overrides, s, args.max_cycles) for s in seeds]
        for label, overrides in COURSES
        for n in args.sizes
        for task_id, policy in RULES
    }
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    with ProcessPoolExecutor(args.workers) as pool:
        futures = {key: [pool.submit(run_one, *job) for job in batch] for key, batch in jobs.items()}
        results = {key: [f.result() for f in batch] for key, batch in futures.items()}
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
    import numba

    machine = (
        f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, numpy "
        f"{np.__version__}, numba {numba.__version__}, {args.workers} workers, {time.perf_counter() - started:.0f} s"
    )
    command = f"python benchmarks/snake_evidence.py --seeds {args.seeds} --first-seed {args.first_seed}" + (
        f" --sizes {' '.join(map(str, args.sizes))}" if args.sizes != [20] else ""
    )
    block = (
        f"<!-- tables -->\n{args.seeds} robots per row (seeds {seeds.start}..{seeds.stop - 1}), at most "
        f"{args.max_cycles} cycles, `minimal`, every obstacle 3 sites ahead of the robot; `{command}` "
        f"({machine}).\n\n" + "\n".join(lines) + "\n<!-- /tables -->"
    )
    text = args.out.read_text() if args.out.exists() else "<!-- tables -->\n<!-- /tables -->\n"
    head, rest = text.split("<!-- tables -->", 1)
    tail = rest.split("<!-- /tables -->", 1)[1]
    args.out.write_text(head + block + tail)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

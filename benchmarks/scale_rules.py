"""The hand-coded rules at ten and a hundred times their benchmark size: success, cycles, time, memory.

For each size of :data:`SIZES` asked for, the task's rules play ``--worlds`` worlds (seeds
``--first-seed`` on) with a generous cycle limit, each world in a fresh process (so that its
peak resident memory, ``ru_maxrss``, is its own), one process at a time or ``--workers`` at once.
Each world is one episode of the judge's evaluator (a batch of one world). Reported per world:
success, cycles to the end, wall-clock seconds (the first world of a process includes compiling)
and peak memory; per size: successes, the largest cycles to
success and the cycle limit a protocol sets from it (:func:`cycle_limit`: the training split's slack
kept). The protocol's
scale splits take their cycle limits from this table.

Usage::

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/scale_rules.py --sizes chain-x10 grasp-x10 --worlds 5 \\
        --out docs/speed/scale_rules.json
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import resource
import sys
import time
from pathlib import Path

SIZES = {
    "chain-x1": ("chain-v1", {"n_modules": 12, "motion_model": "sphere"}, 300),
    "chain-x10": ("chain-v1", {"n_modules": 120, "motion_model": "sphere"}, 3000),
    "chain-x100": ("chain-v1", {"n_modules": 1200, "motion_model": "sphere"}, 20000),
    "branch-x1": ("branch-v0", {"n_modules": 40, "T": 4, "B": 3}, 200),
    "branch-x10": ("branch-v0", {"n_modules": 400, "T": 4, "B": 3}, 2000),
    "branch-x100": ("branch-v0", {"n_modules": 4000, "T": 4, "B": 3}, 2000),
    "grasp-x1": ("grasp-v0", {"n_modules": 100, "distance": 3}, 300),
    "grasp-x10": ("grasp-v0", {"n_modules": 1000, "distance": 3, "object_size": round(2.5 * 10 ** (1 / 3), 2)}, 3000),
    "grasp-x100": ("grasp-v0", {"n_modules": 10000, "distance": 3, "object_size": round(2.5 * 100 ** (1 / 3), 2)}, 3000),
    "table-x1": (
        "table-v2",
        {"board_size": 9, "depth": 2, "n_spares": 16, "schedule": [[0, 8, 2], [150, 2, 8], [300, 5, 5]],
         "stable_window": 50, "motion_model": "minimal"},
        600,
    ),
    "table-x10": (
        "table-v2",
        {"board_size": 28, "depth": 2, "n_spares": 160, "schedule": [[0, 80, 20], [150, 20, 80], [300, 50, 50]],
         "stable_window": 50, "motion_model": "minimal"},
        3000,
    ),
    "locomotion-x1": ("locomotion-v0", {"n_modules": 20, "step_height": 2, "motion_model": "minimal"}, 600),
    "locomotion-x2": ("locomotion-v0", {"n_modules": 40, "step_height": 2, "motion_model": "minimal"}, 3000),
    "locomotion-x5": ("locomotion-v0", {"n_modules": 100, "step_height": 2, "motion_model": "minimal"}, 10000),
    "locomotion-x10": ("locomotion-v0", {"n_modules": 200, "step_height": 2, "motion_model": "minimal"}, 30000),
}  # fmt: skip
"""Name: (task id, settings, a generous cycle limit to measure under)."""


ROOT = Path(__file__).resolve().parents[1]
TRAINING = {
    "chain-v1": "chain",
    "branch-v0": "branch",
    "grasp-v0": "grasp",
    "table-v2": "table",
    "locomotion-v0": "locomotion",
}
"""The protocol's task names of the measured task ids (their v7 judgements hold the training split)."""


def training_split(task: str) -> tuple[int, int | None]:
    """``(cycle limit, the rules' slowest success)`` of the training split (``heldout``) of ``task``,
    from the rules' published v7 judgement (``docs/benchmark/v7/<task>/rules_full``, 100 worlds)."""
    path = ROOT / "docs/benchmark/v7" / TRAINING[task] / "rules_full/benchmark.json"
    row = next(r for r in json.loads(path.read_text())["rows"] if r["split"] == "heldout")
    run = row["runs"][0]
    won = [c for c, ok in zip(run["cycles"], run["successes"]) if ok]
    return int(row["env"]["max_cycles"]), max(won) if won else None


def cycle_limit(worst: int | None, training_limit: int, training_worst: int | None, scale: int) -> int:
    """The cycle limit of a scale split that keeps the training split's slack: ``training_limit``
    times the ratio of the rules' slowest success at that size (``worst``) to their slowest at the
    training size, rounded up to two significant figures, never below ``training_limit``; where the
    rules succeeded on no measured world, ``training_limit`` times ``scale``."""
    if worst is None or training_worst is None:
        return training_limit * scale
    value = training_limit * worst / training_worst
    unit = 10 ** max(0, int(math.log10(value)) - 1)
    return max(training_limit, int(math.ceil(value / unit) * unit))


def play(job: tuple) -> dict:
    """One world in this (fresh) process, through the judge's evaluator (one world a batch):
    ``(task, settings, limit, seed)``."""
    from proteo_env.registry import task_class
    from training.machinery.evaluator import Controller, Episode, run_episodes, settings_json

    task, settings, limit, seed = job
    rules = Controller.rules(task_class(task).default_policy)
    episode = Episode(task, settings_json({**settings, "max_cycles": limit}), "full", rules, seed)
    started = time.perf_counter()
    (result,) = run_episodes([episode], workers=1, batch_size=1)
    return {
        "seed": seed,
        "success": bool(result.success),
        "cycles": int(result.cycles),
        "seconds": round(time.perf_counter() - started, 2),
        "peak_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
    }


def measure(name: str, worlds: int, first_seed: int, workers: int) -> dict:
    """Every world of size ``name``, each in a fresh process."""
    task, settings, limit = SIZES[name]
    jobs = [(task, settings, limit, seed) for seed in range(first_seed, first_seed + worlds)]
    context = multiprocessing.get_context("spawn")
    with context.Pool(workers, maxtasksperchild=1) as pool:
        episodes = pool.map(play, jobs, chunksize=1)
    won = [e["cycles"] for e in episodes if e["success"]]
    training_limit, training_worst = training_split(task)
    scale = int(name.rsplit("-x", 1)[1])
    return {
        "task": task,
        "settings": settings,
        "measured_limit": limit,
        "episodes": episodes,
        "successes": len(won),
        "worst_cycles_to_success": max(won) if won else None,
        "training_limit": training_limit,
        "training_worst_cycles_to_success": training_worst,
        "cycle_limit": cycle_limit(max(won) if won else None, training_limit, training_worst, scale),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", default=["chain-x10"], help=f"of {', '.join(SIZES)}")
    parser.add_argument("--worlds", type=int, default=5)
    parser.add_argument("--first-seed", type=int, default=1000)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--out", type=Path, default=None, help="add the results to this JSON file")
    args = parser.parse_args(argv)
    for name in args.sizes:
        if name not in SIZES:
            parser.error(f"--sizes {name!r} is not allowed; allowed: {', '.join(SIZES)}")
    if args.worlds < 1 or args.workers < 1:
        parser.error(f"--worlds={args.worlds}, --workers={args.workers} is not allowed; allowed: integers >= 1")
    table = json.loads(args.out.read_text()) if args.out and args.out.exists() else {}
    for name in args.sizes:
        started = time.perf_counter()
        table[name] = measure(name, args.worlds, args.first_seed, args.workers)
        r = table[name]
        cycles = [e["cycles"] for e in r["episodes"]]
        print(
            f"{name}: {r['successes']}/{args.worlds}, cycles {cycles}, worst success {r['worst_cycles_to_success']}, "
            f"limit {r['cycle_limit']}, peak {max(e['peak_mib'] for e in r['episodes'])} MiB, "
            f"{time.perf_counter() - started:.0f} s",
            flush=True,
        )
        if args.out:
            args.out.parent.mkdir(parents=True, exist_ok=True)
            args.out.write_text(json.dumps(table, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

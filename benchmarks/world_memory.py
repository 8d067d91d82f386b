"""Memory of worlds that grow with their modules: ``chain-v1`` at 10^3 to 10^5 modules, and every task at reset.

Part 1, one fresh process per size: the process compiles the chain's rollout on a small world
first (so compile time and its memory are apart), notes its peak resident memory, then builds
``chain-v1`` with ``n_modules = N``, resets it (timed) and runs the hand-coded chain rule for
``--cycles`` cycles inside compiled code (:class:`baselines.compiled.CompiledRollout`, timed).
It reports the peak resident memory of the process (``ru_maxrss``), the grid window the world
ended on against the box, and module-cycles per second. Part 2: every task's grid at reset,
at its default size and a larger one, in cells per module (linear in the modules when the
ratio does not grow with them). Part 3, one fresh process per storage: a chain of ``--built``
modules built to the end by the rule (its window grows to the chain's bounding box, which lies
along the box's diagonal), on a dense grid and on a paged one (:mod:`proteo_env.core.paged`): the
peak memory beyond compiling, the time, and a digest of the final positions (the same trajectory).

Usage::

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/world_memory.py --out docs/speed/memory.md
    .venv/bin/python benchmarks/world_memory.py --sizes 1000 --cycles 50
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

RESET_SIZES = {
    "chain-v1": ("n_modules", 40, 400),
    "branch-v1": ("n_modules", 100, 400),
    "grasp-v0": ("n_modules", 100, 400),
    "locomotion-v0": ("n_modules", 20, 80),
    "table-v1": ("board_size", 15, 30),
}
"""Task: (the parameter that sets its size, the default-like size, a larger one)."""


def peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def one(n: int, cycles: int) -> dict:
    """Part 1 for one size, in this process."""
    import proteo_env
    from baselines import make_policy
    from baselines.compiled import CompiledRollout
    from proteo_env.core.lattice import GridShape
    from proteo_env.core.world import GRID_BYTES_PER_CELL

    warm = proteo_env.make("chain-v1", n_modules=50, max_cycles=10**6)
    warm.reset(seed=0)
    CompiledRollout(warm, make_policy("chain", warm, seed=0)).run(5)
    compiled = peak_mib()
    env = proteo_env.make("chain-v1", n_modules=n, max_cycles=10**6)
    started = time.perf_counter()
    env.reset(seed=0)
    reset_s = time.perf_counter() - started
    at_reset = peak_mib()
    window_at_reset = env.engine.shape.extent
    rollout = CompiledRollout(env, make_policy("chain", env, seed=0))
    started = time.perf_counter()
    rollout.run(cycles)
    run_s = time.perf_counter() - started
    shape = rollout.world.shape
    return {
        "n": n,
        "cycles": cycles,
        "compiled_mib": compiled,
        "reset_mib": at_reset,
        "peak_mib": peak_mib(),
        "reset_s": reset_s,
        "run_s": run_s,
        "rate": n * cycles / run_s,
        "box": shape.size,
        "window_at_reset": window_at_reset,
        "window": shape.extent,
        "window_cells": shape.n_cells,
        "box_gib": GridShape(shape.size).n_cells * GRID_BYTES_PER_CELL / 2**30,
    }


def built(n: int, storage: str) -> dict:
    """Part 3 for one storage (``dense`` or ``paged``), in this process: the chain rule on
    ``chain-v1`` with ``n`` modules, world seed 1000, until the chain is complete."""
    import hashlib

    import proteo_env
    from baselines import make_policy
    from baselines.compiled import CompiledRollout
    from proteo_env.core import world

    world.PAGED_ABOVE_CELLS = 0 if storage == "paged" else 2**62  # compile for this storage first
    warm = proteo_env.make("chain-v1", n_modules=50, max_cycles=10**6)
    warm.reset(seed=0)
    CompiledRollout(warm, make_policy("chain", warm, seed=0)).run(300)
    compiled = peak_mib()
    if storage == "paged":
        world.PAGED_ABOVE_CELLS = 2**22  # the default: a window of more cells is paged
    env = proteo_env.make("chain-v1", n_modules=n, max_cycles=10**6)
    started = time.perf_counter()
    env.reset(seed=1000)
    rollout = CompiledRollout(env, make_policy("chain", env, seed=0))
    result = rollout.run(100 * n)
    return {
        "n": n,
        "storage": storage,
        "success": result.success,
        "cycles": result.cycles,
        "seconds": time.perf_counter() - started,
        "compiled_mib": compiled,
        "peak_mib": peak_mib(),
        "window": rollout.world.shape.extent,
        "paged": rollout.world.shape.paged,
        "digest": hashlib.sha256(result.positions.tobytes()).hexdigest()[:12],
    }


def at_reset() -> list[dict]:
    """Part 2: every task's grid cells at reset per module, at two sizes."""
    import proteo_env

    rows = []
    for task, (param, small, large) in RESET_SIZES.items():
        for size in (small, large):
            env = proteo_env.make(task, **{param: size})
            env.reset(seed=0)
            w = env.engine
            rows.append(
                {
                    "task": task,
                    "setting": f"{param}={size}",
                    "modules": w.n_modules,
                    "cells": w.shape.n_cells,
                    "per_module": w.shape.n_cells / w.n_modules,
                    "windowed": not w.shape.whole,
                }
            )
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 100000])
    parser.add_argument("--cycles", type=int, default=200)
    parser.add_argument("--built", type=int, default=1200, help="modules of part 3's chain (0: skip part 3)")
    parser.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--one-built", choices=("dense", "paged"), default=None, help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.one is not None:
        print(json.dumps(one(args.one, args.cycles)))
        return 0
    if args.one_built is not None:
        print(json.dumps(built(args.built, args.one_built)))
        return 0

    env = {**os.environ, "NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}

    def fresh_process(*flags) -> dict:
        """This script with ``flags`` in a fresh process: its one JSON line."""
        out = subprocess.run([sys.executable, __file__, *flags], env=env, check=True, capture_output=True, text=True)
        print(out.stdout.strip().splitlines()[-1], flush=True)
        return json.loads(out.stdout.strip().splitlines()[-1])

    runs = [fresh_process("--one", str(n), "--cycles", str(args.cycles)) for n in args.sizes]
    storages = ("dense", "paged") if args.built else ()
    grown = [fresh_process("--one-built", storage, "--built", str(args.built)) for storage in storages]
    resets = at_reset()
    load = os.getloadavg()

    lines = [
        "# Memory of worlds that grow with their modules",
        "",
        f"Generated by `benchmarks/world_memory.py` ({' '.join(sys.argv[1:]) or 'defaults'}) on "
        f"{platform.machine()}, one thread, load average {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} "
        "(1 / 5 / 15 minutes) at the end.",
        "",
        f"## `chain-v1`: reset and the first {args.cycles} cycles of the hand-coded rule",
        "",
        "One fresh process per size; the rollout is compiled on a 50-module world first. *peak*: the "
        "process's peak resident memory (`ru_maxrss`), after compiling, after the reset and after the "
        "cycles; *window*: the grid's window of the box at reset and at the end (the box itself, the "
        "grid every world held before worlds grew, is in the next column with the memory its grid "
        "would need); *rate*: module-cycles per second of the cycles.",
        "",
        "| N | peak after compiling | after reset | after the cycles | reset | window at reset | window at the end | box (its grid) | rate |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in runs:
        lines.append(
            f"| {r['n']:,} | {r['compiled_mib']:.0f} MiB | {r['reset_mib']:.0f} MiB | {r['peak_mib']:.0f} MiB | "
            f"{r['reset_s']:.1f} s | {' x '.join(map(str, r['window_at_reset']))} | "
            f"{' x '.join(map(str, r['window']))} | {' x '.join(map(str, r['box']))} ({r['box_gib']:.3g} GiB) | "
            f"{r['rate'] / 1e3:,.0f} k |"
        )
    lines += [
        "",
        "## Every task's grid at reset",
        "",
        "Grid cells (the window and its padding) per module at reset, seed 0, at two sizes: linear in "
        "the modules where the ratio does not grow with them.",
        "",
        "| task | setting | modules | grid cells | cells per module | grid |",
        "|---|---|---|---|---|---|",
    ]
    for r in resets:
        lines.append(
            f"| {r['task']} | {r['setting']} | {r['modules']:,} | {r['cells']:,} | {r['per_module']:,.0f} | "
            f"{'a window that grows' if r['windowed'] else 'the whole box'} |"
        )
    if grown:
        lines += [
            "",
            f"## A chain of {args.built:,} modules built to the end: dense grid against paged",
            "",
            "One fresh process per storage, the rule compiled for it first; the chain rule on world seed "
            "1000 until the chain is complete. *beyond compiling*: the peak resident memory less the "
            "peak after compiling; *digest*: of the final positions (the same on both: the same "
            "trajectory).",
            "",
            "| storage | success | cycles | seconds | peak | beyond compiling | window at the end | digest |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in grown:
            lines.append(
                f"| {r['storage']} | {r['success']} | {r['cycles']:,} | {r['seconds']:.1f} | {r['peak_mib']:.0f} MiB | "
                f"{r['peak_mib'] - r['compiled_mib']:.0f} MiB | {' x '.join(map(str, r['window']))} | {r['digest']} |"
            )
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Evolution's generations on every task, this checkout against another: seconds and module-cycles/s.

For each task, the episodes of one generation of its ``evolve-large`` recipe
(``configs/train/evolve_large_<task>_full.yaml`` on the task version of benchmark v7): the
paper's program, random programs and mutants (``--programs`` in all), one world per variation,
through :func:`training.machinery.evaluator.run_episodes` on one worker, the way ``training/trainers/evolve.py``
runs a generation once it is past its first ones (new programs are parsed and built in the
timed call; a warm-up generation of other programs compiles first, the programs' one-call
kernel included). With ``--before DIR`` (a checkout of an earlier commit) the same
generation also runs there, in a subprocess, alternating with this checkout ``--repeats`` times
(the faster of each side's runs is kept), and every episode's cycles, success, return and
metrics are compared between the two.

Usage::

    git worktree add /tmp/before <commit>
    NUMBA_NUM_THREADS=1 python benchmarks/evolution_tasks.py --before /tmp/before --out docs/speed/evolution_tasks
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from machine_info import describe
from research_loop import evolution_episodes

TASKS = {"chain": "chain-v1", "branch": "branch-v0", "table": "table-v2", "grasp": "grasp-v0"}
"""Task -> the version benchmark v7 judges (and trains) it on."""


def generation(task: str, n_programs: int) -> dict:
    """Seconds, module-cycles and every episode's outcome of one generation of ``task`` (this process's checkout)."""
    from proteo_env import batched
    from training.machinery.evaluator import run_episodes

    batched.ONE_CALL_AFTER = (
        0  # the programs act in one call from the start, as in a long run (compiled in the warm-up)
    )
    config = f"configs/train/evolve_large_{task}_full.yaml"
    warm, _ = evolution_episodes(4, 1, config, seed=1, task=TASKS[task])
    run_episodes(warm, workers=1)
    episodes, modules = evolution_episodes(n_programs, 1, config, seed=0, task=TASKS[task])
    started = time.perf_counter()
    results = run_episodes(episodes, workers=1)
    seconds = time.perf_counter() - started
    return {
        "seconds": seconds,
        "episodes": len(episodes),
        "module_cycles": sum(r.cycles * n for r, n in zip(results, modules)),
        "outcomes": [[r.cycles, bool(r.success), float(r.total_reward), r.metrics] for r in results],
    }


def run_in(checkout: Path, task: str, n_programs: int) -> dict:
    """:func:`generation` run by the code of ``checkout`` (a fresh process there)."""
    command = [sys.executable, str(Path(__file__).resolve()), "--one", task, "--programs", str(n_programs)]
    environ = {**os.environ, "PYTHONPATH": str(checkout)}
    done = subprocess.run(command, cwd=checkout, env=environ, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def commit_of(checkout: Path) -> str:
    """The short commit of ``checkout``'s HEAD, with ``+`` when its code (the three packages)
    differs from it."""
    git = ["git", "-C", str(checkout)]
    head = subprocess.run([*git, "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    dirty = subprocess.run([*git, "diff", "--quiet", "HEAD", "--", "proteo_env", "baselines", "training"]).returncode
    return head + ("+" if dirty else "")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), choices=list(TASKS))
    parser.add_argument("--programs", type=int, default=16, help="programs of the generation (default 16)")
    parser.add_argument("--before", default=None, help="a checkout of the earlier code to compare with")
    parser.add_argument("--repeats", type=int, default=2, help="runs of each side, alternating (default 2)")
    parser.add_argument("--one", default=None, help=argparse.SUPPRESS)  # a subprocess: one task, JSON out
    parser.add_argument("--out", default=None, help="write <out>.json and <out>.md")
    args = parser.parse_args(argv)
    if args.one:
        print(json.dumps(generation(args.one, args.programs)))
        return 0
    here = Path(__file__).resolve().parents[1]
    sides = {"after": here} | ({"before": Path(args.before).resolve()} if args.before else {})
    rows = []
    for task in args.tasks:
        runs = {side: [] for side in sides}
        for _ in range(args.repeats):
            for side, checkout in reversed(sides.items()):
                runs[side].append(run_in(checkout, task, args.programs))
        best = {side: min(r, key=lambda x: x["seconds"]) for side, r in runs.items()}
        row = {"task": TASKS[task], "episodes": best["after"]["episodes"]}
        for side, result in best.items():
            row[f"{side}_seconds"] = result["seconds"]
            row[f"{side}_module_cycles_per_s"] = result["module_cycles"] / result["seconds"]
        if "before" in best:
            row["speedup"] = best["before"]["seconds"] / best["after"]["seconds"]
            pairs = zip(best["before"]["outcomes"], best["after"]["outcomes"])
            row["identical"] = f"{sum(a == b for a, b in pairs)}/{row['episodes']}"
        rows.append(row)
        print(json.dumps(row), flush=True)
    commits = {side: commit_of(checkout) for side, checkout in sides.items()}
    info = describe("numpy", "numba", numba_threads=os.environ.get("NUMBA_NUM_THREADS"), commits=commits)
    text = markdown(rows, info, args)
    if args.out:
        out = Path(args.out)
        out.with_suffix(".json").write_text(json.dumps({"machine": info, "args": vars(args), "rows": rows}, indent=2))
        out.with_suffix(".md").write_text(text)
    print(text)
    return 0


def markdown(rows: list, info: dict, args) -> str:
    lines = [
        "# Evolution's generations on every task",
        "",
        f"`NUMBA_NUM_THREADS=1 python benchmarks/evolution_tasks.py --before CHECKOUT --programs {args.programs} "
        f"--repeats {args.repeats}` (what it runs: the script's docstring); best of {args.repeats} runs per side, "
        "alternating; *identical*: episodes whose cycles, success, return and metrics are equal on both sides.",
        "",
        f"Before: commit {info['commits'].get('before', '-')}; after: commit {info['commits']['after']}. Machine: "
        f"{info['cpu']}, {info['cores']} cores, load average {info['load_average_1min']} at the end; numba {info['numba']}.",
        "",
        "| task | episodes | before s | after s | before module-cycles/s | after module-cycles/s | speed-up | identical |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['task']} | {r['episodes']} | {r.get('before_seconds', float('nan')):.2f} | {r['after_seconds']:.2f} | "
            f"{r.get('before_module_cycles_per_s', float('nan')) / 1e3:,.0f} k | {r['after_module_cycles_per_s'] / 1e3:,.0f} k | "
            f"{r.get('speedup', float('nan')):.2f}x | {r.get('identical', '-')} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())

"""Evidence for the chain task: how often and how fast the hand-coded chain forms.

For random connected blobs (the task's start layout, a new blob per seed) it measures, per
motion model and blob size, the share of episodes that reach success (one connected,
one-module-thick chain) within the cycle limit, and the median and 90th percentile of the
cycles to success, for the hand-coded chain policy (``baselines.chain.ChainPolicy``, default
parameters) and for the random policy (uniform legal move, every other field uniform). A
second table gives cycles to success against the number of modules for one motion model.

Percentiles are taken over all episodes, a failed one counting as longer than the limit, so
a percentile that lands on failures is printed as ``> limit``.

Both policies run through the array API (``env.observe_arrays`` / ``env.step_arrays``): the
hand-coded one through ``ChainPolicy.act_arrays``, which applies the same rule to the same
per-agent observations as ``act`` without building dicts; the random one draws what
``RandomPolicy.act`` draws, for all agents at once.

Usage::

    .venv/bin/python benchmarks/chain_evidence.py --out docs/evidence/chain.md
    .venv/bin/python benchmarks/chain_evidence.py --seeds 5 --sizes 30 --models sphere --scaling-sizes 50 100 \
        --scaling-models sphere

``--max-cycles`` is a number or an expression in ``N`` (default ``20*N``). ``--workers`` runs
episodes in parallel processes (default: the number of CPUs).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from evidence import add_workers, command, machine, publish, run_jobs


def cycle_limit(expr: str, n: int) -> int:
    """The cycle limit for ``n`` modules from ``--max-cycles`` (a number or an expression in N)."""
    value = eval(expr, {"__builtins__": {}}, {"N": n})  # noqa: S307 - a command-line number
    return int(value)


def run_one(job: dict) -> dict:
    """One episode; ``job`` has ``policy`` (``chain`` or ``random``), ``n``, ``model``, ``seed``,
    ``max_cycles``. Returns the job with ``success``, ``cycles`` and ``seconds``."""
    import proteo_env
    from baselines.chain import ChainPolicy

    env = proteo_env.make("chain", n_modules=job["n"], motion_model=job["model"], max_cycles=job["max_cycles"])
    env.reset(seed=job["seed"])
    started = time.perf_counter()
    success = False
    if job["policy"] == "chain":
        policy = ChainPolicy.for_env(env, seed=job["seed"])
        act = policy.act_arrays
    else:
        rng = np.random.default_rng(job["seed"])
        nvec = env.action_layout.nvec

        def act(buffers):
            actions = rng.integers(0, nvec, size=(buffers.action_mask.shape[0], len(nvec)))
            keys = rng.random(buffers.action_mask.shape)  # a uniform legal move (staying is legal)
            keys[buffers.action_mask == 0] = -1.0
            actions[:, 0] = keys.argmax(axis=1)
            return actions

    while env.cycle < job["max_cycles"]:
        env.step_arrays(act(env.observe_arrays()))
        if env.task.success(env.engine):
            success = True
            break
    return {**job, "success": success, "cycles": env.cycle, "seconds": time.perf_counter() - started}


def summarise(rows: list[dict]) -> dict:
    """Share of successes and median / 90th percentile of cycles (failures count as infinite)."""
    cycles = np.array([r["cycles"] if r["success"] else math.inf for r in rows], dtype=float)
    limit = rows[0]["max_cycles"]

    def pct(q):
        v = np.percentile(cycles, q, method="higher")
        return f"> {limit}" if math.isinf(v) else str(int(v))

    wins = int(np.isfinite(cycles).sum())
    return {
        "runs": len(rows),
        "wins": wins,
        "share": wins / len(rows),
        "median": pct(50),
        "p90": pct(90),
        "max_ok": str(int(cycles[np.isfinite(cycles)].max())) if wins else "-",
        "limit": limit,
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20, help="episodes (seeds 0..S-1) per model and size")
    parser.add_argument("--sizes", type=int, nargs="+", default=[50, 200], help="blob sizes N for the main table")
    parser.add_argument("--models", nargs="+", default=["minimal", "rounded", "sphere", "rhombic"])
    parser.add_argument("--max-cycles", default="20*N", help="cycle limit: a number or an expression in N")
    parser.add_argument(
        "--random-seeds",
        type=int,
        default=None,
        help="episodes of the random policy per model and size (default: --seeds)",
    )
    parser.add_argument("--scaling-sizes", type=int, nargs="*", default=[50, 100, 200, 400])
    parser.add_argument("--scaling-models", nargs="*", default=["rounded", "sphere"])
    parser.add_argument(
        "--scaling-seeds",
        type=int,
        default=10,
        help="episodes per size in the scaling table (sizes also in the main table reuse those)",
    )
    add_workers(parser)
    parser.add_argument("--out", type=Path, default=None, help="write the Markdown report here")
    args = parser.parse_args(argv)
    random_seeds = args.seeds if args.random_seeds is None else args.random_seeds

    jobs = []
    for model in args.models:
        for n in args.sizes:
            limit = cycle_limit(args.max_cycles, n)
            jobs += [dict(policy="chain", n=n, model=model, seed=s, max_cycles=limit) for s in range(args.seeds)]
            jobs += [dict(policy="random", n=n, model=model, seed=s, max_cycles=limit) for s in range(random_seeds)]
    for model in args.scaling_models:
        for n in args.scaling_sizes:
            if model in args.models and n in args.sizes and args.scaling_seeds <= args.seeds:
                continue  # reuse the main table's episodes
            limit = cycle_limit(args.max_cycles, n)
            jobs += [
                dict(policy="chain", n=n, model=model, seed=s, max_cycles=limit) for s in range(args.scaling_seeds)
            ]
    # largest first so that the long episodes do not finish last on their own
    jobs.sort(key=lambda j: -j["n"] * j["max_cycles"] * (2 if j["policy"] == "random" else 1))

    started = time.time()
    rows = []
    for row in run_jobs(run_one, jobs, args.workers):
        rows.append(row)
        print(
            f"{row['policy']:6s} {row['model']:8s} N={row['n']:<4d} seed={row['seed']:<3d} "
            f"{'ok  ' if row['success'] else 'FAIL'} {row['cycles']:6d} cycles {row['seconds']:7.1f} s",
            file=sys.stderr,
            flush=True,
        )
    wall = time.time() - started

    def group(policy, model, n, seeds=None):
        return [
            r
            for r in rows
            if r["policy"] == policy and r["model"] == model and r["n"] == n and (seeds is None or r["seed"] < seeds)
        ]

    lines = [
        "# Chain task: evidence",
        "",
        "Generated by `benchmarks/chain_evidence.py` (command below); random connected blobs from the "
        'chain task\'s start layout (`proteo_env.make("chain", n_modules=N, motion_model=M)`, seeds '
        "`0..S-1`), one initial SEED picked by the task. Success: one connected, one-module-thick "
        "chain (`terminated`). Cycle percentiles are over all episodes with failures counted as longer "
        "than the limit.",
        "",
        "```",
        command("chain_evidence.py", argv),
        "```",
        "",
        f"Machine: {machine(args.workers)}; wall time {wall / 60:.1f} min.",
        "",
        "## Success and cycles to success",
        "",
        "| policy | motion model | N | episodes | success | median cycles | p90 cycles | slowest success | limit |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for model in args.models:
        for n in args.sizes:
            for policy in ("chain", "random"):
                g = group(policy, model, n)
                if not g:
                    continue
                s = summarise(g)
                name = "hand-coded chain" if policy == "chain" else "random"
                lines.append(
                    f"| {name} | {model} | {n} | {s['runs']} | {s['wins']}/{s['runs']} ({s['share']:.0%}) "
                    f"| {s['median']} | {s['p90']} | {s['max_ok']} | {s['limit']} |"
                )
    if args.scaling_sizes and args.scaling_models:
        lines += [
            "",
            "## Cycles to success against N (hand-coded chain)",
            "",
            f"Seeds `0..{args.scaling_seeds - 1}` per size.",
            "",
            "| motion model | N | episodes | success | median cycles | p90 cycles | median cycles / N | limit |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for model in args.scaling_models:
            for n in args.scaling_sizes:
                g = group("chain", model, n, seeds=args.scaling_seeds)
                if not g:
                    continue
                s = summarise(g)
                per = f"{int(s['median']) / n:.1f}" if s["median"].isdigit() else "-"
                lines.append(
                    f"| {model} | {n} | {s['runs']} | {s['wins']}/{s['runs']} ({s['share']:.0%}) "
                    f"| {s['median']} | {s['p90']} | {per} | {s['limit']} |"
                )
    failures = [r for r in rows if r["policy"] == "chain" and not r["success"]]
    lines += [
        "",
        "Hand-coded episodes that failed (model, N, seed): "
        + (
            ", ".join(
                f"{r['model']} {r['n']} {r['seed']}"
                for r in sorted(failures, key=lambda r: (r["model"], r["n"], r["seed"]))
            )
            or "none"
        )
        + ".",
    ]
    publish("\n".join(lines) + "\n", args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

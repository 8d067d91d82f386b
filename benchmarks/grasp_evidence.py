"""Evidence for the grasp task: success, coverage and timing per object shape and size.

Runs four suites and writes one Markdown report (the tables of ``docs/evidence/grasp.md``)
plus, optionally, the per-episode rows as JSON:

0. the hand-coded grasp policy, per motion model (``sphere``, ``minimal``), object shape and
   object size;
1. the random policy on the same grid (fewer seeds: it never gets close);
2. the paper's rules alone (the policy's additions switched off), object size 2.5;
3. the hand-coded policy under the stricter motion models (``rounded``, ``rhombic``);
4. the hand-coded policy left running for 1500 cycles without stopping at success, to show
   how far coverage and surround go.

Per episode it records: success, the cycle of first contact (first cycle whose ``contact``
metric is positive), the cycle of success, the first cycle that met the default success
thresholds (the same cycle unless a suite changes the thresholds), and the final
``coverage``, ``surround`` and ``contact`` metrics.

Usage::

    .venv/bin/python benchmarks/grasp_evidence.py --seeds 10 --out /tmp/grasp_tables.md

``--workers`` runs episodes in parallel processes (default: the number of CPUs).
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

from evidence import add_workers, command, machine, mean_cell, publish, run_jobs, success_cell

SHAPES = ("sphere", "box", "blob")
SIZES = (1.5, 2.5, 3.5)


def run_one(job: dict) -> dict:
    """One episode: ``job`` has ``policy``, ``seed`` and the ``make`` overrides."""
    from baselines import make_policy
    from proteo_env import make
    from proteo_env.tasks.grasp import GraspParams

    overrides = dict(job["overrides"])
    env = make("grasp-v0", **overrides)
    policy = make_policy(job["policy"], env, seed=job["seed"], **job.get("policy_params", {}))
    obs, infos = env.reset(seed=job["seed"])
    policy.reset(job["seed"])
    info = next(iter(infos.values()))
    default = GraspParams()
    contact_at = success_at = grasp_at = None
    started = time.perf_counter()
    while env.agents:
        obs, _, terms, _, infos = env.step(policy.act(obs))
        info = next(iter(infos.values()))
        if contact_at is None and info["metric/contact"] > 0:
            contact_at = env.cycle
        if success_at is None and next(iter(terms.values())):
            success_at = env.cycle
        if (
            grasp_at is None
            and info["metric/coverage"] >= default.coverage_threshold
            and info["metric/surround"] >= default.surround_threshold
        ):
            grasp_at = env.cycle
    return {
        **job,
        "cycles": env.cycle,
        "success": success_at is not None,
        "contact_at": contact_at,
        "success_at": success_at,
        "grasp_at": grasp_at,
        "coverage": info["metric/coverage"],
        "surround": info["metric/surround"],
        "contact": info["metric/contact"],
        "seconds": time.perf_counter() - started,
        "surface_sites": int(len(env.task.surface_sites)),
    }


def table(rows: list[dict]) -> str:
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        o = r["overrides"]
        key = (r["policy"], o.get("motion_model", "default"), o["shape"], o["object_size"])
        groups.setdefault(key, []).append(r)
    head = (
        "| policy | motion | shape | size | surface sites | success (95% CI) | coverage | surround | "
        "contact modules | cycles to contact | cycles to success |"
    )
    # cycles to success: the first cycle meeting the default thresholds (coverage >= 0.3 and
    # surround >= 0.75); where the episode stops at success that is the cycle it stopped
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for key in sorted(groups, key=lambda k: (k[0], k[1], SHAPES.index(k[2]), k[3])):
        g = groups[key]
        k = sum(r["success"] for r in g)
        contact = [r["contact_at"] for r in g]
        lines.append(
            f"| {key[0]} | {key[1]} | {key[2]} | {key[3]:g} | {mean_cell([r['surface_sites'] for r in g])} | "
            f"{success_cell(k, len(g))} | {mean_cell([r['coverage'] for r in g])} | "
            f"{mean_cell([r['surround'] for r in g])} | {mean_cell([r['contact'] for r in g])} | "
            f"{mean_cell(contact)} ({sum(c is not None for c in contact)}/{len(g)}) | "
            f"{mean_cell([r['grasp_at'] for r in g])} ({sum(r['grasp_at'] is not None for r in g)}/{len(g)}) |"
        )
    return "\n".join(lines)


PAPER_ONLY = {"relocate": False, "retire": False, "straight": False, "wrap_forward": False, "prefer_touch": False}
"""Grasp policy parameters that switch off every addition to the paper's rules."""


def suites(seeds: int, random_seeds: int, quick: bool) -> list[dict]:
    """The experiments of the report: each a titled grid of episodes."""
    sizes = [2.5] if quick else list(SIZES)
    return [
        {
            "title": "Hand-coded grasp policy (default parameters)",
            "policy": "grasp",
            "params": {},
            "motion_models": ["sphere", "minimal"],
            "shapes": list(SHAPES),
            "sizes": sizes,
            "seeds": seeds,
        },
        {
            "title": "Random policy (uniform over legal moves and all other action fields)",
            "policy": "random",
            "params": {},
            "motion_models": ["sphere", "minimal"],
            "shapes": list(SHAPES),
            "sizes": sizes,
            "seeds": random_seeds,
        },
        {
            "title": "The paper's rules alone (our additions off: "
            + ", ".join(f"`{k}=False`" for k in PAPER_ONLY)
            + ")",
            "policy": "grasp",
            "params": PAPER_ONLY,
            "motion_models": ["sphere", "minimal"],
            "shapes": list(SHAPES),
            "sizes": [2.5],
            "seeds": seeds,
        },
        {
            "title": "The stricter motion models",
            "policy": "grasp",
            "params": {},
            "motion_models": ["rounded", "rhombic"],
            "shapes": list(SHAPES),
            "sizes": [2.5],
            "seeds": seeds,
        },
        {
            "title": "No early stop: the hand-coded grasp left running for 1500 cycles (success thresholds set to 1, "
            "so coverage and surround are the values reached at cycle 1500; 'cycles to success' is the first cycle "
            "that met the default thresholds)",
            "policy": "grasp",
            "params": {},
            "motion_models": ["sphere", "minimal"],
            "shapes": list(SHAPES),
            "sizes": sizes,
            "seeds": seeds,
            "overrides": {"coverage_threshold": 1.0, "surround_threshold": 1.0, "max_cycles": 1500},
        },
    ]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=10, help="episodes per setting (hand-coded policy)")
    ap.add_argument("--random-seeds", type=int, default=3, help="episodes per setting for the random policy")
    ap.add_argument(
        "--first-seed",
        type=int,
        default=100,
        help="first episode seed (100: seeds not used while the policy was developed)",
    )
    ap.add_argument("--max-cycles", type=int, default=3000)
    ap.add_argument("--quick", action="store_true", help="object size 2.5 only (a smoke run)")
    ap.add_argument("--only", type=int, nargs="+", default=None, help="run only these suites (0-based)")
    add_workers(ap)
    ap.add_argument("--out", default=None, help="Markdown report (printed if omitted)")
    ap.add_argument("--json", default=None, help="per-episode rows as JSON")
    args = ap.parse_args(argv)

    chosen = suites(args.seeds, args.random_seeds, args.quick)
    if args.only is not None:
        chosen = [chosen[i] for i in args.only]
    jobs = []
    for k, suite in enumerate(chosen):
        for motion, shape, size in itertools.product(suite["motion_models"], suite["shapes"], suite["sizes"]):
            for seed in range(args.first_seed, args.first_seed + suite["seeds"]):
                jobs.append(
                    {
                        "suite": k,
                        "policy": suite["policy"],
                        "seed": seed,
                        "policy_params": suite["params"],
                        "overrides": {
                            "shape": shape,
                            "object_size": size,
                            "motion_model": motion,
                            "max_cycles": args.max_cycles,
                            **suite.get("overrides", {}),
                        },
                    }
                )
    started = time.perf_counter()
    rows = []
    for i, row in enumerate(run_jobs(run_one, jobs, args.workers), start=1):
        rows.append(row)
        print(
            f"[{i}/{len(jobs)}] suite {row['suite']} {row['policy']} {row['overrides']['motion_model']} "
            f"{row['overrides']['shape']} {row['overrides']['object_size']} seed {row['seed']}: "
            f"success={row['success']} coverage={row['coverage']:.2f} surround={row['surround']:.2f} "
            f"cycles={row['cycles']} ({row['seconds']:.0f} s)",
            file=sys.stderr,
            flush=True,
        )
    wall = time.perf_counter() - started
    lines = [
        f"Command: `{command('grasp_evidence.py', argv)}`",
        "",
        f"Machine: {machine(args.workers, packages=('numpy', 'numba', 'proteo_env'))}; {len(jobs)} episodes in "
        f"{wall / 60:.1f} min wall-clock.",
        "",
        f"Every episode: task defaults (`grasp-v0`) except the shape, size and motion model in the row, "
        f"`max_cycles={args.max_cycles}`, seeds {args.first_seed} and up.",
        "",
    ]
    for k, suite in enumerate(chosen):
        lines += [f"### {suite['title']}", "", table([r for r in rows if r["suite"] == k]), ""]
    publish("\n".join(lines), args.out)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

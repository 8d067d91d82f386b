"""Evidence for the branch task: the trees the hand-coded branching policy grows, against T and B,
in the plane of the first node and in 3D.

For random connected blobs (the task's start layout, a new blob per seed) it runs the
hand-coded policy (``baselines.branch.BranchPolicy``, default parameters, ``T`` and ``B`` from
the task) with success switched off (``target_levels=99``) until the modules run out (no
module left in SLEEP or SEARCH) plus ``--settle`` cycles, or the cycle limit. It reports per
setting, over the seeds, the mean (min..max) of the tree statistics the task measures
(``proteo_env/tasks/branch.py``): levels of branching, branching points, branches per point,
mean distance between a branching point and its parent point, whether the grown structure
is a tree; the cycle at which 2 levels were first reached and the cycle at which the
modules ran out; and what is left unfinished when the modules run out: seeds still
waiting for modules (growing tips) and NODEs that had not yet spawned all their seeds.

The policy runs through the array API (``env.observe_arrays`` / ``env.step_arrays`` and
``BranchPolicy.act_arrays``, the same rule as ``act`` on the same per-agent observations).

Usage::

    .venv/bin/python benchmarks/branch_evidence.py --out docs/evidence/branch.md
    .venv/bin/python benchmarks/branch_evidence.py --seeds 3 --sizes 60 --Ts 4 --Bs 2
"""

from __future__ import annotations

import argparse
import itertools
import os
import time
from pathlib import Path

import numpy as np
from evidence import add_workers, arguments, machine, publish, run_jobs

STATS = (
    "levels",
    "branch_points",
    "branches_per_point",
    "max_branches",
    "point_distance",
    "tree",
    "tree_size",
    "seeds",
    "nodes",
)


def run_one(job: dict) -> dict:
    """One episode of ``job`` (``n``, ``T``, ``B``, ``growth``, ``model``, ``seed``, ``max_cycles``,
    ``settle``, ``policy``) on ``branch-v1`` (``growth`` ``planar``: its ``planar=True``)."""
    import proteo_env
    from baselines.branch import BranchPolicy
    from proteo_env.tasks.branch import FINAL, INODE, NODE, SEED

    env = proteo_env.make(
        "branch-v1",
        planar=job["growth"] == "planar",
        n_modules=job["n"],
        T=job["T"],
        B=job["B"],
        motion_model=job["model"],
        max_cycles=job["max_cycles"],
        target_levels=99,
    )
    env.reset(seed=job["seed"])
    policy = BranchPolicy.for_env(env, seed=job["seed"], **job.get("policy", {}))
    started = time.perf_counter()
    two_levels = out_at = None
    while env.cycle < job["max_cycles"]:
        env.step_arrays(policy.act_arrays(env.observe_arrays()))
        m = env.task.metrics(env.engine)
        if two_levels is None and m["levels"] >= 2 and m["tree"]:
            two_levels = env.cycle
        if out_at is None and m["searching"] == 0:
            out_at = env.cycle
        if out_at is not None and env.cycle >= out_at + job["settle"]:
            break
    m = env.task.metrics(env.engine)
    mode = env.engine.mode
    waiting_nodes = int((mode == NODE).sum())
    grown = (mode == SEED) | (mode == FINAL) | (mode == NODE) | (mode == INODE)
    return {
        "layers": int(np.unique(env.engine.positions[grown, 2]).size),
        **job,
        **{k: m[k] for k in STATS},
        "two_levels": two_levels,
        "out_at": out_at,
        "waiting_nodes": waiting_nodes,
        "inodes": int((mode == INODE).sum()),
        "cycles": env.cycle,
        "seconds": time.perf_counter() - started,
    }


def draw_paper_setting(path: Path, seed: int = 0) -> None:
    """The paper's setting (T = 12, B = 6, N = 100, minimal) grown in the plane and in 3D, side by
    side, seen from above at an angle: ``path`` (PNG)."""
    from PIL import Image

    import proteo_env
    from baselines.branch import BranchPolicy
    from proteo_env.render.camera import Camera
    from proteo_env.render.renderer import Renderer
    from proteo_env.render.scene import Scene

    panels = []
    for growth in ("planar", "3d"):
        env = proteo_env.make("branch-v1", planar=growth == "planar", max_cycles=400, motion_model="minimal")
        env.reset(seed=seed)
        policy = BranchPolicy.for_env(env, seed=seed)
        while True:
            result = env.step_arrays(policy.act_arrays(env.observe_arrays()))
            if result.terminated.any() or result.truncated.any():
                break
        caption = f"branch-v1, {growth}, seed {seed}: cycle {env.cycle}"
        renderer = Renderer(Camera.from_options({"width": 800, "height": 600, "follow": True, "elevation": 35.0}))
        panels.append(renderer.render(Scene.from_world(env.world, caption=caption)))
        renderer.close()
    Image.fromarray(np.concatenate(panels, axis=1)).save(path)


def fmt(values, digits=1) -> str:
    v = np.asarray(values, dtype=float)
    return f"{v.mean():.{digits}f} ({v.min():.{digits}f}..{v.max():.{digits}f})"


def cyc(values) -> str:
    got = [v for v in values if v is not None]
    if not got:
        return "never"
    miss = len(values) - len(got)
    return f"{int(np.median(got))} (max {max(got)})" + (f", {miss} never" if miss else "")


def table(rows: list[dict], keys: tuple[str, ...]) -> list[str]:
    groups: dict = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in keys), []).append(r)
    head = list(keys) + [
        "runs",
        "levels",
        ">=2 levels",
        "branch points",
        "branches/point",
        "most at a point",
        "layers",
        "point distance",
        "tree",
        "used",
        "tips left",
        "nodes waiting",
        "2 levels at (median)",
        "modules out at (median)",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for key, rs in sorted(groups.items()):

        def col(k, rs=rs):
            return [r[k] for r in rs]

        cells = [str(v) for v in key] + [
            str(len(rs)),
            fmt(col("levels"), 2),
            f"{sum(r['levels'] >= 2 for r in rs)}/{len(rs)}",
            fmt(col("branch_points")),
            fmt(col("branches_per_point"), 2),
            fmt(col("max_branches"), 0),
            fmt(col("layers"), 0),
            fmt(col("point_distance")),
            f"{sum(r['tree'] > 0 for r in rs)}/{len(rs)}",
            fmt(np.array(col("tree_size")) / np.array(col("n")), 2),
            fmt(col("seeds")),
            fmt(col("waiting_nodes")),
            cyc(col("two_levels")),
            cyc(col("out_at")),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10, help="episodes (seeds 0..S-1) per setting")
    parser.add_argument("--sizes", type=int, nargs="+", default=[100])
    parser.add_argument("--Ts", type=int, nargs="+", default=[4, 8, 12])
    parser.add_argument("--Bs", type=int, nargs="+", default=[1, 2, 3, 6])
    parser.add_argument(
        "--growths", nargs="+", default=["planar", "3d"], choices=["planar", "3d"], help="growth in the plane or in 3D"
    )
    parser.add_argument("--models", nargs="+", default=["minimal"], help="motion models of the T x B table")
    parser.add_argument(
        "--paper-models",
        nargs="*",
        default=["minimal", "rounded", "sphere", "rhombic"],
        help="motion models compared at the paper's T=12, B=6, N=100",
    )
    parser.add_argument("--max-cycles", type=int, default=6000)
    parser.add_argument("--settle", type=int, default=60, help="cycles run after the modules ran out")
    add_workers(parser)
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument(
        "--picture", type=Path, default=None, help="also draw the paper's setting in the plane and in 3D (PNG)"
    )
    args = parser.parse_args(argv)

    base = {"max_cycles": args.max_cycles, "settle": args.settle}
    jobs = [
        {**base, "n": n, "T": t, "B": b, "growth": g, "model": m, "seed": s}
        for n, t, b, g, m, s in itertools.product(
            args.sizes, args.Ts, args.Bs, args.growths, args.models, range(args.seeds)
        )
    ]
    paper = [
        {**base, "n": 100, "T": 12, "B": 6, "growth": g, "model": m, "seed": s}
        for g in args.growths
        for m in args.paper_models
        for s in range(args.seeds)
    ]
    started = time.perf_counter()
    rows = list(run_jobs(run_one, jobs + paper, args.workers))
    elapsed = time.perf_counter() - started
    main_rows, paper_rows = rows[: len(jobs)], rows[len(jobs) :]

    lines = [
        "# Branch task: evidence",
        "",
        f"Generated by `benchmarks/branch_evidence.py` ({arguments(argv) or 'defaults'}) on "
        f"{machine(args.workers)} in {elapsed:.0f} s. Seeds 0..{args.seeds - 1} "
        f"(one random blob per seed), hand-coded `BranchPolicy` with default parameters, success switched off, "
        f"each episode run until no module is left in SLEEP or SEARCH plus {args.settle} cycles "
        f"(limit {args.max_cycles}).",
        "",
        "Cells are mean (min..max) over the seeds. *levels*: branching levels as the task measures them (real branching points, at least `min_gap` = 3 apart; see `docs/tasks/branch.md`); *>=2 levels*: runs ending with at least 2; "
        "*branches/point*: child branches per branching point (degree, minus the parent branch except at the "
        "root); *most at a point*: the most child branches at one branching point; *layers*: horizontal "
        "layers the tree spans; *point distance*: mean hops along the tree from a branching point to its parent point; "
        "*tree*: runs whose grown structure has no cycle; *used*: share of the modules in the grown tree; "
        "*tips left*: seeds still waiting for modules when the modules ran out (unfinished branches); "
        "*nodes waiting*: NODEs that had not spawned all their B seeds; *2 levels at*: cycle at which the "
        "tree first had 2 levels; *modules out at*: cycle at which no module was left searching.",
        "",
        f"## Tree statistics against T and B (motion model {', '.join(args.models)})",
        "",
    ]
    if args.picture:
        draw_paper_setting(args.picture)
        lines += [
            f"![The paper's setting grown in the plane and in 3D]({os.path.relpath(args.picture, args.out.parent if args.out else Path('.'))})",
            "",
        ]
    lines += table(main_rows, ("n", "model", "T", "B", "growth"))
    lines += ["", "## The paper's setting (T = 12, B = 6, N = 100) under each motion model", ""]
    lines += table(paper_rows, ("n", "T", "B", "growth", "model"))
    publish("\n".join(lines) + "\n", args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

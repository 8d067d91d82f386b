"""Evidence for the table task (paper section 4.3), written to ``docs/evidence/table.md``.

Measures, over many seeds of the paper's experiment (``configs/table.yaml``):

1. cycles from each weight shift to the next stable configuration (the task's
   ``restabilise_k`` metric), median and spread, next to the paper's "on the order of 200
   cycles";
2. grounded legs per region over time;
3. the paper's argument for probabilistic roots: leg creations and disbandings per shift,
   reversals of the active-root count, and how far the legs drop, with ``p_max = p_min`` of
   0.05 (paper), 0.2 and 1 (deterministic roots);
4. which motion models the table works under, and the random policy for comparison.

Regenerate (about 10 minutes on 2 busy cores; single-threaded numba is much faster for one
world than the default thread pool)::

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/table_evidence.py --seeds 10 --out docs/evidence/table.md
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from evidence import add_workers, machine, publish, run_jobs

ROOT = Path(__file__).resolve().parents[1]

from baselines import make_policy  # noqa: E402
from proteo_env import make  # noqa: E402
from proteo_env.config import load_run_config  # noqa: E402
from proteo_env.core.lattice import DIRECTIONS  # noqa: E402
from proteo_env.core.world import Physics, World  # noqa: E402
from proteo_env.rollout import run_episode  # noqa: E402
from proteo_env.tasks.table import board_sites  # noqa: E402

PAPER_CYCLES = 200
SERIES = (
    "legs_left",
    "legs_right",
    "grounded_legs",
    "active_left",
    "active_right",
    "support",
    "leg_creations",
    "leg_disbands",
    "weight_left",
    "weight_right",
)


def run(task_id: str, overrides: dict, seed: int, policy: str = "table") -> dict:
    """One episode; the per-cycle series of the metrics we need (index = cycle) and the final metrics."""
    env = make(task_id, **overrides)
    pol = make_policy(policy, env, seed=seed)
    rows = []
    started = time.perf_counter()
    result = run_episode(env, pol, seed=seed, observe=lambda env, info: rows.append(info))
    seconds = time.perf_counter() - started
    series = {name: np.array([row[f"metric/{name}"] for row in rows]) for name in SERIES}
    return {
        "series": series,
        "metrics": result.metrics,
        "cycles": result.cycles,
        "success": result.success,
        "reward": result.total_reward,
        "seconds": seconds,
    }


def run_job(job: dict) -> dict:
    """:func:`run` of one job (its keyword arguments), for :func:`evidence.run_jobs`."""
    return run(**job)


def shift_windows(schedule, cycles: int) -> list[tuple[int, int]]:
    """``[(start, end), ...]`` cycle windows of the schedule's entries (end exclusive, clipped)."""
    starts = [int(entry[0]) for entry in schedule]
    ends = starts[1:] + [cycles + 1]
    return [(s, min(e, cycles + 1)) for s, e in zip(starts, ends) if s <= cycles]


def per_shift(ep: dict, schedule) -> list[dict]:
    """Counts of one episode in each schedule window."""
    s = ep["series"]
    out = []
    for k, (a, b) in enumerate(shift_windows(schedule, ep["cycles"])):
        last = b - 1
        active = s["active_left"][a:b] + s["active_right"][a:b]
        steps = np.sign(np.diff(active))
        steps = steps[steps != 0]
        reversals = int((steps[1:] != steps[:-1]).sum()) if steps.size > 1 else 0
        after = slice(a + 1, b) if b > a + 1 else slice(a, b)
        out.append(
            {
                "restabilise": float(ep["metrics"].get(f"restabilise_{k}", -1)),
                "creations": int(s["leg_creations"][last] - s["leg_creations"][a]),
                "disbands": int(s["leg_disbands"][last] - s["leg_disbands"][a]),
                "reversals": reversals,
                "min_legs_left": int(s["legs_left"][after].min()),
                "min_legs_right": int(s["legs_right"][after].min()),
                "legs_left": int(s["legs_left"][last]),
                "legs_right": int(s["legs_right"][last]),
                "active_left": int(s["active_left"][last]),
                "active_right": int(s["active_right"][last]),
                "unsupported": int((s["support"][after] < 1.0).sum()),
                "weights": (float(s["weight_left"][min(a + 1, last)]), float(s["weight_right"][min(a + 1, last)])),
            }
        )
    return out


def spread(values) -> str:
    v = np.asarray([x for x in values if x >= 0], dtype=float)
    missing = len(values) - len(v)
    if v.size == 0:
        return f"none of {len(values)} stable"
    q1, med, q3 = np.percentile(v, [25, 50, 75])
    text = f"{med:.0f} (IQR {q1:.0f}-{q3:.0f}, range {v.min():.0f}-{v.max():.0f})"
    return text + (f", {missing} of {len(values)} never stable" if missing else "")


def med_range(values) -> str:
    v = np.asarray(values, dtype=float)
    return f"{np.median(v):.1f} ({v.min():.0f}-{v.max():.0f})"


def legs_over_time(episodes: list[dict], every: int, until: int) -> list[tuple]:
    """``(cycle, median legs_left, median legs_right, median active_left, median active_right)``."""
    rows = []
    for c in range(0, until + 1, every):
        vals = []
        for ep in episodes:
            s = ep["series"]
            i = min(c, len(s["legs_left"]) - 1)  # an episode that ended (stable) keeps its last values
            vals.append((s["legs_left"][i], s["legs_right"][i], s["active_left"][i], s["active_right"][i]))
        v = np.median(np.array(vals), axis=0)
        rows.append((c, *v))
    return rows


def reach_floor_spot(model: str) -> bool:
    """Can a lone module, rolling over a static leg that ends in a SEED at z = 1, reach any of
    the 4 sites below that SEED (all on the floor layer)? Breadth-first over single rolls."""
    h = 4
    board = [(x, y, h) for x in range(12) for y in range(12) if (x + y + h) % 2 == 0]
    legs = ([(4, 3, 3), (3, 3, 2), (4, 3, 1)], [(4, 3, 3), (5, 3, 2), (6, 3, 1)], [(4, 3, 3), (4, 4, 2), (5, 4, 1)])
    for leg in legs:
        seed = np.array(leg[-1])
        spots = {tuple(seed + d) for d in DIRECTIONS if d[2] == -1}
        starts = [tuple(seed + d) for d in DIRECTIONS if tuple(seed + d) not in leg and 1 <= (seed + d)[2] < h]
        seen = set(starts)
        frontier = list(starts)
        while frontier:
            p = frontier.pop()
            w = World(
                size=(12, 12, h + 1),
                positions=np.array([p] + board + leg),
                n_agents=1,
                physics=Physics(motion_model=model, keep_connected=False),
                anchored=np.array([False] + [True] * (len(board) + len(leg))),
                floor=True,
            )
            for k in range(12):
                if w.roll_is_legal(0, k):
                    q = tuple(int(v) for v in np.array(p) + DIRECTIONS[k])
                    if q not in seen:
                        seen.add(q)
                        frontier.append(q)
        if seen & spots:
            return True
    return False


def _shown(path) -> str:
    path = Path(path).resolve()
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=str(ROOT / "configs" / "table.yaml"))
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--p-values", type=float, nargs="+", default=[0.05, 0.2, 1.0])
    parser.add_argument("--model-seeds", type=int, default=2, help="seeds per other motion model")
    parser.add_argument("--model-cycles", type=int, default=800, help="cycle limit of the motion-model runs")
    parser.add_argument("--random-seeds", type=int, default=3)
    parser.add_argument("--every", type=int, default=50, help="legs-over-time sampling period (cycles)")
    parser.add_argument("--out", default=None, help="markdown file (default: print)")
    add_workers(parser, default=1)
    args = parser.parse_args(argv)

    task_id, base = load_run_config(args.config)
    env = make(task_id, **base)
    params = env.task.params
    schedule = params.schedule
    n_roots, n_fixed = (len(sites) for sites in board_sites(params))
    began = time.perf_counter()
    lines = [
        "# Table task: evidence (paper section 4.3)",
        "",
        "Written by `benchmarks/table_evidence.py`; regenerate with",
        "",
        "```",
        f"NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/table_evidence.py --seeds {args.seeds} "
        f"--out docs/evidence/table.md",
        "```",
        "",
        f"Experiment: `{_shown(args.config)}` "
        f"({task_id}, hand-coded `table` policy): board {params.board_size} x {params.board_size} "
        f"({n_roots + n_fixed} board modules: {n_roots} roots, {n_fixed} FIXED), roots every "
        f"{params.root_spacing} sites, depth {params.depth}, {params.n_spares} spare modules, "
        f"F_max = {params.f_max}, F_min = {params.f_min}, stable window {params.stable_window} cycles, "
        f"motion model `{base.get('motion_model', 'default')}`, schedule (cycle, W1, W2) = {list(schedule)}.",
        f"Seeds 0..{args.seeds - 1} for each setting. Machine: {machine(args.workers)}.",
        "",
    ]

    def run_seeds(overrides: dict, seeds: int, policy: str = "table") -> list[dict]:
        jobs = [dict(task_id=task_id, overrides=overrides, seed=seed, policy=policy) for seed in range(seeds)]
        return list(run_jobs(run_job, jobs, args.workers))

    results: dict[float, list[dict]] = {}
    for p in args.p_values:
        results[p] = run_seeds({**base, "p_max": p, "p_min": p}, args.seeds)
        for seed, ep in enumerate(results[p]):
            ep["shifts"] = per_shift(ep, schedule)
            print(
                f"p={p} seed={seed}: {ep['cycles']} cycles, success={ep['success']}, "
                f"restabilise={[s['restabilise'] for s in ep['shifts']]}, {ep['seconds']:.1f}s",
                flush=True,
            )

    # 1. re-stabilisation
    lines += [
        "## Cycles to a new stable configuration after each weight shift",
        "",
        "A configuration is stable when every active root (ROOT/AROOT) stands on a grounded leg, no "
        f"other root does, and this stays unchanged for {params.stable_window} cycles; the time is "
        "counted from the shift to the start of that period (`restabilise_k`, docs/tasks/table.md). "
        f'Paper: "on the order of {PAPER_CYCLES} cycles". Median (IQR, range) over seeds.',
        "",
        "| p_max = p_min | "
        + " | ".join(f"entry {k}: cycle {c}, W = {w1:g}/{w2:g}" for k, (c, w1, w2) in enumerate(schedule))
        + " | success |",
        "|---" * (len(schedule) + 2) + "|",
    ]
    for p, episodes in results.items():
        cells = [
            spread([ep["shifts"][k]["restabilise"] if k < len(ep["shifts"]) else -1 for ep in episodes])
            for k in range(len(schedule))
        ]
        lines.append(
            f"| {p:g} | " + " | ".join(cells) + f" | {sum(ep['success'] for ep in episodes)}/{len(episodes)} |"
        )
    lines += ["", "Entry 0 is the first growth from the start (no legs yet).", ""]

    # 3. the paper's argument
    lines += [
        "## Probabilistic versus deterministic roots",
        "",
        "Per schedule window (from a shift to the next, or to the end of the episode): roots turning "
        "active (leg creations) and inactive (disbandings), reversals of the total active-root count "
        "(up then down or down then up), the fewest grounded legs per region after the shift, the cycles "
        "with weight not carried (support < 1), and the legs at the end of the window. Median (range) over "
        "seeds.",
        "",
        "| p | window | W1/W2 | creations | disbandings | reversals | fewest legs L/R | cycles unsupported "
        "| legs at end L/R |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for p, episodes in results.items():
        for k in range(len(schedule)):
            rows = [ep["shifts"][k] for ep in episodes if k < len(ep["shifts"])]
            if not rows:
                continue
            w1, w2 = rows[0]["weights"]
            lines.append(
                f"| {p:g} | {k} | {w1:g}/{w2:g} | {med_range([r['creations'] for r in rows])} | "
                f"{med_range([r['disbands'] for r in rows])} | {med_range([r['reversals'] for r in rows])} | "
                f"{np.median([r['min_legs_left'] for r in rows]):.0f}/{np.median([r['min_legs_right'] for r in rows]):.0f} | "
                f"{med_range([r['unsupported'] for r in rows])} | "
                f"{np.median([r['legs_left'] for r in rows]):.0f}/{np.median([r['legs_right'] for r in rows]):.0f} |"
            )
    lines.append("")

    # 2. legs over time
    until = max(ep["cycles"] for eps in results.values() for ep in eps)
    for p in (args.p_values[0], args.p_values[-1]) if len(args.p_values) > 1 else args.p_values:
        lines += [
            f"## Grounded legs per region over time, p = {p:g}",
            "",
            f"Median over seeds every {args.every} cycles (an episode that ended, stable after the last "
            "shift, keeps its last values). Shifts at cycles "
            f"{', '.join(str(c) for c in params.shift_cycles[1:])}.",
            "",
            "| cycle | W1/W2 | legs left | legs right | active left | active right |",
            "|---|---|---|---|---|---|",
        ]
        for c, ll, lr, al, ar in legs_over_time(results[p], args.every, until):
            k = max(i for i, entry in enumerate(schedule) if entry[0] <= c)
            lines.append(f"| {c} | {schedule[k][1]:g}/{schedule[k][2]:g} | {ll:g} | {lr:g} | {al:g} | {ar:g} |")
        lines.append("")

    # 4. motion models and the random policy
    lines += [
        "## Motion models",
        "",
        "The same experiment under the other motion models (seeds 0.."
        f"{args.model_seeds - 1}, at most {args.model_cycles} cycles), and whether a lone module rolling "
        "over a static leg can reach any site below the leg's SEED when that SEED is one layer above "
        "the floor (breadth-first search over single rolls, three leg shapes).",
        "",
        "| motion model | most grounded legs | success | reaches the floor spot |",
        "|---|---|---|---|",
    ]
    minimal_best = max(int(ep["series"]["grounded_legs"].max()) for ep in results[args.p_values[0]])
    minimal_ok = sum(ep["success"] for ep in results[args.p_values[0]])
    lines.append(
        f"| minimal (above, p = {args.p_values[0]:g}) | {minimal_best} | {minimal_ok}/{args.seeds} | "
        f"{'yes' if reach_floor_spot('minimal') else 'no'} |"
    )
    for model in ("sphere", "rounded", "rhombic"):
        overrides = {**base, "motion_model": model, "max_cycles": args.model_cycles}
        eps = run_seeds(overrides, args.model_seeds)
        best = max(int(ep["series"]["grounded_legs"].max()) for ep in eps)
        print(f"{model}: most grounded legs {best}", flush=True)
        lines.append(
            f"| {model} | {best} | {sum(ep['success'] for ep in eps)}/{len(eps)} | "
            f"{'yes' if reach_floor_spot(model) else 'no'} |"
        )
    lines.append("")

    lines += [
        "## Random policy",
        "",
        f"The `random` policy on the same experiment (seeds 0..{args.random_seeds - 1}) next to the "
        "hand-coded one: team reward summed over the episode, most grounded legs, success.",
        "",
        "| policy | reward per cycle | most grounded legs | success | cycles |",
        "|---|---|---|---|---|",
    ]
    for name, eps in (
        (f"table (p = {args.p_values[0]:g})", results[args.p_values[0]]),
        ("random", run_seeds(base, args.random_seeds, policy="random")),
    ):
        per_cycle = [ep["reward"] / max(ep["cycles"], 1) for ep in eps]
        lines.append(
            f"| {name} | {np.median(per_cycle):.3f} | "
            f"{max(int(ep['series']['grounded_legs'].max()) for ep in eps)} | "
            f"{sum(ep['success'] for ep in eps)}/{len(eps)} | {med_range([ep['cycles'] for ep in eps])} |"
        )
    seconds = [ep["seconds"] for eps in results.values() for ep in eps]
    lines += [
        "",
        f"Episode wall time (hand-coded, all p): median {np.median(seconds):.1f} s; whole run "
        f"{(time.perf_counter() - began) / 60:.1f} min.",
        "",
    ]

    publish("\n".join(lines), args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""In-kernel chain behaviour: module-cycles per second against N, and against the Python loop.

Workload (the same on every machine): the chain task (``chain-v0``, default physics: ``minimal``
rolls, connectivity kept, one scent sweep per cycle) with N modules, reset with seed 0, and the
hand-coded chain policy (``ChainPolicy``, default parameters, seed 0); the first ``--cycles``
cycles from the reset. The box has ``room = cycles + 4`` free sites on each horizontal side
instead of the task's ``N + 3`` (whose grid would not fit in memory above a few thousand
modules); walls that far away touch no module in those cycles, so the trajectory is the
default box's (``tests/test_compiled_rollout.py::test_room_changes_no_early_cycle``).

Each N runs in a fresh process (peak memory per row) with ``NUMBA_NUM_THREADS=--threads``:

* ``build``: ``make`` + ``reset`` (the blob is grown in Python);
* ``first call``: ``CompiledRollout(env, policy).run(1)``, the load of the on-disk JIT cache plus
  one cycle (the compile itself is timed once apart, in a process with an empty
  ``NUMBA_CACHE_DIR``);
* ``kernel``: ``CompiledRollout(env, policy).run(cycles)``, ``--repeats`` times from the same reset
  (the same trajectory every time); the table gives the best repeat and the median;
* ``python``: the observation-based loop
  ``env.step_arrays(policy.act_arrays(env.observe_arrays()))`` over the same cycles from the
  same reset, once. The policy calls the same rule kernels, so the difference is what the
  Python loop adds around them: action validation, fresh observation buffers, the task's
  metrics. The final positions, modes and generator state must equal the kernel's.

``--profile-n`` (default 10,000) also times each kernel of the loop on its own over the same
cycles (called one by one from Python): the cut modules (Tarjan's pass, for exact action
masks), the observation, the chain rule's decisions, the engine's cycle (messages, moves with
the connectivity check, scent sweep) and the success test; and, apart, as many uniform draws
from the policy's generator as 13 per SEARCH module (the least the rule draws for a climbing
module: one "random roll instead?" uniform and 12 keys of its pick), and the cycle's moves
alone, with and without the connectivity check (on copies of the state).
``--chain-episodes N SEEDS`` (default 500 1) and ``--branch-episodes N SEEDS`` (default 100 10)
run whole episodes to success of the chain and the branch behaviours in their tasks' default
boxes, both ways, and check that they end alike; ``--table-episodes BOARD SEEDS`` (default
30 10) the same for the table behaviour in ``configs/table.yaml`` (the paper's two weight
shifts) on a ``BOARD`` by ``BOARD`` board, and ``--grasp-episodes N SEEDS`` (default 160 10)
for the grasp behaviour in ``configs/grasp.yaml`` with N modules.

Usage::

    python benchmarks/chain_kernel_speed.py --sizes 100 1000 10000 100000 --out docs/speed/chain_kernel

writes ``<out>.json`` (machine, arguments, rows), ``<out>.md`` (the tables) and ``<out>.png``.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from machine_info import describe  # noqa: E402

DRAWS_PER_SEARCH_MODULE = 13


def fresh(n: int, cycles: int, room: int | None = None, *, task: str = "chain", seed: int = 0):
    """The workload's env (reset with ``seed``) and the task's hand-coded policy (seeded the same).
    ``n`` is the number of modules, or for the table the board's side (``configs/table.yaml``)."""
    import proteo_env
    from baselines import make_policy
    from proteo_env.config import load_yaml

    if task in ("table", "grasp"):
        config = load_yaml(ROOT / "configs" / f"{task}.yaml")
        size = {"table": "board_size", "grasp": "n_modules"}[task]
        extra = {k: v for k, v in config.items() if k not in ("task", "max_cycles")} | {size: n}
    else:
        extra = {"n_modules": n} if room is None else {"n_modules": n, "room": room}
    env = proteo_env.make(f"{task}-v0", max_cycles=cycles, **extra)
    env.reset(seed=seed)
    return env, make_policy(task, env, seed=seed)


def python_loop(env, policy, cycles: int, *, until_success: bool = False) -> float:
    """Seconds of ``cycles`` cycles of the observation-based loop (stopping at success if asked)."""
    started = time.perf_counter()
    for _ in range(cycles):
        env.step_arrays(policy.act_arrays(env.observe_arrays()))
        if until_success and env.task.success(env.engine):
            break
    return time.perf_counter() - started


def measure(n: int, cycles: int, repeats: int) -> dict:
    """One row: build, first call, kernel repeats and the Python loop at ``n`` modules."""
    from baselines.compiled import CompiledRollout

    started = time.perf_counter()
    env, policy = fresh(n, cycles, room=cycles + 4)
    build_s = time.perf_counter() - started
    started = time.perf_counter()
    CompiledRollout(env, policy).run(1)
    first_s = time.perf_counter() - started
    seconds = []
    for _ in range(repeats):
        rollout = CompiledRollout(env, policy)
        started = time.perf_counter()
        result = rollout.run(cycles)
        seconds.append(time.perf_counter() - started)
    python_s = python_loop(env, policy, result.cycles)
    same = (
        np.array_equal(env.world.positions, result.positions)
        and np.array_equal(env.world.modes, result.modes)
        and policy.rng.bit_generator.state == result.rng.bit_generator.state
    )
    if not same:
        raise AssertionError(f"N={n}: the kernel and the Python loop reached different states")
    best, median = min(seconds), float(np.median(seconds))
    ran = result.cycles
    return {
        "n_modules": n,
        "cycles": ran,
        "repeats": repeats,
        "build_s": build_s,
        "first_call_s": first_s,
        "kernel_s": seconds,
        "kernel_ms_per_cycle": 1e3 * best / ran,
        "kernel_median_ms_per_cycle": 1e3 * median / ran,
        "kernel_module_cycles_per_s": n * ran / best,
        "python_ms_per_cycle": 1e3 * python_s / ran,
        "python_module_cycles_per_s": n * ran / python_s,
        "ratio": python_s / best,
        "modes_at_end": np.bincount(result.modes, minlength=4).tolist(),
        "same_state": same,
        "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def profile(n: int, cycles: int) -> dict:
    """Each kernel of the loop timed on its own over the workload's cycles (ns per module-cycle).

    Every kernel is called once on a small chain first, so that no compile lands in the timings.
    """
    import numba

    from baselines.base import Observed, stacked_fields
    from baselines.chain import chain_actions
    from proteo_env.core import cycle
    from proteo_env.core.records import Actions, Observation
    from proteo_env.tasks.chain import is_chain

    @numba.njit
    def draw(rng, count):
        total = 0.0
        for _ in range(count):
            total += rng.random()
        return total

    def run(n: int, cycles: int) -> dict:
        env, policy = fresh(n, cycles, room=cycles + 4)
        # The kernels are called here one by one, without the env's step that grows a world's grid
        # window as its modules near the window's edge: the grid covers the whole box instead
        # (walls cycles + 4 sites away: no module reaches them in the cycles).
        env.task.window_room = None
        env.reset(seed=0)
        policy.reset(0)
        w, s = env.engine, env.engine.scratch
        obs = env.observe_arrays()
        memory, rules, slots = policy.memory_rows(env.possible_agents), policy.rule_params, np.arange(n)
        seen = Observed(*stacked_fields(lambda f: getattr(obs, f), Observed._fields))
        actions = np.empty((n, env.action_layout.length), dtype=np.int64)
        moved = np.zeros(n, dtype=np.bool_)
        test = [np.zeros(n, dtype=np.int64) for _ in range(3)]
        parts = dict.fromkeys(
            (
                "cut modules",
                "observation",
                "decisions",
                "cycle",
                "success test",
                "draws",
                "moves",
                "moves without the connectivity check",
            ),
            0.0,
        )
        n_search = n_requested = n_moved = 0
        for _ in range(cycles):
            t0 = time.perf_counter()
            cycle.articulation_points(w.grid, w.cell, n, w.dir_delta, s)
            t1 = time.perf_counter()
            cycle.observe(w.state, w.settings, w.geometry, s.is_cut, Observation.of(obs))
            t2 = time.perf_counter()
            searching = int((obs.own_mode[:, 0] == 1).sum())
            spare = copy.deepcopy(policy.rng)
            t3 = time.perf_counter()
            draw(spare, DRAWS_PER_SEARCH_MODULE * searching)
            t4 = time.perf_counter()
            chain_actions(seen, slots, memory.arrays(), rules, policy.rng, actions)
            t5 = time.perf_counter()
            move = actions[:, 0].copy()
            for keep, part in ((True, "moves"), (False, "moves without the connectivity check")):
                trial = w.state._replace(grid=w.grid.copy(), cell=w.cell.copy(), rng_state=w.rng_state.copy())
                started = time.perf_counter()
                cycle.execute_moves(trial, w.settings._replace(keep_connected=keep), w.geometry, move, moved, s)
                parts[part] += time.perf_counter() - started
            n_requested += int((move > 0).sum())
            t6 = time.perf_counter()
            step = Actions.of(
                move=move,
                mode=actions[:, 1],
                scent_role=actions[:, 2:-2],
                message_target=actions[:, -2].copy(),
                message_value=actions[:, -1],
            )
            cycle.run_cycle(w.state, w.settings, w.geometry, step, moved, s)
            t7 = time.perf_counter()
            n_moved += int(moved.sum())
            is_chain(w.grid, w.cell, n, w.dir_delta, *test)
            t8 = time.perf_counter()
            for part, dt in zip(parts, (t1 - t0, t2 - t1, t5 - t4, t7 - t6, t8 - t7, t4 - t3)):
                parts[part] += dt
            n_search += searching
        return {
            "n_modules": n,
            "cycles": cycles,
            "search_module_cycles": n_search,
            "requested_per_cycle": n_requested / cycles,
            "moved_per_cycle": n_moved / cycles,
            "ns_per_module_cycle": {k: 1e9 * v / (n * cycles) for k, v in parts.items()},
        }

    run(20, 2)
    return run(n, cycles)


def compile_time(n: int) -> dict:
    """Seconds of the first ``run(1)`` (the compile of the rollout kernel and everything it calls,
    when the process has an empty ``NUMBA_CACHE_DIR``)."""
    from baselines.compiled import CompiledRollout

    env, policy = fresh(n, 1, room=5)
    started = time.perf_counter()
    CompiledRollout(env, policy).run(1)
    return {"n_modules": n, "first_call_s": time.perf_counter() - started}


def whole_episodes(task: str, n: int, seeds: int) -> dict:
    """Episodes to success of seeds ``0 .. seeds - 1`` in the task's default box and physics
    (limit ``20 N`` cycles; the table: ``configs/table.yaml``, limit 1,300 cycles), compiled
    and through the Python loop (summed); module-cycles count every module (the table's board
    too)."""
    from baselines.compiled import compiled_rollout

    limit = 1300 if task == "table" else 20 * n  # the grasp: 3,200 cycles for 160 modules
    warm_env, warm_policy = fresh(n, limit, task=task)
    compiled_rollout(warm_env, warm_policy, max_cycles=1)
    cycles, successes, kernel_s, python_s = 0, 0, 0.0, 0.0
    for seed in range(seeds):
        env, policy = fresh(n, limit, task=task, seed=seed)
        started = time.perf_counter()
        result = compiled_rollout(env, policy)
        kernel_s += time.perf_counter() - started
        python_s += python_loop(env, policy, limit, until_success=True)
        if env.cycle != result.cycles or not np.array_equal(env.world.positions, result.positions):
            raise AssertionError(f"{task} N={n} seed {seed}: the kernel and the Python loop ended differently")
        cycles += result.cycles
        successes += result.success
    modules = env.engine.n_modules
    return {
        "task": task,
        "n_modules": modules,
        "seeds": seeds,
        "successes": successes,
        "cycles": cycles,
        "kernel_s": kernel_s,
        "python_s": python_s,
        "kernel_module_cycles_per_s": modules * cycles / kernel_s,
        "python_module_cycles_per_s": modules * cycles / python_s,
        "ratio": python_s / kernel_s,
    }


def slope(rows: list[dict], key: str) -> float:
    """Least-squares slope of log(``key``) against log(N)."""
    x = np.log([r["n_modules"] for r in rows])
    y = np.log([r[key] for r in rows])
    return float(np.polyfit(x, y, 1)[0])


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = np.array([r["n_modules"] for r in rows], dtype=float)
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4.2), dpi=110)
    left.plot(n, [r["kernel_module_cycles_per_s"] for r in rows], marker="o", label="in-kernel chain rollout")
    left.plot(n, [r["python_module_cycles_per_s"] for r in rows], marker="s", label="policy through env (Python loop)")
    left.axhline(20e6, color="grey", linestyle=":", label="target: 20 M at N = 10,000")
    left.set_ylabel("module-cycles per second")
    ms = np.array([r["kernel_ms_per_cycle"] for r in rows])
    b, a = np.polyfit(np.log(n), np.log(ms), 1)
    right.plot(n, ms, marker="o", label="in-kernel, ms per cycle")
    right.plot(n, np.exp(a) * n**b, linestyle="--", label=f"fit: slope {b:.2f}")
    right.set_ylabel("ms per cycle")
    for ax in (left, right):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("modules N")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def tables(rows: list[dict], parts: dict | None, episodes: list[dict], args) -> str:
    lines = [
        f"| N | module-cycles/s (in-kernel, best) | ms per cycle (best / median of {args.repeats}) | "
        "module-cycles/s (Python loop) | x Python loop | build s | first call s | peak RSS MiB |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['n_modules']:,} | {r['kernel_module_cycles_per_s']:,.0f} | "
            f"{r['kernel_ms_per_cycle']:.3f} / {r['kernel_median_ms_per_cycle']:.3f} | "
            f"{r['python_module_cycles_per_s']:,.0f} | "
            f"{r['ratio']:.2f} | {r['build_s']:.2f} | {r['first_call_s']:.2f} | {r['peak_rss_mib']:.0f} |"
        )
    big = [r for r in rows if r["n_modules"] >= 10000]
    lines += [
        "",
        f"Log-log slope of ms per cycle against N: {slope(rows, 'kernel_ms_per_cycle'):.3f} over all sizes"
        + (f", {slope(big, 'kernel_ms_per_cycle'):.3f} from 10,000 to 100,000" if len(big) >= 2 else "")
        + ".",
    ]
    if parts:
        cost = parts["ns_per_module_cycle"]
        share = parts["search_module_cycles"] / (parts["n_modules"] * parts["cycles"])
        lines += [
            "",
            f"Parts at N = {parts['n_modules']:,} over the same {parts['cycles']} cycles (ns per "
            f"module-cycle; {share:.0%} of module-cycles were SEARCH):",
            "",
            "| part | ns per module-cycle |",
            "|---|---|",
        ]
        whole = ("cut modules", "observation", "decisions", "cycle", "success test")
        lines += [f"| {k} | {cost[k]:.1f} |" for k in whole]
        lines.append(f"| total of the parts | {sum(cost[k] for k in whole):.1f} |")
        lines.append(
            f"| of the decisions: {DRAWS_PER_SEARCH_MODULE} uniform draws per SEARCH module | {cost['draws']:.1f} |"
        )
        lines.append(
            f"| of the cycle: the moves ({parts['requested_per_cycle']:,.0f} requested and "
            f"{parts['moved_per_cycle']:,.0f} made per cycle, on average) | {cost['moves']:.1f} |"
        )
        lines.append(
            f"| the same moves without the connectivity check | {cost['moves without the connectivity check']:.1f} |"
        )
    if episodes:
        lines += [
            "",
            "Whole episodes to success (limit 20 N cycles; the table: `configs/table.yaml`, 1,300) in the "
            "task's default box, seeds 0 .. S - 1 (N: all modules, the table's board too):",
            "",
            "| task | N | seeds S | successes | cycles (sum) | in-kernel s | module-cycles/s | Python loop s | "
            "module-cycles/s | x Python loop |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        lines += [
            f"| {e['task']} | {e['n_modules']:,} | {e['seeds']} | {e['successes']} | {e['cycles']:,} | "
            f"{e['kernel_s']:.2f} | {e['kernel_module_cycles_per_s']:,.0f} | {e['python_s']:.2f} | "
            f"{e['python_module_cycles_per_s']:,.0f} | {e['ratio']:.2f} |"
            for e in episodes
        ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[100, 1000, 10000, 100000])
    parser.add_argument("--cycles", type=int, default=200, help="cycles from the reset, timed")
    parser.add_argument("--repeats", type=int, default=3, help="kernel runs of those cycles per size")
    parser.add_argument("--profile-n", type=int, default=10000, help="N of the per-part profile (0: none)")
    parser.add_argument(
        "--chain-episodes",
        type=int,
        nargs=2,
        default=[500, 1],
        metavar=("N", "SEEDS"),
        help="whole chain episodes to success: N and the number of seeds (0 0: none)",
    )
    parser.add_argument(
        "--branch-episodes",
        type=int,
        nargs=2,
        default=[100, 10],
        metavar=("N", "SEEDS"),
        help="whole branch episodes to success: N and the number of seeds (0 0: none)",
    )
    parser.add_argument(
        "--table-episodes",
        type=int,
        nargs=2,
        default=[30, 10],
        metavar=("BOARD", "SEEDS"),
        help="whole table episodes to success: board side and the number of seeds (0 0: none)",
    )
    parser.add_argument(
        "--grasp-episodes",
        type=int,
        nargs=2,
        default=[160, 10],
        metavar=("N", "SEEDS"),
        help="whole grasp episodes to success: N and the number of seeds (0 0: none)",
    )
    parser.add_argument("--threads", type=int, default=1, help="NUMBA_NUM_THREADS of the measurements")
    parser.add_argument("--out", default=None, help="write <out>.json, <out>.md and <out>.png")
    parser.add_argument("--one", nargs=2, metavar=("WHAT", "N"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        what, n = args.one[0], int(args.one[1])
        row = {
            "row": lambda: measure(n, args.cycles, args.repeats),
            "profile": lambda: profile(n, args.cycles),
            "chain-episodes": lambda: whole_episodes("chain", n, args.chain_episodes[1]),
            "branch-episodes": lambda: whole_episodes("branch", n, args.branch_episodes[1]),
            "table-episodes": lambda: whole_episodes("table", n, args.table_episodes[1]),
            "grasp-episodes": lambda: whole_episodes("grasp", n, args.grasp_episodes[1]),
            "compile": lambda: compile_time(n),
        }[what]()
        print(json.dumps(row))
        return

    def child(what: str, n: int, **env) -> dict:
        cmd = [
            sys.executable,
            __file__,
            "--one",
            what,
            str(n),
            "--cycles",
            str(args.cycles),
            "--repeats",
            str(args.repeats),
            "--chain-episodes",
            *map(str, args.chain_episodes),
            "--branch-episodes",
            *map(str, args.branch_episodes),
            "--table-episodes",
            *map(str, args.table_episodes),
            "--grasp-episodes",
            *map(str, args.grasp_episodes),
        ]
        env = {**os.environ, "NUMBA_NUM_THREADS": str(args.threads), **env}
        out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
        return json.loads(out.stdout.strip().splitlines()[-1])

    with tempfile.TemporaryDirectory() as empty_cache:
        compiled = child("compile", 100, NUMBA_CACHE_DIR=empty_cache)
    print(f"first call with an empty JIT cache (compile): {compiled['first_call_s']:.1f} s", flush=True)
    rows = []
    for n in args.sizes:
        rows.append(child("row", n))
        r = rows[-1]
        print(
            f"N={n:>7,}: in-kernel {r['kernel_module_cycles_per_s']:>12,.0f} module-cycles/s "
            f"({r['kernel_ms_per_cycle']:.3f} ms per cycle), Python loop {r['python_module_cycles_per_s']:>10,.0f} "
            f"(x{r['ratio']:.2f}), first call {r['first_call_s']:.2f} s, peak {r['peak_rss_mib']:.0f} MiB",
            flush=True,
        )
    parts = child("profile", args.profile_n) if args.profile_n else None
    episodes = [
        child(f"{task}-episodes", n)
        for task, (n, seeds) in (
            ("chain", args.chain_episodes),
            ("branch", args.branch_episodes),
            ("table", args.table_episodes),
            ("grasp", args.grasp_episodes),
        )
        if n and seeds
    ]
    info = describe("numpy", "numba", numba_threads=args.threads)
    text = tables(rows, parts, episodes, args)
    text = (
        f"JIT compile of the rollout (first call with an empty cache, N = 100): {compiled['first_call_s']:.1f} s; "
        "the *first call* column loads the compiled code from the on-disk cache.\n\n" + text
    )
    print(f"\nmachine: {info}\n\n{text}")
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.with_suffix(".json").write_text(
            json.dumps(
                {
                    "machine": info,
                    "args": vars(args),
                    "compile": compiled,
                    "results": rows,
                    "profile": parts,
                    "whole_episodes": episodes,
                },
                indent=2,
            )
        )
        out.with_suffix(".md").write_text(f"machine: `{info}`\n\n{text}\n")
        plot(rows, out.with_suffix(".png"))


if __name__ == "__main__":
    main()

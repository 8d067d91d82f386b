"""The speed suite: module-cycles per second against world size for every way of stepping.

For each world size N (random connected blobs in the sandbox task, uniform random actions on
every field) it measures, each in a fresh process so that peak memory is per measurement:

* ``pettingzoo``: :meth:`ProteoEnv.step` with per-agent dicts in and out;
* ``engine``: :meth:`ProteoEnv.step_arrays` + :meth:`ProteoEnv.observe_arrays` (one world, arrays);
* ``batched``: :class:`~proteo_env.batched.BatchedEnv` with ``B = max(1, batch_modules // N)``
  worlds stepped in one call (``B * N`` module-cycles per cycle);
* ``reference``: the pure-Python reference cycle (:mod:`proteo_env.core.reference`) with its
  observations, for the sizes where it finishes in reasonable time;
* ``chain-kernel``: the chain behaviour run entirely inside the compiled core, when available.

Every row records the first cycle apart (JIT compile, or loading the on-disk cache) and the
peak resident memory of its process. Ratios against the reference come from the same run.

Usage::

    python benchmarks/suite.py --sizes 100 1000 10000 100000 --threads 1 --out docs/speed/suite

``--out docs/speed/suite`` writes ``suite.json`` (machine, arguments, every row), ``suite.md``
(the table) and ``suite.png`` (the log-log plot); ``docs/benchmarks.md`` explains them.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from machine_info import describe

MODES = ("pettingzoo", "engine", "batched", "reference")


def _uniform_actions(nvec: np.ndarray, rows: int, rng: np.random.Generator) -> np.ndarray:
    return rng.integers(0, nvec, size=(rows, len(nvec)))


def _timed_cycles(step, budget_s: float, min_cycles: int = 3) -> tuple[float, int]:
    """Run ``step()`` until ``budget_s`` seconds pass; return (seconds, cycles)."""
    spent, cycles = 0.0, 0
    while spent < budget_s or cycles < min_cycles:
        spent += step()
        cycles += 1
    return spent, cycles


def measure(mode: str, n: int, batch_modules: int, budget_s: float) -> dict:
    """One measurement in this process (called in a subprocess by :func:`main`)."""
    import proteo_env

    rng = np.random.default_rng(0)
    started = time.perf_counter()
    if mode == "batched":
        n_envs = max(1, batch_modules // n)
        env = proteo_env.make_batched("sandbox-v0", n_envs, n_modules=n, max_cycles=10**9)
        env.reset(seed=0)
        rows = n_envs * n
        nvec = env.action_layout.nvec

        def step():
            actions = _uniform_actions(nvec, rows, rng).reshape(n_envs, n, -1)
            t = time.perf_counter()
            env.step_arrays(actions)
            env.observe_arrays()
            return time.perf_counter() - t
    elif mode in ("engine", "pettingzoo"):
        n_envs = 1
        rows = n
        env = proteo_env.make("sandbox-v0", n_modules=n, max_cycles=10**9)
        observations, _ = env.reset(seed=0)
        nvec = env.action_layout.nvec
        agents = env.possible_agents

        if mode == "engine":
            def step():
                actions = _uniform_actions(nvec, rows, rng)
                t = time.perf_counter()
                env.step_arrays(actions)
                env.observe_arrays()
                return time.perf_counter() - t
        else:
            def step():
                actions = dict(zip(agents, _uniform_actions(nvec, rows, rng)))
                t = time.perf_counter()
                env.step(actions)
                return time.perf_counter() - t
    elif mode == "reference":
        from proteo_env.core.reference import ReferenceWorld

        n_envs = 1
        rows = n
        env = proteo_env.make("sandbox-v0", n_modules=n, max_cycles=10**9)
        env.reset(seed=0)
        w = env.engine
        ref = ReferenceWorld(size=w.shape.size, positions=w.positions, n_agents=w.n_agents,
                             physics=w.physics, n_channels=w.n_channels)
        ref.seed(0)
        lay = env.action_layout

        def step():
            a = _uniform_actions(lay.nvec, rows, rng)
            t = time.perf_counter()
            ref.step(move=a[:, lay.move], mode=a[:, lay.mode], scent_role=a[:, lay.roles],
                     message_target=a[:, lay.message_target], message_value=a[:, lay.message_value])
            ref.observe()
            return time.perf_counter() - t
    else:
        raise ValueError(f"mode={mode!r} is not known; allowed: {', '.join(MODES)}")
    first = step() + (time.perf_counter() - started)
    seconds, cycles = _timed_cycles(step, budget_s)
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {"mode": mode, "n_modules": n, "n_envs": n_envs, "cycles": cycles,
            "first_cycle_s": first, "module_cycles_per_s": rows * cycles / seconds,
            "ms_per_cycle": 1e3 * seconds / cycles, "peak_rss_mib": peak_mib}


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.5), dpi=110)
    for mode in dict.fromkeys(r["mode"] for r in rows):
        pts = sorted((r["n_modules"], r["module_cycles_per_s"]) for r in rows if r["mode"] == mode)
        ax.plot(*zip(*pts), marker="o", label=mode)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("modules per world N")
    ax.set_ylabel("module-cycles per second")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[100, 1000, 10000, 100000])
    parser.add_argument("--modes", nargs="+", default=list(MODES), choices=MODES)
    parser.add_argument("--reference-max", type=int, default=1000, help="largest N for the reference")
    parser.add_argument("--batch-modules", type=int, default=20000, help="B * N of the batched runs")
    parser.add_argument("--budget", type=float, default=2.0, help="seconds of timed cycles per row")
    parser.add_argument("--threads", type=int, default=1, help="NUMBA_NUM_THREADS of the measurements")
    parser.add_argument("--out", default=None, help="write <out>.json, <out>.md (the table) and <out>.png")
    parser.add_argument("--one", nargs=2, metavar=("MODE", "N"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(measure(args.one[0], int(args.one[1]), args.batch_modules, args.budget)))
        return

    env = {**os.environ, "NUMBA_NUM_THREADS": str(args.threads)}
    rows = []
    for mode in args.modes:
        for n in args.sizes:
            if mode == "reference" and n > args.reference_max:
                continue
            cmd = [sys.executable, __file__, "--one", mode, str(n), "--batch-modules", str(args.batch_modules),
                   "--budget", str(args.budget)]
            out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
            rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
            r = rows[-1]
            print(f"{mode:>11} N={n:>7,} B={r['n_envs']:>4}: {r['module_cycles_per_s']:>14,.0f} module-cycles/s, "
                  f"{r['ms_per_cycle']:.3f} ms/cycle, first {r['first_cycle_s']:.2f} s, "
                  f"peak {r['peak_rss_mib']:.0f} MiB", flush=True)
    ref = {r["n_modules"]: r["module_cycles_per_s"] for r in rows if r["mode"] == "reference"}
    lines = ["| mode | N | worlds B | module-cycles/s | ms per cycle | x reference | first cycle s | peak RSS MiB |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ratio = f"{r['module_cycles_per_s'] / ref[r['n_modules']]:,.0f}" if r["n_modules"] in ref else "-"
        lines.append(f"| {r['mode']} | {r['n_modules']:,} | {r['n_envs']} | {r['module_cycles_per_s']:,.0f} | "
                     f"{r['ms_per_cycle']:.3f} | {ratio} | {r['first_cycle_s']:.2f} | {r['peak_rss_mib']:.0f} |")
    table = "\n".join(lines)
    info = describe("numpy", "numba", "gymnasium", "pettingzoo", numba_threads=args.threads)
    print(f"\nmachine: {info}\n\n{table}")
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.with_suffix(".json").write_text(json.dumps({"machine": info, "args": vars(args), "results": rows},
                                                       indent=2))
        out.with_suffix(".md").write_text(f"machine: `{info}`\n\n{table}\n")
        plot(rows, out.with_suffix(".png"))


if __name__ == "__main__":
    main()

"""The speed suite: module-cycles per second against world size for every way of stepping.

The workload is fixed so that any machine measures the same work: a random connected blob
of N modules in the sandbox task (default physics), reset with seed 0, then the first
``--cycles`` cycles of uniform random actions on every field (drawn from a generator seeded 0
at every reset, not timed). The episode is repeated from the same reset until ``--budget``
seconds of stepping have been spent, so every repeat follows the same trajectory. (The
workload matters: random rolls loosen the blob into thin strands, and the exact
connectivity check of each roll costs more the thinner the structure; per-cycle cost at
N = 10,000 roughly triples over the first 250 cycles.) Each measurement runs in a fresh
process so that peak memory is per measurement:

* ``pettingzoo``: :meth:`ProteoEnv.step` with per-agent dicts in and out;
* ``engine``: :meth:`ProteoEnv.step_arrays` + :meth:`ProteoEnv.observe_arrays` (one world, arrays);
* ``batched``: :class:`~proteo_env.batched.BatchedEnv` with ``B = max(1, batch_modules // N)``
  worlds stepped in one call (``B * N`` module-cycles per cycle);
* ``chain-kernel``: the hand-coded chain behaviour run inside compiled code
  (:class:`baselines.compiled.CompiledRollout`, observation, rule, cycle and success test in one
  kernel) on the chain task (``chain-v0`` with ``room=CHAIN_ROOM``, reset with seed 0, policy
  seed 0), not on the sandbox workload: the behaviour draws its own actions. One cycle per call
  here, so that each cycle is timed like the other modes; ``benchmarks/chain_kernel_speed.py``
  runs many cycles per call and compares with the policy driven through the env. No reference
  ratio (the reference runs the sandbox workload);
* ``reference``: the pure-Python reference cycle (:mod:`proteo_env.core.reference`) with its
  observations, from the same start and move-order seed as ``engine`` (so the same
  trajectory), for the first ``--reference-cycles`` cycles and sizes up to
  ``--reference-max``.

Ratios against the reference compare the same cycles: each mode's mean time over its first
``--reference-cycles`` cycles. Every row records the first cycle apart (loading the compiled
kernels from numba's on-disk cache, or compiling them when there is none) and the peak resident
memory of its process. The JIT compile itself is measured apart, once per mode: the first cycle
(``make``, ``reset`` and one step) at N = ``--compile-n`` in a process with an empty
``NUMBA_CACHE_DIR``.

Usage::

    python benchmarks/suite.py --sizes 100 1000 10000 100000 --threads 1 --out docs/speed/suite

``--out docs/speed/suite`` writes ``suite.json`` (machine, arguments, every row), ``suite.md``
(the table) and ``suite.png`` (the log-log plot); ``docs/speed/engine.md`` explains them.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from machine_info import describe

MODES = ("pettingzoo", "engine", "batched", "chain-kernel", "reference")
CHAIN_ROOM = 64
"""Free sites on each horizontal side of the ``chain-kernel`` blob: walls that far away touch no
module in the first 61 cycles, so those are the default box's cycles (its grid would not fit in
memory above a few thousand modules)."""


WORKLOADS = ("uniform", "legal")
"""Actions of the ``engine`` and ``pettingzoo`` modes: ``uniform`` on every field (most rolls are
illegal and denied, as in early RL exploration; the suite's workload) or ``legal``: each module's
move drawn uniformly among the moves its action mask allows (a stress case: about a fifth of the
modules roll every cycle), every other field uniform."""


def _draw(nvec, n: int, rng, mask: np.ndarray | None = None) -> np.ndarray:
    """``(n, fields)`` uniform actions of one cycle; with the ``(n, moves)`` action ``mask`` (the
    ``legal`` workload), each move uniform among the legal ones."""
    actions = rng.integers(0, nvec, size=(n, len(nvec)))
    if mask is not None:
        actions[:, 0] = np.argmax(mask * rng.random(mask.shape), axis=1)
    return actions


def _stepper(mode: str, n: int, batch_modules: int, workload: str = "uniform", motion_model: str | None = None):
    """``(reset, step, rows, n_envs)``: ``reset()`` restarts the episode, ``step(rng)`` runs one
    cycle with actions drawn from ``rng`` and returns the seconds spent stepping. ``workload``
    and ``motion_model`` (default: the task's) apply to the ``engine`` and ``pettingzoo`` modes."""
    import proteo_env

    if mode == "batched":
        n_envs = max(1, batch_modules // n)
        env = proteo_env.make_batched("sandbox-v0", n_envs, n_modules=n, max_cycles=10**9)
        nvec = env.action_layout.nvec

        def step(rng):
            actions = rng.integers(0, nvec, size=(n_envs, n, len(nvec)))
            t = time.perf_counter()
            env.step_arrays(actions)
            env.observe_arrays()
            return time.perf_counter() - t

        return (lambda: env.reset(seed=0)), step, n_envs * n, n_envs

    if mode == "chain-kernel":
        from baselines.chain import ChainPolicy
        from baselines.compiled import CompiledRollout

        chain = proteo_env.make("chain-v0", n_modules=n, room=CHAIN_ROOM, max_cycles=10**9)
        rollout = {}

        def reset():
            chain.reset(seed=0)
            rollout["run"] = CompiledRollout(chain, ChainPolicy.for_env(chain, seed=0)).run

        def step(rng):  # the behaviour draws its own actions
            t = time.perf_counter()
            rollout["run"](1)
            return time.perf_counter() - t

        return reset, step, n, 1

    extra = {} if motion_model is None else {"motion_model": motion_model}
    env = proteo_env.make("sandbox-v0", n_modules=n, max_cycles=10**9, **extra)
    nvec = env.action_layout.nvec
    legal = workload == "legal"
    last = {"mask": None}
    if mode == "engine":

        def reset():
            env.reset(seed=0)
            if legal:
                last["mask"] = env.observe_arrays().action_mask

        def step(rng):
            actions = _draw(nvec, n, rng, last["mask"])
            t = time.perf_counter()
            env.step_arrays(actions)
            obs = env.observe_arrays()
            last["mask"] = obs.action_mask if legal else None
            return time.perf_counter() - t

        return reset, step, n, 1
    if mode == "pettingzoo":
        agents = env.possible_agents

        def reset():
            last["obs"], _ = env.reset(seed=0)

        def step(rng):
            mask = np.stack([last["obs"][a]["action_mask"] for a in agents]) if legal else None
            actions = dict(zip(agents, _draw(nvec, n, rng, mask)))
            t = time.perf_counter()
            last["obs"], *_ = env.step(actions)
            return time.perf_counter() - t

        return reset, step, n, 1
    if mode == "reference":
        from proteo_env.core.reference import ReferenceWorld

        lay = env.action_layout
        world = {}

        def reset():
            env.reset(seed=0)
            w = env.engine
            ref = ReferenceWorld(
                size=w.shape.size,
                positions=w.positions,
                n_agents=w.n_agents,
                physics=w.physics,
                n_channels=w.n_channels,
            )
            ref.rng_state = int(w.rng_state[0])
            world["ref"] = ref

        def step(rng):
            a = rng.integers(0, nvec, size=(n, len(nvec)))
            t = time.perf_counter()
            world["ref"].step(
                move=a[:, lay.move],
                mode=a[:, lay.mode],
                scent_role=a[:, lay.roles],
                message_target=a[:, lay.message_target],
                message_value=a[:, lay.message_value],
            )
            world["ref"].observe()
            return time.perf_counter() - t

        return reset, step, n, 1
    raise ValueError(f"mode={mode!r} is not known; allowed: {', '.join(MODES)}")


def measure(mode: str, n: int, batch_modules: int, budget_s: float, cycles: int, **workload) -> dict:
    """One measurement in this process (called in a subprocess by :func:`main`).

    Repeats the episode (reset, then ``cycles`` timed cycles) until ``budget_s`` seconds of
    stepping are spent; returns the mean time of each cycle index over the repeats.
    ``workload``: :func:`_stepper`'s ``workload`` and ``motion_model``.
    """
    started = time.perf_counter()
    reset, step, rows, n_envs = _stepper(mode, n, batch_modules, **workload)
    reset()
    first = step(np.random.default_rng(0)) + (time.perf_counter() - started)
    per_cycle = np.zeros(cycles)
    repeats = 0
    while repeats == 0 or per_cycle.sum() < budget_s:
        reset()
        rng = np.random.default_rng(0)
        per_cycle += [step(rng) for _ in range(cycles)]
        repeats += 1
    per_cycle /= repeats
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {
        "mode": mode,
        "n_modules": n,
        "n_envs": n_envs,
        "cycles": cycles,
        "repeats": repeats,
        "first_cycle_s": first,
        "module_cycles_per_s": rows / per_cycle.mean(),
        "ms_per_cycle": 1e3 * per_cycle.mean(),
        "per_cycle_ms": (1e3 * per_cycle).tolist(),
        "peak_rss_mib": peak_mib,
    }


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
    parser.add_argument(
        "--budget", type=float, default=2.0, help="seconds of timed cycles per row (at least one episode)"
    )
    parser.add_argument("--cycles", type=int, default=50, help="cycles per episode, timed from a fresh reset")
    parser.add_argument("--reference-cycles", type=int, default=3, help="cycles per episode of the reference")
    parser.add_argument("--threads", type=int, default=1, help="NUMBA_NUM_THREADS of the measurements")
    parser.add_argument(
        "--compile-n", type=int, default=100, help="N of the JIT compile measurement with an empty cache (0: none)"
    )
    parser.add_argument("--out", default=None, help="write <out>.json, <out>.md (the table) and <out>.png")
    parser.add_argument("--one", nargs=2, metavar=("MODE", "N"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        mode, n = args.one[0], int(args.one[1])
        cycles = args.reference_cycles if mode == "reference" else args.cycles
        print(json.dumps(measure(mode, n, args.batch_modules, args.budget, cycles)))
        return

    env = {**os.environ, "NUMBA_NUM_THREADS": str(args.threads)}

    def child(mode: str, n: int, *, budget: float, cycles: int, **extra_env) -> dict:
        cmd = [
            sys.executable,
            __file__,
            "--one",
            mode,
            str(n),
            "--batch-modules",
            str(args.batch_modules),
            "--budget",
            str(budget),
            "--cycles",
            str(cycles),
            "--reference-cycles",
            str(args.reference_cycles),
        ]
        out = subprocess.run(cmd, env={**env, **extra_env}, capture_output=True, text=True, check=True)
        return json.loads(out.stdout.strip().splitlines()[-1])

    compiled = {}
    if args.compile_n:
        for mode in (m for m in args.modes if m != "reference"):
            with tempfile.TemporaryDirectory() as cache:
                compiled[mode] = child(mode, args.compile_n, budget=0.0, cycles=1, NUMBA_CACHE_DIR=cache)[
                    "first_cycle_s"
                ]
            print(
                f"{mode:>12}: JIT compile (first cycle, empty cache, N={args.compile_n}) {compiled[mode]:.1f} s",
                flush=True,
            )
    rows = []
    for mode in args.modes:
        for n in args.sizes:
            if mode == "reference" and n > args.reference_max:
                continue
            rows.append(child(mode, n, budget=args.budget, cycles=args.cycles))
            r = rows[-1]
            print(
                f"{mode:>11} N={n:>7,} B={r['n_envs']:>4}: {r['module_cycles_per_s']:>14,.0f} module-cycles/s, "
                f"{r['ms_per_cycle']:.3f} ms/cycle, first {r['first_cycle_s']:.2f} s, "
                f"peak {r['peak_rss_mib']:.0f} MiB",
                flush=True,
            )

    def early_rate(r):  # module-cycles/s over the cycles the reference ran
        rows_per_cycle = r["n_envs"] * r["n_modules"]
        return 1e3 * rows_per_cycle / np.mean(r["per_cycle_ms"][: args.reference_cycles])

    ref = {r["n_modules"]: early_rate(r) for r in rows if r["mode"] == "reference"}
    lines = [
        f"| mode | N | worlds B | module-cycles/s | ms per cycle | x reference (first {args.reference_cycles} "
        "cycles) | first cycle s | peak RSS MiB |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        same_workload = r["mode"] != "chain-kernel"  # the reference runs the sandbox workload
        ratio = f"{early_rate(r) / ref[r['n_modules']]:,.0f}" if r["n_modules"] in ref and same_workload else "-"
        lines.append(
            f"| {r['mode']} | {r['n_modules']:,} | {r['n_envs']} | {r['module_cycles_per_s']:,.0f} | "
            f"{r['ms_per_cycle']:.3f} | {ratio} | {r['first_cycle_s']:.2f} | {r['peak_rss_mib']:.0f} |"
        )
    if compiled:
        lines += [
            "",
            f"JIT compile, once per machine (first cycle with an empty cache, N = {args.compile_n}): "
            + ", ".join(f"{mode} {seconds:.1f} s" for mode, seconds in compiled.items())
            + "; the *first cycle* column loads the compiled kernels from the on-disk cache.",
        ]
    table = "\n".join(lines)
    info = describe("numpy", "numba", "gymnasium", "pettingzoo", numba_threads=args.threads)
    print(f"\nmachine: {info}\n\n{table}")
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.with_suffix(".json").write_text(
            json.dumps({"machine": info, "args": vars(args), "compile_s": compiled, "results": rows}, indent=2)
        )
        out.with_suffix(".md").write_text(f"machine: `{info}`\n\n{table}\n")
        plot(rows, out.with_suffix(".png"))


if __name__ == "__main__":
    main()

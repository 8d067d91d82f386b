"""The chain program through the program kernel against the hand-written chain rules, in the compiled rollout.

Workload: ``chain-v1`` with N modules (``--sizes``), ``--motion-model`` (default ``sphere``,
the benchmark's setting), limit ``--cycles-per-module`` times N cycles (25: 300 cycles at
N = 12, the benchmark's limit), worlds ``env.reset(seed=s)`` for s in ``--first-seed`` ..
``--first-seed + --worlds - 1``, policy seed s. On every world, both:

* ``rules``: the hand-written chain rules (``make_policy("chain", env)``, the kernel
  :func:`~baselines.chain.chain_actions`);
* ``program``: ``baselines/programs/chain.yaml`` (``make_policy("program", env,
  program="chain")``, the program kernel :func:`~baselines.program_rules.run_program`);

each run to success or the limit by :func:`~baselines.compiled.compiled_rollout` (observation,
rule, cycle and success test in one numba loop; the reset is not timed). Cycles per second
are the worlds' cycles over their summed seconds, the best of ``--repeats`` passes over all
worlds (the passes alternate the two policies; every pass runs the same trajectories). The
two policies run different trajectories on the same worlds (the program lacks some of the
rules' refinements, ``docs/guides/programs.md``), so the table also gives each one's
successes and cycles; ``rules / this`` is the rules' cycles per second over the program's. The
first call of each rollout (compiling its loop) runs on a world apart, before the timing.

The decisions alone, on the same observations: the observations of the rules' own episodes
on the same worlds (stepped through the env), every cycle's rows stacked, and each policy's
rule kernel run over them cycle after cycle in one compiled call
(:func:`~baselines.base.worlds_rule` with the policy's one memory and generator for every
cycle), so no Python and no call overhead lands between decisions; ns per module-decision,
best of ``--repeats``.

Usage::

    NUMBA_NUM_THREADS=1 python benchmarks/program_kernel_speed.py --sizes 12 80 --out docs/speed/program_kernel

prints the table and with ``--out`` writes ``<out>.json`` (machine, arguments, rows) and ``<out>.md``.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import time
from pathlib import Path

import numpy as np
from machine_info import describe

POLICIES = {"rules": ("chain", {}), "program": ("program", {"program": "chain"})}
"""The two policies compared: the name and parameters ``make_policy`` takes."""


def measure(n: int, args) -> dict:
    """One row: both policies on the same worlds of ``n`` modules."""
    import proteo_env
    from baselines import make_policy
    from baselines.compiled import compiled_rollout

    env = proteo_env.make(
        "chain-v1", n_modules=n, motion_model=args.motion_model, max_cycles=args.cycles_per_module * n
    )
    seeds = range(args.first_seed, args.first_seed + args.worlds)
    for name, params in POLICIES.values():  # compile each rollout loop on a world apart
        env.reset(seed=args.first_seed - 1)
        compiled_rollout(env, make_policy(name, env, seed=0, **params), max_cycles=2)
    seconds = {label: [] for label in POLICIES}
    outcome = {}
    for _ in range(args.repeats):
        for label, (name, params) in POLICIES.items():
            total, results = 0.0, []
            for seed in seeds:
                env.reset(seed=seed)
                policy = make_policy(name, env, seed=seed, **params)
                started = time.perf_counter()
                results.append(compiled_rollout(env, policy))
                total += time.perf_counter() - started
            seconds[label].append(total)
            outcome[label] = results
    row = {"n_modules": n, "worlds": args.worlds, "max_cycles": env.max_cycles}
    for label, results in outcome.items():
        cycles = sum(r.cycles for r in results)
        successes = [r.cycles for r in results if r.success]
        best = min(seconds[label])
        row[label] = {
            "successes": len(successes),
            "mean_cycles_of_successes": float(np.mean(successes)) if successes else None,
            "cycles": cycles,
            "seconds": seconds[label],
            "cycles_per_s": cycles / best,
            "module_cycles_per_s": n * cycles / best,
        }
    row["rules_over_program"] = row["rules"]["cycles_per_s"] / row["program"]["cycles_per_s"]
    return row


def decisions(n: int, args) -> dict:
    """ns per module-decision of each policy's rule kernel on the observations of the rules' episodes."""
    import proteo_env
    from baselines import make_policy
    from baselines.base import Observed, _kernel_list, stacked_fields, worlds_rule

    env = proteo_env.make(
        "chain-v1", n_modules=n, motion_model=args.motion_model, max_cycles=args.cycles_per_module * n
    )
    worlds = []
    for seed in range(args.first_seed, args.first_seed + args.worlds):
        env.reset(seed=seed)
        rules, cycles, done = make_policy("chain", env, seed=seed), [], False
        while not done:
            buffers = env.observe_arrays()
            cycles.append(stacked_fields(functools.partial(getattr, buffers), Observed._fields))
            result = env.step_arrays(rules.act_arrays(buffers))
            done = bool(result.terminated[0] or result.truncated[0])
        worlds.append((seed, Observed(*(np.concatenate(field) for field in zip(*cycles)))))
    rows = sum(len(seen.own_mode) for _, seen in worlds)
    out = {"n_modules": n, "module_decisions": rows}
    for label, (name, params) in POLICIES.items():
        best = float("inf")
        for _ in range(args.repeats + 1):  # the first pass compiles
            total = 0.0
            for seed, seen in worlds:
                policy = make_policy(name, env, seed=seed, **params)
                policy.memory.reserve(n)
                each_cycle = len(seen.own_mode) // n
                memories = _kernel_list([policy.memory.arrays()] * each_cycle)
                rngs = _kernel_list([policy.rng] * each_cycle)
                actions = np.empty((len(seen.own_mode), env.action_layout.length), dtype=np.int64)
                slots = np.arange(n, dtype=np.int64)
                started = time.perf_counter()
                worlds_rule(policy.rule)(seen, n, slots, memories, policy.rule_params, rngs, actions)
                total += time.perf_counter() - started
            best = min(best, total)
        out[f"{label}_ns_per_decision"] = 1e9 * best / rows
    out["program_over_rules"] = out["program_ns_per_decision"] / out["rules_ns_per_decision"]
    return out


def table(rows: list[dict]) -> str:
    lines = [
        "| N | policy | successes | mean cycles (successes) | cycles run | cycles/s | module-cycles/s | rules / this, cycles/s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        for label in POLICIES:
            r = row[label]
            mean = "-" if r["mean_cycles_of_successes"] is None else f"{r['mean_cycles_of_successes']:.1f}"
            ratio = "1" if label == "rules" else f"{row['rules_over_program']:.2f}"
            lines.append(
                f"| {row['n_modules']} | {label} | {r['successes']}/{row['worlds']} | {mean} | {r['cycles']:,} | "
                f"{r['cycles_per_s']:,.0f} | {r['module_cycles_per_s']:,.0f} | {ratio} |"
            )
    lines += [
        "",
        "The decisions alone, on the observations of the rules' episodes (ns per module-decision):",
        "",
        "| N | module-decisions | rules | program | program / rules |",
        "|---|---|---|---|---|",
    ]
    lines += [
        f"| {row['n_modules']} | {d['module_decisions']:,} | {d['rules_ns_per_decision']:.0f} | "
        f"{d['program_ns_per_decision']:.0f} | {d['program_over_rules']:.2f} |"
        for row in rows
        for d in [row["decisions"]]
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[12, 80])
    parser.add_argument("--worlds", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=1000)
    parser.add_argument("--motion-model", default="sphere")
    parser.add_argument("--cycles-per-module", type=int, default=25, help="the episode limit is this times N")
    parser.add_argument("--repeats", type=int, default=3, help="timed passes over all worlds per policy")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    threads = int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count()))
    load_before = round(os.getloadavg()[0], 2)
    rows = []
    for n in args.sizes:
        rows.append(measure(n, args) | {"decisions": decisions(n, args)})
        print(
            f"N={n}: rules {rows[-1]['rules_over_program']:.2f} x the program's cycles per second, "
            f"decisions alone {rows[-1]['decisions']['program_over_rules']:.2f} x the rules' time",
            flush=True,
        )
    info = describe("numpy", "numba", numba_threads=threads, load_average_1min_before=load_before)
    text = table(rows)
    print(f"\nmachine: {info}\n\n{text}")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.with_suffix(".json").write_text(
            json.dumps({"machine": info, "args": vars(args), "rows": rows}, indent=2, default=str)
        )
        args.out.with_suffix(".md").write_text(f"machine: `{info}`\n\n{text}\n")


if __name__ == "__main__":
    main()

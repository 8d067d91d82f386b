"""proteo's sandbox beside MAgent2's battle world, one thread, one run: agent-steps per second.

MAgent2 (``pip install -c constraints.txt -e ".[bench]"``, its C++ ``GridWorld``) is the fast
many-agent gridworld MARL users know. Both sides take random actions and build every agent's
observation each step, through two APIs each:

- **raw**: MAgent2's ``GridWorld`` (``env.unwrapped.env``: ``get_observation``, ``set_action``,
  ``step``, ``clear_dead`` per group) against proteo's array API (``step_arrays`` then
  ``observe_arrays``), uniform random actions on every field;
- **pettingzoo**: both through their PettingZoo parallel API (per-agent dicts).

Sizes: battle worlds of about 160, 1,000 and 10,000 agents (``map_size`` 45, 112, 354; the
two armies fill a fixed share of the map) and sandbox blobs of the same count. Each pair is
measured ``--repeats`` times alternately (MAgent2, proteo, MAgent2, ...) for ``--cycles`` steps
from a reset, and the median of each side is reported with their ratio, so that both sides see
the same load; the load average and the machine are written beside the figures.

Usage::

    NUMBA_NUM_THREADS=1 python benchmarks/magent2_comparison.py --out docs/speed/magent2
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
from machine_info import describe

MAP_SIZES = {160: 45, 1000: 112, 10000: 354}
"""Agents wanted -> battle's ``map_size`` that gives about that many."""


def magent2_stepper(map_size: int, api: str):
    """``(reset, step, agents)`` of MAgent2's battle world: ``step(rng)`` runs one step with random
    actions and returns its seconds and the agents that acted; ``agents`` at the reset."""
    from magent2.environments import battle_v4

    env = battle_v4.parallel_env(map_size=map_size, max_cycles=10**9)
    env.reset(seed=0)
    agents = len(env.agents)
    if api == "raw":
        grid = env.unwrapped.env
        handles = grid.get_handles()
        n_actions = [grid.get_action_space(h)[0] for h in handles]

        def step(rng):
            started, acted = time.perf_counter(), 0
            for handle, n in zip(handles, n_actions):
                grid.get_observation(handle)
                count = grid.get_num(handle)
                grid.set_action(handle, rng.integers(0, n, count).astype(np.int32))
                acted += count
            grid.step()
            grid.clear_dead()
            return time.perf_counter() - started, acted

        return (lambda: env.reset(seed=0)), step, agents

    def step(rng):
        actions = {agent: int(rng.integers(0, env.action_space(agent).n)) for agent in env.agents}
        started = time.perf_counter()
        env.step(actions)
        return time.perf_counter() - started, len(actions)

    return (lambda: env.reset(seed=0)), step, agents


def proteo_stepper(n_modules: int, api: str):
    """``(reset, step)`` of proteo's sandbox blob of ``n_modules``, as :func:`magent2_stepper`."""
    import proteo_env

    env = proteo_env.make("sandbox-v0", n_modules=n_modules, max_cycles=10**9)
    nvec = env.action_layout.nvec
    if api == "raw":

        def step(rng):
            actions = rng.integers(0, nvec, size=(n_modules, len(nvec)))
            started = time.perf_counter()
            env.step_arrays(actions)
            env.observe_arrays()
            return time.perf_counter() - started, n_modules

    else:

        def step(rng):
            actions = {agent: rng.integers(0, nvec) for agent in env.agents}
            started = time.perf_counter()
            env.step(actions)
            return time.perf_counter() - started, n_modules

    return (lambda: env.reset(seed=0)), step


def rate(reset, step, cycles: int) -> float:
    """Agent-steps per second over ``cycles`` steps from a reset (the first step, a cache load or
    a compile, is run before the clock starts)."""
    reset()
    rng = np.random.default_rng(0)
    step(rng)
    seconds, steps = 0.0, 0
    for _ in range(cycles):
        s, n = step(rng)
        seconds, steps = seconds + s, steps + n
    return steps / seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--agents", type=int, nargs="+", default=list(MAP_SIZES), choices=list(MAP_SIZES))
    parser.add_argument("--apis", nargs="+", default=["raw", "pettingzoo"], choices=["raw", "pettingzoo"])
    parser.add_argument("--cycles", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default=None, help="write <out>.json and <out>.md")
    args = parser.parse_args()
    try:
        import magent2  # noqa: F401
    except ImportError:
        raise SystemExit(
            'magent2 is not installed; allowed: pip install -c constraints.txt -e ".[bench]" (MAgent2 0.3.4)'
        ) from None
    rows = []
    for api in args.apis:
        for wanted in args.agents:
            if api == "pettingzoo" and wanted > 1000:
                continue  # per-agent dicts at 10,000 agents take minutes and tell nothing new
            reset_m, step_m, n_agents = magent2_stepper(MAP_SIZES[wanted], api)
            reset_p, step_p = proteo_stepper(n_agents, api)
            magent, proteo = [], []
            for _ in range(args.repeats):  # alternately, so that both sides see the same load
                magent.append(rate(reset_m, step_m, args.cycles))
                proteo.append(rate(reset_p, step_p, args.cycles))
            row = {
                "api": api,
                "agents": n_agents,
                "magent2_agent_steps_per_s": float(np.median(magent)),
                "proteo_module_cycles_per_s": float(np.median(proteo)),
            }
            row["ratio"] = row["proteo_module_cycles_per_s"] / row["magent2_agent_steps_per_s"]
            rows.append(row)
            print(json.dumps(row))
    import magent2
    import numba

    info = describe("numpy", "numba", "pettingzoo", numba_threads=numba.config.NUMBA_NUM_THREADS)
    info["magent2"] = getattr(magent2, "__version__", "0.3.4")
    info["load_average_1min_end"] = round(os.getloadavg()[0], 2)
    lines = [
        "| API | agents | MAgent2 battle (agent-steps/s) | proteo sandbox (module-cycles/s) | proteo / MAgent2 |",
        "|---|---|---|---|---|",
        *(
            f"| {r['api']} | {r['agents']:,} | {r['magent2_agent_steps_per_s'] / 1e6:.2f} M | "
            f"{r['proteo_module_cycles_per_s'] / 1e6:.2f} M | {r['ratio']:.2f}x |"
            for r in rows
        ),
    ]
    print("\n".join(lines))
    print(json.dumps(info))
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.with_suffix(".json").write_text(json.dumps({"machine": info, "rows": rows}, indent=2) + "\n")
        out.with_suffix(".md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()

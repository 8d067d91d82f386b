"""Environment step speed: module-cycles per second, JIT compile time reported apart.

For each world size N (random connected blobs in the sandbox task) it measures

* ``engine``: :meth:`ProteoEnv.step_arrays` plus :meth:`ProteoEnv.observe_arrays` (arrays in,
  arrays out, observations and action masks built);
* ``pettingzoo``: the PettingZoo API (:meth:`ProteoEnv.step` with one action dict entry per
  agent and per-agent observation dicts back), same actions.

Two action workloads: ``uniform`` draws every action field uniformly (most rolls are then
illegal and denied, as in early RL exploration); ``legal`` draws each module's move
uniformly among the moves its action mask allows (a stress case: about a fifth of the
modules roll every cycle). Drawing the actions is not timed.

Compile time is the first cycle of the first world (numba caches compiled kernels on disk,
so a second run of the script shows the cache-load time instead). Results go to stdout as a
markdown table and, with ``--json``, to a file together with the machine description.

Usage::

    python benchmarks/step_speed.py --sizes 1000 10000 --cycles 200
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from machine_info import describe


def random_legal_moves(mask: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``(A,)`` one uniformly chosen legal move per row of an ``(A, 13)`` mask."""
    return np.argmax(mask * rng.random(mask.shape), axis=1)


def draw_moves(workload: str, mask: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    if workload == "legal":
        return random_legal_moves(mask, rng)
    return rng.integers(0, 13, size=len(mask))


def bench_size(n: int, cycles: int, motion_model: str, seed: int, workload: str) -> dict:
    import proteo_env

    env = proteo_env.make("sandbox-v0", n_modules=n, margin=4, motion_model=motion_model, max_cycles=10 * cycles + 10)
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    layout = env.action_layout
    actions = np.zeros((n, layout.length), dtype=np.int64)
    actions[:, layout.roles] = 1
    actions[0, layout.roles] = 2

    started = time.perf_counter()
    obs = env.observe_arrays()
    env.step_arrays(actions)
    first_cycle = time.perf_counter() - started

    engine_seconds = 0.0
    moved = 0
    for _ in range(cycles):
        actions[:, layout.move] = draw_moves(workload, obs.action_mask, rng)
        started = time.perf_counter()
        env.step_arrays(actions)
        obs = env.observe_arrays()
        engine_seconds += time.perf_counter() - started
        moved += int(env.last_moved.sum())

    agents = env.possible_agents
    observations, _ = env.reset(seed=seed)
    pz_cycles = max(cycles // 4, 5)
    pz_seconds = 0.0
    for _ in range(pz_cycles):
        mask = np.stack([observations[a]["action_mask"] for a in agents])
        actions[:, layout.move] = draw_moves(workload, mask, rng)
        action_dict = dict(zip(agents, actions))
        started = time.perf_counter()
        observations, *_ = env.step(action_dict)
        pz_seconds += time.perf_counter() - started
    return {
        "n_modules": n,
        "motion_model": motion_model,
        "workload": workload,
        "cycles": cycles,
        "first_cycle_s": first_cycle,
        "engine_module_cycles_per_s": n * cycles / engine_seconds,
        "engine_cycle_ms": 1e3 * engine_seconds / cycles,
        "moves_per_cycle": moved / cycles,
        "pettingzoo_agent_steps_per_s": n * pz_cycles / pz_seconds,
        "pettingzoo_cycle_ms": 1e3 * pz_seconds / pz_cycles,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000])
    parser.add_argument("--cycles", type=int, default=200)
    parser.add_argument("--motion-model", default="sphere")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workloads", nargs="+", default=["uniform", "legal"], choices=["uniform", "legal"])
    parser.add_argument("--json", default=None, help="write results and machine info to this file")
    args = parser.parse_args()
    import numba

    info = describe("numpy", "numba", "gymnasium", "pettingzoo", numba_threads=numba.config.NUMBA_NUM_THREADS)
    rows = [bench_size(n, args.cycles, args.motion_model, args.seed, w) for w in args.workloads for n in args.sizes]
    print(f"machine: {info}")
    print(
        "| actions | N | first cycle (compile or cache load) s | engine module-cycles/s | engine ms/cycle | "
        "PettingZoo agent-steps/s | PettingZoo ms/cycle | moves/cycle |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['workload']} | {r['n_modules']:,} | {r['first_cycle_s']:.2f} | "
            f"{r['engine_module_cycles_per_s']:,.0f} | "
            f"{r['engine_cycle_ms']:.2f} | {r['pettingzoo_agent_steps_per_s']:,.0f} | "
            f"{r['pettingzoo_cycle_ms']:.2f} | {r['moves_per_cycle']:.0f} |"
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"machine": info, "args": vars(args), "results": rows}, f, indent=2)


if __name__ == "__main__":
    main()

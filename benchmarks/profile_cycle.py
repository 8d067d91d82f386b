"""Where the time of one cycle goes: each kernel of the array API timed on its own.

Runs the speed suite's workload (sandbox blob of N modules, reset with seed 0, uniform random
actions drawn from a generator seeded 0) up to cycle ``--at``, then times every part of the
next cycle on copies of that state, ``--repeats`` times each, and prints the best time of
each part in milliseconds:

* ``checks``: validating the action batch (:meth:`BatchedEnv.check_actions`);
* ``messages``: :func:`~proteo_env.core.cycle.deliver_messages`;
* ``moves``: :func:`~proteo_env.core.cycle.execute_moves` with connectivity kept, and
  ``moves without connectivity`` (the same requests, no detach check) to show its share;
* ``scent``: the scent sweep of channel 0;
* ``cut modules``: :func:`~proteo_env.core.cycle.articulation_points` (Tarjan), needed for
  exact action masks;
* ``observation``: :func:`~proteo_env.core.cycle.observe` (neighbour fields and masks);
* ``per-agent dicts``: what the PettingZoo API adds, building one dict per agent;
* ``array API kernels``: the parts the array API runs (every part above but the per-agent
  dicts, moves with connectivity), and ``... connectivity free``: the same with the moves'
  connectivity checks taken out, the most a faster check could give (its ratio below).

Usage::

    python benchmarks/profile_cycle.py --n 10000 --at 0 25 50
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def best_ms(run, prepare, repeats: int) -> float:
    """Best wall time of ``run()`` in ms, calling ``prepare()`` (untimed) before each repeat."""
    best = float("inf")
    for _ in range(repeats):
        prepare()
        started = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - started)
    return 1e3 * best


def profile(n: int, at: int, repeats: int) -> dict[str, float]:
    import proteo_env
    from proteo_env.core import cycle
    from proteo_env.core.lattice import OPPOSITE
    from proteo_env.core.records import Actions, Observation
    from proteo_env.spaces import ObservationBuffers

    env = proteo_env.make("sandbox-v0", n_modules=n, max_cycles=10**9)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    lay = env.action_layout
    for _ in range(at):
        env.step_arrays(rng.integers(0, lay.nvec, size=(n, lay.length)))
    actions = rng.integers(0, lay.nvec, size=(n, lay.length))
    w, s, p = env.engine, env.engine.scratch, env.engine.physics
    saved = {name: getattr(w, name).copy() for name in ("grid", "cell", "rng_state", "inbox")}

    def restore():  # the connectivity search's epoch (search[0]) only grows, so its marks need no reset
        for name, value in saved.items():
            getattr(w, name)[:] = value

    move = actions[:, lay.move].copy()
    messages = Actions.of(
        move=move,
        mode=actions[:, lay.mode],
        scent_role=actions[:, lay.roles],
        message_target=actions[:, lay.message_target],
        message_value=actions[:, lay.message_value],
    )
    role = np.full(w.n_modules, cycle.RELAY, dtype=np.int8)
    role[:n] = actions[:, lay.roles][:, 0]
    scent = w.scent[0].copy()
    moved = np.zeros(n, dtype=np.bool_)
    buffers = ObservationBuffers(n, env.batch.n_sites, w.n_channels)

    def moves(keep_connected):
        settings = w.settings._replace(keep_connected=keep_connected)
        return lambda: cycle.execute_moves(w.state, settings, w.geometry, move, moved, s)

    def observation():
        cycle.observe(w.state, w.settings, w.geometry, s.is_cut, Observation.of(buffers))

    parts = {
        "checks": lambda: env.batch.check_actions(actions[None]),
        "messages": lambda: cycle.deliver_messages(w.state, n, messages, w.dir_delta, OPPOSITE),
        "moves": moves(True),
        "moves without connectivity": moves(False),
        "scent": lambda: cycle.relax_scent(
            w.grid, w.cell, w.n_modules, role, False, scent, s.scent_buffer, p.scent_sweeps, p.scent_max, w.dir_delta
        ),
        "cut modules": lambda: cycle.articulation_points(w.grid, w.cell, w.n_modules, w.dir_delta, s),
        "observation": observation,
        "per-agent dicts": lambda: buffers.per_agent(env.possible_agents),
    }
    result = {name: best_ms(run, restore, repeats) for name, run in parts.items()}
    kernels = sum(v for k, v in result.items() if k not in ("moves without connectivity", "per-agent dicts"))
    result["array API kernels"] = kernels
    result["array API kernels, connectivity free"] = kernels - result["moves"] + result["moves without connectivity"]
    restore()
    env.step_arrays(actions)
    result["modules moved"] = int(env.last_moved.sum())
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=10000)
    parser.add_argument("--at", type=int, nargs="+", default=[0, 50], help="cycles run before profiling")
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    columns = {at: profile(args.n, at, args.repeats) for at in args.at}
    print(f"N = {args.n:,}, best of {args.repeats}, ms")
    print("| part | " + " | ".join(f"cycle {at}" for at in args.at) + " |")
    print("|---|" + "---|" * len(args.at))
    for name in next(iter(columns.values())):
        cells = [
            f"{columns[at][name]:.3f}" if isinstance(columns[at][name], float) else f"{columns[at][name]:,}"
            for at in args.at
        ]
        print(f"| {name} | " + " | ".join(cells) + " |")
    bounds = [columns[at]["array API kernels"] / columns[at]["array API kernels, connectivity free"] for at in args.at]
    print("| kernels / kernels without the connectivity checks | " + " | ".join(f"{b:.2f}x" for b in bounds) + " |")


if __name__ == "__main__":
    main()

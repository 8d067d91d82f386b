"""Large worlds inside the judge's evaluator: module-cycles per second at 1,000 and 10,000 modules.

On ``grasp-v0`` worlds of N modules (the object's radius scaled with the cube root of N / 100, as
protocol v8's scale split does; world seed 1000), for the rules, the paper's grasp program and a
network (``checkpoints/v7/grasp/kickstart_move/seed_0``, at ``move``), each through the evaluator
(``training.machinery.evaluator.run_episodes``, one world a batch), and beside them the array API's
own rate on the same world (``ProteoEnv.step_arrays`` and ``observe_arrays`` with the rules'
``act_arrays``, no evaluator). The evaluator's rate leaves its set-up out: an episode capped at one
cycle is timed too, and the rate is ``N x (cycles - 1) / (seconds - seconds of the one-cycle
episode)``, each episode timed the second time it runs (its environments built the first). Everything runs in this process after a warm-up (compiled code loaded), one thread.

Usage::

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/scale_speed.py --sizes 1000 10000 --cycles 150 \\
        --json docs/speed/scale.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from machine_info import describe

TASK = "grasp-v0"
NETWORK = str(Path(__file__).resolve().parents[1] / "checkpoints/v7/grasp/kickstart_move/seed_0")
SEED = 1000


def settings(n: int, cycles: int) -> dict:
    return {"n_modules": n, "distance": 3, "object_size": round(2.5 * (n / 100) ** (1 / 3), 2), "max_cycles": cycles}


def array_api(n: int, cycles: int) -> dict:
    """The rules on the world through the array API alone."""
    import proteo_env
    from baselines import make_policy

    env = proteo_env.make(TASK, **settings(n, cycles))
    policy = make_policy("grasp", env, seed=SEED)
    env.reset(seed=SEED)
    policy.reset(SEED)
    buffers = env.observe_arrays()
    started, done = time.perf_counter(), 0
    while done < cycles:
        result = env.step_arrays(policy.act_arrays(buffers))
        buffers = env.observe_arrays()
        done += 1
        if result.terminated or result.truncated:
            break
    seconds = time.perf_counter() - started
    return {"controller": "rules (array API)", "cycles": done, "seconds": seconds, "rate": n * done / seconds}


def evaluator(n: int, cycles: int, name: str, controller, level: str) -> dict:
    """``controller`` on the world through the evaluator, its set-up left out."""
    from training.machinery.evaluator import Episode, run_episodes, settings_json

    def timed(limit: int):
        episode = Episode(TASK, settings_json(settings(n, limit)), level, controller, SEED)
        started = time.perf_counter()
        (result,) = run_episodes([episode], workers=1, batch_size=1)
        return result.cycles, time.perf_counter() - started

    timed(1), timed(cycles)  # each settings' environments built once, then both timed again
    one_cycles, one_seconds = timed(1)
    done, seconds = timed(cycles)
    stepping = seconds - one_seconds
    return {
        "controller": name,
        "cycles": done,
        "seconds": seconds,
        "setup_seconds": one_seconds,
        "rate": n * (done - one_cycles) / stepping,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000])
    parser.add_argument("--cycles", type=int, default=150)
    parser.add_argument("--json", default=None, help="write results and machine info to this file")
    args = parser.parse_args()
    from training.machinery.evaluator import Controller

    controllers = [
        ("rules", Controller.rules("grasp"), "full"),
        ("program (the paper's)", Controller.program("grasp"), "full"),
        ("network (kickstart-move seed 0)", Controller.from_checkpoint(NETWORK), "move"),
    ]
    for name, controller, level in controllers:  # warm-up: compiled code loaded, networks built
        evaluator(100, 3, name, controller, level)
    array_api(100, 3)
    rows = []
    for n in args.sizes:
        reference = array_api(n, args.cycles)
        rows.append({"n_modules": n, **reference, "ratio": 1.0})
        for name, controller, level in controllers:
            row = evaluator(n, args.cycles, name, controller, level)
            rows.append({"n_modules": n, **row, "ratio": row["rate"] / reference["rate"]})
    info = describe("numpy", "numba", "torch")
    print(f"machine: {info}")
    print("| N | controller | cycles | module-cycles/s | / array API | set-up s |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        setup = f"{r['setup_seconds']:.1f}" if "setup_seconds" in r else "-"
        print(
            f"| {r['n_modules']:,} | {r['controller']} | {r['cycles']} | {r['rate']:,.0f} | {r['ratio']:.2f} | {setup} |"
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"machine": info, "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main()

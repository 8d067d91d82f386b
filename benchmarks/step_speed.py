"""Environment step speed, the short form of ``benchmarks/suite.py`` (``make bench``): the array
API and the PettingZoo API for both action workloads and a chosen motion model.

For each world size N (a random connected blob in the sandbox task, reset with seed 0) it runs
suite.py's ``engine`` (:meth:`ProteoEnv.step_arrays` plus :meth:`ProteoEnv.observe_arrays`) and
``pettingzoo`` (:meth:`ProteoEnv.step` with per-agent dicts) measurements, in this process, for
``--cycles`` timed cycles from the reset (one episode each), under the ``uniform`` workload
(every action field uniform, the suite's) and the ``legal`` one (each module's move uniform
among the moves its action mask allows): ``suite.WORKLOADS``. The first cycle (numba's cache
load, or the JIT compile without a cache) is reported apart. Results go to stdout as a markdown
table and, with ``--json``, to a file together with the machine description.

Usage::

    python benchmarks/step_speed.py --sizes 1000 10000 --cycles 200
"""

from __future__ import annotations

import argparse
import json

from machine_info import describe
from suite import WORKLOADS, measure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000])
    parser.add_argument("--cycles", type=int, default=200)
    parser.add_argument("--motion-model", default="sphere")
    parser.add_argument("--workloads", nargs="+", default=list(WORKLOADS), choices=WORKLOADS)
    parser.add_argument("--json", default=None, help="write results and machine info to this file")
    args = parser.parse_args()
    import numba

    info = describe("numpy", "numba", "gymnasium", "pettingzoo", numba_threads=numba.config.NUMBA_NUM_THREADS)
    rows = [
        {"workload": w, **measure(mode, n, 0, 0.0, args.cycles, workload=w, motion_model=args.motion_model)}
        for w in args.workloads
        for n in args.sizes
        for mode in ("engine", "pettingzoo")
    ]
    print(f"machine: {info}")
    print("| actions | N | mode | first cycle (compile or cache load) s | module-cycles/s | ms/cycle |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['workload']} | {r['n_modules']:,} | {r['mode']} | {r['first_cycle_s']:.2f} | "
            f"{r['module_cycles_per_s']:,.0f} | {r['ms_per_cycle']:.2f} |"
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"machine": info, "args": vars(args), "results": rows}, f, indent=2)


if __name__ == "__main__":
    main()

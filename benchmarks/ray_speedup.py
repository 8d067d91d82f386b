"""Speed-up of proteo eval's episodes and of one CMA-ES generation on Ray (2 workers) against serial,
and Ray's overhead per task, measured in one run (docs/guides/distributed.md).

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 python benchmarks/ray_speedup.py

Every timing is taken warm (JIT compiled in this process and in every Ray worker first).
"""

from __future__ import annotations

import multiprocessing
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

from machine_info import describe  # noqa: E402


def noop(job):
    return job


def main() -> None:
    import ray

    from training.judging.episodes import run_alone
    from training.machinery.distributed import run_jobs
    from training.machinery.evaluator import Controller, Episode, episode_key
    from training.trainers import cma_es

    settings = '{"max_cycles": 1500, "motion_model": "rhombic", "n_modules": 40}'
    jobs = [(Episode("chain-v1", settings, "full", Controller.rules("chain"), s), "") for s in range(16)]
    keys = [episode_key(episode) for episode, _ in jobs]
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    options = {"address": None, "workers": 2}
    run_jobs(run_alone, jobs[:4], keys[:4], ray=options, progress=False)  # warm the workers
    run_alone(jobs[0])  # and this process
    rows = []

    def timed(label, fn):
        load = os.getloadavg()[0]
        started = time.perf_counter()
        fn()
        rows.append((label, time.perf_counter() - started, load))

    timed("eval: 16 chain episodes (N=40, rhombic), serial", lambda: run_jobs(run_alone, jobs, keys, progress=False))
    timed(
        "eval: 16 chain episodes (N=40, rhombic), Ray, 2 workers",
        lambda: run_jobs(run_alone, jobs, keys, ray=options, progress=False),
    )
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        list(pool.map(run_alone, jobs[:4]))  # warm both processes
        timed(
            "eval: the same 16 episodes, 2 plain processes (no Ray: what two cores allow)",
            lambda: list(pool.map(run_alone, jobs)),
        )
    cma = [
        "--config",
        "configs/train/cma_rules_chain_full.yaml",
        "--generations",
        "2",
        "--popsize",
        "8",
        "--episodes-per-candidate",
        "2",
        "--env",
        "{n_modules: 30, max_cycles: 1500, motion_model: rhombic}",
        "--tensorboard",
        "false",
    ]
    for label, extra in (("serial", []), ("Ray, 2 workers", ["--ray", "true"])):
        with tempfile.TemporaryDirectory() as tmp:
            load = os.getloadavg()[0]
            cma_es.main([*cma, "--run-dir", f"{tmp}/run", *extra])
            lines = open(f"{tmp}/run/progress.csv").read().splitlines()
            seconds = [float(line.split(",")[1]) for line in lines[1:]]
            rows.append(
                (
                    f"CMA-ES: one generation (8 candidates x 2 episodes, N=30, rhombic; the 2nd), {label}",
                    seconds[1] - seconds[0],
                    load,
                )
            )
    n = 400
    timed(
        f"Ray overhead: {n} empty tasks, 2 workers",
        lambda: run_jobs(noop, list(range(n)), [str(i) for i in range(n)], ray=options, progress=False),
    )
    print(describe("ray", "numba", "numpy"))
    print("| measurement | seconds | load average (1 min) before |\n|---|---|---|")
    for label, seconds, load in rows:
        print(f"| {label} | {seconds:.2f} | {load:.2f} |")
    print(
        f"\neval speed-up: {rows[0][1] / rows[1][1]:.2f}x on Ray, {rows[0][1] / rows[2][1]:.2f}x on plain processes;"
        f" CMA-ES generation speed-up: {rows[3][1] / rows[4][1]:.2f}x;"
        f" overhead per task: {1000 * rows[5][1] / n:.1f} ms wall ({2000 * rows[5][1] / n:.1f} ms of a worker)"
    )
    ray.shutdown()


if __name__ == "__main__":
    main()

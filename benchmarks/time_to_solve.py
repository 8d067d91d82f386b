"""How long native PPO takes to solve chain-v1: wall-clock to 90 % success on held-out worlds.

    NUMBA_NUM_THREADS=1 python benchmarks/time_to_solve.py --out docs/speed/time_to_solve
    python benchmarks/time_to_solve.py --device cuda --workers 8 --out docs/speed/time_to_solve_gpu

For each training seed it trains ``training/trainers/ppo.py`` with the config's settings
(``configs/train/ppo_chain_move.yaml``: 12-module chains at ``move``, 64 worlds, the config's
network) for ``--steps`` agent-steps with a checkpoint every ``--every``, then judges every
checkpoint on the same ``--worlds`` held-out worlds (seeds 1000 on, the benchmark's first world
seed; :func:`training.machinery.evaluator.evaluate`, sampled actions). A seed has solved the task at the
first checkpoint whose success rate reaches ``--target``; its time is the training's wall-clock
at that checkpoint (``progress.csv``'s ``seconds``: rollouts and updates, not the judging).
Training success as logged is no measure of this: its first rows count only the episodes that
ended early, which are the successes.

The same command runs on any machine (``--device cuda`` moves the networks to a GPU); the
machine, its load average and the torch and numba versions are written beside the figures.
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from machine_info import describe

from proteo_env.config import load_yaml

CONFIG = "configs/train/ppo_chain_move.yaml"


def train(seed: int, steps: int, every: int, threads: int, device: str, run_dir: Path, workers: int = 1) -> None:
    """One PPO run of the config, with checkpoints every ``every`` agent-steps, its worlds split
    over ``workers`` processes (the same run on any number)."""
    cmd = [
        sys.executable,
        "-m",
        "training.trainers.ppo",
        "--config",
        CONFIG,
        "--seed",
        str(seed),
        "--run-dir",
        str(run_dir),
    ]
    cmd += ["--total-steps", str(steps), "--checkpoint-every", str(every), "--time-limit-minutes", "0"]
    cmd += ["--threads", str(threads), "--device", device, "--progress-bar", "false", "--tensorboard", "false"]
    cmd += ["--workers", str(workers)]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def seconds_at(run_dir: Path) -> dict[int, float]:
    """Training wall-clock at each logged agent-step count (``progress.csv``)."""
    with open(run_dir / "progress.csv") as f:
        return {int(row["agent_steps"]): float(row["seconds"]) for row in csv.DictReader(f)}


def judge(run_dir: Path, worlds: int) -> list[tuple[int, float]]:
    """``[(agent-steps, success rate on the held-out worlds)]`` of every checkpoint, in order."""
    from training.machinery.checkpoints import read_meta
    from training.machinery.evaluator import Controller, evaluate

    cfg = load_yaml(Path(CONFIG))
    folders = {}  # by agent-steps: the final checkpoint is the last periodic one when the budget is a multiple
    for folder in [*sorted((run_dir / "checkpoints").glob("step_*")), run_dir / "final"]:
        folders.setdefault(int(read_meta(folder)["agent_steps"]), folder)
    controllers = [Controller.from_checkpoint(folder) for folder in folders.values()]
    results = evaluate(cfg["task"], controllers, range(1000, 1000 + worlds), env=cfg["env"], level=cfg["control"])
    steps = list(folders)
    return [(s, float(np.mean([r.success for r in rs]))) for s, rs in zip(steps, results)]


def solve_time(curve: list[tuple[int, float]], clock: dict[int, float], target: float) -> tuple[int, float] | None:
    """``(agent-steps, seconds)`` of the first checkpoint at ``target`` success, or None."""
    for steps, rate in curve:
        if rate >= target:
            logged = min(clock, key=lambda s: abs(s - steps))  # the progress row written with the checkpoint
            return steps, clock[logged]
    return None


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="training seeds (default 0 1 2)")
    parser.add_argument("--steps", type=int, default=6_000_000, help="agent-steps per run (default 6,000,000)")
    parser.add_argument("--every", type=int, default=500_000, help="agent-steps between checkpoints (default 500,000)")
    parser.add_argument("--worlds", type=int, default=100, help="held-out worlds per checkpoint (default 100)")
    parser.add_argument("--target", type=float, default=0.9, help="the success rate that counts as solved (0.9)")
    parser.add_argument("--threads", type=int, default=1, help="torch and numba threads of the training (1)")
    parser.add_argument("--device", default="cpu", help="where the networks run: cpu, cuda, cuda:N, mps (cpu)")
    parser.add_argument("--workers", type=int, default=1, help="processes that step the worlds (1)")
    parser.add_argument("--out", type=Path, default=None, help="write <out>.json and <out>.md")
    args = parser.parse_args(argv)

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            run_dir = Path(tmp) / f"s{seed}"
            train(seed, args.steps, args.every, args.threads, args.device, run_dir, args.workers)
            curve = judge(run_dir, args.worlds)
            solved = solve_time(curve, seconds_at(run_dir), args.target)
            rows.append({"seed": seed, "curve": curve, "solved": solved, "seconds": max(seconds_at(run_dir).values())})
            print(f"seed {seed}: " + (f"{solved[1]:.0f} s, {solved[0]:,} agent-steps" if solved else "not solved"))
    machine = describe("torch", "numba", device=args.device, threads=args.threads, workers=args.workers)
    times = [r["solved"][1] for r in rows if r["solved"]]
    lines = [
        "# Time to solve chain-v1 with native PPO",
        "",
        f"`{' '.join(['python benchmarks/time_to_solve.py', *(argv if argv is not None else sys.argv[1:])])}` "
        f"(the script's docstring says what it does): `{CONFIG}` (12-module chains at control level `move`: the "
        "policy picks each module's move, the rules' autopilot the rest) trained for "
        f"{args.steps:,} agent-steps per seed, "
        f"every checkpoint ({args.every:,} agent-steps apart) judged on {args.worlds} held-out worlds; solved: "
        f"{args.target * 100:.0f} % success. Machine: {machine['cpu']}, {machine['cores']} cores, device {args.device}, "
        f"{args.threads} thread(s), {args.workers} worker process(es), load average {machine['load_average_1min']} at the end; torch {machine['torch']}, "
        f"numba {machine['numba']}.",
        "",
        "| training seed | solved at (agent-steps) | wall-clock to solve | success at each checkpoint | run's wall-clock |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        at = f"{r['solved'][0]:,}" if r["solved"] else "not solved"
        clock = f"{r['solved'][1]:.0f} s" if r["solved"] else "-"
        curve = " ".join(f"{rate:.2f}" for _, rate in r["curve"])
        lines.append(f"| {r['seed']} | {at} | {clock} | {curve} | {r['seconds']:.0f} s |")
    if times:
        lines += [
            "",
            f"Median wall-clock to solve: {np.median(times):.0f} s ({len(times)} of {len(rows)} seeds solved).",
        ]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.with_suffix(".json").write_text(
            json.dumps({"machine": machine, "args": vars(args) | {"out": str(args.out)}, "rows": rows}, indent=1)
        )
        args.out.with_suffix(".md").write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

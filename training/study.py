"""A study: ``training/ppo.py`` on several tasks with several training seeds, kept for ``proteo eval``.

    python -m training.study                                  # every task at move, seeds 0 1 2
    python -m training.study --tasks "[chain]" --seeds "[0, 1, 2, 3, 4]" --minutes 8 --parallel 2
    python -m training.study --total-steps 16000000 --minutes 0      # the published study

For each task and seed it trains ``configs/train/ppo_<task>_<level>.yaml`` with ``--seed S`` for
``total_steps`` agent-steps or the time limit ``minutes`` (``parallel`` runs at a time, one
thread each), then keeps:

- the final checkpoint in ``checkpoints/<task>/ppo_<level>/seed_<S>/`` (what
  ``configs/eval_study.yaml`` names, one ``{label, runs}`` group per task);
- its ``progress.csv`` in ``docs/learning/progress/ppo_<task>_<level>_s<S>.csv`` and one figure
  of the learning curves of all seeds per task, ``docs/learning/curves_ppo_<task>_<level>.png``;
- ``docs/learning/study_<level>.json``: per run the agent-steps, the wall-clock and the final
  checkpoint (runs of other tasks or seeds already recorded there are kept).

Then ``proteo eval --config configs/eval_study.yaml --out docs/eval/study --pictures`` gives
the table with the spread over training seeds (``make learning-results`` runs both).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from training.common import parse_args


@dataclass(frozen=True)
class Args:
    """Train ``training/ppo.py`` on several tasks and training seeds (arguments of training/study.py)."""

    tasks: tuple[str, ...] = ("chain", "branch", "table", "grasp", "locomotion")
    level: str = "move"
    """Control level; the config of each run is configs/train/ppo_<task>_<level>.yaml."""
    seeds: tuple[int, ...] = (0, 1, 2)
    total_steps: int = 0
    """Agent-steps of each run (0: the config's total_steps)."""
    minutes: float = 6.0
    """Wall-clock limit of each run (0: none; then every run trains for its steps, whatever the machine's load)."""
    parallel: int = 2
    """Runs at a time (each uses one thread)."""
    runs_dir: str = "runs/study"
    keep_dir: str = "checkpoints"
    docs_dir: str = "docs/learning"


def _config(task: str, level: str) -> Path:
    path = Path("configs/train") / f"ppo_{task}_{level.replace('+', '-')}.yaml"
    if not path.is_file():
        raise ValueError(f"no training config {str(path)!r} for task {task!r} at level {level!r}; allowed: "
                         f"{', '.join(sorted(p.name for p in Path('configs/train').glob('ppo_*.yaml')))}")
    return path


def main(argv=None) -> int:
    args = parse_args(Args, argv)
    level = args.level.replace("+", "-")
    jobs = [(task, seed, _config(task, args.level)) for task in args.tasks for seed in args.seeds]
    pending, running, done = list(jobs), [], []
    while pending or running:
        while pending and len(running) < args.parallel:
            task, seed, config = pending.pop(0)
            run_dir = Path(args.runs_dir) / f"ppo_{task}_{level}_s{seed}"
            cmd = [sys.executable, "-m", "training.ppo", "--config", str(config), "--seed", str(seed),
                   "--run-dir", str(run_dir), "--time-limit-minutes", str(args.minutes),
                   "--progress-bar", "false"] + (["--total-steps", str(args.total_steps)] if args.total_steps else [])
            print(f"started {task} seed {seed}: {' '.join(cmd)}", flush=True)
            running.append((task, seed, run_dir, time.perf_counter(), subprocess.Popen(cmd)))
        time.sleep(1.0)
        for job in [j for j in running if j[4].poll() is not None]:
            running.remove(job)
            task, seed, run_dir, started, proc = job
            if proc.returncode != 0:
                raise RuntimeError(f"training {task} seed {seed} failed (exit {proc.returncode}); see {run_dir}")
            done.append((task, seed, run_dir, time.perf_counter() - started))
            print(f"finished {task} seed {seed} in {done[-1][3] / 60:.1f} min", flush=True)

    docs = Path(args.docs_dir)
    (docs / "progress").mkdir(parents=True, exist_ok=True)
    summary = []
    for task, seed, run_dir, seconds in sorted(done):
        keep = Path(args.keep_dir) / task / f"ppo_{level}" / f"seed_{seed}"
        if keep.exists():
            shutil.rmtree(keep)
        shutil.copytree(run_dir / "final", keep)
        shutil.copy(run_dir / "progress.csv", docs / "progress" / f"ppo_{task}_{level}_s{seed}.csv")
        meta = json.loads((keep / "proteo.json").read_text())
        summary.append({"task": task, "seed": seed, "level": args.level, "agent_steps": meta.get("agent_steps"),
                        "wall_clock_minutes": round(seconds / 60.0, 2), "checkpoint": str(keep)})
    record = docs / f"study_{level}.json"
    kept = json.loads(record.read_text()) if record.is_file() else []
    trained = {(run["task"], run["seed"]) for run in summary}
    runs = [run for run in kept if (run["task"], run["seed"]) not in trained] + summary
    record.write_text(json.dumps(sorted(runs, key=lambda run: (run["task"], run["seed"])), indent=1))

    from training.plots import plot_runs

    for task in args.tasks:
        runs = {f"seed {s}": str(docs / "progress" / f"ppo_{task}_{level}_s{s}.csv") for s in args.seeds}
        plot_runs(runs, docs / f"curves_ppo_{task}_{level}.png", title=f"training/ppo.py on {task} at {args.level}")
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""A study: several training recipes on several tasks with several training seeds, kept for ``proteo eval``.

    python -m training.trainers.study                                  # plain PPO on every task at move, seeds 0 1 2
    python -m training.trainers.study --tasks "[chain]" --seeds "[0, 1, 2, 3, 4]" --minutes 8 --parallel 2
    python -m training.trainers.study --total-steps 16000000 --minutes 0      # the published PPO study
    python -m training.trainers.study --recipes "[imitation, kickstart]" --minutes 0   # clones, then PPO from them

Recipes (``recipes``), each a script and a config per task and level:

================ ======================== ====================================================
recipe           script                   config
================ ======================== ====================================================
``ppo``          ``training/trainers/ppo.py``      ``configs/train/ppo_<task>_<level>.yaml``
``ppo48``        ``training/trainers/ppo.py``      the same, for 48 M agent-steps
``imitation``    ``training/trainers/imitate.py``  ``configs/train/bc_<task>_<level>.yaml`` (a clone)
``kickstart``    ``training/trainers/ppo.py``      ``configs/train/kickstart_<task>_<level>.yaml``, with
                                          ``--init`` the kept clone of the same task and seed
``curriculum``   ``training/trainers/ppo.py``      ``configs/train/curriculum_<task>_<level>.yaml`` (stages
                                          of env overrides, no demonstrations)
``credit``       ``training/trainers/ppo.py``      ``configs/train/credit_<task>_<level>.yaml``: kickstarting
                                          with module credit (``join_bonus``), from the same clone
``kickstart-     ``training/trainers/ppo.py``      ``configs/train/kickstart_sizes_<task>_<level>.yaml``:
sizes``                                   kickstarting through a curriculum of sizes (the scale
                                          track), from the same clone
``cma``          ``training/trainers/cma_es.py``   ``configs/train/cma_rules_<task>_full.yaml``: CMA-ES over
                                          the hand-coded rules' parameters (level ``full``, for
                                          the config's generations)
``evolve``       ``training/trainers/evolve.py``   ``configs/train/evolve_<task>_full.yaml``: evolution of
                                          programs of the paper's primitives from random ones
                                          (level ``full``, for the config's generations)
``evolve-paper`` ``training/trainers/evolve.py``   ``configs/train/evolve_paper_<task>_full.yaml``: the
                                          same from the paper's program
                                          (``baselines/programs/<task>.yaml``)
``evolve-large`` ``training/trainers/evolve.py``   ``configs/train/evolve_large_<task>_full.yaml``:
                                          ``evolve`` with ten times the episodes per generation
``evolve-large-  ``training/trainers/evolve.py``   ``configs/train/evolve_large_paper_<task>_full.yaml``:
paper``                                   ``evolve-paper`` with ten times the episodes
================ ======================== ====================================================

For each recipe, task and seed it trains the config with ``--seed S`` (PPO recipes for
``total_steps`` agent-steps or the time limit ``minutes``, CMA-ES and program evolution for
their generations or that limit; ``parallel`` runs at a time, one
thread each; a kickstart run waits for its clone), then keeps:

- the final checkpoint, without its optimiser state (``--resume`` reads that from the run
  folder), in ``<keep_dir>/<task>/<recipe>_<level>/seed_<S>/`` (the protocol's tree:
  ``--keep-dir checkpoints/v6``; ``configs/eval.yaml`` names such folders as one ``{label, runs}``
  group per task and recipe);
- its ``progress.csv`` in ``<docs_dir>/progress/<recipe>_<task>_<level>_s<S>.csv`` and one
  figure of the learning curves per task of every seed recorded there (this call's and earlier
  ones'), ``<docs_dir>/curves_<recipe>_<task>_<level>.png``;
- ``<docs_dir>/study_<level>.json``: per run the recipe, agent-steps, wall-clock (the training's
  own, from its ``progress.csv``: a run resumed part way counts in all) and final checkpoint, recorded as each run finishes (runs of other recipes, tasks or seeds already recorded there
  are kept).

A run whose folder already holds a final checkpoint (an earlier study of the same ``runs_dir``
that stopped part way) is kept as it is, not trained again; delete its folder to retrain it.

With ``--benchmark VERSION`` each recipe's config, budget, task id and starting checkpoint are the
protocol's (``config``, ``agent_steps``, the task's id, ``init``: kickstart-move starts from the
kept imitation-move clone), and a recipe the protocol does not fix for a task is refused before
anything runs.

Then ``proteo eval --benchmark v7 --checkpoint ... --out docs/benchmark/v7/<task>/<recipe>`` judges
each recipe's seeds on every split of the benchmark protocol and ``make results`` writes
docs/results.md (``make learning-results-v7`` runs all three for the published recipes, with
``--benchmark v7 --keep-dir checkpoints/v7 --docs-dir docs/benchmark/v7/learning``).
"""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from proteo_env.config import CONTROL_LEVELS, ConfigError
from training.judging.plots import plot_runs
from training.judging.protocol import load_protocol
from training.machinery import registry
from training.machinery.checkpoints import keep_checkpoint
from training.machinery.runs import check_integers, check_numbers, parse_args

RECIPES = {
    "ppo": ("ppo", "ppo", 0),
    "ppo48": ("ppo", "ppo", 48_000_000),
    "imitation": ("imitate", "bc", 0),
    "kickstart": ("ppo", "kickstart", 0),
    "curriculum": ("ppo", "curriculum", 0),
    "credit": ("ppo", "credit", 0),
    "kickstart-sizes": ("ppo", "kickstart_sizes", 0),
    "cma": ("cma_es", "cma_rules", 0),
    "evolve": ("evolve", "evolve", 0),
    "evolve-paper": ("evolve", "evolve_paper", 0),
    "evolve-large": ("evolve", "evolve_large", 0),
    "evolve-large-paper": ("evolve", "evolve_large_paper", 0),
}
"""Recipe name: (its trainer's name in :mod:`training.machinery.registry`, prefix of its configs in
configs/train, agent-steps of a PPO run unless ``total_steps`` says otherwise; 0: the config's)."""
FROM_CLONE = ("kickstart", "credit", "kickstart-sizes")
"""Recipes whose runs start from the kept clone of the same task and seed (``--init``)."""


@dataclass(frozen=True)
class Args:
    """Train several recipes on several tasks and training seeds (arguments of training/trainers/study.py)."""

    tasks: tuple[str, ...] = ("chain", "branch", "table", "grasp", "locomotion")
    """Task names (no version): each run trains configs/train/<prefix>_<task>_<level>.yaml."""
    recipes: tuple[str, ...] = ("ppo",)
    """Training recipes (ppo, ppo48, imitation, kickstart, curriculum, credit, kickstart-sizes, cma, evolve,
    evolve-paper, evolve-large, evolve-large-paper); see the module docstring."""
    level: str = "move"
    """Control level; the config of each run is configs/train/<prefix>_<task>_<level>.yaml."""
    seeds: tuple[int, ...] = (0, 1, 2)
    """Training seeds: every recipe is trained on every task once per seed (``--seed S``)."""
    total_steps: int = 0
    """Agent-steps of each PPO run (0: the config's total_steps)."""
    minutes: float = 6.0
    """Wall-clock limit of each PPO, CMA-ES or evolution run (0: none; then every run trains for its steps, whatever the machine's load)."""
    parallel: int = 2
    """Runs at a time (each uses one thread)."""
    flags: dict = field(default_factory=dict)
    """Extra flags of each recipe's script, e.g. ``{imitation: [--rounds, "1"]}``."""
    runs_dir: str = "runs/study"
    """Folder of the run folders, <recipe>_<task>_<level>_s<S>; one with a final checkpoint is not retrained."""
    keep_dir: str = "runs/study/checkpoints"
    """Where the final checkpoints are kept, as <task>/<recipe>_<level>/seed_<S>/ (without trainer.pt); the
    protocol's studies keep theirs in its tree (``checkpoints/v7``, the Makefile's learning-results-v7)."""
    benchmark: str | None = None
    """A benchmark protocol version (``v7``): each recipe's config, budget and clone are the protocol's
    (recipe ``kickstart`` at level ``move`` is its ``kickstart-move``) and each run trains on the protocol's
    task id (``--task``); default: the configs configs/train/<prefix>_<task>_<level>.yaml as they are."""
    clone_dir: str | None = None
    """Where the recipes that start from a clone (kickstart, credit, kickstart-sizes) find it, as
    <task>/imitation_<level>/seed_<S>/ (None: ``keep_dir``; ``checkpoints/v7``: the published clones)."""
    docs_dir: str = "runs/study/docs"
    """Where the progress logs (progress/), the learning-curve figures and study_<level>.json are written (the
    protocol's studies: ``docs/benchmark/v6/learning``)."""


def _config(recipe: str, task: str, level: str) -> Path:
    if recipe not in RECIPES:
        raise ValueError(f"recipe {recipe!r} is not allowed; allowed: {', '.join(RECIPES)}")
    prefix = RECIPES[recipe][1]
    if not Path("configs/train").is_dir():
        raise ValueError(
            f"the working folder {str(Path.cwd())!r} has no configs/train, where the recipes' configs are; allowed: "
            "running the study from the repository's root"
        )
    path = Path("configs/train") / f"{prefix}_{task}_{level.replace('+', '-')}.yaml"
    if not path.is_file():
        raise ValueError(
            f"no training config {str(path)!r} for recipe {recipe!r} on task {task!r} at level "
            f"{level!r}; allowed: {', '.join(sorted(p.name for p in Path('configs/train').glob(prefix + '_*.yaml')))}"
        )
    return path


@dataclass(frozen=True)
class Recipe:
    """One recipe on one task, as the study trains it."""

    config: Path
    steps: int
    """Agent-steps of a PPO run (0: the config's)."""
    task_id: str | None
    """The task id to train on (``--task``; None: the config's)."""
    init: str | None
    """The recipe whose kept checkpoint of the same task and seed the run starts from (``--init``; None: none)."""


class StudyPlan:
    """What the study trains: each recipe's config, budget, task id and starting checkpoint, from
    ``configs/train`` (kickstart and credit from the imitation clone) or from a benchmark protocol
    (its ``config``, ``agent_steps`` and ``init``)."""

    def __init__(self, args: Args):
        self.args = args
        self.protocol = None
        if args.benchmark is not None:
            self.protocol = load_protocol(args.benchmark)

    def recipe(self, recipe: str, task: str) -> Recipe:
        """``recipe`` on ``task``; an unknown recipe, or one the protocol does not fix for the task, is one
        error naming what is allowed."""
        args = self.args
        if self.protocol is None:
            steps = args.total_steps or RECIPES[recipe][2]
            return Recipe(_config(recipe, task, args.level), steps, None, "imitation" if recipe in FROM_CLONE else None)
        if recipe not in RECIPES:
            raise ValueError(f"recipe {recipe!r} is not allowed; allowed: {', '.join(RECIPES)}")
        where = f"benchmark {self.protocol.version}"
        if task not in self.protocol.tasks:
            raise ValueError(f"{where}: task {task!r} is not allowed; allowed: {', '.join(self.protocol.tasks)}")
        fixed = self.protocol.tasks[task]
        suffix = f"-{args.level.replace('+', '-')}"
        label = f"{recipe}{suffix}"
        if label not in fixed.recipes:
            raise ValueError(
                f"{where}: recipe {recipe!r} at level {args.level!r} ({label}) on {task} is not allowed; "
                f"allowed: {', '.join(fixed.recipes)}"
            )
        entry = fixed.recipes[label]
        init = entry["init"]
        if init is not None and init.removesuffix(suffix) not in RECIPES:
            raise ValueError(
                f"{where}: {task}.recipes.{label}.init = {init!r} is not allowed here; allowed: a recipe of the "
                f"study at level {args.level!r} ({', '.join(r + suffix for r in RECIPES)})"
            )
        init = None if init is None else init.removesuffix(suffix)
        return Recipe(Path(entry["config"]), args.total_steps or entry["agent_steps"] or 0, fixed.task_id, init)

    def command(self, recipe: str, task: str, seed: int, run_dir: Path, init_dir: Path | None) -> list[str]:
        """The command line of one run; ``init_dir``: the kept checkpoint it starts from, where it has one."""
        args, plan = self.args, self.recipe(recipe, task)
        trainer = RECIPES[recipe][0]
        cmd = [
            sys.executable,
            "-m",
            registry.trainer(trainer).module,
            "--config",
            str(plan.config),
            "--seed",
            str(seed),
            "--run-dir",
            str(run_dir),
            "--progress-bar",
            "false",
        ]
        if trainer in ("ppo", "cma_es", "evolve"):
            cmd += ["--time-limit-minutes", str(args.minutes)]
        if trainer in ("cma_es", "evolve"):
            cmd += ["--workers", "1"]  # one process per run: the study runs ``parallel`` of them
        if trainer == "ppo":
            cmd += ["--total-steps", str(plan.steps)] if plan.steps else []
        if plan.task_id is not None:
            cmd += ["--task", plan.task_id]
        if plan.init is not None:
            cmd += ["--init", str(init_dir)]
        return cmd + [str(flag) for flag in args.flags.get(recipe, ())]


def _run_seconds(run_dir: Path) -> float:
    """Training seconds of a finished run, from the last row of its ``progress.csv`` (across resumes)."""
    with open(run_dir / "progress.csv") as f:
        rows = list(csv.DictReader(f))
    return float(rows[-1]["seconds"]) if rows else 0.0


def _record(path: Path, run: dict) -> None:
    """Add one finished run to the study record (replacing an earlier record of the same recipe, task and
    seed), written whole to a temporary file and moved into place: a study stopped part way keeps every run it
    finished, and the record is never half-written."""
    runs = json.loads(path.read_text()) if path.is_file() else []
    key = (run["recipe"], run["task"], run["seed"])
    runs = [r for r in runs if (r.get("recipe", "ppo"), r["task"], r["seed"]) != key] + [run]
    runs.sort(key=lambda r: (r.get("recipe", "ppo"), r["task"], r["seed"]))
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(runs, indent=1))
    tmp.replace(path)


def check_args(args: Args) -> None:
    """Every argument of a study checked before any run starts: one :class:`ConfigError` naming the
    field, the value and what is allowed."""
    check_integers(args, {"parallel": 1, "total_steps": 0})
    check_numbers(args, {"minutes": (0.0, None)})
    if args.level not in CONTROL_LEVELS:
        raise ConfigError(f"level={args.level!r} is not allowed; allowed: {', '.join(CONTROL_LEVELS)}")
    for recipe in args.recipes:
        if recipe not in RECIPES:
            raise ConfigError(f"recipes: {recipe!r} is not allowed; allowed: {', '.join(RECIPES)}")
    for seed in args.seeds:
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ConfigError(f"seeds: {seed!r} is not allowed; allowed: integers >= 0 (training seeds)")
    for name, values in (("recipes", args.recipes), ("tasks", args.tasks), ("seeds", args.seeds)):
        if not values:
            raise ConfigError(f"{name} = [] is not allowed; allowed: at least one")


def main(argv=None) -> int:
    args = parse_args(Args, argv)
    check_args(args)
    level = args.level.replace("+", "-")
    keep_dir, docs = Path(args.keep_dir), Path(args.docs_dir)
    clones = keep_dir if args.clone_dir is None else Path(args.clone_dir)

    def kept(recipe: str, task: str, seed: int, root: Path = keep_dir) -> Path:
        return root / task / f"{recipe}_{level}" / f"seed_{seed}"

    plan = StudyPlan(args)
    jobs = [(recipe, task, seed) for recipe in args.recipes for task in args.tasks for seed in args.seeds]
    init = {(recipe, task): plan.recipe(recipe, task).init for recipe, task, _ in jobs}
    for recipe in args.flags:
        if recipe not in args.recipes:
            raise ValueError(f"flags of recipe {recipe!r} are not allowed; allowed: flags of {', '.join(args.recipes)}")
    (docs / "progress").mkdir(parents=True, exist_ok=True)
    pending, running, summary = list(jobs), [], []
    while pending or running:
        waiting = set(pending) | {j[:3] for j in running}
        for job in list(pending):
            if len(running) >= args.parallel:
                break
            recipe, task, seed = job
            start = init[(recipe, task)]
            if start is not None and (start, task, seed) in waiting:  # what it starts from is still to be trained
                continue
            pending.remove(job)
            run_dir = Path(args.runs_dir) / f"{recipe}_{task}_{level}_s{seed}"
            if (run_dir / "final" / "proteo.json").is_file():  # trained by an earlier study: kept, not retrained
                print(f"already trained {recipe} {task} seed {seed}: {run_dir}", flush=True)
                running.append((recipe, task, seed, run_dir, None))
                continue
            cmd = plan.command(recipe, task, seed, run_dir, kept(start, task, seed, clones) if start else None)
            print(f"started {recipe} {task} seed {seed}: {' '.join(cmd)}", flush=True)
            running.append((recipe, task, seed, run_dir, subprocess.Popen(cmd)))
        time.sleep(1.0)
        for job in [j for j in running if j[4] is None or j[4].poll() is not None]:
            running.remove(job)
            recipe, task, seed, run_dir, proc = job
            if proc is not None and proc.returncode != 0:
                raise RuntimeError(
                    f"training {recipe} {task} seed {seed} failed (exit {proc.returncode}); see {run_dir}"
                )
            seconds = _run_seconds(run_dir)  # the trainer's clock: a run resumed part way counts in all
            if proc is not None:
                print(f"finished {recipe} {task} seed {seed} in {seconds / 60:.1f} min", flush=True)
            keep = kept(recipe, task, seed)
            # the recipe recorded: the judge recognises it by it, and checks it against the protocol
            keep_checkpoint(run_dir / "final", keep, recipe=f"{recipe}-{level}")  # resume: run_dir
            shutil.copy(run_dir / "progress.csv", docs / "progress" / f"{recipe}_{task}_{level}_s{seed}.csv")
            meta = json.loads((keep / "proteo.json").read_text())
            summary.append(
                {
                    "recipe": recipe,
                    "task": task,
                    "seed": seed,
                    "level": args.level,
                    "agent_steps": meta.get("agent_steps"),
                    "wall_clock_minutes": round(seconds / 60.0, 2),
                    "checkpoint": str(keep),
                }
            )
            _record(docs / f"study_{level}.json", summary[-1])

    for recipe in args.recipes:
        for task in args.tasks:
            # every seed recorded in docs_dir, not only this call's: a study resumed for more seeds redraws them all
            recorded = (docs / "progress").glob(f"{recipe}_{task}_{level}_s*.csv")
            seeds = sorted(int(path.stem.rsplit("_s", 1)[1]) for path in recorded)
            runs = {f"seed {s}": str(docs / "progress" / f"{recipe}_{task}_{level}_s{s}.csv") for s in seeds}
            plot_runs(
                runs,
                docs / f"curves_{recipe}_{task}_{level}.png",
                title=f"{recipe} (training/{RECIPES[recipe][0]}.py) on {task} at {args.level}",
            )
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

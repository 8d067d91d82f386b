"""Train BenchMARL's MAPPO or IPPO on a proteo task and describe the runs in an entrant.yaml that
`proteo eval --benchmark v7 --entrant` judges, from the checkpoints as BenchMARL saves them.

Written as a BenchMARL user would: BenchMARL's own Experiment, algorithms, MLP and checkpoints, on
proteo's BenchMARL task (`proteo_env.adapters.benchmarl.ProteoTask`). Runs in BenchMARL's own
environment (`make benchmarl`; BenchMARL 1.5 needs torchrl < 0.12), and so does the judge:

    .venv-benchmarl/bin/python examples/benchmarl/train.py --algorithm mappo --task chain --seeds 0 1 --out my_entrant
    .venv-benchmarl/bin/proteo eval --benchmark v7 --entrant my_entrant --out my_entrant/judged

Each training seed is one BenchMARL experiment in ``OUT/seed_K/`` (its ``config.pkl`` and its last
checkpoint, ``checkpoints/checkpoint_<frames>.pt``); a seed already trained is skipped and a seed
cut off resumes from its last checkpoint (BenchMARL's ``Experiment.reload_from_file``), so the
seeds may run in separate processes, one core each. Every invocation rewrites ``OUT/entrant.yaml``
from the seeds finished so far.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import torch
import yaml
from benchmarl.algorithms import algorithm_config_registry
from benchmarl.experiment import Experiment
from benchmarl.models import MlpConfig

from proteo_env.adapters.benchmarl import ProteoTask, experiment_config

TASKS = {  # protocol v7's training settings (configs/benchmark/v7.yaml)
    "chain": (ProteoTask.CHAIN_V1, "chain-v1", {"n_modules": 12, "max_cycles": 300, "motion_model": "sphere"}),
    "grasp": (ProteoTask.GRASP_V0, "grasp-v0", {"n_modules": 100, "distance": 3, "max_cycles": 300}),
}
AGENT_STEPS_PER_BATCH = 24_576  # proteo's native PPO: 64 worlds x 32 cycles x 12 modules
STEPS_PER_WORLD = 32
HIDDEN = [64, 64]
LEARNING_RATE, ENTROPY, LAMBDA, EPOCHS, MINIBATCHES = 3e-4, 0.01, 0.95, 4, 4
RUN_FILE = "run.yaml"


def build(algorithm: str, task: str, seed: int, agent_steps: int, folder: Path) -> Experiment:
    """A new BenchMARL experiment: ``algorithm`` with an MLP actor and critic of :data:`HIDDEN`,
    batches of about :data:`AGENT_STEPS_PER_BATCH` agent-steps (:data:`EPOCHS` epochs of
    :data:`MINIBATCHES` minibatches each)."""
    member, _, settings = TASKS[task]
    n_modules = settings["n_modules"]
    n_worlds = max(1, round(AGENT_STEPS_PER_BATCH / n_modules / STEPS_PER_WORLD))
    frames_per_batch = n_worlds * STEPS_PER_WORLD
    n_batches = max(1, round(agent_steps / n_modules / frames_per_batch))
    algorithm_config = algorithm_config_registry[algorithm].get_from_yaml()
    algorithm_config.entropy_coef, algorithm_config.lmbda = ENTROPY, LAMBDA
    model = MlpConfig.get_from_yaml()
    model.num_cells = HIDDEN
    config = experiment_config(
        max_n_frames=n_batches * frames_per_batch,
        on_policy_collected_frames_per_batch=frames_per_batch,
        on_policy_n_envs_per_worker=n_worlds,
        on_policy_minibatch_size=frames_per_batch // MINIBATCHES,
        on_policy_n_minibatch_iters=EPOCHS,
        lr=LEARNING_RATE,
        evaluation=False,
        loggers=[],
        render=False,
        save_folder=str(folder),
        checkpoint_interval=frames_per_batch * 10,
        keep_checkpoints_num=1,
        checkpoint_at_end=True,
        exclude_buffer_from_checkpoint=True,
    )
    return Experiment(
        task=member.get_task(settings),
        algorithm_config=algorithm_config,
        model_config=model,
        critic_model_config=model,
        seed=seed,
        config=config,
    )


def train_seed(algorithm: str, task: str, seed: int, agent_steps: int, out: Path) -> dict:
    """Train (or finish, or skip) training seed ``seed`` in ``out/seed_<seed>``; its run record."""
    folder = out / f"seed_{seed}"
    if (folder / RUN_FILE).is_file():
        return yaml.safe_load((folder / RUN_FILE).read_text())
    folder.mkdir(parents=True, exist_ok=True)
    saved = sorted(folder.glob("*/checkpoints/checkpoint_*.pt"), key=lambda p: int(p.stem.split("_")[1]))
    if saved:
        run = Experiment.reload_from_file(str(saved[-1]))
        print(f"seed {seed}: resumed at {run.total_frames} frames")
    else:
        run = build(algorithm, task, seed, agent_steps, folder)
    run.run()
    checkpoint = max(folder.glob("*/checkpoints/checkpoint_*.pt"), key=lambda p: int(p.stem.split("_")[1]))
    record = {
        "checkpoint": str(checkpoint.relative_to(out)),
        "frames": run.total_frames,
        "agent_steps": run.total_frames * TASKS[task][2]["n_modules"],
        "seconds": round(run.total_time, 1),  # BenchMARL's own clock, kept across a resume
    }
    (folder / RUN_FILE).write_text(yaml.safe_dump(record, sort_keys=False))
    print(f"seed {seed}: {record['agent_steps']} agent-steps in {record['seconds']:.0f} s")
    return record


def write_entrant(algorithm: str, task: str, out: Path) -> Path:
    """``out/entrant.yaml`` for every seed finished in ``out`` (written whole, then renamed)."""
    runs = {}
    for file in out.glob(f"seed_*/{RUN_FILE}"):
        runs[int(file.parent.name.split("_")[1])] = yaml.safe_load(file.read_text())
    seeds = sorted(runs)
    entrant = {
        "entrant": 1,
        "name": f"benchmarl-{algorithm}",
        "task": TASKS[task][1],
        "control": "move",
        "format": "benchmarl",
        "seeds": {seed: runs[seed]["checkpoint"] for seed in seeds},
        "actions": "sample",
        "budget": {
            "agent_steps": max(runs[seed]["agent_steps"] for seed in seeds),
            "wall_clock_minutes": round(sum(runs[seed]["seconds"] for seed in seeds) / 60 / len(seeds), 2),
        },
        "code": "examples/benchmarl/train.py in the proteo repository",
        "about": (
            f"BenchMARL 1.5's {algorithm.upper()} (its defaults but: lr {LEARNING_RATE}, entropy {ENTROPY}, "
            f"lambda {LAMBDA}, {EPOCHS} epochs of {MINIBATCHES} minibatches a batch of about {AGENT_STEPS_PER_BATCH} "
            "agent-steps); "
            f"MLP actor and critic {'-'.join(map(str, HIDDEN))} tanh, parameters shared by every module"
        ),
    }
    partial = out / "entrant.yaml.partial"
    partial.write_text(yaml.safe_dump(entrant, sort_keys=False))
    os.replace(partial, out / "entrant.yaml")
    return out / "entrant.yaml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--algorithm", choices=("mappo", "ippo"), default="mappo")
    parser.add_argument("--task", choices=sorted(TASKS), default="chain")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="training seeds, one experiment each")
    parser.add_argument("--agent-steps", type=int, default=2_000_000, help="agent-steps per training seed")
    parser.add_argument("--out", default="out/benchmarl_entrant", help="folder for the experiments and entrant.yaml")
    args = parser.parse_args()
    torch.set_num_threads(1)
    out = Path(args.out)
    for seed in args.seeds:
        train_seed(args.algorithm, args.task, seed, args.agent_steps, out)
    print(
        f"{write_entrant(args.algorithm, args.task, out)}; judge it with .venv-benchmarl/bin/proteo eval --benchmark "
        f"v7 --entrant {out} --out {out / 'judged'}"
    )


if __name__ == "__main__":
    main()

"""training/trainers/study.py: several training seeds run, their checkpoints and progress are kept where
configs/eval_study.yaml and the docs read them (a tiny budget)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from training.machinery.checkpoints import read_meta
from training.trainers import study


@pytest.mark.slow  # several training seeds
def test_a_tiny_study_keeps_each_seed_s_checkpoint_progress_and_curves(tmp_path):
    keep, docs = tmp_path / "checkpoints", tmp_path / "docs"
    study.main(
        [
            "--tasks",
            "[chain]",
            "--seeds",
            "[0, 1]",
            "--minutes",
            "0.02",
            "--parallel",
            "2",
            "--runs-dir",
            str(tmp_path / "runs"),
            "--keep-dir",
            str(keep),
            "--docs-dir",
            str(docs),
        ]
    )
    summary = json.loads((docs / "study_move.json").read_text())
    assert [(r["task"], r["seed"]) for r in summary] == [("chain", 0), ("chain", 1)]
    for seed in (0, 1):
        meta = read_meta(keep / "chain" / "ppo_move" / f"seed_{seed}")
        assert meta["seed"] == seed and meta["control"] == "move" and meta["agent_steps"] > 0
        assert (
            meta["recipe"] == "ppo-move" and "trainer.pt" not in meta["files"]
        )  # recorded; read_meta checked the rest
        assert (docs / "progress" / f"ppo_chain_move_s{seed}.csv").is_file()
    assert (docs / "curves_ppo_chain_move.png").stat().st_size > 0


@pytest.mark.slow  # one training seed
def test_a_study_run_again_keeps_its_finished_runs_without_training_them_again(tmp_path, monkeypatch):
    keep, docs = tmp_path / "checkpoints", tmp_path / "docs"
    argv = ["--tasks", "[chain]", "--seeds", "[0]", "--minutes", "0.02", "--runs-dir", str(tmp_path / "runs")]
    argv += ["--keep-dir", str(keep), "--docs-dir", str(docs)]
    study.main(argv)
    trained = read_meta(keep / "chain" / "ppo_move" / "seed_0")
    (keep / "chain").rename(tmp_path / "first")  # the kept copy goes; the run folder stays

    def no_training(cmd, *a, **k):
        raise AssertionError(f"trained again: {cmd}")

    monkeypatch.setattr(study.subprocess, "Popen", no_training)
    study.main(argv)
    assert read_meta(keep / "chain" / "ppo_move" / "seed_0") == trained
    [run] = json.loads((docs / "study_move.json").read_text())
    assert run["seed"] == 0 and run["agent_steps"] == trained["agent_steps"] and run["wall_clock_minutes"] > 0


@pytest.mark.slow  # several training seeds
def test_a_clone_then_ppo_from_it_in_one_study(tmp_path):
    keep, docs = tmp_path / "checkpoints", tmp_path / "docs"
    tiny = ["--n-envs", "4", "--env", "{n_modules: 6, max_cycles: 40}"]
    study.main(
        [
            "--tasks",
            "[chain]",
            "--seeds",
            "[0]",
            "--recipes",
            "[imitation, kickstart]",
            "--minutes",
            "0.02",
            "--parallel",
            "2",
            "--runs-dir",
            str(tmp_path / "runs"),
            "--keep-dir",
            str(keep),
            "--docs-dir",
            str(docs),
            "--flags",
            json.dumps({"imitation": ["--rounds", "1", "--cycles-per-round", "20", *tiny], "kickstart": tiny}),
        ]
    )
    summary = json.loads((docs / "study_move.json").read_text())
    assert [(r["recipe"], r["task"]) for r in summary] == [("imitation", "chain"), ("kickstart", "chain")]
    clone = read_meta(keep / "chain" / "imitation_move" / "seed_0")
    kicked = read_meta(keep / "chain" / "kickstart_move" / "seed_0")
    assert clone["algorithm"] == "imitation" and kicked["algorithm"] == "ppo"
    assert kicked["args"]["init"] == str(keep / "chain" / "imitation_move" / "seed_0")
    assert (docs / "curves_imitation_chain_move.png").is_file() and (docs / "curves_kickstart_chain_move.png").is_file()


def test_a_study_that_fails_part_way_keeps_the_record_of_every_run_it_finished(tmp_path, monkeypatch):
    keep, docs = tmp_path / "checkpoints", tmp_path / "docs"

    class Finished:  # a training process: seed 0 writes its final checkpoint, seed 1 fails
        def __init__(self, cmd, *a, **k):
            run_dir = Path(cmd[cmd.index("--run-dir") + 1])
            self.returncode = int(cmd[cmd.index("--seed") + 1])
            if self.returncode == 0:
                (run_dir / "final").mkdir(parents=True)
                (run_dir / "final" / "proteo.json").write_text(json.dumps({"agent_steps": 123, "files": {}}))
                (run_dir / "progress.csv").write_text("seconds,agent_steps\n1.0,123\n")

        def poll(self):
            return self.returncode

    monkeypatch.setattr(study.subprocess, "Popen", Finished)
    argv = ["--tasks", "[chain]", "--seeds", "[0, 1]", "--runs-dir", str(tmp_path / "runs")]
    with pytest.raises(RuntimeError, match="training ppo chain seed 1 failed"):
        study.main(argv + ["--keep-dir", str(keep), "--docs-dir", str(docs)])
    [run] = json.loads((docs / "study_move.json").read_text())
    assert (run["task"], run["seed"], run["agent_steps"]) == ("chain", 0, 123)
    assert not list(docs.glob("*.tmp"))


def test_the_long_ppo_recipe_trains_the_ppo_config_for_its_own_steps(tmp_path):
    args = study.Args(tasks=("table",), recipes=("ppo48",), minutes=0.0)
    cmd = study.StudyPlan(args).command("ppo48", "table", 1, tmp_path / "run", tmp_path / "clone")
    assert cmd[cmd.index("--config") + 1] == "configs/train/ppo_table_move.yaml"
    assert cmd[cmd.index("--total-steps") + 1] == "48000000"
    cmd = study.StudyPlan(study.Args(total_steps=1000)).command(
        "ppo48", "table", 1, tmp_path / "run", tmp_path / "clone"
    )
    assert cmd[cmd.index("--total-steps") + 1] == "1000", "an explicit budget still wins"
    assert "--total-steps" not in study.StudyPlan(args).command("ppo", "table", 1, tmp_path / "run", tmp_path / "clone")


def test_the_credit_recipe_starts_from_the_clone_with_module_credit(tmp_path):
    args = study.Args(tasks=("grasp",), recipes=("credit",), minutes=0.0)
    cmd = study.StudyPlan(args).command("credit", "grasp", 2, tmp_path / "run", tmp_path / "clone")
    config = cmd[cmd.index("--config") + 1]
    assert config == "configs/train/credit_grasp_move.yaml"
    assert cmd[cmd.index("--init") + 1] == str(tmp_path / "clone")
    from training.machinery.runs import parse_args
    from training.trainers.ppo import Args

    assert parse_args(Args, ["--config", config]).join_bonus > 0


@pytest.mark.parametrize(
    ("recipe", "config"),
    [
        ("evolve", "configs/train/evolve_chain_full.yaml"),
        ("evolve-paper", "configs/train/evolve_paper_chain_full.yaml"),
    ],
)
def test_the_evolution_recipes_run_their_config_for_its_generations(tmp_path, recipe, config):
    args = study.Args(tasks=("chain",), recipes=(recipe,), level="full", minutes=0.0)
    cmd = study.StudyPlan(args).command(recipe, "chain", 2, tmp_path / "run", tmp_path / "clone")
    assert cmd[cmd.index("-m") + 1] == "training.trainers.evolve" and cmd[cmd.index("--config") + 1] == config
    assert cmd[cmd.index("--time-limit-minutes") + 1] == "0.0" and cmd[cmd.index("--seed") + 1] == "2"


def test_every_recipe_names_a_registered_trainer_and_its_configs_exist():
    from pathlib import Path

    from training.machinery.registry import trainer

    for name, prefix, _ in study.RECIPES.values():
        assert trainer(name).algorithms  # a trainer that writes checkpoints
        assert list(Path("configs/train").glob(f"{prefix}_*.yaml"))


def test_a_study_for_a_protocol_trains_its_recipes_configs_and_budgets_on_its_task_id(tmp_path):
    args = study.Args(benchmark="v7", level="move", tasks=("table",))
    cmd = study.StudyPlan(args).command("kickstart", "table", 3, tmp_path / "run", tmp_path / "clone")
    assert cmd[cmd.index("--config") + 1] == "configs/train/kickstart_table_move.yaml"
    assert cmd[cmd.index("--task") + 1] == "table-v2", "the config says table-v1; the protocol judges table-v2"
    assert cmd[cmd.index("--total-steps") + 1] == "6000000"
    assert cmd[cmd.index("--init") + 1] == str(tmp_path / "clone")
    assert study.StudyPlan(args).recipe("kickstart", "table").init == "imitation", "the protocol's init: imitation-move"
    assert study.StudyPlan(args).recipe("ppo", "table").init is None
    full = study.Args(benchmark="v7", level="full", tasks=("branch",))
    cmd = study.StudyPlan(full).command("evolve-large", "branch", 0, tmp_path / "run", tmp_path / "clone")
    assert cmd[cmd.index("--config") + 1] == "configs/train/evolve_large_branch_full.yaml"
    assert cmd[cmd.index("--task") + 1] == "branch-v0" and "--total-steps" not in cmd
    assert "--task" not in study.StudyPlan(study.Args()).command(
        "ppo", "table", 1, tmp_path / "run", tmp_path / "clone"
    )


def test_a_recipe_the_protocol_does_not_fix_is_one_error_before_anything_is_written(tmp_path):
    docs = tmp_path / "docs"
    argv = ["--benchmark", "v7", "--recipes", "[curriculum]", "--tasks", "[table]", "--docs-dir", str(docs)]
    with pytest.raises(ValueError, match=r"recipe 'curriculum' at level 'move' \(curriculum-move\) on table"):
        study.main(argv)
    assert not docs.exists()


def test_a_study_for_more_seeds_draws_the_curves_of_every_recorded_seed(tmp_path, monkeypatch):
    class Finished:  # a training process that writes its final checkpoint and progress log
        returncode = 0

        def __init__(self, cmd, *a, **k):
            run_dir = Path(cmd[cmd.index("--run-dir") + 1])
            (run_dir / "final").mkdir(parents=True)
            (run_dir / "final" / "proteo.json").write_text(json.dumps({"agent_steps": 123, "files": {}}))
            (run_dir / "progress.csv").write_text("seconds,agent_steps\n1.0,123\n")

        def poll(self):
            return 0

    drawn = []
    monkeypatch.setattr(study.subprocess, "Popen", Finished)
    monkeypatch.setattr(study, "plot_runs", lambda runs, path, title: drawn.append((path.name, sorted(runs))))
    for seeds in ("[0, 1]", "[2]"):
        study.main(
            ["--tasks", "[chain]", "--seeds", seeds, "--runs-dir", str(tmp_path / "runs")]
            + ["--keep-dir", str(tmp_path / "checkpoints"), "--docs-dir", str(tmp_path / "docs")]
        )
    assert drawn[-1] == ("curves_ppo_chain_move.png", ["seed 0", "seed 1", "seed 2"])


def test_the_sizes_recipe_kickstarts_from_a_published_clone_through_a_curriculum_of_sizes(tmp_path, monkeypatch):
    """kickstart-sizes: the kickstart config's settings and budget, a curriculum whose stages grow
    the chain, started from the clone of the same seed found under --clone-dir (not --keep-dir)."""
    started = []

    class Finished:  # a training process that writes its final checkpoint at once
        def __init__(self, cmd, *a, **k):
            started.append(cmd)
            run_dir = Path(cmd[cmd.index("--run-dir") + 1])
            (run_dir / "final").mkdir(parents=True)
            (run_dir / "final" / "proteo.json").write_text(json.dumps({"agent_steps": 123, "files": {}}))
            (run_dir / "progress.csv").write_text(
                "seconds,agent_steps,episode/return,episode/success,episode/cycles\n1.0,123,0.5,1.0,90\n"
            )
            self.returncode = 0

        def poll(self):
            return self.returncode

    monkeypatch.setattr(study.subprocess, "Popen", Finished)
    argv = ["--tasks", "[chain]", "--seeds", "[3]", "--recipes", "[kickstart-sizes]", "--minutes", "0"]
    argv += ["--runs-dir", str(tmp_path / "runs"), "--keep-dir", str(tmp_path / "kept"), "--docs-dir", str(tmp_path)]
    study.main(argv + ["--clone-dir", "checkpoints/v7"])
    [cmd] = started
    assert cmd[cmd.index("--init") + 1] == str(Path("checkpoints/v7/chain/imitation_move/seed_3"))
    config = cmd[cmd.index("--config") + 1]
    assert config == "configs/train/kickstart_sizes_chain_move.yaml"
    assert (tmp_path / "kept" / "chain" / "kickstart-sizes_move" / "seed_3" / "proteo.json").is_file()

    from training.machinery.runs import parse_args
    from training.trainers.ppo import Args

    sizes = parse_args(Args, ["--config", config])
    kickstart = parse_args(Args, ["--config", "configs/train/kickstart_chain_move.yaml"])
    assert sizes.curriculum and not kickstart.curriculum
    assert replace(sizes, curriculum=None) == replace(kickstart, curriculum=None)
    stages = [s["n_modules"] for s in sizes.curriculum["stages"]]
    assert stages[0] == kickstart.env["n_modules"] and stages == sorted(stages) and len(set(stages)) == 3

"""Evolution of programs (training/trainers/program_variation.py, training/trainers/evolve.py).

The small world: chain-v1 with 8 modules and 100 cycles, where random programs rarely form
the chain and a few generations of evolution find ones that do.
"""

from __future__ import annotations

import csv
import json
import pickle

import numpy as np
import pytest

import proteo_env
from baselines.program import format_program, load_program
from proteo_env.config import ConfigError
from training import load_controller
from training.machinery.checkpoints import checkpoint_kind
from training.trainers.evolve import main as evolve
from training.trainers.program_variation import ProgramSpace, complexity, crossover, mutate, random_program

SMALL = ["--env", "{n_modules: 8, max_cycles: 100, motion_model: sphere}", "--variations", "[{}, {n_modules: 7}]"]
QUIET = ["--progress-bar", "false", "--tensorboard", "false", "--population", "6", "--offspring", "10"]


@pytest.fixture(scope="module")
def env():
    return proteo_env.make("chain-v1", n_modules=8, max_cycles=100, motion_model="sphere")


def _valid(program, env) -> bool:
    return load_program(format_program(program), env) == program


def test_mutated_and_crossed_programs_stay_valid(env):
    space = ProgramSpace.for_env(env)
    paper = load_program("chain", env)
    paper_space = ProgramSpace.for_program(paper, type(env.task))
    for seed in range(40):
        rng = np.random.default_rng(seed)
        first, second = random_program(space, rng, "chain"), random_program(space, rng, "chain")
        assert _valid(first, env) and _valid(second, env)
        for _ in range(10):
            first = mutate(crossover(first, second, space, rng), space, rng)
            assert _valid(first, env)
            assert all(len(rules) <= space.max_rules for _, rules in first.modes)
        mutant = mutate(paper, paper_space, rng)
        assert _valid(mutant, env) and mutant != paper
    assert complexity(paper) == 7 + 5 + 12  # rules, conditions, actions


def _rows(run_dir) -> list[dict]:
    with open(run_dir / "progress.csv") as f:
        return list(csv.DictReader(f))


def test_evolution_improves_then_loads_as_a_checkpoint(tmp_path):
    final = evolve([*SMALL, *QUIET, "--generations", "6", "--run-dir", str(tmp_path / "run")])
    best = [float(row["fitness/best"]) for row in _rows(tmp_path / "run")]
    assert len(best) == 6 and best[-1] > best[0]
    from training.judging.plots import plot_evolution

    plot_evolution({"evolve": [str(tmp_path / "run" / "progress.csv")] * 2}, tmp_path / "evolution.png")
    assert (tmp_path / "evolution.png").stat().st_size > 0
    meta = json.loads((final / "proteo.json").read_text())
    assert (meta["algorithm"], meta["generation"], meta["seed"]) == ("program-evolution", 6, 0)
    assert checkpoint_kind(meta) == "evolved"
    env, policy = load_controller(final, seed=3)
    assert env.task.name == "chain" and "program" in policy.name
    run = proteo_env.rollout.run_episode(env, policy, seed=3)
    assert run.cycles > 0

    from training.cli import main as cli_main

    out = tmp_path / "eval"
    assert (
        cli_main(
            ["eval", "--checkpoint", str(final), "--tasks", "chain", "--seeds", "1", "--out", str(out), "--no-plots"]
        )
        == 0
    )
    assert "program-evolution" in (out / "results.md").read_text()


def test_resume_gives_the_same_run(tmp_path):
    args = [*SMALL, *QUIET, "--seed-program", "chain", "--episodes-per-variation", "1"]
    whole = evolve([*args, "--generations", "3", "--run-dir", str(tmp_path / "whole")])
    evolve([*args, "--generations", "2", "--run-dir", str(tmp_path / "cut")])
    (tmp_path / "cut" / "final" / "proteo.json").unlink()  # as if interrupted after generation 2
    (tmp_path / "cut" / "final").rename(tmp_path / "stale")
    resumed = evolve([*args, "--generations", "3", "--run-dir", str(tmp_path / "cut")])
    assert (resumed / "program.yaml").read_text() == (whole / "program.yaml").read_text()
    fitness = [[row["fitness/best"] for row in _rows(tmp_path / name)] for name in ("whole", "cut")]
    assert fitness[0] == fitness[1]


def test_the_final_checkpoint_is_the_best_survivor_on_new_worlds(tmp_path):
    """With ``final_episodes_per_variation`` the survivors are re-scored on new worlds after the
    last generation; the checkpoint is the best of them there, with that fitness."""
    from training.machinery.evaluator import run_episodes
    from training.trainers.evolve import generation_seeds, program_episodes

    final = evolve([*SMALL, *QUIET, "--generations", "2", "--final-episodes-per-variation", "2"]
                   + ["--run-dir", str(tmp_path / "run")])  # fmt: skip
    meta = json.loads((final / "proteo.json").read_text())
    survivors = pickle.loads((final / "state.pkl").read_bytes())["population"]
    assert (final / "program.yaml").read_text() == survivors[0]
    final_stream = np.random.SeedSequence(0).spawn(3)[2]
    seeds = generation_seeds(final_stream, 2, 2)
    worlds = [json.dumps({**meta["args"]["env"], **v}, sort_keys=True) for v in meta["args"]["variations"]]
    env = proteo_env.make("chain-v1", **meta["args"]["env"])

    def fitness(text: str) -> float:
        returns = [r.total_reward for r in run_episodes(program_episodes("chain-v1", worlds, [text], seeds), workers=1)]
        return float(np.mean(returns)) - 0.001 * complexity(load_program(text, env))

    scores = [fitness(text) for text in survivors]
    assert scores[0] == pytest.approx(meta["fitness"]) and scores[0] == pytest.approx(max(scores))


@pytest.mark.parametrize(
    "config, named",
    [
        ("popsize: 3", "popsize"),
        ("variations: []", "variations"),
        ("variations: [{n_modules: 0}]", "variations[0]"),
        ("seed_program: no_such_program", "no_such_program"),
        ("fitness: reward", "fitness"),
        ("fitness: progress", "progress"),  # the default task, chain, has no partial credit
    ],
)
def test_bad_config_is_one_error_before_anything_is_written(tmp_path, config, named):
    (tmp_path / "evolve.yaml").write_text(config + "\n")
    with pytest.raises(ConfigError, match=named.replace("[", r"\[").replace("]", r"\]")):
        evolve(["--config", str(tmp_path / "evolve.yaml"), "--run-dir", str(tmp_path / "run")])
    assert not (tmp_path / "run").exists()


def test_the_success_score_ranks_every_success_above_every_failure_and_faster_above_slower():
    from proteo_env.rollout import EpisodeResult
    from training.trainers.evolve import success_score

    fast, slow, failed = (
        EpisodeResult(c, s, r, {}) for c, s, r in ((50, True, 0.5), (299, True, 0.5), (300, False, 9.0))
    )
    env = proteo_env.make("chain-v1", max_cycles=300)
    assert success_score(fast, env) > success_score(slow, env) > success_score(failed, env) == 0.0
    assert 1.0 < success_score(slow, env) and success_score(fast, env) <= 2.0


def test_table_progress_pays_the_legs_that_moved_for_a_shift_not_a_table_that_stands_still():
    """A table that restabilised after every shift by moving its legs (the rules) scores above one
    whose legs stood still after forming (``restabilise_k == 0``), success or not; a failure that
    moved for two shifts scores above a static success's progress."""
    from proteo_env.rollout import EpisodeResult
    from training.trainers.evolve import progress_score, success_score

    env = proteo_env.make("table-v1", max_cycles=600)  # the paper's schedule: three entries
    moved = EpisodeResult(400, True, 1.0, {"restabilise_0": 40.0, "restabilise_1": 30.0, "restabilise_2": 20.0})
    static = EpisodeResult(400, True, 1.0, {"restabilise_0": 40.0, "restabilise_1": 0.0, "restabilise_2": 0.0})
    half = EpisodeResult(600, False, 1.0, {"restabilise_0": 40.0, "restabilise_1": 30.0, "restabilise_2": -1.0})
    assert progress_score(moved, env) == pytest.approx(success_score(moved, env)) == pytest.approx(2 - 400 / 600)
    assert progress_score(static, env) == pytest.approx(1 / 3 + 1 - 400 / 600)
    assert progress_score(half, env) == pytest.approx(2 / 3)
    assert progress_score(half, env) > progress_score(static, env) - (1 - 400 / 600)  # its progress alone


def test_branch_progress_pays_levels_of_a_tree_only():
    """Branch's partial credit is the share of ``target_levels`` a tree reached; a structure with
    cycles or without a real branching point earns nothing; at success it is the success score."""
    from proteo_env.rollout import EpisodeResult
    from training.trainers.evolve import progress_score, success_score

    env = proteo_env.make("branch-v0", n_modules=40, max_cycles=200)  # target_levels 2
    one = EpisodeResult(200, False, 0.0, {"tree": 1.0, "levels": 1.0})
    cyclic = EpisodeResult(200, False, 0.0, {"tree": 0.0, "levels": 2.0})
    chain = EpisodeResult(200, False, 0.0, {"tree": 1.0, "levels": 0.0})
    done = EpisodeResult(120, True, 0.0, {"tree": 1.0, "levels": 2.0})
    assert progress_score(one, env) == 0.5 and progress_score(cyclic, env) == progress_score(chain, env) == 0.0
    assert progress_score(done, env) == pytest.approx(success_score(done, env))


def test_progress_of_real_episodes_ranks_the_rules_above_a_table_that_stands_still():
    """On the benchmark's table worlds the rules' legs move after each shift (progress 1 wherever
    they succeed), while a program evolved under ``fitness: success`` that grows a leg under every
    root and never disbands (benchmark v4, seed 1) earns at most 1/3, success or not."""
    from training.machinery.evaluator import Controller, evaluate
    from training.trainers.evolve import TASK_PROGRESS

    settings = {"board_size": 9, "depth": 2, "n_spares": 16, "schedule": [[0, 8, 2], [150, 2, 8], [300, 5, 5]],
                "stable_window": 50, "motion_model": "minimal", "max_cycles": 600}  # fmt: skip
    params = proteo_env.make("table-v1", **settings).task.params
    static = Controller.from_checkpoint("checkpoints/v4/table/evolve-paper_full/seed_1")
    rules, legs = evaluate("table-v1", [Controller.rules("table"), static], [1000, 1001, 1007], env=settings, workers=1)
    assert all(r.success and TASK_PROGRESS["table"](r.metrics, params) == 1.0 for r in rules)
    assert sum(r.success for r in legs) >= 2
    assert all(TASK_PROGRESS["table"](r.metrics, params) <= 1 / 3 for r in legs)

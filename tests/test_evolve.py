"""Evolution of programs (training/program_variation.py, training/evolve.py).

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
from training.common import checkpoint_kind
from training.evolve import main as evolve
from training.program_variation import ProgramSpace, complexity, crossover, mutate, random_program

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
    from training.plots import plot_evolution

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
    from training.evaluator import run_episodes
    from training.evolve import generation_seeds, program_episodes

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
    ],
)
def test_bad_config_is_one_error_before_anything_is_written(tmp_path, config, named):
    (tmp_path / "evolve.yaml").write_text(config + "\n")
    with pytest.raises(ConfigError, match=named.replace("[", r"\[").replace("]", r"\]")):
        evolve(["--config", str(tmp_path / "evolve.yaml"), "--run-dir", str(tmp_path / "run")])
    assert not (tmp_path / "run").exists()


def test_the_success_score_ranks_every_success_above_every_failure_and_faster_above_slower():
    from proteo_env.rollout import EpisodeResult
    from training.evolve import success_score

    fast, slow, failed = (
        EpisodeResult(c, s, r, {}) for c, s, r in ((50, True, 0.5), (299, True, 0.5), (300, False, 9.0))
    )
    assert success_score(fast, 300) > success_score(slow, 300) > success_score(failed, 300) == 0.0
    assert 1.0 < success_score(slow, 300) and success_score(fast, 300) <= 2.0

"""Nothing judged wrong, nothing lost: the cases a reliability probe of the newer surfaces found,
one table per surface. Each bad input is one clear error naming the field (or flag), the value and
what is allowed, raised before anything is written; the next surface gets a table of its own."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import proteo_env
from proteo_env.config import ConfigError, load_yaml, parse_yaml

ROOT = Path(__file__).resolve().parents[1]
PUBLISHED = ROOT / "checkpoints/v7/chain/ppo_move/seed_0"


# ---------------------------------------------------------------------- the one YAML loader
@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("worlds: {reference: 100}\nworlds: {reference: 200}\n", r"line 2, column 1: found duplicate key 'worlds'"),
        ("a:\n  b: 1\n  b: 2\n", r"line 3, column 3: found duplicate key 'b'"),
        ("base: &b {n_modules: 12}\nheldout: *b\n", r"line 1, column 7: an anchor or alias"),
        ("a: &a [1, 2]\nb: [*a, *a, *a]\n" + "junk: 1\n", r"an anchor or alias"),
        ("[" * 50_000 + "]" * 50_000, r"nested 33 deep; allowed: at most 32 levels"),
        ("- " * 2_000 + "x\n", r"nested 33 deep"),
        ("a: [1, 2\n", r"line 2, column 1 \(expected ',' or ']'"),
    ],
)
def test_the_yaml_loader_refuses_duplicates_aliases_and_deep_nesting_naming_the_line(text, message):
    with pytest.raises(ConfigError, match=r"^file 'x.yaml' is not (allowed|valid YAML).*" + message):
        parse_yaml(text, "file 'x.yaml'")


def test_every_yaml_file_of_the_repository_passes_the_loader():
    files = [p for p in ROOT.glob("**/*.y*ml") if ".venv" not in p.parts and p.suffix in (".yaml", ".yml")]
    assert len(files) > 50
    for file in files:
        load_yaml(file)


def test_a_file_that_is_not_utf8_is_named(tmp_path):
    bad = tmp_path / "prog.yaml"
    bad.write_bytes(b"name: chain\n\xff\xfe\n")
    with pytest.raises(ConfigError, match=r"prog.yaml' is not allowed: byte 12 is not UTF-8 text"):
        load_yaml(bad, "program")
    from baselines import make_policy

    env = proteo_env.make("chain-v1", n_modules=8)
    with pytest.raises(ConfigError, match=r"program .*prog.yaml' is not allowed: byte 12"):
        make_policy("program", env, program=str(bad))


def test_a_protocol_with_a_key_twice_is_refused_not_read_with_the_later_one(tmp_path):
    from training.judging.protocol import load_protocol

    (tmp_path / "configs/benchmark").mkdir(parents=True)
    (tmp_path / "configs/train").symlink_to(ROOT / "configs/train")
    text = (ROOT / "configs/benchmark/v7.yaml").read_text()
    (tmp_path / "configs/benchmark/v7.yaml").write_text(text + "worlds: {first_seed: 5000}\n")
    with pytest.raises(
        ConfigError, match=r"v7.yaml' is not allowed at line \d+, column 1: found duplicate key 'worlds'"
    ):
        load_protocol("v7", tmp_path)


def test_a_training_config_with_a_key_twice_is_refused(tmp_path):
    from training.trainers import ppo

    config = tmp_path / "c.yaml"
    config.write_text("total_steps: 1000\nseed: 1\ntotal_steps: 9\n")
    with pytest.raises(ConfigError, match=r"c.yaml' is not allowed at line 3, column 1: found duplicate key"):
        ppo.main(["--config", str(config), "--run-dir", str(tmp_path / "run")])
    assert not (tmp_path / "run").exists()


# ---------------------------------------------------------------------- environments
@pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf")])
def test_settings_that_are_not_finite_are_refused(value):
    with pytest.raises(ConfigError, match=r"time_penalty=(nan|inf|-inf) is not allowed; allowed: finite numbers"):
        proteo_env.make("chain-v1", time_penalty=value)


def test_the_array_api_refuses_a_step_after_the_episode_ended():
    env = proteo_env.make("chain-v1", n_modules=8, max_cycles=2, control="move")
    env.reset(seed=0)
    stay = np.zeros((8, 1), dtype=np.int64)
    env.step_arrays(stay)
    assert env.step_arrays(stay).truncated[0]
    with pytest.raises(RuntimeError, match="step_arrays\\(\\) called after the episode ended at cycle 2; call reset"):
        env.step_arrays(stay)
    assert env.cycle == 2
    env.reset(seed=0)
    env.step_arrays(stay)  # a new episode steps again


def test_reset_worlds_refuses_a_world_twice():
    batch = proteo_env.make_batched("chain-v1", 2, n_modules=8)
    batch.reset(seed=0)
    with pytest.raises(ValueError, match=r"worlds \[0, 0\] are not allowed: a world listed twice"):
        batch.reset_worlds([0, 0], world_seeds=[1, 2])


def test_step_with_an_array_instead_of_a_dict_says_so():
    env = proteo_env.make("chain-v1", n_modules=12)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"actions of type ndarray are not allowed; allowed: a dict .*step_arrays"):
        env.step(np.zeros((50, 5), int))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [({"n_copies": 2.5}, r"n_copies=2.5 is not allowed"), ({"seed": 1.7}, r"seed=1.7 is not allowed")],
)
def test_the_torchrl_env_refuses_what_it_would_round(kwargs, message):
    pytest.importorskip("torchrl")
    from proteo_env.adapters.torchrl import ProteoTorchRLEnv

    with pytest.raises(ConfigError, match=message):
        ProteoTorchRLEnv("chain-v1", n_modules=8, **kwargs)


def test_the_torchrl_env_refuses_float_actions():
    pytest.importorskip("torchrl")
    import torch

    from proteo_env.adapters.torchrl import ProteoTorchRLEnv

    env = ProteoTorchRLEnv("chain-v1", n_modules=8, control="move", seed=0)
    td = env.reset()
    td.set(("agents", "action"), torch.full((1, 8), float("nan")))
    with pytest.raises(ValueError, match=r"\('agents', 'action'\) of dtype float32 is not allowed; allowed: integers"):
        env.step(td)


# ---------------------------------------------------------------------- programs
@pytest.mark.parametrize(
    ("change", "message"),
    [
        (("parameters:", "parameters:\n  zz: .nan"), r"parameters.zz: nan is not allowed; allowed: a finite number"),
        (("parameters:", "parameters:\n  zz: .inf"), r"parameters.zz: inf is not allowed; allowed: a finite number"),
    ],
)
def test_a_program_with_a_number_that_is_not_finite_is_refused(change, message):
    from baselines import make_policy

    env = proteo_env.make("chain-v1", n_modules=8)
    text = (ROOT / "baselines/programs/chain.yaml").read_text().replace(*change, 1)
    with pytest.raises(ConfigError, match=message):
        make_policy("program", env, program=text)


def test_a_condition_on_nan_is_not_a_number():
    from baselines import make_policy
    from baselines.program import _number

    assert _number("nan") is None and _number("inf") is None and _number("0.5") == 0.5
    env = proteo_env.make("table-v2")
    text = (ROOT / "baselines/programs/table.yaml").read_text()
    assert "load above" in text
    bad = text.replace("load above f_max", "load above nan", 1)
    with pytest.raises(ConfigError, match=r"'load above nan' is not allowed \(unknown number\)"):
        make_policy("program", env, program=bad)


# ---------------------------------------------------------------------- checkpoints
@pytest.mark.parametrize(
    ("task", "message"),
    [("chain-v7", r"task = 'chain-v7' is not allowed; allowed: a registered task id"), (5, r"task = 5 is not allowed")],
)
def test_a_checkpoint_of_a_task_that_is_not_registered_is_refused(tmp_path, task, message):
    pytest.importorskip("torch")
    from training.machinery.checkpoints import CheckpointError, load_controller

    folder = tmp_path / "copy"
    shutil.copytree(PUBLISHED, folder)
    meta = json.loads((folder / "proteo.json").read_text())
    (folder / "proteo.json").write_text(json.dumps({**meta, "task": task}))
    with pytest.raises(CheckpointError, match=message):
        load_controller(str(folder))


# ---------------------------------------------------------------------- the command line
def _cli(argv, capsys) -> tuple[int, str]:
    from training.cli import main

    try:
        code = main(argv)
    except SystemExit as stop:  # argparse's own errors
        code = stop.code
    return code, capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["run", "chain-v1", "--episodes", "0"], "argument --episodes: '0' is not allowed; allowed: an integer >= 1"),
        (["run", "chain-v1", "--episodes", "-2"], "argument --episodes: '-2' is not allowed"),
        (["run", "chain-v1", "--seed", "-3"], "argument --seed: '-3' is not allowed; allowed: an integer >= 0"),
        (["run", "chain-v1", "--max-frames", "0"], "argument --max-frames: '0' is not allowed"),
        (["view", "docs/figures/grasp.npz", "--cycle", "999"], "--cycle 999 without --screenshot is not allowed"),
        (
            ["train", "study", "--parallel", "0", "--tasks", "[chain]"],
            "parallel=0 is not allowed; allowed: an integer >= 1",
        ),
        (["train", "study", "--recipes", "[pop]"], "recipes: 'pop' is not allowed; allowed: ppo, ppo48"),
        (["train", "study", "--seeds", "[-1]"], "seeds: -1 is not allowed; allowed: integers >= 0"),
        (["train", "study", "--minutes", "-1"], "minutes=-1 is not allowed; allowed: a number >= 0.0"),
        (["train", "ppo", "--seed", "-1"], "seed=-1 is not allowed; allowed: an integer from 0 to 2**32 - 1"),
        (
            ["train", "ppo", "--resume", "checkpoints/v7/chain/cma_full/seed_0"],
            "is a 'cma-rules' checkpoint without args.yaml",
        ),
    ],
)
def test_bad_command_lines_get_one_clear_error(argv, named, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    code, err = _cli([*argv, *(["--run-dir", str(tmp_path / "run")] if argv[:2] == ["train", "ppo"] else [])], capsys)
    assert code == 2 and named in err, err
    assert "Traceback" not in err and not (tmp_path / "run").exists()


def test_resuming_a_kept_checkpoint_without_trainer_state_writes_nothing(capsys, tmp_path, monkeypatch):
    pytest.importorskip("torch")
    monkeypatch.chdir(ROOT)
    code, err = _cli(["train", "ppo", "--resume", str(PUBLISHED), "--run-dir", str(tmp_path / "run")], capsys)
    assert code == 2 and "has no trainer.pt (a checkpoint kept for judging holds the policy alone)" in err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    "argv",
    [
        ["eval", "--tasks", "chain", "--seeds", "1"],
        ["eval", "--benchmark", "v7", "--policy", "rules", "--tasks", "chain"],
        ["sweep", "configs/sweeps/chain_cycles.yaml"],
    ],
)
def test_out_naming_a_file_is_refused_before_anything_runs(argv, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    file = tmp_path / "results"
    file.write_text("mine")
    code, err = _cli([*argv, "--out", str(file)], capsys)
    assert code == 2 and f"--out '{file}' is not allowed: it is a file; allowed: a folder" in err
    assert file.read_text() == "mine"


# ---------------------------------------------------------------------- the evaluator and the judge
def test_the_evaluator_names_what_it_refuses():
    from training.machinery.evaluator import Controller, evaluate

    with pytest.raises(ConfigError, match=r"seeds=5 is not allowed; allowed: a non-empty list"):
        evaluate("chain-v1", [Controller.rules("chain")], seeds=5)
    with pytest.raises(ValueError, match=r"parameter 'bogus' is not allowed; allowed: p_seed, p_random"):
        evaluate("chain-v1", [Controller.rules("chain", bogus=3)], seeds=[0], env={"n_modules": 8}, workers=1)


def test_the_journal_is_written_as_each_batch_lands_with_one_worker(tmp_path, monkeypatch):
    """An interrupted run loses at most the batch in flight: one worker journals every batch (it
    journaled once per task, settings and level, so a long group was played again after a resume)."""
    from training.machinery.distributed import Journal
    from training.machinery.evaluator import Controller, Episode, run_episodes, settings_json

    writes = []
    monkeypatch.setattr(Journal, "add_many", lambda self, items: writes.append(len(list(items))))
    journal = Journal(tmp_path / "episodes.jsonl", {"test": 1}, fresh=True, what="test")
    overrides = settings_json({"n_modules": 8, "max_cycles": 20})
    episodes = [Episode("chain-v1", overrides, "full", Controller.rules("chain"), s) for s in range(10)]
    run_episodes(episodes, workers=1, batch_size=4, journal=journal)
    assert sorted(writes) == [3, 3, 4]  # ten episodes in batches of at most four


def test_ctrl_c_says_what_is_kept_instead_of_a_traceback(capsys, monkeypatch):
    from training.judging import judge

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(judge, "main", interrupted)
    code, err = _cli(["eval", "--benchmark", "v7", "--policy", "rules"], capsys)
    assert code == 130 and "interrupted; what finished is kept" in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"momentum": "fast"}, r"momentum='fast' is not allowed; allowed: a finite number \(default 1.0\)"),
        ({"directed": "yes"}, r"directed='yes' is not allowed; allowed: true or false"),
        ({"p_random": float("nan")}, r"p_random=nan is not allowed; allowed: a finite number"),
    ],
)
def test_a_rule_parameter_of_the_wrong_kind_is_refused_when_the_policy_is_built(params, message):
    from baselines import make_policy

    env = proteo_env.make("chain-v1", n_modules=8)
    with pytest.raises(ValueError, match=message):
        make_policy("chain", env, **params)


def test_the_study_outside_the_repository_says_where_to_run_it(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, err = _cli(["train", "study", "--tasks", "[chain]", "--minutes", "0"], capsys)
    assert code == 2 and "has no configs/train, where the recipes' configs are; allowed: running the study" in err
    assert list(tmp_path.iterdir()) == []

"""What a researcher relies on around the benchmark: the citation file, the version, named
envs, clear errors before reset, checkpoint provenance, ``training.load_controller`` and
``proteo train``."""

from __future__ import annotations

import json
import subprocess
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
import yaml

import proteo_env
from proteo_env.config import ConfigError
from proteo_env.env import ProteoEnv
from proteo_env.rollout import run_episode
from training.cli import main as cli_main
from training.machinery.checkpoints import read_meta, write_checkpoint_meta
from training.machinery.registry import ALGORITHMS, TRAINERS, loader

ROOT = Path(__file__).resolve().parents[1]
PUBLISHED = ROOT / "checkpoints" / "v1" / "chain" / "ppo_move" / "seed_0"  # the README's: 12 modules, 300 cycles, move


def pyproject_version() -> str:
    import tomllib

    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]


# ---------------------------------------------------------------------- LICENSE, CITATION.cff
def test_license_is_mit():
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License")
    assert "Copyright (c) 2026 The proteo developers" in text
    assert 'THE SOFTWARE IS PROVIDED "AS IS"' in text


def test_citation_file_names_the_software_and_the_paper():
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    for key in ("cff-version", "message", "title", "authors"):  # required by CFF 1.2.0
        assert cff.get(key), key
    assert cff["cff-version"] == "1.2.0"
    assert cff["title"] == "proteo"
    assert cff["version"] == pyproject_version()
    assert cff["license"] == "MIT"
    assert cff["authors"] == [{"name": "The proteo developers"}]
    papers = [r for r in cff.get("references", []) if r.get("type") == "conference-paper"]
    assert len(papers) == 1
    paper = papers[0]
    assert paper["title"] == "Multiagent Control of Self-reconfigurable Robots"
    assert [a["family-names"] for a in paper["authors"]] == ["Bojinov", "Casal", "Hogg"]
    assert all(a.get("given-names") for a in paper["authors"])
    assert paper["year"] == 2000
    assert "ICMAS 2000" in paper["collection-title"]


# ---------------------------------------------------------------------- proteo --version
def test_proteo_version_prints_the_distribution_version(capsys):
    with pytest.raises(SystemExit) as done:
        cli_main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out.strip() == f"proteo {metadata.version('proteo-env')}"
    assert metadata.version("proteo-env") == pyproject_version()


# ---------------------------------------------------------------------- the env's name and errors
def test_the_env_name_names_the_task_and_version():
    chain = proteo_env.make("chain-v1", n_modules=8, max_cycles=10)
    grasp = proteo_env.make("grasp-v0", max_cycles=10)
    assert chain.metadata["name"] == "proteo_chain_v1"
    assert grasp.metadata["name"] == "proteo_grasp_v0"
    assert proteo_env.make("chain-v0", n_modules=8).metadata["name"] == "proteo_chain_v0"
    # each env has its own dict; the rest of the metadata is the class's
    assert ProteoEnv.metadata["name"] == "proteo"
    for env in (chain, grasp):
        assert {k: v for k, v in env.metadata.items() if k != "name"} == {
            k: v for k, v in ProteoEnv.metadata.items() if k != "name"
        }


def test_the_name_does_not_change_the_trajectory():
    def trajectory(env):
        env.reset(seed=3)
        states, rng = [env.state()], np.random.default_rng(0)
        for _ in range(15):
            if not env.agents:
                break
            env.step({a: rng.integers(0, env.action_space(a).nvec) for a in env.agents})
            states.append(env.state())
        return np.stack(states)

    named = proteo_env.make("chain-v1", n_modules=8, max_cycles=20)
    renamed = proteo_env.make("chain-v1", n_modules=8, max_cycles=20)
    renamed.metadata = {**renamed.metadata, "name": "proteo_v0"}  # the name every env had before
    np.testing.assert_array_equal(trajectory(named), trajectory(renamed))


@pytest.mark.parametrize(
    "call",
    [
        lambda env: env.state(),
        lambda env: env.step({}),
        lambda env: env.step({a: 0 for a in env.possible_agents}),
        lambda env: env.observe_arrays(),
        lambda env: env.step_arrays(np.zeros((len(env.possible_agents), len(env.control_fields)), np.int64)),
        lambda env: env.world,
        lambda env: env.render(),
    ],
    ids=["state", "step-empty", "step", "observe_arrays", "step_arrays", "world", "render"],
)
def test_before_reset_every_method_says_to_call_reset(call):
    env = proteo_env.make("chain-v1", n_modules=8, max_cycles=10, control="move", render_mode="ansi")
    with pytest.raises(RuntimeError, match=r"^no world yet; call reset\(\) first$"):
        call(env)
    env.reset(seed=0)
    assert env.state().shape == env.state_space.shape


# ---------------------------------------------------------------------- checkpoint provenance
def git_head(cwd) -> str | None:
    try:
        done = subprocess.run(["git", "rev-parse", "HEAD"], cwd=cwd, capture_output=True, text=True, check=False)
    except OSError:
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def write_meta(folder: Path) -> dict:
    write_checkpoint_meta(
        folder,
        algorithm="program-evolution",
        task="chain-v1",
        env_overrides={"n_modules": 8},
        encoder_spec=None,
        nvec=[13],
        agent_steps=10,
        seed=0,
        extra={"control": "full"},
    )
    return read_meta(folder)


def test_checkpoints_record_the_version_and_the_commit(tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    meta = write_meta(tmp_path / "here")
    assert meta["proteo_version"] == metadata.version("proteo-env")
    assert meta["commit"] == git_head(ROOT)  # None when this checkout is not a git repository

    outside = tmp_path / "not_a_repo"
    outside.mkdir()
    monkeypatch.chdir(outside)
    monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path))  # git does not look above tmp_path
    assert write_meta(tmp_path / "outside")["commit"] is None

    monkeypatch.chdir(ROOT)
    monkeypatch.setenv("PATH", str(tmp_path / "no_programs_here"))  # no git at all
    meta = write_meta(tmp_path / "no_git")
    assert meta["commit"] is None and meta["proteo_version"] == metadata.version("proteo-env")


def test_checkpoints_without_the_provenance_keys_still_load(tmp_path):
    old = tmp_path / "old"
    old.mkdir()
    for file in PUBLISHED.iterdir():
        (old / file.name).write_bytes(file.read_bytes())
    saved = json.loads((PUBLISHED / "proteo.json").read_text())
    for key in ("proteo_version", "commit"):  # as written before they existed
        saved.pop(key, None)
    (old / "proteo.json").write_text(json.dumps(saved))
    env, policy = _load_controller()(old)
    assert policy is not None and env.task.task_id() == saved["task"]


# ---------------------------------------------------------------------- load_controller
def _load_controller():
    pytest.importorskip("torch")
    from training import load_controller

    return load_controller


def test_a_published_checkpoint_runs_an_episode_to_the_end():
    load_controller = _load_controller()
    meta = json.loads((PUBLISHED / "proteo.json").read_text())
    env, policy = load_controller(str(PUBLISHED))
    assert env.task.task_id() == meta["task"] and env.control == meta["control"]
    assert env.engine is None  # not reset yet: the episode's seed is the caller's
    result = run_episode(env, policy, seed=0)
    assert not env.agents
    assert result.success or result.cycles == meta["env"]["max_cycles"]
    assert 0 < result.cycles <= meta["env"]["max_cycles"]


def test_overrides_apply_over_the_checkpoints_settings():
    env, _ = _load_controller()(PUBLISHED, max_cycles=7)
    assert env.max_cycles == 7
    assert env.config.physics.motion_model == "sphere"  # the checkpoint's own setting


def test_the_rules_and_the_random_policy_by_name():
    load_controller = _load_controller()
    env, policy = load_controller("rules:chain-v1", n_modules=12, max_cycles=300)
    assert env.task.task_id() == "chain-v1" and policy.name == env.task.default_policy
    result = run_episode(env, policy, seed=0)
    assert result.success and not env.agents

    env, policy = load_controller("random:grasp-v0", seed=1, max_cycles=5)
    assert policy.name == "random" and env.task.task_id() == "grasp-v0"
    assert run_episode(env, policy, seed=0).cycles == 5


@pytest.mark.parametrize("level", ["move", "full"])
def test_the_random_policy_draws_what_uniform_choices_over_its_fields_and_legal_moves_draw(level):
    """The random policy's actions, cycle by cycle, are those of its first form: per agent
    ``integers(0, nvec)`` then ``choice(legal moves)`` from one generator (its published episodes
    stay as they were)."""
    from baselines import make_policy

    env = proteo_env.make("chain-v1", n_modules=20, max_cycles=40, control=level)
    policy = make_policy("random", env, seed=7)
    reference = np.random.default_rng(7)
    observations, _ = env.reset(seed=3)
    policy.reset(7)
    while env.agents:
        actions = policy.act(observations)
        for agent, obs in observations.items():
            expected = reference.integers(0, policy.nvec)
            expected[env.action_layout.move] = reference.choice(obs["action_mask"].nonzero()[0])
            assert np.array_equal(actions[agent], expected), (agent, env.cycle)
        observations, *_ = env.step(actions)
    assert env.cycle == 40


@pytest.mark.parametrize(
    "source, named",
    [
        ("no/such/checkpoint", "'no/such/checkpoint'"),
        (Path("no/such/checkpoint"), "'no/such/checkpoint'"),
        ("rules:nope-v0", "'nope-v0'"),
        ("nope:chain-v1", "'nope:chain-v1'"),
        ("rules:", "'rules:'"),
        (3, "3"),
    ],
)
def test_bad_sources_get_one_clear_error(source, named):
    with pytest.raises(ConfigError, match="allowed") as err:
        _load_controller()(source)
    assert named in str(err.value)


# ---------------------------------------------------------------------- proteo train
def test_proteo_train_runs_the_trainers_with_their_flags(capsys):
    import importlib

    for trainer in TRAINERS:  # every name is a module with a main(argv)
        assert callable(importlib.import_module(trainer.module).main)
    with pytest.raises(SystemExit) as done:
        cli_main(["train", "ppo", "--help"])
    assert done.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: proteo train ppo") and "--total-steps" in out
    # each option's docstring reaches the user, with its type and default
    assert (
        " ".join(out.split()).count(
            "Agent-steps (module-cycles) to train for, counted across all worlds. (int, default: 10000000)"
        )
        == 1
    )


def test_every_trainer_option_has_a_docstring_for_help():
    import dataclasses
    import importlib

    from training.machinery.runs import field_docs

    missing = []
    for trainer in TRAINERS:  # as proteo train imports them
        args = importlib.import_module(trainer.module).Args
        docs = field_docs(args)
        missing += [f"{trainer.module} {f.name}" for f in dataclasses.fields(args) if not docs.get(f.name)]
    assert not missing, "Args fields without a docstring (their --help says nothing): " + ", ".join(missing)


def test_every_checkpoint_algorithm_has_one_trainer_and_a_loader():
    for algorithm in ALGORITHMS:
        assert callable(loader(algorithm))
        assert sum(algorithm in t.algorithms for t in TRAINERS) == 1
    for trainer in TRAINERS:
        assert bool(trainer.algorithms) == bool(trainer.loader)


def test_proteo_train_passes_bad_flags_to_the_trainer_and_refuses_unknown_names(capsys):
    assert cli_main(["train", "ppo", "--total-steps", "-5"]) == 2
    assert "total_steps=-5" in capsys.readouterr().err
    assert cli_main(["train", "nope", "--config", "x.yaml"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("proteo: error: trainer 'nope' is not allowed; allowed: ppo, imitate, cma_es")
    assert len(err.splitlines()) == 1


def test_proteo_train_ppo_writes_a_checkpoint_with_its_provenance(tmp_path, monkeypatch, capsys):
    pytest.importorskip("torch")
    monkeypatch.chdir(ROOT)
    run_dir = tmp_path / "run"
    flags = ["--task", "chain-v1", "--control", "move", "--env", "{n_modules: 6, max_cycles: 20}"]
    flags += ["--n-envs", "2", "--n-steps", "8", "--minibatch-size", "32"]
    flags += ["--total-steps", "96", "--checkpoint-every", "96", "--run-dir", str(run_dir)]
    flags += ["--tensorboard", "false", "--progress-bar", "false"]
    assert cli_main(["train", "ppo", *flags]) == 0
    meta = read_meta(run_dir / "final")
    assert meta["task"] == "chain-v1" and meta["control"] == "move"
    assert meta["proteo_version"] == metadata.version("proteo-env")
    assert meta["commit"] == git_head(ROOT)
    env, policy = _load_controller()(run_dir, max_cycles=5)
    assert run_episode(env, policy, seed=0).cycles <= 5

"""BenchMARL on proteo (proteo_env/adapters/benchmarl.py): its MAPPO and IPPO train on a tiny
world, the policy's moves are legal, evaluation is stochastic by default; a BenchMARL run enters
the benchmark from its checkpoints (examples/benchmarl/train.py, format: benchmarl).

BenchMARL lives in its own environment (make test-benchmarl, which CI runs): there
``PROTEO_NEEDS=benchmarl`` makes a missing BenchMARL an error; in the main environment these
tests skip.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

if os.environ.get("PROTEO_NEEDS") == "benchmarl":
    import benchmarl  # noqa: F401  (an error, not a skip, where BenchMARL is required)
else:
    pytest.importorskip("benchmarl")

import torch  # noqa: E402
from benchmarl.experiment import Experiment  # noqa: E402

import proteo_env  # noqa: E402
from proteo_env.adapters.benchmarl import ProteoTask, experiment, experiment_config  # noqa: E402
from training.machinery.entrants import EntrantError, load_network  # noqa: E402

TINY = {"n_modules": 6, "max_cycles": 16}


def _experiment(tmp_path, algorithm: str):
    return experiment(
        ProteoTask.CHAIN_V1,
        algorithm,
        settings=TINY,
        max_n_iters=2,
        on_policy_collected_frames_per_batch=64,
        on_policy_n_envs_per_worker=2,
        on_policy_minibatch_size=32,
        on_policy_n_minibatch_iters=2,
        evaluation_interval=64,
        evaluation_episodes=2,
        loggers=[],
        render=False,
        save_folder=str(tmp_path),
    )


def test_every_registered_task_is_a_member_with_its_settings_over_the_move_level():
    assert {m.name for m in ProteoTask} == {t.upper().replace("-", "_") for t in proteo_env.TASKS}
    task = ProteoTask.GRASP_V0.get_task({"n_modules": 20})
    assert task.config == {"control": "move", "n_modules": 20}
    env = task.get_env_fun(num_envs=3, continuous_actions=False, seed=0, device="cpu")()
    assert task.max_steps(env) == proteo_env.make("grasp-v0", n_modules=20).max_cycles
    assert task.group_map(env) == {"agents": [f"module_{i}" for i in range(20)]}
    assert task.action_spec(env)["agents", "action"].shape == (20,)  # one Categorical(13) per module
    assert task.action_mask_spec(env)["agents", "action_mask"].shape == (20, 13)
    assert experiment_config().evaluation_deterministic_actions is False
    with pytest.raises(ValueError, match="algorithm='ppo' is not allowed; allowed: .*mappo"):
        experiment(ProteoTask.CHAIN_V1, "ppo")
    with pytest.raises(ValueError, match="max_frames=5 is not allowed"):
        experiment_config(max_frames=5)


@pytest.mark.parametrize("algorithm", ["mappo", "ippo"])
def test_benchmarl_trains_on_proteo_and_its_policy_moves_legally(tmp_path, algorithm):
    experiment = _experiment(tmp_path, algorithm)
    experiment.run()
    assert experiment.n_iters_performed == 2 and experiment.total_frames == 128
    rollout = experiment.test_env.rollout(TINY["max_cycles"], policy=experiment.policy, break_when_any_done=False)
    actions, masks = rollout["agents", "action"], rollout["agents", "action_mask"]
    assert masks.gather(-1, actions.unsqueeze(-1)).all()  # every sampled move was allowed


ROOT = Path(__file__).resolve().parents[1]


def _train_example(out: Path, *seeds: int) -> dict:
    argv = [sys.executable, str(ROOT / "examples/benchmarl/train.py"), "--algorithm", "mappo", "--seeds",
            *map(str, seeds), "--agent-steps", "1000", "--out", str(out)]  # fmt: skip
    done = subprocess.run(argv, cwd=out.parent, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return yaml.safe_load((out / "entrant.yaml").read_text())


def test_a_benchmarl_run_enters_the_benchmark_as_benchmarl_saves_it(tmp_path):
    """The example trains two seeds (one batch each), writes the entrant.yaml, and the judge plays
    BenchMARL's own checkpoints: the logits it uses are those of the policy BenchMARL restores."""
    out = tmp_path / "entrant"
    entry = _train_example(out, 0, 1)
    assert entry["format"] == "benchmarl" and sorted(entry["seeds"]) == [0, 1]
    assert entry["budget"]["agent_steps"] == 2048 * 12  # one batch of 64 worlds x 32 cycles x 12 modules
    checkpoint = out / entry["seeds"][0]
    logits_fn = load_network(checkpoint, "benchmarl")
    restored = Experiment.reload_from_file(str(checkpoint), experiment_patch={"save_folder": str(tmp_path)})
    td = restored.test_env.reset()
    observation = td["agents", "observation"]
    with torch.no_grad():
        expected = restored.policy(td)["agents", "logits"]
    assert np.allclose(logits_fn(observation.reshape(-1, observation.shape[-1]).numpy()), expected.reshape(-1, 13))

    judged = tmp_path / "judged"
    argv = [str(Path(sys.executable).parent / "proteo"), "eval", "--benchmark", "v7", "--entrant", str(out),
            "--worlds-cap", "2", "--out", str(judged)]  # fmt: skip
    done = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, env={**os.environ, "PROTEO_WORKERS": "1"})
    assert done.returncode == 0, done.stderr[-3000:]
    rows = json.loads((judged / "benchmark.json").read_text())["rows"]
    assert [r["split"] for r in rows] == ["heldout", "larger"]  # 24 modules: the shared actor runs at any size
    assert all(r["training"] == "declared" and len(r["runs"]) == 2 and r["level"] == "move" for r in rows)


def test_a_benchmarl_checkpoint_that_is_damaged_or_out_of_place_is_refused(tmp_path):
    out = tmp_path / "entrant"
    checkpoint = out / _train_example(out, 0)["seeds"][0]
    moved = tmp_path / "checkpoint.pt"
    moved.write_bytes(checkpoint.read_bytes())
    with pytest.raises(EntrantError, match="no config.pkl .* allowed: a checkpoint where BenchMARL saves it"):
        load_network(moved, "benchmarl")
    data = bytearray(checkpoint.read_bytes())
    checkpoint.write_bytes(bytes(data[: len(data) // 2]))
    with pytest.raises(EntrantError, match="is not a BenchMARL checkpoint .* allowed: a checkpoint_N.pt"):
        load_network(checkpoint, "benchmarl")

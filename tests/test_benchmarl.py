"""BenchMARL on proteo (proteo_env/adapters/benchmarl.py): its MAPPO and IPPO train on a tiny
world, the policy's moves are legal, evaluation is stochastic by default.

BenchMARL lives in its own environment (make test-benchmarl, which CI runs): there
``PROTEO_NEEDS=benchmarl`` makes a missing BenchMARL an error; in the main environment these
tests skip.
"""

from __future__ import annotations

import os

import pytest

if os.environ.get("PROTEO_NEEDS") == "benchmarl":
    import benchmarl  # noqa: F401  (an error, not a skip, where BenchMARL is required)
else:
    pytest.importorskip("benchmarl")

import proteo_env  # noqa: E402
from proteo_env.adapters.benchmarl import ProteoTask, experiment, experiment_config  # noqa: E402

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

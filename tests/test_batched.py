"""The batched engine: B worlds stepped together follow exactly their single-world trajectories."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import proteo_env
from proteo_env.spaces import ObservationBuffers

from conftest import SMALL_OVERRIDES

N_ENVS = 3


def _random_actions(layout, masks: np.ndarray, rng) -> np.ndarray:
    """``(rows, L)`` actions: every field uniform, the move uniform among legal ones half the time."""
    actions = rng.integers(0, layout.nvec, size=(len(masks), layout.length))
    legal = np.argmax(masks * rng.random(masks.shape), axis=1)
    use_legal = rng.random(len(masks)) < 0.5
    actions[use_legal, layout.move] = legal[use_legal]
    return actions


@pytest.mark.parametrize("task_id", sorted(proteo_env.TASKS))
@pytest.mark.parametrize("motion_model", ["sphere", "minimal"])
def test_batch_matches_single_envs(task_id, motion_model):
    overrides = {**SMALL_OVERRIDES.get(proteo_env.TASKS[task_id].name, {}), "motion_model": motion_model}
    batched = proteo_env.make_batched(task_id, N_ENVS, **overrides)
    singles = [proteo_env.make(task_id, **overrides) for _ in range(N_ENVS)]
    obs = batched.reset(seed=7)
    for b, env in enumerate(singles):
        env.reset(seed=7 + b)
    a, lay, rng = batched.n_agents, batched.action_layout, np.random.default_rng(0)
    for _ in range(60):
        actions = _random_actions(lay, obs.action_mask, rng).reshape(N_ENVS, a, lay.length)
        terms = batched.step_arrays(actions)
        obs = batched.observe_arrays()
        for b, env in enumerate(singles):
            assert env.step_arrays(actions[b]) == terms[b]
            single_obs = env.observe_arrays()
            for field in ObservationBuffers.FIELDS:
                np.testing.assert_array_equal(getattr(obs, field)[b * a:(b + 1) * a], getattr(single_obs, field),
                                              err_msg=field)
            np.testing.assert_array_equal(batched.last_moved[b], env.last_moved)
            for key, value in env.engine.snapshot().items():
                np.testing.assert_array_equal(batched.worlds[b].snapshot()[key], value, err_msg=key)
        assert batched.metrics() == [env.batch.metrics()[0] for env in singles]


def test_batch_survives_pickling():
    batched = proteo_env.make_batched("sandbox-v0", N_ENVS, n_modules=15)
    obs = batched.reset(seed=1)
    twin = pickle.loads(pickle.dumps(batched))
    rng = np.random.default_rng(3)
    for _ in range(20):
        actions = _random_actions(batched.action_layout, obs.action_mask, rng)
        actions = actions.reshape(N_ENVS, batched.n_agents, -1)
        batched.step_arrays(actions)
        twin.step_arrays(actions)
        obs = batched.observe_arrays()
    for world, other in zip(batched.worlds, twin.worlds):
        for key, value in world.snapshot().items():
            np.testing.assert_array_equal(other.snapshot()[key], value, err_msg=key)


def test_bad_batch_names_world_agent_and_field():
    batched = proteo_env.make_batched("sandbox-v0", 2, n_modules=10)
    batched.reset(seed=0)
    actions = np.zeros((2, batched.n_agents, batched.action_layout.length), dtype=np.int64)
    actions[1, 4, 0] = 13
    before = [w.snapshot() for w in batched.worlds]
    with pytest.raises(ValueError, match=r"action of world 1, module_4: move=13 is not allowed; allowed: 0\.\.12"):
        batched.step_arrays(actions)
    with pytest.raises(ValueError, match=r"actions shape \(1, 10, 5\) is not allowed; allowed: \(2, 10, 5\)"):
        batched.step_arrays(actions[:1])
    for world, snap in zip(batched.worlds, before):
        for key, value in world.snapshot().items():
            np.testing.assert_array_equal(value, snap[key])
    with pytest.raises(proteo_env.ConfigError, match=r"n_envs=0 is not allowed"):
        proteo_env.make_batched("sandbox-v0", 0)

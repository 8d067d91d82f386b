"""Same seed and same actions give the same trajectory, bit for bit, over many cycles.

PettingZoo 1.27's ``parallel_seed_test`` compares one step only, so this is our own test:
two environments, the same seed, the same action sequences (drawn from a seeded numpy
generator with the action mask, plus some unmasked moves so that denials and the random move
order matter), compared at every cycle: observations (values and dtypes), rewards,
terminations, truncations, infos, the global state and the engine's full mutable state.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import task_params

import proteo_env

TASK_IDS = task_params()
MOTION_MODELS = list(proteo_env.MOTION_MODELS)
N_CYCLES = 200


def _assert_obs_equal(obs_a, obs_b):
    assert obs_a.keys() == obs_b.keys()
    for agent in obs_a:
        assert obs_a[agent].keys() == obs_b[agent].keys()
        for key, value in obs_a[agent].items():
            other = obs_b[agent][key]
            assert value.dtype == other.dtype and value.shape == other.shape, (agent, key)
            assert value.tobytes() == other.tobytes(), f"{agent} {key} differs"


def _assert_engine_equal(env_a, env_b):
    snap_a, snap_b = env_a.engine.snapshot(), env_b.engine.snapshot()
    assert snap_a.keys() == snap_b.keys()
    for key in snap_a:
        assert snap_a[key].tobytes() == snap_b[key].tobytes(), f"engine {key} differs"
    assert env_a.state().tobytes() == env_b.state().tobytes()
    assert env_a.world.positions.tobytes() == env_b.world.positions.tobytes()
    assert env_a.cycle == env_b.cycle


def _assert_infos_equal(infos_a, infos_b):
    assert infos_a.keys() == infos_b.keys()
    for agent in infos_a:
        a, b = infos_a[agent], infos_b[agent]
        assert a.keys() == b.keys()
        for key in a:
            assert type(a[key]) is type(b[key]), key
            # bit-for-bit: floats must be identical, NaN included
            assert np.asarray(a[key]).tobytes() == np.asarray(b[key]).tobytes(), f"info {key} differs"


def _run_pair(env_a, env_b, seed, action_seed, n_cycles, actions_from):
    """Run both envs in lockstep, comparing everything at every cycle; return env_a's trajectory."""
    obs_a, infos_a = env_a.reset(seed=seed)
    obs_b, infos_b = env_b.reset(seed=seed)
    _assert_obs_equal(obs_a, obs_b)
    _assert_infos_equal(infos_a, infos_b)
    _assert_engine_equal(env_a, env_b)
    rng = np.random.default_rng(action_seed)
    trajectory = [env_a.engine.positions.copy()]
    for _ in range(n_cycles):
        if not env_a.agents:
            break
        assert env_a.agents == env_b.agents
        actions = actions_from(env_a, obs_a, rng, p_unmasked=0.25)
        out_a = env_a.step({a: v.copy() for a, v in actions.items()})
        out_b = env_b.step({a: v.copy() for a, v in actions.items()})
        obs_a, obs_b = out_a[0], out_b[0]
        _assert_obs_equal(obs_a, obs_b)
        for ra, rb in ((out_a[1], out_b[1]),):
            assert ra.keys() == rb.keys()
            assert all(np.float64(ra[k]).tobytes() == np.float64(rb[k]).tobytes() for k in ra)
        assert out_a[2] == out_b[2] and out_a[3] == out_b[3]
        _assert_infos_equal(out_a[4], out_b[4])
        _assert_engine_equal(env_a, env_b)
        trajectory.append(env_a.engine.positions.copy())
    assert env_a.agents == env_b.agents
    return trajectory


@pytest.mark.parametrize("motion_model", MOTION_MODELS)
@pytest.mark.parametrize("task_id", TASK_IDS)
def test_same_seed_same_trajectory(task_id, motion_model, make_small, actions_from):
    env_a = make_small(task_id, motion_model=motion_model, max_cycles=N_CYCLES)
    env_b = make_small(task_id, motion_model=motion_model, max_cycles=N_CYCLES)
    trajectory = _run_pair(env_a, env_b, seed=123, action_seed=7, n_cycles=N_CYCLES, actions_from=actions_from)
    if len(trajectory) == N_CYCLES + 1:
        assert env_a.agents == [], "the episode is truncated at max_cycles"


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_same_seed_same_trajectory_other_physics(task_id, make_small, actions_from):
    """Faster scents, exact scents and no connectivity rule are deterministic too."""
    for extra in ({"scent_sweeps": 3}, {"exact_scent": True}, {"keep_connected": False}):
        env_a = make_small(task_id, max_cycles=60, **extra)
        env_b = make_small(task_id, max_cycles=60, **extra)
        _run_pair(env_a, env_b, seed=5, action_seed=9, n_cycles=60, actions_from=actions_from)


def test_different_seed_different_trajectory(make_small, actions_from):
    """The sandbox's random blob layout and move order depend on the seed."""
    trajectories = []
    for seed in (0, 1):
        env_a = make_small("sandbox-v0", layout="blob", max_cycles=50)
        env_b = make_small("sandbox-v0", layout="blob", max_cycles=50)
        trajectories.append(_run_pair(env_a, env_b, seed=seed, action_seed=3, n_cycles=50, actions_from=actions_from))
    assert not np.array_equal(trajectories[0][0], trajectories[1][0]), "start blobs differ"
    assert any(not np.array_equal(a, b) for a, b in zip(*trajectories))


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_different_seed_different_move_order(task_id, make_small):
    """The engine's move-order generator is seeded from the episode seed."""
    env = make_small(task_id)
    env.reset(seed=0)
    state_0 = env.engine.snapshot()["rng_state"].copy()
    env.reset(seed=1)
    assert env.engine.snapshot()["rng_state"].tobytes() != state_0.tobytes()


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_reset_same_seed_twice_same_start_and_trajectory(task_id, make_small, actions_from):
    env = make_small(task_id, max_cycles=500)
    runs = []
    for _ in range(2):
        obs, infos = env.reset(seed=42)
        start = (obs, infos, env.engine.snapshot(), env.state().copy())
        rng = np.random.default_rng(8)
        history = []
        for _ in range(30):
            if not env.agents:
                break
            out = env.step(actions_from(env, obs, rng, p_unmasked=0.25))
            obs = out[0]
            history.append((out, env.engine.snapshot()))
        runs.append((start, history))
    (start_a, hist_a), (start_b, hist_b) = runs
    _assert_obs_equal(start_a[0], start_b[0])
    _assert_infos_equal(start_a[1], start_b[1])
    for key in start_a[2]:
        assert start_a[2][key].tobytes() == start_b[2][key].tobytes(), key
    assert start_a[3].tobytes() == start_b[3].tobytes()
    assert len(hist_a) == len(hist_b)
    for (out_a, snap_a), (out_b, snap_b) in zip(hist_a, hist_b):
        _assert_obs_equal(out_a[0], out_b[0])
        assert out_a[1:4] == out_b[1:4]
        _assert_infos_equal(out_a[4], out_b[4])
        for key in snap_a:
            assert snap_a[key].tobytes() == snap_b[key].tobytes(), key


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_reset_does_not_depend_on_history(task_id, make_small, actions_from):
    """A fresh env and a used env reset with the same seed start the same."""
    used = make_small(task_id)
    obs, _ = used.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(10):
        obs, *_ = used.step(actions_from(used, obs, rng))
    obs_used, _ = used.reset(seed=99)
    fresh = make_small(task_id)
    obs_fresh, _ = fresh.reset(seed=99)
    _assert_obs_equal(obs_used, obs_fresh)
    _assert_engine_equal(used, fresh)


def test_every_tasks_recorded_episodes_are_the_published_ones():
    """The rules' and random episodes of every task and version, recorded and hashed
    (benchmarks/episode_hashes.py), are the ones docs/speed/episode_hashes.json holds: an
    engine or task change that alters any trajectory fails here until the file is remade."""
    import json
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root / "benchmarks"))
    try:
        from episode_hashes import task_hashes
    finally:
        sys.path.remove(str(root / "benchmarks"))
    published = json.loads((root / "docs/speed/episode_hashes.json").read_text())
    assert set(published["hashes"]) == set(proteo_env.registry.TASKS)
    for task_id, expected in published["hashes"].items():
        assert task_hashes(task_id, published["seeds"], published["cycles"]) == expected, task_id

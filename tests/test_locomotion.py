"""The locomotion task and its hand-coded policy: the robot advances (more than the random
policy) and most robots cross the default step, every move is legal and keeps the robot connected, success means the whole robot is
beyond the finish line, bad parameters get one clear error, and the compiled rollout is the
policy driven through the environment, cycle for cycle."""

from __future__ import annotations

import numpy as np
import pytest
from test_compiled_rollout import assert_same_trajectory, drive

import proteo_env
from baselines import make_policy
from baselines.compiled import compiled_rollout
from baselines.locomotion import LocomotionPolicy
from proteo_env.config import ConfigError

SMALL = dict(n_modules=16, step_height=0, distance=2, max_cycles=600)


def centroid_advance(env, policy, cycles):
    """Centroid advance along ``+x`` after ``cycles`` cycles of ``policy`` through the env's dict API."""
    start = env.world.positions[:, 0].mean()
    observations = env.observe_arrays().per_agent(env.possible_agents)
    for _ in range(cycles):
        observations, _, terminated, truncated, _ = env.step(policy.act(observations))
        if any(terminated.values()) or any(truncated.values()):
            break
    return env.world.positions[:, 0].mean() - start


def test_the_robot_advances_more_than_the_random_policy():
    hand, rand = [], []
    for seed in range(4):
        for name, out in (("locomotion", hand), ("random", rand)):
            env = proteo_env.make("locomotion-v0", **SMALL)
            env.reset(seed=seed)
            out.append(centroid_advance(env, make_policy(name, env, seed=seed), 150))
    assert np.mean(hand) > 3.0, hand
    assert np.mean(hand) > np.mean(rand) + 2.0, (hand, rand)


@pytest.mark.slow
def test_most_robots_cross_the_step():
    """The default task (20 modules, a step 2 high, ``minimal``): 8 of 12 robots (seeds 200..211)
    cross in 3,000 cycles; without the no-strands preference (``contacts=0``) 5 of 12."""
    wins = 0
    for seed in range(200, 212):
        env = proteo_env.make("locomotion-v0", max_cycles=3000)
        env.reset(seed=seed)
        wins += compiled_rollout(env, LocomotionPolicy.for_env(env, seed=seed)).success
    assert wins > 6, wins


def assert_legal_connected_cycles(env, policy, cycles):
    """Run ``cycles`` cycles of ``policy``: every requested move is in the action mask, every move
    is one face step, the robot stays one piece, and no module enters a solid site."""
    solid = {tuple(s) for s in env.engine.solid_sites}
    for _ in range(cycles):
        buffers = env.observe_arrays()
        actions = policy.act_arrays(buffers)
        moves = actions[:, 0]
        assert buffers.action_mask[np.arange(len(moves)), moves].all()
        before = env.world.positions
        env.step_arrays(actions)
        after = env.world.positions
        steps = np.abs(after - before)
        moved = steps.any(axis=1)
        assert ((steps[moved].sum(axis=1) == 2) & (steps[moved].max(axis=1) == 1)).all()  # one face step
        assert env.engine.n_components() == 1
        assert (after[:, 2] >= 0).all() and not solid & {tuple(p) for p in after}


@pytest.mark.parametrize("overrides", [{}, {"step_height": 2}, {"tunnel_height": 2}])
def test_moves_are_legal_and_the_robot_stays_connected(overrides):
    env = proteo_env.make("locomotion-v0", **{**SMALL, **overrides})
    env.reset(seed=1)
    assert_legal_connected_cycles(env, LocomotionPolicy.for_env(env, seed=1), 120)


@pytest.mark.parametrize("overrides", [{}, {"step_height": 2}])
def test_success_means_the_whole_robot_is_beyond_the_line(overrides):
    env = proteo_env.make("locomotion-v0", **{**SMALL, **overrides})
    for seed in range(6):
        env.reset(seed=seed)
        assert not env.task.success(env.engine)
        policy = LocomotionPolicy.for_env(env, seed=seed)
        positions, _, success = drive(env, policy, SMALL["max_cycles"])
        beyond = positions[:, :, 0] >= env.task.finish
        first = int(np.argmax(beyond.all(axis=1))) if beyond.all(axis=1).any() else None
        assert success == (first is not None)
        if success:
            assert first == len(positions) - 1  # success ends the drive on the first cycle it holds
            assert (positions[-1][:, 2] >= overrides.get("step_height", 0)).all()  # on top of the step
            assert env.task.metrics(env.engine)["beyond"] == 1.0
            break
    else:
        pytest.fail(f"no success in 6 seeds with {overrides}")


@pytest.mark.parametrize(
    "field, value, allowed",
    [
        ("step_height", -1, "an integer >= 0"),
        ("distance", 0, "an integer >= 1"),
        ("tunnel_height", 1, "0 (no tunnel) or an integer >= 2"),
        ("n_modules", 1, "an integer >= 2"),
        ("room", 0, "None or an integer >= 1"),
        ("time_penalty", -0.5, "a number >= 0"),
    ],
)
def test_bad_parameters_get_one_clear_error(field, value, allowed):
    with pytest.raises(ConfigError) as error:
        proteo_env.make("locomotion-v0", **{field: value})
    message = str(error.value)
    assert f"{field}={value!r} is not allowed" in message and allowed in message


@pytest.mark.parametrize("field, value", [("p_random", 1.5), ("patience", 0), ("contacts", 5)])
def test_bad_rule_parameters_get_one_clear_error(field, value):
    env = proteo_env.make("locomotion-v0", **SMALL)
    with pytest.raises(ValueError, match=f"{field}={value!r} is not allowed; allowed: "):
        LocomotionPolicy.for_env(env, **{field: value})


@pytest.mark.parametrize("overrides", [{}, {"step_height": 2}, {"tunnel_height": 2, "motion_model": "sphere"}])
def test_compiled_rollout_is_the_observation_based_policy(overrides):
    for seed in range(2):
        env = proteo_env.make("locomotion-v0", **{**SMALL, "max_cycles": 300, **overrides})
        env.reset(seed=seed)
        result = compiled_rollout(env, LocomotionPolicy.for_env(env, seed=seed), record_every=1)
        policy = LocomotionPolicy.for_env(env, seed=seed)
        positions, modes, success = drive(env, policy, 300)
        assert_same_trajectory(result, positions, modes, success, policy.rng)

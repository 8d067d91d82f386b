"""One kernel call for the rules of every world (``KernelPolicy.batch``): the same actions, draw
for draw, as one call per world, across resets; what the batched env and the teachers use."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import small_overrides

import proteo_env
from baselines import make_policy
from baselines.base import PolicyBatch
from proteo_env import batched
from training.trainers.teachers import Teachers

N_WORLDS = 3


@pytest.mark.parametrize("task_id", ["chain-v1", "grasp-v0", "table-v1"])  # three memories; grasp and table sense
def test_one_call_gives_what_one_call_per_world_gives(task_id):
    env = proteo_env.make_batched(task_id, N_WORLDS, **small_overrides(task_id))
    name = env.task.name
    together = [make_policy(name, env, seed=10 + b) for b in range(N_WORLDS)]
    alone = [make_policy(name, env, seed=10 + b) for b in range(N_WORLDS)]
    batch = type(together[0]).batch(together)
    assert isinstance(batch, PolicyBatch)
    buffers, a = env.reset(seed=4), env.n_agents
    for cycle in range(40):
        actions = batch.act_arrays(buffers)
        expected = np.concatenate([p.act_arrays(buffers.rows(b * a, (b + 1) * a)) for b, p in enumerate(alone)])
        np.testing.assert_array_equal(actions, expected)
        result = env.step_arrays(actions.reshape(N_WORLDS, a, -1))
        restart = result.done | (np.arange(N_WORLDS) == cycle % N_WORLDS if cycle % 9 == 8 else False)
        for b in np.flatnonzero(restart):  # a new episode: each world's policy reset on its own
            together[b].reset(seed=100 + cycle)
            alone[b].reset(seed=100 + cycle)
        buffers = env.reset_worlds(restart) if restart.any() else env.observe_arrays()
    assert any(p.memory.version > 2 for p in together), "some world's policy was reset on its own"


def _move_level_trace(task_id, one_call_after, monkeypatch):
    """Positions and modes of 3 worlds at ``move`` over 40 cycles of seeded random legal moves."""
    monkeypatch.setattr(batched, "ONE_CALL_AFTER", one_call_after)
    env = proteo_env.make_batched(task_id, N_WORLDS, **small_overrides(task_id, control="move", max_cycles=25))
    buffers, rng, trace = env.reset(seed=2), np.random.default_rng(0), []
    for _ in range(40):
        masks = buffers.action_mask.reshape(N_WORLDS, env.n_agents, 13).astype(bool)
        moves = np.array([[rng.choice(np.flatnonzero(m)) for m in world] for world in masks])
        result = env.step_arrays(moves[..., None])
        trace.append(np.concatenate([np.concatenate([w.positions.ravel(), w.mode]) for w in env.worlds]))
        buffers = env.reset_worlds(result.done) if result.done.any() else env.observe_arrays()
    return trace, env


@pytest.mark.parametrize("task_id", ["chain-v1", "grasp-v0"])
def test_the_env_switches_to_one_call_without_changing_a_trajectory(task_id, monkeypatch):
    per_world, env = _move_level_trace(task_id, 10**9, monkeypatch)
    assert env._autopilot_batch is None
    from_start, env = _move_level_trace(task_id, 0, monkeypatch)
    assert isinstance(env._autopilot_batch, PolicyBatch) and env._autopilot_batch.policies == env._autopilots
    midway, env = _move_level_trace(task_id, 20 * N_WORLDS, monkeypatch)  # switches at cycle 20, mid-episode
    assert env._autopilot_batch is not None
    for a, b, c in zip(per_world, from_start, midway, strict=True):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)


def test_the_teachers_label_each_group_of_worlds_in_one_call():
    env = proteo_env.make_batched("chain-v1", N_WORLDS, **small_overrides("chain-v1", control="move"))
    teachers = Teachers(env, 2 * N_WORLDS)
    first, second = env.reset(seed=1), env.reset(seed=1)
    alone, a = Teachers(env, 2 * N_WORLDS), env.n_agents  # the same teachers, asked world by world
    for _ in range(3):
        labels = teachers.labels([first, second])
        rows = [buffers.rows(b * a, (b + 1) * a) for buffers in (first, second) for b in range(N_WORLDS)]
        expected = np.concatenate([p.act_arrays(r)[:, :1] for p, r in zip(alone.policies, rows)])
        np.testing.assert_array_equal(labels, expected)
    assert labels.shape == (2 * N_WORLDS * a, 1)
    assert sorted(teachers._batches) == [0, N_WORLDS]


def test_each_world_acts_with_its_own_rule_parameters_also_after_a_replacement():
    env = proteo_env.make_batched("chain-v1", N_WORLDS, **small_overrides("chain-v1"))
    params = [{}, {"p_random": 0.5}, {"p_random": 0.9}]
    together = [make_policy("chain", env, seed=b, **p) for b, p in enumerate(params)]
    alone = [make_policy("chain", env, seed=b, **p) for b, p in enumerate(params)]
    batch, a = PolicyBatch(together), env.n_agents
    buffers = env.reset(seed=3)
    for cycle in range(30):
        if cycle == 15:  # world 0 gets another policy mid-run, with other parameters
            together[0], alone[0] = (make_policy("chain", env, seed=9, p_random=0.7) for _ in range(2))
            batch.replace(0, together[0])
        actions = batch.act_arrays(buffers)
        expected = np.concatenate([p.act_arrays(buffers.rows(b * a, (b + 1) * a)) for b, p in enumerate(alone)])
        np.testing.assert_array_equal(actions, expected)
        buffers = env.step_arrays(actions.reshape(N_WORLDS, a, -1)) and env.observe_arrays()


def test_a_batch_refuses_mixed_policies_and_rows_that_do_not_split():
    env = proteo_env.make_batched("chain-v1", 2, **small_overrides("chain-v1"))
    with pytest.raises(ValueError, match="one class"):
        PolicyBatch([make_policy("chain", env), make_policy("branch", proteo_env.make_batched("branch-v0", 1))])
    with pytest.raises(ValueError, match="policies=\\[\\] is not allowed"):
        PolicyBatch([])
    batch = PolicyBatch([make_policy("chain", env) for _ in range(2)])
    buffers = env.reset(seed=0)
    with pytest.raises(ValueError, match="observation rows are not allowed for 2 worlds"):
        batch.act_arrays(buffers.rows(0, env.n_agents + 1))

"""Worlds whose grid covers a window of the box around the modules and grows with them
(``Task.window_room``; chain and branch): the trajectories are those of a grid over the whole
box, bit for bit (serial, batched with restarts, and inside compiled code), the window really
grows, and memory follows the modules rather than the box (a large window's grid stored by pages:
tests/test_paged_grid.py)."""

from __future__ import annotations

import numpy as np
import pytest

import proteo_env
from baselines import make_policy
from baselines.compiled import CompiledRollout
from proteo_env.core import world as world_module
from proteo_env.tasks.branch import BranchV1
from proteo_env.tasks.chain import ChainV1


def chain_run(n_envs=1, cycles=260, restart=()):
    """Positions of every world after every cycle under the chain rule, and the grids seen."""
    env = proteo_env.make_batched("chain-v1", n_envs, n_modules=30, max_cycles=400)
    env.reset(seed=5)
    policy = make_policy("chain", proteo_env.make("chain-v1", n_modules=30), seed=1)
    trajectory, grids = [], []
    for cycle in range(cycles):
        result = env.step_arrays(policy.act_arrays(env.observe_arrays()).reshape(n_envs, 30, -1))
        done = result.terminated | result.truncated
        if cycle in restart:
            done[1] = True
        if done.any():
            env.reset_worlds(done)
        trajectory.append(np.stack([w.positions for w in env.worlds]))
        grids.append([(w.shape.extent, w.shape.origin, w.shape.size) for w in env.worlds])
    return np.stack(trajectory), grids


@pytest.mark.parametrize("n_envs, restart", [(1, ()), (3, (60, 150))])
def test_a_growing_window_follows_the_same_trajectory_as_the_whole_box(n_envs, restart, monkeypatch):
    windowed, grids = chain_run(n_envs, restart=restart)
    monkeypatch.setattr(ChainV1, "window_room", None)
    whole, whole_grids = chain_run(n_envs, restart=restart)
    np.testing.assert_array_equal(windowed, whole)
    extents = [world[0] for row in grids for world in row]
    assert len(set(extents)) > 1 and np.prod(extents[0]) < np.prod(extents[-1])  # the window grew
    for row in grids:  # and stayed smaller than the boxes (the batch shares one extent: the largest window)
        assert np.prod(row[0][0]) < max(np.prod(size) for _, _, size in row)
    assert all(world[1] == (0, 0, 0) for row in whole_grids for world in row)


def test_branch_in_3d_grows_its_window_in_every_direction(monkeypatch):
    def run():
        env = proteo_env.make("branch-v1", n_modules=150, target_levels=99, max_cycles=200)
        env.reset(seed=2)
        policy = make_policy("branch", env, seed=2)
        for _ in range(200):
            env.step_arrays(policy.act_arrays(env.observe_arrays()))
        return env.engine.positions, env.engine.shape

    positions, shape = run()
    default = world_module.PAGED_ABOVE_CELLS
    monkeypatch.setattr(world_module, "PAGED_ABOVE_CELLS", 0)  # the same window, stored by pages
    paged, paged_shape = run()
    monkeypatch.setattr(world_module, "PAGED_ABOVE_CELLS", default)
    monkeypatch.setattr(BranchV1, "window_room", None)
    whole, whole_shape = run()
    np.testing.assert_array_equal(positions, whole)
    np.testing.assert_array_equal(paged, whole)
    assert paged_shape.paged and not shape.paged
    assert np.prod(shape.padded) < np.prod(whole_shape.padded) / 4


def test_compiled_rollout_regrids_on_the_way_and_matches_the_python_loop():
    env = proteo_env.make("chain-v1", n_modules=30, max_cycles=400)
    env.reset(seed=4)
    start = env.engine.shape.extent
    rollout = CompiledRollout(env, make_policy("chain", env, seed=4))
    result = rollout.run(300, record_every=7)
    assert rollout.world.shape.extent != start and env.engine.shape.extent == start  # its copy grew, not env's
    policy = make_policy("chain", env, seed=4)
    recorded = dict(zip(result.recorded_cycles.tolist(), result.recorded_positions))
    for cycle in range(1, result.cycles + 1):
        env.step_arrays(policy.act_arrays(env.observe_arrays()))
        if cycle in recorded:
            np.testing.assert_array_equal(recorded[cycle], env.engine.positions)
    assert sorted(recorded)[:3] == [7, 14, 21] and result.success
    np.testing.assert_array_equal(result.positions, env.engine.positions)


def test_a_large_chain_resets_on_a_grid_the_size_of_its_blob():
    env = proteo_env.make("chain-v1", n_modules=10**4)
    env.reset(seed=0)
    shape = env.engine.shape
    box_cells = np.prod([s + 4 for s in shape.size])
    assert shape.n_cells < box_cells / 10**4  # about 1 M cells, not the box's 2.5e10
    assert shape.n_cells < 100 * 10**4

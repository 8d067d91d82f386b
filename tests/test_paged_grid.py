"""A grid stored by pages (``proteo_env.core.paged``): the same trajectories and observations as a
dense grid, bit for bit (one world, a batch with restarts, a growing window, compiled code), pages
returned when the modules leave them, and memory that follows the modules, not their bounding box."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from test_growing_world import chain_run

import proteo_env
from baselines import make_policy
from baselines.compiled import CompiledRollout
from proteo_env.core import world as world_module
from proteo_env.core.paged import PAGE_CELLS
from proteo_env.core.world import Physics, World
from proteo_env.spaces import ObservationBuffers


def random_world(paged, n=40, solid=((30, 30, 2),)):
    """A line of ``n`` modules on a floor with an obstacle, every module an agent."""
    positions = np.array([[2 + i, 2 + i, 0] for i in range(n)])
    return World(
        size=(70, 70, 8), positions=positions, n_agents=n, physics=Physics(), floor=True, solid=solid, paged=paged
    )


def random_actions(rng, n):
    return dict(
        move=rng.integers(0, 13, n),
        mode=rng.integers(0, 3, n).astype(np.int32),
        scent_role=rng.integers(0, 3, (n, 1)).astype(np.int8),
        message_target=rng.integers(0, 13, n),
        message_value=rng.integers(0, 4, n).astype(np.int32),
    )


def observed(world):
    out = ObservationBuffers(world.n_agents, 12, world.n_channels)
    world.observe(out)
    return out


def test_random_moves_on_a_paged_grid_follow_the_dense_grid_and_return_pages():
    dense, paged = random_world(False), random_world(True)
    assert isinstance(dense.grid, np.ndarray) and paged.shape.paged
    for w in (dense, paged):
        w.seed(7)
    rng = np.random.default_rng(0)
    copied, returned, moves = [], 0, 0
    for _ in range(600):
        actions = random_actions(rng, dense.n_agents)
        moved = dense.step(**actions)
        np.testing.assert_array_equal(moved, paged.step(**actions))
        moves += moved.sum()
        np.testing.assert_array_equal(dense.positions, paged.positions)
        np.testing.assert_array_equal(dense.scent, paged.scent)
        np.testing.assert_array_equal(dense.inbox, paged.inbox)
        a, b = observed(dense), observed(paged)
        for field in a.FIELDS:
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
        if len(copied) % 25 == 0:  # a collection between cycles changes nothing either
            before = paged.grid.n_copied()
            paged.grid.collect()
            returned += paged.grid.n_copied() < before
        copied.append(paged.grid.n_copied())
    assert moves > 500
    assert returned > 0  # pages went back to their background when the modules had left them
    assert max(copied) <= 2 * dense.n_modules + 64


def test_a_paged_world_pickles_and_goes_on_as_the_original():
    world = random_world(True)
    world.seed(3)
    rng = np.random.default_rng(1)
    for _ in range(50):
        world.step(**random_actions(rng, world.n_agents))
    twin = pickle.loads(pickle.dumps(world))
    for _ in range(100):
        actions = random_actions(rng, world.n_agents)
        np.testing.assert_array_equal(world.step(**actions), twin.step(**actions))
    np.testing.assert_array_equal(world.positions, twin.positions)
    assert twin.grid.cell is twin.cell and twin.n_components() == world.n_components()


def test_a_module_cannot_enter_a_solid_site_of_a_paged_grid():
    with pytest.raises(ValueError, match="is a solid site"):
        random_world(True, n=4, solid=((4, 4, 0),))


@pytest.mark.parametrize("n_envs, restart", [(1, ()), (3, (60, 150))])
def test_a_paged_growing_window_follows_the_dense_one(n_envs, restart, monkeypatch):
    dense, _ = chain_run(n_envs, restart=restart)
    monkeypatch.setattr(world_module, "PAGED_ABOVE_CELLS", 0)
    paged, _ = chain_run(n_envs, restart=restart)
    np.testing.assert_array_equal(paged, dense)


def test_grasp_on_a_paged_grid_scores_as_on_the_dense_one(monkeypatch):
    def run():
        env = proteo_env.make("grasp-v0", n_modules=60, max_cycles=80)
        env.reset(seed=3)
        policy = make_policy("grasp", env, seed=3)
        rewards = [env.step_arrays(policy.act_arrays(env.observe_arrays())).reward for _ in range(80)]
        return env.engine.positions, np.array(rewards), env.engine.shape.paged

    dense, dense_rewards, was_paged = run()
    monkeypatch.setattr(world_module, "PAGED_ABOVE_CELLS", 0)
    paged, paged_rewards, is_paged = run()
    assert is_paged and not was_paged
    np.testing.assert_array_equal(paged, dense)
    np.testing.assert_array_equal(paged_rewards, dense_rewards)


def test_compiled_rollout_on_a_paged_grid_matches_the_dense_one(monkeypatch):
    def run():
        env = proteo_env.make("chain-v1", n_modules=30, max_cycles=400)
        env.reset(seed=4)
        rollout = CompiledRollout(env, make_policy("chain", env, seed=4))
        return rollout.run(300, record_every=7), rollout.world

    dense, _ = run()
    monkeypatch.setattr(world_module, "PAGED_ABOVE_CELLS", 0)
    paged, world = run()
    assert world.shape.paged and dense.success
    np.testing.assert_array_equal(paged.positions, dense.positions)
    np.testing.assert_array_equal(paged.recorded_positions, dense.recorded_positions)
    assert paged.cycles == dense.cycles


def test_a_chain_of_1200_modules_across_its_box_holds_megabytes_not_gigabytes():
    n = 1200
    positions = np.array([[2 + i, 2 + i, 0] for i in range(n)])
    world = World(size=(2 * n, 2 * n, 33), positions=positions, n_agents=n, physics=Physics(), floor=True)
    grid = world.grid
    dense_bytes = world.shape.n_cells * 8  # the grid and the marks, int32 each
    assert world.shape.paged and dense_bytes > 2 * 2**30
    held = grid.n_copied() + grid.n_shared
    stored = held * PAGE_CELLS * 8 + sum(a.nbytes for a in (grid.table, grid.background, grid.keep))
    assert stored < 30 * 2**20
    assert world.n_components() == 1 and world.can_detach(n - 1) and not world.can_detach(n // 2)

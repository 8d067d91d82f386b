"""Rewards whose optimum is the paper's behaviour: chain-v1 and table-v1 against their v0."""

from __future__ import annotations

import numpy as np
import pytest

import proteo_env
from baselines import make_policy
from proteo_env.layouts import Layout, line_sites, place_in_box
from proteo_env.registry import task_class
from proteo_env.rollout import run_episode
from proteo_env.tasks.chain import Chain, ChainV1
from proteo_env.tasks.table import Table, TableV1

TABLE = dict(board_size=9, depth=2, n_spares=16, schedule=((0, 8.0, 2.0), (60, 2.0, 8.0)), stable_window=20,
             motion_model="minimal", max_cycles=400)
"""A table whose rules settle after one weight shift in about 150 cycles."""


def test_versions_are_registered_and_a_bare_name_means_the_newest():
    assert {"chain-v0", "chain-v1", "table-v0", "table-v1"} <= set(proteo_env.TASKS)
    assert task_class("chain-v0") is Chain and task_class("table-v0") is Table
    assert task_class("chain") is ChainV1 and task_class("table") is TableV1


def _settle_then_continue(task_id: str, extra_cycles: int) -> tuple[int, float, float]:
    """The table rules until success, then ``extra_cycles`` more cycles of the same episode (the
    batched env does not stop at success). Returns (cycle of success, return up to it, reward of
    the cycles after it)."""
    env = proteo_env.make(task_id, **TABLE)
    policy = make_policy("table", env, seed=5)
    batch = proteo_env.make_batched(task_id, 1, **TABLE)
    buffers = batch.reset(seed=5)
    policy.reset(5)
    settled, before, after = None, 0.0, 0.0
    while settled is None or batch.cycle < settled + extra_cycles:
        reward = sum(batch.step_arrays(policy.act_arrays(buffers)[None])[0].values())
        buffers = batch.observe_arrays()
        if settled is None:
            before += reward
            if batch.success()[0]:
                settled = batch.cycle
        else:
            after += reward
        assert batch.cycle < TABLE["max_cycles"], "the rules did not settle"
    return settled, before, after


def test_table_v1_settling_earns_at_least_going_on_without_settling():
    settled, before, after = _settle_then_continue("table-v1", 100)
    assert settled > TABLE["schedule"][-1][0]
    assert after <= 0.0  # continuing past success only loses reward
    assert before + after <= before
    settled_v0, _, after_v0 = _settle_then_continue("table-v0", 100)
    assert settled_v0 == settled  # the reward does not change the trajectory
    assert after_v0 > 0.0  # v0: going on without settling pays more (its flaw)


def test_table_v1_doing_nothing_does_not_succeed():
    for task_id, succeeds in (("table-v0", True), ("table-v1", False)):
        env = proteo_env.make(task_id, **TABLE)
        result = run_episode(env, make_policy("stay", env, seed=0), seed=0)
        assert result.success is succeeds, task_id
        assert result.metrics["grounded_legs"] == 0
    assert result.total_reward == pytest.approx(-TABLE["max_cycles"])  # v1: all the weight unsupported every cycle


def test_table_v1_success_needs_the_weight_carried():
    env = proteo_env.make("table-v1", **TABLE)
    result = run_episode(env, make_policy("table", env, seed=1), seed=1)
    assert result.success
    book = env.task.ledger
    legs = np.array([(book.grounded & book.left).sum(), (book.grounded & ~book.left).sum()])
    roots = np.array([book.left.sum(), (~book.left).sum()])
    f_max = env.task.params.f_max
    assert (np.minimum(book.weights, f_max * legs) == np.minimum(book.weights, f_max * roots)).all()


def _path_layout(xy: list[tuple[int, int]]) -> Layout:
    sites, size = place_in_box(np.array([(x, y, 0) for x, y in xy], dtype=np.int64), margin=2)
    return Layout(size=size, modules=sites)


STRAIGHT = [tuple(p[:2]) for p in line_sites(7)]
U_SHAPE = [(0, 2), (1, 3), (2, 4), (3, 3), (4, 2), (3, 1), (2, 0)]
"""Seven modules in one layer folded into a U: its ends are 2 hops apart (6 for a straight chain)."""


def _first_cycle_reward(task_id: str, layout: Layout) -> tuple[float, dict, bool]:
    env = proteo_env.make(task_id, n_modules=len(layout.modules), max_cycles=5)
    env.task.build_layout = lambda rng: layout
    observations, _ = env.reset(seed=0)
    stay = make_policy("stay", env, seed=0)
    _, rewards, terminations, _, infos = env.step(stay.act(observations))
    info = infos["module_0"]
    return rewards["module_0"], info, terminations["module_0"]


def test_chain_v1_pays_a_straight_chain_more_than_a_winding_one():
    straight, info_s, done_s = _first_cycle_reward("chain-v1", _path_layout(STRAIGHT))
    winding, info_w, done_w = _first_cycle_reward("chain-v1", _path_layout(U_SHAPE))
    assert done_s and done_w  # both are complete chains: success ends the episode either way
    assert info_s["reward/success"] == 1.0 and info_s["metric/straightness"] == 1.0
    assert info_w["reward/success"] == pytest.approx(2 / 6)
    assert straight > winding
    v0_straight, _, _ = _first_cycle_reward("chain-v0", _path_layout(STRAIGHT))
    v0_winding, _, _ = _first_cycle_reward("chain-v0", _path_layout(U_SHAPE))
    assert v0_straight == v0_winding  # v0 paid both the same

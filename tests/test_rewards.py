"""Rewards whose optimum is the paper's behaviour: chain-v1 pays a straight chain, table-v1 pays
settling and asks the legs to carry the weight, table-v2 asks them to follow it (docs/tasks/*.md, "Reward against degenerate
strategies", measured by benchmarks/degenerate_strategies.py)."""

from __future__ import annotations

import numpy as np
import pytest

import proteo_env
from baselines import make_policy
from proteo_env.registry import newest_tasks, task_class
from proteo_env.rollout import run_episode
from proteo_env.tasks.chain import fcc_hops
from training.machinery.checkpoints import load_policy

CHAIN = {"n_modules": 12, "max_cycles": 300, "motion_model": "sphere"}
TABLE = {
    "board_size": 9,
    "depth": 2,
    "n_spares": 16,
    "schedule": ((0, 8, 2), (150, 2, 8)),
    "stable_window": 30,
    "motion_model": "minimal",
    "max_cycles": 500,
}


def test_versions_are_registered_and_bare_names_mean_the_newest():
    assert {"chain-v0", "chain-v1", "table-v0", "table-v1", "table-v2"} <= set(proteo_env.TASKS)
    assert task_class("chain").task_id() == "chain-v1" and task_class("table").task_id() == "table-v2"
    assert set(newest_tasks()) == {
        "sandbox-v0",
        "chain-v1",
        "branch-v1",
        "table-v2",
        "grasp-v0",
        "locomotion-v0",
        "snake-v0",
    }


def test_fcc_hops():
    assert fcc_hops((0, 0, 0), (5, 5, 0)) == 5  # straight along a face direction
    assert fcc_hops((0, 0, 0), (2, 0, 0)) == 2  # two steps: (1,1,0) then (1,-1,0)
    assert fcc_hops((0, 0, 0), (1, 1, 2)) == 2
    assert fcc_hops((3, 1, 0), (3, 1, 0)) == 0


def _final_terms(env, policy, seed):
    result = run_episode(env, policy, seed=seed)
    return result, result.history[-1]


def test_chain_v1_pays_a_straight_chain_more_than_a_winding_one():
    env = proteo_env.make("chain-v1", **CHAIN)
    straight = run_episode(env, make_policy("chain", env, seed=1000), seed=1000)
    winding = run_episode(env, load_policy("checkpoints/exhibits/winding_chain", env, seed=1000), seed=1000)
    assert straight.success and winding.success
    assert straight.metrics["straightness"] == pytest.approx(1.0)
    assert winding.metrics["straightness"] < 0.8
    v0 = proteo_env.make("chain-v0", **CHAIN)
    winding_v0 = run_episode(v0, load_policy("checkpoints/exhibits/winding_chain", v0, seed=1000), seed=1000)
    # the same trajectory; only the success bonus differs, by exactly 1 - straightness
    assert winding_v0.cycles == winding.cycles
    assert winding_v0.total_reward - winding.total_reward == pytest.approx(1 - winding.metrics["straightness"])
    assert straight.total_reward > winding.total_reward


def test_table_v1_pays_the_rest_of_the_horizon_on_success():
    env = proteo_env.make("table-v1", **TABLE)
    policy = make_policy("table", env, seed=3)
    observations, _ = env.reset(seed=3)
    policy.reset(3)
    last = None
    while env.agents:
        observations, rewards, terms, truncs, infos = env.step(policy.act(observations))
        info = infos["module_0"]
        if not terms["module_0"]:
            last = info
    assert terms["module_0"], "the rules settle the small table"
    rest = TABLE["max_cycles"] - info["cycle"]
    assert info["reward/settled"] == pytest.approx(rest * (info["reward/support"] + info["reward/legs"]))
    assert info["reward/settled"] > 0
    # before success nothing is settled
    assert last["reward/settled"] == 0.0


def test_table_v1_does_not_count_doing_nothing_as_success():
    for task_id, expected in (("table-v0", True), ("table-v1", False)):
        env = proteo_env.make(task_id, **TABLE)
        result = run_episode(env, make_policy("table", env, seed=0, p_max=0.0, p_min=0.0), seed=0)
        assert result.success is expected, task_id
        assert result.total_reward == 0.0


class _IdleThenRules:
    """The table rules with ``p_max = p_min = 0`` (no leg) for ``idle`` cycles, then the rules."""

    def __init__(self, env, idle: int):
        self.idle = make_policy("table", env, seed=0, p_max=0.0, p_min=0.0)
        self.rules = make_policy("table", env, seed=0)
        self.idle_cycles = idle

    def reset(self, seed):
        self.idle.reset(seed)
        self.rules.reset(seed)
        self.cycle = 0

    def act(self, observations):
        self.cycle += 1
        return (self.idle if self.cycle <= self.idle_cycles else self.rules).act(observations)


def test_table_v1_success_is_a_stable_configuration_whose_legs_carry_the_weight():
    # Idle past the last shift plus stable_window: the empty signature has been stable that long
    # (table-v0 would end here). Legs grown afterwards must settle again before success.
    idle = TABLE["schedule"][-1][0] + TABLE["stable_window"] + 10
    env = proteo_env.make("table-v1", **TABLE)
    result = run_episode(env, _IdleThenRules(env, idle), seed=1)
    assert result.success
    assert result.metrics["stable"] == 1.0  # not merely the first cycle every region had a leg
    assert result.cycles >= idle + TABLE["stable_window"]
    book = env.task.ledger
    legs = np.array([(book.grounded & book.left).sum(), (book.grounded & ~book.left).sum()])
    roots = np.array([book.left.sum(), (~book.left).sum()])
    f_max = env.task.params.f_max
    assert (np.minimum(book.weights, f_max * legs) == np.minimum(book.weights, f_max * roots)).all()


def test_table_v1_compiled_rollout_ends_where_the_env_does():
    from baselines.compiled import CompiledRollout

    env = proteo_env.make("table-v1", **TABLE)
    policy = make_policy("table", env, seed=2)
    env.reset(seed=2)
    policy.reset(2)
    compiled = CompiledRollout(env, policy).run(TABLE["max_cycles"])
    stepped = run_episode(env, make_policy("table", env, seed=2), seed=2)
    assert stepped.success
    assert (compiled.success, compiled.cycles) == (stepped.success, stepped.cycles)


def test_table_v2_spares_start_under_a_point_drawn_from_the_world_seed():
    def spares(task_id, seed):
        env = proteo_env.make(task_id, **TABLE)
        env.reset(seed=seed)
        assert env.engine.n_components() == 1
        n = TABLE["n_spares"]
        positions = np.array(env.world.positions[:n])
        assert (positions[:, 2] < TABLE["depth"]).all()  # under the board
        return frozenset(map(tuple, positions))

    v2 = {seed: spares("table-v2", seed) for seed in range(6)}
    assert len(set(v2.values())) >= 4, "the start layout varies with the world seed"
    assert spares("table-v2", 3) == v2[3]
    assert len({spares("table-v1", seed) for seed in range(3)}) == 1, "table-v1 keeps its one layout"


def test_table_v2_a_table_that_never_disbands_fails_where_table_v1_lets_it_succeed():
    # The rules with p_min = 0 grow legs where the weight is and never disband one: after the shift to
    # (2, 8) the left half keeps all 3 of its legs for a weight of 2 (f_min = 1 per leg).
    seeds = range(1000, 1010)

    def successes(task_id, **rule_params):
        env = proteo_env.make(task_id, **TABLE)
        return sum(run_episode(env, make_policy("table", env, seed=s, **rule_params), seed=s).success for s in seeds)

    assert successes("table-v1", p_min=0.0) >= 8
    assert successes("table-v2", p_min=0.0) == 0
    assert successes("table-v2") >= 8, "the rules move their legs and succeed"


def test_table_v2_success_has_a_stable_configuration_after_every_shift_without_idle_legs():
    env = proteo_env.make("table-v2", **TABLE)
    result = run_episode(env, make_policy("table", env, seed=4), seed=4)
    assert result.success
    restabilised = [result.metrics[f"restabilise_{k}"] for k in range(len(TABLE["schedule"]))]
    assert all(r >= 0 for r in restabilised), restabilised
    book = env.task.ledger
    legs = np.array([(book.grounded & book.left).sum(), (book.grounded & ~book.left).sum()])
    assert (book.weights >= env.task.params.f_min * legs).all()
    assert result.metrics["leg_disbands"] > 0

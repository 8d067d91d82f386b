"""The snake task and its composed behaviour (the chain's rules, then the crawl): robots get
through a tunnel two layers high where locomotion's tread does not, the chain really forms first
and the crawl really takes over, every move is legal and keeps the robot connected and under the
roof, the composed rule runs the same in the Python loop, through dicts and in the compiled
rollout, the handover reads only local conditions, and bad input gets one clear error."""

from __future__ import annotations

import numpy as np
import pytest
from test_compiled_rollout import assert_same_trajectory, drive
from test_locomotion import assert_legal_connected_cycles

import proteo_env
from baselines import make_policy
from baselines.base import Observed, stacked_fields
from baselines.compiled import compiled_rollout
from baselines.compose import Stage, _view_table, compose
from baselines.crawl import BECOME_HEAD, CrawlPolicy
from baselines.locomotion import LocomotionPolicy
from baselines.snake import SnakePolicy, chain_handover
from proteo_env.config import ConfigError
from proteo_env.spaces import KIND_EMPTY, KIND_MODULE
from proteo_env.tasks.snake import SnakeMode

SMALL = dict(n_modules=12, tunnel_length=4, max_cycles=400)


@pytest.mark.slow
def test_most_robots_snake_through_the_tunnel_where_the_tread_does_not():
    """The task's default course (20 modules, a tunnel 2 free layers high and 6 long): the
    composed rule gets 16 of 16 robots of seeds 100..115 through (docs/evidence/snake.md);
    here 6 seeds, against locomotion's tread rule on the same course."""
    snake = tread = 0
    for seed in range(100, 106):
        env = proteo_env.make("snake-v0", max_cycles=1500)
        env.reset(seed=seed)
        snake += compiled_rollout(env, SnakePolicy.for_env(env, seed=seed)).success
        env = proteo_env.make("locomotion-v0", step_height=0, tunnel_height=2, closed_above=True, max_cycles=1500)
        env.reset(seed=seed)
        tread += compiled_rollout(env, LocomotionPolicy.for_env(env, seed=seed)).success
    assert snake >= 5 and tread <= 1, (snake, tread)


def test_the_chain_forms_first_then_the_crawl_takes_over_and_crosses():
    env = proteo_env.make("snake-v0", max_cycles=1500)
    env.reset(seed=101)
    result = compiled_rollout(env, SnakePolicy.for_env(env, seed=101), record_every=1)
    assert result.success
    modes = result.recorded_modes
    crawl = modes >= SnakeMode.CRAWL
    first = int(np.argmax(crawl.any(axis=1)))  # the first cycle any module is in the crawl
    assert first > 0 and (modes[:first] == SnakeMode.FINAL).sum(axis=1).max() >= 5  # a chain of 5+ first
    assert (modes[first - 1] == SnakeMode.SEED).sum() == 1
    assert (modes[-1] >= SnakeMode.CRAWL).sum() >= 10  # most modules crawled
    assert (modes[-1] == SnakeMode.HEAD).sum() == 1
    positions = result.recorded_positions
    p = env.task.params
    inside = (positions[..., 0] >= env.task.finish - p.tunnel_length) & (positions[..., 0] < env.task.finish)
    assert inside.any(axis=1).sum() > 50  # modules were in the tunnel for many cycles, under its roof
    assert (positions[..., 2][inside] < p.step_height + p.tunnel_height).all()
    solid = env.engine.solid_sites
    wall = solid[(solid[:, 0] >= env.task.finish - p.tunnel_length) & (solid[:, 0] < env.task.finish)]
    assert wall[:, 2].max() == env.engine.shape.size[2] - 1  # the roof is a wall up to the box's top
    assert (positions[-1][:, 0] >= env.task.finish).all()


@pytest.mark.parametrize("overrides", [{}, {"tunnel_height": 0, "step_height": 2}])
def test_moves_are_legal_and_the_robot_stays_connected(overrides):
    env = proteo_env.make("snake-v0", **{**SMALL, **overrides})
    env.reset(seed=3)
    assert_legal_connected_cycles(env, SnakePolicy.for_env(env, seed=3), 150)


@pytest.mark.parametrize("use_dicts", [False, True])
def test_compiled_rollout_is_the_composed_policy_driven_through_the_env(use_dicts):
    for seed in range(2):
        env = proteo_env.make("snake-v0", **SMALL)
        env.reset(seed=seed)
        result = compiled_rollout(env, SnakePolicy.for_env(env, seed=seed), record_every=1)
        policy = SnakePolicy.for_env(env, seed=seed)
        positions, modes, success = drive(env, policy, SMALL["max_cycles"], use_dicts=use_dicts)
        assert (modes >= SnakeMode.CRAWL).any()  # both stages ran
        assert_same_trajectory(result, positions, modes, success, policy.rng)


def one_row(**fields) -> Observed:
    """An :class:`Observed` of one module: nothing around it, no messages, then ``fields``."""
    base = {
        "own_mode": np.zeros((1, 1)),
        "messages": np.zeros((1, 12)),
        "neighbour_kind": np.full((1, 12), KIND_EMPTY),
        "neighbour_mode": np.full((1, 12), -1),
        "neighbour_scent": np.zeros((1, 12, 1)),
        "own_scent": np.zeros((1, 1)),
        "action_mask": np.ones((1, 13)),
        "contact": np.zeros((1, 2)),
        "load": np.zeros((1, 1)),
        "hint": np.array([[1.0, 0.0, 0.0]]),
        **fields,
    }
    return Observed(*stacked_fields(base.__getitem__, Observed._fields))


def around(modes: dict[int, int]) -> dict:
    """Neighbour fields with a module of mode ``m`` at slot ``k`` for each ``{k: m}``."""
    kind, mode = np.full((1, 12), KIND_EMPTY), np.full((1, 12), -1)
    for k, m in modes.items():
        kind[0, k], mode[0, k] = KIND_MODULE, m
    return {"neighbour_kind": kind, "neighbour_mode": mode}


M = SnakeMode


@pytest.mark.parametrize(
    "own, neighbours, message, handed",
    [
        (M.FINAL, {0: M.FINAL}, 0, M.CRAWL),  # the chain's tail, nobody looking for the chain: crawl
        (M.FINAL, {0: M.FINAL, 5: M.SEARCH}, 0, -1),  # a module still looking: wait
        (M.FINAL, {0: M.FINAL, 5: M.SEED}, 0, -1),  # two neighbours: not the tail
        (M.SEED, {0: M.FINAL, 5: M.CRAWL}, 0, M.HEAD),  # a crawler came round: the seed is the head
        (M.SEED, {0: M.FINAL, 5: M.SEARCH}, 0, -1),
        (M.SEARCH, {0: M.HEAD}, BECOME_HEAD, M.CRAWL),  # asked to join at the head
        (M.SLEEP, {0: M.HEAD}, BECOME_HEAD, M.CRAWL),
        (M.SEARCH, {0: M.SEED}, 13, -1),  # the chain's own promotion stays in the chain
    ],
)
def test_the_handover_reads_only_local_conditions(own, neighbours, message, handed):
    messages = np.zeros((1, 12))
    messages[0, 0] = message
    seen = one_row(own_mode=np.array([[own]]), messages=messages, **around(neighbours))
    assert chain_handover(seen, 0, SnakePolicy.for_env(proteo_env.make("snake-v0")).rule_params[0]) == handed


def test_each_stage_reads_the_other_stage_s_modes_as_its_own():
    chain, crawl = SnakePolicy.stages
    composed = tuple(SnakeMode.__members__)
    np.testing.assert_array_equal(_view_table(chain, composed, 0), [0, 1, 2, 3, 1, 2, 3])  # CRAWL as SEARCH ...
    np.testing.assert_array_equal(_view_table(crawl, composed, 4), [0, 0, 1, 2, 0, 1, 2])  # SEED as HEAD ...
    unnamed = Stage(CrawlPolicy, crawl.modes, sees={})
    np.testing.assert_array_equal(_view_table(unnamed, composed, 4), [3, 3, 3, 3, 0, 1, 2])  # "some other"


def test_a_composition_refuses_a_task_with_other_modes_and_routes_stage_parameters():
    env = proteo_env.make("chain-v0", n_modules=8)
    with pytest.raises(ValueError, match=r"policy 'snake' composes chain\+crawl with the modes .*allowed: a task"):
        SnakePolicy.for_env(env)
    env = proteo_env.make("snake-v0", **SMALL)
    policy = make_policy("snake", env, seed=0, first={"p_random": 0.1}, then={"prefer": "ahead"})
    assert policy.parts[0].p_random == 0.1 and policy.parts[1].prefer == "ahead"
    with pytest.raises(ValueError, match=r"prefer='uphill' is not allowed; allowed: none, ahead, downhill"):
        make_policy("snake", env, then={"prefer": "uphill"})
    with pytest.raises(ValueError, match=r"head_patience=0 is not allowed; allowed: an integer >= 1"):
        make_policy("snake", env, then={"head_patience": 0})


def test_compose_makes_a_policy_of_any_two_stages():
    """The mechanism is general: a composition of the chain with itself (the second stage's modes
    renamed) runs and hands over as its kernel says."""
    twin = compose(
        "snake",
        SnakePolicy.stages[0],
        Stage(CrawlPolicy, ("CRAWL", "HEAD", "BODY"), sees={"SEED": "HEAD"}),
        chain_handover,
    )
    env = proteo_env.make("snake-v0", **SMALL)
    env.reset(seed=0)
    result = compiled_rollout(env, twin.for_env(env, seed=0))
    assert result.cycles > 0 and (result.modes >= SnakeMode.CRAWL).any()


def test_the_slot_is_a_wall_with_an_opening():
    env = proteo_env.make("locomotion-v0", step_height=0, slot_width=2, tunnel_length=3)
    env.reset(seed=0)
    solid = env.engine.solid_sites
    wall = solid[solid[:, 2] >= 0]
    face = env.task.finish - 3
    assert set(np.unique(wall[:, 0])) == {face, face + 1, face + 2}
    width = env.engine.shape.size[1] if hasattr(env.engine, "shape") else None
    open_y = sorted(set(range(int(wall[:, 1].max()) + 1)) - set(wall[:, 1].tolist()))
    assert len(open_y) == 2 and open_y[1] == open_y[0] + 1, (open_y, width)


@pytest.mark.parametrize(
    "field, value, allowed",
    [("tunnel_height", 1, "0 (no tunnel) or an integer >= 2"), ("slot_width", -1, "an integer >= 0")],
)
def test_bad_parameters_get_one_clear_error(field, value, allowed):
    with pytest.raises(ConfigError) as error:
        proteo_env.make("snake-v0", **{field: value})
    message = str(error.value)
    assert f"{field}={value!r} is not allowed" in message and allowed in message

"""The batched engine: B worlds stepped together follow exactly their single-world trajectories."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from conftest import SMALL_OVERRIDES, task_params

import proteo_env
from proteo_env.config import ConfigError, world_seeds
from proteo_env.spaces import ObservationBuffers

N_ENVS = 3


def _random_actions(layout, masks: np.ndarray, rng) -> np.ndarray:
    """``(rows, L)`` actions: every field uniform, the move uniform among legal ones half the time."""
    actions = rng.integers(0, layout.nvec, size=(len(masks), layout.length))
    legal = np.argmax(masks * rng.random(masks.shape), axis=1)
    use_legal = rng.random(len(masks)) < 0.5
    actions[use_legal, layout.move] = legal[use_legal]
    return actions


@pytest.mark.parametrize("task_id", task_params())
@pytest.mark.parametrize("motion_model", ["sphere", "minimal"])
def test_batch_matches_single_envs(task_id, motion_model):
    overrides = {**SMALL_OVERRIDES.get(proteo_env.TASKS[task_id].name, {}), "motion_model": motion_model}
    batched = proteo_env.make_batched(task_id, N_ENVS, **overrides)
    singles = [proteo_env.make(task_id, **overrides) for _ in range(N_ENVS)]
    obs = batched.reset(seed=7)
    for b, env in enumerate(singles):
        env.reset(seed=world_seeds(7, N_ENVS)[b])
    a, lay, rng = batched.n_agents, batched.action_layout, np.random.default_rng(0)
    for _ in range(60):
        actions = _random_actions(lay, obs.action_mask, rng).reshape(N_ENVS, a, lay.length)
        terms = batched.step_arrays(actions)
        obs = batched.observe_arrays()
        for b, env in enumerate(singles):
            single = env.step_arrays(actions[b])
            assert single.terms[0] == terms.terms[b] and single.reward[0] == terms.reward[b]
            assert single.terminated[0] == terms.terminated[b] and single.truncated[0] == terms.truncated[b]
            single_obs = env.observe_arrays()
            for field in ObservationBuffers.FIELDS:
                np.testing.assert_array_equal(
                    getattr(obs, field)[b * a : (b + 1) * a], getattr(single_obs, field), err_msg=field
                )
            np.testing.assert_array_equal(batched.last_moved[b], env.last_moved)
            for key, value in env.engine.snapshot().items():
                np.testing.assert_array_equal(batched.worlds[b].snapshot()[key], value, err_msg=key)
        assert batched.metrics() == [env.batch.metrics()[0] for env in singles]


RESET_EVERY = (5, 8, 13)
"""World ``b`` of the per-world reset test starts a new episode every ``RESET_EVERY[b]`` cycles."""


@pytest.mark.parametrize(
    "task_id,control",
    [
        pytest.param(t.values[0], c, marks=t.marks, id=f"{t.values[0]}-{c}")
        for t in task_params()
        for c in ("full", "move")
        if c == "full" or proteo_env.TASKS[t.values[0]].name != "sandbox"
    ],
)
def test_worlds_reset_one_at_a_time_match_single_envs(task_id, control):
    """reset_worlds restarts some worlds while the others run on; world b's episodes are those
    of a single env reset with child b of SeedSequence(7) and then reset() without a seed, also across a move
    of every world onto a larger grid (start layouts of chain, branch and grasp vary in size;
    sandbox has no hand-coded rules, so no move level)."""
    name = proteo_env.TASKS[task_id].name
    overrides = {**SMALL_OVERRIDES.get(name, {}), "control": control}
    batched = proteo_env.make_batched(task_id, N_ENVS, **overrides)
    singles = [proteo_env.make(task_id, **overrides) for _ in range(N_ENVS)]
    obs = batched.reset(seed=7)
    for b, env in enumerate(singles):
        env.reset(seed=world_seeds(7, N_ENVS)[b])
    extent = batched.worlds[0].shape.extent
    a, lay, rng = batched.n_agents, batched.action_layout, np.random.default_rng(0)
    for cycle in range(1, 61):
        actions = _random_actions(lay, obs.action_mask, rng)[:, : len(batched.control_nvec)]
        actions = actions.reshape(N_ENVS, a, -1)
        terms = batched.step_arrays(actions)
        restart = np.array([cycle % every == 0 for every in RESET_EVERY])
        # on odd cycles the cycle is observed first, so only the restarted worlds are observed anew
        before = batched.observe_arrays() if cycle % 2 else None
        kept = None if before is None else before.copy()
        obs = batched.reset_worlds(restart) if restart.any() else batched.observe_arrays()
        if before is not None:  # what was returned before stays as it was
            for field in ObservationBuffers.FIELDS:
                np.testing.assert_array_equal(getattr(before, field), getattr(kept, field), err_msg=field)
        for b, env in enumerate(singles):
            single = env.step_arrays(actions[b])
            assert single.terms[0] == terms.terms[b] and single.reward[0] == terms.reward[b]
            assert single.terminated[0] == terms.terminated[b] and single.truncated[0] == terms.truncated[b]
            if restart[b]:
                env.reset()
            single_obs = env.observe_arrays()
            for field in ObservationBuffers.FIELDS:
                np.testing.assert_array_equal(
                    getattr(obs, field)[b * a : (b + 1) * a], getattr(single_obs, field), err_msg=field
                )
            for key, value in env.engine.snapshot().items():
                np.testing.assert_array_equal(batched.worlds[b].snapshot()[key], value, err_msg=key)
            assert batched.cycles[b] == env.cycle
        assert batched.metrics() == [env.batch.metrics()[0] for env in singles]
    if name in ("chain", "branch", "grasp"):
        assert batched.worlds[0].shape.extent != extent, "no start layout outgrew the batch's grid"


def test_reset_worlds_names_a_bad_world():
    batched = proteo_env.make_batched("sandbox-v0", 2, n_modules=10)
    with pytest.raises(RuntimeError, match="call reset"):
        batched.reset_worlds([0])
    batched.reset(seed=0)
    with pytest.raises(ValueError, match=r"world 2 is not allowed; allowed: 0\.\.1"):
        batched.reset_worlds([2])


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


def test_the_step_result_sums_the_terms_and_says_how_each_world_ended():
    batched = proteo_env.make_batched("chain-v0", 3, n_modules=6, max_cycles=4)
    obs = batched.reset(seed=0)
    lay, rng = batched.action_layout, np.random.default_rng(0)
    for cycle in range(1, 5):
        result = batched.step_arrays(_random_actions(lay, obs.action_mask, rng).reshape(3, 6, lay.length))
        obs = batched.observe_arrays()
        assert result.reward.shape == result.terminated.shape == result.truncated.shape == (3,)
        assert result.reward.tolist() == [sum(t.values()) for t in result.terms]
        assert result.terminated.tolist() == batched.success().tolist()
        assert result.truncated.tolist() == [cycle == 4 and not s for s in result.terminated]
        assert result.done.tolist() == (result.terminated | result.truncated).tolist()


def test_reset_worlds_with_seeds_starts_each_as_a_single_env_reset_with_its_seed():
    env = proteo_env.make_batched("chain-v1", 3, n_modules=12)
    env.reset(seed=0)
    env.reset_worlds([2, 0], world_seeds=[41, 7])
    for b, seed in ((2, 41), (0, 7)):
        alone = proteo_env.make("chain-v1", n_modules=12)
        alone.reset(seed=seed)
        np.testing.assert_array_equal(env.worlds[b].positions, alone.engine.positions)
    with pytest.raises(ConfigError, match="world_seeds=\\[1\\] is not allowed; allowed: a list of 2 seeds"):
        env.reset_worlds([0, 1], world_seeds=[1])


@pytest.mark.parametrize("task_id", ["chain-v0", "chain-v1"])
def test_the_chains_one_call_scoring_is_the_per_world_hooks_bit_for_bit(task_id):
    """The chain scores every world of a batch in one kernel call (``Chain.score_cycle``); the
    per-world hooks (``Task.score_cycle``, the default) on copies of the same tasks give the same
    rewards, terms and success, and leave the tasks in the same state, over episodes the rules
    complete (straightness paid on chain-v1) and restarts."""
    import copy

    from proteo_env.tasks.base import Task

    env = proteo_env.make_batched(task_id, 8, control="move", n_modules=6, max_cycles=60)
    env.reset(seed=3)
    rng, completed = np.random.default_rng(1), 0
    for _ in range(150):
        mask = env.last_observation().action_mask.reshape(8, env.n_agents, -1)
        moves = np.where(rng.random((8, env.n_agents)) < 0.8, 0, np.argmax(mask * rng.random(mask.shape), axis=2))
        before = copy.deepcopy(env.tasks)
        result = env.step_arrays(moves[..., None])
        per_world = Task.score_cycle.__func__(type(before[0]), before, env.world_batch, env.last_moved, env.cycles)
        assert result.terms == per_world.terms
        assert result.reward.tobytes() == per_world.reward.tobytes()
        assert result.terminated.tolist() == per_world.success.tolist()
        for mine, theirs in zip(env.tasks, before):
            assert (mine._last, mine._previous) == (theirs._last, theirs._previous)
            np.testing.assert_array_equal(mine._probe.degree, theirs._probe.degree)
        completed += int(result.terminated.sum())
        if result.done.any():
            env.reset_worlds(result.done)
    assert completed >= 3  # random legal moves of a fifth of the modules string six modules into chains

"""PettingZoo citizenship of every registered task, and the contracts of the agent interface.

PettingZoo 1.27's ``parallel_api_test`` does not check that observations lie in their spaces
and ``parallel_seed_test`` compares one step only (see ECOSYSTEM.md), so besides PettingZoo's
own tests this file checks spaces, dtypes, infos, rewards, termination and the masked move
semantics itself, over many steps.
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import math
import pickle
import types
import warnings

import numpy as np
import pytest
from conftest import task_params
from gymnasium import spaces
from pettingzoo.test import api_test, max_cycles_test, parallel_api_test, parallel_seed_test, state_test
from pettingzoo.utils import parallel_to_aec

import proteo_env
from proteo_env.spaces import N_MOVES, ModuleActionSpace

TASK_IDS = task_params()
MOTION_MODELS = list(proteo_env.MOTION_MODELS)

# Warnings PettingZoo's tests raise for a Dict observation with a MultiDiscrete action; anything
# else they warn about is a failure.
EXPECTED_WARNINGS = (
    "Observation is not a NumPy array",
    "Observation numpy array is all zeros",
    "Action mask is not a NumPy array",
    "space for each agent probably should be gymnasium.spaces.box or gymnasium.spaces.discrete",
)


def _check_warnings(record):
    unexpected = [str(w.message) for w in record if not any(text in str(w.message) for text in EXPECTED_WARNINGS)]
    assert not unexpected, f"unexpected warnings: {unexpected}"


# ---------------------------------------------------------------------- PettingZoo's own tests
@pytest.mark.parametrize("task_id", TASK_IDS)
def test_parallel_api(task_id, make_small):
    env = make_small(task_id)
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        parallel_api_test(env, num_cycles=40)
    _check_warnings(record)


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_aec_api(task_id, make_small):
    """``api_test`` on the AEC conversion: it checks observations against spaces and dtypes."""
    env = parallel_to_aec(make_small(task_id, max_cycles=30))
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        api_test(env, num_cycles=40)
    _check_warnings(record)


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_max_cycles(task_id, make_small):
    def parallel_env(max_cycles):
        return make_small(task_id, max_cycles=max_cycles)

    def aec_env(max_cycles):
        return parallel_to_aec(parallel_env(max_cycles))

    max_cycles_test(types.SimpleNamespace(parallel_env=parallel_env, env=aec_env))


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_state(task_id, make_small):
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        state_test(parallel_to_aec(make_small(task_id)), make_small(task_id), num_cycles=10)
    _check_warnings(record)


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_parallel_seed(task_id, make_small):
    parallel_seed_test(lambda: make_small(task_id), num_cycles=20)


# ---------------------------------------------------------------------- static contracts
@pytest.mark.parametrize("task_id", TASK_IDS)
def test_metadata_agents_and_spaces(task_id, make_small):
    env = make_small(task_id)
    meta = env.metadata
    assert isinstance(meta["name"], str) and meta["name"]
    assert list(meta["render_modes"]) and isinstance(meta["render_fps"], int)
    assert meta["is_parallelizable"] is True

    n = len(env.possible_agents)
    assert n > 0
    assert env.possible_agents == [f"module_{i}" for i in range(n)]
    first = list(env.possible_agents)
    env.reset(seed=0)
    assert env.possible_agents == first and env.agents == first
    assert env.agents is not env.possible_agents
    assert env.world.n_agents == n

    for agent in env.possible_agents:
        assert env.observation_space(agent) is env.observation_space(env.possible_agents[0])
        assert env.action_space(agent) is env.action_space(env.possible_agents[0])
    obs_space = env.observation_space(first[0])
    assert isinstance(obs_space, spaces.Dict)
    assert obs_space["action_mask"].shape == (N_MOVES,) and obs_space["action_mask"].dtype == np.int8
    act_space = env.action_space(first[0])
    assert isinstance(act_space, ModuleActionSpace)
    assert act_space.nvec[0] == N_MOVES
    assert list(act_space.nvec) == list(env.action_layout.nvec)
    assert len(env.action_layout.field_names) == act_space.shape[0]
    assert isinstance(env.state_space, spaces.Box)
    assert env.state_space.contains(env.state())


def test_directions():
    d = proteo_env.DIRECTIONS
    assert d.shape == (12, 3)
    expected = {p for v in itertools.product((1, -1), (1, -1), (0,)) for p in itertools.permutations(v)}
    assert len(expected) == 12
    assert {tuple(int(c) for c in row) for row in d} == expected
    with pytest.raises(ValueError):
        d[0, 0] = 5


# ---------------------------------------------------------------------- dynamic contracts
def _check_observation(space, obs):
    assert set(obs) == set(space.spaces), f"observation keys {sorted(obs)} != {sorted(space.spaces)}"
    for key, sub in space.spaces.items():
        value = obs[key]
        assert isinstance(value, np.ndarray), key
        assert value.dtype == sub.dtype, f"{key}: dtype {value.dtype} != {sub.dtype}"
        assert value.shape == sub.shape, f"{key}: shape {value.shape} != {sub.shape}"
        assert sub.contains(value), f"{key} out of its space: {value}"
    assert space.contains(obs)
    mask = obs["action_mask"]
    assert mask[0] == 1, "stay must always be legal"
    assert set(np.unique(mask)) <= {0, 1}
    # a legal move goes to an empty neighbour site
    assert np.all(obs["neighbour_kind"][:12][mask[1:] == 1] == 0)


def _check_infos(env, infos, agents, metric_keys=None):
    info = infos[agents[0]]
    for agent in agents:
        assert infos[agent] == info, "all agents share the cycle's info"
    assert info["cycle"] == env.cycle
    metrics = {k for k in info if k.startswith("metric/")}
    assert metrics, "infos report metric/... keys"
    if metric_keys is not None:
        assert metrics == metric_keys, "the same metric keys every cycle"
    return info, metrics


@pytest.mark.parametrize("obs_radius", [1, 2])
@pytest.mark.parametrize("task_id", TASK_IDS)
def test_many_steps_obs_infos_rewards(task_id, obs_radius, make_small, actions_from):
    env = make_small(task_id, obs_radius=obs_radius, max_cycles=100)
    space = env.observation_space(env.possible_agents[0])
    assert space["neighbour_kind"].shape == ((12,) if obs_radius == 1 else (54,))
    rng = np.random.default_rng(1)
    obs, infos = env.reset(seed=3)
    assert set(obs) == set(infos) == set(env.agents)
    for agent in env.agents:
        _check_observation(space, obs[agent])
    _, metric_keys = _check_infos(env, infos, env.agents)
    reward_keys = None
    while env.agents:
        agents = list(env.agents)
        obs, rewards, terms, truncs, infos = env.step(actions_from(env, obs, rng, p_unmasked=0.3))
        for d in (obs, rewards, terms, truncs, infos):
            assert set(d) == set(agents)
        info, _ = _check_infos(env, infos, agents, metric_keys)
        assert isinstance(info["moved"], int) and 0 <= info["moved"] <= len(agents)
        terms_now = {k: v for k, v in info.items() if k.startswith("reward/")}
        if reward_keys is None:
            reward_keys = set(terms_now)
        assert set(terms_now) == reward_keys, "the same reward terms every cycle"
        total = float(sum(terms_now.values()))
        for agent in agents:
            assert isinstance(rewards[agent], float)
            assert math.isclose(rewards[agent], total, rel_tol=1e-12, abs_tol=1e-12)
            assert isinstance(terms[agent], bool) and isinstance(truncs[agent], bool)
            _check_observation(space, obs[agent])
        assert env.state_space.contains(env.state())
        assert env.observation_space(agents[0]) is space
    assert env.cycle <= 100
    assert env.possible_agents == [f"module_{i}" for i in range(len(env.possible_agents))]


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_terminated_and_truncated_are_distinct(task_id, make_small, actions_from):
    max_cycles = 6
    env = make_small(task_id, max_cycles=max_cycles)
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=0)
    while True:
        agents = list(env.agents)
        obs, _, terms, truncs, _ = env.step(actions_from(env, obs, rng))
        term, trunc = terms[agents[0]], truncs[agents[0]]
        assert all(v == term for v in terms.values()) and all(v == trunc for v in truncs.values())
        assert not (term and trunc), "terminated (success) and truncated (limit) are exclusive"
        assert trunc == (env.cycle >= max_cycles and not term)
        if term or trunc:
            break
        assert env.agents == agents
    assert env.agents == []
    with pytest.raises(RuntimeError, match="reset"):
        env.step({})
    obs, _ = env.reset(seed=1)
    assert env.agents == env.possible_agents and env.cycle == 0


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_pickle_round_trip(task_id, make_small, actions_from):
    env = make_small(task_id)
    rng = np.random.default_rng(5)
    obs, _ = env.reset(seed=11)
    for _ in range(3):
        obs, *_ = env.step(actions_from(env, obs, rng))
    twin = pickle.loads(pickle.dumps(env))
    assert twin.cycle == env.cycle and twin.agents == env.agents
    obs_twin = obs
    for _ in range(15):
        if not env.agents:
            break
        actions = actions_from(env, obs, rng, p_unmasked=0.5)
        out = env.step(actions)
        out_twin = twin.step({a: v.copy() for a, v in actions.items()})
        obs, obs_twin = out[0], out_twin[0]
        for agent in obs:
            for key in obs[agent]:
                np.testing.assert_array_equal(obs[agent][key], obs_twin[agent][key])
        assert out[1:] == out_twin[1:]
        np.testing.assert_array_equal(env.state(), twin.state())
        for key, value in env.engine.snapshot().items():
            np.testing.assert_array_equal(value, twin.engine.snapshot()[key])
    # a pickled env can be reset too
    assert twin.reset(seed=0)[0].keys() == env.reset(seed=0)[0].keys()


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_world_view_is_read_only(task_id, make_small):
    env = make_small(task_id)
    with pytest.raises(RuntimeError):
        env.world  # noqa: B018  (no world before reset)
    env.reset(seed=0)
    w = env.world
    n = env.engine.n_modules
    assert w.positions.shape == (n, 3) and w.positions.dtype == np.int64
    assert w.modes.shape == (n,)
    assert w.scents.shape == (env.task.n_channels, n)
    assert w.anchored.shape == (n,)
    assert w.solid_sites.ndim == 2 and w.solid_sites.shape[1] == 3
    assert w.object_sites.ndim == 2 and w.object_sites.shape[1] == 3
    assert len(w.box) == 3 and all(isinstance(s, int) and s > 0 for s in w.box)
    assert w.motion_model in proteo_env.MOTION_MODELS
    assert isinstance(w.keep_connected, bool) and isinstance(w.floor, bool)
    assert w.n_agents == len(env.possible_agents)
    assert w.cycle == env.cycle == 0
    assert len(w.mode_names) == env.action_layout.n_modes
    # sites are distinct FCC sites inside the box
    assert np.all(w.positions.sum(axis=1) % 2 == 0)
    assert np.all((w.positions >= 0) & (w.positions < np.array(w.box)))
    assert len({tuple(p) for p in w.positions}) == n

    before = env.engine.positions.copy()
    for name in ("positions", "modes", "scents", "anchored", "solid_sites"):
        arr = getattr(w, name)
        with pytest.raises(ValueError):
            arr[...] = 0 if arr.dtype != np.bool_ else True
    with pytest.raises(dataclasses.FrozenInstanceError):
        w.positions = np.zeros((n, 3), dtype=np.int64)
    np.testing.assert_array_equal(env.engine.positions, before)
    assert env.world is not w, "each access gives a fresh snapshot"


def _stay_actions(env, obs):
    lay = env.action_layout
    return {a: lay.encode(move=0, mode=int(obs[a]["own_mode"][0])) for a in env.agents}


@pytest.mark.parametrize("keep_connected", [True, False])
@pytest.mark.parametrize("motion_model", MOTION_MODELS)
@pytest.mark.parametrize("task_id", TASK_IDS)
def test_masked_move_semantics(task_id, motion_model, keep_connected, make_small, actions_from):
    """A lone move happens exactly when its mask bit is 1, and lands on the target site."""
    env = make_small(task_id, motion_model=motion_model, keep_connected=keep_connected)
    rng = np.random.default_rng(2)
    obs, _ = env.reset(seed=4)
    n_legal = n_illegal = 0
    for round_ in range(3):
        if round_:
            for _ in range(4):
                if not env.agents:
                    break
                obs, *_ = env.step(actions_from(env, obs, rng))
        if not env.agents:
            break
        start = env.engine.positions
        stay = _stay_actions(env, obs)
        for i, agent in enumerate(env.agents):
            mask = obs[agent]["action_mask"]
            for move in range(1, N_MOVES):
                trial = copy.deepcopy(env)
                actions = {a: v.copy() for a, v in stay.items()}
                actions[agent][0] = move
                trial.step(actions)
                end = trial.engine.positions
                others = np.arange(len(start)) != i
                np.testing.assert_array_equal(end[others], start[others])
                if mask[move]:
                    n_legal += 1
                    target = start[i] + proteo_env.DIRECTIONS[move - 1]
                    assert tuple(end[i]) == tuple(target), (
                        f"{agent}: legal move {move} did not reach {tuple(target)} ({motion_model})"
                    )
                    assert trial.last_moved[i]
                else:
                    n_illegal += 1
                    assert tuple(end[i]) == tuple(start[i]), f"{agent}: masked move {move} happened ({motion_model})"
                    assert not trial.last_moved.any()
    assert n_illegal > 0
    if motion_model == "minimal":
        assert n_legal > 0, "some module of a small blob can move under the minimal model"


def test_sample_with_move_mask_only_samples_legal_moves():
    space = ModuleActionSpace(np.array([N_MOVES, 4, 3, 13, 16]))
    space.seed(0)
    rng = np.random.default_rng(0)
    for _ in range(200):
        mask = (rng.random(N_MOVES) < 0.3).astype(np.int8)
        mask[0] = 1
        legal = set(np.flatnonzero(mask))
        seen = set()
        for _ in range(20):
            action = space.sample(mask)
            assert space.contains(action)
            assert int(action[0]) in legal
            seen.add(int(action[0]))
        assert seen <= legal
    only_stay = np.zeros(N_MOVES, dtype=np.int8)
    only_stay[0] = 1
    assert all(space.sample(only_stay)[0] == 0 for _ in range(50))
    # every legal move is reachable and the other fields are not restricted by the move mask
    mask = np.zeros(N_MOVES, dtype=np.int8)
    mask[[0, 3, 12]] = 1
    draws = np.array([space.sample(mask) for _ in range(600)])
    assert set(draws[:, 0]) == {0, 3, 12}
    assert set(draws[:, 1]) == {0, 1, 2, 3}
    assert set(draws[:, 4]) == set(range(16))
    # a full MultiDiscrete mask (tuple) still works as in gymnasium
    full = tuple(np.ones(n, dtype=np.int8) for n in space.nvec)
    assert space.contains(space.sample(full))


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_env_sample_with_observation_mask(task_id, make_small):
    env = make_small(task_id)
    obs, _ = env.reset(seed=2)
    for agent in env.agents:
        mask = obs[agent]["action_mask"]
        space = env.action_space(agent)
        for _ in range(10):
            assert mask[space.sample(mask)[0]] == 1


def test_task_ids_split_into_name_and_version_in_one_place():
    from proteo_env.registry import split_task_id, task_name

    assert split_task_id("chain-v1") == ("chain", 1) and split_task_id("chain") == ("chain", None)
    assert split_task_id("my-velocity-v12") == ("my-velocity", 12) and task_name("my-velocity") == "my-velocity"
    assert all(task_name(task_id) == cls.name for task_id, cls in proteo_env.TASKS.items())

"""Bad input: every bad input gets one clear error naming the field, the value and what
is allowed; a running environment loses no state.

Config errors are :class:`proteo_env.ConfigError`, layout errors :class:`proteo_env.LayoutError`
(both ``ValueError`` subclasses); bad actions raise ``ValueError``.
"""

from __future__ import annotations

import pickle
import re

import numpy as np
import pytest
from conftest import task_params

import proteo_env
from proteo_env import ConfigError, LayoutError
from proteo_env.config import ENV_KEYS, PHYSICS_KEYS, load_run_config
from proteo_env.core.world import Physics, World
from proteo_env.layouts import parse_layout

TASK_IDS = task_params()


# ---------------------------------------------------------------------- helpers
@pytest.fixture(params=TASK_IDS)
def running(request, make_small, actions_from):
    """A small env of each task, reset and a few cycles in, with its last observations."""
    env = make_small(request.param)
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(3):
        obs, *_ = env.step(actions_from(env, obs, rng))
    assert env.agents, "the episode must still be running"
    return env, obs


def _stay(env, obs):
    lay = env.action_layout
    return {a: lay.encode(move=0, mode=int(obs[a]["own_mode"][0])) for a in env.agents}


def _raises_and_unchanged(env, obs, call, error, match):
    """``call()`` raises ``error`` matching ``match`` and leaves ``env`` exactly as it was."""
    twin = pickle.loads(pickle.dumps(env))  # taken before the bad call
    snap = env.engine.snapshot()
    cycle, agents, state = env.cycle, list(env.agents), env.state().copy()
    with pytest.raises(error, match=match):
        call()
    after = env.engine.snapshot()
    for key in snap:
        np.testing.assert_array_equal(after[key], snap[key], err_msg=key)
    assert env.cycle == cycle and env.agents == agents
    np.testing.assert_array_equal(env.state(), state)
    # stepping still works, and goes exactly as it would have without the bad call
    actions = _stay(env, obs)
    out = env.step({a: v.copy() for a, v in actions.items()})
    out_twin = twin.step({a: v.copy() for a, v in actions.items()})
    assert env.cycle == cycle + 1
    assert out[1:] == out_twin[1:]
    for key, value in env.engine.snapshot().items():
        np.testing.assert_array_equal(value, twin.engine.snapshot()[key], err_msg=key)


# ---------------------------------------------------------------------- configs given to make
@pytest.mark.parametrize("task_id", TASK_IDS)
def test_unknown_config_key_lists_allowed_keys(task_id):
    with pytest.raises(ConfigError, match=r"unknown key 'bogus_key'.*allowed: ") as info:
        proteo_env.make(task_id, bogus_key=1)
    message = str(info.value)
    allowed = message.split("allowed: ", 1)[1]
    for key in (*ENV_KEYS, *PHYSICS_KEYS, *proteo_env.TASKS[task_id].param_names()):
        assert key in allowed, f"{key} not listed in {message!r}"


@pytest.mark.parametrize("task_id", TASK_IDS)
@pytest.mark.parametrize(
    "key, value, expected",
    [
        ("max_cycles", "10", "int"),
        ("max_cycles", 2.5, "int"),
        ("keep_connected", "yes", "bool"),
        ("scent_sweeps", True, "int"),
        ("motion_model", 3, "str"),
    ],
)
def test_wrong_type_of_config_value(task_id, key, value, expected):
    with pytest.raises(
        ConfigError,
        match=rf"{key}={re.escape(repr(value))} is not allowed; "
        rf"allowed: a value of type {expected}",
    ):
        proteo_env.make(task_id, **{key: value})


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_bad_motion_model(task_id):
    allowed = ", ".join(proteo_env.MOTION_MODELS)
    with pytest.raises(ConfigError, match=rf"motion_model='cube' is not known; allowed: {allowed}"):
        proteo_env.make(task_id, motion_model="cube")


def test_unknown_task_id_lists_valid_ids():
    valid = ", ".join(sorted(proteo_env.TASKS))
    with pytest.raises(ValueError, match=rf"unknown task 'nope-v0'; allowed: {re.escape(valid)}"):
        proteo_env.make("nope-v0")
    for task_id in proteo_env.TASKS:
        assert task_id in valid


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_scent_sweeps_zero(task_id):
    with pytest.raises(ConfigError, match=r"scent_sweeps=0 is not allowed; allowed: an integer in \[1, 2\*\*31 - 1\]"):
        proteo_env.make(task_id, scent_sweeps=0)


@pytest.mark.parametrize("task_id", TASK_IDS)
@pytest.mark.parametrize(
    "key, value, match",
    [
        ("max_cycles", 0, r"max_cycles=0 is not allowed; allowed: an integer >= 1"),
        ("obs_radius", 3, r"obs_radius=3 is not allowed; allowed: 1 or 2"),
        ("scent_max", 0, r"scent_max=0 is not allowed; allowed: an integer in \[1, 2\*\*31 - 2\]"),
    ],
)
def test_config_value_out_of_range(task_id, key, value, match):
    with pytest.raises(ConfigError, match=match):
        proteo_env.make(task_id, **{key: value})


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_bad_render_mode(task_id):
    with pytest.raises(ValueError, match=r"render_mode='rgb' is not allowed; allowed: None or ansi, rgb_array, human"):
        proteo_env.make(task_id, render_mode="rgb")


def test_bad_task_parameter():
    with pytest.raises(ConfigError, match=r"task 'sandbox-v0': n_modules=0 is not allowed; allowed: an integer >= 1"):
        proteo_env.make("sandbox-v0", n_modules=0)
    with pytest.raises(ConfigError, match=r"layout='foo' is not allowed; allowed: blob, ball, line"):
        proteo_env.make("sandbox-v0", layout="foo")
    # an object 0 layers away could overlap the base at reset; it is refused when the env is made
    with pytest.raises(ConfigError, match=r"distance=0 is not allowed; allowed: an integer in 1..100"):
        proteo_env.make("grasp-v0", distance=0)


# ---------------------------------------------------------------------- layouts given to the world
def _world(positions, **kwargs):
    kwargs.setdefault("physics", Physics())
    positions = np.asarray(positions)
    return World(size=kwargs.pop("size", (6, 6, 6)), positions=positions, n_agents=len(positions), **kwargs)


def test_overlapping_modules():
    with pytest.raises(LayoutError, match=r"two modules at site \(2, 2, 2\); allowed: at most one module per site"):
        _world([[2, 2, 2], [3, 3, 2], [2, 2, 2]])


def test_module_in_a_solid_site():
    with pytest.raises(LayoutError, match=r"module site \(3, 3, 2\) is a solid site; allowed: empty sites only"):
        _world([[2, 2, 2], [3, 3, 2]], solid=[[3, 3, 2]])
    with pytest.raises(LayoutError, match=r"module site \(3, 3, 2\) is an object site; allowed: empty sites only"):
        _world([[2, 2, 2], [3, 3, 2]], object_sites=[[3, 3, 2]])


@pytest.mark.parametrize("site", [(6, 0, 0), (-1, 1, 0), (0, 0, 6), (1, 7, 0)])
def test_module_outside_the_box(site):
    match = (
        rf"module site \({site[0]}, {site[1]}, {site[2]}\) is outside the box \(6, 6, 6\); "
        r"allowed: 0 <= site < size"
    )
    with pytest.raises(LayoutError, match=match):
        _world([site], physics=Physics(keep_connected=False))


def test_solid_site_outside_the_box():
    with pytest.raises(LayoutError, match=r"solid site \(9, 9, 0\) is outside the box \(6, 6, 6\); allowed: "):
        _world([[0, 0, 0]], solid=[[9, 9, 0]])


def test_non_fcc_site():
    with pytest.raises(
        LayoutError,
        match=r"module site \(1, 0, 0\) is not an FCC site; "
        r"allowed: integer sites with x \+ y \+ z even",
    ):
        _world([[0, 0, 0], [1, 0, 0]])


def test_too_many_agents():
    with pytest.raises(LayoutError, match=r"n_agents=3 is not allowed; allowed: 0\.\.2"):
        World(size=(6, 6, 6), positions=[[0, 0, 0], [1, 1, 0]], n_agents=3, physics=Physics())


def test_disconnected_start():
    sites = [[0, 0, 0], [1, 1, 0], [4, 0, 0]]
    with pytest.raises(
        LayoutError,
        match=r"positions form 2 connected pieces; allowed: one connected whole "
        r"when keep_connected=True",
    ):
        _world(sites)
    world = _world(sites, physics=Physics(keep_connected=False))
    assert world.n_components() == 2


def test_disconnected_layout_file_through_the_env(tmp_path):
    path = tmp_path / "two_pieces.txt"
    path.write_text("size 7 3 1\nz = 0\nm.m...m\n.m.....\n")
    with pytest.raises(LayoutError, match=r"positions form 2 connected pieces; allowed: one connected whole"):
        proteo_env.make("sandbox-v0", layout=str(path))  # checked at construction, not at the first reset
    env = proteo_env.make("sandbox-v0", layout=str(path), keep_connected=False)
    env.reset(seed=0)
    assert env.engine.n_components() == 2
    env.step(_stay(env, env.reset(seed=0)[0]))


# ---------------------------------------------------------------------- layout texts and files
@pytest.mark.parametrize(
    "text, match",
    [
        ("floor\nz = 0\nm.x.m\n", r"line 3, column 3: character 'x' is not in the legend; allowed: '\.', 'm', 'F'"),
        ("z = 0\nm.m\n.m.\nm.?\n", r"line 4, column 3: character '\?' is not in the legend"),
        (
            "z = 0\nmm\n",
            r"line 2, column 2: 'm' at \(1, 0, 0\) is not an FCC site; allowed: '\.' where x \+ y \+ z is odd",
        ),
        ("size 4 4 2\nz = 0\nm.m.\nz = 1\nm...\n", r"line 5, column 1: 'm' at \(0, 0, 1\) is not an FCC site"),
        ("z = 0\n.#\n", r"line 2, column 2: '#' at \(1, 0, 0\) is not an FCC site"),
        ("sise 3 3 3\nz = 0\nm\n", r"line 1: 'sise 3 3 3' is not a header; allowed: 'size X Y Z', 'floor'"),
        ("z = a\nm\n", r"line 1: 'z = a' is not a layer header; allowed: 'z = K'"),
    ],
)
def test_malformed_layout_text(text, match):
    with pytest.raises(LayoutError, match=match):
        parse_layout(text)


def test_malformed_layout_file_through_make(tmp_path):
    path = tmp_path / "bad.txt"
    path.write_text("; a comment\nz = 0\nm.m\n.m.\nmm.\n")
    with pytest.raises(LayoutError, match=r"line 5, column 2: 'm' at \(1, 2, 0\) is not an FCC site"):
        proteo_env.make("sandbox-v0", layout=str(path))


def test_missing_layout_file(tmp_path):
    path = str(tmp_path / "missing.txt")
    with pytest.raises(
        ValueError,
        match=rf"layout={re.escape(repr(path))}: no such file; "
        r"allowed: a path to a layout text file",
    ):
        proteo_env.make("sandbox-v0", layout=path)


# ---------------------------------------------------------------------- run config files
def test_yaml_run_config_with_unknown_key(tmp_path):
    path = tmp_path / "run.yaml"
    path.write_text("task: sandbox-v0\nn_modules: 12\nmotion_modle: sphere\n")
    task_id, overrides = load_run_config(path)
    assert task_id == "sandbox-v0"
    with pytest.raises(ConfigError, match=r"unknown key 'motion_modle' for task 'sandbox-v0'; allowed: .*motion_model"):
        proteo_env.make(task_id, **overrides)


def test_yaml_run_config_with_wrong_type(tmp_path):
    path = tmp_path / "run.yaml"
    path.write_text("task: sandbox-v0\nmax_cycles: ten\n")
    task_id, overrides = load_run_config(path)
    with pytest.raises(ConfigError, match=r"max_cycles='ten' is not allowed; allowed: a value of type int"):
        proteo_env.make(task_id, **overrides)


def test_valid_yaml_run_config(tmp_path):
    path = tmp_path / "run.yaml"
    path.write_text("task: sandbox-v0\nn_modules: 12\nmotion_model: minimal\nmax_cycles: 7\n")
    task_id, overrides = load_run_config(path)
    assert (task_id, overrides) == ("sandbox-v0", {"n_modules": 12, "motion_model": "minimal", "max_cycles": 7})
    env = proteo_env.make(task_id, **overrides)
    env.reset(seed=0)
    assert env.world.motion_model == "minimal" and env.max_cycles == 7 and len(env.agents) == 12


@pytest.mark.parametrize(
    "text, match",
    [
        ("task: [sandbox-v0\nn_modules: 3\n", r"is not valid YAML"),
        ("task: sandbox-v0\n  n_modules: : 3\n", r"is not valid YAML"),
        ("- task\n- sandbox-v0\n", r"a mapping with a 'task' key is required"),
        ("n_modules: 3\n", r"a mapping with a 'task' key is required"),
    ],
)
def test_malformed_yaml_run_config(tmp_path, text, match):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=rf"config file {re.escape(repr(str(path)))}.*{match}"):
        load_run_config(path)


def test_missing_yaml_run_config(tmp_path):
    path = str(tmp_path / "nope.yaml")
    with pytest.raises(ConfigError, match=rf"config file {re.escape(repr(path))} does not exist; allowed: "):
        load_run_config(path)


# ---------------------------------------------------------------------- actions on a running env
def test_wrong_action_shape_for_every_agent(running):
    env, obs = running
    n = env.action_layout.length
    actions = {a: np.zeros(n + 1, dtype=np.int64) for a in env.agents}
    match = rf"action of module_0: shape \({n + 1},\) is not allowed; allowed: \({n},\) = \['move', 'mode'"
    _raises_and_unchanged(env, obs, lambda: env.step(actions), ValueError, match)


@pytest.mark.parametrize("bad", [np.zeros(2, dtype=np.int64), np.zeros((1, 5), dtype=np.int64), 3, None])
def test_wrong_action_shape_for_one_agent(running, bad):
    env, obs = running
    actions = _stay(env, obs)
    actions["module_1"] = bad
    shape = re.escape(str(np.shape(bad)))
    match = rf"action of module_1: shape {shape} is not allowed; allowed: \({env.action_layout.length},\)"
    _raises_and_unchanged(env, obs, lambda: env.step(actions), ValueError, match)


def test_wrong_batch_shape_in_the_array_api(running):
    env, obs = running
    lay = env.action_layout
    n_agents = len(env.possible_agents)
    for batch, match in (
        (
            np.zeros((n_agents - 1, lay.length), dtype=np.int64),
            rf"actions shape \({n_agents - 1}, {lay.length}\) is not allowed; allowed: \({n_agents}, {lay.length}\)",
        ),
        (
            np.zeros((n_agents, lay.length + 2), dtype=np.int64),
            rf"actions shape \({n_agents}, {lay.length + 2}\) is not allowed; allowed: \({n_agents}, {lay.length}\)",
        ),
    ):
        _raises_and_unchanged(env, obs, lambda b=batch: env.step_arrays(b), ValueError, match)


@pytest.mark.parametrize("dtype", [np.int8, np.uint8, np.int32, np.uint64])
def test_an_action_batch_of_any_integer_dtype_is_checked_value_by_value(running, dtype):
    env, obs = running
    lay = env.action_layout
    batch = np.zeros((len(env.possible_agents), lay.length), dtype=dtype)
    batch[2, lay.mode] = len(env.task.modes)  # one past the last mode
    match = rf"action of module_2: mode={len(env.task.modes)} is not allowed; allowed: 0\.\.{len(env.task.modes) - 1}"
    _raises_and_unchanged(env, obs, lambda: env.step_arrays(batch), ValueError, match)
    batch[2, lay.mode] = 0
    env.step_arrays(batch)  # the same batch in range is taken


@pytest.mark.parametrize(
    "field, value",
    [
        ("move", 13),
        ("move", -1),
        ("mode", "n_modes"),
        ("role_0", 3),
        ("message_target", 13),
        ("message_value", -1),
        ("message_value", "too_big"),
    ],
)
def test_action_value_out_of_range(running, field, value):
    env, obs = running
    lay = env.action_layout
    column = lay.field_names.index(field)
    if value == "n_modes":
        value = lay.n_modes
    elif value == "too_big":
        value = lay.n_message_values + 1
    actions = _stay(env, obs)
    actions["module_2"][column] = value
    match = rf"action of module_2: {field}={value} is not allowed; allowed: 0\.\.{lay.nvec[column] - 1}$"
    _raises_and_unchanged(env, obs, lambda: env.step(actions), ValueError, match)


def test_missing_agent_in_actions(running):
    env, obs = running
    actions = _stay(env, obs)
    del actions["module_1"]
    match = r"actions missing for 1 agents \(first: module_1\); allowed: one action for every agent in env.agents"
    _raises_and_unchanged(env, obs, lambda: env.step(actions), ValueError, match)
    _raises_and_unchanged(
        env, obs, lambda: env.step({}), ValueError, rf"actions missing for {len(env.agents)} agents \(first: module_0\)"
    )


def test_float_action_is_rejected_not_truncated(running):
    env, obs = running
    actions = _stay(env, obs)
    actions["module_1"] = actions["module_1"].astype(float) + 0.7
    _raises_and_unchanged(
        env,
        obs,
        lambda: env.step(actions),
        ValueError,
        r"action of module_1: dtype float64 is not allowed; allowed: integers",
    )


def test_action_for_unknown_agent_is_rejected(running):
    env, obs = running
    actions = _stay(env, obs)
    actions["module_999"] = actions["module_0"]
    _raises_and_unchanged(
        env,
        obs,
        lambda: env.step(actions),
        ValueError,
        r"actions for 1 unknown agents \(first: 'module_999'\); allowed: the agents in env.agents",
    )


@pytest.mark.parametrize("seed", [-1, "a", 1.5, True, [1, 2]])
def test_a_seed_that_is_not_a_non_negative_integer_is_refused_naming_it(seed):
    env = proteo_env.make("chain-v0", n_modules=6)
    with pytest.raises(ConfigError, match=re.escape(f"seed={seed!r} is not allowed; allowed: None or an integer >= 0")):
        env.reset(seed=seed)
    batch = proteo_env.make_batched("chain-v0", 2, n_modules=6)
    with pytest.raises(ConfigError, match=re.escape(f"seed={seed!r} is not allowed")):
        batch.reset(seed=seed)
    env.reset(seed=np.int64(3))  # NumPy integers are seeds


def test_a_world_too_large_for_memory_is_refused_before_anything_is_allocated():
    from proteo_env.core.world import LayoutError, Physics, World

    with pytest.raises(
        ConfigError,
        match=r"n_modules=1000000000 needs about 3.81e\+03 GiB at reset \(4096 bytes per module\); "
        r"allowed: at most about [\d,]+ modules, what the memory available \(.* GiB\) holds",
    ):
        proteo_env.make("chain-v1", n_modules=10**9)
    with pytest.raises(LayoutError, match=r"a box of 100000 x 100000 x 100 sites needs .* GiB for its grid"):
        World(size=(10**5, 10**5, 100), positions=[[0, 0, 0]], n_agents=1, physics=Physics())
    proteo_env.make("chain-v1", n_modules=10**5)  # its grid covers the modules, not the box (test_growing_world.py)

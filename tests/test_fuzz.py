"""Bad input found by search, not by hand: hypothesis draws env settings, array-API actions,
program texts and checkpoint metadata, and each must either work or give the surface's one clear
error (a ``ConfigError``/``ValueError``/``CheckpointError`` whose message says what is allowed),
never another exception, a crash, or a changed state.

A few seconds of each in the test suite; ``make fuzz`` runs them with ``PROTEO_FUZZ_EXAMPLES``
(default there 2,000) examples each.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import proteo_env
from proteo_env.config import ENV_KEYS, PHYSICS_KEYS, ConfigError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = int(os.environ.get("PROTEO_FUZZ_EXAMPLES", "40"))
SETTINGS = dict(
    max_examples=EXAMPLES,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
CLEAR = ("is not allowed", "allowed:", "unknown key")
"""Every clear error names what is allowed."""

values = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-50, 600),  # larger worlds are legal and slow: the sizes beyond are the huge ones, refused at once
    st.sampled_from([2**31, 2**63, 2**70, -(2**63)]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
    st.lists(st.integers(-5, 50), max_size=4),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
)


def clear(err: Exception) -> bool:
    return any(word in str(err) for word in CLEAR)


# ---------------------------------------------------------------------- env settings
@settings(**SETTINGS)
@given(
    key=st.sampled_from(
        [*ENV_KEYS, *PHYSICS_KEYS, "n_modules", "time_penalty", "T", "B", "first_node", "bogus", "control"]
    ),
    value=values,
    task=st.sampled_from(["chain-v1", "branch-v0", "grasp-v0", "table-v2", "locomotion-v0"]),
)
def test_any_setting_makes_an_env_or_one_clear_error(task, key, value):
    try:
        env = proteo_env.make(task, **{key: value})
    except (ConfigError, ValueError) as err:
        assert clear(err), f"{task} {key}={value!r}: {err}"
        return
    env.reset(seed=0)  # what make accepts, runs
    env.step_arrays(np.zeros((len(env.possible_agents), len(env.control_fields)), dtype=np.int64))


# ---------------------------------------------------------------------- the array API's actions
@st.composite
def action_arrays(draw):
    shape = draw(st.sampled_from([(12, 5), (12, 1), (11, 5), (12, 6), (12,), (1, 12, 5), (0, 5)]))
    kind = draw(st.sampled_from(["int64", "int8", "uint8", "float64", "bool", "object"]))
    low, high = draw(st.sampled_from([(0, 2), (-3, 20), (-(2**40), 2**40)]))
    data = np.random.default_rng(draw(st.integers(0, 2**32 - 1))).integers(low, high, size=shape)
    return data.astype(kind) if kind != "object" else data.astype(object)


@settings(**SETTINGS)
@given(actions=action_arrays(), level=st.sampled_from(["full", "move", "move+mode"]))
def test_any_action_array_steps_or_is_refused_and_changes_nothing(actions, level):
    env = proteo_env.make("chain-v1", n_modules=12, control=level)
    env.reset(seed=3)
    before = env.engine.positions.copy(), env.cycle
    try:
        env.step_arrays(actions)
    except ValueError as err:
        assert clear(err), f"{actions.dtype} {actions.shape}: {err}"
        assert np.array_equal(env.engine.positions, before[0]) and env.cycle == before[1]


# ---------------------------------------------------------------------- program texts
PROGRAMS = {name: (ROOT / f"baselines/programs/{name}.yaml").read_text() for name in ("chain", "branch", "grasp")}
TASKS = {"chain": "chain-v1", "branch": "branch-v0", "grasp": "grasp-v0"}
TOKENS = ["nan", "inf", "-1", "1e309", "0x10", "[", "]", "{", "}", ":", "- ", "&a", "*a", "!!python/object", "\t",
          "\x00", "é", "if:", "then:", "mode", "SEARCH", "scent", "chance", "load above", "'", '"']  # fmt: skip


@settings(**SETTINGS)
@given(
    name=st.sampled_from(sorted(PROGRAMS)),
    edits=st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 12), st.sampled_from(TOKENS)), max_size=4),
)
def test_any_program_text_builds_a_policy_or_one_clear_error(name, edits):
    from baselines import make_policy

    text = PROGRAMS[name]
    for at, cut, token in edits:
        at %= len(text) + 1
        text = text[:at] + token + text[at + cut :]
    env = proteo_env.make(TASKS[name])
    try:
        policy = make_policy("program", env, program=text + "\n", seed=0)
    except (ConfigError, ValueError) as err:
        assert clear(err) or "is not valid YAML" in str(err), f"{err}"
        return
    observations, _ = env.reset(seed=0)
    policy.act(observations)  # what builds, acts


# ---------------------------------------------------------------------- checkpoint metadata
pytest.importorskip("torch")

PUBLISHED = {
    "ppo": ROOT / "checkpoints/v7/chain/ppo_move/seed_0",
    "cma-rules": ROOT / "checkpoints/v7/chain/cma_full/seed_0",
    "program": ROOT / "checkpoints/v7/chain/evolve-large-paper_full/seed_0",
}


@settings(**{**SETTINGS, "max_examples": max(10, EXAMPLES // 2)})
@given(
    which=st.sampled_from(sorted(PUBLISHED)),
    key=st.sampled_from(["task", "control", "encoder", "hidden", "activation", "memory", "sampled", "arch", "nvec",
                         "files", "algorithm", "version", "format", "policy", "params", "env", "seed", "recipe"]),
    value=values,
    drop=st.booleans(),
)  # fmt: skip
@example(which="cma-rules", key="algorithm", value=[], drop=False)  # a value a dict cannot hold as a key
@example(which="cma-rules", key="policy", value={}, drop=False)
def test_any_checkpoint_metadata_loads_or_one_clear_error(tmp_path_factory, which, key, value, drop):
    from training.machinery.checkpoints import CheckpointError, load_controller

    folder = tmp_path_factory.mktemp("ck") / "copy"
    shutil.copytree(PUBLISHED[which], folder)
    meta = json.loads((folder / "proteo.json").read_text())
    if drop:
        meta.pop(key, None)
    else:
        meta[key] = value
    (folder / "proteo.json").write_text(json.dumps(meta))
    try:
        env, policy = load_controller(str(folder))
    except (CheckpointError, ConfigError) as err:
        assert clear(err) or "lacks" in str(err) or "does not match" in str(err), f"{key}={value!r}: {err}"
        return
    observations, _ = env.reset(seed=0)
    policy.act(observations)

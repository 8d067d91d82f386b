"""The chain, branch, table and grasp behaviours inside compiled code (``baselines.compiled``) against
the observation-based policies driven through the environment: same trajectory cycle for cycle,
same cycles to success, same draws from the policy's generator; also with the kernels run as
plain Python."""

from __future__ import annotations

import copy
import hashlib

import numpy as np
import pytest
from conftest import run_without_jit

import proteo_env
from baselines.branch import BranchPolicy
from baselines.chain import ChainPolicy
from baselines.compiled import CompiledRollout, compiled_rollout
from baselines.grasp import GraspPolicy
from baselines.table import TablePolicy
from proteo_env.tasks.table import FINAL as LEG_FINAL

LIMIT = 400
SMALL_TABLE = dict(
    board_size=12,
    depth=3,
    n_spares=40,
    schedule=[[0, 8.0, 2.0], [150, 2.0, 8.0]],
    stable_window=30,
    motion_model="minimal",
    max_cycles=800,
)
"""A table that grows legs, moves them after one weight shift and settles in about 240 cycles."""


def drive(env, policy, limit, *, use_dicts=False):
    """Step ``env`` with ``policy`` through the observation API until success or ``limit`` cycles;
    returns per-cycle positions and modes and whether the task succeeded."""
    positions, modes = [], []
    success = False
    while not success and env.cycle < limit:
        if use_dicts:
            actions = policy.act(env.observe_arrays().per_agent(env.possible_agents))
            env.step_arrays(np.stack([actions[a] for a in env.possible_agents]))
        else:
            env.step_arrays(policy.act_arrays(env.observe_arrays()))
        positions.append(env.world.positions)
        modes.append(env.world.modes)
        success = bool(env.task.success(env.engine))
    return np.array(positions), np.array(modes), success


def assert_same_trajectory(result, positions, modes, success, rng):
    assert result.success == success
    assert result.cycles == len(positions)
    np.testing.assert_array_equal(result.recorded_cycles, np.arange(1, len(positions) + 1))
    np.testing.assert_array_equal(result.recorded_positions, positions)
    np.testing.assert_array_equal(result.recorded_modes, modes)
    np.testing.assert_array_equal(result.positions, positions[-1])
    assert result.rng.bit_generator.state == rng.bit_generator.state


@pytest.mark.parametrize("model", ["minimal", "sphere"])
@pytest.mark.parametrize("n", [12, 24])
def test_compiled_rollout_is_the_observation_based_policy(model, n):
    for seed in range(3):
        env = proteo_env.make("chain-v0", n_modules=n, motion_model=model, max_cycles=LIMIT)
        env.reset(seed=seed)
        result = compiled_rollout(env, ChainPolicy.for_env(env, seed=seed), record_every=1)
        policy = ChainPolicy.for_env(env, seed=seed)
        positions, modes, success = drive(env, policy, LIMIT)
        assert success, f"{model} n={n} seed={seed}: no chain within {LIMIT} cycles"
        assert_same_trajectory(result, positions, modes, success, policy.rng)


@pytest.mark.parametrize(
    "params",
    [
        {"queue": True, "p_seed": 0.01, "on_stuck": "random"},
        {
            "directed": False,
            "momentum": 0.0,
            "avoid_octahedra": "all",
            "greedy_approach": False,
            "wake_when_free": True,
        },
    ],
)
def test_same_trajectory_with_other_rule_parameters(params):
    env = proteo_env.make("chain-v0", n_modules=20, motion_model="rounded", max_cycles=150)
    env.reset(seed=4)
    result = compiled_rollout(env, ChainPolicy.for_env(env, seed=4, **params), record_every=1)
    policy = ChainPolicy.for_env(env, seed=4, **params)
    positions, modes, success = drive(env, policy, 150)
    assert_same_trajectory(result, positions, modes, success, policy.rng)


@pytest.mark.parametrize("model", ["minimal", "sphere"])
def test_compiled_branch_is_the_observation_based_policy(model):
    for seed in range(2):
        env = proteo_env.make("branch-v0", n_modules=40, T=4, B=3, motion_model=model, max_cycles=LIMIT)
        env.reset(seed=seed)
        result = compiled_rollout(env, BranchPolicy.for_env(env, seed=seed), record_every=1)
        policy = BranchPolicy.for_env(env, seed=seed)
        positions, modes, success = drive(env, policy, LIMIT)
        assert_same_trajectory(result, positions, modes, success, policy.rng)
        assert success or model == "sphere", f"{model} seed={seed}: no tree of 2 levels within {LIMIT} cycles"


@pytest.mark.parametrize(
    "task, params",
    [
        ({"initial_node": False, "target_levels": 9}, {"p_node": 0.02, "refuse": False}),
        ({"T": 3, "B": 2, "target_levels": 9}, {"patience": 3, "search_relays_node": False, "queue": True}),
    ],
)
def test_same_branch_trajectory_with_other_parameters(task, params):
    env = proteo_env.make("branch-v0", n_modules=40, motion_model="minimal", max_cycles=150, **task)
    env.reset(seed=5)
    result = compiled_rollout(env, BranchPolicy.for_env(env, seed=5, **params), record_every=1)
    policy = BranchPolicy.for_env(env, seed=5, **params)
    positions, modes, success = drive(env, policy, 150)
    assert_same_trajectory(result, positions, modes, success, policy.rng)


def test_compiled_table_is_the_observation_based_policy():
    for seed in range(3):
        env = proteo_env.make("table-v0", **SMALL_TABLE)
        env.reset(seed=seed)
        result = compiled_rollout(env, TablePolicy.for_env(env, seed=seed), record_every=1)
        policy = TablePolicy.for_env(env, seed=seed)
        positions, modes, success = drive(env, policy, SMALL_TABLE["max_cycles"])
        assert success, f"seed={seed}: the table did not settle after the shift"
        assert_same_trajectory(result, positions, modes, success, policy.rng)
        assert (result.modes == LEG_FINAL).sum() >= env.task.params.depth - 1  # legs stand


def test_same_table_trajectory_with_other_rule_parameters():
    params = {"p_random": 0.3, "p_max": 1.0, "p_min": 1.0, "f_max": 1.5, "f_min": 0.7}
    env = proteo_env.make("table-v0", **SMALL_TABLE)
    env.reset(seed=6)
    result = compiled_rollout(env, TablePolicy.for_env(env, seed=6, **params), max_cycles=200, record_every=1)
    policy = TablePolicy.for_env(env, seed=6, **params)
    positions, modes, success = drive(env, policy, 200)
    assert_same_trajectory(result, positions, modes, success, policy.rng)


def test_table_rollout_continues_after_a_weight_shift():
    """From mid-episode (past the shift, legs and memory in place) the rollout continues the
    env's bookkeeping: same trajectory, same cycle of success; the env's task is untouched."""
    env = proteo_env.make("table-v0", **SMALL_TABLE)
    env.reset(seed=1)
    policy = TablePolicy.for_env(env, seed=1)
    drive(env, policy, 160, use_dicts=True)
    ledger = env.task.ledger.copy()
    result = compiled_rollout(env, policy, record_every=1)
    for before, after in zip(ledger, env.task.ledger):
        np.testing.assert_array_equal(before, after)
    positions, modes, success = drive(env, policy, SMALL_TABLE["max_cycles"], use_dicts=True)
    assert success and result.success
    assert result.cycles == 160 + len(positions) == env.cycle
    np.testing.assert_array_equal(result.recorded_positions, positions)
    np.testing.assert_array_equal(result.recorded_modes, modes)
    assert result.rng.bit_generator.state == policy.rng.bit_generator.state


SMALL_GRASP = dict(n_modules=160, motion_model="sphere", max_cycles=400)
"""``configs/grasp.yaml``'s grasp, which the hand-coded fingers reach and wrap in 200 to 310 cycles
(seeds 0, 1, 2)."""


@pytest.mark.parametrize(
    "params",
    [
        {},
        {
            "on_flat": "random",
            "straight": False,
            "wrap_forward": False,
            "relocate": False,
            "prefer_touch": False,
            "greedy_approach": False,
        },
    ],
)
def test_compiled_grasp_is_the_observation_based_policy(params):
    successes = 0
    for seed in range(3):
        env = proteo_env.make("grasp-v0", **SMALL_GRASP)
        env.reset(seed=seed)
        result = compiled_rollout(env, GraspPolicy.for_env(env, seed=seed, **params), record_every=1)
        policy = GraspPolicy.for_env(env, seed=seed, **params)
        positions, modes, success = drive(env, policy, SMALL_GRASP["max_cycles"])
        assert_same_trajectory(result, positions, modes, success, policy.rng)
        successes += success
    assert successes == 3 or params, "the default rules wrap the sphere with seeds 0, 1, 2"


def test_grasp_rollout_continues_a_started_episode():
    env = proteo_env.make("grasp-v0", **SMALL_GRASP)
    env.reset(seed=4)
    policy = GraspPolicy.for_env(env, seed=4)
    drive(env, policy, 60, use_dicts=True)
    result = compiled_rollout(env, policy, record_every=1)
    positions, modes, success = drive(env, policy, SMALL_GRASP["max_cycles"], use_dicts=True)
    assert result.success == success and result.cycles == env.cycle
    np.testing.assert_array_equal(result.recorded_positions, positions)
    np.testing.assert_array_equal(result.recorded_modes, modes)
    assert result.rng.bit_generator.state == policy.rng.bit_generator.state


@pytest.mark.parametrize("use_dicts", [False, True])
def test_rollout_continues_a_started_episode(use_dicts):
    """The rollout starts from the env's state and the policy's memory, whichever way it was keyed."""
    env = proteo_env.make("chain-v0", n_modules=16, motion_model="sphere", max_cycles=LIMIT)
    env.reset(seed=1)
    policy = ChainPolicy.for_env(env, seed=1)
    drive(env, policy, 40, use_dicts=use_dicts)
    result = compiled_rollout(env, policy, record_every=1)
    positions, modes, success = drive(env, policy, LIMIT, use_dicts=use_dicts)
    assert success
    assert result.cycles == 40 + len(positions)
    np.testing.assert_array_equal(result.recorded_positions, positions)
    np.testing.assert_array_equal(result.recorded_modes, modes)
    assert result.rng.bit_generator.state == policy.rng.bit_generator.state


def test_runs_resume_and_leave_env_and_policy_unchanged():
    env = proteo_env.make("chain-v0", n_modules=16, motion_model="minimal", max_cycles=LIMIT)
    env.reset(seed=2)
    policy = ChainPolicy.for_env(env, seed=2)
    state, before = copy.deepcopy(env.engine.snapshot()), copy.deepcopy(policy.rng.bit_generator.state)
    whole = compiled_rollout(env, policy)
    rollout = CompiledRollout(env, policy)
    first = rollout.run(30, record_every=10)
    np.testing.assert_array_equal(first.recorded_cycles, [10, 20, 30])
    rest = rollout.run(LIMIT)
    assert whole.success and rest.success and rest.cycles == whole.cycles
    np.testing.assert_array_equal(rest.positions, whole.positions)
    np.testing.assert_array_equal(rest.modes, whole.modes)
    assert rollout.run(5).cycles == whole.cycles  # nothing left to do after success
    for key, value in env.engine.snapshot().items():
        np.testing.assert_array_equal(value, state[key], err_msg=key)
    assert policy.rng.bit_generator.state == before


def test_room_changes_no_early_cycle():
    """A box with ``room`` free sites gives the default box's first ``room - 3`` cycles."""
    room = 12
    runs = []
    for extra in ({}, {"room": room}):
        env = proteo_env.make("chain-v0", n_modules=30, motion_model="sphere", **extra)
        env.reset(seed=0)
        start = env.world.positions
        result = compiled_rollout(env, ChainPolicy.for_env(env, seed=0), max_cycles=room - 3)
        runs.append((result.positions - start[0], result.modes, env.world.box))
    (default, default_modes, default_box), (small, small_modes, small_box) = runs
    assert small_box[0] < default_box[0]
    np.testing.assert_array_equal(default, small)
    np.testing.assert_array_equal(default_modes, small_modes)


def test_bad_inputs_are_refused():
    env = proteo_env.make("chain-v0", n_modules=8)
    policy = ChainPolicy.for_env(env, seed=0)
    with pytest.raises(ValueError, match="no world yet"):
        compiled_rollout(env, policy)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="max_cycles=-1 is not allowed"):
        compiled_rollout(env, policy, max_cycles=-1)
    with pytest.raises(ValueError, match="record_every=1.5 is not allowed"):
        compiled_rollout(env, policy, record_every=1.5)
    allowed = r"allowed: the task's hand-coded policy \(a KernelPolicy named 'chain'"
    with pytest.raises(ValueError, match=f"policy=BranchPolicy on task='chain-v0' is not allowed; {allowed}"):
        compiled_rollout(env, BranchPolicy.for_env(env, seed=0))
    sandbox = proteo_env.make("sandbox-v0", n_modules=8)
    sandbox.reset(seed=0)
    with pytest.raises(ValueError, match="policy=ChainPolicy on task='sandbox-v0' is not allowed"):
        compiled_rollout(sandbox, policy)
    with pytest.raises(ValueError, match="room=0 is not allowed"):
        proteo_env.make("chain-v0", room=0)


# ------------------------------------------------------------------ kernels as plain Python
def fingerprint() -> str:
    """Hash of short compiled rollouts of a small chain, branching tree, table and grasp."""
    digest = hashlib.sha256()
    small = {"n_modules": 12, "motion_model": "sphere", "max_cycles": 25}
    for task, policy_cls, extra, params in (
        ("chain-v0", ChainPolicy, small, {"queue": True}),
        ("branch-v0", BranchPolicy, {**small, "T": 3, "B": 2}, {"queue": True}),
        ("table-v0", TablePolicy, {**SMALL_TABLE, "max_cycles": 40}, {"p_max": 0.5}),
        ("grasp-v0", GraspPolicy, {**SMALL_GRASP, "n_modules": 30, "max_cycles": 40}, {"straight": False}),
    ):
        env = proteo_env.make(task, **extra)
        env.reset(seed=3)
        result = compiled_rollout(env, policy_cls.for_env(env, seed=3, **params), record_every=1)
        digest.update(result.recorded_positions.tobytes() + result.recorded_modes.tobytes())
        digest.update(repr(result.rng.bit_generator.state).encode())
    return digest.hexdigest()


def nojit_child() -> None:
    """Entry point of the subprocess run with ``NUMBA_DISABLE_JIT=1``."""
    import numba

    assert numba.config.DISABLE_JIT, "NUMBA_DISABLE_JIT was not picked up"
    from baselines import chain

    assert not hasattr(chain.chain_actions, "signatures"), "kernels are still compiled"
    print("FINGERPRINT", fingerprint())


@pytest.mark.slow
def test_kernels_as_plain_python_give_the_same_rollout():
    result = run_without_jit("test_compiled_rollout", "nojit_child")
    assert result.returncode == 0, result.stdout + result.stderr
    assert f"FINGERPRINT {fingerprint()}" in result.stdout

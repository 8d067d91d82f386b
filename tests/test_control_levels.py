"""Control levels (``make(task, control=...)``): PettingZoo citizenship at every level, what
fills the fields an agent does not choose, determinism, the TorchRL wrapper, and bad input."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import small_overrides, task_params
from gymnasium import spaces
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test
from pettingzoo.utils import parallel_to_aec

import proteo_env
from baselines import make_policy
from baselines.autopilot import hand_coded_rules
from proteo_env import control
from proteo_env.config import ConfigError, world_seeds
from proteo_env.core.cycle import EMIT, RELAY

RULE_TASKS = task_params(sorted(tid for tid, cls in proteo_env.TASKS.items() if cls.name != "sandbox"))
LEVELS = ("move", "move+mode")  # "full" is every other test file's level


def _make(task_id, level, **extra):
    return proteo_env.make(task_id, **small_overrides(task_id, control=level, **extra))


def _check_warnings(record):
    expected = (
        "Observation is not a NumPy array",
        "Observation numpy array is all zeros",
        "space for each agent probably should be gymnasium.spaces.box or gymnasium.spaces.discrete",
    )
    unexpected = [str(w.message) for w in record if not any(text in str(w.message) for text in expected)]
    assert not unexpected, f"unexpected warnings: {unexpected}"


# ---------------------------------------------------------------------- PettingZoo's own tests
@pytest.mark.parametrize("level", LEVELS)
@pytest.mark.parametrize("task_id", RULE_TASKS)
def test_pettingzoo_tests_pass_at_every_level(task_id, level):
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        parallel_api_test(_make(task_id, level), num_cycles=30)
        api_test(parallel_to_aec(_make(task_id, level, max_cycles=25)), num_cycles=30)
    _check_warnings(record)
    parallel_seed_test(lambda: _make(task_id, level), num_cycles=20)


@pytest.mark.parametrize("task_id", RULE_TASKS)
def test_spaces_of_each_level(task_id):
    move = _make(task_id, "move")
    assert isinstance(move.action_space("module_0"), spaces.Discrete) and move.action_space("module_0").n == 13
    assert move.control_fields == ("move",)
    both = _make(task_id, "move+mode")
    n_modes = len(both.task.modes)
    assert list(both.action_space("module_0").nvec) == [13, n_modes]
    assert both.control_fields == ("move", "mode")
    full = _make(task_id, "full")
    assert list(full.action_space("module_0").nvec) == list(full.action_layout.nvec)
    # the controlled fields are a prefix of the full action
    assert full.action_layout.field_names[:2] == list(both.control_fields)


# ---------------------------------------------------------------------- many steps, bit for bit
def _episode(env, seed, n_cycles, level):
    """Positions and modes after each of ``n_cycles`` cycles of seeded random legal moves
    (and random modes at ``move+mode``)."""
    rng = np.random.default_rng(seed + 1)
    observations, _ = env.reset(seed=seed)
    trace = []
    while env.agents and len(trace) < n_cycles:
        actions = {}
        for agent in env.agents:
            move = rng.choice(np.flatnonzero(observations[agent]["action_mask"]))
            actions[agent] = int(move) if level == "move" else np.array([move, rng.integers(len(env.task.modes))])
        observations, *_ = env.step(actions)
        trace.append((env.world.positions.copy(), env.world.modes.copy(), env.world.scents.copy()))
    return trace


@pytest.mark.parametrize("level", LEVELS)
@pytest.mark.parametrize("task_id", RULE_TASKS)
def test_same_seed_same_trajectory_over_many_cycles(task_id, level):
    first = _episode(_make(task_id, level), 3, 40, level)
    second = _episode(_make(task_id, level), 3, 40, level)
    assert len(first) == len(second) > 10
    for a, b in zip(first, second):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("task_id", RULE_TASKS)
def test_batched_world_follows_the_single_env_at_move_level(task_id):
    overrides = small_overrides(task_id, control="move")
    batch = proteo_env.make_batched(task_id, 3, **overrides)
    buffers = batch.reset(seed=10)
    singles = [proteo_env.make(task_id, **overrides) for _ in range(3)]
    for b, env in enumerate(singles):
        env.reset(seed=world_seeds(10, 3)[b])
    rng = np.random.default_rng(0)
    a = batch.n_agents
    for _ in range(30):
        masks = buffers.action_mask.reshape(3, a, 13).astype(bool)
        moves = np.array([[rng.choice(np.flatnonzero(m)) for m in world] for world in masks])
        batch.step_arrays(moves[..., None])
        buffers = batch.observe_arrays()
        for b, env in enumerate(singles):
            env.step_arrays(moves[b][:, None])
            np.testing.assert_array_equal(batch.worlds[b].positions, env.engine.positions)
            np.testing.assert_array_equal(batch.worlds[b].mode, env.engine.mode)


# ---------------------------------------------------------------------- what fills the other fields
class _Twin:
    """An autopilot (the hand-coded rules) and a twin copy of the same rules with the same seed:
    the twin proposes the moves the autopilot's rules would make."""

    instances: list = []

    def __init__(self, env, seed):
        self.pilot = hand_coded_rules(env, seed)
        self.twin = hand_coded_rules(env, seed)
        self.seed = None
        _Twin.instances.append(self)

    def reset(self, seed=None):
        self.seed = seed
        self.pilot.reset(seed)
        self.twin.reset(seed)

    def act_arrays(self, buffers):
        return self.pilot.act_arrays(buffers)


@pytest.mark.parametrize("task_id", RULE_TASKS)
def test_move_level_with_the_rules_moves_is_the_hand_coded_episode(task_id, monkeypatch):
    """At ``move`` the autopilot is the task's hand-coded rules: an agent that moves as the rules
    would reproduces, cycle for cycle, the hand-coded policy's episode at ``full``."""
    name = proteo_env.TASKS[task_id].name
    monkeypatch.setitem(control._autopilots, name, _Twin)
    _Twin.instances.clear()
    env = _make(task_id, "move", max_cycles=400)
    (pilot,) = _Twin.instances
    buffers = env.batch.reset(seed=5)
    moved_trace = []
    while True:
        moves = pilot.twin.act_arrays(buffers)[:, :1]
        env.batch.step_arrays(moves[None])
        buffers = env.batch.observe_arrays()
        moved_trace.append(env.engine.positions.copy())
        if env.batch.success()[0] or env.cycle >= 150:
            break
    if name == "chain":
        assert env.batch.success()[0], "the chain rules at move level finish the chain"
    assert not np.array_equal(moved_trace[0], moved_trace[-1]), "the rules' moves moved modules"

    reference = _make(task_id, "full", max_cycles=400)
    policy = make_policy(name, reference, seed=pilot.seed)
    buffers = reference.batch.reset(seed=5)
    for positions in moved_trace:
        reference.step_arrays(policy.act_arrays(buffers))
        buffers = reference.observe_arrays()
        np.testing.assert_array_equal(reference.engine.positions, positions)
    assert reference.batch.success()[0] == env.batch.success()[0]


def test_move_level_modes_follow_the_rules_while_nobody_moves():
    """Chain at ``move`` with every agent staying: nobody moves, but the rules still wake the
    SLEEP modules as the seed's scent spreads through the blob (the autopilot sets modes)."""
    env = _make("chain-v0", "move")
    env.reset(seed=0)
    search = env.task.mode_index("SEARCH")
    start = env.world.positions.copy()
    for _ in range(12):
        env.step({a: 0 for a in env.agents})
    np.testing.assert_array_equal(env.world.positions, start)
    assert (env.world.modes == search).sum() >= env.engine.n_agents - 2


@pytest.mark.parametrize("task_id", RULE_TASKS)
def test_move_plus_mode_roles_follow_the_mode_table(task_id):
    env = _make(task_id, "move+mode")
    obs, _ = env.reset(seed=0)
    table = env.task.mode_role_table()
    assert table.shape == (len(env.task.modes), env.task.n_channels)
    assert (table == EMIT).any() and (table == RELAY).any()
    emitting = int(np.flatnonzero((table == EMIT).any(axis=1))[0])
    channel = int(np.flatnonzero(table[emitting] == EMIT)[0])
    actions = {a: np.array([0, obs[a]["own_mode"][0]]) for a in env.agents}
    actions["module_0"] = np.array([0, emitting])
    obs, *_ = env.step(actions)
    assert env.world.modes[0] == emitting
    assert obs["module_0"]["own_scent"][channel] == 0, "a mode that emits by the table has scent 0"


def test_move_plus_mode_needs_no_rules():
    env = proteo_env.make("sandbox-v0", n_modules=8, control="move+mode")
    env.reset(seed=0)
    env.step({a: np.array([0, 1]) for a in env.agents})
    assert (env.world.modes == 1).all()


# ---------------------------------------------------------------------- TorchRL
def test_torchrl_pettingzoo_wrapper_with_mask_at_move_level():
    pytest.importorskip("torchrl")
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper
    from torchrl.envs.utils import check_env_specs

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # TorchRL warns that it was tested with PettingZoo 1.24.3
        env = PettingZooWrapper(_make("chain-v0", "move", max_cycles=20), use_mask=True, seed=0)
        check_env_specs(env)
        rollout = env.rollout(5)
    mask = rollout["module", "action_mask"]
    assert mask.shape[-1] == 13 and mask.dtype.is_floating_point is False
    chosen = rollout["module", "action"]
    assert mask.gather(-1, chosen.unsqueeze(-1)).all(), "a random rollout picks masked-in moves only"


# ---------------------------------------------------------------------- bad input
def test_unknown_level_is_one_clear_error():
    with pytest.raises(ConfigError, match=r"control='fly' is not allowed; allowed: 'move', 'move\+mode', 'full'"):
        proteo_env.make("chain-v0", control="fly")
    with pytest.raises(ConfigError, match="control='fly'"):
        proteo_env.make_batched("chain-v0", 2, control="fly")


def test_move_level_without_rules_names_the_tasks_that_have_them():
    with pytest.raises(
        ConfigError,
        match=r"task 'sandbox'.*allowed: tasks with rules \(branch, chain, grasp, locomotion, snake, table\)",
    ):
        proteo_env.make("sandbox-v0", control="move")


def test_actions_that_do_not_fit_the_level_change_nothing():
    env = _make("chain-v0", "move")
    obs, _ = env.reset(seed=0)
    policy = make_policy("chain", _make("chain-v0", "full"), seed=0)  # full actions: not this level's
    before = env.world.positions.copy()
    with pytest.raises(
        ValueError,
        match=r"module_0: shape \(5,\) is not allowed at control level 'move'; "
        r"allowed: an int, the move",
    ):
        env.step(policy.act(obs))
    with pytest.raises(ValueError, match=r"not allowed at control level 'move'; allowed: \(12, 1\)"):
        env.step_arrays(np.zeros((12, 5), dtype=np.int64))
    with pytest.raises(ValueError, match=r"module_3: move=13 is not allowed; allowed: 0..12"):
        env.step({a: (13 if a == "module_3" else 0) for a in env.agents})
    np.testing.assert_array_equal(env.world.positions, before)
    assert env.cycle == 0
    both = _make("chain-v0", "move+mode")
    both.reset(seed=0)
    with pytest.raises(ValueError, match=r"module_0: mode=4 is not allowed; allowed: 0..3"):
        both.step({a: np.array([0, 4]) for a in both.agents})


def test_policies_refuse_a_level_they_do_not_act_at():
    from baselines.base import Policy

    class FullOnly(Policy):
        name = "full-only"

    env = _make("chain-v0", "move")
    with pytest.raises(
        ValueError,
        match=r"policy 'full-only' gives actions at control level full, not at the env's "
        r"control='move'",
    ):
        FullOnly.for_env(env)
    random = make_policy("random", env, seed=0)  # random moves under the rules
    obs, _ = env.reset(seed=0)
    obs, *_ = env.step(random.act(obs))
    assert env.cycle == 1


@pytest.mark.parametrize("level", ["move", "move+mode"])
def test_the_rules_act_below_full_with_the_leading_fields_of_their_action(level):
    """Below ``full`` the hand-coded policy gives the leading fields of the action it would take
    at ``full`` (the same draw for the same seed and observation). At ``move`` its moves still
    build the chain under the level's autopilot (at ``move+mode`` they need not: its modes and the
    autopilot's messages come from two instances of the rules)."""
    from proteo_env.rollout import run_episode

    full, low = _make("chain-v0", "full"), _make("chain-v0", level)
    n_fields = len(low.control_fields)
    at_full, at_low = make_policy("chain", full, seed=3), make_policy("chain", low, seed=3)
    obs_full, _ = full.reset(seed=0)
    obs_low, _ = low.reset(seed=0)
    actions_full, actions_low = at_full.act(obs_full), at_low.act(obs_low)
    for agent in full.agents:
        np.testing.assert_array_equal(actions_low[agent], actions_full[agent][:n_fields])
    at_low.reset(3)
    assert at_low.act_arrays(low.observe_arrays()).shape == (len(low.agents), n_fields)
    if level == "move":
        assert run_episode(low, make_policy("chain", low), seed=0).success


def test_the_rules_random_streams_benchmark_runs_the_rules_as_eval_does(tmp_path, capsys, monkeypatch):
    """``benchmarks/rules_random_streams.py``: its first variant is the episode ``proteo eval``
    runs (the rules seeded with the episode's seed), its rows count what it ran, ``--split``
    splits an evaluation's ``move`` rows by the verdict of the autopilot's rules, and bad input
    is one error before anything is written."""
    import importlib
    import json
    from pathlib import Path

    from proteo_env.rollout import run_episode
    from training.judging import record
    from training.judging.report import Result, Run

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "benchmarks"))
    benchmark = importlib.import_module("rules_random_streams")
    overrides = small_overrides("chain-v0")
    out = tmp_path / "results" / "streams.json"
    args = ["--task", "chain-v0", "--env", json.dumps(overrides), "--first-seed", "4", "--seeds", "2"]
    assert benchmark.main([*args, "--out", str(out)]) == 0
    results = json.loads(out.read_text())["results"]
    assert list(results) == list(benchmark.VARIANTS)
    env = proteo_env.make("chain-v0", **overrides)
    for i, seed in enumerate((4, 5)):
        episode = run_episode(env, make_policy("chain", env), seed=seed)
        as_eval = results[benchmark.VARIANTS[0]]
        assert (as_eval["success"][i], as_eval["cycles"][i]) == (episode.success, episode.cycles)
    assert all(len(r["success"]) == 2 for r in results.values())
    assert f"| {benchmark.VARIANTS[3]} | " in capsys.readouterr().out
    # "full, the autopilot's stream" is the episode at move in which the moves are the
    # autopilot's own: a copy of it, taken at the episode's start, also chooses the moves
    move = proteo_env.make("chain-v0", **overrides, control="move")
    assert proteo_env.make("chain-v0", **overrides).batch.autopilots == ()
    for i, seed in enumerate((4, 5)):
        mover = benchmark.autopilot_of(move, seed)
        assert len(move.batch.autopilots) == 1 and move.batch.autopilots[0] is not mover
        move.reset(seed=seed)
        while True:
            result = move.step_arrays(mover.act_arrays(move.observe_arrays())[:, :1])
            if result.terminated[0] or result.truncated[0]:
                break
        as_autopilot = results[benchmark.VARIANTS[2]]
        assert (as_autopilot["success"][i], as_autopilot["cycles"][i]) == (bool(result.terminated[0]), move.cycle)
    # --split: proteo eval's rows at move, split by the autopilot's rules' verdict per world
    verdict = results[benchmark.VARIANTS[2]]["success"]

    def evaluation(settings, levels=("move", "full")):
        """A results.json of two rows of one checkpoint (at ``move``: worlds 5, 4 and 99; at
        ``full``: world 4) evaluated with ``settings``."""
        played = {"move": ([5, 4, 99], [not verdict[1], verdict[0], True]), "full": ([4], [True])}
        rows = [
            Result("chain-v0", "x", "learned", level, env=settings, runs=[
                Run("checkpoints/x", seeds=played[level][0], successes=played[level][1],
                    returns=[0.0] * len(played[level][0]), cycles=[1] * len(played[level][0]))
            ])
            for level in levels
        ]  # fmt: skip
        return json.dumps(record.document(rows, judgement="evaluation", seconds=0.0))

    evaluated = tmp_path / "eval" / "results.json"
    evaluated.parent.mkdir()
    evaluated.write_text(evaluation(overrides))
    assert benchmark.main([*args, "--out", str(out), "--split", str(evaluated)]) == 0
    (split,) = json.loads(out.read_text())["split"]  # the full row and the unrun seed 99 left out
    succeed = [v for v in verdict if v]
    assert split["where_rules_succeed"][1] == len(succeed) and split["where_rules_fail"][1] == 2 - len(succeed)
    assert split["agree"] == [1, 2] and split["policy"] == "checkpoints/x"
    assert "| checkpoints/x | " in capsys.readouterr().out
    bad = tmp_path / "bad" / "streams.json"
    other, full_only = tmp_path / "eval" / "other.json", tmp_path / "eval" / "full_only.json"
    other.write_text(evaluation({**overrides, "max_cycles": 7}))
    full_only.write_text(evaluation(overrides, levels=("full",)))
    env = ["--env", json.dumps(overrides)]
    for flags, message in (
        (["--env", "{n_modules: 6"], "--env='{n_modules: 6' is not allowed; allowed: a YAML mapping"),
        (["--env", "{n_modules: -3}"], "--task/--env: "),
        (["--seeds", "0"], "--seeds=0 is not allowed; allowed: an integer >= 1"),
        ([*env, "--split", str(tmp_path / "none.json")], "none.json' is not allowed ("),
        ([*env, "--split", str(other)], "other.json' evaluated other settings"),
        ([*env, "--split", str(full_only)], "has no row of chain-v0 at control level move"),
    ):
        with pytest.raises(SystemExit) as exit_info:
            benchmark.main(["--task", "chain-v0", *flags, "--out", str(bad)])
        assert exit_info.value.code == 2
        assert message in capsys.readouterr().err
    assert not bad.parent.exists()

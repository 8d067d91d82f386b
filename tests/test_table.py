"""The table task (paper section 4.3) and its hand-coded policy, on small instances.

The behaviour runs use a 12 x 12 board (8 roots, 4 per half), legs 3 modules long, 30 spare
modules and the ``minimal`` motion model (the only one under which legs reach the floor; see
docs/tasks/table.md).
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

import proteo_env
from baselines import make_policy
from baselines.table import TablePolicy
from proteo_env.config import ConfigError, load_run_config
from proteo_env.core.lattice import DIRECTIONS
from proteo_env.core.world import Physics, World
from proteo_env.rollout import run_episode
from proteo_env.tasks.table import AROOT, FINAL, IROOT, ROOT, SLEEP, TableParams, board_sites, spare_sites

CONFIGS = sorted(Path(__file__).resolve().parents[1].glob("configs/table*.yaml"))
SHIFT = 250
SMALL = {
    "board_size": 12,
    "depth": 3,
    "n_spares": 30,
    "schedule": ((0, 6.0, 1.0), (SHIFT, 1.0, 6.0)),
    "motion_model": "minimal",
    "max_cycles": 700,
}
SEEDS = (0, 1, 2)


def _episode(seed: int, **extra):
    env = proteo_env.make("table-v0", **{**SMALL, **extra})
    policy = make_policy("table", env, seed=seed)
    return env, run_episode(env, policy, seed=seed)


@pytest.fixture(scope="module")
def episodes():
    return {seed: _episode(seed) for seed in SEEDS}


# ---------------------------------------------------------------------- layout
def test_paper_board_is_30_by_30_with_roots_every_3_sites():
    p = TableParams()
    roots, fixed = board_sites(p)
    board = np.concatenate([roots, fixed])
    assert len(board) == 450 and len(roots) == 50
    assert np.all(board[:, 2] == p.depth) and np.all(board.sum(axis=1) % 2 == 0)
    assert board[:, :2].min() == 0 and board[:, :2].max() == 29
    left = roots[:, 0] < 15
    assert left.sum() == 25 and (~left).sum() == 25
    # neighbouring roots are 3 face hops apart along the layer's rows: offsets (+-3, +-3, 0)
    for r in roots:
        d = np.abs(roots - r)
        d = d[d.any(axis=1)]
        nearest = d[np.argmin((d**2).sum(axis=1))]
        assert tuple(nearest) == (3, 3, 0)
    spares = spare_sites(p)
    assert len(spares) == p.n_spares and np.all(spares[:, 2] < p.depth) and np.all(spares[:, 2] >= 0)
    assert len({tuple(s) for s in spares}) == len(spares)


def test_start_state_is_one_piece_with_fixed_board_and_sleeping_spares():
    env = proteo_env.make("table-v0", **SMALL)
    env.reset(seed=0)
    w = env.world
    n_spares = SMALL["n_spares"]
    modes = np.array(w.modes)
    assert env.engine.n_components() == 1
    assert w.n_agents == n_spares + 8  # 8 roots on a 12 x 12 board
    assert np.all(modes[:n_spares] == SLEEP) and np.all(modes[n_spares : w.n_agents] == IROOT)
    assert np.all(np.array(w.mode_names)[modes[w.n_agents :]] == "FIXED")
    assert np.all(w.anchored[n_spares:]) and not w.anchored[:n_spares].any()


# ---------------------------------------------------------------------- load sensor
def _step_with_root_modes(env, obs, root_modes: dict[int, int]):
    lay = env.action_layout
    actions = {a: lay.encode(mode=int(o["own_mode"][0])) for a, o in obs.items()}
    for i, mode in root_modes.items():
        actions[f"module_{i}"] = lay.encode(mode=mode)
    return env.step(actions)[0]


def test_load_sensor_reads_region_weight_per_active_root():
    env = proteo_env.make("table-v0", **{**SMALL, "schedule": ((0, 6.0, 1.0), (2, 0.0, 5.0))})
    obs, _ = env.reset(seed=0)
    n_spares = SMALL["n_spares"]
    roots = range(n_spares, env.world.n_agents)
    left = [i for i in roots if env.world.positions[i, 0] < 6]
    right = [i for i in roots if env.world.positions[i, 0] >= 6]
    cap = env.task.params.load_cap
    # no active root anywhere: a region with weight saturates the sensor
    assert all(obs[f"module_{i}"]["load"][0] == cap for i in roots)
    obs = _step_with_root_modes(env, obs, {left[0]: ROOT, left[1]: AROOT})
    assert all(obs[f"module_{i}"]["load"][0] == pytest.approx(3.0) for i in left)  # 6 / 2 active
    assert all(obs[f"module_{i}"]["load"][0] == cap for i in right)  # 1 / 0 active
    assert all(obs[f"module_{i}"]["load"][0] == 0.0 for i in range(n_spares))
    obs = _step_with_root_modes(env, obs, {right[0]: ROOT})  # cycle 2: weights now 0 / 5
    assert all(obs[f"module_{i}"]["load"][0] == 0.0 for i in left)  # no weight: 0 per root
    assert all(obs[f"module_{i}"]["load"][0] == pytest.approx(5.0) for i in right)
    info = env.step({a: env.action_layout.encode(mode=int(o["own_mode"][0])) for a, o in obs.items()})[4]
    m = info["module_0"]
    assert (m["metric/weight_left"], m["metric/weight_right"]) == (0.0, 5.0)
    assert (m["metric/active_left"], m["metric/active_right"]) == (2.0, 1.0)


# ---------------------------------------------------------------------- behaviour
def _history(result, name):
    return np.array([h[f"metric/{name}"] for h in result.history])


@pytest.mark.parametrize("seed", SEEDS)
def test_legs_grow_where_the_weight_is_and_move_after_the_shift(episodes, seed):
    env, result = episodes[seed]
    p = env.task.params
    legs_left, legs_right = _history(result, "legs_left"), _history(result, "legs_right")
    before = SHIFT - 1  # history row i is cycle i + 1
    # weight 6 / 1: at least 3 legs on the left (6 / 3 <= f_max), 1 or more on the right
    assert legs_left[before - 1] >= 3 and legs_right[before - 1] >= 1
    assert legs_left[before - 1] > legs_right[before - 1]
    # after the shift to 1 / 6 the legs have moved to the right
    assert result.success, "the table re-stabilised after the shift"
    end_left, end_right = legs_left[-1], legs_right[-1]
    assert end_right >= 3 and end_right > end_left >= 1
    for weight, legs in ((1.0, end_left), (6.0, end_right)):
        assert p.f_min <= weight / legs <= p.f_max
    assert result.metrics["support"] == 1.0
    for k in (0, 1):
        assert 0 <= result.metrics[f"restabilise_{k}"] < SHIFT


@pytest.mark.parametrize("seed", SEEDS)
def test_restabilise_metric_marks_an_unchanged_complete_period(episodes, seed):
    env, result = episodes[seed]
    window = env.task.params.stable_window
    series = {
        name: _history(result, name) for name in ("legs_left", "legs_right", "active_left", "active_right", "stable")
    }
    for k, shift in enumerate((0, SHIFT)):
        start = shift + int(result.metrics[f"restabilise_{k}"])
        rows = slice(max(start - 1, 0), start + window)  # cycles start .. start + window
        for name in ("legs_left", "legs_right", "active_left", "active_right"):
            assert np.all(series[name][rows] == series[name][rows][0]), name
        assert np.all(series["legs_left"][rows] == series["active_left"][rows])
        assert series["stable"][start + window - 1] == 1.0


def test_deterministic_roots_all_switch_at_once():
    """p_max = 1: every overloaded IROOT goes AROOT in the same cycle (the paper's worry)."""
    for p, expected in ((1.0, 8), (0.05, None)):
        env = proteo_env.make("table-v0", **{**SMALL, "p_max": p, "p_min": p})
        policy = make_policy("table", env, seed=0)
        obs, _ = env.reset(seed=0)
        policy.reset(0)
        info = env.step(policy.act(obs))[4]["module_0"]
        created = info["metric/leg_creations"]
        if expected is not None:
            assert created == expected
        else:
            assert created <= 3


def test_policy_rule_parameters_come_from_the_task_config():
    env = proteo_env.make("table-v0", **{**SMALL, "p_max": 0.3, "f_min": 0.5})
    policy = make_policy("table", env, seed=0)
    assert (policy.p_max, policy.p_min, policy.f_max, policy.f_min) == (0.3, 0.05, 2.0, 0.5)
    assert make_policy("table", env, seed=0, p_max=0.7).p_max == 0.7


def test_hand_coded_policy_beats_random():
    _, table = _episode(0, max_cycles=300, schedule=((0, 6.0, 1.0),))
    env = proteo_env.make("table-v0", **{**SMALL, "max_cycles": 300})
    random_result = run_episode(env, make_policy("random", env, seed=0), seed=0)
    per_cycle = table.total_reward / table.cycles
    assert per_cycle > 0.8 > random_result.total_reward / random_result.cycles


# ---------------------------------------------------------------------- observations only
def _holds(obj, types, seen=None) -> bool:
    seen = set() if seen is None else seen
    if id(obj) in seen:
        return False
    seen.add(id(obj))
    if isinstance(obj, types):
        return True
    if isinstance(obj, dict):
        return any(_holds(v, types, seen) for v in obj.values())
    if isinstance(obj, (list, tuple, set)):
        return any(_holds(v, types, seen) for v in obj)
    if hasattr(obj, "__dict__") and not isinstance(obj, type):
        return any(_holds(v, types, seen) for v in vars(obj).values())
    return False


@pytest.mark.parametrize("policy_name", ["table", "random"])
def test_policies_use_only_their_observations(policy_name):
    """Recorded observations fed to a fresh policy give the same actions: nothing else is read."""
    env = proteo_env.make("table-v0", **{**SMALL, "max_cycles": 120})
    policy = make_policy(policy_name, env, seed=3)
    assert not _holds(policy, (proteo_env.ProteoEnv, World, proteo_env.WorldView, type(env.task)))
    obs, _ = env.reset(seed=3)
    policy.reset(3)
    recorded = []
    while env.agents:
        actions = policy.act(obs)
        recorded.append((copy.deepcopy(obs), {a: v.copy() for a, v in actions.items()}))
        obs = env.step(actions)[0]
    assert any(int(o["own_mode"][0]) == FINAL for o in obs.values()) or policy_name == "random"
    replay = make_policy(policy_name, proteo_env.make("table-v0", **SMALL), seed=3)
    replay.reset(3)
    for observations, actions in recorded:
        again = replay.act(observations)
        assert again.keys() == actions.keys()
        for agent in actions:
            np.testing.assert_array_equal(again[agent], actions[agent])


# ---------------------------------------------------------------------- motion models
def test_legs_reach_the_floor_under_minimal_only():
    """Under sphere (and the stricter models) a lone module cannot roll onto a floor site
    below a leg's SEED one layer up: legs never ground. Under minimal it can."""
    h = 4
    board = [(x, y, h) for x in range(10) for y in range(10) if (x + y + h) % 2 == 0]
    leg = [(4, 3, 3), (3, 3, 2), (4, 3, 1)]  # a zigzag leg under the root (3, 3, 4)
    spots = {tuple(np.array(leg[-1]) + d) for d in DIRECTIONS if d[2] == -1}

    def reachable(model):
        start = [
            tuple(np.array(leg[-1]) + d)
            for d in DIRECTIONS
            if tuple(np.array(leg[-1]) + d) not in leg and 1 <= leg[-1][2] + d[2] < h
        ]
        seen, frontier = set(start), list(start)
        while frontier:
            p = frontier.pop()
            w = World(
                size=(10, 10, h + 1),
                positions=np.array([p] + board + leg),
                n_agents=1,
                physics=Physics(motion_model=model, keep_connected=False),
                anchored=np.array([False] + [True] * (len(board) + len(leg))),
                floor=True,
            )
            for k in range(12):
                q = tuple(int(v) for v in np.array(p) + DIRECTIONS[k])
                if q not in seen and w.roll_is_legal(0, k):
                    seen.add(q)
                    frontier.append(q)
        return seen

    assert reachable("minimal") & spots
    assert not reachable("sphere") & spots

    _, result = _episode(0, motion_model="sphere", max_cycles=300)
    assert _history(result, "grounded_legs").max() == 0
    assert (_history(result, "active_left") > 0).any()  # roots did ask for legs


# ---------------------------------------------------------------------- configs and bad input
@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_configs_carry_the_paper_parameters(path):
    task_id, overrides = load_run_config(path)
    env = proteo_env.make(task_id, **overrides)
    p = env.task.params
    assert env.task.name == "table"
    assert (p.board_size, p.root_spacing, p.f_max, p.f_min) == (30, 3, 2.0, 1.0)
    expected = 1.0 if "deterministic" in path.name else 0.05
    assert p.p_max == p.p_min == expected
    assert all(w1 + w2 == 10 for _, w1, w2 in p.schedule)
    assert env.max_cycles > p.schedule[-1][0]


@pytest.mark.parametrize(
    "key, value, match",
    [
        ("schedule", ((5, 8.0, 2.0),), r"schedule=.* is not allowed; allowed: .*cycles increasing from 0"),
        ("schedule", ((0, 8.0, 2.0), (0, 2.0, 8.0)), r"schedule=.* is not allowed"),
        ("schedule", ((0, -1.0, 2.0),), r"schedule=.* is not allowed; allowed: .*weights >= 0"),
        ("schedule", ((0, 8.0),), r"schedule=.* is not allowed"),
        ("f_min", 3.0, r"f_min=3.0 is not allowed; allowed: a number in \[0, f_max = 2.0\]"),
        ("p_max", 1.5, r"p_max=1.5 is not allowed; allowed: a probability in \[0, 1\]"),
        ("n_spares", 0, r"n_spares=0 is not allowed"),
        ("root_spacing", 1, r"root_spacing=1 is not allowed; allowed: an integer >= 2"),
        ("weights", 3, r"unknown key 'weights'"),
    ],
)
def test_bad_table_settings_are_rejected(key, value, match):
    with pytest.raises(ConfigError, match=match):
        proteo_env.make("table-v0", **{key: value})


def test_yaml_lists_become_a_schedule_of_tuples(tmp_path):
    path = tmp_path / "t.yaml"
    path.write_text("task: table-v0\nboard_size: 12\ndepth: 3\nn_spares: 30\nschedule: [[0, 6, 1], [100, 1, 6]]\n")
    task_id, overrides = load_run_config(path)
    env = proteo_env.make(task_id, **overrides)
    assert env.task.params.schedule == ((0, 6.0, 1.0), (100, 1.0, 6.0))
    assert isinstance(TablePolicy.for_env(env), TablePolicy)

"""The grasp task (paper 4.4) and its hand-coded policy: layout, metrics, reward, behaviour."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

import proteo_env
from baselines import make_policy
from baselines.grasp import GraspPolicy
from proteo_env.config import ConfigError, load_run_config
from proteo_env.core.lattice import DIRECTIONS
from proteo_env.core.world import Physics, World
from proteo_env.rollout import run_episode
from proteo_env.tasks.grasp import SIDES, TOUCH, TOUCHSEED, Grasp, GraspParams

ROOT = Path(__file__).resolve().parents[1]
SMALL = {"n_modules": 60, "n_seed_modules": 4, "object_size": 1.5, "distance": 3}
"""A small grasp: a 13-site object 3 layers in front of a 60-module base with 4 seeds."""


def _sites(a) -> set:
    return {tuple(int(v) for v in p) for p in np.asarray(a).reshape(-1, 3)}


# ---------------------------------------------------------------------- layout
@pytest.mark.parametrize("shape", ["sphere", "box", "blob"])
def test_layout_places_object_ahead_and_seeds_in_front(shape):
    env = proteo_env.make("grasp-v0", shape=shape, hint_noise_deg=10.0)
    for seed in range(4):
        env.reset(seed=seed)
        task, world = env.task, env.engine
        layout = task._built
        modules, obj = world.positions, world.object_sites
        assert _sites(modules).isdisjoint(_sites(obj))
        assert (obj >= 0).all() and (obj < np.array(world.shape.size)).all()
        d = layout.direction
        assert (obj @ d).min() > (modules @ d).max(), "the object lies ahead of the whole base"
        assert int((world.mode == 2).sum()) == 8, "eight initial SEEDs"
        seeds = modules[world.mode == 2]
        base_centre = modules.mean(axis=0)
        assert ((seeds - base_centre) @ d > 0).all(), "seeds sit on the side facing the object"
        hint = env.observe_arrays().hint
        assert hint.dtype == np.float32 and np.allclose(hint, hint[0])
        assert np.isclose(np.linalg.norm(hint[0]), 1.0, atol=1e-5)
        angle = np.degrees(np.arccos(np.clip(hint[0] @ d, -1, 1)))
        assert angle <= 10.0 + 1e-3


def test_surface_sites_are_the_empty_face_neighbours_of_the_object():
    env = proteo_env.make("grasp-v0", shape="blob")
    env.reset(seed=5)
    obj = _sites(env.engine.object_sites)
    expected = {(x + dx, y + dy, z + dz) for (x, y, z) in obj for dx, dy, dz in DIRECTIONS.tolist()} - obj
    size = env.engine.shape.size
    expected = {p for p in expected if all(0 <= p[i] < size[i] for i in range(3))}
    assert _sites(env.task.surface_sites) == expected


def test_shapes_differ_and_blob_is_connected_and_new_each_episode():
    def object_of(shape, seed):
        env = proteo_env.make("grasp-v0", shape=shape, object_size=2.5)
        env.reset(seed=seed)
        obj = env.engine.object_sites
        return obj - obj.min(axis=0)

    sphere, box = object_of("sphere", 0), object_of("box", 0)
    assert _sites(sphere) != _sites(box) and len(box) > len(sphere)
    blob_a, blob_b = object_of("blob", 0), object_of("blob", 1)
    assert len(blob_a) == len(sphere) and _sites(blob_a) != _sites(blob_b)
    todo, seen = [tuple(blob_a[0])], {tuple(blob_a[0])}
    sites = _sites(blob_a)
    while todo:
        p = todo.pop()
        for d in DIRECTIONS.tolist():
            q = (p[0] + d[0], p[1] + d[1], p[2] + d[2])
            if q in sites and q not in seen:
                seen.add(q)
                todo.append(q)
    assert seen == sites, "the blob object is one face-connected piece"


def test_same_seed_same_layout_and_sizes_grow():
    a = proteo_env.make("grasp-v0", shape="blob")
    b = proteo_env.make("grasp-v0", shape="blob")
    a.reset(seed=3)
    b.reset(seed=3)
    np.testing.assert_array_equal(a.engine.object_sites, b.engine.object_sites)
    np.testing.assert_array_equal(a.engine.positions, b.engine.positions)
    counts = []
    for size in (1.5, 2.5, 3.5):
        env = proteo_env.make("grasp-v0", object_size=size)
        env.reset(seed=0)
        counts.append(len(env.task.surface_sites))
    assert counts == sorted(counts) and counts[0] < counts[-1]


# ---------------------------------------------------------------------- metrics
def _world_with_modules_on(task, layout, positions):
    physics = Physics(motion_model="minimal", keep_connected=False)
    world = World(
        size=layout.size,
        positions=positions,
        n_agents=len(positions),
        physics=physics,
        object_sites=layout.object_sites,
        n_channels=task.n_channels,
    )
    task.reset(world, np.random.default_rng(0))
    return world


def test_metrics_when_every_surface_site_is_held_and_when_one_is():
    task = Grasp(GraspParams(object_size=2.5))
    layout = task.build_layout(np.random.default_rng(0))
    env_like = _world_with_modules_on(task, layout, layout.modules)
    surface = task.surface_sites
    m = task.metrics(env_like)
    assert m["contact"] == 0 and m["coverage"] == 0 and m["surround"] == 0 and m["gap"] > 0
    assert not task.success(env_like)

    task.build_layout(np.random.default_rng(0))  # the same layout again
    full = _world_with_modules_on(task, layout, surface)
    m = task.metrics(full)
    assert m == {"gap": 0.0, "contact": float(len(surface)), "coverage": 1.0, "surround": 1.0, "success": 1.0}
    assert task.success(full)

    task.build_layout(np.random.default_rng(0))
    one = _world_with_modules_on(task, layout, surface[:1])
    m = task.metrics(one)
    assert m["contact"] == 1 and m["coverage"] == pytest.approx(1 / len(surface))
    assert m["surround"] == pytest.approx(1 / 12), "a sphere has all 12 sides"
    # the side of that site is the face direction nearest its direction from the centroid
    rel = surface[0] - layout.object_sites.mean(axis=0)
    side = int(np.argmax(SIDES @ (rel / np.linalg.norm(rel)) - 1e-6 * (SIDES @ layout.direction)))
    assert task.surface.side[0] == side


# ---------------------------------------------------------------------- reward and termination
def test_reward_terms_add_up_and_termination_is_success():
    env = proteo_env.make("grasp-v0", **SMALL, max_cycles=1500)
    policy = make_policy("grasp", env, seed=1)
    obs, infos = env.reset(seed=1)
    policy.reset(1)
    info = next(iter(infos.values()))
    gap0 = info["metric/gap"]
    sums = {}
    done = False
    while env.agents:
        obs, rewards, terms, truncs, infos = env.step(policy.act(obs))
        info = next(iter(infos.values()))
        for k, v in info.items():
            if k.startswith("reward/"):
                sums[k] = sums.get(k, 0.0) + v
        term, trunc = next(iter(terms.values())), next(iter(truncs.values()))
        assert not (term and trunc)
        assert term == bool(info["metric/success"])
        assert info["reward/success"] == (1.0 if term else 0.0)
        done = term
    assert done, "the small grasp succeeds from this seed"
    assert set(sums) == {"reward/reach", "reward/coverage", "reward/surround", "reward/success", "reward/time"}
    assert sums["reward/reach"] == pytest.approx((gap0 - info["metric/gap"]) / gap0)
    assert sums["reward/reach"] == pytest.approx(1.0)
    assert sums["reward/coverage"] == pytest.approx(info["metric/coverage"])
    assert sums["reward/surround"] == pytest.approx(info["metric/surround"])
    assert sums["reward/time"] == pytest.approx(-0.001 * env.cycle)


# ---------------------------------------------------------------------- behaviour
@pytest.mark.parametrize("motion_model", ["minimal", "sphere"])
def test_hand_coded_grasp_reaches_and_wraps_a_small_object(motion_model):
    """From several start seeds the fingers reach the object and wrap past its equator."""
    successes = 0
    for seed in range(6):
        env = proteo_env.make("grasp-v0", **SMALL, motion_model=motion_model, max_cycles=1500)
        policy = make_policy("grasp", env, seed=seed)
        contact_at = None

        def watch(env_, info):
            nonlocal contact_at
            if contact_at is None and info.get("metric/contact", 0) > 0:
                contact_at = info["cycle"]

        result = run_episode(env, policy, seed=seed, observe=watch)
        assert contact_at is not None, f"seed {seed}: the fingers never reached the object"
        if not result.success:
            continue
        successes += 1
        assert contact_at < result.cycles
        assert result.metrics["coverage"] >= 0.3 and result.metrics["surround"] >= 0.75
        world = env.engine
        assert np.isin(world.mode, (TOUCH, TOUCHSEED)).sum() >= 5, "the grasp grew by TOUCH modules"
        # some module holds the far side of the object (beyond its centre along the true direction)
        task = env.task
        held = world.grid[task._surface_cell] >= 0
        centre = world.object_sites.mean(axis=0)
        ahead = (task.surface_sites[held] - centre) @ task._built.direction
        assert (ahead > 0.5).any(), f"seed {seed}: nothing wraps round to the far side"
        assert world.n_components() == 1
    assert successes >= 5, f"{successes}/6 small grasps succeeded under {motion_model}"


def test_random_policy_does_not_grasp_the_small_object():
    env = proteo_env.make("grasp-v0", **SMALL, motion_model="minimal", max_cycles=300)
    result = run_episode(env, make_policy("random", env, seed=0), seed=0)
    assert not result.success and result.metrics["coverage"] < 0.3


# ---------------------------------------------------------------------- observations only
def _reachable_objects(root, depth=4):
    seen, todo, found = set(), [(root, 0)], []
    while todo:
        obj, level = todo.pop()
        if id(obj) in seen or level > depth:
            continue
        seen.add(id(obj))
        found.append(obj)
        children = []
        if isinstance(obj, dict):
            children = list(obj.keys()) + list(obj.values())
        elif isinstance(obj, (list, tuple, set)):
            children = list(obj)
        elif hasattr(obj, "__dict__") and not isinstance(obj, type):
            children = list(vars(obj).values())
        todo.extend((c, level + 1) for c in children)
    return found


def test_policy_holds_no_handle_on_the_environment():
    env = proteo_env.make("grasp-v0", **SMALL)
    policy = make_policy("grasp", env, seed=0)
    obs, _ = env.reset(seed=0)
    for _ in range(30):
        obs, *_ = env.step(policy.act(obs))
    for obj in _reachable_objects(policy):
        assert not isinstance(obj, (proteo_env.ProteoEnv, World, Grasp)), type(obj)


def test_policy_actions_are_a_function_of_the_observations_alone():
    """Copies of the observations, under other agent names, give the same actions; the world
    behind them is not consulted."""
    env = proteo_env.make("grasp-v0", **SMALL, max_cycles=120)
    a = make_policy("grasp", env, seed=7)
    b = GraspPolicy(env.action_layout, env.task.modes, scent_max=env.config.physics.scent_max, seed=7)
    obs, _ = env.reset(seed=2)
    rename = {agent: f"other_{i}" for i, agent in enumerate(env.agents)}
    while env.agents:
        copied = {rename[k]: {f: np.array(v, copy=True) for f, v in o.items()} for k, o in obs.items()}
        real = a.act(obs)
        from_copies = b.act(copy.deepcopy(copied))
        for agent, action in real.items():
            np.testing.assert_array_equal(action, from_copies[rename[agent]])
        obs, *_ = env.step(real)


# ---------------------------------------------------------------------- configs and bad input
@pytest.mark.parametrize("path", sorted(ROOT.glob("configs/grasp*.yaml")), ids=lambda p: p.name)
def test_config_files_build_and_run(path):
    task_id, overrides = load_run_config(path)
    assert task_id == "grasp-v0"
    env = proteo_env.make(task_id, **overrides)
    policy = make_policy(env.task.default_policy, env, seed=0)
    obs, _ = env.reset(seed=0)
    for _ in range(5):
        obs, *_ = env.step(policy.act(obs))
    assert env.engine.n_components() == 1


@pytest.mark.parametrize(
    "key, value",
    [
        ("shape", "cone"),
        ("n_seed_modules", 0),
        ("n_seed_modules", 1000),
        ("object_size", 0.1),
        ("direction", (0.0, 0.0, 0.0)),
        ("hint_noise_deg", 120.0),
        ("surround_threshold", 1.5),
        ("base", "plate"),
        ("margin", 1),
    ],
)
def test_bad_parameters_name_the_field(key, value):
    with pytest.raises(ConfigError, match=key):
        proteo_env.make("grasp-v0", **{key: value})


def test_bad_policy_parameters_name_the_field():
    env = proteo_env.make("grasp-v0", **SMALL)
    for key, value in (("p_random", 2.0), ("patience", 0), ("on_flat", "fly")):
        with pytest.raises(ValueError, match=key):
            make_policy("grasp", env, **{key: value})


@pytest.mark.parametrize("shape", ["sphere", "box", "blob"])
def test_the_gap_field_is_the_hop_count_to_the_object_s_surface_through_free_or_module_cells(shape):
    """Level by level from the surface, each cell's hops are one more than its nearest neighbour's
    (walls, the ground and the object are never entered), checked on every cell."""
    from proteo_env.core.lattice import EMPTY
    from proteo_env.tasks.grasp import FAR

    env = proteo_env.make_batched("grasp-v0", 2, shape=shape)
    env.reset(seed=5)
    for task, world in zip(env.tasks, env.worlds):
        field, grid = task._gap_field, world.grid
        expected = np.full(grid.shape, FAR, dtype=np.int32)
        frontier, hops = np.unique(task.surface.cell), 0
        expected[frontier] = 0
        while frontier.size:
            hops += 1
            around = (frontier[:, None] + world.dir_delta[None, :]).ravel()
            frontier = np.unique(around[(grid[around] >= EMPTY) & (expected[around] == FAR)])
            expected[frontier] = hops
        np.testing.assert_array_equal(field, expected)
        assert hops > 3 and (field == FAR).any()  # far cells reached, walls and the object not

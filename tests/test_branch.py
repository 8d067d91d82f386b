"""The branch task (paper 4.2) with its hand-coded policy: the tree metrics are right on
hand-made layouts and on real runs (checked by an independent computation from sites and
modes), the policy grows at least two levels of branching, and it acts on observations alone.

Limits come from measurements (``benchmarks/branch_evidence.py``, ``docs/evidence/branch.md``):
40-module blobs with ``T = 4``, ``B = 3`` reach a tree with 2 levels of branching in 37..52
cycles under ``minimal`` (seeds 0..9, measured while writing this test); the limit here is
400. Seeds are 0..5, not picked. Under the other models the same instance is slower and less
reliable (seeds 0..9 within 400 cycles: ``rounded`` 10/10, slowest 131; ``sphere`` 9/10;
``rhombic`` 8/10), so the test runs ``minimal`` only. The same holds for ``branch-v1`` (growth
in 3D), which the tests run beside ``branch-v0`` (in the plane).
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

import proteo_env
from baselines.branch import BranchPolicy
from baselines.random_policy import RandomPolicy
from proteo_env.core.lattice import DIRECTIONS
from proteo_env.core.records import OBSERVATION_FIELDS
from proteo_env.core.world import Physics, World
from proteo_env.tasks.branch import FINAL, INODE, NODE, SEARCH, SEED, SLEEP, Branch, BranchParams

N, T, B = 40, 4, 3
LIMIT = 400
SEEDS = range(6)
GROWN = (SEED, FINAL, NODE, INODE)


def tree_stats(positions: np.ndarray, modes: np.ndarray, root: int, min_gap: int = 3) -> dict:
    """Tree statistics computed here from sites and modes alone (independently of the task):
    the grown piece holding ``root``, its size, cycles, branching points, levels, branches per
    point and mean distance from a branching point to its parent point."""
    sites = {tuple(int(v) for v in p): i for i, p in enumerate(positions)}
    grown = {i for i, m in enumerate(modes) if m in GROWN}
    if root not in grown:
        return {"size": 0, "tree": False, "points": 0, "levels": 0}

    def nbrs(i):
        out = []
        for d in DIRECTIONS:
            j = sites.get(tuple(int(v) for v in positions[i] + d))
            if j is not None and j in grown:
                out.append(j)
        return out

    parent, order = {root: None}, [root]
    for i in order:
        for j in nbrs(i):
            if j not in parent:
                parent[j] = i
                order.append(j)
    degree = {i: len(nbrs(i)) for i in order}
    edges = sum(degree.values()) // 2
    points = [i for i in order if degree[i] >= 3]

    def chain_up(i):  # branching points strictly above i, nearest first, with hop counts
        out, hops, a = [], 0, parent[i]
        while a is not None:
            hops += 1
            if degree[a] >= 3:
                out.append(hops)
            a = parent[a]
        return out

    kids = {i: [] for i in order}
    for i in order[1:]:
        kids[parent[i]].append(i)

    def arm(i):  # modules from i down to the next branching point or leaf, both included
        return 1 if degree[i] >= 3 or not kids[i] else 1 + arm(kids[i][0])

    real = {i for i in points if sum(arm(c) >= min_gap for c in kids[i]) >= 2}

    def level(i):  # the definition on the task's doc page, recursively
        a, hops = parent[i], 1
        while a is not None and a not in real:
            a, hops = parent[a], hops + 1
        return 1 if a is None else level(a) + (1 if hops >= min_gap else 0)

    levels = max((level(i) for i in real), default=0)
    dists = [chain_up(i)[0] for i in points if chain_up(i)]
    children = [degree[i] - (0 if parent[i] is None else 1) for i in points]
    return {
        "size": len(order),
        "tree": edges == len(order) - 1,
        "points": len(points),
        "levels": levels,
        "branches_per_point": float(np.mean(children)) if children else 0.0,
        "max_branches": max(children, default=0),
        "point_distance": float(np.mean(dists)) if dists else 0.0,
    }


def measure(sites, modes, root=0):
    """The task's metrics for hand-made ``sites`` (offsets from the box's middle) and ``modes``."""
    sites = np.asarray(sites, dtype=np.int64) + np.array([12, 12, 4])
    world = World(
        size=(30, 30, 9), positions=sites, n_agents=len(sites), physics=Physics(), n_channels=2, modes=np.asarray(modes)
    )
    task = Branch(BranchParams(n_modules=len(sites)))
    task._root = root
    task.reset(world, np.random.default_rng(0))
    return task.metrics(world), tree_stats(world.positions, world.mode, root)


def arm(start, direction, length):
    return [tuple(np.add(start, np.multiply(direction, k))) for k in range(1, length + 1)]


def test_metrics_line_and_star():
    line = [(0, 0, 0)] + arm((0, 0, 0), (1, 1, 0), 5)
    m, _ = measure(line, [NODE] + [FINAL] * 5)
    # both ends are leaves
    assert (m["tree_size"], m["tree"], m["branch_points"], m["levels"], m["leaves"]) == (6, 1, 0, 0, 2)
    star = [(0, 0, 0)] + arm((0, 0, 0), (1, 1, 0), 3) + arm((0, 0, 0), (1, -1, 0), 3) + arm((0, 0, 0), (-1, 1, 0), 3)
    m, _ = measure(star, [INODE] + [FINAL] * 9)
    assert (m["tree_size"], m["tree"], m["branch_points"], m["levels"]) == (10, 1, 1, 1)
    assert m["branches_per_point"] == 3 and m["point_distance"] == 0 and m["leaves"] == 3
    assert m["success"] == 0  # one level is not enough
    stubby = [(0, 0, 0)] + arm((0, 0, 0), (1, 1, 0), 3) + arm((0, 0, 0), (1, -1, 0), 2) + arm((0, 0, 0), (-1, 1, 0), 2)
    m, _ = measure(stubby, [INODE] + [FINAL] * 7)
    assert (m["branch_points"], m["levels"]) == (1, 0)  # arms of 2 < min_gap: no branching level


def test_metrics_two_levels():
    root = (0, 0, 0)
    sites = [root]
    for d in ((1, 1, 0), (1, -1, 0), (-1, 1, 0), (-1, -1, 0)):
        sites += arm(root, d, 4)
    node = (4, 4, 0)  # end of the first arm
    sites += arm(node, (1, -1, 0), 3) + arm(node, (-1, 1, 0), 3) + arm(node, (1, 1, 0), 1)
    modes = [INODE] + [FINAL] * (len(sites) - 1)
    modes[sites.index(node)] = NODE
    m, ref = measure(sites, modes)
    assert (m["tree_size"], m["tree"], m["branch_points"], m["levels"]) == (24, 1, 2, 2)
    assert m["branches_per_point"] == 3.5  # root: 4 arms; node: 3 beyond its parent branch
    assert m["point_distance"] == 4 and m["leaves"] == 6
    assert m["success"] == 1 and m["nodes"] == 2
    assert ref == {
        "size": 24,
        "tree": True,
        "points": 2,
        "levels": 2,
        "branches_per_point": 3.5,
        "max_branches": 4,
        "point_distance": 4.0,
    }
    assert m["max_branches"] == 4
    # structure, not modes: a module shown as NODE on a plain stretch of branch is no branching point
    modes2 = list(modes)
    modes2[sites.index((-2, -2, 0))] = NODE
    m2, _ = measure(sites, modes2)
    assert (m2["branch_points"], m2["levels"], m2["nodes"]) == (2, 2, 3)


def test_metrics_ignore_the_crowd_and_see_cycles():
    root = (0, 0, 0)
    sites = [root] + arm(root, (1, 1, 0), 3) + arm(root, (1, -1, 0), 3) + arm(root, (-1, 1, 0), 3)
    # SLEEP and SEARCH modules touching the tree are not part of it
    crowd = [(-1, -1, 0), (-2, -2, 0), (-1, 0, 1)]
    m, _ = measure(sites + crowd, [NODE] + [FINAL] * 9 + [SLEEP, SEARCH, SEARCH])
    assert (m["tree_size"], m["tree"], m["branch_points"], m["searching"]) == (10, 1, 1, 3)
    # a ring is no tree
    ring = [(0, 0, 0), (1, 1, 0), (2, 0, 0), (1, -1, 0), (3, 1, 0), (4, 2, 0)]
    m, ref = measure(ring, [NODE] + [FINAL] * 5)
    assert m["tree"] == 0 and not ref["tree"] and m["success"] == 0
    # a piece not holding the root is not counted (joined to the tree by SLEEP modules only)
    bridge = arm((3, 3, 0), (1, 1, 0), 6)
    m, _ = measure(sites + bridge, [NODE] + [FINAL] * 9 + [SLEEP] * 4 + [FINAL] * 2)
    assert m["tree_size"] == 10


def test_close_branching_points_are_one_level():
    """Branching points fewer than min_gap (3) hops apart count as one level."""
    root = (0, 0, 0)
    sites = [root] + arm(root, (1, 1, 0), 6) + arm(root, (1, -1, 0), 3) + arm(root, (-1, 1, 0), 3)
    for gap, want in ((2, 1), (3, 2)):
        node = (gap, gap, 0)
        extra = arm(node, (1, -1, 0), 3) + arm(node, (-1, 1, 0), 3)
        m, ref = measure(sites + extra, [NODE] + [FINAL] * (len(sites) + len(extra) - 1))
        assert m["branch_points"] == 2 and m["point_distance"] == gap
        assert m["levels"] == ref["levels"] == want, gap


def run(policy_cls, seed, *, task="branch-v0", model="minimal", n=N, limit=LIMIT, **params):
    params = {"T": T, "B": B, **params}
    env = proteo_env.make(task, n_modules=n, motion_model=model, max_cycles=limit, **params)
    policy = policy_cls.for_env(env, seed=seed)
    obs, _ = env.reset(seed=seed)
    policy.reset(seed)
    terminated = truncated = False
    info = {}
    while env.agents:
        obs, _, terms, truncs, infos = env.step(policy.act(obs))
        terminated, truncated = any(terms.values()), any(truncs.values())
        info = next(iter(infos.values()))
    return env, terminated, truncated, info


@pytest.mark.parametrize("task", ["branch-v0", "branch-v1"])
@pytest.mark.parametrize("seed", SEEDS)
def test_hand_coded_policy_grows_two_levels(seed, task):
    env, terminated, truncated, info = run(BranchPolicy, seed, task=task)
    assert terminated and not truncated, f"seed {seed}: no 2-level tree within {LIMIT} cycles"
    ref = tree_stats(env.world.positions, env.world.modes, env.task._root)
    assert ref["tree"] and ref["levels"] >= 2
    grown = np.isin(env.world.modes, GROWN)
    layers = np.unique(env.world.positions[grown, 2]).size
    assert layers == 1 if task == "branch-v0" else layers > 1  # planar, or grown out of the plane
    for key, name in (
        ("size", "tree_size"),
        ("points", "branch_points"),
        ("levels", "levels"),
        ("branches_per_point", "branches_per_point"),
        ("max_branches", "max_branches"),
        ("point_distance", "point_distance"),
    ):
        assert info[f"metric/{name}"] == pytest.approx(ref[key]), key


def test_tree_until_modules_run_out_matches_independent_count():
    """Success switched off: the tree grows until the modules run out; the task's numbers
    equal the independent ones, and branching points sit about T + 1 apart."""
    env, terminated, truncated, info = run(BranchPolicy, 0, n=60, limit=300, target_levels=99)
    assert truncated and not terminated
    ref = tree_stats(env.world.positions, env.world.modes, env.task._root)
    assert info["metric/tree_size"] == ref["size"] and info["metric/levels"] == ref["levels"] >= 2
    assert info["metric/point_distance"] == pytest.approx(ref["point_distance"])
    assert info["metric/searching"] == 0  # modules ran out


def test_random_policy_grows_no_tree():
    for seed in range(2):
        env, terminated, truncated, info = run(RandomPolicy, seed, limit=100)
        assert not terminated


def test_policy_sees_only_observations_and_acts_legally():
    env = proteo_env.make("branch", n_modules=30, T=3, B=2, motion_model="minimal", max_cycles=80)
    obs, _ = env.reset(seed=1)
    policy = BranchPolicy(env.action_layout, env.task.modes, seed=0, T=3, B=2)
    twin = BranchPolicy(env.action_layout, env.task.modes, seed=0, T=3, B=2)
    space = env.action_space(env.agents[0])
    lay = env.action_layout
    seen_fields = set()

    class Watched(dict):
        def __getitem__(self, key):
            seen_fields.add(key)
            return super().__getitem__(key)

    promotions = nodes = 0
    while env.agents:
        copies = {a: Watched(copy.deepcopy(o)) for a, o in obs.items()}
        before = copy.deepcopy(copies)
        actions = policy.act(copies)
        for a in copies:
            for f, v in copies[a].items():
                np.testing.assert_array_equal(v, before[a][f])
        np.testing.assert_equal(twin.act({a: copy.deepcopy(o) for a, o in obs.items()}), actions)
        for a, action in actions.items():
            assert space.contains(np.asarray(action, dtype=space.dtype)), (a, action)
            assert obs[a]["action_mask"][action[lay.move]] == 1, (a, action)
            promotions += action[lay.message_value] == 13
            nodes += obs[a]["own_mode"][0] == FINAL and action[lay.mode] == NODE
        obs, *_ = env.step(actions)
    assert seen_fields <= set(OBSERVATION_FIELDS)
    assert promotions > 0 and nodes > 0  # seeds were spawned and FINAL modules became nodes


def test_array_api_is_the_same_policy():
    env = proteo_env.make("branch", n_modules=30, T=3, B=2, motion_model="minimal", max_cycles=60, target_levels=99)
    obs, _ = env.reset(seed=2)
    by_dict = BranchPolicy.for_env(env, seed=5)
    by_array = BranchPolicy.for_env(env, seed=5)
    while env.agents:
        actions = by_dict.act(obs)
        batch = by_array.act_arrays(env.observe_arrays())
        np.testing.assert_array_equal(np.stack([actions[a] for a in env.agents]), batch)
        obs, *_ = env.step(actions)


def test_parameters_reach_the_policy_and_are_checked():
    env = proteo_env.make("branch", n_modules=20, T=7, B=2)
    policy = BranchPolicy.for_env(env)
    assert (policy.T, policy.B) == (7, 2)
    with pytest.raises(ValueError):
        proteo_env.make("branch", T=0)
    with pytest.raises(ValueError):
        proteo_env.make("branch", B=0)


def test_the_first_node_at_the_blob_s_edge_and_the_rules_still_grow_a_tree():
    settings = {"n_modules": 40, "T": 4, "B": 3, "max_cycles": 200}
    for seed in (0, 1, 2):
        env = proteo_env.make("branch-v0", first_node="edge", **settings)
        env.reset(seed=seed)
        positions = np.array(env.world.positions)
        d2 = ((positions - positions.mean(axis=0)) ** 2).sum(axis=1)
        [node] = np.flatnonzero(np.array(env.world.modes) == NODE)
        assert d2[node] == d2.max() > 2 * np.median(d2), "the first node is on the rim"
        centre = proteo_env.make("branch-v0", **settings)
        centre.reset(seed=seed)
        assert (np.array(centre.world.positions) == positions).all(), "the same blob; only the node moves"
        _, terminated, _, info = run(BranchPolicy, seed, first_node="edge", n=40, limit=200, T=4, B=3)
        assert terminated and info["metric/levels"] >= 2
    with pytest.raises(ValueError, match="first_node='middle' is not allowed; allowed: centre, edge"):
        proteo_env.make("branch", first_node="middle")


# ---------------------------------------------------------------------- branch-v1: growth in 3D
def independent_neighbour_sets():
    """Every set of a site's face neighbours no two of which touch (each a possible set of a
    tree node's neighbours in the tree: two touching ones would close a triangle)."""
    touching = [[bool(np.abs(a - b).sum() == 2 and np.abs(a - b).max() == 1) for b in DIRECTIONS] for a in DIRECTIONS]
    sets = []
    for bits in range(1 << 12):
        members = [k for k in range(12) if bits >> k & 1]
        if not any(touching[a][b] for a in members for b in members if a < b):
            sets.append(members)
    return sets


def test_no_tree_point_has_more_than_four_branches_on_the_lattice():
    """Why B = 6 cannot give 6 branches at a point of a tree: of the 12 face neighbours of a
    site (a cuboctahedron, the line graph of the cube) at most 4 are pairwise apart, and 3D
    sets of 4 exist besides the horizontal one; the task measures such a 3D star as 4 branches."""
    sets = independent_neighbour_sets()
    assert max(len(s) for s in sets) == 4
    spread = [s for s in sets if len(s) == 4 and np.any(DIRECTIONS[s, 2] != 0)]
    assert spread
    directions = DIRECTIONS[spread[0]]
    sites = [(0, 0, 0)] + [site for d in directions for site in arm((0, 0, 0), d, 3)]
    m, ref = measure(sites, [INODE] + [FINAL] * 12)
    assert (m["tree"], m["branch_points"], m["levels"], m["max_branches"]) == (1, 1, 1, 4) and ref["max_branches"] == 4
    touching = [(0, 0, 0)] + arm((0, 0, 0), (1, 1, 0), 3) + arm((0, 0, 0), (1, 0, 1), 3)  # two arms that touch
    m, _ = measure(touching, [INODE] + [FINAL] * 6)
    assert m["tree"] == 0


def test_3d_nodes_reach_the_lattice_bound_and_planar_v1_is_v0():
    """branch-v1 at the paper's setting (N = 100, T = 12, B = 6): every run grows a 2-level tree
    spread over many layers whose root has the 4 branches the lattice allows (the node picks
    directions that rule out the fewest others; docs/evidence/branch.md). With ``planar=True``
    branch-v1 is branch-v0, bit for bit."""
    for seed in range(3):
        env, terminated, _, info = run(BranchPolicy, seed, task="branch-v1", n=100, T=12, B=6)
        assert terminated and info["metric/max_branches"] == 4
        grown = np.isin(env.world.modes, GROWN)
        assert np.unique(env.world.positions[grown, 2]).size >= 10
    for seed in range(2):
        old, *_ = run(BranchPolicy, seed, limit=120, target_levels=99)
        new, *_ = run(BranchPolicy, seed, task="branch-v1", limit=120, target_levels=99, planar=True)
        np.testing.assert_array_equal(old.world.positions, new.world.positions)
        np.testing.assert_array_equal(old.world.modes, new.world.modes)

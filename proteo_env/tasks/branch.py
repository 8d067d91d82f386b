"""Branch: grow a recursively branching tree from an arbitrary connected blob.

All modules start in SLEEP as a random blob, except one NODE picked by the task; a NODE spawns up to ``B`` seeds
that grow branches like the chain's seed, and a FINAL module more than ``T`` hops from the nearest node becomes a
NODE, so branches branch again. Registered: ``branch-v0`` (growth in the horizontal plane of the first node) and
``branch-v1``, the newest (:class:`BranchV1`: growth in every direction, ``planar=False``). Paper section 4.2
(Recursive Branching for Locomotion and Manipulation).

The contract (layout, agents, observation, actions, reward, metrics, termination, parameters): docs/tasks/branch.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import numpy as np

from ..core.cycle import EMIT, RELAY
from ..core.jit import kernel
from ..core.structure import BARRED, UNREACHED, breadth_first
from ..core.world import check_module_memory
from ..layouts import Layout, blob_sites, place_in_box
from .base import Task, TaskKernels, no_sensor

REGULAR, NODE_SCENT = 0, 1


class BranchMode(IntEnum):
    """The branch task's modes (paper section 4.2): the chain's four, then the branching points; the one definition the task and its rules share."""

    SLEEP = 0
    SEARCH = 1
    SEED = 2
    FINAL = 3
    NODE = 4
    INODE = 5


SLEEP, SEARCH, SEED, FINAL, NODE, INODE = (int(m) for m in BranchMode)
"""The same modes as plain ints, for the numba kernels."""


@kernel
def measure_tree(
    grid,
    cell,
    mode,
    n_modules,
    dir_delta,
    root,
    min_gap,
    degree,
    parent,
    queue,
    arm,
    longc,
    real_up,
    real_d,
    any_d,
    level,
):
    """The grown piece reached from ``root`` (:func:`~proteo_env.core.structure.breadth_first`)
    and its branching levels (O(N)).

    A module is grown when its mode is SEED, FINAL, NODE or INODE. Scratch (N,) arrays are
    filled for grown modules reached from the root: ``degree`` (neighbours in the piece),
    ``parent`` (the module it was reached from, -1 for the root, below -1 when not reached),
    ``arm`` (modules from here down the branch to the next branching point or leaf, both
    included), ``longc`` (child arms of at least ``min_gap`` modules), ``real_up``/``real_d``
    (nearest *real* branching point above and its distance), ``any_d`` (distance to the nearest
    branching point above, 0 if none), ``level`` (at real branching points). Returns ``(size, edges, points, levels, children,
    most_children, distance_sum, distance_count, leaves)`` (``children``: summed over the
    branching points, ``most_children``: the largest at one point); see docs/tasks/branch.md
    for the definitions.
    """
    for n in range(n_modules):
        m = mode[n]
        parent[n] = UNREACHED if (m == SEED or m == FINAL or m == NODE or m == INODE) else BARRED
        degree[n] = 0
        arm[n] = 0
        longc[n] = 0
        level[n] = 0
    if parent[root] == BARRED:
        return 0, 0, 0, 0, 0, 0, 0, 0, 0
    parent[root] = -1
    queue[0] = root
    size = breadth_first(grid, cell, dir_delta, parent, queue, 1, n_modules)
    for i in range(size):  # neighbours in the piece: every grown neighbour of a reached module is reached
        n = queue[i]
        for k in range(12):
            nb = grid[cell[n] + dir_delta[k]]
            if nb >= 0 and parent[nb] >= -1:
                degree[n] += 1
    # children before parents: arm lengths and long child arms
    for i in range(size - 1, -1, -1):
        n = queue[i]
        if degree[n] == 2 and parent[n] >= 0:
            arm[n] += 1  # arm[n] held the arm of its one child
        else:
            arm[n] = 1
        p = parent[n]
        if p >= 0:
            if arm[n] >= min_gap:
                longc[p] += 1
            if degree[p] == 2 and parent[p] >= 0:
                arm[p] = arm[n]
    edges = 0
    points = 0
    levels = 0
    children = 0
    most_children = 0
    dist_sum = 0
    dist_count = 0
    leaves = 0
    # parents before children: nearest branching points above, levels
    for i in range(size):
        n = queue[i]
        edges += degree[n]
        if degree[n] == 1:
            leaves += 1
        p = parent[n]
        if p < 0:
            real_up[n] = -1
            real_d[n] = 0
            any_d[n] = 0
        else:
            if degree[p] >= 3:
                any_d[n] = 1
            else:
                any_d[n] = any_d[p] + 1 if any_d[p] > 0 else 0
            if degree[p] >= 3 and longc[p] >= 2:
                real_up[n] = p
                real_d[n] = 1
            else:
                real_up[n] = real_up[p]
                real_d[n] = real_d[p] + 1
        if degree[n] < 3:
            continue
        points += 1
        here = degree[n] if p < 0 else degree[n] - 1
        children += here
        if here > most_children:
            most_children = here
        if any_d[n] > 0:
            dist_sum += any_d[n]
            dist_count += 1
        if longc[n] >= 2:
            a = real_up[n]
            if a < 0:
                level[n] = 1
            else:
                level[n] = level[a] + (1 if real_d[n] >= min_gap else 0)
            if level[n] > levels:
                levels = level[n]
    return size, edges // 2, points, levels, children, most_children, dist_sum, dist_count, leaves


@kernel
def measure_branch(grid, cell, mode, dir_delta, first_node, min_gap, target_levels, scratch):
    """The grown piece measured from its root by :func:`measure_tree`, and the success test, for
    the environment and for compiled rollouts alike.

    The root is ``first_node``, or when it is -1 the lowest-index NODE or INODE (module 0 when
    there is none); ``scratch`` is ``(9, N)`` int64. Returns :func:`measure_tree`'s nine numbers
    followed by ``tree`` (the piece has ``size - 1`` contacts: no cycles) and ``success`` (a
    tree with at least ``target_levels`` levels of branching).
    """
    n_modules = cell.shape[0]
    root = first_node
    if root < 0:
        root = 0
        for n in range(n_modules):
            if mode[n] == NODE or mode[n] == INODE:
                root = n
                break
    size, edges, points, levels, children, most_children, dist_sum, dist_count, leaves = measure_tree(
        grid,
        cell,
        mode,
        n_modules,
        dir_delta,
        root,
        min_gap,
        scratch[0],
        scratch[1],
        scratch[2],
        scratch[3],
        scratch[4],
        scratch[5],
        scratch[6],
        scratch[7],
        scratch[8],
    )
    tree = size > 0 and edges == size - 1
    success = tree and levels >= target_levels
    return size, edges, points, levels, children, most_children, dist_sum, dist_count, leaves, tree, success


class TreeMeasure(NamedTuple):
    """:func:`measure_branch`'s numbers by name: the task's view of the grown piece after each
    cycle (``size`` modules, ``points`` branching points, ``levels`` of branching, their
    ``children`` and ``most_children``, ``dist_sum / dist_count`` the mean distance between
    successive points, ``leaves``; ``tree`` and ``success`` as the kernel says)."""

    size: int
    edges: int
    points: int
    levels: int
    children: int
    most_children: int
    dist_sum: int
    dist_count: int
    leaves: int
    tree: bool
    success: bool


@kernel
def branch_update_and_test(grid, cell, mode, anchored, dir_delta, cycle, test):
    """:func:`measure_branch`'s success as a task's ``update_and_test``
    (:class:`~proteo_env.tasks.base.TaskKernels`); ``test`` is ``(first_node, min_gap,
    target_levels, scratch)``."""
    first_node, min_gap, target_levels, scratch = test
    return measure_branch(grid, cell, mode, dir_delta, first_node, min_gap, target_levels, scratch)[10]


FIRST_NODES = ("centre", "edge")
"""Where the first NODE starts (:attr:`BranchParams.first_node`)."""


@dataclass(frozen=True)
class BranchParams:
    """Parameters of the branch task.

    Attributes:
        n_modules: number of modules in the start blob.
        T: node-scent threshold: a FINAL module whose node scent exceeds ``T`` becomes a
            NODE (paper: 12). Read by the policy from the environment's parameters.
        B: number of seeds a NODE spawns before it goes INODE (paper: 6).
        target_levels: levels of branching needed for success (a large value: never succeed,
            to watch the tree grow until the modules run out).
        min_gap: shortest arm, in modules, that counts as a branch for the ``levels`` metric,
            and the least distance between two branching points of successive levels (so that
            a clump of modules with 3 neighbours is not a tree of many levels).
        initial_node: start with one NODE (see ``first_node``); if False every module
            starts in SLEEP and the policy must start growth itself.
        first_node: where that NODE is: ``centre``, the module nearest the blob's centre, or
            ``edge``, the module farthest from it (the tree grows from the blob's rim).
        planar: the tree grows in the horizontal plane of the first node (the hand-coded rule
            reads it; ``branch-v0``'s only growth); False: in every direction, as the paper says
            (``branch-v1``'s default).
        margin: free sites around the blob (as in the chain task): in the directions the tree
            may grow (horizontally when ``planar``, else also vertically) the blob gets
            ``n_modules // 2 + margin`` free sites on each side (a branch of more than half the
            modules is possible but then the tree has at most one level); vertically, when
            ``planar``, ``margin``.
        time_penalty: reward lost per cycle.
    """

    n_modules: int = 100
    T: int = 12
    B: int = 6
    target_levels: int = 2
    min_gap: int = 3
    initial_node: bool = True
    first_node: str = "centre"
    planar: bool = True
    margin: int = 6
    time_penalty: float = 0.001

    def __post_init__(self):
        if self.n_modules < 2:
            raise ValueError(f"n_modules={self.n_modules!r} is not allowed; allowed: an integer >= 2")
        check_module_memory(self.n_modules)
        if self.T < 1:
            raise ValueError(f"T={self.T!r} is not allowed; allowed: an integer >= 1")
        if self.B < 1:
            raise ValueError(f"B={self.B!r} is not allowed; allowed: an integer >= 1")
        if self.target_levels < 1:
            raise ValueError(f"target_levels={self.target_levels!r} is not allowed; allowed: an integer >= 1")
        if self.min_gap < 1:
            raise ValueError(f"min_gap={self.min_gap!r} is not allowed; allowed: an integer >= 1")
        if self.margin < 1:
            raise ValueError(f"margin={self.margin!r} is not allowed; allowed: an integer >= 1")
        if self.first_node not in FIRST_NODES:
            raise ValueError(f"first_node={self.first_node!r} is not allowed; allowed: {', '.join(FIRST_NODES)}")


class Branch(Task):
    name = "branch"
    demo_settings = {"n_modules": 100, "max_cycles": 400, "motion_model": "minimal"}
    version = 0
    modes = tuple(BranchMode.__members__)
    Params = BranchParams
    n_channels = 2
    surface_channels = (False, False)
    passive_role = (1, 1)
    n_message_values = 15
    default_policy = "branch"
    mode_roles = ((RELAY, RELAY), (RELAY, RELAY), (EMIT, RELAY), (RELAY, RELAY), (EMIT, EMIT), (RELAY, EMIT))
    """``move+mode``: SEED emits the regular scent, NODE both, INODE the node scent; the rest relay."""
    window_room = 8
    """The grid covers the modules and 8 sites around them, and grows with them (see :class:`Task`)."""
    plot_groups = {"tree": ["branch_points", "levels", "nodes"]}

    def build_layout(self, rng):
        p = self.params
        room = p.n_modules // 2 + p.margin
        sites, size = place_in_box(blob_sites(p.n_modules, rng), margin=(room, room, p.margin if p.planar else room))
        return Layout(size=size, modules=sites)

    def root_of(self, layout) -> int:
        """The first node: the module nearest the blob's centre, or with ``first_node: edge`` the
        farthest from it (lowest index on ties)."""
        d2 = ((layout.modules - layout.modules.mean(axis=0)) ** 2).sum(axis=1)
        return int(np.argmax(d2) if self.params.first_node == "edge" else np.argmin(d2))

    def initial_modes(self, layout):
        modes = np.full(len(layout.positions), SLEEP, dtype=np.int32)
        self._root = self.root_of(layout)
        if self.params.initial_node:
            modes[self._root] = NODE
        return modes

    def reset(self, world, rng):
        n = world.n_modules
        self._scratch = np.zeros((9, n), dtype=np.int64)
        if not hasattr(self, "_root") or self._root >= n:
            self._root = 0
        self._last = self._measure(world)

    @property
    def first_node(self) -> int:
        """The module the task picked as the first NODE this episode (the tree's root when
        ``initial_node``)."""
        return self._root

    def _given_root(self) -> int:
        """The root handed to :func:`measure_branch`: the first node, or -1 without one
        (``initial_node=False``), so that the kernel roots the tree at the lowest-index NODE
        or INODE module."""
        return self._root if self.params.initial_node else -1

    def _measure(self, world) -> TreeMeasure:
        p, w = self.params, world
        root = self._given_root()
        return TreeMeasure(
            *measure_branch(w.grid, w.cell, w.mode, w.dir_delta, root, p.min_gap, p.target_levels, self._scratch)
        )

    def after_cycle(self, world, cycle):
        self._previous, self._last = self._last, self._measure(world)

    def reward_terms(self, world, moved):
        n = world.n_modules
        prev = getattr(self, "_previous", self._last)
        return {
            "grown": (self._last.size - prev.size) / n,
            "levels": 0.5 * (self._last.levels - prev.levels),
            "success": 1.0 if self._last.success else 0.0,
            "time": -self.params.time_penalty,
        }

    def metrics(self, world):
        m, mode = self._last, world.mode
        return {
            "tree_size": float(m.size),
            "tree": float(m.tree),
            "branch_points": float(m.points),
            "levels": float(m.levels),
            "branches_per_point": m.children / m.points if m.points else 0.0,
            "max_branches": float(m.most_children),
            "point_distance": m.dist_sum / m.dist_count if m.dist_count else 0.0,
            "leaves": float(m.leaves),
            "used_share": m.size / world.n_modules,
            "nodes": float(((mode == NODE) | (mode == INODE)).sum()),
            "seeds": float((mode == SEED).sum()),
            "searching": float(((mode == SLEEP) | (mode == SEARCH)).sum()),
            "success": float(m.success),
        }

    def kernels(self, world):
        p = self.params
        return TaskKernels(
            no_sensor,
            branch_update_and_test,
            (self._given_root(), p.min_gap, p.target_levels, np.zeros((9, world.n_modules), dtype=np.int64)),
        )

    def success(self, world):
        return bool(self._last.success)


@dataclass(frozen=True)
class BranchV1Params(BranchParams):
    """``branch-v1``'s parameters: those of :class:`BranchParams`, growth in 3D by default."""

    planar: bool = False


class BranchV1(Branch):
    """``branch-v1``: the tree grows in every direction around each node, as the paper says.

    ``branch-v0`` grew in the horizontal plane of the first node. Here ``planar`` defaults to False:
    the hand-coded rule's nodes spawn seeds towards any of the 12 face neighbours and its seeds
    turn in 3D, and the box has room for a branch in every direction (vertically too). The
    planar growth stays an option (``planar=True``). A point of a tree has at most 4 branches in
    3D as in the plane (docs/tasks/branch.md); 3D changes where they go. Modes, observation,
    actions, reward, metrics and the success test are those of ``branch-v0``.
    """

    version = 1
    Params = BranchV1Params

"""Grasp: grow eight fingers towards an object of unknown shape and size and wrap it.

A connected base of SLEEP modules with ``n_seed_modules`` SEEDs on its front grows fingers towards a solid object
it knows only by a rough direction (the observation ``hint``) and by touch (``contact[1]``), then wraps it until
it holds enough of its surface from enough of its sides. Registered: ``grasp-v0``. Paper section 4.4 (Grasping an
Object).

The contract (layout, agents, observation, actions, reward, metrics, termination, parameters): docs/tasks/grasp.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import NamedTuple

import numpy as np

from ..core.cycle import EMIT, RELAY
from ..core.jit import kernel
from ..core.lattice import DIRECTIONS, EMPTY
from ..core.paged import cells_at
from ..core.world import check_module_memory
from ..layouts import Layout, ball_sites, blob_sites
from .base import Task, TaskKernels, no_sensor

SHAPES = ("sphere", "box", "blob")
BASES = ("blob", "ball")

SIDES = DIRECTIONS / np.sqrt(2.0)
"""``(12, 3)`` unit directions around the object's centroid (the 12 face directions of the
lattice); side ``k`` is the set of surface sites whose direction from the centroid is nearest
``SIDES[k]``. The 12 sectors are the faces of a rhombic dodecahedron seen from its centre:
congruent, each a twelfth of the sphere."""


class GraspMode(IntEnum):
    """The grasp task's modes (paper section 4.4): the one definition the task and its rules share."""

    SLEEP = 0
    SEARCH = 1
    SEED = 2
    FINAL = 3
    TOUCHSEED = 4
    TOUCH = 5


SLEEP, SEARCH, SEED, FINAL, TOUCHSEED, TOUCH = (int(m) for m in GraspMode)
"""The same modes as plain ints, for the numba kernels."""


class GraspSurface(NamedTuple):
    """The object's surface as :func:`grasp_hold` reads it (S surface sites); the compiled rollout
    of the hand-coded behaviour (:mod:`baselines.compiled`) tests success with it too.

    Attributes:
        cell: ``(S,)`` int64 grid cell of each surface site.
        side: ``(S,)`` int64 side (0..11, :data:`SIDES`) of each surface site.
        n_sides: the number of sides that hold a surface site.
        coverage_threshold, surround_threshold: the task's parameters of those names.
    """

    cell: np.ndarray
    side: np.ndarray
    n_sides: int
    coverage_threshold: float
    surround_threshold: float


@kernel
def grasp_hold(grid, surface):
    """``(contact, coverage, surround, success)`` of the modules on :class:`GraspSurface`
    ``surface``: modules on surface sites, their share of the sites, the share of the sides held,
    and both thresholds met with some contact."""
    held_side = np.zeros(12, dtype=np.bool_)
    contact, sides = 0, 0
    for j in range(surface.cell.shape[0]):
        if grid[surface.cell[j]] >= 0:
            contact += 1
            if not held_side[surface.side[j]]:
                held_side[surface.side[j]] = True
                sides += 1
    coverage = contact / max(surface.cell.shape[0], 1)
    surround = sides / max(surface.n_sides, 1)
    success = coverage >= surface.coverage_threshold and surround >= surface.surround_threshold and contact > 0
    return contact, coverage, surround, success


FAR = np.iinfo(np.int32).max
"""The hop distance of a cell no path reaches."""


@kernel
def hop_distances(grid, n_cells, sources, dir_delta):
    """``(n_cells,)`` int32: the fewest face steps from any cell of ``sources`` to each of the
    ``n_cells`` cells of ``grid`` (dense or paged), through cells that are empty or hold a module;
    :data:`FAR` where no path leads (breadth-first, one queue)."""
    out = np.full(n_cells, FAR, dtype=np.int32)
    queue = np.empty(n_cells, dtype=np.int64)
    tail = 0
    for c in sources:
        if out[c] != 0:
            out[c] = 0
            queue[tail] = c
            tail += 1
    head = 0
    while head < tail:
        c = queue[head]
        head += 1
        for k in range(dir_delta.shape[0]):
            n = c + dir_delta[k]
            if grid[n] >= EMPTY and out[n] == FAR:
                out[n] = out[c] + 1
                queue[tail] = n
                tail += 1
    return out


class HoldMeasure(NamedTuple):
    """The task's view of the modules after each cycle (:func:`hold_measure`): ``gap``, the
    fewest hops from a module to the object's surface, and :func:`grasp_hold`'s numbers."""

    gap: int
    contact: int
    coverage: float
    surround: float
    success: bool


@kernel
def hold_measure(grid, cell, n_agents, gap_field, surface):
    """``(gap, contact, coverage, surround, success)``: the least of ``gap_field`` (cells,) over the
    cells of the first ``n_agents`` modules, then :func:`grasp_hold`."""
    gap = gap_field[cell[0]]
    for n in range(1, n_agents):
        gap = min(gap, gap_field[cell[n]])
    contact, coverage, surround, success = grasp_hold(grid, surface)
    return gap, contact, coverage, surround, success


@kernel
def grasp_update_and_test(grid, cell, mode, anchored, dir_delta, cycle, surface):
    """:func:`grasp_hold`'s success as a task's ``update_and_test`` (:class:`~proteo_env.tasks.base.TaskKernels`)."""
    return grasp_hold(grid, surface)[3]


@dataclass(frozen=True)
class GraspParams:
    """Parameters of the grasp task (lengths in lattice units: neighbours are ``sqrt(2)`` apart).

    Attributes:
        n_modules: modules in the base (all of them agents).
        base: ``blob`` (a random connected blob, new each episode) or ``ball`` (the ``n_modules``
            sites nearest a point: compact, and under the stricter motion models mostly jammed).
        n_seed_modules: initial SEED modules on the side of the base facing the object (paper: 8).
        seed_spread: the seeds are spread over the front of the base (modules with a line of
            sight towards the object) within this lateral distance of the axis through the
            base's centroid along the true direction.
        shape: ``sphere``, ``box`` or ``blob`` (a random connected blob, new each episode).
        object_size: sphere radius; box half side (times ``box_aspect`` per axis); for a blob the
            radius of the sphere with the same number of sites.
        box_aspect: per-axis factors of a box's half sides.
        distance: empty lattice layers between the base's foremost module and the near side of
            the object along the true direction (about the length a finger needs to touch it).
        direction: nominal direction from the base to the object (normalised).
        direction_spread_deg: the true direction is drawn per episode uniformly within this
            angle of ``direction`` (0: always ``direction``).
        hint_noise_deg: the hint the agents see is drawn per episode uniformly within this
            angle of the true direction (0: exact).
        margin: free sites around the base and the object inside the box.
        coverage_threshold: share of the surface sites held for success.
        surround_threshold: share of the object's sides held for success.
        coverage_weight, surround_weight: weights of the reward terms.
        time_penalty: reward lost per cycle.
    """

    n_modules: int = 160
    base: str = "blob"
    n_seed_modules: int = 8
    seed_spread: float = 3.0
    shape: str = "sphere"
    object_size: float = 2.5
    box_aspect: tuple[float, float, float] = (1.0, 1.0, 1.0)
    distance: int = 5
    direction: tuple[float, float, float] = (1.0, 0.0, 0.0)
    direction_spread_deg: float = 0.0
    hint_noise_deg: float = 10.0
    margin: int = 4
    coverage_threshold: float = 0.3
    surround_threshold: float = 0.75
    coverage_weight: float = 1.0
    surround_weight: float = 1.0
    time_penalty: float = 0.001

    def __post_init__(self):
        def bad(name, allowed):
            raise ValueError(f"{name}={getattr(self, name)!r} is not allowed; allowed: {allowed}")

        if self.n_modules < 2:
            bad("n_modules", "an integer >= 2")
        check_module_memory(self.n_modules)
        if self.base not in BASES:
            bad("base", ", ".join(BASES))
        if not 1 <= self.n_seed_modules <= self.n_modules // 2:
            bad("n_seed_modules", f"an integer in 1..{self.n_modules // 2} (half of n_modules)")
        if self.shape not in SHAPES:
            bad("shape", ", ".join(SHAPES))
        if not 0.5 <= self.object_size <= 20:
            bad("object_size", "a number in [0.5, 20]")
        if len(self.box_aspect) != 3 or not all(0.1 <= a <= 10 for a in self.box_aspect):
            bad("box_aspect", "three numbers in [0.1, 10]")
        if not 1 <= self.distance <= 100:  # at 0 the object's rounded placement can overlap the base
            bad("distance", "an integer in 1..100")
        if len(self.direction) != 3 or not np.isfinite(self.direction).all() or not np.any(self.direction):
            bad("direction", "three finite numbers, not all zero")
        if not 0 <= self.seed_spread <= 100:
            bad("seed_spread", "a distance in [0, 100]")
        for name in ("direction_spread_deg", "hint_noise_deg"):
            if not 0 <= getattr(self, name) <= 90:
                bad(name, "an angle in degrees in [0, 90]")
        if self.margin < 2:
            bad("margin", "an integer >= 2")
        for name in ("coverage_threshold", "surround_threshold"):
            if not 0 <= getattr(self, name) <= 1:
                bad(name, "a share in [0, 1]")
        for name in ("coverage_weight", "surround_weight", "time_penalty"):
            if getattr(self, name) < 0:
                bad(name, "a number >= 0")


@dataclass(frozen=True)
class GraspLayout(Layout):
    """A grasp start layout: the common layout plus the episode's seeds and directions.

    Attributes:
        seed_mask: ``(N,)`` bool, the modules that start as SEED.
        direction: ``(3,)`` the true unit direction from the base to the object.
        hint: ``(3,)`` the rough direction the agents are given (unit vector).
    """

    seed_mask: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    direction: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    hint: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))


# ---------------------------------------------------------------------- geometry helpers
def _fcc_grid(r: float) -> np.ndarray:
    """FCC sites of the cube ``[-r, r]^3`` around the origin."""
    n = int(np.ceil(r)) + 1
    g = np.mgrid[-n : n + 1, -n : n + 1, -n : n + 1].reshape(3, -1).T
    return g[g.sum(axis=1) % 2 == 0]


def object_offsets(shape: str, size: float, aspect, rng: np.random.Generator) -> np.ndarray:
    """``(O, 3)`` object sites around the origin (an FCC site): a sphere, a box or a blob."""
    if shape == "box":
        half = size * np.asarray(aspect, dtype=np.float64)
        g = _fcc_grid(float(half.max()))
        return g[(np.abs(g) <= half + 1e-9).all(axis=1)]
    g = _fcc_grid(size)
    ball = g[(g**2).sum(axis=1) <= size * size + 1e-9]
    if shape == "sphere":
        return ball
    return blob_sites(len(ball), rng)


def random_in_cone(axis: np.ndarray, angle_deg: float, rng: np.random.Generator) -> np.ndarray:
    """A unit vector uniformly distributed on the spherical cap of ``angle_deg`` around ``axis``."""
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    if angle_deg <= 0:
        return axis
    cos_t = rng.uniform(np.cos(np.radians(angle_deg)), 1.0)
    phi = rng.uniform(0.0, 2 * np.pi)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    sin_t = np.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    out = cos_t * axis + sin_t * (np.cos(phi) * u + np.sin(phi) * v)
    return out / np.linalg.norm(out)


def nearest_fcc_site(point) -> np.ndarray:
    """The FCC site nearest ``point`` (round, then fix the parity on the worst-rounded axis)."""
    p = np.asarray(point, dtype=np.float64)
    q = np.round(p).astype(np.int64)
    if q.sum() % 2:
        err = p - q
        k = int(np.argmax(np.abs(err)))
        q[k] += 1 if err[k] > 0 else -1
    return q


PAIRS_PER_BLOCK = 1 << 20
"""Pairs of base sites :func:`spread_seeds` compares at once (a block of rows against every site:
24 MiB of differences), so that its memory grows with the modules, not their square."""


def spread_seeds(sites: np.ndarray, direction: np.ndarray, n_seed_modules: int, spread: float) -> np.ndarray:
    """Indices of ``n_seed_modules`` base sites on the front of the base, spread out across ``direction``.

    A site is on the front when no other base site lies ahead of it along ``direction``
    within a lateral distance of 1.5 (a clear line of sight towards the object). Among the front
    sites within lateral distance ``spread`` of the axis through the base's centroid (all
    front sites if too few), the first seed is the one nearest the axis and each next one the
    site laterally farthest from the seeds chosen so far (farthest-point sampling).
    """
    rel = sites - sites.mean(axis=0)
    ahead = rel @ direction
    lateral = rel - ahead[:, None] * direction[None, :]
    blocked = np.zeros(len(sites), dtype=bool)
    rows = max(1, PAIRS_PER_BLOCK // max(1, len(sites)))  # memory in blocks of rows, not (N, N, 3) at once
    for start in range(0, len(sites), rows):
        diff = sites[None, :, :] - sites[start : start + rows, None, :]  # diff[i, j] = j - i
        along = diff @ direction
        across = np.linalg.norm(diff - along[..., None] * direction, axis=2)
        blocked[start : start + rows] = ((along > 0) & (across < 1.5)).any(axis=1)
    front = np.flatnonzero(~blocked)
    radius = np.linalg.norm(lateral, axis=1)
    pool = front[radius[front] <= spread]
    if len(pool) < n_seed_modules:
        pool = front[np.argsort(radius[front], kind="stable")[:n_seed_modules]]
    if len(pool) < n_seed_modules:  # a tiny base: the foremost sites
        pool = np.argsort(-ahead, kind="stable")[:n_seed_modules]
    chosen = [int(pool[np.argmin(radius[pool])])]
    dist = ((lateral[pool] - lateral[chosen[0]]) ** 2).sum(axis=1)
    for _ in range(n_seed_modules - 1):
        dist[np.isin(pool, chosen)] = -1.0
        nxt = int(np.argmax(dist))
        chosen.append(int(pool[nxt]))
        dist = np.minimum(dist, ((lateral[pool] - lateral[pool[nxt]]) ** 2).sum(axis=1))
    return np.array(chosen, dtype=np.int64)


class Grasp(Task):
    name = "grasp"
    demo_settings = {"n_modules": 120, "object_size": 2.0, "distance": 4, "max_cycles": 1500}
    version = 0
    modes = tuple(GraspMode.__members__)
    Params = GraspParams
    n_channels = 2
    surface_channels = (False, False)
    passive_role = (1, 1)
    n_message_values = 15
    default_policy = "grasp"
    mode_roles = ((RELAY, RELAY), (RELAY, RELAY), (EMIT, RELAY), (RELAY, RELAY), (EMIT, EMIT), (RELAY, RELAY))
    """``move+mode``: SEED emits the seed scent, TOUCHSEED both scents; the rest relay."""
    plot_groups = {"coverage and surround": ["coverage", "surround"]}

    # ------------------------------------------------------------------ layout
    def build_layout(self, rng):
        p = self.params
        nominal = np.asarray(p.direction, dtype=np.float64)
        direction = random_in_cone(nominal, p.direction_spread_deg, rng)
        hint = random_in_cone(direction, p.hint_noise_deg, rng)
        base = ball_sites(p.n_modules) if p.base == "ball" else blob_sites(p.n_modules, rng)
        base = base - nearest_fcc_site(base.mean(axis=0))
        obj = object_offsets(p.shape, p.object_size, p.box_aspect, rng)
        obj = obj - nearest_fcc_site(obj.mean(axis=0))
        front = float((base @ direction).max())
        back = float((-(obj @ direction)).max())
        centre = nearest_fcc_site(direction * (front + p.distance + 1 + back))
        obj = obj + centre
        seeds = spread_seeds(base, direction, p.n_seed_modules, p.seed_spread)
        everything = np.concatenate([base, obj])
        lo = everything.min(axis=0) - p.margin
        hi = everything.max(axis=0) + p.margin
        shift = -lo
        if shift.sum() % 2:
            shift[0] += 1
            hi[0] += 1
        size = tuple(int(v) for v in hi - lo + 1)
        mask = np.zeros(len(base), dtype=bool)
        mask[seeds] = True
        self._built = GraspLayout(
            size=size, modules=base + shift, object_sites=obj + shift, seed_mask=mask, direction=direction, hint=hint
        )
        return self._built

    def initial_modes(self, layout):
        modes = np.full(len(layout.positions), SLEEP, dtype=np.int32)
        mask = getattr(layout, "seed_mask", None)
        if mask is not None and len(mask) == len(layout.modules):
            modes[: len(mask)][mask] = SEED
        return modes

    # ------------------------------------------------------------------ episode state
    def reset(self, world, rng):
        layout = getattr(self, "_built", None)
        if layout is None:
            raise RuntimeError("grasp: reset() before build_layout()")
        self._hint = np.asarray(layout.hint, dtype=np.float32)
        self._direction = layout.direction
        self._index_surface(world)
        self._last = self._measure(world)
        self._previous = self._last
        self._gap0 = max(self._last.gap, 1)
        self._hint_rows = np.broadcast_to(self._hint, (world.n_agents, 3))

    def regrid(self, world):
        self._index_surface(world)

    def _index_surface(self, world) -> None:
        """The object's surface sites as cells of ``world``'s grid (:attr:`surface`) and the hop
        field to them."""
        obj = world.object_sites
        shape = world.shape
        grid = world.grid
        # surface sites: in-box, non-object face neighbours of the object
        cand = (obj[:, None, :] + DIRECTIONS[None, :, :]).reshape(-1, 3)
        cand = np.unique(cand, axis=0)
        cand = cand[shape.inside(cand)]
        idx = shape.index(cand)
        keep = cells_at(grid, idx) >= EMPTY  # empty or a module (not object, solid or wall)
        self._surface_sites = cand[keep]
        self._surface_cell = idx[keep]
        centroid = obj.mean(axis=0)
        rel = self._surface_sites - centroid
        rel = rel / np.maximum(np.linalg.norm(rel, axis=1, keepdims=True), 1e-12)
        # ties (a site on a sector boundary) go to the sector facing the base most, so a
        # site on the object's equator is never credited to its far side
        towards_base = -(SIDES @ np.asarray(self._direction, dtype=np.float64))
        side = np.argmax(rel @ SIDES.T + 1e-6 * towards_base[None, :], axis=1).astype(np.int64)
        p = self.params
        self.surface = GraspSurface(
            cell=np.ascontiguousarray(self._surface_cell, dtype=np.int64),
            side=side,
            n_sides=len(np.unique(side)),
            coverage_threshold=float(p.coverage_threshold),
            surround_threshold=float(p.surround_threshold),
        )
        """The object's surface sites and the success thresholds (:class:`GraspSurface`)."""
        self._gap_field = self._hop_field(world)

    def _hop_field(self, world) -> np.ndarray:
        """Hop distance of every grid cell to the nearest surface site through non-object cells."""
        return hop_distances(world.grid, world.shape.n_cells, self._surface_cell, world.dir_delta)

    def _measure(self, world) -> HoldMeasure:
        return HoldMeasure(*hold_measure(world.grid, world.cell, world.n_agents, self._gap_field, self.surface))

    def after_cycle(self, world, cycle):
        self._previous, self._last = self._last, self._measure(world)

    # ------------------------------------------------------------------ hooks read by the env
    def hint(self, world):
        return self._hint_rows

    def reward_terms(self, world, moved):
        p, now, before = self.params, self._last, self._previous
        return {
            "reach": (before.gap - now.gap) / self._gap0,
            "coverage": p.coverage_weight * (now.coverage - before.coverage),
            "surround": p.surround_weight * (now.surround - before.surround),
            "success": 1.0 if now.success else 0.0,
            "time": -p.time_penalty,
        }

    def metrics(self, world):
        return {name: float(value) for name, value in self._last._asdict().items()}

    def kernels(self, world):
        return TaskKernels(no_sensor, grasp_update_and_test, self.surface)

    def success(self, world):
        return bool(self._last.success)

    @property
    def surface_sites(self) -> np.ndarray:
        """``(S, 3)`` the surface sites of this episode's object (after :meth:`reset`)."""
        return self._surface_sites

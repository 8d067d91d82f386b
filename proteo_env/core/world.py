"""The lattice world: state arrays and the cycle, behind a small keyword-only API.

This module is the compute core's front door; it imports nothing from gymnasium or
pettingzoo. A :class:`World` owns plain NumPy arrays, held in its ``state`` (a
:class:`~proteo_env.core.records.WorldState`) and readable as attributes (``world.grid``):

============== ============ ==================================================================
array          shape        meaning
============== ============ ==================================================================
``grid``       (cells,)     padded flat occupancy: module index, or EMPTY/WALL/SOLID/OBJECT
``cell``       (N,)         flat grid index of each module (the truth about positions)
``anchored``   (N,)         module never moves (board modules and roots)
``mode``       (N,)         each module's mode (FSM state) as shown to its neighbours
``scent``      (C, N)       scent value per channel; ``scent_max`` means "no scent"
``inbox``      (N, 12)      message received from each direction last cycle (0: none)
============== ============ ==================================================================

A window of more than :data:`PAGED_ABOVE_CELLS` cells keeps ``grid`` by pages
(:class:`~proteo_env.core.paged.PagedCells`, indexed like the array; its batch steps its worlds one
by one instead of stacking them).

Modules ``0 .. n_agents - 1`` are agents; the rest are passive board modules that keep their
mode and play a fixed scent role (``passive_role``).

One call of :meth:`World.step` is the paper's cycle (docs/model.md, "The cycle"), given every agent's
action: (1) modes are set; (2) messages are delivered, in agent order, to the module in the
target direction now; (3) requested moves are shuffled with the world's own xorshift64
generator (Fisher-Yates, ``j = rng_below(i + 1)`` for ``i = M-1 .. 1``) and tried one at a
time against the occupancy of that moment, geometry first, then connectivity; (4) scents are
relaxed with this cycle's roles. Same seed and actions give the same trajectory, bit for bit.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from operator import attrgetter

import numpy as np

from . import cycle
from .lattice import (
    DIRECTIONS,
    EMPTY,
    OBJECT,
    OPPOSITE,
    PAD,
    PAGE_CELLS,
    SOLID,
    WALL,
    GridShape,
    neighbourhood_offsets,
)
from .motion import LOCAL_ADJACENCY_BITS, LOCAL_OFFSETS, check_motion_model, common_neighbours, motion_bits
from .paged import (
    PAGE_TABLE_BYTES,
    cells_at,
    marks_of,
    paged_bytes,
    paged_cells,
    paged_from_state,
    paged_state,
    write_cells,
)
from .records import Actions, Geometry, Observation, Scratch, Settings, WorldState

SCENT_ROLES = ("silent", "relay", "emit")
"""Scent roles in action order: 0 silent, 1 relay, 2 emit."""

MESSAGE_TO_ALL = 12
"""Message target meaning "every neighbour" (targets 0..11 are directions)."""


class LayoutError(ValueError):
    """A start layout that the world cannot hold (names the field, value and what is allowed)."""


GRID_BYTES_PER_CELL = 20
"""Bytes a world holds per cell of its padded grid at reset, measured: ``chain-v1`` with 1,000
modules (a 2,036 x 2,026 x 33 box, 1.4e8 cells) peaks at 2.5 GiB (the grid and the
connectivity search's marks, ``int32`` each, and their copies while the batch stacks them)."""


PAGED_ABOVE_CELLS = 2**22
"""A world's grid is stored by pages (:mod:`~proteo_env.core.paged`) when its window has more
cells than this (dense, 16 MiB for the grid and as much for the connectivity search's marks)."""


MODULE_BYTES = 4096
"""Bytes per module a world of a compact start layout holds at reset and in its first cycles
with a hand-coded rule (its arrays, the grid of its window, the observation and the rule's
memory), with a margin over the 2.3 KiB measured with ``chain-v1`` at 100,000 modules
(``benchmarks/world_memory.py``, ``docs/speed/memory.md``)."""


def machine_memory() -> int:
    """Bytes of memory available now (``MemAvailable`` of ``/proc/meminfo``; the physical
    memory where that cannot be read)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def check_module_memory(n_modules: int) -> None:
    """A ``ValueError`` naming ``n_modules`` when a world of that many modules cannot fit in the
    memory available (:data:`MODULE_BYTES` each): refused when the task's parameters are built,
    before a start layout is drawn (which for 2**63 modules would run out of time, not memory)."""
    need, have = n_modules * MODULE_BYTES, machine_memory()
    if need > have:
        raise ValueError(
            f"n_modules={n_modules!r} needs about {gib(need)} at reset ({MODULE_BYTES} bytes per module); "
            f"allowed: at most about {have // MODULE_BYTES:,} modules, what the memory available ({gib(have)}) holds"
        )


def gib(n_bytes: float) -> str:
    """``n_bytes`` in GiB, readably (``"98.9 GiB"``, ``"5.4e+06 GiB"``)."""
    value = n_bytes / 2**30
    return f"{value:.3g} GiB" if value < 1e5 else f"{value:.2g} GiB"


def world_bytes(size, extent, n_modules: int, cycles: int) -> int:
    """Bytes a world can come to hold in ``cycles`` cycles, from a grid window of ``extent`` in a box
    of ``size`` sites with ``n_modules`` modules: its grid over the window it can grow to and its
    modules (:data:`MODULE_BYTES` each). A module moves at most one site a cycle and a window grows
    by at least half of itself, so per axis the window stays within twice its extent at reset plus
    four sites a cycle, and within the box. A window of up to :data:`PAGED_ABOVE_CELLS` cells costs
    :data:`GRID_BYTES_PER_CELL` a cell; a larger one is paged: its page table, and its pages
    (:func:`~proteo_env.core.paged.paged_bytes`), twice (the old grid and the new one while a
    window grows). An upper bound that a long structure nears: a chain of 1,200 modules spans its
    box's diagonal."""
    reach = np.minimum(np.asarray(size, dtype=np.int64), 2 * (np.asarray(extent, dtype=np.int64) + 2 * int(cycles)))
    cells = GridShape(tuple(int(v) for v in reach)).n_cells
    grid = cells * GRID_BYTES_PER_CELL
    if cells > PAGED_ABOVE_CELLS:
        paged = 2 * (cells // PAGE_CELLS * PAGE_TABLE_BYTES + paged_bytes(n_modules))
        grid = max(PAGED_ABOVE_CELLS * GRID_BYTES_PER_CELL, paged)
    return grid + int(n_modules) * MODULE_BYTES


def grid_memory(shape: GridShape, n_modules: int) -> tuple[int, int]:
    """``(bytes the grid of shape needs, bytes available)``: :data:`GRID_BYTES_PER_CELL` a cell, or
    paged its page table and pages (:func:`~proteo_env.core.paged.paged_bytes`)."""
    if shape.paged:
        return shape.n_cells // PAGE_CELLS * PAGE_TABLE_BYTES + paged_bytes(n_modules), machine_memory()
    return shape.n_cells * GRID_BYTES_PER_CELL, machine_memory()


def check_grid_fits(shape: GridShape, n_modules: int) -> None:
    """A :class:`LayoutError` when the grid of ``shape`` with ``n_modules`` modules would not fit
    in this machine's memory, naming the box, the memory it needs and what is allowed (before
    anything is allocated)."""
    need, have = grid_memory(shape, n_modules)
    if need > have:
        raise LayoutError(
            f"a box of {' x '.join(map(str, shape.size))} sites needs {gib(need)} for its grid "
            f"({shape.n_cells:.3g} cells); allowed: a box whose grid fits in the memory available "
            f"({gib(have)}): fewer modules, or a task setting that keeps the box small"
        )


@dataclass(frozen=True)
class Physics:
    """How the lattice behaves; the same for every task.

    Attributes:
        motion_model: ``rhombic``, ``rounded``, ``sphere`` or ``minimal`` (docs/model.md,
            "Motion"). The default, ``minimal``, is the only model under which all four paper
            behaviours succeed: under the others no table leg reaches the floor (``docs/model.md``).
        keep_connected: deny a move that would disconnect the other modules.
        scent_sweeps: relaxation sweeps per cycle (1: the paper's slow propagation).
        exact_scent: compute true hop distances every cycle instead of sweeping.
        scent_max: saturating value that means "no scent".
    """

    motion_model: str = "minimal"
    keep_connected: bool = True
    scent_sweeps: int = 1
    exact_scent: bool = False
    scent_max: int = 65535

    def __post_init__(self):
        check_motion_model(self.motion_model)
        if not isinstance(self.scent_sweeps, int) or not 1 <= self.scent_sweeps <= 2**31 - 1:
            raise ValueError(
                f"scent_sweeps={self.scent_sweeps!r} is not allowed; allowed: an integer in [1, 2**31 - 1]"
            )
        if not isinstance(self.scent_max, int) or not 1 <= self.scent_max <= 2**31 - 2:
            raise ValueError(f"scent_max={self.scent_max!r} is not allowed; allowed: an integer in [1, 2**31 - 2]")


def _direction_adjacency() -> np.ndarray:
    """``(12, 4)``: for each direction, the 4 directions whose sites touch it."""
    index = {tuple(d): k for k, d in enumerate(DIRECTIONS)}
    return np.array([[index[tuple(q)] for q in common_neighbours(d)] for d in DIRECTIONS], dtype=np.int64)


DIRECTION_ADJACENCY = _direction_adjacency()


class World:
    """Mutable state of one lattice world and the cycle that advances it.

    Args:
        size: box extent ``(X, Y, Z)``; module centres stay in ``[0, X) x [0, Y) x [0, Z)``.
        positions: ``(N, 3)`` int start sites of the modules (FCC sites, distinct, in the box).
        n_agents: modules ``0 .. n_agents-1`` act; the others are passive board modules.
        anchored: ``(N,)`` bool, modules that never move (default: none).
        solid: ``(S, 3)`` obstacle sites; ``floor=True`` adds every site with ``z < 0``.
        object_sites: ``(O, 3)`` sites of the object (grasp task).
        n_channels: number of scent channels ``C``.
        surface_channels: ``(C,)`` bool, channels that relay only through surface modules.
        passive_role: ``(C,)`` scent role of the passive modules on each channel.
        modes: ``(N,)`` start modes (default 0).
        physics: :class:`Physics`.
        obs_radius: neighbourhood radius of observations (1: 12 sites, 2: 54 sites).
        extent: grid extent so that worlds can share one grid layout in a
            :class:`~proteo_env.core.batch.WorldBatch` (at least ``size``), or the extent of a
            window of the box (:class:`~proteo_env.core.lattice.GridShape`); default ``size``.
        origin: box coordinates of the window's first site (default: the box's, 0); every
            module must lie inside the window's :meth:`~.lattice.GridShape.guard`.
        paged: store the grid by pages (:mod:`~proteo_env.core.paged`); default: when the window
            has more than :data:`PAGED_ABOVE_CELLS` cells. The trajectory is the same either way.
    """

    grid, cell, anchored, mode, scent, inbox, rng_state = (
        property(attrgetter(f"state.{name}"), doc=f"``state.{name}``") for name in WorldState._fields
    )

    def __init__(
        self,
        *,
        size,
        positions,
        n_agents,
        physics,
        anchored=None,
        solid=None,
        object_sites=None,
        floor=False,
        n_channels=1,
        surface_channels=None,
        passive_role=None,
        modes=None,
        obs_radius=1,
        extent=None,
        origin=None,
        paged=None,
    ):
        self.shape = GridShape(size, extent, origin)
        self._paged = paged
        if paged or (paged is None and self.shape.n_cells > PAGED_ABOVE_CELLS):
            self.shape = GridShape(size, extent, origin, paged=True)
        self.physics = physics
        positions = np.asarray(positions, dtype=np.int64).reshape(-1, 3)
        check_grid_fits(self.shape, len(positions))
        self.n_modules = n = len(positions)
        if not 0 <= n_agents <= n:
            raise LayoutError(f"n_agents={n_agents} is not allowed; allowed: 0..{n} (the number of modules)")
        self.n_agents = int(n_agents)
        self.n_channels = int(n_channels)
        self.floor = bool(floor)
        self.obs_radius = obs_radius
        self.surface_channels = (
            np.zeros(n_channels, dtype=np.bool_)
            if surface_channels is None
            else np.asarray(surface_channels, dtype=np.bool_)
        )
        self.passive_role = (
            np.full(n_channels, cycle.RELAY, dtype=np.int8)
            if passive_role is None
            else np.asarray(passive_role, dtype=np.int8)
        )
        anchored = np.zeros(n, dtype=np.bool_) if anchored is None else np.array(anchored, dtype=np.bool_)
        for field, value, length in (
            ("anchored", anchored, n),
            ("modes", modes, n),
            ("surface_channels", self.surface_channels, n_channels),
            ("passive_role", self.passive_role, n_channels),
        ):
            if value is not None and np.shape(value) != (length,):
                raise LayoutError(f"{field} has shape {np.shape(value)}; allowed: ({length},)")
        self.solid_sites = _sites(solid)
        self.object_sites = _sites(object_sites)

        self._check_sites(positions)
        cell = self.shape.index(positions)
        grid = self._static_grid(cell)
        self._check_occupancy(grid, positions, cell)
        write_cells(grid, cell, np.arange(n, dtype=np.int32))
        self.state = WorldState(
            grid=grid,
            cell=cell,
            anchored=anchored,
            mode=np.zeros(n, dtype=np.int32) if modes is None else np.array(modes, dtype=np.int32),
            scent=np.full((n_channels, n), physics.scent_max, dtype=np.int32),
            inbox=np.zeros((n, 12), dtype=np.int32),
            rng_state=np.ones(1, dtype=np.uint64),
        )

        roll_offsets, roll_table = motion_bits(physics.motion_model)
        self.geometry = Geometry(
            directions=DIRECTIONS,
            opposite=OPPOSITE,
            dir_delta=self.shape.deltas(DIRECTIONS),
            neighbourhood_delta=self.shape.deltas(neighbourhood_offsets(obs_radius)),
            roll_delta=self.shape.deltas(roll_offsets),
            roll_table=roll_table,
            local_delta=self.shape.deltas(LOCAL_OFFSETS),
            local_adjacency=LOCAL_ADJACENCY_BITS,
        )
        self.settings = Settings(
            n_agents=self.n_agents,
            keep_connected=bool(physics.keep_connected),
            exact_scent=bool(physics.exact_scent),
            scent_sweeps=int(physics.scent_sweeps),
            scent_max=int(physics.scent_max),
            passive_role=self.passive_role,
            surface_channels=self.surface_channels,
        )
        self.scratch = Scratch.allocate(n, self.grid)

        if physics.keep_connected and n > 0 and self.n_components() != 1:
            raise LayoutError(
                f"positions form {self.n_components()} connected pieces; allowed: one connected "
                "whole when keep_connected=True"
            )

    # ------------------------------------------------------------------ building
    def _static_grid(self, cell: np.ndarray):
        """The grid without modules: walls outside the box, the ground (every site with
        ``z < 0`` when ``floor``), solid and object sites, over the window and its padding; paged
        when the shape is (its pages keep ``cell``, the modules' cells, for collections)."""
        shape = self.shape
        low = np.array(shape.origin) - PAD
        high = np.array(shape.origin) + np.array(shape.extent) + PAD
        static = []
        for sites, code, field in ((self.solid_sites, SOLID, "solid"), (self.object_sites, OBJECT, "object_sites")):
            inside = shape.inside(sites)
            if not inside.all():
                bad = tuple(sites[~inside][0].tolist())
                raise LayoutError(f"{field} site {bad} is outside the box {shape.size}; allowed: 0 <= site < size")
            static.append((shape.index(sites[((sites >= low) & (sites < high)).all(axis=1)]), code))
        if shape.paged:
            return paged_cells(shape, self.floor, static, cell)
        axes = [np.arange(o - PAD, o + e + PAD) for o, e in zip(shape.origin, shape.extent)]
        in_box = [(a >= 0) & (a < s) for a, s in zip(axes, shape.size)]
        grid = np.full(shape.padded, WALL, dtype=np.int32)
        grid[np.ix_(*in_box)] = EMPTY
        if self.floor:
            grid[:, :, axes[2] < 0] = SOLID
        grid = grid.reshape(-1)
        for cells, code in static:
            grid[cells] = code
        return grid

    def _check_sites(self, positions: np.ndarray) -> None:
        """Every module site an FCC site of the box, inside the window's guard."""
        shape = self.shape
        odd = positions.sum(axis=1) % 2 != 0
        if odd.any():
            raise LayoutError(
                f"module site {tuple(positions[odd][0].tolist())} is not an FCC site; "
                "allowed: integer sites with x + y + z even"
            )
        inside = shape.inside(positions)
        if not inside.all():
            raise LayoutError(
                f"module site {tuple(positions[~inside][0].tolist())} is outside the box "
                f"{shape.size}; allowed: 0 <= site < size"
            )
        if not shape.whole and cycle.out_of_room(shape.index(positions), shape.strides, shape.guard()):
            raise ValueError(f"a module lies outside the guard of the window {shape.origin} + {shape.extent}")

    def _check_occupancy(self, grid, positions: np.ndarray, index: np.ndarray) -> None:
        """Every module site empty in the static ``grid``, one module a site."""
        occupied = cells_at(grid, index)
        if (occupied != EMPTY).any():
            p = tuple(positions[occupied != EMPTY][0].tolist())
            what = {SOLID: "a solid site", OBJECT: "an object site"}[int(occupied[occupied != EMPTY][0])]
            raise LayoutError(f"module site {p} is {what}; allowed: empty sites only")
        unique, counts = np.unique(index, return_counts=True)
        if (counts > 1).any():
            p = tuple(self.shape.point(unique[counts > 1][0]).tolist())
            raise LayoutError(f"two modules at site {p}; allowed: at most one module per site")

    # ------------------------------------------------------------------ reading
    @property
    def dir_delta(self) -> np.ndarray:
        """``(12,)`` grid-index offsets of the face neighbours (``geometry.dir_delta``)."""
        return self.geometry.dir_delta

    @property
    def neighbourhood_delta(self) -> np.ndarray:
        """``(K,)`` grid-index offsets of the observed sites (``geometry.neighbourhood_delta``)."""
        return self.geometry.neighbourhood_delta

    @property
    def positions(self) -> np.ndarray:
        """``(N, 3)`` int64 box coordinates of the modules (a fresh array)."""
        return self.shape.point(self.cell)

    def n_components(self) -> int:
        """Number of connected pieces of the module graph (board modules included)."""
        return int(
            cycle.count_components(
                self.grid,
                self.cell,
                self.n_modules,
                self.dir_delta,
                np.zeros(self.n_modules, dtype=np.int64),
                self.scratch.queue,
            )
        )

    def cut_modules(self) -> np.ndarray:
        """``(N,)`` bool: modules whose removal would disconnect the others (articulation points)."""
        cycle.articulation_points(self.grid, self.cell, self.n_modules, self.dir_delta, self.scratch)
        return self.scratch.is_cut

    def roll_is_legal(self, module: int, direction: int) -> bool:
        """Geometry alone: may ``module`` roll towards ``DIRECTIONS[direction]`` now?"""
        g = self.geometry
        legal = cycle.legal_directions(self.grid, self.cell[module], g.roll_delta, g.roll_table)
        return bool((legal >> direction) & 1)

    def can_detach(self, module: int) -> bool:
        """Do the other modules stay connected if ``module`` leaves its site?"""
        return bool(cycle.detach_keeps_connected(self.grid, self.cell, module, self.geometry, self.scratch))

    # ------------------------------------------------------------------ the cycle
    def seed(self, seed: int) -> None:
        """Set the move-order generator from a non-negative integer."""
        self.rng_state[0] = np.uint64((int(seed) % (2**64 - 1)) + 1)

    def step(self, *, move, mode, scent_role, message_target, message_value) -> np.ndarray:
        """Advance one cycle with every agent's action; return ``(A,)`` bool, who moved.

        Args (A = ``n_agents``, C = ``n_channels``; validated by the caller):
            move: ``(A,)`` 0 to stay or ``k + 1`` to roll towards ``DIRECTIONS[k]``.
            mode: ``(A,)`` each agent's new mode.
            scent_role: ``(A, C)`` 0 silent, 1 relay, 2 emit.
            message_target: ``(A,)`` direction 0..11, or 12 for all neighbours.
            message_value: ``(A,)`` value to send, 0 for none.
        """
        moved = np.zeros(self.n_agents, dtype=np.bool_)
        actions = Actions.of(
            move=move, mode=mode, scent_role=scent_role, message_target=message_target, message_value=message_value
        )
        cycle.run_cycle(
            tuple(self.state), tuple(self.settings), tuple(self.geometry), tuple(actions), moved, tuple(self.scratch)
        )
        return moved

    def observe(self, out) -> None:
        """Fill an :class:`~proteo_env.spaces.ObservationBuffers`-like ``out`` for all agents."""
        cycle.observe_world(
            tuple(self.state), tuple(self.settings), tuple(self.geometry), tuple(self.scratch), Observation.plain(out)
        )

    def window(self) -> tuple[np.ndarray, np.ndarray]:
        """``(low, high)`` (3,) each: the box sites the grid's window covers now."""
        origin, extent = np.asarray(self.shape.origin), np.asarray(self.shape.extent)
        return np.maximum(origin, 0), np.minimum(origin + extent, np.asarray(self.shape.size))

    def grown_window(self, room: int) -> tuple[np.ndarray, np.ndarray]:
        """``(low, high)``: the window grown to hold the modules and ``room`` sites around them, or
        half the window's extent where that is more (so that a growing structure regrids about
        ``log`` of its size times), clipped to the box."""
        low, high = self.window()
        room = np.maximum(room, np.asarray(self.shape.extent) // 2)
        near_low, near_high = window_around(self.positions, self.shape.size, room)
        return np.minimum(low, near_low), np.maximum(high, near_high)

    def regrid(self, extent, origin=None) -> World:
        """This world, same state, on another grid: of a larger ``extent`` (to share a batch's
        layout), or over another window ``origin + extent`` of the box (a fresh ``World``).

        The box, the modules' sites, modes, scents, inbox and move-order generator are
        kept; only the grid (and so every grid cell index) changes, so the trajectory from
        here is the one the world would have followed on its old grid.
        """
        world = World(
            size=self.shape.size,
            positions=self.positions,
            n_agents=self.n_agents,
            physics=self.physics,
            anchored=self.anchored.copy(),
            solid=self.solid_sites,
            object_sites=self.object_sites,
            floor=self.floor,
            n_channels=self.n_channels,
            surface_channels=self.surface_channels,
            passive_role=self.passive_role,
            modes=self.mode.copy(),
            obs_radius=self.obs_radius,
            extent=extent,
            origin=origin,
            paged=self._paged,
        )
        world.scent[:] = self.scent
        world.inbox[:] = self.inbox
        world.rng_state[:] = self.rng_state
        return world

    def __getstate__(self):
        # a paged grid pickles as its arrays (numba's compiled classes do not pickle)
        state = self.__dict__.copy()
        if self.shape.paged:
            state["state"] = self.state._replace(grid=paged_state(self.grid))
            state["scratch"] = self.scratch._replace(mark=None)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        if self.shape.paged:
            grid = paged_from_state(self.state.grid, self.state.cell)
            self.state = self.state._replace(grid=grid)
            self.scratch = self.scratch._replace(mark=marks_of(grid))

    # ------------------------------------------------------------------ snapshots
    def snapshot(self) -> dict:
        """Copies of the mutable state, independent of the grid layout (for checks)."""
        return {
            "positions": self.positions,
            "mode": self.mode.copy(),
            "scent": self.scent.copy(),
            "inbox": self.inbox.copy(),
            "rng_state": self.rng_state.copy(),
        }


def window_around(positions, size, room) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)`` (3,) each: the box sites within ``room`` (an int or (3,)) of the modules'
    bounding box, clipped to the box ``0 <= p < size``."""
    positions = np.asarray(positions, dtype=np.int64).reshape(-1, 3)
    return (
        np.maximum(positions.min(axis=0) - room, 0),
        np.minimum(positions.max(axis=0) + 1 + room, np.asarray(size, dtype=np.int64)),
    )


def shared_windows(regions, sizes) -> tuple[tuple, list[tuple]]:
    """One grid layout for worlds that must each cover a ``(low, high)`` region of its box of
    ``size``: ``(extent, origins)``, the common window extent (the largest region) and each
    world's window origin, placed to cover its region and, where the extent allows, to stay
    inside its box."""
    extent = tuple(int(v) for v in np.max([high - low for low, high in regions], axis=0))
    return extent, [place_window(low, size, extent) for (low, _), size in zip(regions, sizes)]


def place_window(low, size, extent) -> tuple:
    """The origin of a window of ``extent`` that covers a region starting at ``low`` (and no
    larger than ``extent``) of a box of ``size``: inside the box where the extent allows."""
    return tuple(int(v) for v in np.maximum(np.minimum(low, np.asarray(size) - np.asarray(extent)), 0))


def _sites(sites) -> np.ndarray:
    if sites is None:
        return np.zeros((0, 3), dtype=np.int64)
    return np.asarray(sites, dtype=np.int64).reshape(-1, 3)

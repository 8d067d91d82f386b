"""FCC lattice geometry: directions, cell codes and the padded occupancy grid.

Sites are integer points ``(x, y, z)`` with ``x + y + z`` even; ``z`` is up. The 12 face
neighbours of a site are the permutations of ``(+-1, +-1, 0)``; :data:`DIRECTIONS` fixes
their order, which is also the order of the move actions (action ``k + 1`` rolls towards
``DIRECTIONS[k]``; action 0 stays).

The engine keeps occupancy in a flat ``int32`` grid covering the box plus a margin of
:data:`PAD` cells on every side, so that every cell a kernel looks at (neighbours, cells
swept by a roll, a radius-2 neighbourhood) has a valid index without bounds checks. A grid
cell holds a module index (``>= 0``) or one of the negative codes below. The grid is a dense
array, or for a large window a paged one that stores only the pages near the modules
(:mod:`~proteo_env.core.paged`); both are read as ``grid[cell]``.
"""

from __future__ import annotations

import itertools

import numpy as np

EMPTY = -1
"""An empty site inside the box."""
WALL = -2
"""A site outside the box: modules never enter it and rolls never sweep through it."""
SOLID = -3
"""Ground (every site with ``z < 0`` when the task has a floor) or an obstacle."""
OBJECT = -4
"""A site of the object to grasp."""

PAD = 2
"""Margin of grid cells around the box; covers sweeps and radius-2 neighbourhoods."""


PAGE_BITS = 9
PAGE_CELLS = 1 << PAGE_BITS
"""Cells a page of a paged grid holds (whole columns of its aligned layout; :mod:`~proteo_env.core.paged`)."""


def page_aligned(padded) -> tuple[int, int, int]:
    """Padded extents ``(sx, sy, sz)`` rounded up for pages of whole columns: ``sz`` to a power of
    two (at most :data:`PAGE_CELLS`) and ``sy`` to a multiple of the columns a page holds."""
    sx, sy, sz = (int(v) for v in padded)
    if sz > PAGE_CELLS:
        raise ValueError(f"a paged grid's padded height {sz} is not allowed; allowed: at most {PAGE_CELLS} cells")
    sz = 1 << max(sz - 1, 0).bit_length()
    columns = PAGE_CELLS // sz
    return sx, -(-sy // columns) * columns, sz


def _face_directions() -> np.ndarray:
    dirs = []
    for axes in ((0, 1), (0, 2), (1, 2)):
        for sa, sb in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
            d = [0, 0, 0]
            d[axes[0]], d[axes[1]] = sa, sb
            dirs.append(d)
    return np.array(dirs, dtype=np.int64)


DIRECTIONS: np.ndarray = _face_directions()
"""``(12, 3)`` int64: the face-neighbour offsets in action order (move ``k + 1``)."""
DIRECTIONS.setflags(write=False)

N_DIRECTIONS = 12

OPPOSITE: np.ndarray = np.array(
    [int(np.flatnonzero((DIRECTIONS == -d).all(axis=1))[0]) for d in DIRECTIONS], dtype=np.int64
)
"""``(12,)``: index of the direction opposite to each direction."""
OPPOSITE.setflags(write=False)


def neighbourhood_offsets(radius: int) -> np.ndarray:
    """Offsets of the sites within ``radius`` hops of a site, the site itself excluded.

    Radius 1 gives exactly :data:`DIRECTIONS` (same order); radius 2 appends the 42 sites
    two hops away in lexicographic order. Returns ``(K, 3)`` int64 with ``K = 12`` or ``54``.
    """
    if radius not in (1, 2):
        raise ValueError(f"obs_radius={radius!r} is not allowed; allowed: 1 or 2")
    offsets = [tuple(d) for d in DIRECTIONS]
    if radius == 2:
        ring = {tuple(a + b) for a, b in itertools.product(DIRECTIONS, DIRECTIONS) if (a + b).any()} - set(offsets)
        offsets += sorted(ring)
    return np.array(offsets, dtype=np.int64)


class GridShape:
    """Box of sites ``0 <= x < size[0]`` (etc.), or a window of it, embedded in a padded flat grid.

    The grid covers the *window* ``origin <= p < origin + extent`` of box coordinates plus
    :data:`PAD` cells on every side: by default the whole box (``origin`` 0, ``extent`` =
    ``size``); ``extent`` larger than ``size`` when worlds of different boxes share one grid
    layout in a batch; a window smaller than the box when a world grows with its modules
    (:meth:`~proteo_env.core.world.World.regrid`). Cells outside the box are walls.
    ``index(p) = ((x - ox + PAD) * sy + (y - oy + PAD)) * sz + (z - oz + PAD)`` with
    ``(sx, sy, sz)`` the padded extents and ``(ox, oy, oz)`` the origin; :attr:`strides` turns
    an offset into a flat index delta. A ``paged`` grid's padded extents are rounded up so that
    its pages hold whole columns (:func:`page_aligned`); the cells past
    ``extent + PAD`` are read as the box has them there and never reached.
    """

    def __init__(self, size, extent=None, origin=None, *, paged=False):
        self.size = tuple(int(s) for s in size)
        self.extent = self.size if extent is None else tuple(int(e) for e in extent)
        self.origin = (0, 0, 0) if origin is None else tuple(int(o) for o in origin)
        self.paged = bool(paged)
        self.padded = tuple(s + 2 * PAD for s in self.extent)
        if paged:
            self.padded = page_aligned(self.padded)
        sx, sy, sz = self.padded
        self.strides = np.array([sy * sz, sz, 1], dtype=np.int64)
        self.n_cells = sx * sy * sz

    @property
    def whole(self) -> bool:
        """The window covers the whole box (it never needs to grow)."""
        return all(o <= 0 and o + e >= s for o, e, s in zip(self.origin, self.extent, self.size))

    def guard(self) -> np.ndarray:
        """``(6,)`` int64 ``(lo_x, hi_x, lo_y, hi_y, lo_z, hi_z)``: the padded-grid coordinates a
        module may hold before a cycle so that nothing the cycle reads (up to :data:`PAD` sites
        from a module that moved one site) falls outside the grid. Where the window ends at
        the box's wall there is no limit."""
        bounds = []
        for o, e, s, p in zip(self.origin, self.extent, self.size, self.padded):
            bounds.append(PAD + 1 if o > 0 else 0)
            bounds.append(PAD + e - 2 if o + e < s else p - 1)
        return np.array(bounds, dtype=np.int64)

    def deltas(self, offsets: np.ndarray) -> np.ndarray:
        """Flat index deltas of ``(..., 3)`` offsets."""
        return np.asarray(offsets, dtype=np.int64) @ self.strides

    def index(self, points: np.ndarray) -> np.ndarray:
        """Flat grid indices of ``(..., 3)`` box coordinates (inside the window)."""
        return (np.asarray(points, dtype=np.int64) - np.array(self.origin) + PAD) @ self.strides

    def point(self, index: np.ndarray) -> np.ndarray:
        """Box coordinates ``(..., 3)`` of flat grid indices."""
        index = np.asarray(index, dtype=np.int64)
        sx, sy, sz = self.padded
        x, rest = np.divmod(index, sy * sz)
        y, z = np.divmod(rest, sz)
        return np.stack([x, y, z], axis=-1) - PAD + np.array(self.origin)

    def inside(self, points: np.ndarray) -> np.ndarray:
        """``(...,)`` bool: which ``(..., 3)`` points lie inside the box."""
        points = np.asarray(points)
        return ((points >= 0) & (points < np.array(self.size))).all(axis=-1)

"""A paged occupancy grid: memory that grows with the modules, not with their bounding box.

A world's grid is a flat array of cells over its window (:class:`~proteo_env.core.lattice.GridShape`).
Dense, it costs 4 bytes a cell, and a long structure spans a large window: a chain of 1,200
modules lies along its box's diagonal, 2,000 x 2,000 x 36 cells (0.6 GB, and as much again for
the connectivity search's marks). :class:`PagedCells` keeps the same flat cell indices, so every
kernel reads and writes ``grid[cell]`` as before, but stores only pages of
:data:`PAGE_CELLS` consecutive cells:

- The layout is aligned (:func:`~proteo_env.core.lattice.page_aligned`) so that a page holds whole columns (every ``z`` of
  some consecutive ``y`` at one ``x``). Columns differ only by whether their ``(x, y)`` lies in
  the box, so a page without modules or static sites has one of a few *background* contents,
  stored once and shared (read only).
- A page a module enters is copied from its background the first time a cell of it is written
  (:meth:`PagedCells.__setitem__`); pages that hold a solid or object site are copied once at
  build and kept.
- When no copied page is free, the pages that hold no module and no static site return to their
  background (:meth:`PagedCells.collect`). There are ``2 N + 64`` pages beside those, so a
  collection frees at least ``N + 64`` and runs once in that many page copies.

The connectivity search's marks (:class:`PagedMarks`) use the same page table: a search marks only
cells that hold a module, which lie in copied pages. What a cycle does does not depend on where
the cells are stored, so a world follows the same trajectory on a paged grid as on a dense one,
draw for draw.
"""

from __future__ import annotations

import numba
import numpy as np
from numba.experimental import jitclass

from .jit import kernel
from .lattice import EMPTY, PAD, PAGE_BITS, PAGE_CELLS, SOLID, WALL

PAGE_MASK = PAGE_CELLS - 1

PAGE_TABLE_BYTES = 24
"""Bytes a virtual page costs whether stored or not, at most: its entries in ``table``,
``background`` and ``keep`` (9) and the temporaries of building them."""

SPARE_PAGES = 64
"""Copied pages beyond twice the modules: what a collection frees at least, beside ``N``."""


@jitclass(
    [
        ("table", numba.int32[:]),
        ("background", numba.int32[:]),
        ("keep", numba.boolean[:]),
        ("pages", numba.int32[:, :]),
        ("marks", numba.int32[:, :]),
        ("owner", numba.int64[:]),
        ("free", numba.int64[:]),
        ("n_free", numba.int64),
        ("n_shared", numba.int64),
        ("cell", numba.int64[:]),
    ]
)
class PagedCells:
    """The cells of a grid, stored by pages; indexed like the dense ``(cells,)`` array.

    Attributes (V virtual pages, P stored pages, N modules):
        table: ``(V,)`` the stored page of each virtual page.
        background: ``(V,)`` the shared page of each virtual page's background (ids ``< n_shared``).
        keep: ``(V,)`` pages never returned to their background (they hold static sites).
        pages: ``(P, PAGE_CELLS)`` stored pages: the shared backgrounds first, then copies.
        marks: ``(P, PAGE_CELLS)`` the connectivity search's marks, page for page.
        owner: ``(P,)`` the virtual page a copy stands for (-1: free; shared pages: -1).
        free: ``(P,)`` a stack of the free copies, ``n_free`` deep.
        cell: ``(N,)`` the world's module cells (the same array as its state's): what a
            collection keeps.
    """

    def __init__(self, table, background, keep, pages, marks, owner, free, n_free, n_shared, cell):
        self.table = table
        self.background = background
        self.keep = keep
        self.pages = pages
        self.marks = marks
        self.owner = owner
        self.free = free
        self.n_free = n_free
        self.n_shared = n_shared
        self.cell = cell

    def __getitem__(self, i):
        return self.pages[self.table[i >> PAGE_BITS], i & PAGE_MASK]

    def __setitem__(self, i, value):
        page = i >> PAGE_BITS
        stored = self.table[page]
        if stored < self.n_shared:
            stored = self.copy_page(page)
        self.pages[stored, i & PAGE_MASK] = value

    def copy_page(self, page):
        """Give virtual ``page`` a stored copy of its background; return its id."""
        if self.n_free == 0:
            self.collect()
        self.n_free -= 1
        stored = self.free[self.n_free]
        self.pages[stored, :] = self.pages[self.table[page], :]
        self.marks[stored, :] = -1
        self.owner[stored] = page
        self.table[page] = stored
        return stored

    def collect(self):
        """Return every copied page that holds no module and no static site to its background."""
        held = np.zeros(self.pages.shape[0], dtype=np.bool_)
        for n in range(self.cell.shape[0]):
            held[self.table[self.cell[n] >> PAGE_BITS]] = True
        for stored in range(self.n_shared, self.pages.shape[0]):
            page = self.owner[stored]
            if page >= 0 and not held[stored] and not self.keep[page]:
                self.table[page] = self.background[page]
                self.owner[stored] = -1
                self.free[self.n_free] = stored
                self.n_free += 1
        if self.n_free == 0:
            raise MemoryError("a paged grid ran out of pages (more modules than it was built for)")

    def n_copied(self):
        """Pages holding copies now."""
        return self.pages.shape[0] - self.n_shared - self.n_free


@jitclass([("table", numba.int32[:]), ("marks", numba.int32[:, :])])
class PagedMarks:
    """The connectivity search's marks over a :class:`PagedCells`' pages (its ``table`` and
    ``marks``): indexed like the dense ``(cells,)`` array, at cells that hold a module."""

    def __init__(self, table, marks):
        self.table = table
        self.marks = marks

    def __getitem__(self, i):
        return self.marks[self.table[i >> PAGE_BITS], i & PAGE_MASK]

    def __setitem__(self, i, value):
        self.marks[self.table[i >> PAGE_BITS], i & PAGE_MASK] = value

    def fill(self, value):
        self.marks[:, :] = value


def paged_cells(shape, floor: bool, static, cell: np.ndarray) -> PagedCells:
    """The static grid of ``shape`` (a paged :class:`~proteo_env.core.lattice.GridShape`) stored by
    pages, with room for the modules of ``cell`` (``(N,)`` int64, not placed yet).

    Args:
        shape: the grid layout (``shape.paged``).
        floor: every site with ``z < 0`` is ground.
        static: ``(cells, code)`` pairs: ``(S,)`` cell indices and the code they hold.
        cell: the world's module cells; the grid keeps this array (:class:`PagedCells`).
    """
    sx, sy, sz = shape.padded
    columns = PAGE_CELLS // sz
    rows = sy // columns  # virtual pages along y, at one x
    # what a column holds: in the box, empty between the box's floor and ceiling; outside, wall
    z = np.arange(sz) - PAD + shape.origin[2]
    inside_column = np.where((z >= 0) & (z < shape.size[2]), EMPTY, WALL).astype(np.int32)
    outside_column = np.full(sz, WALL, dtype=np.int32)
    if floor:
        inside_column[z < 0] = SOLID
        outside_column[z < 0] = SOLID
    x = np.arange(sx) - PAD + shape.origin[0]
    y = np.arange(sy) - PAD + shape.origin[1]
    x_in = (x >= 0) & (x < shape.size[0])
    y_in = ((y >= 0) & (y < shape.size[1])).reshape(rows, columns)
    kinds, kind_of = np.unique(np.vstack([y_in, np.zeros((1, columns), bool)]), axis=0, return_inverse=True)
    kind_of = kind_of.reshape(-1).astype(np.int32)
    background = np.where(x_in[:, None], kind_of[None, :rows], kind_of[rows]).reshape(-1)
    n_shared = len(kinds)
    kept = np.unique(np.concatenate([c for c, _ in static] + [np.zeros(0, np.int64)]) >> PAGE_BITS)
    capacity = n_shared + len(kept) + 2 * len(cell) + SPARE_PAGES
    pages = np.zeros((capacity, PAGE_CELLS), dtype=np.int32)
    for k, in_box in enumerate(kinds):
        pages[k] = np.where(in_box[:, None], inside_column[None, :], outside_column[None, :]).reshape(-1)
    keep = np.zeros(len(background), dtype=np.bool_)
    keep[kept] = True
    grid = PagedCells(
        background.copy(),
        background,
        keep,
        pages,
        np.zeros((capacity, PAGE_CELLS), dtype=np.int32),
        np.full(capacity, -1, dtype=np.int64),
        np.arange(capacity - 1, n_shared - 1, -1, dtype=np.int64),
        capacity - n_shared,
        n_shared,
        cell,
    )
    for cells, code in static:
        write_cells(grid, np.asarray(cells, dtype=np.int64), np.full(len(cells), code, dtype=np.int32))
    return grid


def paged_bytes(n_modules: int) -> int:
    """Bytes a paged grid of ``n_modules`` modules holds at most beside its page table: its copied
    pages and their marks (a few shared pages and the static sites' pages besides)."""
    return (2 * int(n_modules) + SPARE_PAGES + 8) * PAGE_CELLS * 8


@kernel
def write_cells(grid, index, values):
    """``grid[index[i]] = values[i]`` for every ``i`` (a dense or a paged grid)."""
    for i in range(index.shape[0]):
        grid[index[i]] = values[i]


@kernel
def read_cells(grid, index, out):
    """``out[i] = grid[index[i]]`` for every ``i`` (a dense or a paged grid)."""
    for i in range(index.shape[0]):
        out[i] = grid[index[i]]


def cells_at(grid, index) -> np.ndarray:
    """``(K,)`` int32: what ``grid`` (dense or paged) holds at the cells ``index`` (``(K,)``)."""
    index = np.ascontiguousarray(index, dtype=np.int64).reshape(-1)
    if isinstance(grid, np.ndarray):
        return grid[index]
    out = np.empty(len(index), dtype=np.int32)
    read_cells(grid, index, out)
    return out


def copy_grid(grid, cell: np.ndarray):
    """A copy of ``grid`` (dense or paged) for a copy of the world whose module cells are ``cell``
    (a paged grid keeps the cells it collects by)."""
    if isinstance(grid, np.ndarray):
        return grid.copy()
    shared = ("background", "keep", "n_free", "n_shared")  # read only, or numbers
    return paged_from_state({k: v if k in shared else v.copy() for k, v in paged_state(grid).items()}, cell)


PAGED_FIELDS = ("table", "background", "keep", "pages", "marks", "owner", "free", "n_free", "n_shared")
"""What a :class:`PagedCells` holds beside the module cells (what pickling keeps)."""


def paged_state(grid: PagedCells) -> dict:
    """``grid``'s arrays and counts by name (:data:`PAGED_FIELDS`), for pickling."""
    return {name: getattr(grid, name) for name in PAGED_FIELDS}


def paged_from_state(state: dict, cell: np.ndarray) -> PagedCells:
    """The :class:`PagedCells` of :func:`paged_state`'s ``state``, over the module cells ``cell``."""
    return PagedCells(*(state[name] for name in PAGED_FIELDS), cell)


def marks_of(grid: PagedCells) -> PagedMarks:
    """The connectivity search's marks over ``grid``'s pages."""
    return PagedMarks(grid.table, grid.marks)

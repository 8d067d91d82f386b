"""O(N) kernels that measure the shape of the module graph (for task metrics and success)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .jit import inline_kernel, kernel


@kernel
def module_degrees(grid, cell, n_modules, dir_delta, degree):
    """Fill ``degree`` (N,) with each module's number of face-neighbour modules."""
    for n in range(n_modules):
        d = 0
        for k in range(12):
            if grid[cell[n] + dir_delta[k]] >= 0:
                d += 1
        degree[n] = d


UNREACHED, BARRED = -2, -3
""":func:`breadth_first`'s ``reach`` values of a module it has not reached yet and of one it may not enter."""


@inline_kernel
def breadth_first(grid, cell, dir_delta, reach, queue, tail, max_hops):
    """The breadth-first search of the core: from the modules ``queue[:tail]`` through face
    neighbours, in the order of ``dir_delta``, into modules whose ``reach`` is :data:`UNREACHED`.

    ``reach`` (N,) int: set by the caller to -1 for the sources, :data:`UNREACHED` for a module
    the search may enter and :data:`BARRED` for one it may not; the search sets each module it
    reaches to the module it was reached from. A module ``max_hops`` hops from the nearest
    source is not expanded. Returns the number of modules in ``queue`` (sources included), in
    the order reached: parents before children, nearer before farther.
    """
    head, hops = 0, 0
    while head < tail and hops < max_hops:
        level_end = tail  # the modules ``hops`` hops away are queue[head:level_end]
        while head < level_end:
            n = queue[head]
            head += 1
            c = cell[n]
            for k in range(12):
                nb = grid[c + dir_delta[k]]
                if nb >= 0 and reach[nb] == UNREACHED:
                    reach[nb] = n
                    queue[tail] = nb
                    tail += 1
        hops += 1
    return tail


@kernel
def largest_thin_piece(grid, cell, n_modules, dir_delta, degree, mark, queue):
    """Size of the largest connected piece made only of modules with at most 2 neighbours.

    Such a piece is a one-module-thick chain (or ring). ``degree`` from :func:`module_degrees`;
    ``mark`` and ``queue`` are (N,) scratch (``mark``: :func:`breadth_first`'s ``reach``).
    """
    for n in range(n_modules):
        mark[n] = UNREACHED if degree[n] <= 2 else BARRED
    best = 0
    for root in range(n_modules):
        if mark[root] != UNREACHED:
            continue
        mark[root] = -1
        queue[0] = root
        best = max(best, breadth_first(grid, cell, dir_delta, mark, queue, 1, n_modules))
    return best


@kernel
def graph_shape(grid, cell, n_modules, dir_delta, degree, mark, queue):
    """``(edges, thin_piece, thin, max_degree)``: the number of face contacts between modules,
    the size of the largest one-module-thick piece (:func:`largest_thin_piece`), the number of
    modules with at most 2 neighbours and the largest number of neighbours; fills ``degree`` (N,)
    as :func:`module_degrees` does."""
    module_degrees(grid, cell, n_modules, dir_delta, degree)
    edges, thin, max_degree = 0, 0, 0
    for n in range(n_modules):
        edges += degree[n]
        thin += degree[n] <= 2
        max_degree = max(max_degree, degree[n])
    thin_piece = largest_thin_piece(grid, cell, n_modules, dir_delta, degree, mark, queue)
    return edges // 2, thin_piece, thin, max_degree


@kernel
def graph_shapes(grid, cell, n_modules, dir_delta, degree, mark, queue, out):
    """:func:`graph_shape` of every world of a batch (one grid layout, ``B`` rows): ``grid``
    ``(B, cells)``, ``cell`` ``(B, N)``; ``degree``, ``mark`` and ``queue`` ``(B, N)`` scratch
    (``degree[b]`` filled as :func:`module_degrees` does); ``out`` ``(B, 4)`` int64 gets each
    world's ``(edges, thin_piece, thin, max_degree)``."""
    for b in range(grid.shape[0]):
        edges, piece, thin, most = graph_shape(grid[b], cell[b], n_modules, dir_delta, degree[b], mark[b], queue[b])
        out[b, 0], out[b, 1], out[b, 2], out[b, 3] = edges, piece, thin, most


class GraphShape(NamedTuple):
    """The shape of a world's module graph (:meth:`StructureProbe.measure`)."""

    edges: int
    """Face contacts between modules."""
    thin_piece: int
    """Modules in the largest one-module-thick piece (a chain or ring)."""
    thin: int
    """Modules with at most 2 module neighbours."""
    max_degree: int
    """The most module neighbours of any module."""


class StructureProbe:
    """Reusable scratch for measuring a world's module graph.

    ``measure(world)`` returns its :class:`GraphShape`; ``degree`` (N,) then holds each
    module's number of module neighbours.
    """

    def __init__(self, n_modules: int):
        self.degree = np.zeros(n_modules, dtype=np.int64)
        self.mark = np.zeros(n_modules, dtype=np.int64)
        self.queue = np.zeros(n_modules, dtype=np.int64)

    def measure(self, world) -> GraphShape:
        # the kernel returns Python ints already
        return GraphShape._make(
            graph_shape(world.grid, world.cell, world.n_modules, world.dir_delta, self.degree, self.mark, self.queue)
        )

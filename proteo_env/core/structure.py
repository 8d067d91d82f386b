"""O(N) kernels that measure the shape of the module graph (for task metrics and success)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .jit import kernel


@kernel
def module_degrees(grid, cell, n_modules, dir_delta, degree):
    """Fill ``degree`` (N,) with each module's number of face-neighbour modules."""
    for n in range(n_modules):
        d = 0
        for k in range(12):
            if grid[cell[n] + dir_delta[k]] >= 0:
                d += 1
        degree[n] = d


@kernel
def largest_thin_piece(grid, cell, n_modules, dir_delta, degree, mark, queue):
    """Size of the largest connected piece made only of modules with at most 2 neighbours.

    Such a piece is a one-module-thick chain (or ring). ``degree`` from :func:`module_degrees`;
    ``mark`` and ``queue`` are (N,) scratch.
    """
    for n in range(n_modules):
        mark[n] = 0
    best = 0
    for root in range(n_modules):
        if mark[root] or degree[root] > 2:
            continue
        mark[root] = 1
        queue[0] = root
        head, tail = 0, 1
        while head < tail:
            n = queue[head]
            head += 1
            for k in range(12):
                nb = grid[cell[n] + dir_delta[k]]
                if nb >= 0 and not mark[nb] and degree[nb] <= 2:
                    mark[nb] = 1
                    queue[tail] = nb
                    tail += 1
        best = max(best, tail)
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

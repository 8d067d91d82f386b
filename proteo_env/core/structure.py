"""O(N) kernels that measure the shape of the module graph (for task metrics and success)."""

from __future__ import annotations

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


class StructureProbe:
    """Reusable scratch for measuring a world's module graph.

    ``measure(world)`` returns ``degree (N,)``, the number of edges, and the size of the
    largest one-module-thick piece.
    """

    def __init__(self, n_modules: int):
        self.degree = np.zeros(n_modules, dtype=np.int64)
        self.mark = np.zeros(n_modules, dtype=np.int64)
        self.queue = np.zeros(n_modules, dtype=np.int64)

    def measure(self, world):
        module_degrees(world.grid, world.cell, world.n_modules, world.dir_delta, self.degree)
        edges = int(self.degree.sum()) // 2
        thin = largest_thin_piece(
            world.grid, world.cell, world.n_modules, world.dir_delta, self.degree, self.mark, self.queue
        )
        return self.degree, edges, int(thin)

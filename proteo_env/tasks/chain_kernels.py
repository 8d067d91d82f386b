"""The chain task's success test as numba kernels (:mod:`proteo_env.tasks.chain` is the task),
for compiled rollouts (:meth:`~proteo_env.tasks.chain.Chain.kernels`)."""

from __future__ import annotations

from enum import IntEnum

from ..core.jit import kernel
from ..core.structure import largest_thin_piece


class ChainMode(IntEnum):
    """The chain's modes (paper section 4.1): the one definition the task and its rules share."""

    SLEEP = 0
    SEARCH = 1
    SEED = 2
    FINAL = 3


SLEEP, SEARCH, SEED, FINAL = (int(m) for m in ChainMode)
"""The same modes as plain ints, for the numba kernels."""


@kernel
def is_chain(grid, cell, n_modules, dir_delta, degree, mark, queue):
    """The chain task's success test: connected, ``N - 1`` contacts, every module with at most
    2 neighbours. Stops at the first module with 3 or more (``degree``, ``mark``, ``queue``:
    (N,) scratch)."""
    contacts = 0
    for n in range(n_modules):
        d = 0
        for k in range(12):
            if grid[cell[n] + dir_delta[k]] >= 0:
                d += 1
        if d > 2:
            return False
        degree[n] = d
        contacts += d
    if contacts // 2 != n_modules - 1:
        return False
    return largest_thin_piece(grid, cell, n_modules, dir_delta, degree, mark, queue) == n_modules


@kernel
def chain_update_and_test(grid, cell, mode, anchored, dir_delta, cycle, scratch):
    """:func:`is_chain` as a task's ``update_and_test`` (:class:`~proteo_env.tasks.base.TaskKernels`);
    ``scratch`` is ``(3, N)`` int64."""
    return is_chain(grid, cell, cell.shape[0], dir_delta, scratch[0], scratch[1], scratch[2])

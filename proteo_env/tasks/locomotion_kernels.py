"""The locomotion task's success test as numba kernels (:mod:`proteo_env.tasks.locomotion` is the
task), for the environment and for compiled rollouts (:meth:`~proteo_env.tasks.locomotion.Locomotion.kernels`)."""

from __future__ import annotations

from enum import IntEnum

from ..core.jit import kernel


class LocomotionMode(IntEnum):
    """The locomotion task's modes: the one definition the task and its rules share."""

    SEARCH = 0
    SEED = 1


SEARCH, SEED = (int(m) for m in LocomotionMode)
"""The same modes as plain ints, for the numba kernels."""


@kernel
def all_beyond(cell, finish_cell):
    """Every module is beyond the finish line: each of ``cell`` (N,) is at least ``finish_cell``
    (grid cells are ordered by ``x`` first, so this compares ``x`` with the line's)."""
    for n in range(cell.shape[0]):
        if cell[n] < finish_cell:
            return False
    return True


@kernel
def locomotion_update_and_test(grid, cell, mode, anchored, dir_delta, cycle, finish_cell):
    """:func:`all_beyond` as a task's ``update_and_test`` (:class:`~proteo_env.tasks.base.TaskKernels`);
    the state is the finish line's first grid cell (an int)."""
    return all_beyond(cell, finish_cell)

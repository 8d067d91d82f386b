"""The grasp task's success test as a numba kernel (:mod:`proteo_env.tasks.grasp` is the task):
the environment and the compiled rollout of the hand-coded behaviour (:mod:`baselines.compiled`)
both test a hold with :func:`grasp_hold`.
"""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple

import numpy as np

from ..core.jit import kernel


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
        side: ``(S,)`` int64 side (0..11, :data:`~proteo_env.tasks.grasp.SIDES`) of each surface site.
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


@kernel
def grasp_update_and_test(grid, cell, mode, anchored, dir_delta, cycle, surface):
    """:func:`grasp_hold`'s success as a task's ``update_and_test`` (:class:`~proteo_env.tasks.base.TaskKernels`)."""
    return grasp_hold(grid, surface)[3]

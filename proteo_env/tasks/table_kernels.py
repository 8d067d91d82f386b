"""The table task's bookkeeping as numba kernels: the ledger of roots, legs, the weight
schedule and the stable period, and the load sensor (:mod:`proteo_env.tasks.table` is the task).

The environment calls them after every cycle; the compiled rollout of the hand-coded behaviour
(:mod:`baselines.compiled`) runs the same kernels on a copy of the ledger.
"""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple

import numpy as np

from ..core.jit import kernel


class TableMode(IntEnum):
    """The table task's modes (paper section 4.3): the board (FIXED), the roots, the legs; the one definition the task and its rules share."""

    FIXED = 0
    ROOT = 1
    IROOT = 2
    AROOT = 3
    SLEEP = 4
    SEARCH = 5
    SEED = 6
    FINAL = 7
    DISBAND = 8


FIXED, ROOT, IROOT, AROOT, SLEEP, SEARCH, SEED, FINAL, DISBAND = (int(m) for m in TableMode)
"""The same modes as plain ints, for the numba kernels."""
CYCLE, SHIFT, SINCE, CREATIONS, DISBANDS = range(5)
"""Entries of :attr:`TableLedger.clock`: the last cycle, the schedule entry in force, the cycle the
signature last changed, leg creations and leg disbands so far."""


class TableLedger(NamedTuple):
    """The table episode's bookkeeping as the kernels below read and update it (R roots, K
    schedule entries, N modules); the compiled rollout of the hand-coded behaviour
    (:mod:`baselines.compiled`) runs the same kernels on a copy.

    Attributes:
        roots: ``(R,)`` int64 agent index of each root.
        left: ``(R,)`` bool, the root is in the left region.
        down_delta: ``(4,)`` int64 grid offsets of the face sites one layer down.
        shift_cycles: ``(K,)`` int64 cycles at which the schedule's entries start.
        schedule_weights: ``(K, 2)`` float64 weights (left, right) of each entry.
        depth, stable_window, load_cap, f_max: the task's parameters of those names.
        carry: a complete signature also needs the legs to carry the weight
            (:func:`weight_carried`; ``table-v1``); ``False`` in ``table-v0``.
        active: ``(R,)`` bool, the root is ROOT or AROOT (after the last cycle).
        grounded: ``(R,)`` bool, the root has a grounded leg (after the last cycle).
        signature: ``(2, R)`` bool, (active, grounded) since ``clock[SINCE]``.
        clock: ``(5,)`` int64, indexed by :data:`CYCLE`, :data:`SHIFT`, :data:`SINCE`,
            :data:`CREATIONS`, :data:`DISBANDS`.
        weights: ``(2,)`` float64 weights (left, right) now.
        restabilise: ``(K,)`` float64, cycles to re-stabilise after each shift (-1: not yet).
        scratch: ``(3, N)`` int64 scratch of :func:`grounded_legs`; ``stamp``: ``(1,)`` int64.
    """

    roots: np.ndarray
    left: np.ndarray
    down_delta: np.ndarray
    shift_cycles: np.ndarray
    schedule_weights: np.ndarray
    depth: int
    stable_window: int
    load_cap: float
    active: np.ndarray
    grounded: np.ndarray
    signature: np.ndarray
    clock: np.ndarray
    weights: np.ndarray
    restabilise: np.ndarray
    scratch: np.ndarray
    stamp: np.ndarray
    f_max: float
    carry: bool

    def copy(self) -> TableLedger:
        """A copy whose arrays are new."""
        return TableLedger(*(v.copy() if isinstance(v, np.ndarray) else v for v in self))


@kernel
def region_loads(book):
    """``(2,)`` the load sensor's reading in the left and the right region of
    :class:`TableLedger` ``book``: the region's weight per active root, ``load_cap`` with weight
    and no active root, at most ``load_cap``."""
    loads = np.zeros(2)
    for region in range(2):
        n_active = 0
        for r in range(book.roots.shape[0]):
            if book.active[r] and book.left[r] == (region == 0):
                n_active += 1
        if n_active > 0:
            loads[region] = min(book.weights[region] / n_active, book.load_cap)
        elif book.weights[region] > 0:
            loads[region] = book.load_cap
    return loads


@kernel
def weight_carried(book):
    """Whether the grounded legs of :class:`TableLedger` ``book`` carry the weight as far as
    the roots allow: in each region ``min(W, f_max * G) == min(W, f_max * R)``, ``G`` the roots
    with a grounded leg and ``R`` all roots of the region (a region whose roots cannot carry
    all of its weight needs every one of them grounded)."""
    for region in range(2):
        n_grounded = 0
        n_roots = 0
        for r in range(book.roots.shape[0]):
            if book.left[r] == (region == 0):
                n_roots += 1
                if book.grounded[r]:
                    n_grounded += 1
        weight = book.weights[region]
        if min(weight, book.f_max * n_grounded) < min(weight, book.f_max * n_roots):
            return False
    return True


@kernel
def root_loads(book, out):
    """Write each root's reading (:func:`region_loads`) into ``out[roots]`` (float32, (A,) or (A, 1))."""
    loads = region_loads(book)
    for r in range(book.roots.shape[0]):
        out[book.roots[r]] = loads[0] if book.left[r] else loads[1]


@kernel
def _legs_below(grid, cell, mode, anchored, above, n_above, down_delta, seen, stamp, below):
    """Write into ``below`` the leg modules (SEED or FINAL, not anchored) one layer below the
    modules ``above[:n_above]``, each once (``seen[v] == stamp``); return how many."""
    n_below = 0
    for j in range(n_above):
        for d in range(down_delta.shape[0]):
            v = grid[cell[above[j]] + down_delta[d]]
            if v >= 0 and (mode[v] == SEED or mode[v] == FINAL) and not anchored[v] and seen[v] != stamp:
                seen[v] = stamp
                below[n_below] = v
                n_below += 1
    return n_below


@kernel
def grounded_legs(grid, cell, mode, anchored, book):
    """Write ``book.grounded`` (R,): a chain of SEED or FINAL modules runs from the root down to
    the floor, one layer per module (``depth`` modules). ``stamp`` is bumped so that
    ``scratch[2]`` never needs clearing."""
    roots, down_delta, stamp = book.roots, book.down_delta, book.stamp
    level, below, seen = book.scratch[0], book.scratch[1], book.scratch[2]
    for r in range(roots.shape[0]):
        level[0] = roots[r]
        n_level = 1
        for _ in range(book.depth):
            stamp[0] += 1
            n_level = _legs_below(grid, cell, mode, anchored, level, n_level, down_delta, seen, stamp[0], below)
            level, below = below, level
            if n_level == 0:
                break
        book.grounded[r] = n_level > 0


@kernel
def table_update(grid, cell, mode, anchored, cycle, book):
    """Update :class:`TableLedger` ``book`` after ``cycle``: active roots and grounded legs, leg
    creations and disbands, the signature and the cycle it last changed, ``restabilise`` of the
    schedule entry in force, and the schedule's next shift."""
    roots, active, grounded, signature, clock = book.roots, book.active, book.grounded, book.signature, book.clock
    shift_cycles, restabilise = book.shift_cycles, book.restabilise
    clock[CYCLE] = cycle
    changed = False
    for r in range(roots.shape[0]):
        now = mode[roots[r]] == ROOT or mode[roots[r]] == AROOT
        if now and not active[r]:
            clock[CREATIONS] += 1
        if active[r] and not now:
            clock[DISBANDS] += 1
        active[r] = now
    grounded_legs(grid, cell, mode, anchored, book)
    complete = True
    for r in range(roots.shape[0]):
        changed |= signature[0, r] != active[r] or signature[1, r] != grounded[r]
        complete &= active[r] == grounded[r]
    if book.carry:
        complete = complete and weight_carried(book)
    if changed:
        signature[0] = active
        signature[1] = grounded
        clock[SINCE] = cycle
    k = clock[SHIFT]
    start = max(clock[SINCE], shift_cycles[k])
    if restabilise[k] < 0 and complete and cycle - start >= book.stable_window:
        restabilise[k] = start - shift_cycles[k]
    if k + 1 < shift_cycles.shape[0] and cycle == shift_cycles[k + 1]:
        clock[SHIFT] = k + 1
        book.weights[:] = book.schedule_weights[k + 1]


@kernel
def table_sense(book, load):
    """The load sensor as a task's ``sense`` (:class:`~proteo_env.tasks.base.TaskKernels`): each
    root's share of its region's weight into ``load`` (A, 1) (:func:`root_loads`)."""
    root_loads(book, load[:, 0])


@kernel
def table_update_and_test(grid, cell, mode, anchored, dir_delta, cycle, book):
    """:func:`table_update` as a task's ``update_and_test``: success once the last schedule entry
    has re-stabilised."""
    table_update(grid, cell, mode, anchored, cycle, book)
    return book.restabilise[-1] >= 0

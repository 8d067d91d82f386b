"""The engine's named records: what the kernels take instead of long lists of arrays.

A world travels into the kernels as a few records, each a ``NamedTuple`` that numba compiles
as a struct (reading a field costs nothing):

=================== ===========================================================================
record              holds
=================== ===========================================================================
:class:`WorldState` the arrays a cycle changes (and the anchors): what a batch stacks per world
:class:`Settings`   the numbers and per-channel arrays that say how the cycle runs
:class:`Geometry`   the lattice tables turned into grid-index offsets for one grid layout
:class:`Scratch`    work arrays of the kernels, never part of the state
:class:`Actions`    every agent's action of one cycle, one array per action field
:class:`Observation` the observation arrays the engine fills (first axis: agent)
=================== ===========================================================================

Adding an array to the world means adding a field to one record and reading it where it is
used; no argument list changes.

Records cross from Python into compiled code as plain tuples in field order
(``tuple(record)``, :meth:`Observation.plain`): numba types a plain tuple of arrays at the call several times faster than
a named one (about 1.7 against 3.1 microseconds for seven arrays), which matters at a few
hundred modules per cycle. The entry kernels name them again at their first line
(``state = WorldState(*state)``), which costs nothing in compiled code.

A batch of ``B`` worlds holds the same records with a leading ``B`` axis on every array of
:class:`WorldState`, :class:`Scratch`, :class:`Actions` and :class:`Observation`;
:func:`row` takes world ``b``'s row of such a record inside a kernel.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba.extending import overload

from .paged import marks_of


class WorldState(NamedTuple):
    """One world's state (N modules, C channels, a padded grid of ``cells`` cells).

    Attributes:
        grid: ``(cells,)`` int32 occupancy: module index, or EMPTY/WALL/SOLID/OBJECT (or a
            :class:`~proteo_env.core.paged.PagedCells` indexed alike).
        cell: ``(N,)`` int64 flat grid index of each module.
        anchored: ``(N,)`` bool, modules that never move.
        mode: ``(N,)`` int32 each module's mode as its neighbours see it.
        scent: ``(C, N)`` int32 scent per channel (``scent_max``: none).
        inbox: ``(N, 12)`` int32 message received from each direction last cycle (0: none).
        rng_state: ``(1,)`` uint64 the move-order generator (xorshift64).
    """

    grid: np.ndarray
    cell: np.ndarray
    anchored: np.ndarray
    mode: np.ndarray
    scent: np.ndarray
    inbox: np.ndarray
    rng_state: np.ndarray


class Settings(NamedTuple):
    """How one world's cycle runs (fixed for its life).

    Attributes:
        n_agents: modules ``0 .. n_agents - 1`` act; the rest are passive board modules.
        keep_connected: deny a move that would disconnect the other modules.
        exact_scent: true hop distances every cycle instead of relaxation sweeps.
        scent_sweeps: relaxation sweeps per cycle.
        scent_max: saturating value that means "no scent".
        passive_role: ``(C,)`` int8 scent role of the passive modules on each channel.
        surface_channels: ``(C,)`` bool, channels that relay only through surface modules.
    """

    n_agents: int
    keep_connected: bool
    exact_scent: bool
    scent_sweeps: int
    scent_max: int
    passive_role: np.ndarray
    surface_channels: np.ndarray


class Geometry(NamedTuple):
    """The lattice tables of one grid layout (K neighbourhood sites, R swept sites).

    Attributes:
        directions: ``(12, 3)`` int64 the face directions (:data:`~proteo_env.core.lattice.DIRECTIONS`).
        opposite: ``(12,)`` int64 index of each direction's opposite.
        dir_delta: ``(12,)`` int64 grid-index offset of each face neighbour.
        neighbourhood_delta: ``(K,)`` int64 offsets of the observed sites, face neighbours first.
        roll_delta: ``(R,)`` int64 offsets of the sites the motion model reads.
        roll_table: the motion model's legality table (:func:`~proteo_env.core.motion.motion_bits`).
        local_delta: ``(54,)`` int64 offsets of the sites within two hops.
        local_adjacency: ``(7, 256)`` int64 adjacency bits of those sites, a byte at a time.
    """

    directions: np.ndarray
    opposite: np.ndarray
    dir_delta: np.ndarray
    neighbourhood_delta: np.ndarray
    roll_delta: np.ndarray
    roll_table: np.ndarray
    local_delta: np.ndarray
    local_adjacency: np.ndarray


class Scratch(NamedTuple):
    """Work arrays of one world's kernels, for N modules on a grid of ``cells`` cells.

    Attributes:
        mark: ``(cells,)`` int32 labels of the connectivity search (paged with a paged grid).
        queue: ``(N,)`` int64 breadth-first queue.
        movers: ``(N,)`` int64 the agents that asked to move, in trial order.
        stacks: ``(12, N)`` int64 the connectivity search's stacks, one per neighbour group.
        search: ``(13,)`` int64 the connectivity search's epoch and stack tops.
        adjacency: ``(N, 13)`` int32 neighbour lists of the cut-module search.
        disc, low, stack_node, stack_k: ``(N,)`` int32 the cut-module search's arrays.
        scent_buffer: ``(N,)`` int32 the previous relaxation sweep (the exact scent's ``reach``).
        is_cut: ``(N,)`` bool, modules whose removal disconnects the others.
    """

    mark: np.ndarray
    queue: np.ndarray
    movers: np.ndarray
    stacks: np.ndarray
    search: np.ndarray
    adjacency: np.ndarray
    disc: np.ndarray
    low: np.ndarray
    stack_node: np.ndarray
    stack_k: np.ndarray
    scent_buffer: np.ndarray
    is_cut: np.ndarray

    @classmethod
    def allocate(cls, n: int, grid) -> Scratch:
        """Fresh work arrays for ``n`` modules on ``grid`` (dense, or paged: its marks are kept
        with its pages, :class:`~proteo_env.core.paged.PagedMarks`)."""
        return cls(
            mark=np.full(len(grid), -1, dtype=np.int32) if isinstance(grid, np.ndarray) else marks_of(grid),
            queue=np.zeros(n, dtype=np.int64),
            movers=np.zeros(n, dtype=np.int64),
            stacks=np.zeros((12, n), dtype=np.int64),
            search=np.zeros(13, dtype=np.int64),
            adjacency=np.zeros((n, 13), dtype=np.int32),
            disc=np.zeros(n, dtype=np.int32),
            low=np.zeros(n, dtype=np.int32),
            stack_node=np.zeros(n, dtype=np.int32),
            stack_k=np.zeros(n, dtype=np.int32),
            scent_buffer=np.zeros(n, dtype=np.int32),
            is_cut=np.zeros(n, dtype=np.bool_),
        )


class Actions(NamedTuple):
    """Every agent's action of one cycle (A agents, C channels).

    Attributes:
        move: ``(A,)`` int64 0 to stay or ``k + 1`` to roll towards ``DIRECTIONS[k]``.
        mode: ``(A,)`` int32 each agent's new mode.
        scent_role: ``(A, C)`` int8 0 silent, 1 relay, 2 emit.
        message_target: ``(A,)`` int64 direction 0..11, or 12 for all neighbours.
        message_value: ``(A,)`` int32 value to send, 0 for none.
    """

    move: np.ndarray
    mode: np.ndarray
    scent_role: np.ndarray
    message_target: np.ndarray
    message_value: np.ndarray

    @classmethod
    def of(cls, *, move, mode, scent_role, message_target, message_value) -> Actions:
        """The record of these arrays in the kernels' dtypes (no copy where they already are)."""
        return cls(
            np.asarray(move, dtype=np.int64),
            np.asarray(mode, dtype=np.int32),
            np.asarray(scent_role, dtype=np.int8),
            np.asarray(message_target, dtype=np.int64),
            np.asarray(message_value, dtype=np.int32),
        )


class Observation(NamedTuple):
    """The observation arrays the engine fills (A agents, K neighbourhood sites, C channels).

    Attributes:
        neighbour_kind: ``(A, K)`` int8 empty, module, solid or object.
        neighbour_mode: ``(A, K)`` int32 the neighbour's mode (-1: no module).
        neighbour_scent: ``(A, K, C)`` int32 the neighbour's scents.
        own_mode: ``(A, 1)`` int32.
        own_scent: ``(A, C)`` int32.
        messages: ``(A, 12)`` int32 the inbox.
        contact: ``(A, 2)`` int8 touching the ground, touching the object.
        action_mask: ``(A, 13)`` int8 stay and the 12 rolls.
    """

    neighbour_kind: np.ndarray
    neighbour_mode: np.ndarray
    neighbour_scent: np.ndarray
    own_mode: np.ndarray
    own_scent: np.ndarray
    messages: np.ndarray
    contact: np.ndarray
    action_mask: np.ndarray

    @classmethod
    def of(cls, buffers) -> Observation:
        """The record of the arrays of the same names in ``buffers`` (any object that has them)."""
        return cls(*cls.plain(buffers))

    @staticmethod
    def plain(buffers) -> tuple:
        """The arrays of :meth:`of` as a plain tuple, in field order (how Python hands them over)."""
        b = buffers
        return (
            b.neighbour_kind,
            b.neighbour_mode,
            b.neighbour_scent,
            b.own_mode,
            b.own_scent,
            b.messages,
            b.contact,
            b.action_mask,
        )


OBSERVATION_FIELDS = (*Observation._fields[:-1], "load", "hint", Observation._fields[-1])
"""The fields of a module's observation, in order (:mod:`proteo_env.spaces` has their shapes):
the engine's :class:`Observation` with the task's ``load`` and ``hint`` before the action mask."""


def row(record, b):
    """World ``b``'s row of a batch's ``record`` (every field indexed by ``b``), as a plain tuple."""
    return tuple(x[b] for x in record)


@overload(row)
def _compiled_row(record, b):
    # numba cannot build a tuple in a loop over a heterogeneous tuple: write the indexing out
    source = "def row_of(record, b):\n    return (" + "".join(f"record[{i}][b], " for i in range(len(record))) + ")\n"
    namespace = {}
    exec(source, namespace)
    return namespace["row_of"]

"""Many worlds stepped in one call: the batched engine.

A :class:`WorldBatch` stacks ``B`` :class:`~proteo_env.core.world.World` objects that share
one grid layout (same padded extent, same number of modules and agents, same physics). Their
state arrays become rows of ``(B, ...)`` arrays and each ``World`` keeps working on its own
row, so per-world code (tasks, metrics, the single-world API) is unchanged. :meth:`step` and
:meth:`observe` run the single-world kernels over the rows in parallel (numba ``prange``):
each world keeps its own move-order generator, so world ``b`` of a batch follows exactly the
trajectory it would follow alone with the same seed and actions.
"""

from __future__ import annotations

import numpy as np

from . import cycle
from .jit import kernel, parallel_kernel, prange
from .records import Actions, Observation, Scratch, WorldState, row
from .world import World


@parallel_kernel
def _run_cycles(state, settings, geometry, actions, moved, scratch):
    """:func:`~.cycle.run_cycle` of every world; ``state``, ``actions``, ``moved`` and
    ``scratch`` have a leading ``B`` axis."""
    for b in prange(moved.shape[0]):
        cycle.run_cycle(row(state, b), settings, geometry, row(actions, b), moved[b], row(scratch, b))


@kernel
def _out_of_room(cell, strides, guards, out):
    """:func:`~.cycle.out_of_room` of every world into ``out`` (B,); ``cell`` (B, N), ``guards`` (B, 6)."""
    for b in range(cell.shape[0]):
        out[b] = cycle.out_of_room(cell[b], strides, guards[b])


@parallel_kernel
def _observe_worlds(state, settings, geometry, scratch, out):
    """:func:`~.cycle.observe_world` of every world; ``state``, ``scratch`` and ``out`` have a
    leading ``B`` axis."""
    for b in prange(state[0].shape[0]):
        cycle.observe_world(row(state, b), settings, geometry, row(scratch, b), row(out, b))


class WorldBatch:
    """``B`` worlds with one grid layout, stepped and observed together.

    Args:
        worlds: the worlds, built with a common ``extent`` and equal module and agent counts,
            channels, physics and observation radius. Their arrays are re-homed into the batch.

    Attributes:
        worlds: the ``World`` objects; ``worlds[b]`` works on row ``b``.
        paged: the worlds' grids are paged (:mod:`~.paged`): they are not stacked but stepped
            one after another, and ``state`` and ``scratch`` are None.
        state: the worlds' :class:`~.records.WorldState` arrays, stacked (``(B, ...)`` each).
        scratch: the worlds' :class:`~.records.Scratch` arrays, stacked.
    """

    def __init__(self, worlds: list[World]):
        if not worlds:
            raise ValueError("a WorldBatch needs at least one world")
        first = worlds[0]
        for w in worlds[1:]:
            same = (
                w.shape.padded == first.shape.padded
                and w.n_modules == first.n_modules
                and w.n_agents == first.n_agents
                and w.n_channels == first.n_channels
                and w.physics == first.physics
                and w.obs_radius == first.obs_radius
            )
            if not same:
                raise ValueError(
                    "worlds of a batch must share grid extent, module and agent counts, "
                    "channels, physics and observation radius"
                )
        self.worlds = list(worlds)
        self.n_worlds = len(worlds)
        self.n_agents = first.n_agents
        self.paged = first.shape.paged
        self.state = self.scratch = None
        if not self.paged:
            self.state = WorldState(*(np.stack(arrays) for arrays in zip(*(w.state for w in worlds))))
            self.scratch = Scratch(*(np.stack(arrays) for arrays in zip(*(w.scratch for w in worlds))))
        self._guards = np.stack([w.shape.guard() for w in worlds])
        self._whole = np.array([w.shape.whole for w in worlds])
        self._rehome()

    def _rehome(self, rows=None) -> None:
        """Point every world's arrays (or those of ``rows``) at its row of the stacked arrays."""
        if self.paged:
            return
        for b in range(self.n_worlds) if rows is None else rows:
            w = self.worlds[b]
            w.state = WorldState(*row(self.state, b))
            w.scratch = Scratch(*row(self.scratch, b))

    def replace(self, b: int, world: World) -> None:
        """Put ``world`` (built on this batch's grid layout) in row ``b``, state copied into the row."""
        first = self.worlds[0]
        if (
            world.shape.padded != first.shape.padded
            or world.n_modules != first.n_modules
            or world.n_agents != first.n_agents
        ):
            raise ValueError("a world replacing one of a batch must share its grid extent, module and agent counts")
        if not self.paged:
            for record, into in ((world.state, self.state), (world.scratch, self.scratch)):
                for arrays, rows in zip(record, into):
                    rows[b] = arrays
        self.worlds[b] = world
        self._guards[b] = world.shape.guard()
        self._whole[b] = world.shape.whole
        self._rehome([b])

    def __setstate__(self, state):
        # pickling copies the row views into separate arrays; make them views again
        self.__dict__.update(state)
        self._rehome()

    def out_of_room(self) -> np.ndarray:
        """``(B,)`` bool: the worlds whose modules came near an edge of their grid's window inside
        the box (:meth:`~proteo_env.core.world.World.out_of_room`); all False when every grid
        covers its whole box."""
        out = np.zeros(self.n_worlds, dtype=np.bool_)
        if not self._whole.all():
            cell = self.state.cell if not self.paged else np.stack([w.cell for w in self.worlds])
            _out_of_room(cell, self.worlds[0].shape.strides, self._guards, out)
        return out

    def step(self, *, move, mode, scent_role, message_target, message_value) -> np.ndarray:
        """One cycle of every world; arguments as :meth:`World.step` with a leading ``B`` axis.

        Returns ``(B, A)`` bool, who moved. A batch of one world runs the serial kernels (a
        parallel region costs a thread wake-up, which on a busy machine can cost milliseconds),
        as does a batch of paged worlds (large ones), world by world.
        """
        if self.n_worlds == 1 or self.paged:
            moved = [
                w.step(
                    move=move[b],
                    mode=mode[b],
                    scent_role=scent_role[b],
                    message_target=message_target[b],
                    message_value=message_value[b],
                )
                for b, w in enumerate(self.worlds)
            ]
            return moved[0][None] if self.n_worlds == 1 else np.stack(moved)
        moved = np.zeros((self.n_worlds, self.n_agents), dtype=np.bool_)
        actions = Actions.of(
            move=move, mode=mode, scent_role=scent_role, message_target=message_target, message_value=message_value
        )
        w = self.worlds[0]
        _run_cycles(tuple(self.state), tuple(w.settings), tuple(w.geometry), tuple(actions), moved, tuple(self.scratch))
        return moved

    def observe(self, out) -> None:
        """Fill ``out`` (:class:`~proteo_env.spaces.ObservationBuffers` for ``B * A`` agents, world-major)."""
        if self.n_worlds == 1 or self.paged:
            a = self.n_agents
            for b, w in enumerate(self.worlds):
                w.observe(out.rows(b * a, (b + 1) * a) if self.n_worlds > 1 else out)
            return
        w = self.worlds[0]
        shape = (self.n_worlds, self.n_agents)
        out = tuple(x.reshape(shape + x.shape[1:]) for x in Observation.plain(out))
        _observe_worlds(tuple(self.state), tuple(w.settings), tuple(w.geometry), tuple(self.scratch), out)

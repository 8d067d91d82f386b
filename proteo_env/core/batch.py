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

from . import kernels
from .jit import parallel_kernel, prange
from .lattice import DIRECTIONS, OPPOSITE
from .world import LOCAL_ADJACENCY_BITS, Scratch, World


@parallel_kernel
def _run_cycles(
    grid,
    cell,
    n_agents,
    anchored,
    mode,
    scent,
    inbox,
    rng_state,
    passive_role,
    surface,
    keep_connected,
    exact,
    sweeps,
    scent_max,
    move,
    new_mode,
    role,
    message_target,
    message_value,
    moved,
    dir_delta,
    directions,
    opposite,
    roll_delta,
    local_delta,
    local_adjacent,
    roll_table,
    movers,
    mark,
    queue,
    stacks,
    search,
    scent_buffer,
):
    for b in prange(grid.shape[0]):
        kernels.run_cycle(
            grid[b],
            cell[b],
            n_agents,
            anchored[b],
            mode[b],
            scent[b],
            inbox[b],
            rng_state[b],
            passive_role,
            surface,
            keep_connected,
            exact,
            sweeps,
            scent_max,
            move[b],
            new_mode[b],
            role[b],
            message_target[b],
            message_value[b],
            moved[b],
            dir_delta,
            directions,
            opposite,
            roll_delta,
            local_delta,
            local_adjacent,
            roll_table,
            movers[b],
            mark[b],
            queue[b],
            stacks[b],
            search[b],
            scent_buffer[b],
        )


@parallel_kernel
def _observe_worlds(
    grid,
    cell,
    n_agents,
    mode,
    scent,
    inbox,
    anchored,
    keep_connected,
    nb_delta,
    dir_delta,
    roll_delta,
    roll_table,
    scent_max,
    is_cut,
    adjacency,
    disc,
    low,
    stack_node,
    stack_k,
    neighbour_kind,
    neighbour_mode,
    neighbour_scent,
    own_mode,
    own_scent,
    messages,
    contact,
    action_mask,
):
    for b in prange(grid.shape[0]):
        kernels.observe_world(
            grid[b],
            cell[b],
            n_agents,
            mode[b],
            scent[b],
            inbox[b],
            anchored[b],
            keep_connected,
            nb_delta,
            dir_delta,
            roll_delta,
            roll_table,
            scent_max,
            is_cut[b],
            adjacency[b],
            disc[b],
            low[b],
            stack_node[b],
            stack_k[b],
            neighbour_kind[b],
            neighbour_mode[b],
            neighbour_scent[b],
            own_mode[b],
            own_scent[b],
            messages[b],
            contact[b],
            action_mask[b],
        )


class WorldBatch:
    """``B`` worlds with one grid layout, stepped and observed together.

    Args:
        worlds: the worlds, built with a common ``extent`` and equal module and agent counts,
            channels, physics and observation radius. Their arrays are re-homed into the batch.

    Attributes:
        worlds: the ``World`` objects; ``worlds[b]`` works on row ``b``.
        grid, cell, anchored, mode, scent, inbox, rng_state: ``(B, ...)`` stacked state.
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
        for name in World.STATE:
            setattr(self, name, np.stack([getattr(w, name) for w in worlds]))
        self.scratch = Scratch(0, 0)
        for name in Scratch.NAMES:
            setattr(self.scratch, name, np.stack([getattr(w.scratch, name) for w in worlds]))
        self._rehome()

    def _rehome(self, rows=None) -> None:
        """Point every world's arrays (or those of ``rows``) at its row of the stacked arrays."""
        for b in range(self.n_worlds) if rows is None else rows:
            w = self.worlds[b]
            for name in World.STATE:
                setattr(w, name, getattr(self, name)[b])
            for name in Scratch.NAMES:
                setattr(w.scratch, name, getattr(self.scratch, name)[b])

    def replace(self, b: int, world: World) -> None:
        """Put ``world`` (built on this batch's grid layout) in row ``b``, state copied into the row."""
        first = self.worlds[0]
        if (
            world.shape.padded != first.shape.padded
            or world.n_modules != first.n_modules
            or world.n_agents != first.n_agents
        ):
            raise ValueError("a world replacing one of a batch must share its grid extent, module and agent counts")
        for name in World.STATE:
            getattr(self, name)[b] = getattr(world, name)
        for name in Scratch.NAMES:
            getattr(self.scratch, name)[b] = getattr(world.scratch, name)
        self.worlds[b] = world
        self._rehome([b])

    def __setstate__(self, state):
        # pickling copies the row views into separate arrays; make them views again
        self.__dict__.update(state)
        self._rehome()

    def step(self, *, move, mode, scent_role, message_target, message_value) -> np.ndarray:
        """One cycle of every world; arguments as :meth:`World.step` with a leading ``B`` axis.

        Returns ``(B, A)`` bool, who moved. A batch of one world runs the serial kernels (a
        parallel region costs a thread wake-up, which on a busy machine can cost milliseconds).
        """
        if self.n_worlds == 1:
            return self.worlds[0].step(
                move=move[0],
                mode=mode[0],
                scent_role=scent_role[0],
                message_target=message_target[0],
                message_value=message_value[0],
            )[None]
        w, s = self.worlds[0], self.scratch
        p = w.physics
        moved = np.zeros((self.n_worlds, self.n_agents), dtype=np.bool_)
        _run_cycles(
            self.grid,
            self.cell,
            self.n_agents,
            self.anchored,
            self.mode,
            self.scent,
            self.inbox,
            self.rng_state,
            w.passive_role,
            w.surface_channels,
            p.keep_connected,
            p.exact_scent,
            p.scent_sweeps,
            p.scent_max,
            np.asarray(move, dtype=np.int64),
            np.asarray(mode, dtype=np.int32),
            np.asarray(scent_role, dtype=np.int8),
            np.asarray(message_target, dtype=np.int64),
            np.asarray(message_value, dtype=np.int32),
            moved,
            w.dir_delta,
            DIRECTIONS,
            OPPOSITE,
            w.roll_delta,
            w.local_delta,
            LOCAL_ADJACENCY_BITS,
            w.roll_table,
            s.movers,
            s.mark,
            s.queue,
            s.stacks,
            s.search,
            s.scent_buffer,
        )
        return moved

    def observe(self, out) -> None:
        """Fill ``out`` (:class:`~proteo_env.spaces.ObservationBuffers` for ``B * A`` agents, world-major)."""
        if self.n_worlds == 1:
            self.worlds[0].observe(out)
            return
        w, s = self.worlds[0], self.scratch
        b, a = self.n_worlds, self.n_agents

        def rows(x):
            return x.reshape((b, a) + x.shape[1:])

        _observe_worlds(
            self.grid,
            self.cell,
            a,
            self.mode,
            self.scent,
            self.inbox,
            self.anchored,
            w.physics.keep_connected,
            w.neighbourhood_delta,
            w.dir_delta,
            w.roll_delta,
            w.roll_table,
            w.physics.scent_max,
            s.is_cut,
            s.adjacency,
            s.disc,
            s.low,
            s.stack_node,
            s.stack_k,
            rows(out.neighbour_kind),
            rows(out.neighbour_mode),
            rows(out.neighbour_scent),
            rows(out.own_mode),
            rows(out.own_scent),
            rows(out.messages),
            rows(out.contact),
            rows(out.action_mask),
        )

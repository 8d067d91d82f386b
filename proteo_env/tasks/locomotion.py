"""Locomotion: move the robot's centroid in a goal direction, over a step or through a tunnel.

A random blob of modules on a floor must get every module beyond a finish line ahead of it along ``+x``: the face
of a step, or the exit of a tunnel or of a slot in a wall, rolling its modules over each other like a tread.
Registered: ``locomotion-v0``. Paper sections 1 and 4.1 (chains "for moving over steps, snaking into holes"), 2.2
(directed random moves).

The contract (layout, agents, observation, actions, reward, metrics, termination, parameters): docs/tasks/locomotion.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from ..core.cycle import EMIT, RELAY
from ..core.jit import kernel
from ..core.lattice import PAD
from ..core.world import check_module_memory
from ..layouts import Layout, blob_sites
from .base import Task, TaskKernels, no_sensor

GOAL = np.array([1.0, 0.0, 0.0], dtype=np.float32)
"""The goal direction, ``+x``."""


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


@dataclass(frozen=True)
class LocomotionParams:
    """Parameters of the locomotion task (lengths in sites along the box's axes).

    Attributes:
        n_modules: modules in the robot.
        step_height: height of the step (solid layers ``z = 0 .. step_height - 1``); 0: flat.
        distance: empty sites between the robot's foremost module and the step's face.
        tunnel_height: free layers under the tunnel's roof (above the ground or the step); 0:
            no tunnel.
        tunnel_length: the roof's (or the slot's) extent along ``+x`` from the step's face.
        closed_above: the tunnel's roof rises as a wall to the top of the box, so the tunnel is
            a hole in a wall and the only way on (False: a slab that a robot may also climb).
        slot_width: free sites across the goal direction in a wall over ``tunnel_length``
            sites, at the middle of the box's width (the wall spans every height); 0: no slot.
        margin: free sites on each side of the robot across the goal direction and above the
            highest of the robot, the step and the roof.
        room: free sites beyond the finish line (None: ``n_modules // 2 + margin``).
        time_penalty: reward lost per cycle.
    """

    n_modules: int = 20
    step_height: int = 2
    distance: int = 3
    tunnel_height: int = 0
    tunnel_length: int = 6
    closed_above: bool = False
    slot_width: int = 0
    margin: int = 3
    room: int | None = None
    time_penalty: float = 0.001

    def __post_init__(self):
        def bad(name, allowed):
            raise ValueError(f"{name}={getattr(self, name)!r} is not allowed; allowed: {allowed}")

        if not isinstance(self.n_modules, int) or self.n_modules < 2:
            bad("n_modules", "an integer >= 2")
        check_module_memory(self.n_modules)
        for name, low in (
            ("step_height", 0),
            ("distance", 1),
            ("tunnel_height", 0),
            ("tunnel_length", 1),
            ("slot_width", 0),
            ("margin", 1),
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                bad(name, f"an integer >= {low}")
        if self.tunnel_height == 1:
            bad("tunnel_height", "0 (no tunnel) or an integer >= 2 (one free layer leaves no module a pivot)")
        if not isinstance(self.closed_above, bool):
            bad("closed_above", "True or False")
        if self.room is not None and (isinstance(self.room, bool) or not isinstance(self.room, int) or self.room < 1):
            bad("room", "None or an integer >= 1")
        if self.time_penalty < 0:
            bad("time_penalty", "a number >= 0")


class Locomotion(Task):
    name = "locomotion"
    version = 0
    modes = tuple(LocomotionMode.__members__)
    Params = LocomotionParams
    default_policy = "locomotion"
    mode_roles = ((RELAY,), (EMIT,))
    """``move+mode``: a SEED emits the scent, a SEARCH module relays it."""

    def build_layout(self, rng):
        p = self.params
        blob = blob_sites(p.n_modules, rng, flat=True)
        blob = blob - blob.min(axis=0) + np.array([p.margin, p.margin, 0])
        if blob.sum(axis=1)[0] % 2:
            blob[:, 0] += 1
        face = int(blob[:, 0].max()) + 1 + p.distance
        finish = face + (p.tunnel_length if p.tunnel_height or p.slot_width else 0)
        room = p.n_modules // 2 + p.margin if p.room is None else p.room
        roof = p.step_height + p.tunnel_height
        top = max(int(blob[:, 2].max()), p.step_height, roof if p.tunnel_height else 0)
        size = (finish + room, max(int(blob[:, 1].max()) + 1, p.slot_width + 2) + p.margin, top + 1 + p.margin)
        grid = np.mgrid[face : size[0], 0 : size[1], 0 : size[2]].reshape(3, -1).T
        grid = grid[grid.sum(axis=1) % 2 == 0]
        over = grid[:, 0] < face + p.tunnel_length
        opening = (size[1] - p.slot_width) // 2
        solid = grid[
            (grid[:, 2] < p.step_height)
            | (bool(p.tunnel_height) & ((grid[:, 2] == roof) | (p.closed_above & (grid[:, 2] > roof))) & over)
            | (bool(p.slot_width) & over & ((grid[:, 1] < opening) | (grid[:, 1] >= opening + p.slot_width)))
        ]
        self._finish = finish
        return Layout(size=size, modules=blob, solid=solid, floor=True)

    def reset(self, world, rng):
        self._start = self._centroid(world)
        self._course = max(self._finish - self._start, 1.0)
        self._last = self._previous = self._start
        self._success = False
        self._cycles = 0

    @staticmethod
    def _centroid(world) -> float:
        return float(world.positions[:, 0].mean())

    @property
    def finish(self) -> int:
        """The finish line: the ``x`` every module must reach (after :meth:`build_layout`)."""
        return self._finish

    def finish_cell(self, world) -> int:
        """The first grid cell of ``world`` at the finish line: a module is beyond the line exactly
        when its cell index is at least this (cells are ordered by ``x`` first)."""
        return int((self._finish + PAD) * world.shape.strides[0])

    def after_cycle(self, world, cycle):
        self._cycles = cycle
        self._previous, self._last = self._last, self._centroid(world)
        self._success = bool(all_beyond(world.cell[: world.n_modules], self.finish_cell(world)))

    def hint(self, world):
        return np.broadcast_to(GOAL, (world.n_agents, 3))

    def reward_terms(self, world, moved):
        return {
            "progress": (self._last - self._previous) / self._course,
            "success": 1.0 if self._success else 0.0,
            "time": -self.params.time_penalty,
        }

    def metrics(self, world):
        x = world.positions[:, 0]
        distance = self._last - self._start
        return {
            "distance": distance,
            "speed": distance / max(self._cycles, 1),
            "beyond": float((x >= self._finish).mean()),
            "components": float(world.n_components()),
            "success": float(self._success),
        }

    def success(self, world):
        return self._success

    def kernels(self, world):
        return TaskKernels(no_sensor, locomotion_update_and_test, self.finish_cell(world))

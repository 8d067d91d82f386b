"""Chain: turn an arbitrary connected blob into one one-module-thick chain.

All modules start in SLEEP as a random blob, except one SEED picked by the task; searching modules climb its
scent and extend the chain at the seed until every module is in it. Registered: ``chain-v0`` (success bonus 1 for
any complete chain) and ``chain-v1``, the newest (:class:`ChainV1`: the bonus is the chain's straightness, and the
metric ``straightness``). Paper section 4.1 (A Chain).

The contract (layout, agents, observation, actions, reward, metrics, termination, parameters): docs/tasks/chain.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from ..core.cycle import EMIT, RELAY
from ..core.jit import kernel
from ..core.structure import StructureProbe, graph_shapes, largest_thin_piece
from ..core.world import check_module_memory
from ..layouts import Layout, blob_sites, place_in_box
from .base import CycleScores, Task, TaskKernels, no_sensor


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


@dataclass(frozen=True)
class ChainParams:
    """Parameters of the chain task.

    Attributes:
        n_modules: number of modules in the start blob.
        initial_seed_module: start with one SEED module (paper: "determined centrally"); if False every
            module starts in SLEEP and the policy must elect seeds itself.
        margin: free sites around the blob: above and below it, and horizontally on top of
            the room a straight chain needs (``n_modules + margin`` on every horizontal side,
            so a straight horizontal chain fits whichever way it grows). The box's walls
            block rolls that would sweep through them; with the hand-coded policy a margin of
            6 gave the same success as 3 (50 of 50 blobs of 50 modules and 20 of 20 of 200
            under ``sphere``, ``rounded`` and ``minimal``).
        time_penalty: reward lost per cycle.
        room: free sites on every horizontal side of the blob instead of ``n_modules +
            margin`` (None: that default). The default box grows with the square of
            ``n_modules`` (about 1.6e10 grid cells for 10,000 modules); a smaller room keeps
            large worlds in memory, and walls ``room`` sites away cannot touch a module in its
            first ``room - 3`` cycles (a module moves at most one site per axis and cycle, and
            a roll reads sites at most two away), so those cycles are the same as in the
            default box. A size whose smallest box would not fit in the memory available is
            refused when the env is made (``n_modules=10**7``: about 8e7 GiB), and any world
            whose grid would not fit when it is built, each time naming the memory needed.
    """

    n_modules: int = 50
    initial_seed_module: bool = True
    margin: int = 3
    time_penalty: float = 0.001
    room: int | None = None

    def __post_init__(self):
        if self.n_modules < 2:
            raise ValueError(f"n_modules={self.n_modules!r} is not allowed; allowed: an integer >= 2")
        if self.margin < 1:
            raise ValueError(f"margin={self.margin!r} is not allowed; allowed: an integer >= 1")
        if self.room is not None and self.room < 1:
            raise ValueError(f"room={self.room!r} is not allowed; allowed: None or an integer >= 1")
        check_module_memory(self.n_modules)

    @property
    def side_room(self) -> int:
        """Free sites on each horizontal side of the blob: ``room``, or ``n_modules + margin``."""
        return self.n_modules + self.margin if self.room is None else self.room


class Chain(Task):
    name = "chain"
    demo_settings = {"n_modules": 40, "max_cycles": 3000}
    version = 0
    modes = tuple(ChainMode.__members__)
    Params = ChainParams
    n_message_values = 15
    default_policy = "chain"
    mode_roles = ((RELAY,), (RELAY,), (EMIT,), (RELAY,))
    """``move+mode``: the SEED emits the scent, every other mode relays it."""
    window_room = 8
    """The grid covers the modules and 8 sites around them, and grows with them (see :class:`Task`)."""

    def build_layout(self, rng):
        p = self.params
        room = p.side_room  # by default any straight chain fits
        sites, size = place_in_box(blob_sites(p.n_modules, rng), margin=(room, room, p.margin))
        return Layout(size=size, modules=sites)

    def initial_modes(self, layout):
        modes = np.full(len(layout.positions), SLEEP, dtype=np.int32)
        if self.params.initial_seed_module:
            centre = layout.modules.mean(axis=0)
            modes[int(np.argmax(((layout.modules - centre) ** 2).sum(axis=1)))] = SEED
        return modes

    def reset(self, world, rng):
        self._probe = StructureProbe(world.n_modules)
        self._last = self._measure(world)
        self._previous = self._last

    def _measure(self, world):
        return shape_measures(*self._probe.measure(world), world.n_modules)

    def after_cycle(self, world, cycle):
        self._previous, self._last = self._last, self._measure(world)

    def reward_terms(self, world, moved):
        n = world.n_modules
        return {
            "thin": (self._last["thin"] - self._previous["thin"]) / n,
            "success": self.success_bonus(world),
            "time": -self.params.time_penalty,
        }

    def success_bonus(self, world) -> float:
        """The ``success`` term: 1 once the chain is complete."""
        return 1.0 if self._last["complete"] else 0.0

    @classmethod
    def score_cycle(cls, tasks, worlds, moved, cycles):
        """Every world's graph measured in one kernel call (:func:`~proteo_env.core.structure.graph_shapes`);
        the same bookkeeping, terms, rewards and success as the per-world hooks, bit for bit
        (paged worlds, which a batch does not stack: the per-world hooks)."""
        if worlds.paged:
            return super().score_cycle(tasks, worlds, moved, cycles)
        first = worlds.worlds[0]
        n, state = first.n_modules, worlds.state
        scratch = np.empty((3, len(tasks), n), dtype=np.int64)
        shapes = np.empty((len(tasks), 4), dtype=np.int64)
        graph_shapes(state.grid, state.cell, n, first.dir_delta, scratch[0], scratch[1], scratch[2], shapes)
        terms, success = [], np.empty(len(tasks), dtype=bool)
        for b, (task, world, shape) in enumerate(zip(tasks, worlds.worlds, shapes.tolist())):
            task._probe.degree[:] = scratch[0, b]
            task._previous, task._last = task._last, shape_measures(*shape, n)
            success[b] = task._last["complete"]
            terms.append(task.reward_terms(world, moved[b]))
        reward = np.array([sum(t.values()) for t in terms], dtype=np.float64)
        return CycleScores(reward, success, terms)

    def metrics(self, world):
        m = self._last
        return {
            "chain_length": float(m["chain_length"]),
            "thin_share": m["thin"] / world.n_modules,
            "max_degree": float(m["max_degree"]),
            "components": float(world.n_components()),
            "success": float(m["complete"]),
        }

    def success(self, world):
        return self._last["complete"]

    def kernels(self, world):
        return TaskKernels(no_sensor, chain_update_and_test, np.zeros((3, world.n_modules), dtype=np.int64))


def shape_measures(edges: int, thin_piece: int, thin: int, max_degree: int, n_modules: int) -> dict:
    """The chain's measures of a world from its graph's shape (:class:`~proteo_env.core.structure.GraphShape`)."""
    return {
        "thin": thin,
        "max_degree": max_degree,
        "chain_length": thin_piece,
        # is_chain's test: N - 1 contacts, no module with 3 neighbours, one thin piece of all N
        "complete": max_degree <= 2 and edges == n_modules - 1 and thin_piece == n_modules,
    }


def fcc_hops(a: np.ndarray, b: np.ndarray) -> int:
    """The fewest face-neighbour steps between sites ``a`` and ``b`` (3,) of the FCC lattice."""
    d = np.abs(np.asarray(a, dtype=np.int64) - np.asarray(b, dtype=np.int64))
    return int(max(d.max(), d.sum() // 2))


class ChainV1(Chain):
    """``chain-v1``: the chain's success bonus is paid for a *straight* chain.

    ``chain-v0`` paid the ``success`` bonus of 1 for any one-module-thick chain, and a learner
    that folds the blob into a winding path finishes sooner and earns more than the paper's
    straight chain (docs/tasks/chain.md, "Reward against degenerate strategies"). Here the
    bonus is the chain's *straightness*: the lattice distance (fewest face steps) between its
    two ends divided by ``N - 1``, 1 for a straight chain along one lattice direction, less
    for a winding one. Dynamics, observation, actions, success test and the other terms are
    those of ``chain-v0``; the metric ``straightness`` is added (0 until the chain is complete).
    """

    version = 1

    def straightness(self, world) -> float:
        """End-to-end lattice distance over ``N - 1`` of the complete chain; 0 before it is complete."""
        if not self._last["complete"]:
            return 0.0
        ends = np.flatnonzero(self._probe.degree[: world.n_modules] == 1)
        return fcc_hops(world.positions[ends[0]], world.positions[ends[-1]]) / (world.n_modules - 1)

    def success_bonus(self, world) -> float:
        """The ``success`` term: the chain's straightness once it is complete."""
        return self.straightness(world) if self._last["complete"] else 0.0

    def metrics(self, world):
        return {**super().metrics(world), "straightness": self.straightness(world)}

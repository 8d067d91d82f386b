"""The task interface: what a task defines and when the environment calls it."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from ..core.jit import kernel
from ..core.world import World
from ..layouts import Layout


@kernel
def no_sensor(state, load):
    """The ``sense`` of a task whose agents carry no load: leaves ``load`` (A, 1) as it is."""


class TaskKernels(NamedTuple):
    """A task as a compiled rollout runs it (:mod:`baselines.compiled`), cycle after cycle.

    Attributes:
        sense: numba kernel ``sense(state, load)``, called after the engine's observation:
            writes the task's sensor reading into ``load`` (A, 1) float32 (the ``load`` field);
            :func:`no_sensor` for a task without one.
        settle: numba kernel ``settle(grid, cell, mode, anchored, dir_delta, cycle, state) -> bool``,
            called after each cycle (``cycle`` counted like ``env.cycle``): the task's
            bookkeeping, then its success test (what :meth:`Task.success` would say).
        state: what the two read and update (numbers, arrays, tuples or NamedTuples of them);
            a copy, so the environment's own bookkeeping never changes.
    """

    sense: Callable
    settle: Callable
    state: object


class Task:
    """Base class of every task (one file per task in this package).

    Required class attributes:
        name: short name, e.g. ``"chain"``; the registry id is ``f"{name}-v{version}"``.
        version: integer, bumped when dynamics, reward or layout change.
        modes: mode names; mode ``i`` is ``modes[i]``.
        Params: a frozen dataclass of the task's parameters (all with defaults).

    Optional class attributes: ``n_channels`` (scent channels, default 1),
    ``surface_channels`` (which channels relay only over the surface), ``passive_role``
    (scent role of passive board modules per channel, default relay), ``n_message_values``
    (default 15), ``default_policy`` (name of the baseline ``proteo demo`` runs),
    ``plot_groups`` (plot title -> metric names drawn together in one plot; metrics in no group
    are plotted alone; default none), ``mode_roles`` (the scent role of a module on each channel
    in each mode at the ``move+mode`` control level, ``mode_roles[mode][channel]``; default
    relay everywhere; see :mod:`proteo_env.control`).

    Required hook:
        ``build_layout(rng) -> Layout``: the start layout for an episode.

    Optional hooks (defaults do nothing / give zeros):
        ``initial_modes(layout) -> (N,) int``: start modes of all modules (world order).
        ``reset(world, rng)``: per-episode task state.
        ``after_cycle(world, cycle)``: task-side changes after each cycle (weight schedule).
        ``regrid(world)``: the running ``world`` moved onto a larger grid (a batch restarting
        some of its worlds, :meth:`~proteo_env.batched.BatchedEnv.reset_worlds`); recompute
        what the task keeps as grid cell indices.
        ``load(world) -> (A,) float32``: weight each agent carries (observation ``load``).
        ``hint(world) -> (A, 3) float32``: the global hint of each agent (observation ``hint``).
        ``reward_terms(world, moved) -> dict[str, float]``: named team reward terms; the reward
        of every agent is their sum.
        ``metrics(world) -> dict[str, float]``: named metrics reported in ``infos``.
        ``success(world) -> bool``: sets ``terminated`` for every agent.
        ``kernels(world) -> TaskKernels | None``: the task's bookkeeping and success test as
        numba kernels, for compiled rollouts (default ``None``: the task has no compiled form).
    """

    name: str = ""
    version: int = 0
    modes: tuple[str, ...] = ()
    Params: type = None
    n_channels: int = 1
    surface_channels: tuple[bool, ...] = (False,)
    passive_role: tuple[int, ...] = (1,)
    n_message_values: int = 15
    default_policy: str = "random"
    plot_groups: dict[str, list[str]] = {}
    max_cycles: int = 1000
    """The environment's cycle limit, set by the environment on its task instances."""
    mode_roles: tuple[tuple[int, ...], ...] | None = None

    def __init__(self, params=None):
        self.params = params if params is not None else self.Params()

    @classmethod
    def task_id(cls) -> str:
        return f"{cls.name}-v{cls.version}"

    @classmethod
    def param_names(cls) -> list[str]:
        return [f.name for f in dataclasses.fields(cls.Params)]

    def mode_index(self, name: str) -> int:
        return self.modes.index(name)

    def mode_role_table(self) -> np.ndarray:
        """``(n_modes, n_channels)`` int64: :attr:`mode_roles` as an array (relay, 1, where unset)."""
        if self.mode_roles is None:
            return np.ones((len(self.modes), self.n_channels), dtype=np.int64)
        table = np.array(self.mode_roles, dtype=np.int64)
        if table.shape != (len(self.modes), self.n_channels):
            raise ValueError(
                f"{self.task_id()}: mode_roles has shape {table.shape}; allowed: "
                f"({len(self.modes)}, {self.n_channels}), one role per mode and channel"
            )
        return table

    # ------------------------------------------------------------------ hooks
    def build_layout(self, rng: np.random.Generator) -> Layout:
        raise NotImplementedError

    def initial_modes(self, layout: Layout) -> np.ndarray:
        return np.zeros(len(layout.positions), dtype=np.int32)

    def reset(self, world: World, rng: np.random.Generator) -> None:
        pass

    def after_cycle(self, world: World, cycle: int) -> None:
        pass

    def regrid(self, world: World) -> None:
        pass

    def load(self, world: World) -> np.ndarray:
        return np.zeros(world.n_agents, dtype=np.float32)

    def hint(self, world: World) -> np.ndarray:
        return np.zeros((world.n_agents, 3), dtype=np.float32)

    def reward_terms(self, world: World, moved: np.ndarray) -> dict[str, float]:
        return {}

    def metrics(self, world: World) -> dict[str, float]:
        return {}

    def success(self, world: World) -> bool:
        return False

    def kernels(self, world: World) -> TaskKernels | None:
        return None

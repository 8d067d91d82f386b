"""The task interface: what a task defines and when the environment calls it."""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from ..core.batch import WorldBatch
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
        update_and_test: numba kernel ``update_and_test(grid, cell, mode, anchored, dir_delta,
            cycle, state) -> bool``, called after each cycle (``cycle`` counted like
            ``env.cycle``): the task's bookkeeping, then its success test (what
            :meth:`Task.success` would say).
        state: what the two read and update (numbers, arrays, tuples or NamedTuples of them);
            a copy, so the environment's own bookkeeping never changes.
    """

    sense: Callable
    update_and_test: Callable
    state: object


class CycleScores(NamedTuple):
    """What a batch's worlds scored in the cycle just run (:meth:`Task.score_cycle`)."""

    reward: np.ndarray
    """``(B,)`` float64: each world's reward, the sum of its terms."""
    success: np.ndarray
    """``(B,)`` bool: each world's success test."""
    terms: list[dict[str, float]]
    """Each world's named reward terms."""


class Task(abc.ABC):
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
    ``demo_settings`` (the settings ``proteo demo`` runs the task with, default none),
    ``plot_groups`` (plot title -> metric names drawn together in one plot; metrics in no group
    are plotted alone; default none), ``mode_roles`` (the scent role of a module on each channel
    in each mode at the ``move+mode`` control level, ``mode_roles[mode][channel]``; default
    relay everywhere; see :mod:`proteo_env.control`), ``window_room`` (``None``, the default:
    each world's grid covers its whole box; a number: the grid covers a window of the box
    around the modules, with that many free sites around them at reset, and grows when a
    module nears its edge, so that memory follows the modules rather than the box, with the
    same trajectories; a task that keeps grid cell indices recomputes them in :meth:`regrid`,
    and its kernels read no further than 2 sites from a module).

    Required hook: :meth:`build_layout`. Optional hooks (each documented below with an
    example; the defaults do nothing or give zeros): :meth:`initial_modes`, :meth:`reset`,
    :meth:`after_cycle`, :meth:`regrid`, :meth:`load`, :meth:`hint`, :meth:`reward_terms`,
    :meth:`metrics`, :meth:`success`, :meth:`kernels`. The environment calls them in this
    order: at ``reset``, ``build_layout``, ``initial_modes``, then ``reset`` on the new world;
    after each cycle, ``after_cycle``, then ``reward_terms`` and ``success`` (through
    :meth:`score_cycle`, which a task may override to score every world of a batch at once),
    and ``metrics`` when they are asked for; ``load`` and ``hint`` whenever observations are built.

    Example (a complete task: a ball of modules on the ground, achieved when every module
    touches the ground; ``tests/test_plugin.py`` runs it)::

        from dataclasses import dataclass

        from proteo_env.layouts import Layout, ball_sites, place_in_box
        from proteo_env.tasks.base import Task

        @dataclass(frozen=True)
        class FlattenParams:
            n_modules: int = 13

        class Flatten(Task):
            name, version, modes, Params = "flatten", 0, ("IDLE",), FlattenParams

            def build_layout(self, rng):
                sites, size = place_in_box(ball_sites(self.params.n_modules), margin=4, floor=True)
                return Layout(size=size, modules=sites, floor=True)

            def success(self, world):
                return bool((world.positions[:, 2] == 0).all())

    ``docs/guides/adding_a_behaviour.md`` walks through a whole behaviour.
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
    demo_settings: dict = {}
    plot_groups: dict[str, list[str]] = {}
    max_cycles: int = 1000
    """The environment's cycle limit, set by the environment on its task instances."""
    mode_roles: tuple[tuple[int, ...], ...] | None = None
    window_room: int | None = None

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
    @abc.abstractmethod
    def build_layout(self, rng: np.random.Generator) -> Layout:
        """The start layout of an episode, drawn with ``rng`` (the episode's generator).

        Example: ``return place_in_box(blob_sites(self.params.n_modules, rng), margin=4)``.
        """

    def initial_modes(self, layout: Layout) -> np.ndarray:
        """``(N,)`` int start modes of all modules, in the layout's order (default: mode 0).

        Example (the paper's seed module): ``modes = np.full(n, SLEEP); modes[0] = SEED``.
        """
        return np.zeros(len(layout.positions), dtype=np.int32)

    def reset(self, world: World, rng: np.random.Generator) -> None:
        """Per-episode task state, once ``world`` is built (e.g. a weight schedule drawn from ``rng``)."""

    def after_cycle(self, world: World, cycle: int) -> None:
        """Task-side changes after cycle ``cycle`` (e.g. the table's weight shifting)."""

    def regrid(self, world: World) -> None:
        """The running ``world`` was moved onto another grid (a batch restarting some of its
        worlds, :meth:`~proteo_env.batched.BatchedEnv.reset_worlds`, or a window that grew with
        the modules, see ``window_room``): recompute what the task keeps as grid cell indices
        (e.g. ``self.finish = world.shape.index(sites)``)."""

    def load(self, world: World) -> np.ndarray:
        """``(A,)`` float32 weight each agent carries (the ``load`` observation; default zeros)."""
        return np.zeros(world.n_agents, dtype=np.float32)

    def hint(self, world: World) -> np.ndarray:
        """``(A, 3)`` float32 each agent's global hint (the ``hint`` observation; default zeros)."""
        return np.zeros((world.n_agents, 3), dtype=np.float32)

    def reward_terms(self, world: World, moved: np.ndarray) -> dict[str, float]:
        """Named team reward terms of the cycle just run (``moved`` (A,) bool: who moved); every
        agent's reward is their sum.

        Example: ``return {"progress": float(world.positions[:, 0].mean()) - self.last_x}``.
        """
        return {}

    def metrics(self, world: World) -> dict[str, float]:
        """Named numbers reported in ``infos`` as ``metric/<name>`` (e.g. ``{"components": 1.0}``)."""
        return {}

    def success(self, world: World) -> bool:
        """The task is achieved: sets ``terminated`` for every agent (default: never)."""
        return False

    @classmethod
    def score_cycle(cls, tasks: list[Task], worlds: WorldBatch, moved: np.ndarray, cycles: np.ndarray) -> CycleScores:
        """Every world of a batch after its cycle: ``tasks[b]`` runs ``worlds.worlds[b]``, whose
        cycle ``cycles[b]`` (``(B,)``, counted like ``env.cycle``) just ran; ``moved`` ``(B, A)``
        bool: who moved. The default calls, world by world, :meth:`after_cycle`,
        :meth:`reward_terms` (the reward is their sum, in order) and :meth:`success`.

        A task whose per-world Python costs more than its worlds' cycle (small worlds, many of
        them: the trainers' case) overrides it to score every world in one compiled call
        (:class:`~proteo_env.tasks.chain.Chain`). An override must leave every task as the
        per-world hooks would and give the same scores, bit for bit (``tests/test_batched.py``
        checks the chain's against this default).
        """
        reward, success, terms = np.empty(len(tasks)), np.empty(len(tasks), dtype=bool), []
        for b, (task, world, cycle) in enumerate(zip(tasks, worlds.worlds, cycles.tolist())):
            task.after_cycle(world, cycle)
            terms.append(task.reward_terms(world, moved[b]))
            reward[b] = sum(terms[b].values())
            success[b] = task.success(world)
        return CycleScores(reward, success, terms)

    def kernels(self, world: World) -> TaskKernels | None:
        """The task's bookkeeping and success test as numba kernels (:class:`TaskKernels`), for
        compiled rollouts; ``None`` (the default): the task has no compiled form.

        Example: ``return TaskKernels(no_sensor, chain_update_and_test, np.zeros((3, n), np.int64))``.
        """
        return None

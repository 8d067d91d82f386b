"""Control levels: how much of a module's action the agent chooses, and what sets the rest.

The benchmark's ladder of difficulty, chosen with ``proteo_env.make(task_id, control=...)``:

============= =================== ===========================================================
level         the agent chooses   the other fields
============= =================== ===========================================================
``move``      ``move``            the task's hand-coded rules (its *autopilot*): mode, scent
                                  roles and messages as the paper's finite-state machine sets
                                  them from the same observation; the agent's move replaces
                                  the rules' move (their gradient climb and random moves)
``move+mode`` ``move``, ``mode``  scent roles follow from the chosen mode by the task's table
                                  :attr:`~proteo_env.tasks.base.Task.mode_roles`; no messages
``full``      every field         nothing (the default; the interface of
                                  :mod:`proteo_env.spaces`)
============= =================== ===========================================================

The controlled fields are always the first fields of the task's full action
(:class:`~proteo_env.spaces.ActionLayout`: ``[move, mode, roles.., target, value]``), so an
action at a level is the prefix of a full action.

Where the autopilot comes from. ``proteo_env`` holds the engine and the tasks, and the
paper's rules live one layer up, in ``baselines``; ``proteo_env`` must not import it. The
rules therefore reach the environment through a *registration made by the layer above*: an
entry point of the ``proteo_env.autopilots`` group is a function that returns a dict of
autopilot factories by task name (``baselines`` declares one in ``pyproject.toml``,
:func:`baselines.autopilot.autopilots`, which serves every task whose rules are in
``baselines.POLICIES``, so an installed project finds them without importing anything by
name, and a new behaviour's rules need no new registration), or a factory registered at run
time with :func:`register_autopilot` (for a behaviour of your own, or a source tree that is
not installed). We chose entry points over copying each task's finite-state machine into its
task file: the rules exist once, in ``baselines``, where the hand-coded policies, the
compiled rollouts and the evolved parameters already share them.

An autopilot factory is called as ``factory(env, seed)`` with an environment-like object
(``action_layout``: the full layout, ``task``, ``config``) and returns an object with
``reset(seed)`` and ``act_arrays(buffers) -> (A, L)`` full actions (a
:class:`baselines.base.KernelPolicy` is one). Each world has its own autopilot, seeded from
the world's generator, so world ``b`` of a batch follows the trajectory of a single
environment reset with the world's own seed (:func:`~proteo_env.config.world_seeds`). When
the autopilot's class also has ``batch(autopilots)``, a batched env that has run :data:`~proteo_env.batched.ONE_CALL_AFTER`
world-cycles calls it once with the ``B`` worlds' autopilots and from then on takes every
world's actions from one ``act_arrays(buffers) -> (B * A, L)`` over all the worlds' rows
(world-major), which must give what the per-world calls give (a
:class:`baselines.base.KernelPolicy` gives a :class:`baselines.base.PolicyBatch`: one kernel
call per cycle instead of one per world). The autopilot keeps its private memory as the rules
do; that memory records the moves the *rules* proposed, not the agent's (the rules' only
move-dependent memory is their heading and whether they asked to move).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from importlib import metadata

import numpy as np

from .config import CONTROL_LEVELS as LEVELS
from .config import ConfigError
from .spaces import ActionLayout

AUTOPILOT_GROUP = "proteo_env.autopilots"
"""Entry-point group in which the layer above registers one autopilot factory per task name."""

_autopilots: dict[str, Callable] = {}


@dataclass(frozen=True)
class ControlLevel:
    """The fields an agent chooses at one level of a task.

    Attributes:
        name: one of :data:`LEVELS`.
        layout: the task's full :class:`~proteo_env.spaces.ActionLayout`.
    """

    name: str
    layout: ActionLayout

    def __post_init__(self):
        check_level(self.name)

    @cached_property
    def n_fields(self) -> int:
        """How many leading fields of the full action the agent chooses (1, 2 or ``4 + C``)."""
        return {"move": 1, "move+mode": 2}.get(self.name, self.layout.length)

    @cached_property
    def fields(self) -> tuple[str, ...]:
        return tuple(self.layout.field_names[: self.n_fields])

    @cached_property
    def nvec(self) -> np.ndarray:
        """``(n_fields,)`` number of values of each chosen field (read-only)."""
        return self.layout.nvec[: self.n_fields]


def check_level(name) -> str:
    """``name`` if it is a level; else a :class:`~proteo_env.config.ConfigError` listing them."""
    if name not in LEVELS:
        raise ConfigError(f"control={name!r} is not allowed; allowed: {', '.join(map(repr, LEVELS))}")
    return name


def register_autopilot(task_name: str, factory: Callable) -> None:
    """Make ``factory(env, seed)`` the autopilot of task ``task_name`` at the ``move`` level
    (replacing any entry-point registration for that name)."""
    _autopilots[task_name] = factory


def autopilot_factory(task_name: str) -> Callable:
    """The autopilot factory of ``task_name``: registered at run time, else from the
    :data:`AUTOPILOT_GROUP` entry points (each a function returning ``{task name: factory}``);
    a :class:`~proteo_env.config.ConfigError` when none."""
    if task_name not in _autopilots:
        for point in metadata.entry_points(group=AUTOPILOT_GROUP):
            for name, factory in point.load()().items():
                _autopilots.setdefault(name, factory)  # a run-time registration stays
    if task_name not in _autopilots:
        known = sorted(_autopilots)
        raise ConfigError(
            f"control='move' needs the hand-coded rules of task {task_name!r}, and none is "
            f"registered; allowed: tasks with rules ({', '.join(known) or 'none found'}); "
            "install the project (pip install -e .) or call "
            "proteo_env.control.register_autopilot"
        )
    return _autopilots[task_name]

"""The one registry of tasks: versioned ids (``chain-v0``) to task classes, and :func:`make`."""

from __future__ import annotations

from .config import ConfigError, split_overrides
from .tasks.base import Task
from .tasks.chain import Chain
from .tasks.sandbox import Sandbox

TASKS: dict[str, type[Task]] = {cls.task_id(): cls for cls in (Sandbox, Chain)}
"""Registered task classes by id ``<name>-v<version>``."""


def task_class(task_id: str) -> type[Task]:
    """The class registered as ``task_id``; a bare name means its newest version."""
    if task_id in TASKS:
        return TASKS[task_id]
    versions = sorted((cls.version, tid) for tid, cls in TASKS.items() if cls.name == task_id)
    if versions:
        return TASKS[versions[-1][1]]
    raise ConfigError(f"unknown task {task_id!r}; allowed: {', '.join(sorted(TASKS))}")


def make(task_id: str, *, render_mode: str | None = None, **overrides):
    """Build the environment of a registered task.

    Args:
        task_id: a registered id such as ``"sandbox-v0"`` (or a bare name for its newest version).
        render_mode: ``None`` or one of ``ProteoEnv.metadata["render_modes"]``.
        **overrides: environment settings (``max_cycles``, ``obs_radius``), physics
            (``motion_model``, ``keep_connected``, ``scent_sweeps``, ``exact_scent``,
            ``scent_max``) and the task's own parameters. Unknown keys raise ``ValueError``
            listing the allowed ones.

    Returns:
        a :class:`~proteo_env.env.ProteoEnv` (call ``reset(seed=...)`` before stepping).
    """
    from .env import ProteoEnv

    cls = task_class(task_id)
    config, params = split_overrides(overrides, cls.Params, task_name=cls.task_id())
    return ProteoEnv(cls(params), config, render_mode=render_mode)

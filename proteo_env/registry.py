"""The one registry of tasks: versioned ids (``chain-v0``) to task classes, and :func:`make`."""

from __future__ import annotations

from .config import ConfigError, split_overrides
from .tasks.base import Task
from .tasks.branch import Branch, BranchV1
from .tasks.chain import Chain, ChainV1
from .tasks.grasp import Grasp
from .tasks.locomotion import Locomotion
from .tasks.sandbox import Sandbox
from .tasks.snake import Snake
from .tasks.table import Table, TableV1, TableV2

TASKS: dict[str, type[Task]] = {
    cls.task_id(): cls
    for cls in (Sandbox, Chain, ChainV1, Grasp, Table, TableV1, TableV2, Branch, BranchV1, Locomotion, Snake)
}
"""Registered task classes by id ``<name>-v<version>``."""


def register(cls: type[Task]) -> type[Task]:
    """Register a task class defined anywhere (a module of your own) as ``cls.task_id()``;
    returns it, so it serves as a class decorator. A class that is not a
    :class:`~proteo_env.tasks.base.Task`, or an id already taken by another class, is a
    :class:`~proteo_env.config.ConfigError`."""
    if not (isinstance(cls, type) and issubclass(cls, Task)):
        raise ConfigError(f"register({cls!r}) is not allowed; allowed: a subclass of proteo_env.tasks.base.Task")
    task_id = cls.task_id()
    if TASKS.get(task_id, cls) is not cls:
        raise ConfigError(
            f"task id {task_id!r} is taken by {TASKS[task_id].__qualname__}; allowed: a new name or version"
        )
    TASKS[task_id] = cls
    return cls


def split_task_id(task_id: str) -> tuple[str, int | None]:
    """``"chain-v1"`` -> ``("chain", 1)``; a bare name (``"chain"``) -> ``("chain", None)``."""
    name, sep, version = task_id.rpartition("-v")
    if sep and name and version.isdigit():
        return name, int(version)
    return task_id, None


def task_name(task_id: str) -> str:
    """The task's name without its version: ``"chain-v1"`` -> ``"chain"``."""
    return split_task_id(task_id)[0]


def newest_tasks() -> dict[str, type[Task]]:
    """The newest version of every task name, by id (what ``proteo demo`` runs)."""
    newest = {cls.name: task_class(cls.name) for cls in TASKS.values()}
    return {cls.task_id(): cls for cls in newest.values()}


def task_class(task_id: str) -> type[Task]:
    """The class registered as ``task_id``; a bare name means its newest version."""
    if task_id in TASKS:
        return TASKS[task_id]
    versions = sorted((cls.version, tid) for tid, cls in TASKS.items() if cls.name == task_id)
    if versions:
        return TASKS[versions[-1][1]]
    raise ConfigError(f"unknown task {task_id!r}; allowed: {', '.join(sorted(TASKS))}")


def make(task_id: str, *, render_mode: str | None = None, camera=None, **overrides):
    """Build the environment of a registered task.

    Args:
        task_id: a registered id such as ``"sandbox-v0"`` (or a bare name for its newest version).
        render_mode: ``None`` or one of ``ProteoEnv.metadata["render_modes"]``.
        camera: picture settings for ``rgb_array``/``human``: a dict of ``azimuth``,
            ``elevation``, ``zoom``, ``follow``, ``width``, ``height`` (see
            :class:`~proteo_env.render.camera.Camera`).
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
    return ProteoEnv(cls(params), config, render_mode=render_mode, camera=camera)


def make_batched(task_id: str, n_envs: int, **overrides):
    """Build ``n_envs`` copies of a registered task stepped together on arrays.

    Same arguments as :func:`make` (no ``render_mode``). Returns a
    :class:`~proteo_env.batched.BatchedEnv`; world ``b`` of ``reset(seed=s)`` follows the
    trajectory of ``make(task_id, **overrides)`` reset with seed ``world_seeds(s, n_envs)[b]``
    (child ``b`` of ``numpy.random.SeedSequence(s)``, :func:`~proteo_env.config.world_seeds`).
    """
    from .batched import BatchedEnv

    if not isinstance(n_envs, int) or n_envs < 1:
        raise ConfigError(f"n_envs={n_envs!r} is not allowed; allowed: an integer >= 1")
    cls = task_class(task_id)
    config, params = split_overrides(overrides, cls.Params, task_name=cls.task_id())
    return BatchedEnv([cls(params) for _ in range(n_envs)], config)

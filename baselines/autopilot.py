"""The paper's rules as the autopilot of the ``move`` control level (:mod:`proteo_env.control`).

At ``control="move"`` the agent chooses only its move; mode, scent roles and messages come
from the task's hand-coded policy run on the same observation. ``pyproject.toml`` registers
:func:`hand_coded_rules` for each task under the ``proteo_env.autopilots`` entry-point group,
which is how the environment finds it without importing this package by name.
"""

from __future__ import annotations

from types import SimpleNamespace

from . import POLICIES
from .base import KernelPolicy


def hand_coded_rules(env, seed: int | None = None) -> KernelPolicy:
    """The task's hand-coded policy (the policy of :data:`baselines.POLICIES` named as the task) for
    ``env`` (anything with ``action_layout``, ``task`` and ``config``), with the task's rule parameters; its :meth:`~baselines.base.KernelPolicy.act_arrays`
    gives full actions, whatever the env's control level."""
    full = SimpleNamespace(action_layout=env.action_layout, task=env.task, config=env.config)
    return POLICIES[env.task.name].for_env(full, seed=seed)

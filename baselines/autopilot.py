"""The paper's rules as the autopilot of the ``move`` control level (:mod:`proteo_env.control`).

At ``control="move"`` the agent chooses only its move; mode, scent roles and messages come
from the task's hand-coded policy run on the same observation. ``pyproject.toml`` registers
:func:`autopilots` under the ``proteo_env.autopilots`` entry-point group, which is how the
environment finds the rules without importing this package by name; it serves
:func:`hand_coded_rules` for every registered task whose policy is in :data:`POLICIES`.
"""

from __future__ import annotations

from types import SimpleNamespace

from proteo_env.registry import TASKS

from . import POLICIES
from .base import KernelPolicy


def hand_coded_rules(env, seed: int | None = None) -> KernelPolicy:
    """The task's hand-coded policy (the policy of :data:`baselines.POLICIES` named as the task) for
    ``env`` (anything with ``action_layout``, ``task`` and ``config``), with the task's rule parameters; its :meth:`~baselines.base.KernelPolicy.act_arrays`
    gives full actions, whatever the env's control level."""
    full = SimpleNamespace(action_layout=env.action_layout, task=env.task, config=env.config)
    return POLICIES[env.task.name].for_env(full, seed=seed)


def autopilots() -> dict:
    """``{task name: hand_coded_rules}`` for every registered task with a policy of the same name
    in :data:`POLICIES` (the entry point of the ``proteo_env.autopilots`` group)."""
    return {cls.name: hand_coded_rules for cls in TASKS.values() if cls.name in POLICIES}

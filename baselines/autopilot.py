"""The paper's rules as the autopilot of the ``move`` control level (:mod:`proteo_env.control`).

At ``control="move"`` the agent chooses only its move; mode, scent roles and messages come
from the task's hand-coded policy run on the same observation. ``pyproject.toml`` registers
:func:`hand_coded_rules` for each task under the ``proteo_env.autopilots`` entry-point group,
which is how the environment finds it without importing this package by name.
"""

from __future__ import annotations

from types import SimpleNamespace

from .base import KernelPolicy
from .branch import BranchPolicy
from .chain import ChainPolicy
from .grasp import GraspPolicy
from .table import TablePolicy

RULES: dict[str, type[KernelPolicy]] = {"chain": ChainPolicy, "branch": BranchPolicy, "table": TablePolicy,
                                        "grasp": GraspPolicy}
"""The hand-coded policy of each task name."""


def hand_coded_rules(env, seed: int | None = None) -> KernelPolicy:
    """The task's hand-coded policy for ``env`` (anything with ``action_layout``, ``task`` and
    ``config``), with the task's rule parameters; its :meth:`~baselines.base.KernelPolicy.act_arrays`
    gives full actions, whatever the env's control level."""
    full = SimpleNamespace(action_layout=env.action_layout, task=env.task, config=env.config)
    return RULES[env.task.name].for_env(full, seed=seed)

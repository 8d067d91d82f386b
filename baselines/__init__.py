"""Baseline policies: the paper's hand-coded behaviours and the random floor.

``POLICIES`` maps policy names to classes; :func:`make_policy` builds one for an env.
"""

from __future__ import annotations

from .base import Policy
from .branch import BranchPolicy
from .chain import ChainPolicy
from .grasp import GraspPolicy
from .locomotion import LocomotionPolicy
from .random_policy import RandomPolicy
from .table import TablePolicy

POLICIES: dict[str, type[Policy]] = {
    cls.name: cls for cls in (RandomPolicy, ChainPolicy, GraspPolicy, TablePolicy, BranchPolicy, LocomotionPolicy)
}


def make_policy(name: str, env, *, seed: int | None = None, **params) -> Policy:
    """Build policy ``name`` for ``env`` (from its static interface only)."""
    if name not in POLICIES:
        raise ValueError(f"unknown policy {name!r}; allowed: {', '.join(sorted(POLICIES))}")
    return POLICIES[name].for_env(env, seed=seed, **params)


__all__ = ["POLICIES", "Policy", "make_policy"]

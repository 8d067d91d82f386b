"""Baseline policies: the paper's hand-coded behaviours, programs of its primitives, and the random floor.

``POLICIES`` maps policy names to classes; :func:`make_policy` builds one for an env.
"""

from __future__ import annotations

import numpy as np

from .base import Policy, constructor_parameters
from .branch import BranchPolicy
from .chain import ChainPolicy
from .grasp import GraspPolicy
from .locomotion import LocomotionPolicy
from .program_policy import ProgramPolicy
from .random_policy import RandomPolicy
from .snake import SnakePolicy
from .table import TablePolicy

POLICIES: dict[str, type[Policy]] = {
    cls.name: cls
    for cls in (
        RandomPolicy,
        ChainPolicy,
        GraspPolicy,
        TablePolicy,
        BranchPolicy,
        LocomotionPolicy,
        SnakePolicy,
        ProgramPolicy,
    )
}


def register_policy(cls: type[Policy]) -> type[Policy]:
    """Add a policy class defined anywhere to :data:`POLICIES` under ``cls.name``; returns it (a
    class decorator). Named as a registered task, it is that task's hand-coded rules: the
    ``move`` level's autopilot and ``proteo eval``'s rules row find it. A class that is not a
    :class:`~baselines.base.Policy`, or a name taken by another class, is a ``ValueError``."""
    if not (isinstance(cls, type) and issubclass(cls, Policy)):
        raise ValueError(f"register_policy({cls!r}) is not allowed; allowed: a subclass of baselines.base.Policy")
    if POLICIES.get(cls.name, cls) is not cls:
        raise ValueError(f"policy name {cls.name!r} is taken by {POLICIES[cls.name].__qualname__}; allowed: a new name")
    POLICIES[cls.name] = cls
    return cls


def make_policy(name: str, env, *, seed: int | None = None, **params) -> Policy:
    """Build policy ``name`` for ``env`` (from its static interface only)."""
    if name not in POLICIES:
        raise ValueError(f"unknown policy {name!r}; allowed: {', '.join(sorted(POLICIES))}")
    given_by_env = ("self", "action_layout", "modes", "scent_max", "seed")
    accepted = [p for p in constructor_parameters(POLICIES[name]) if p not in given_by_env]
    unknown = sorted(set(params) - set(accepted))
    if unknown:
        raise ValueError(
            f"policy {name!r}: parameter {unknown[0]!r} is not allowed; allowed: {', '.join(accepted) or 'none'}"
        )
    for key, value in params.items():
        _check_kind(name, key, value, constructor_parameters(POLICIES[name])[key].default)
    return POLICIES[name].for_env(env, seed=seed, **params)


def _check_kind(policy: str, key: str, value, default) -> None:
    """A ``ValueError`` when ``value`` is not of the kind of the parameter's ``default`` (a number
    for a number, a bool for a bool, a string for a string; other defaults are not checked)."""
    if isinstance(default, bool):
        ok, kind = isinstance(value, bool | np.bool_), "true or false"
    elif isinstance(default, int | float):
        ok = isinstance(value, int | float | np.number) and not isinstance(value, bool) and np.isfinite(value)
        kind = "a finite number"
    elif isinstance(default, str):
        ok, kind = isinstance(value, str), "a string"
    else:
        return
    if not ok:
        raise ValueError(f"policy {policy!r}: {key}={value!r} is not allowed; allowed: {kind} (default {default!r})")


__all__ = ["POLICIES", "Policy", "make_policy", "register_policy"]

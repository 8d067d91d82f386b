"""Shared helpers of the environment tests: small episodes of every registered task.

``SMALL_OVERRIDES`` maps a task *name* (``Task.name``, not the versioned id) to the
overrides that keep its episodes small and fast; a task without an entry runs with its
defaults. When a task is registered, add its entry here if its defaults are large.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import proteo_env

# The tests run on every core already (pytest -n 2): the batched evaluator of each test runs in
# its own process unless a test asks for workers (training.machinery.evaluator.default_workers).
os.environ.setdefault("PROTEO_WORKERS", "1")

SMALL_OVERRIDES: dict[str, dict] = {
    "sandbox": {"n_modules": 12},
    "chain": {"n_modules": 12},
    "branch": {"n_modules": 12, "T": 3, "B": 2},
    "table": {"board_size": 6, "depth": 2, "n_spares": 8},
    "grasp": {"n_modules": 16, "n_seed_modules": 2, "object_size": 1.5, "distance": 1, "margin": 2},
}


REPRESENTATIVE_TASKS = ("sandbox-v0", "chain-v1", "grasp-v0", "table-v2")
"""The task ids whose cases run in the fast tier (``make test``): the bare engine, a growing
structure, an object and a board. Every other id runs in the slow tier (``make test-all``)."""


def task_params(task_ids=None) -> list:
    """``task_ids`` (default: every registered id) as pytest params for ``parametrize``: the
    :data:`REPRESENTATIVE_TASKS` in the fast tier, every other id marked ``slow``."""
    ids = sorted(proteo_env.TASKS) if task_ids is None else task_ids
    return [pytest.param(t, marks=() if t in REPRESENTATIVE_TASKS else pytest.mark.slow, id=t) for t in ids]


def reseal(folder: Path) -> None:
    """Record in checkpoint ``folder``'s ``proteo.json`` the SHA-256 of its payload files as they
    are now (a test that edits a payload file on purpose, as if its trainer had written it so)."""
    import json

    from training.machinery.checkpoints import payload_digests

    meta = json.loads((folder / "proteo.json").read_text())
    (folder / "proteo.json").write_text(json.dumps({**meta, "files": payload_digests(folder)}))


def small_overrides(task_id: str, **extra) -> dict:
    """The small overrides of ``task_id`` (by its task name) updated with ``extra``."""
    name = proteo_env.TASKS[task_id].name
    return {**SMALL_OVERRIDES.get(name, {}), **extra}


def make_small_env(task_id: str, **extra):
    """``proteo_env.make(task_id)`` with the task's small overrides and ``extra``."""
    return proteo_env.make(task_id, **small_overrides(task_id, **extra))


def random_actions(env, observations, rng: np.random.Generator, *, p_unmasked: float = 0.0) -> dict:
    """One random action per live agent from a numpy generator (reproducible).

    The move is uniform over the legal moves of the observation's ``action_mask``; with
    probability ``p_unmasked`` it is uniform over all 13 moves instead (denied moves too).
    Every other field is uniform over its range.
    """
    actions = {}
    for agent in env.agents:
        nvec = env.action_space(agent).nvec
        action = rng.integers(0, nvec).astype(np.int64)
        if rng.random() >= p_unmasked:
            legal = np.flatnonzero(observations[agent]["action_mask"])
            action[0] = legal[rng.integers(len(legal))]
        actions[agent] = action
    return actions


@pytest.fixture
def make_small():
    """Factory fixture: ``make_small(task_id, **extra)`` builds a small env of that task."""
    return make_small_env


@pytest.fixture
def actions_from():
    """Factory fixture: :func:`random_actions`."""
    return random_actions


def run_without_jit(module: str, function: str) -> subprocess.CompletedProcess:
    """Run ``tests/<module>.py``'s ``function()`` in a fresh interpreter with
    ``NUMBA_DISABLE_JIT=1`` (every kernel as plain Python); returns the finished process."""
    here = Path(__file__).resolve().parent
    code = f"import sys; sys.path.insert(0, {str(here)!r}); import {module} as t; t.{function}()"
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    return subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300, cwd=here.parent
    )

"""The policy interface shared by hand-coded, random, learned and evolved controllers."""

from __future__ import annotations

import numpy as np

from proteo_env.spaces import ActionLayout


class Policy:
    """Maps every agent's observation to its action, seeing nothing else.

    A policy is built from the environment's static interface (``env.action_layout`` and
    the task's mode names) and then only ever receives observations: ``act`` takes the dict
    ``{agent: observation}`` that ``env.reset``/``env.step`` return and gives back
    ``{agent: action}``. Per-agent private memory (the paper's module memory) may be kept
    between calls, keyed by agent name; :meth:`reset` clears it.

    Args:
        layout: the task's :class:`~proteo_env.spaces.ActionLayout`.
        modes: the task's mode names (``env.task.modes``).
        scent_max: the scent value that means "no scent" (``env.config.physics.scent_max``).
        seed: seed of the policy's own random generator.
    """

    name = ""

    def __init__(self, layout: ActionLayout, modes, *, scent_max: int = 65535, seed: int | None = None):
        self.layout = layout
        self.modes = tuple(modes)
        self.scent_max = scent_max
        self.rng = np.random.default_rng(seed)

    @classmethod
    def for_env(cls, env, *, seed: int | None = None, **params):
        """Build the policy from an environment's static interface (never its state)."""
        return cls(env.action_layout, env.task.modes, scent_max=env.config.physics.scent_max,
                   seed=seed, **params)

    def reset(self, seed: int | None = None) -> None:
        if seed is not None:
            self.rng = np.random.default_rng(seed)

    def act(self, observations: dict) -> dict:
        raise NotImplementedError

    def random_legal_move(self, mask: np.ndarray, allowed=None) -> int:
        """A uniformly chosen legal move ``1..12`` (``allowed``: optional (13,) bool filter), or 0."""
        legal = mask[1:].astype(bool)
        if allowed is not None:
            legal &= allowed[1:]
        choices = np.flatnonzero(legal)
        return int(self.rng.choice(choices)) + 1 if choices.size else 0

"""Random policy: uniform over legal moves, uniform over every other action field."""

from __future__ import annotations

import numpy as np

from .base import Policy, check_level


class RandomPolicy(Policy):
    """The floor every other policy is compared with.

    Each agent picks its move uniformly among the moves its ``action_mask`` allows (staying
    included) and every other field it chooses at the env's control level (mode, scent roles,
    message) uniformly over its range; at ``control="move"`` that is random moves under the
    task's rules.
    """

    name = "random"
    levels = ("move", "move+mode", "full")

    def __init__(self, action_layout, modes, *, scent_max=65535, seed=None, n_fields=None):
        super().__init__(action_layout, modes, scent_max=scent_max, seed=seed)
        self.nvec = action_layout.nvec[: n_fields or action_layout.length]

    @classmethod
    def for_env(cls, env, *, seed=None, **params):
        check_level(cls, env)
        return cls(
            env.action_layout,
            env.task.modes,
            scent_max=env.config.physics.scent_max,
            seed=seed,
            n_fields=len(getattr(env, "control_fields", env.action_layout.field_names)),
            **params,
        )

    def act(self, observations):
        """Per agent, in order: every field chosen uniformly, then the move uniformly among the
        legal ones. ``integers(0, n)`` draws what ``integers(0, [n])`` and ``choice(legal)`` draw,
        from the same stream (``tests/test_controller_api.py`` holds the two ways to each other), at a
        fifth of their cost: a robot of 1,200 modules acts in about 10 ms a cycle."""
        actions = {}
        move, nvec = self.action_layout.move, self.nvec
        for agent, obs in observations.items():
            if len(nvec) == 1:  # the move alone (control="move"): its first draw is replaced below
                action = np.array([self.rng.integers(0, nvec[0])])
            else:
                action = self.rng.integers(0, nvec)
            legal = obs["action_mask"].nonzero()[0]
            action[move] = legal[self.rng.integers(0, len(legal))]
            actions[agent] = action
        return actions

"""Random policy: uniform over legal moves, uniform over every other action field."""

from __future__ import annotations

from .base import Policy


class RandomPolicy(Policy):
    """The floor every other policy is compared with.

    Each agent picks its move uniformly among the moves its ``action_mask`` allows (staying
    included) and every other field (mode, scent roles, message) uniformly over its range.
    """

    name = "random"

    def act(self, observations):
        nvec = self.layout.nvec
        actions = {}
        for agent, obs in observations.items():
            action = self.rng.integers(0, nvec)
            legal = obs["action_mask"].nonzero()[0]
            action[self.layout.move] = self.rng.choice(legal)
            actions[agent] = action
        return actions

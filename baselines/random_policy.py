"""Random policy: uniform over legal moves, uniform over every other action field."""

from __future__ import annotations

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
        actions = {}
        for agent, obs in observations.items():
            action = self.rng.integers(0, self.nvec)
            legal = obs["action_mask"].nonzero()[0]
            action[self.action_layout.move] = self.rng.choice(legal)
            actions[agent] = action
        return actions

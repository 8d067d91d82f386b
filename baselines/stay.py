"""Never-move policy: every module stays where it is and keeps its mode."""

from __future__ import annotations

from .base import Policy


class StayPolicy(Policy):
    """The floor of doing nothing, a degenerate strategy every reward must rank below the rules.

    Each agent stays (move 0), repeats its own mode (``own_mode``: the mode field of the
    action sets the mode, so keeping it means sending the current one), relays scent on every
    channel and sends no message.
    """

    name = "stay"

    def act(self, observations):
        actions = {}
        for agent, obs in observations.items():
            actions[agent] = self.layout.encode(move=0, mode=int(obs["own_mode"][0]))
        return actions

"""An entrant written as a plain Python object: no network, nothing imported from proteo.

`proteo eval --benchmark v7 --entrant examples/factory` calls `make(spec)` once per process and
split, then every cycle `act(observation)`: a dict of the observation fields of every agent of
every world in the batch, each an array (worlds, agents, ...), with `action_mask` (worlds,
agents, 13) marking the legal moves. It returns integer actions (worlds, agents, F); at control
level "move", F = 1, the move: 0 stays, 1 to 12 roll towards one of the 12 neighbour sites.
`reset(world, seed)` starts a new episode in row `world` of the batch.

The rule: each module stays with probability `stay`, else rolls to a legal site drawn at random.
Each world draws from a generator of its own world seed, so an episode depends on its world
alone, whatever else is in the batch.
"""

from __future__ import annotations

import numpy as np


class RandomRoller:
    def __init__(self, n_fields: int, stay: float = 0.5):
        self.n_fields, self.stay = n_fields, stay
        self.rngs: dict[int, np.random.Generator] = {}

    def reset(self, world: int, seed: int) -> None:
        self.rngs[world] = np.random.default_rng(seed)

    def act(self, observation: dict) -> np.ndarray:
        mask = observation["action_mask"].astype(bool)  # (worlds, agents, 13)
        worlds, agents = mask.shape[:2]
        actions = np.zeros((worlds, agents, self.n_fields), dtype=np.int64)
        for w in range(worlds):
            rng = self.rngs[w]
            draw = np.where(mask[w, :, 1:], rng.random((agents, 12)), -1.0)  # a random legal roll
            roll = np.where(draw.max(axis=1) >= 0, draw.argmax(axis=1) + 1, 0)
            actions[w, :, 0] = np.where(rng.random(agents) < self.stay, 0, roll)
        return actions


def make(spec) -> RandomRoller:
    """`spec` tells the worlds: spec.task, spec.level, spec.n_agents, spec.action_fields, spec.nvec."""
    if spec.level != "move":
        raise ValueError(f"RandomRoller chooses moves only, not the fields of control level {spec.level!r}")
    return RandomRoller(len(spec.nvec))

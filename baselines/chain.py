"""The paper's chain behaviour (section 4.1) as a policy over observations.

Rules, as the paper lists them (modes SLEEP, SEARCH, SEED, FINAL):

- If in SLEEP mode, if a scent is detected, go to SEARCH mode.
- If in SEARCH mode, propagate scent and move along scent gradient.
- If in SEED mode, emit scent, and if a module has appeared in the direction of growth,
  set that module to SEED mode, and go to FINAL mode.
- If in FINAL mode, propagate scent.

How each rule is carried out through the agent interface:

- "Set that module to SEED mode" is a message (``BECOME_SEED``) sent to the growth direction;
  the receiver becomes SEED next cycle and keeps growing in the same direction (the message
  arrives from the opposite side).
- A SEED broadcasts its growth direction to its neighbours every cycle, so a SEARCH module
  that reaches the seed knows which face to roll to ("find a spot next to the seed"). A
  SEARCH module next to a SEED that has not yet heard the direction waits a cycle, so it
  cannot leave the growth spot in the cycle it is promoted.
- A SEED without a direction (the first one) picks an empty neighbour site, preferring one
  facing away from the structure, among horizontal directions when ``horizontal``.
- SLEEP modules relay scent so that it spreads through the blob.
- With ``p_seed > 0`` a SLEEP module that detects no scent becomes a SEED with that
  probability each cycle (the paper's decentralised start).
"""

from __future__ import annotations

from proteo_env.core.lattice import OPPOSITE
from proteo_env.spaces import EMIT, KIND_MODULE, MESSAGE_TO_ALL, RELAY

from .base import Policy
from .primitives import (BECOME_SEED, approach_growth_spot, climb, outward_direction, received,
                         scent_detected, seed_growth_message)

SLEEP, SEARCH, SEED, FINAL = range(4)


class ChainPolicy(Policy):
    """Hand-coded chain growth (rules in the module docstring).

    Args:
        p_seed: per-cycle probability that a SLEEP module with no scent around becomes a SEED.
        p_random: probability that a SEARCH module makes a random legal move instead of
            following the gradient.
        horizontal: first seeds grow along horizontal directions only.
    """

    name = "chain"

    def __init__(self, layout, modes, *, scent_max=65535, seed=None, p_seed=0.0, p_random=0.05,
                 horizontal=True):
        super().__init__(layout, modes, scent_max=scent_max, seed=seed)
        self.p_seed = p_seed
        self.p_random = p_random
        self.horizontal = horizontal
        self.growth: dict[str, int] = {}

    def reset(self, seed=None):
        super().reset(seed)
        self.growth.clear()

    def act(self, observations):
        return {agent: self.decide(agent, obs) for agent, obs in observations.items()}

    def decide(self, agent: str, obs) -> object:
        mode = int(obs["own_mode"][0])
        encode = self.layout.encode
        promoted = received(obs, BECOME_SEED)
        if promoted >= 0 and mode in (SLEEP, SEARCH):
            self.growth[agent] = int(OPPOSITE[promoted])
            return encode(mode=SEED, roles=[EMIT])
        if mode == SLEEP:
            if scent_detected(obs, 0, self.scent_max):
                return encode(mode=SEARCH, roles=[RELAY])
            if self.rng.random() < self.p_seed:
                return encode(mode=SEED, roles=[EMIT])
            return encode(mode=SLEEP, roles=[RELAY])
        if mode == SEARCH:
            slot, growth = seed_growth_message(obs)
            if slot >= 0:
                move = approach_growth_spot(obs, slot, growth, self.rng)
            elif (obs["neighbour_mode"][:12] == SEED).any():
                move = 0  # next to a seed: wait to hear its growth direction
            else:
                move = climb(obs, 0, self.scent_max, self.rng, self.p_random)
            return encode(move=move, mode=SEARCH, roles=[RELAY])
        if mode == SEED:
            growth = self.growth.get(agent, -1)
            if growth < 0:
                growth = outward_direction(obs, self.rng, self.horizontal)
                if growth < 0:
                    return encode(mode=SEED, roles=[EMIT])
                self.growth[agent] = growth
            if obs["neighbour_kind"][growth] == KIND_MODULE and obs["neighbour_mode"][growth] != FINAL:
                del self.growth[agent]
                return encode(mode=FINAL, roles=[RELAY], message_target=growth, message_value=BECOME_SEED)
            return encode(mode=SEED, roles=[EMIT], message_target=MESSAGE_TO_ALL, message_value=growth + 1)
        return encode(mode=FINAL, roles=[RELAY])

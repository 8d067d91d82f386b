"""The paper's control primitives, read from one module's observation.

Shared by the hand-coded behaviours: scent detection, climbing a scent gradient by rolling
over neighbours, and the SEED hand-over handshake by messages. Everything here reads only
the observation dict of one module (fields of :mod:`proteo_env.spaces`).
"""

from __future__ import annotations

import numpy as np

from proteo_env.core.lattice import DIRECTIONS, OPPOSITE
from proteo_env.core.world import DIRECTION_ADJACENCY
from proteo_env.spaces import KIND_EMPTY, KIND_MODULE

BECOME_SEED = 13
"""Message value asking the receiver to become the new SEED (it grows on in the same direction)."""
GROWTH_BASE = 0
"""Message values ``1..12``: "I am a seed growing towards ``DIRECTIONS[value - 1]``"."""

_FACE = {tuple(d): k for k, d in enumerate(DIRECTIONS)}


def face_index(offset) -> int:
    """Index of a face-neighbour offset, or -1 when the offset is not a face direction."""
    return _FACE.get(tuple(int(v) for v in offset), -1)


def neighbour_scents(obs, channel: int, scent_max: int) -> np.ndarray:
    """``(12,)`` scent of each face neighbour on ``channel`` (``scent_max`` where no module)."""
    is_module = obs["neighbour_kind"][:12] == KIND_MODULE
    return np.where(is_module, obs["neighbour_scent"][:12, channel], scent_max)


def scent_detected(obs, channel: int, scent_max: int) -> bool:
    """Does this module or any neighbour carry scent on ``channel``?"""
    return bool(obs["own_scent"][channel] < scent_max
                or (neighbour_scents(obs, channel, scent_max) < scent_max).any())


def climb(obs, channel: int, scent_max: int, rng: np.random.Generator, p_random: float,
          allowed: np.ndarray | None = None) -> int:
    """A move along the scent gradient, or 0 to stay.

    The value a module would take at a target site is one more than the smallest scent among
    the modules it can see next to that site (the 4 sites adjacent to both here and there).
    The module takes a legal move of lowest such value; if none improves on its value here, it
    wanders among moves that keep that value (the paper's random search over a neighbour's
    faces), and stays if every move would make it worse. With probability ``p_random`` it
    makes a uniformly random legal move instead. ``allowed`` (13,) bool restricts the moves.
    """
    legal = np.flatnonzero(obs["action_mask"][1:])
    if allowed is not None:
        legal = legal[allowed[1 + legal]]
    if legal.size == 0:
        return 0
    if rng.random() < p_random:
        return int(rng.choice(legal)) + 1
    scents = neighbour_scents(obs, channel, scent_max).astype(np.int64)
    value_there = 1 + scents[DIRECTION_ADJACENCY[legal]].min(axis=1)
    value_here = 1 + scents.min()
    best = value_there.min()
    if best > value_here:
        return 0
    return int(rng.choice(legal[value_there == best])) + 1


def received(obs, value: int) -> int:
    """Direction slot a message ``value`` came from, or -1."""
    hits = np.flatnonzero(obs["messages"] == value)
    return int(hits[0]) if hits.size else -1


def seed_growth_message(obs) -> tuple[int, int]:
    """``(slot, growth)`` of a neighbouring seed's growth broadcast, or ``(-1, -1)``."""
    msgs = obs["messages"]
    hits = np.flatnonzero((msgs >= 1) & (msgs <= 12))
    if hits.size == 0:
        return -1, -1
    slot = int(hits[0])
    return slot, int(msgs[slot]) - 1


def approach_growth_spot(obs, slot: int, growth: int, rng: np.random.Generator) -> int:
    """Move towards the site next to a seed in its growth direction; 0 when there (or stuck).

    The seed lies at ``DIRECTIONS[slot]`` from here and grows towards ``DIRECTIONS[growth]``.
    If the spot is a neighbour site and the roll is legal, take it; otherwise roll randomly
    over the seed's faces (moves that keep the seed as a neighbour).
    """
    spot = DIRECTIONS[slot] + DIRECTIONS[growth]
    if not spot.any():
        return 0
    mask = obs["action_mask"]
    k = face_index(spot)
    if k >= 0 and mask[k + 1]:
        return k + 1
    around_seed = np.zeros(13, dtype=bool)
    around_seed[1 + DIRECTION_ADJACENCY[slot]] = True
    legal = np.flatnonzero(mask[1:].astype(bool) & around_seed[1:])
    return int(rng.choice(legal)) + 1 if legal.size else 0


def outward_direction(obs, rng: np.random.Generator, horizontal: bool) -> int:
    """A growth direction for a new seed: an empty neighbour site, preferring one whose
    opposite site holds a module (so growth leads away from the structure); horizontal
    directions only when ``horizontal``. Returns -1 when no neighbour site is empty."""
    kinds = obs["neighbour_kind"][:12]
    empty = kinds == KIND_EMPTY
    if horizontal:
        empty &= DIRECTIONS[:, 2] == 0
    outward = empty & (kinds[OPPOSITE] == KIND_MODULE)
    pool = np.flatnonzero(outward) if outward.any() else np.flatnonzero(empty)
    return int(rng.choice(pool)) if pool.size else -1

"""The paper's control primitives, read from one module's observation.

Shared by the hand-coded behaviours: scent detection, climbing a scent gradient by rolling
over neighbours, picking a growth direction, and the SEED hand-over handshake by messages.
Everything here reads only the observation dict of one module (fields of
:mod:`proteo_env.spaces`) plus the fixed lattice geometry (:data:`DIRECTIONS`, which face
sites touch which).

Geometry a module can read from its own observation: the 12 face sites around it; for a move
towards ``DIRECTIONS[k]`` the 4 sites adjacent to both here and the target are
``DIRECTION_ADJACENCY[k]`` (face slots of this module), so the module sees 4 of the target's
11 other neighbours (the rest are two hops away and not observed with ``obs_radius=1``).
"""

from __future__ import annotations

import numpy as np

from proteo_env.core.lattice import DIRECTIONS, OPPOSITE
from proteo_env.core.world import DIRECTION_ADJACENCY
from proteo_env.spaces import KIND_EMPTY, KIND_MODULE

from . import kernels

GROWTH_BASE = 0
"""Message values ``1..12``: "I am a seed growing towards ``DIRECTIONS[value - 1]``"."""

_FACE = {tuple(d): k for k, d in enumerate(DIRECTIONS)}
HORIZONTAL = DIRECTIONS[:, 2] == 0
"""``(12,)`` bool: the 4 face directions in the horizontal plane."""


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


def legal_moves(obs, allowed: np.ndarray | None = None) -> np.ndarray:
    """Direction indices ``k`` (0..11) whose move ``k + 1`` the action mask allows."""
    legal = np.flatnonzero(obs["action_mask"][1:])
    if allowed is not None:
        legal = legal[allowed[1 + legal]]
    return legal


def climb(obs, channel: int, scent_max: int, rng: np.random.Generator, p_random: float,
          allowed: np.ndarray | None = None, *, on_stuck: str = "stay", fewer_neighbours: bool = False,
          bias: np.ndarray | None = None) -> int:
    """A move along the scent gradient, or 0 to stay.

    The value a module would take at a target site is one more than the smallest scent among
    the modules it can see next to that site (with ``obs_radius=1`` these are the 4 sites
    adjacent to both here and there; the target's other neighbours are out of sight). A
    module's value here is one more than its smallest neighbour scent, so with radius-1
    observations no single roll is seen to improve it: the best a module can see is a roll
    that keeps touching its lowest neighbour. The rule is therefore the paper's:

    - take a legal roll of lowest value; if it improves on the value here, take it;
    - if the best rolls keep the value (they roll over the faces of the lowest neighbour),
      take one of them at random (the paper's "moves randomly over the available faces of
      its neighbour until it encounters" a lower one). With ``bias`` (a direction in space,
      e.g. downhill plus the module's previous heading) only rolls with a positive dot
      product with it are used when there are any (the paper's "directed random move");
      ``fewer_neighbours`` further prefers targets with fewer modules seen around them;
    - if every legal roll would lose the lowest neighbour, ``on_stuck`` decides: ``"stay"``
      (wait for the structure to change) or ``"random"`` (a uniformly random legal roll).

    With probability ``p_random`` it makes a uniformly random legal move instead.
    ``allowed`` (13,) bool restricts the moves.
    """
    legal = legal_moves(obs, allowed)
    if legal.size == 0:
        return 0
    if rng.random() < p_random:
        return int(rng.choice(legal)) + 1
    scents = neighbour_scents(obs, channel, scent_max).astype(np.int64)
    value_there = 1 + scents[DIRECTION_ADJACENCY[legal]].min(axis=1)
    value_here = 1 + scents.min()
    best = value_there.min()
    if best > value_here:
        return int(rng.choice(legal)) + 1 if on_stuck == "random" else 0
    pool = legal[value_there == best]
    if bias is not None and pool.size > 1:
        ahead = DIRECTIONS[pool] @ bias > 0
        if ahead.any():
            pool = pool[ahead]
    if fewer_neighbours and pool.size > 1:
        is_module = obs["neighbour_kind"][:12] == KIND_MODULE
        crowd = is_module[DIRECTION_ADJACENCY[pool]].sum(axis=1)
        pool = pool[crowd == crowd.min()]
    return int(rng.choice(pool)) + 1


def descent_direction(scents: np.ndarray, scent_max: int) -> np.ndarray:
    """``(3,)`` rough direction of decreasing scent seen from here (zero when flat).

    Sum of the neighbour directions weighted by how much lower than the neighbours' mean
    each neighbour's scent is; only neighbours that carry scent count.
    """
    has = scents < scent_max
    if has.sum() < 2:
        return np.zeros(3)
    s = scents[has].astype(np.float64)
    return ((s.mean() - s)[:, None] * DIRECTIONS[has]).sum(axis=0)


def received(obs, value: int) -> int:
    """Direction slot a message ``value`` came from, or -1."""
    hits = np.flatnonzero(obs["messages"] == value)
    return int(hits[0]) if hits.size else -1


def seed_growth_message(obs) -> tuple[int, int]:
    """``(slot, growth)`` of a neighbouring seed's growth broadcast, or ``(-1, -1)``.

    The slot is where the message came from when it was sent, at the start of last cycle's
    moves; if this module moved since, the slot is stale (the growth value is not).
    """
    msgs = obs["messages"]
    hits = np.flatnonzero((msgs >= 1) & (msgs <= 12))
    if hits.size == 0:
        return -1, -1
    slot = int(hits[0])
    return slot, int(msgs[slot]) - 1


def neighbour_slots(obs, mode: int) -> np.ndarray:
    """Face slots (0..11) whose neighbour shows ``mode`` now."""
    return np.flatnonzero(obs["neighbour_mode"][:12] == mode)


def approach_growth_spot(obs, slot: int, growth: int, rng: np.random.Generator,
                         greedy: bool = False) -> int:
    """Move towards the site next to a seed in its growth direction; 0 when there (or stuck).

    The seed lies at ``DIRECTIONS[slot]`` from here and grows towards ``DIRECTIONS[growth]``.
    If the spot is a neighbour site and the roll is legal, take it; otherwise roll over the
    seed's faces (moves that keep the seed as a neighbour): uniformly at random, or with
    ``greedy`` among those that end nearest the spot (random among ties).
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
    if legal.size == 0:
        return 0
    if greedy:
        dist = ((spot[None, :] - DIRECTIONS[legal]) ** 2).sum(axis=1)
        legal = legal[dist == dist.min()]
    return int(rng.choice(legal)) + 1


def outward_direction(obs, rng: np.random.Generator, horizontal: bool) -> int:
    """A growth direction for a new seed: an empty neighbour site, preferring one whose
    opposite site holds a module (so growth leads away from the structure); horizontal
    directions only when ``horizontal``. Returns -1 when no neighbour site is empty."""
    kinds = obs["neighbour_kind"][:12]
    empty = kinds == KIND_EMPTY
    if horizontal:
        empty &= HORIZONTAL
    outward = empty & (kinds[OPPOSITE] == KIND_MODULE)
    pool = np.flatnonzero(outward) if outward.any() else np.flatnonzero(empty)
    return int(rng.choice(pool)) if pool.size else -1


def growth_direction(obs, rng: np.random.Generator, *, horizontal: bool, previous: int = -1,
                     avoid_modes=(), clean: bool = True) -> int:
    """A growth direction for a seed, from what it sees; -1 when there is none.

    Candidates are the neighbour sites that are empty (horizontal ones only when
    ``horizontal``) and whose seen neighbours (the 4 sites adjacent to both the seed and the
    spot) hold no module in ``avoid_modes`` (e.g. FINAL, so a new chain site touches no
    earlier chain module but the seed). With ``previous`` (the direction the chain came in)
    a direction at more than 90 degrees to it is excluded (that spot would touch the
    module before the seed) and the straight one is preferred. Among the rest the choice
    prefers, in order: with ``clean``, spots that touch the fewest modules besides the seed
    (the chain leaves the blob cleanly); spots whose opposite site holds a module (growth
    away from the structure); then uniformly at random (one ``rng.integers`` draw). The
    rule runs as the kernel :func:`baselines.kernels.growth_direction`.
    """
    kinds = np.ascontiguousarray(obs["neighbour_kind"], dtype=np.int8)[None]
    modes = np.ascontiguousarray(obs["neighbour_mode"], dtype=np.int32)[None]
    avoid_bits = sum(1 << int(m) for m in set(avoid_modes))
    return int(kernels.growth_direction(kinds, modes, 0, rng, bool(horizontal), int(previous), avoid_bits,
                                        bool(clean)))


# ---------------------------------------------------------------------- batched forms
# Helpers over stacked observation fields (first axis: module); each row is computed from
# that module's own observation.


def random_pick(pool: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``(Q,)`` one uniformly chosen True column per row of ``pool`` (Q, 12); -1 where none."""
    keys = rng.random(pool.shape)
    keys[~pool] = -1.0
    pick = keys.argmax(axis=1)
    return np.where(pool.any(axis=1), pick, -1)

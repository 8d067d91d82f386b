"""The paper's control primitives, read from one module's observation.

Shared by the hand-coded behaviours: scent detection, approaching a seed's growth spot by
rolling over its faces, picking a growth direction, and random picks over stacked rows (the
chain and branch rules themselves are the kernels of :mod:`baselines.kernels`). Everything here reads only the observation dict of one module (fields of
:mod:`proteo_env.spaces`) plus the fixed lattice geometry (:data:`DIRECTIONS`, which face
sites touch which).

Geometry a module can read from its own observation: the 12 face sites around it; for a move
towards ``DIRECTIONS[k]`` the 4 sites adjacent to both here and the target are
``DIRECTION_ADJACENCY[k]`` (face slots of this module), so the module sees 4 of the target's
11 other neighbours (the rest are two hops away and not observed with ``obs_radius=1``).
"""

from __future__ import annotations

import numpy as np

from proteo_env.core.lattice import DIRECTIONS
from proteo_env.core.world import DIRECTION_ADJACENCY
from proteo_env.spaces import KIND_MODULE

from . import kernels

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

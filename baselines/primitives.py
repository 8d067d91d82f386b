"""The primitives every hand-coded rule is built from, as numba kernels over stacked observation fields.

The paper's control primitives, one row (module) at a time, reading only that module's
observation (fields of :mod:`proteo_env.spaces` stacked over agents, first axis: agent row)
and the fixed lattice geometry:

- **writing actions**: :func:`write_action` (move, mode, scent roles, message);
- **bit sets and picks** over the 12 face slots (bit ``k``: ``DIRECTIONS[k]``):
  :func:`legal_bits`, :func:`module_bits`, :func:`hint_bits`, :func:`random_pick`, :func:`uniform_pick`,
  :func:`first_bit`, :func:`fewest_neighbours`, :func:`fewest_ruled_out`;
- **scents** (the roles' effect as a module sees it): :func:`seen_scent`,
  :func:`detects_scent`, the gradient climb's step :func:`lowest_rolls` (the rolls whose
  target lies next to the lowest scent) and its direction :func:`downhill_bias`;
- **seeding**: :func:`growth_direction` (where a seed grows), :func:`outward_pick`, :func:`spot_touches`;
- **directed random moves**: :func:`approach_spot` (roll over a seed's faces to its growth
  spot), :func:`approach` and :func:`approach_rows` (a group rolling towards target sites over
  a pivot's faces, with random legal moves when stuck).

Draws follow one convention so the same observations, memory and generator state give the
same actions wherever a rule runs (a policy's ``act``, the compiled rollout): a uniform pick
among a set of directions draws 12 uniforms (one key per direction, the largest key among the
set wins), also when the set has one member or none; :func:`uniform_pick` draws one integer.

The behaviours' rules (:mod:`baselines.chain`, :mod:`baselines.branch`,
:mod:`baselines.table`, :mod:`baselines.grasp`,
:mod:`baselines.locomotion`, :mod:`baselines.crawl`) are written with these.
"""

from __future__ import annotations

import numpy as np

from proteo_env.core.jit import kernel
from proteo_env.core.lattice import DIRECTIONS, OPPOSITE
from proteo_env.core.world import DIRECTION_ADJACENCY
from proteo_env.spaces import KIND_EMPTY, KIND_MODULE


def _spot_face() -> np.ndarray:
    index = {tuple(d): k for k, d in enumerate(DIRECTIONS)}
    table = np.full((12, 12), -1, dtype=np.int64)
    for s in range(12):
        for g in range(12):
            table[s, g] = index.get(tuple(DIRECTIONS[s] + DIRECTIONS[g]), -1)
    return table


SPOT_FACE = _spot_face()
"""``SPOT_FACE[s, g]``: face slot of ``DIRECTIONS[s] + DIRECTIONS[g]`` (the growth spot of a
neighbour at ``s`` growing towards ``g``), -1 when that site is no face neighbour (or is
here, ``g == OPPOSITE[s]``)."""
AROUND_BITS = np.array([sum(1 << int(j) for j in row) for row in DIRECTION_ADJACENCY], dtype=np.int64)
"""``AROUND_BITS[s]``: the face slots still next to ``DIRECTIONS[s]`` after any roll over them
(the 4 slots adjacent to both here and there), as a bit set."""
EQUATOR_BITS = np.array(
    [sum(1 << k for k in range(12) if DIRECTIONS[k, axis] == sign) for axis in range(3) for sign in (1, -1)],
    dtype=np.int64,
)
"""``(6,)`` the face slots around each of the 6 octahedral holes that touch a site, as bit sets:
the hole at half a step along ``+x`` is surrounded by this module, the 4 face sites with
``x = +1`` (its "equator", all seen) and the site two steps along ``+x`` (not seen)."""
BIT_COUNT = np.array([bin(v).count("1") for v in range(1 << 12)], dtype=np.int64)
"""``BIT_COUNT[bits]``: the number of set bits of a 12-bit set."""
HORIZONTAL_BITS = sum(1 << k for k in range(12) if DIRECTIONS[k, 2] == 0)
"""The 4 face directions in the horizontal plane, as a bit set."""
UP_BITS = sum(1 << k for k in range(12) if DIRECTIONS[k, 2] > 0)
"""The 4 face directions pointing up (``z > 0``), as a bit set."""
DOT = DIRECTIONS @ DIRECTIONS.T
"""``(12, 12)`` dot products of the face directions (2 same, 1 at 60, 0 at 90, -1 at 120, -2 opposite)."""
ALL_BITS = (1 << 12) - 1
"""All 12 face slots, as a bit set."""
FAR = np.iinfo(np.int64).max
"""Larger than any distance or scent value (the int64 maximum)."""


# ---------------------------------------------------------------- writing actions
@kernel
def write_action(actions, i, move, mode, first_role, other_roles, target, value):
    """Write row ``i`` of ``actions`` (A, L): ``move``, ``mode``, scent role ``first_role`` on
    channel 0 and ``other_roles`` on every other channel, message ``target`` and ``value``."""
    n_fields = actions.shape[1]
    actions[i, 0] = move
    actions[i, 1] = mode
    actions[i, 2] = first_role
    for f in range(3, n_fields - 2):
        actions[i, f] = other_roles
    actions[i, n_fields - 2] = target
    actions[i, n_fields - 1] = value


# ---------------------------------------------------------------- picks and bit sets
@kernel
def first_bit(bits):
    """Lowest set bit of ``bits`` (a face slot), or -1 when none."""
    for k in range(12):
        if (bits >> k) & 1:
            return k
    return -1


@kernel
def random_pick(rng, pool):
    """A uniformly chosen slot of the bit set ``pool``, or -1 when empty; always draws 12 uniforms."""
    best, best_key = -1, -1.0
    for k in range(12):
        key = rng.random()
        if (pool >> k) & 1 and key > best_key:
            best, best_key = k, key
    return best


@kernel
def uniform_pick(rng, pool):
    """A uniformly chosen slot of the bit set ``pool`` (the ``n``-th set bit, ``n`` one
    ``rng.integers`` draw, as ``rng.choice`` over the slots in ascending order draws), or -1
    and no draw when empty."""
    if pool == 0:
        return -1
    nth = rng.integers(0, BIT_COUNT[pool])
    for k in range(12):
        if (pool >> k) & 1:
            if nth == 0:
                return k
            nth -= 1
    return -1


@kernel
def lowest_rolls(scent, legal):
    """``(pool, low)``: the rolls of the bit set ``legal`` whose 4 sites next to both here and the
    target (``DIRECTION_ADJACENCY``) hold the lowest of ``scent`` (12,), and that lowest value
    (the largest int64 when ``legal`` is empty)."""
    there = np.empty(12, dtype=np.int64)
    best = FAR
    for k in range(12):
        if (legal >> k) & 1:
            low = FAR
            for a in range(4):
                low = min(low, scent[DIRECTION_ADJACENCY[k, a]])
            there[k] = low
            best = min(best, low)
    pool = 0
    for k in range(12):
        if (legal >> k) & 1 and there[k] == best:
            pool |= 1 << k
    return pool, best


@kernel
def legal_bits(action_mask, i):
    """Bit set of the legal rolls of row ``i`` (``action_mask[i, k + 1]``)."""
    bits = 0
    for k in range(12):
        if action_mask[i, k + 1]:
            bits |= 1 << k
    return bits


@kernel
def kind_bits(neighbour_kind, i, kind):
    """Bit set of the face slots of row ``i`` whose site is of ``kind`` (a ``KIND_*`` code)."""
    bits = 0
    for k in range(12):
        if neighbour_kind[i, k] == kind:
            bits |= 1 << k
    return bits


@kernel
def module_bits(neighbour_kind, i):
    """Bit set of the face slots of row ``i`` that hold a module."""
    return kind_bits(neighbour_kind, i, KIND_MODULE)


@kernel
def hint_bits(hint, i):
    """``(ahead, level)`` bit sets of row ``i``: the face directions with a positive and a zero
    dot product with its ``hint`` (A, 3)."""
    ahead, level = 0, 0
    for k in range(12):
        dot = DIRECTIONS[k, 0] * hint[i, 0] + DIRECTIONS[k, 1] * hint[i, 1] + DIRECTIONS[k, 2] * hint[i, 2]
        if dot > 1e-6:
            ahead |= 1 << k
        elif dot > -1e-6:
            level |= 1 << k
    return ahead, level


@kernel
def detects_scent(own_scent, neighbour_kind, neighbour_scent, i, scent_max):
    """Row ``i`` senses the channel-0 scent: its own value or a face neighbour's is below ``scent_max``."""
    if own_scent[i, 0] < scent_max:
        return True
    for k in range(12):
        if seen_scent(neighbour_kind, neighbour_scent, i, k, scent_max) < scent_max:
            return True
    return False


@kernel
def fewest_neighbours(neighbour_kind, i, pool):
    """The directions of the bit set ``pool`` (of row ``i``) with the fewest modules in the 4
    face slots around them (:data:`AROUND_BITS`), as a bit set."""
    modules = module_bits(neighbour_kind, i)
    fewest = 99
    for k in range(12):
        if (pool >> k) & 1:
            fewest = min(fewest, BIT_COUNT[modules & AROUND_BITS[k]])
    for k in range(12):
        if (pool >> k) & 1 and BIT_COUNT[modules & AROUND_BITS[k]] != fewest:
            pool &= ~(1 << k)
    return pool


@kernel
def fewest_ruled_out(pool):
    """The slots of the bit set ``pool`` next to the fewest other slots of ``pool``
    (:data:`AROUND_BITS`), as a bit set: where a site may not touch a sibling, choosing one of
    them rules out the fewest others. Slots of one horizontal plane touch none another, so
    there ``pool`` comes back unchanged."""
    fewest = 99
    for k in range(12):
        if (pool >> k) & 1:
            fewest = min(fewest, BIT_COUNT[pool & AROUND_BITS[k]])
    kept = 0
    for k in range(12):
        if (pool >> k) & 1 and BIT_COUNT[pool & AROUND_BITS[k]] == fewest:
            kept |= 1 << k
    return kept


@kernel
def seen_scent(neighbour_kind, neighbour_scent, i, k, scent_max):
    """Channel-0 scent of the face neighbour ``k`` of row ``i`` (``scent_max`` where no module)."""
    if neighbour_kind[i, k] == KIND_MODULE:
        return np.int64(neighbour_scent[i, k, 0])
    return np.int64(scent_max)


@kernel
def downhill_bias(raw, scent_max, bias):
    """Add to ``bias`` (3,) float the downhill direction estimated from the scents ``raw`` (12,)
    seen in the face slots (``scent_max``: none): each scented slot's direction weighted by how far
    its scent lies below their mean, summed slot by slot per axis. Nothing with fewer than 2
    scented slots."""
    n, total = 0, 0
    for k in range(12):
        if raw[k] < scent_max:
            n += 1
            total += raw[k]
    if n < 2:
        return
    mean = total / n
    for axis in range(3):
        acc = 0.0
        for k in range(12):
            weight = mean - raw[k] if raw[k] < scent_max else 0.0
            acc += weight * DIRECTIONS[k, axis]
        bias[axis] += acc


@kernel
def spot_touches(neighbour_mode, i, direction, mode_bits):
    """How many of the 4 sites row ``i`` sees next to ``DIRECTIONS[direction]`` hold a module whose
    mode is in the bit set ``mode_bits``."""
    count = 0
    for j in range(4):
        m = neighbour_mode[i, DIRECTION_ADJACENCY[direction, j]]
        if m >= 0 and (mode_bits >> m) & 1:
            count += 1
    return count


# ---------------------------------------------------------------- seeding
@kernel
def growth_direction(neighbour_kind, neighbour_mode, i, rng, horizontal, previous, avoid_bits, clean):
    """A growth direction for the seed at row ``i``, from what it sees; -1 when there is none.

    Candidates are the neighbour sites that are empty (horizontal ones only when
    ``horizontal``) and whose seen neighbours (the 4 sites adjacent to both the seed and the
    spot) hold no module whose mode is in the bit set ``avoid_bits`` (e.g. FINAL, so a new
    chain site touches no earlier chain module but the seed). With ``previous`` (the
    direction the chain came in, -1 none) the straight direction is kept when it is a
    candidate, and a direction at more than 90 degrees to it is excluded. Among the rest the
    choice prefers, in order: with ``clean``, spots that touch the fewest modules besides the
    seed; spots whose opposite site holds a module (growth away from the structure); then
    uniformly at random (one ``rng.integers`` draw).
    """
    ok = 0
    for k in range(12):
        if neighbour_kind[i, k] == KIND_EMPTY:
            ok |= 1 << k
    if horizontal:
        ok &= HORIZONTAL_BITS
    if previous >= 0:
        if (ok >> previous) & 1 and spot_touches(neighbour_mode, i, previous, avoid_bits) == 0:
            return previous
        for k in range(12):
            if DOT[previous, k] < 0:
                ok &= ~(1 << k)
    pool = 0
    for k in range(12):
        if (ok >> k) & 1 and spot_touches(neighbour_mode, i, k, avoid_bits) == 0:
            pool |= 1 << k
    if pool == 0:
        return -1
    if clean:
        pool = fewest_neighbours(neighbour_kind, i, pool)
    return outward_pick(neighbour_kind, i, rng, pool)


@kernel
def outward_pick(neighbour_kind, i, rng, pool):
    """A direction of the bit set ``pool`` for the seed at row ``i``, preferring those whose
    opposite site holds a module (growth away from the structure): a uniform pick
    (:func:`uniform_pick`), -1 when ``pool`` is empty."""
    outward = 0
    for k in range(12):
        if (pool >> k) & 1 and neighbour_kind[i, OPPOSITE[k]] == KIND_MODULE:
            outward |= 1 << k
    if outward:
        pool = outward
    return uniform_pick(rng, pool)


# ---------------------------------------------------------------- directed random moves
@kernel
def approach_spot(action_mask, i, slot, growth, greedy, rng):
    """A roll of row ``i`` towards the growth spot ``DIRECTIONS[slot] + DIRECTIONS[growth]`` of
    the seed at ``slot``: straight in when it is a face site and the roll is legal, else over
    the seed's faces (with ``greedy`` only to the sites nearest the spot), a uniform pick
    (:func:`uniform_pick`); 0 when there or stuck."""
    if growth == OPPOSITE[slot]:
        return 0
    legal = legal_bits(action_mask, i)
    k = SPOT_FACE[slot, growth]
    if k >= 0 and (legal >> k) & 1:
        return k + 1
    pool = legal & AROUND_BITS[slot]
    if pool == 0:
        return 0
    if greedy:
        nearest, pool_nearest = FAR, 0
        for j in range(12):
            if (pool >> j) & 1:
                d = 0
                for axis in range(3):
                    d += (DIRECTIONS[slot, axis] + DIRECTIONS[growth, axis] - DIRECTIONS[j, axis]) ** 2
                if d < nearest:
                    nearest, pool_nearest = d, 0
                if d == nearest:
                    pool_nearest |= 1 << j
        pool = pool_nearest
    return uniform_pick(rng, pool) + 1


@kernel
def approach(rng, target, pivot, legal, greedy, p_random, moves):
    """Moves of a group of modules towards ``target`` (Q, 3) sites, rolling over the faces of
    the neighbour at slot ``pivot`` (Q,); ``legal`` (Q,) bit sets; writes ``moves`` (Q,).

    The rule: roll straight into the target when it is a face site and the roll is legal;
    otherwise roll over the pivot's faces, the rolls ending nearest the target with
    ``greedy`` (uniform among ties) or any of them; with no such roll, a uniform legal roll
    with probability ``p_random``, else stay. Draws: 12 per module; then, when ``p_random > 0``
    and some module had no roll over the pivot's faces, one per module and 12 per module.
    """
    q = target.shape[0]
    stuck_any = False
    for r in range(q):
        pool = legal[r] & AROUND_BITS[pivot[r]]
        if greedy and pool:
            nearest = FAR
            for k in range(12):
                if (pool >> k) & 1:
                    d = 0
                    for axis in range(3):
                        d += (target[r, axis] - DIRECTIONS[k, axis]) ** 2
                    nearest = min(nearest, d)
            for k in range(12):
                if (pool >> k) & 1:
                    d = 0
                    for axis in range(3):
                        d += (target[r, axis] - DIRECTIONS[k, axis]) ** 2
                    if d != nearest:
                        pool &= ~(1 << k)
        moves[r] = random_pick(rng, pool) + 1
        stuck_any |= moves[r] == 0
    if p_random > 0 and stuck_any:
        wild = np.zeros(q, dtype=np.bool_)
        for r in range(q):
            draw = rng.random()
            wild[r] = moves[r] == 0 and draw < p_random
        for r in range(q):
            pick = random_pick(rng, legal[r]) + 1
            if wild[r]:
                moves[r] = pick
    for r in range(q):
        for k in range(12):
            if (
                DIRECTIONS[k, 0] == target[r, 0]
                and DIRECTIONS[k, 1] == target[r, 1]
                and DIRECTIONS[k, 2] == target[r, 2]
            ):
                if (legal[r] >> k) & 1:
                    moves[r] = k + 1
                break


@kernel
def approach_rows(rng, group, count, target, pivot, legal, greedy, p_random, moves):
    """:func:`approach` for the ``count`` modules ``group[:count]`` (indices into the SEARCH
    group's per-module arrays ``target``, ``pivot``, ``legal``); writes their ``moves``."""
    t = np.empty((count, 3), dtype=np.int64)
    p = np.empty(count, dtype=np.int64)
    lg = np.empty(count, dtype=np.int64)
    out = np.empty(count, dtype=np.int64)
    for j in range(count):
        r = group[j]
        t[j] = target[r]
        p[j] = pivot[r]
        lg[j] = legal[r]
    approach(rng, t, p, lg, greedy, p_random, out)
    for j in range(count):
        moves[group[j]] = out[j]

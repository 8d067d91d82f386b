"""The hand-coded chain and branch rules as numba kernels over stacked observation fields.

These kernels are the one implementation of those behaviours' decisions:
:class:`~baselines.chain.ChainPolicy` and :class:`~baselines.branch.BranchPolicy` call them on
the observations the environment hands out, and :class:`baselines.compiled.CompiledRollout`
calls them inside a compiled loop with the engine.

Every kernel reads the observation fields of :mod:`proteo_env.spaces` stacked over agents
(first axis: agent row) and the module's private memory, and draws from the policy's
``numpy.random.Generator`` in the order the rule lists its draws, so the same observations,
memory and generator state give the same actions wherever the rule runs:

- a uniform pick among a set of directions draws 12 uniforms (one key per direction, the
  largest key among the set wins), also when the set has one member or none;
- a group of modules that share a step of the rule draws per step, in row order: for
  example all climbers draw their "random move?" uniform before any of them draws its pick.

Directions are bit sets over the 12 face slots (bit ``k``: ``DIRECTIONS[k]``).

Array shapes (A agents, K neighbourhood sites, C scent channels, S memory slots,
L = 4 + C action fields):

================== ========== ==================================================
``own_mode``       (A, 1)     int32
``messages``       (A, 12)    int32
``neighbour_kind`` (A, K)     int8, only the first 12 sites are read
``neighbour_mode`` (A, K)     int32
``neighbour_scent`` (A, K, C) int32, channel 0 is the chain's scent
``own_scent``      (A, C)     int32
``action_mask``    (A, 13)    int8
``slots``          (A,)       int64, memory slot of each row
``heading``        (S,)       int64, direction of the last requested move, -1 none
``growth``         (S,)       int64, growth direction of a SEED, -1 none
``asked``          (S,)       bool, asked to move last cycle
``actions``        (A, L)     int64, written
================== ========== ==================================================
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from proteo_env.core.jit import kernel
from proteo_env.core.lattice import DIRECTIONS, OPPOSITE
from proteo_env.core.world import DIRECTION_ADJACENCY, MESSAGE_TO_ALL
from proteo_env.spaces import EMIT, KIND_EMPTY, KIND_MODULE, RELAY, SILENT

SLEEP, SEARCH, SEED, FINAL = range(4)
BECOME_SEED = 13
"""Message value asking the receiver to become the new SEED (it grows on in the same direction)."""
OCTAHEDRA_OFF, OCTAHEDRA_CHAIN, OCTAHEDRA_ALL = range(3)
"""``ChainRules.avoid_octahedra``: off, when a chain module is among the 4 sites, always."""


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
EQUATOR_BITS = np.array([sum(1 << k for k in range(12) if DIRECTIONS[k, axis] == sign)
                         for axis in range(3) for sign in (1, -1)], dtype=np.int64)
"""``(6,)`` the face slots around each of the 6 octahedral holes that touch a site, as bit sets:
the hole at half a step along ``+x`` is surrounded by this module, the 4 face sites with
``x = +1`` (its "equator", all seen) and the site two steps along ``+x`` (not seen)."""
BIT_COUNT = np.array([bin(v).count("1") for v in range(1 << 12)], dtype=np.int64)
"""``BIT_COUNT[bits]``: the number of set bits of a 12-bit set."""
HORIZONTAL_BITS = sum(1 << k for k in range(12) if DIRECTIONS[k, 2] == 0)
"""The 4 face directions in the horizontal plane, as a bit set."""
DOT = DIRECTIONS @ DIRECTIONS.T
"""``(12, 12)`` dot products of the face directions (2 same, 1 at 60, 0 at 90, -1 at 120, -2 opposite)."""
_ALL = (1 << 12) - 1
_FAR = np.iinfo(np.int64).max


class ChainRules(NamedTuple):
    """The chain rule's parameters as the kernels read them (see :class:`~baselines.chain.ChainPolicy`)."""

    scent_max: int
    p_seed: float
    p_random: float
    random_when_stuck: bool
    fewer_neighbours: bool
    horizontal: bool
    clean_exit: bool
    turn: bool
    greedy_approach: bool
    wake_when_free: bool
    directed: bool
    momentum: float
    queue: bool
    prefer_chain: bool
    avoid_octahedra: int


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
    best = _FAR
    for k in range(12):
        if (legal >> k) & 1:
            low = _FAR
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
def module_bits(neighbour_kind, i):
    """Bit set of the face slots of row ``i`` that hold a module."""
    bits = 0
    for k in range(12):
        if neighbour_kind[i, k] == KIND_MODULE:
            bits |= 1 << k
    return bits


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
def seen_scent(neighbour_kind, neighbour_scent, i, k, scent_max):
    """Channel-0 scent of the face neighbour ``k`` of row ``i`` (``scent_max`` where no module)."""
    if neighbour_kind[i, k] == KIND_MODULE:
        return np.int64(neighbour_scent[i, k, 0])
    return np.int64(scent_max)


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


# ---------------------------------------------------------------- SEED
@kernel
def growth_direction(neighbour_kind, neighbour_mode, i, rng, horizontal, previous, avoid_bits, clean):
    """A growth direction for the seed at row ``i``, from what it sees; -1 when there is none.

    The rule of :func:`baselines.primitives.growth_direction` (``avoid_bits``: the modes to
    avoid as a bit set). Draws one integer (``rng.integers``) when it picks among candidates.
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
    outward = 0
    for k in range(12):
        if (pool >> k) & 1 and neighbour_kind[i, OPPOSITE[k]] == KIND_MODULE:
            outward |= 1 << k
    if outward:
        pool = outward
    return uniform_pick(rng, pool)


@kernel
def _seed_blocked(neighbour_kind, neighbour_mode, i, growth, grown_bits):
    """Can the chain not grow into ``DIRECTIONS[growth]`` from row ``i``? (solid, wall, a module
    neither SLEEP nor SEARCH there, or a module whose mode is in ``grown_bits`` seen next to the spot)"""
    kind = neighbour_kind[i, growth]
    if kind == KIND_MODULE:
        m = neighbour_mode[i, growth]
        if m != SLEEP and m != SEARCH:
            return True
    elif kind != KIND_EMPTY:
        return True
    return spot_touches(neighbour_mode, i, growth, grown_bits) > 0


@kernel
def seed_action(neighbour_kind, neighbour_mode, i, growth, fresh, rules, rng, actions):
    """Write the action of the seed at row ``i`` growing towards ``growth`` (-1: not chosen
    yet) into ``actions[i]``; return the growth it keeps in memory (-1: none).

    A seed whose growth is unknown, or blocked (with ``turn``), picks a new direction; an
    old seed (not ``fresh``) with a SLEEP or SEARCH module at its growth site promotes it
    (message ``BECOME_SEED``) and goes FINAL; otherwise it emits and broadcasts ``growth + 1``.
    """
    final_bits = 1 << FINAL
    if growth < 0 or (rules.turn and _seed_blocked(neighbour_kind, neighbour_mode, i, growth, final_bits)):
        new = growth_direction(neighbour_kind, neighbour_mode, i, rng, rules.horizontal, growth, final_bits,
                               rules.clean_exit)
        if new < 0 and rules.horizontal:  # nowhere to go in the plane: leave it
            new = growth_direction(neighbour_kind, neighbour_mode, i, rng, False, growth, final_bits,
                                   rules.clean_exit)
        if new >= 0 or growth < 0:
            growth = new
    if growth < 0:
        write_action(actions, i, 0, SEED, EMIT, EMIT, 0, 0)
        return -1
    kind, m = neighbour_kind[i, growth], neighbour_mode[i, growth]
    if (not fresh and kind == KIND_MODULE and (m == SLEEP or m == SEARCH)
            and not (rules.turn and _seed_blocked(neighbour_kind, neighbour_mode, i, growth, final_bits))):
        write_action(actions, i, 0, FINAL, RELAY, RELAY, growth, BECOME_SEED)
        return -1
    write_action(actions, i, 0, SEED, EMIT, EMIT, MESSAGE_TO_ALL, growth + 1)
    return growth


# ---------------------------------------------------------------- SEARCH
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
        nearest, pool_nearest = _FAR, 0
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
def _approach(rng, target, pivot, legal, greedy, p_random, moves):
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
            nearest = _FAR
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
            if (DIRECTIONS[k, 0] == target[r, 0] and DIRECTIONS[k, 1] == target[r, 1]
                    and DIRECTIONS[k, 2] == target[r, 2]):
                if (legal[r] >> k) & 1:
                    moves[r] = k + 1
                break


@kernel
def _approach_rows(rng, group, count, target, pivot, legal, greedy, p_random, moves):
    """:func:`_approach` for the ``count`` modules ``group[:count]`` (indices into the SEARCH
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
    _approach(rng, t, p, lg, greedy, p_random, out)
    for j in range(count):
        moves[group[j]] = out[j]


@kernel
def _climb(rng, rows, group, count, neighbour_kind, neighbour_mode, neighbour_scent, heading_dir, legal,
           rules, moves):
    """Moves of the climbers ``group[:count]`` (indices into the SEARCH group; agent rows
    ``rows[group[j]]``) along the scent gradient (the rule in :class:`~baselines.chain.ChainPolicy`).

    Per climber: the value of a legal target is one more than the smallest scent seen next
    to it; the pool is the legal rolls of the lowest value (empty, or every legal roll with
    ``random_when_stuck``, when that value is worse than here); with a bias (downhill
    estimate when ``directed``, plus ``momentum`` times the previous heading) only the pool's
    rolls with a positive dot product with it, when there are such; with
    ``fewer_neighbours`` those whose targets have the fewest modules seen around them. Draws:
    one "random legal roll instead?" uniform per climber, then a pick (12) per climber, then
    a pick (12) per climber leaving an octahedron (``avoid_octahedra``).
    """
    smax = rules.scent_max
    pools = np.empty(count, dtype=np.int64)
    raw = np.empty(12, dtype=np.int64)
    sc = np.empty(12, dtype=np.int64)
    there = np.empty(12, dtype=np.int64)
    bias = np.empty(3)
    for j in range(count):
        r = group[j]
        i = rows[r]
        lg = legal[r]
        pools[j] = 0
        if lg == 0:  # no legal roll: the pool is empty whatever the scents
            continue
        here = _FAR
        n_scented = 0
        total = 0
        for k in range(12):
            raw[k] = seen_scent(neighbour_kind, neighbour_scent, i, k, smax)
            s = raw[k]
            if raw[k] < smax:
                n_scented += 1
                total += raw[k]
            if rules.prefer_chain:  # equal scents: a chain module counts as slightly lower
                m = neighbour_mode[i, k]
                s = 2 * raw[k] + (1 if m == SEARCH or m == SLEEP else 0) if raw[k] < smax else 2 * smax
            sc[k] = s
            here = min(here, 1 + s)
        best = _FAR
        for k in range(12):
            there[k] = _FAR
            if (lg >> k) & 1:
                low = _FAR
                for a in range(4):
                    low = min(low, sc[DIRECTION_ADJACENCY[k, a]])
                there[k] = 1 + low
                best = min(best, there[k])
        pool = 0
        for k in range(12):
            if (lg >> k) & 1 and there[k] == best:
                pool |= 1 << k
        stuck = best > here
        several = (pool & (pool - 1)) != 0  # the filters below never change a pool of one
        if several and (rules.directed or rules.momentum > 0):
            # the sums run in the order of a (Q, 12) @ (12, 3) product, term by term
            bias[:] = 0.0
            if rules.directed and n_scented >= 2:
                mean = total / n_scented
                for axis in range(3):
                    acc = 0.0
                    for k in range(12):
                        weight = mean - raw[k] if raw[k] < smax else 0.0
                        acc += weight * DIRECTIONS[k, axis]
                    bias[axis] = acc
            if rules.momentum > 0 and heading_dir[r] >= 0:
                for axis in range(3):
                    bias[axis] = bias[axis] + rules.momentum * DIRECTIONS[heading_dir[r], axis]
            ahead = 0
            for k in range(12):
                if (pool >> k) & 1:
                    dot = 0.0
                    for axis in range(3):
                        dot += bias[axis] * DIRECTIONS[k, axis]
                    if dot > 0:
                        ahead |= 1 << k
            if ahead:
                pool = ahead
        if rules.fewer_neighbours and (pool & (pool - 1)) != 0:
            pool = fewest_neighbours(neighbour_kind, i, pool)
        if stuck:
            pool = lg if rules.random_when_stuck else 0
        pools[j] = pool
    for j in range(count):
        if rng.random() < rules.p_random:
            pools[j] = legal[group[j]]
    for j in range(count):
        moves[group[j]] = random_pick(rng, pools[j]) + 1
    if rules.avoid_octahedra == OCTAHEDRA_OFF:
        return
    for j in range(count):
        r = group[j]
        i = rows[r]
        if legal[r] == 0:
            continue
        modules = module_bits(neighbour_kind, i)
        chain = 0
        for k in range(12):
            m = neighbour_mode[i, k]
            if m == FINAL or m == SEED:
                chain |= 1 << k
        leave = False
        for e in range(6):
            full = (modules & EQUATOR_BITS[e]) == EQUATOR_BITS[e]
            if full and ((chain & EQUATOR_BITS[e]) != 0 or rules.avoid_octahedra == OCTAHEDRA_ALL):
                leave = True
        if leave:
            moves[r] = random_pick(rng, legal[r]) + 1


@kernel
def search_moves(rows, messages, neighbour_kind, neighbour_mode, neighbour_scent, action_mask, slots,
                 heading, asked, rules, rng, moves, send):
    """Moves ``moves`` (Q,) and growth broadcasts ``send`` (Q,) (-1: none) of the SEARCH agents
    at rows ``rows`` (Q,), each from its own observation row and memory.

    ``neighbour_mode`` is the modes as the chain rule reads them (the branch policy passes
    NODE as SEED and INODE as FINAL). The steps, in order: modules next to a SEED hold
    still at the growth spot or until they heard the growth; with ``queue`` modules hold
    still next to a module holding a spot; modules next to a seed roll over its faces to a
    free spot; with ``queue`` modules follow a holder's broadcast to the spot ahead (or wait
    a cycle when they moved since hearing it); modules next to a seed whose spot is taken
    round the seed; the others climb the gradient.
    """
    q = rows.shape[0]
    todo = np.ones(q, dtype=np.bool_)
    near = np.zeros(q, dtype=np.bool_)
    seed_slot = np.full(q, -1, dtype=np.int64)
    growth = np.full(q, -1, dtype=np.int64)
    spot_taken = np.zeros(q, dtype=np.bool_)
    holders = np.zeros(q, dtype=np.int64)
    still = np.zeros(q, dtype=np.bool_)
    legal = np.empty(q, dtype=np.int64)
    target = np.zeros((q, 3), dtype=np.int64)
    pivot = np.zeros(q, dtype=np.int64)
    group = np.empty(q, dtype=np.int64)
    for r in range(q):
        i = rows[r]
        moves[r] = 0
        send[r] = -1
        legal[r] = legal_bits(action_mask, i)
        growth_msgs = 0
        for k in range(12):
            v = messages[i, k]
            if 1 <= v <= 12:
                growth_msgs |= 1 << k
        for k in range(12):
            if neighbour_mode[i, k] == SEED:
                seed_slot[r] = k
                break
        near[r] = seed_slot[r] >= 0
        heard_slot = first_bit(growth_msgs)
        if heard_slot >= 0:  # the seed's growth: the value does not go stale, only the side may
            growth[r] = messages[i, heard_slot] - 1
        g = growth[r]
        at_spot = near[r] and g >= 0 and seed_slot[r] == OPPOSITE[g]
        if near[r] and (g < 0 or at_spot):  # at the spot, or growth not heard yet
            todo[r] = False
        if rules.queue and at_spot:
            send[r] = g
        if near[r] and g >= 0:
            face = SPOT_FACE[seed_slot[r], g]
            spot_taken[r] = face >= 0 and neighbour_kind[i, face] == KIND_MODULE
        if rules.queue:
            # a SEARCH neighbour broadcasting a growth holds a spot; its side is only trusted
            # when this module asked for no move last cycle (so it has not moved since)
            still[r] = not asked[slots[i]]
            at_pre = -1
            for k in range(12):
                if (growth_msgs >> k) & 1 and neighbour_mode[i, k] == SEARCH:
                    if still[r]:
                        holders[r] |= 1 << k
                        if at_pre < 0 and k == OPPOSITE[messages[i, k] - 1]:
                            at_pre = k
            if todo[r] and at_pre >= 0:
                send[r] = messages[i, at_pre] - 1
                todo[r] = False

    count = 0
    for r in range(q):  # next to a seed: roll over its faces to the free spot
        if todo[r] and near[r] and not spot_taken[r]:
            group[count] = r
            count += 1
            target[r] = DIRECTIONS[seed_slot[r]] + DIRECTIONS[growth[r]]
            pivot[r] = seed_slot[r]
            todo[r] = False
    _approach_rows(rng, group, count, target, pivot, legal, rules.greedy_approach, rules.p_random, moves)

    if rules.queue:
        count = 0
        for r in range(q):  # follow a holder to the spot ahead of it
            if not (todo[r] and holders[r]):
                continue
            i = rows[r]
            free = 0
            for k in range(12):
                if (holders[r] >> k) & 1:
                    face = SPOT_FACE[k, messages[i, k] - 1]
                    if face < 0 or neighbour_kind[i, face] == KIND_EMPTY:  # out of sight: try it
                        free |= 1 << k
            pick = first_bit(free) if free else first_bit(holders[r])
            ahead = messages[i, pick] - 1
            steps = 1 if (free >> pick) & 1 else 2
            target[r] = DIRECTIONS[pick] + DIRECTIONS[ahead] * steps
            pivot[r] = pick
            group[count] = r
            count += 1
            todo[r] = False
        _approach_rows(rng, group, count, target, pivot, legal, rules.greedy_approach, rules.p_random, moves)
        for r in range(q):  # heard a holder but cannot trust the side: wait a cycle
            if todo[r] and not still[r]:
                i = rows[r]
                for k in range(12):
                    if 1 <= messages[i, k] <= 12 and neighbour_mode[i, k] == SEARCH:
                        todo[r] = False
                        break

    count = 0
    for r in range(q):  # spot taken, no holder to follow: round the seed
        if todo[r] and near[r]:
            group[count] = r
            count += 1
            target[r] = DIRECTIONS[seed_slot[r]] + DIRECTIONS[growth[r]]
            pivot[r] = seed_slot[r]
        if near[r]:
            todo[r] = False
    _approach_rows(rng, group, count, target, pivot, legal, rules.greedy_approach, rules.p_random, moves)

    count = 0
    heading_dir = np.empty(q, dtype=np.int64)
    for r in range(q):
        if todo[r]:
            group[count] = r
            count += 1
        heading_dir[r] = heading[slots[rows[r]]]
    _climb(rng, rows, group, count, neighbour_kind, neighbour_mode, neighbour_scent, heading_dir, legal, rules,
           moves)


@kernel
def search_actions(rows, messages, neighbour_kind, neighbour_mode, neighbour_scent, action_mask, slots,
                   heading, asked, rules, rng, actions):
    """:func:`search_moves` written into ``actions`` (move, and a growth broadcast to all), and
    the SEARCH agents' memory updated (``heading`` and ``asked`` of each requested move)."""
    q = rows.shape[0]
    moves = np.empty(q, dtype=np.int64)
    send = np.empty(q, dtype=np.int64)
    search_moves(rows, messages, neighbour_kind, neighbour_mode, neighbour_scent, action_mask, slots,
                 heading, asked, rules, rng, moves, send)
    n_fields = actions.shape[1]
    for r in range(q):
        i = rows[r]
        actions[i, 0] = moves[r]
        if send[r] >= 0:
            actions[i, n_fields - 2] = MESSAGE_TO_ALL
            actions[i, n_fields - 1] = send[r] + 1
        s = slots[i]
        if moves[r] > 0:
            heading[s] = moves[r] - 1
            asked[s] = True
        else:
            asked[s] = False


# ---------------------------------------------------------------- the whole decision
@kernel
def chain_actions(own_mode, messages, neighbour_kind, neighbour_mode, neighbour_scent, own_scent, action_mask,
                  slots, heading, growth, asked, rules, rng, actions):
    """Every agent's action under the chain rule (shapes in the module docstring).

    In order: defaults (stay, keep the mode, relay every channel, no message); modules
    asked to become a seed (a ``BECOME_SEED`` message, when SLEEP or SEARCH) become a fresh
    seed growing on straight; SEEDs act as seeds; SLEEP modules wake (SEARCH) when they or
    a neighbour carry scent (and, with ``wake_when_free``, have a legal roll), and with
    ``p_seed`` one that detects no scent becomes a seed with that probability; SEARCH
    modules act by :func:`search_actions`; FINAL modules forget their heading.
    """
    n_agents = own_mode.shape[0]
    smax = rules.scent_max
    promoted = np.full(n_agents, -1, dtype=np.int64)
    for i in range(n_agents):
        own = own_mode[i, 0]
        write_action(actions, i, 0, own, RELAY, RELAY, 0, 0)
        if own == SLEEP or own == SEARCH:
            for k in range(12):
                if messages[i, k] == BECOME_SEED:
                    promoted[i] = k
                    break
    for i in range(n_agents):
        if promoted[i] >= 0:
            growth[slots[i]] = seed_action(neighbour_kind, neighbour_mode, i, OPPOSITE[promoted[i]], True, rules,
                                           rng, actions)
    for i in range(n_agents):
        if own_mode[i, 0] == SEED:
            growth[slots[i]] = seed_action(neighbour_kind, neighbour_mode, i, growth[slots[i]], False, rules,
                                           rng, actions)
    n_search = 0
    for i in range(n_agents):
        own = own_mode[i, 0]
        if promoted[i] >= 0:
            continue
        if own == SEARCH:
            n_search += 1
        elif own == SLEEP:
            if detects_scent(own_scent, neighbour_kind, neighbour_scent, i, smax):
                if not rules.wake_when_free or legal_bits(action_mask, i):
                    actions[i, 1] = SEARCH
            elif rules.p_seed > 0 and rng.random() < rules.p_seed:
                growth[slots[i]] = seed_action(neighbour_kind, neighbour_mode, i, -1, True, rules, rng, actions)
        elif own == FINAL:
            heading[slots[i]] = -1
            asked[slots[i]] = False
    search = np.empty(n_search, dtype=np.int64)
    n_search = 0
    for i in range(n_agents):
        if own_mode[i, 0] == SEARCH and promoted[i] < 0:
            search[n_search] = i
            n_search += 1
    search_actions(search, messages, neighbour_kind, neighbour_mode, neighbour_scent, action_mask, slots,
                   heading, asked, rules, rng, actions)


# ---------------------------------------------------------------- the branch rule
NODE, INODE = 4, 5
REFUSE = 14
"""Message value: "I will not become your seed: I touch another part of the tree"."""
GROWN_BITS = (1 << SEED) | (1 << FINAL) | (1 << NODE) | (1 << INODE)
"""The modes of the grown tree (SEED, FINAL, NODE, INODE), as a bit set."""
NO_COUNT = np.iinfo(np.int64).min
"""``spawned`` of a module that has no count (a count may go below 0 when seeds refuse)."""


class BranchRules(NamedTuple):
    """The branch rule's own parameters as the kernels read them (see :class:`~baselines.branch.BranchPolicy`)."""

    T: int
    B: int
    p_node: float
    search_relays_node: bool
    refuse: bool
    patience: int


@kernel
def branch_seed_action(neighbour_kind, neighbour_mode, i, growth, fresh, previous, refused, rules, rng, actions):
    """Write the action of the branch seed at row ``i`` into ``actions[i]``; return the growth it
    keeps in memory (-1: none).

    The chain's seed (:func:`seed_action`) with the tree's modes (SEED, FINAL, NODE, INODE) as
    the structure to keep away from, the bit set ``refused`` of directions whose module refused
    to become a seed (never chosen again), ``previous`` as the direction it came in when
    ``growth`` is unknown, and no second, non-horizontal try.
    """
    known = growth >= 0
    if (not known or (refused >> growth) & 1
            or (rules.turn and _seed_blocked(neighbour_kind, neighbour_mode, i, growth, GROWN_BITS))):
        new = growth_direction(neighbour_kind, neighbour_mode, i, rng, rules.horizontal,
                               growth if known else previous, GROWN_BITS, rules.clean_exit)
        if new >= 0 and (refused >> new) & 1:
            new = -1
        if new >= 0 or not known or (refused >> growth) & 1:
            growth = new
    if growth < 0:
        write_action(actions, i, 0, SEED, EMIT, RELAY, 0, 0)
        return -1
    kind, m = neighbour_kind[i, growth], neighbour_mode[i, growth]
    if (not fresh and kind == KIND_MODULE and (m == SLEEP or m == SEARCH)
            and not (rules.turn and _seed_blocked(neighbour_kind, neighbour_mode, i, growth, GROWN_BITS))):
        write_action(actions, i, 0, FINAL, RELAY, RELAY, growth, BECOME_SEED)
        return -1
    write_action(actions, i, 0, SEED, EMIT, RELAY, MESSAGE_TO_ALL, growth + 1)
    return growth


@kernel
def _spot_free(neighbour_kind, neighbour_mode, i, k):
    """Can a new branch start at the face site ``k`` of row ``i``? It holds no grown module and the
    sites seen next to it hold none."""
    kind = neighbour_kind[i, k]
    if kind == KIND_MODULE:
        m = neighbour_mode[i, k]
        if m >= 0 and (GROWN_BITS >> m) & 1:
            return False
    elif kind != KIND_EMPTY:
        return False
    return spot_touches(neighbour_mode, i, k, GROWN_BITS) == 0


@kernel
def _retire(s, spawned, spot_direction, spot_announced, spot_waited, refused):
    """Forget a node's memory at slot ``s`` (it goes INODE)."""
    spawned[s] = NO_COUNT
    spot_direction[s] = -1
    spot_announced[s] = False
    spot_waited[s] = 0
    refused[s] = 0


@kernel
def node_action(neighbour_kind, neighbour_mode, i, s, spawned, spot_direction, spot_announced, spot_waited, refused,
                rules, branch, rng, actions):
    """Write the action of the NODE at row ``i`` (memory slot ``s``) into ``actions[i]``.

    It keeps the number of seeds spawned (``spawned``, :data:`NO_COUNT`: none yet) and its current growth
    spot (direction, announced last cycle, cycles waited; direction -1: none). A spot that is
    no longer free, or has stayed empty for ``patience`` cycles, is replaced by a uniform
    choice among the free face sites (horizontal ones with ``horizontal``) it has not been
    refused (one ``rng.integers`` draw). A SLEEP module at the spot, or a SEARCH one that has
    heard the spot announced, gets ``BECOME_SEED``; after ``B`` seeds, or with no free site
    left, the node goes INODE. Otherwise it announces the spot (message ``direction + 1``).
    """
    count = spawned[s] if spawned[s] != NO_COUNT else 0
    if count >= branch.B:
        _retire(s, spawned, spot_direction, spot_announced, spot_waited, refused)
        write_action(actions, i, 0, INODE, RELAY, EMIT, 0, 0)
        return
    direction, announced, waited = spot_direction[s], spot_announced[s], spot_waited[s]
    if (direction < 0 or not _spot_free(neighbour_kind, neighbour_mode, i, direction)
            or (neighbour_kind[i, direction] != KIND_MODULE and waited >= branch.patience)):
        allowed = HORIZONTAL_BITS if rules.horizontal else _ALL
        pool = 0
        for k in range(12):
            if (allowed >> k) & 1 and not (refused[s] >> k) & 1 and _spot_free(neighbour_kind, neighbour_mode, i, k):
                pool |= 1 << k
        if pool == 0:
            _retire(s, spawned, spot_direction, spot_announced, spot_waited, refused)
            write_action(actions, i, 0, INODE, RELAY, EMIT, 0, 0)
            return
        new = uniform_pick(rng, pool)
        announced = announced and new == direction
        direction, waited = new, 0
    spawned[s] = count
    kind, m = neighbour_kind[i, direction], neighbour_mode[i, direction]
    if kind == KIND_MODULE and (m == SLEEP or (m == SEARCH and announced)):
        spawned[s] = count + 1
        spot_direction[s] = -1
        spot_announced[s] = False
        spot_waited[s] = 0
        if count + 1 >= branch.B:  # the last seed: go INODE in the same action
            write_action(actions, i, 0, INODE, RELAY, EMIT, direction, BECOME_SEED)
        else:
            write_action(actions, i, 0, NODE, EMIT, EMIT, direction, BECOME_SEED)
        return
    spot_direction[s] = direction
    spot_announced[s] = True
    spot_waited[s] = waited + 1
    write_action(actions, i, 0, NODE, EMIT, EMIT, MESSAGE_TO_ALL, direction + 1)


@kernel
def branch_actions(own_mode, messages, neighbour_kind, neighbour_mode, neighbour_scent, own_scent, action_mask,
                   slots, heading, growth, asked, spawned, spot_direction, spot_announced, spot_waited, refused,
                   rules, branch, rng, actions):
    """Every agent's action under the branch rule (:class:`~baselines.branch.BranchPolicy`).

    Shapes as in the module docstring, two scent channels (0 regular, 1 node); the branch
    memory (S,): ``spawned``, ``spot_direction``, ``spot_announced``, ``spot_waited`` (see
    :func:`node_action`) and ``refused`` (bit set of refused directions). In order: defaults;
    modules asked to become a seed refuse (``REFUSE`` to the sender, with ``refuse``, when they
    touch a grown module other than the sender) or become a fresh seed; a FINAL module whose
    seed refused becomes a seed again; a NODE or INODE whose seed refused counts one seed
    fewer; SEEDs act; SLEEP modules are silent on the node scent and wake on regular scent
    (with ``p_node`` one that detects none becomes a NODE); FINAL modules with a known node
    scent above ``T`` and no NODE or INODE next to them become NODEs; NODEs (and INODEs whose
    seed refused) act as nodes, INODEs emit the node scent; SEARCH modules act as the chain's,
    seeing a NODE as a SEED and an INODE as FINAL; grown modules forget their heading.
    """
    n_agents = own_mode.shape[0]
    smax = rules.scent_max
    promoted = np.full(n_agents, -1, dtype=np.int64)
    refused_from = np.full(n_agents, -1, dtype=np.int64)
    for i in range(n_agents):
        own = own_mode[i, 0]
        write_action(actions, i, 0, own, RELAY, RELAY, 0, 0)
        for k in range(12):
            if messages[i, k] == REFUSE:
                refused_from[i] = k
                break
        if own == SLEEP or own == SEARCH:
            for k in range(12):
                if messages[i, k] == BECOME_SEED:
                    promoted[i] = k
                    break
    for i in range(n_agents):
        if promoted[i] < 0:
            continue
        if branch.refuse:
            touches_tree = False
            for k in range(12):
                m = neighbour_mode[i, k]
                if (k != promoted[i] and neighbour_kind[i, k] == KIND_MODULE and m >= 0
                        and (GROWN_BITS >> m) & 1):
                    touches_tree = True
            if touches_tree:  # joining would touch another part of the tree
                actions[i, actions.shape[1] - 2] = promoted[i]
                actions[i, actions.shape[1] - 1] = REFUSE
                promoted[i] = -2  # neither a seed nor moving this cycle
                continue
        growth[slots[i]] = branch_seed_action(neighbour_kind, neighbour_mode, i, OPPOSITE[promoted[i]], True, -1,
                                              refused[slots[i]], rules, rng, actions)
    for i in range(n_agents):  # the seed it made refused: seed again
        if refused_from[i] >= 0 and own_mode[i, 0] == FINAL:
            s = slots[i]
            refused[s] |= 1 << refused_from[i]
            growth[s] = branch_seed_action(neighbour_kind, neighbour_mode, i, -1, True, refused_from[i], refused[s],
                                           rules, rng, actions)
    for i in range(n_agents):  # a node's seed refused: one seed fewer
        own = own_mode[i, 0]
        if refused_from[i] >= 0 and (own == NODE or own == INODE):
            s = slots[i]
            refused[s] |= 1 << refused_from[i]
            spawned[s] = min(spawned[s] if spawned[s] != NO_COUNT else branch.B, branch.B) - 1
            spot_direction[s] = -1
            spot_announced[s] = False
            spot_waited[s] = 0
    for i in range(n_agents):
        if own_mode[i, 0] == SEED:
            s = slots[i]
            growth[s] = branch_seed_action(neighbour_kind, neighbour_mode, i, growth[s], False, -1, refused[s], rules,
                                           rng, actions)
    for i in range(n_agents):
        if own_mode[i, 0] != SLEEP or promoted[i] != -1:
            continue
        actions[i, 3] = SILENT
        if detects_scent(own_scent, neighbour_kind, neighbour_scent, i, smax):
            if not rules.wake_when_free or legal_bits(action_mask, i):
                actions[i, 1] = SEARCH
        elif branch.p_node > 0 and rng.random() < branch.p_node:
            node_action(neighbour_kind, neighbour_mode, i, slots[i], spawned, spot_direction, spot_announced,
                        spot_waited, refused, rules, branch, rng, actions)
    for i in range(n_agents):  # FINAL: a weak node scent (known, > T) with no node next to it: go NODE
        if own_mode[i, 0] != FINAL or refused_from[i] >= 0:
            continue
        node_scent = own_scent[i, 1]
        near_node = False
        for k in range(12):
            m = neighbour_mode[i, k]
            near_node |= m == NODE or m == INODE
        if node_scent > branch.T and node_scent < smax and not near_node:
            node_action(neighbour_kind, neighbour_mode, i, slots[i], spawned, spot_direction, spot_announced,
                        spot_waited, refused, rules, branch, rng, actions)
    for i in range(n_agents):
        own = own_mode[i, 0]
        if own == NODE or (own == INODE and refused_from[i] >= 0):
            node_action(neighbour_kind, neighbour_mode, i, slots[i], spawned, spot_direction, spot_announced,
                        spot_waited, refused, rules, branch, rng, actions)
        elif own == INODE:
            actions[i, 3] = EMIT
    n_search = 0
    for i in range(n_agents):
        if own_mode[i, 0] == SEARCH and promoted[i] == -1:
            n_search += 1
    search = np.empty(n_search, dtype=np.int64)
    n_search = 0
    for i in range(n_agents):
        if own_mode[i, 0] == SEARCH and promoted[i] == -1:
            search[n_search] = i
            n_search += 1
            if not branch.search_relays_node:
                actions[i, 3] = SILENT
    seen = neighbour_mode.copy()  # a NODE is a seed to approach, an INODE part of the chain
    for i in range(n_agents):
        for k in range(12):
            if seen[i, k] == NODE:
                seen[i, k] = SEED
            elif seen[i, k] == INODE:
                seen[i, k] = FINAL
    search_actions(search, messages, neighbour_kind, seen, neighbour_scent, action_mask, slots, heading, asked, rules,
                   rng, actions)
    for i in range(n_agents):
        if own_mode[i, 0] >= FINAL:
            heading[slots[i]] = -1
            asked[slots[i]] = False

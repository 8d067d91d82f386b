"""The hand-coded chain rule as numba kernels over stacked observation fields.

These kernels are the one implementation of those behaviours' decisions:
   :class:`~baselines.chain.ChainPolicy` calls them on
the observations the environment hands out, and :class:`baselines.compiled.CompiledRollout`
calls them inside a compiled loop with the engine; the branch rule
(:mod:`baselines.branch_rules`) builds on them. Shared primitives: :mod:`baselines.primitives`.

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
from proteo_env.spaces import EMIT, KIND_EMPTY, KIND_MODULE, RELAY
from proteo_env.tasks.chain import FINAL, SEARCH, SEED, SLEEP

from .primitives import (
    EQUATOR_BITS,
    FAR,
    SPOT_FACE,
    approach_rows,
    detects_scent,
    downhill_bias,
    fewest_neighbours,
    first_bit,
    growth_direction,
    legal_bits,
    module_bits,
    random_pick,
    seen_scent,
    spot_touches,
    write_action,
)

BECOME_SEED = 13
"""Message value asking the receiver to become the new SEED (it grows on in the same direction)."""
OCTAHEDRA_OFF, OCTAHEDRA_CHAIN, OCTAHEDRA_ALL = range(3)
"""``ChainRuleParams.avoid_octahedra``: off, when a chain module is among the 4 sites, always."""


class ChainRuleParams(NamedTuple):
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


# ---------------------------------------------------------------- SEED
@kernel
def seed_blocked(neighbour_kind, neighbour_mode, i, growth, grown_bits):
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
    if growth < 0 or (rules.turn and seed_blocked(neighbour_kind, neighbour_mode, i, growth, final_bits)):
        new = growth_direction(
            neighbour_kind, neighbour_mode, i, rng, rules.horizontal, growth, final_bits, rules.clean_exit
        )
        if new < 0 and rules.horizontal:  # nowhere to go in the plane: leave it
            new = growth_direction(neighbour_kind, neighbour_mode, i, rng, False, growth, final_bits, rules.clean_exit)
        if new >= 0 or growth < 0:
            growth = new
    if growth < 0:
        write_action(actions, i, 0, SEED, EMIT, EMIT, 0, 0)
        return -1
    kind, m = neighbour_kind[i, growth], neighbour_mode[i, growth]
    if (
        not fresh
        and kind == KIND_MODULE
        and (m == SLEEP or m == SEARCH)
        and not (rules.turn and seed_blocked(neighbour_kind, neighbour_mode, i, growth, final_bits))
    ):
        write_action(actions, i, 0, FINAL, RELAY, RELAY, growth, BECOME_SEED)
        return -1
    write_action(actions, i, 0, SEED, EMIT, EMIT, MESSAGE_TO_ALL, growth + 1)
    return growth


# ---------------------------------------------------------------- SEARCH
@kernel
def _climb(rng, rows, group, count, neighbour_kind, neighbour_mode, neighbour_scent, heading_dir, legal, rules, moves):
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
        here = FAR
        for k in range(12):
            raw[k] = seen_scent(neighbour_kind, neighbour_scent, i, k, smax)
            s = raw[k]
            if rules.prefer_chain:  # equal scents: a chain module counts as slightly lower
                m = neighbour_mode[i, k]
                s = 2 * raw[k] + (1 if m == SEARCH or m == SLEEP else 0) if raw[k] < smax else 2 * smax
            sc[k] = s
            here = min(here, 1 + s)
        best = FAR
        for k in range(12):
            there[k] = FAR
            if (lg >> k) & 1:
                low = FAR
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
            if rules.directed:
                downhill_bias(raw, smax, bias)
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
def search_moves(
    rows,
    messages,
    neighbour_kind,
    neighbour_mode,
    neighbour_scent,
    action_mask,
    slots,
    heading,
    asked,
    rules,
    rng,
    moves,
    send,
):
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
    approach_rows(rng, group, count, target, pivot, legal, rules.greedy_approach, rules.p_random, moves)

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
        approach_rows(rng, group, count, target, pivot, legal, rules.greedy_approach, rules.p_random, moves)
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
    approach_rows(rng, group, count, target, pivot, legal, rules.greedy_approach, rules.p_random, moves)

    count = 0
    heading_dir = np.empty(q, dtype=np.int64)
    for r in range(q):
        if todo[r]:
            group[count] = r
            count += 1
        heading_dir[r] = heading[slots[rows[r]]]
    _climb(rng, rows, group, count, neighbour_kind, neighbour_mode, neighbour_scent, heading_dir, legal, rules, moves)


@kernel
def search_actions(
    rows,
    messages,
    neighbour_kind,
    neighbour_mode,
    neighbour_scent,
    action_mask,
    slots,
    heading,
    asked,
    rules,
    rng,
    actions,
):
    """:func:`search_moves` written into ``actions`` (move, and a growth broadcast to all), and
    the SEARCH agents' memory updated (``heading`` and ``asked`` of each requested move)."""
    q = rows.shape[0]
    moves = np.empty(q, dtype=np.int64)
    send = np.empty(q, dtype=np.int64)
    search_moves(
        rows,
        messages,
        neighbour_kind,
        neighbour_mode,
        neighbour_scent,
        action_mask,
        slots,
        heading,
        asked,
        rules,
        rng,
        moves,
        send,
    )
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
def chain_actions(
    own_mode,
    messages,
    neighbour_kind,
    neighbour_mode,
    neighbour_scent,
    own_scent,
    action_mask,
    slots,
    heading,
    growth,
    asked,
    rules,
    rng,
    actions,
):
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
            growth[slots[i]] = seed_action(
                neighbour_kind, neighbour_mode, i, OPPOSITE[promoted[i]], True, rules, rng, actions
            )
    for i in range(n_agents):
        if own_mode[i, 0] == SEED:
            growth[slots[i]] = seed_action(
                neighbour_kind, neighbour_mode, i, growth[slots[i]], False, rules, rng, actions
            )
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
    search_actions(
        search,
        messages,
        neighbour_kind,
        neighbour_mode,
        neighbour_scent,
        action_mask,
        slots,
        heading,
        asked,
        rules,
        rng,
        actions,
    )


@kernel
def chain_decide(seen, slots, memory, rules, rng, actions):
    """:func:`chain_actions` as a policy's ``rule`` (:attr:`baselines.base.KernelPolicy.rule`):
    ``memory`` is ``(heading, growth, asked)``, ``rules`` a :class:`ChainRuleParams`."""
    heading, growth, asked = memory
    chain_actions(
        seen.own_mode,
        seen.messages,
        seen.neighbour_kind,
        seen.neighbour_mode,
        seen.neighbour_scent,
        seen.own_scent,
        seen.action_mask,
        slots,
        heading,
        growth,
        asked,
        rules,
        rng,
        actions,
    )

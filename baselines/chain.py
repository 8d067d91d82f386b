"""The paper's chain behaviour (section 4.1) as a policy over observations.

Rules, as the paper lists them (modes SLEEP, SEARCH, SEED, FINAL):

- If in SLEEP mode, if a scent is detected, go to SEARCH mode.
- If in SEARCH mode, propagate scent and move along scent gradient.
- If in SEED mode, emit scent, and if a module has appeared in the direction of growth,
  set that module to SEED mode, and go to FINAL mode.
- If in FINAL mode, propagate scent.

How each rule is carried out through the agent interface (one module's observation in,
one action out, plus the module's own private memory; nothing else is read):

- SLEEP: relays scent (so that it spreads through the blob) and goes to SEARCH when it or a
  neighbour carries scent. With ``wake_when_free`` it waits in SLEEP until it also has a
  legal move. With ``p_seed > 0`` a SLEEP module that detects no scent becomes a SEED with
  that probability each cycle (the paper's decentralised start; the task's default is one
  seed picked centrally).
- SEARCH, "move along scent gradient" (``_climb``): the value of a
  site is one more than the smallest scent next to it. A module sees only 4 of a target
  site's neighbours (those next to both sites), so no single roll is ever *seen* to lower its
  value; the gradient says which neighbour is lowest and the module rolls over that
  neighbour's faces (rolls that keep touching it) until it touches a lower one: the paper's
  "moves randomly over the available faces of its neighbor until it encounters the module"
  with a smaller value. Among those rolls it uses the paper's *directed* random move: only
  rolls with a positive dot product with a direction, here the downhill direction estimated
  from its neighbours' scents plus ``momentum`` times its own previous roll (``directed``,
  ``momentum``). With ``prefer_chain`` a FINAL or SEED neighbour counts as lower than a
  SEARCH or SLEEP neighbour of equal scent, so modules travel along the chain rather than
  ride on other travellers. When every legal roll would lose the lowest neighbour it stays
  (``on_stuck``); with probability ``p_random`` it makes a uniformly random legal roll
  instead (the paper's randomness against getting stuck). It relays scent throughout.
  With ``avoid_octahedra`` a climber that sees the 4 sites round one of its octahedral holes
  all taken, one of them by a chain module, makes a random legal roll instead: the sixth
  module to fill such an octahedron (2 chain modules of a link and 4 travellers in its
  crooks) would lock it for good, since no member of an isolated octahedron can roll under
  ``sphere``, ``rounded`` or ``rhombic``; this was the last failure seen under those models.
- SEARCH next to a SEED (seen by the neighbour's mode, so its side is known now): it rolls
  over the seed's faces to the growth spot, ``DIRECTIONS[seed side] + DIRECTIONS[growth]``,
  with the growth heard from the seed's broadcast (the value does not go stale when the
  module has moved, only the side it came from would). It holds still when it is at the
  spot or has not heard the growth yet, so the module the seed promotes is still at the
  spot when the promotion lands (messages are delivered before the cycle's moves). With no
  roll over the seed's faces it makes a random legal roll with probability ``p_random``.
  With ``queue`` a module holding the spot also broadcasts the growth, and modules next to
  it (that asked for no move last cycle, so the side is fresh) queue at the next spot ahead.
- SEED: emits scent and broadcasts its growth direction to all neighbours every cycle
  (message ``growth + 1``). "A module has appeared in the direction of growth" is read from
  the seed's own neighbour site there: a SLEEP or SEARCH module. "Set that module to SEED
  mode" is the message ``BECOME_SEED`` sent to that site; the seed goes FINAL in the same
  action. The receiver becomes SEED next cycle and grows on in the same direction (the
  message arrived from the opposite side). A fresh seed promotes nobody in its first cycle,
  so the module at its spot has heard where the spot is and holds still.
  The first seed picks its direction from what it sees
  (:func:`~baselines.primitives.growth_direction`): an empty horizontal site (when
  ``horizontal``) that touches the fewest modules, preferring one with a module opposite
  (``clean_exit``), so the chain leaves the blob. With ``turn``, a seed whose growth site is
  blocked (solid, the box wall, a FINAL module, or a site touching a FINAL module other
  than itself, which would make the chain two modules thick) picks a new direction at most
  90 degrees from the old one whose site touches no FINAL module it can see.
- FINAL: relays scent and never moves.

The rules run as the numba kernel :func:`chain_actions` (the policy's ``rule``) on the
observation fields stacked over modules, here and in the compiled rollout
(:mod:`baselines.compiled`); the private memory is one row per module (:class:`ModuleMemory`);
the branch rule (:mod:`baselines.branch`) builds on the SEARCH and seed kernels. Shared
primitives: :mod:`baselines.primitives`.

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

from .base import KernelPolicy, SlotMemory
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
STUCK_STAY, STUCK_RANDOM = range(2)
"""``ChainRuleParams.on_stuck`` as the kernels read it: ``"stay"``, ``"random"``."""
OCTAHEDRA_OFF, OCTAHEDRA_CHAIN, OCTAHEDRA_ALL = range(3)
"""``ChainRuleParams.avoid_octahedra`` as the kernels read it: ``False`` (off), ``True`` (when a
chain module is among the 4 sites), ``"all"`` (always)."""


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
    ``on_stuck`` random, when that value is worse than here); with a bias (downhill
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
            pool = lg if rules.on_stuck == STUCK_RANDOM else 0
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
def chain_actions(seen, slots, memory, rules, rng, actions):
    """Every agent's action under the chain rule: the policy's ``rule``
    (:attr:`baselines.base.KernelPolicy.rule`; ``memory`` is ``(heading, growth, asked)``,
    shapes in the module docstring).

    In order: defaults (stay, keep the mode, relay every channel, no message); modules
    asked to become a seed (a ``BECOME_SEED`` message, when SLEEP or SEARCH) become a fresh
    seed growing on straight; SEEDs act as seeds; SLEEP modules wake (SEARCH) when they or
    a neighbour carry scent (and, with ``wake_when_free``, have a legal roll), and with
    ``p_seed`` one that detects no scent becomes a seed with that probability; SEARCH
    modules act by :func:`search_actions`; FINAL modules forget their heading.
    """
    own_mode, messages, own_scent, action_mask = seen.own_mode, seen.messages, seen.own_scent, seen.action_mask
    neighbour_kind, neighbour_mode, neighbour_scent = seen.neighbour_kind, seen.neighbour_mode, seen.neighbour_scent
    heading, growth, asked = memory
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


class ChainRuleParams(NamedTuple):
    """The chain rule's parameters, :class:`ChainPolicy`'s keywords (``scent_max``: the scent
    value that means "no scent").

    Attributes:
        p_seed: per-cycle probability that a SLEEP module with no scent around becomes a SEED
            (0: rely on the task's central seed).
        p_random: probability that a SEARCH module makes a uniformly random legal move instead
            of following the gradient (the paper's randomness against getting stuck).
        on_stuck: what a SEARCH module does when every legal roll would lose its lowest
            neighbour (the gradient says "worse" everywhere): ``"stay"`` or ``"random"``.
        directed: wander among equal-value rolls only in directions with a positive dot
            product with the local downhill direction (estimated from the neighbours' scents)
            plus ``momentum`` times the module's previous move, when there are such rolls
            (the paper's "directed random move").
        momentum: weight of the previous move in that direction (0: none).
        prefer_chain: a FINAL or SEED neighbour counts as slightly lower than a SEARCH or
            SLEEP neighbour of the same scent.
        queue: modules holding a seed's growth spot broadcast the growth so that others
            queue at the spot ahead (see the module docstring).
        avoid_octahedra: a climber that sees all 4 sites round one of its octahedral holes
            taken, one of them by a FINAL or SEED module, takes a random legal roll instead
            of the gradient's (``"all"``: also when no chain module is among them).
        fewer_neighbours: among equally good gradient moves prefer targets next to fewer
            modules (of the 4 seen there). Only ``minimal`` allows rolls whose target has more
            than the pivot seen next to it, so under the other models this changes nothing.
        horizontal: seeds grow along the 4 horizontal directions only (the task's box is
            roomy horizontally, tight vertically).
        clean_exit: the first seed prefers a growth site that touches few other modules.
        turn: a seed whose growth site is blocked (solid, wall, FINAL module, or touching a
            FINAL module) turns to a free direction.
        greedy_approach: next to a seed, roll over its faces towards the growth spot rather
            than at random. A module next to a seed with no roll over the seed's faces makes
            a random legal move with probability ``p_random`` (so crowds around the seed
            cannot jam for ever).
        wake_when_free: a SLEEP module goes SEARCH only once it also has a legal move.
    """

    scent_max: int = 65535
    p_seed: float = 0.0
    p_random: float = 0.05
    on_stuck: str = "stay"
    fewer_neighbours: bool = True
    horizontal: bool = True
    clean_exit: bool = True
    turn: bool = True
    greedy_approach: bool = True
    wake_when_free: bool = False
    directed: bool = True
    momentum: float = 1.0
    queue: bool = False
    prefer_chain: bool = True
    avoid_octahedra: bool | str = True

    CHOICES = {"on_stuck": ("stay", "random"), "avoid_octahedra": (False, True, "all")}

    def check(self) -> None:
        """A ``ValueError`` for a value not allowed."""
        for name in ("p_seed", "p_random"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name}={getattr(self, name)!r} is not allowed; allowed: a probability in [0, 1]")
        if self.momentum < 0:
            raise ValueError(f"momentum={self.momentum!r} is not allowed; allowed: a number >= 0")


class ModuleMemory(SlotMemory):
    """The chain rule's private memory of every module, one entry per memory slot.

    Attributes (S slots):
        heading: ``(S,)`` int64, direction of the module's last requested move (-1: none).
        growth: ``(S,)`` int64, a SEED's growth direction (-1: none).
        asked: ``(S,)`` bool, the module asked to move last cycle.
    """

    FIELDS = {"heading": (np.int64, -1), "growth": (np.int64, -1), "asked": (np.bool_, False)}


class ChainPolicy(KernelPolicy):
    """Hand-coded chain growth (rules and how they are carried out in the module docstring;
    parameters: :class:`ChainRuleParams`)."""

    name = "chain"
    Params = ChainRuleParams
    Memory = ModuleMemory
    rule = staticmethod(chain_actions)

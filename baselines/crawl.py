"""A chain travelling head first (the second stage of the snake, :mod:`baselines.snake`) as a
policy over observations.

Rules (modes CRAWL, HEAD, BODY, numbered 0-2 within the crawl), in the paper's style:

- HEAD, the chain's front end: emits scent and broadcasts its growth direction to all
  neighbours every cycle (message ``growth + 1``, as the chain's SEED does). It picks the
  growth by following the ground towards the goal (the observation's ``hint``): among the
  empty sites next to no other chain module (the chain stays one module thick), those ahead,
  the lowest first; else those level with the goal direction, the highest first (up the face
  of a step); else any. When a CRAWL module sits at the growth spot it asks that module to
  become the HEAD (message ``BECOME_HEAD``) and becomes BODY; a fresh HEAD first lets the
  crawlers hear its growth. A growth spot that gets blocked is chosen again.
- BODY: relays scent and never moves; the chain's tail (a BODY with exactly one module
  neighbour, so no crawler is holding on to it) becomes a CRAWL module. (A chain whose end
  came round to touch itself has no such module and stops; other tests of the tail lost more
  than they saved, docs/evidence/snake.md.)
- CRAWL: relays scent. Next to the HEAD it rolls over the HEAD's faces to the growth spot it
  heard (:func:`~baselines.primitives.approach_spot`) and holds still there; elsewhere it
  climbs the scent gradient along the chain (:func:`~baselines.primitives.lowest_rolls`; a
  chain module counts as lower than a crawler of the same scent, so crawlers travel on the
  chain rather than on each other), preferring rolls ahead, then level. With probability
  ``p_random``, and after ``patience`` cycles in a row without a roll to ask for, it makes a
  uniformly random legal roll instead.
- A HEAD that no crawler reached in ``head_patience`` cycles gives its growth spot up for
  another (walls and the ground can leave no roll into a spot).

So modules leave the chain at its tail, travel along it and join it at its head: the chain
moves head first, one module thick with at most one layer of crawlers beside it, which is
what a tunnel two layers high leaves room for.

The rule runs as the numba kernel :func:`crawl_actions` (the policy's ``rule``), here and in
the compiled rollout (:mod:`baselines.compiled`); every decision reads only that agent's
observation and its private memory (:class:`CrawlMemory`, one row per module). Modes are the
crawl's own (:class:`~proteo_env.tasks.crawl.CrawlMode`: 0 CRAWL, 1 HEAD, 2 BODY); a
composition (:mod:`baselines.compose`) shows it the modes of other behaviours as these.
Shared primitives: :mod:`baselines.primitives`.

Draws from the policy's ``numpy.random.Generator``, row after row: a HEAD choosing its growth
one ``rng.integers`` (:func:`~baselines.primitives.uniform_pick`); a CRAWL module its roll (12
uniforms, :func:`~baselines.primitives.random_pick`, or next to the HEAD what
:func:`~baselines.primitives.approach_spot` draws), then one "random legal roll instead?"
uniform, and 12 more when it takes one.

Array shapes (A agents, K neighbourhood sites, C = 1 scent channel, S memory slots, L = 5
action fields): ``own_mode`` (A, 1) int32, ``messages`` (A, 12) int32, ``neighbour_kind``
(A, K) int8, ``neighbour_mode`` (A, K) int32 and ``neighbour_scent`` (A, K, C) int32 (only
the first 12 sites are read), ``action_mask`` (A, 13) int8,
``hint`` (A, 3) float32 (the direction to travel), ``slots`` (A,) int64, the memory
``growth`` and ``idle`` (S,) int64 (a HEAD's ``idle``: cycles it has waited for a crawler at
its growth spot), ``actions`` (A, L) int64.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from proteo_env.core.jit import kernel
from proteo_env.core.lattice import DIRECTIONS, OPPOSITE
from proteo_env.core.world import MESSAGE_TO_ALL
from proteo_env.spaces import EMIT, KIND_EMPTY, KIND_MODULE, RELAY
from proteo_env.tasks.crawl import BODY, CRAWL, HEAD

from .base import KernelPolicy, SlotMemory
from .primitives import (
    BIT_COUNT,
    SPOT_FACE,
    approach_spot,
    downhill_bias,
    hint_bits,
    legal_bits,
    lowest_rolls,
    module_bits,
    random_pick,
    seen_scent,
    spot_touches,
    uniform_pick,
    write_action,
)

BECOME_HEAD = 14
"""Message value asking the receiver (a CRAWL module at the HEAD's growth spot) to become the HEAD."""
PREFER_NONE, PREFER_AHEAD, PREFER_DOWNHILL = range(3)
"""``CrawlRuleParams.prefer`` as the kernels read it: ``"none"``, ``"ahead"``, ``"downhill"``."""
CHAIN_BITS = (1 << HEAD) | (1 << BODY)
"""The chain's modes as a bit set: a growth spot next to one of these (but the HEAD) would make the chain two thick."""


@kernel
def _extreme_height(pool, lowest):
    """The slots of the bit set ``pool`` whose direction points lowest (``lowest``) or highest."""
    best = 2 if lowest else -2
    for k in range(12):
        if (pool >> k) & 1:
            best = min(best, DIRECTIONS[k, 2]) if lowest else max(best, DIRECTIONS[k, 2])
    out = 0
    for k in range(12):
        if (pool >> k) & 1 and DIRECTIONS[k, 2] == best:
            out |= 1 << k
    return out


@kernel
def head_growth(neighbour_kind, neighbour_mode, hint, i, rng, avoid):
    """The growth direction of the HEAD at row ``i``, following the ground; -1 when it has none.

    Candidates are the empty neighbour sites next to no chain module (so the chain stays one
    module thick), but ``avoid`` (a slot, -1 none) when there are others. Among them: ahead (a
    positive dot product with the hint), the lowest first; else level with the hint, the
    highest first (up a step's face); else any. One uniform pick.
    """
    free = 0
    for k in range(12):
        if neighbour_kind[i, k] == KIND_EMPTY and spot_touches(neighbour_mode, i, k, CHAIN_BITS) == 0:
            free |= 1 << k
    if avoid >= 0 and free & ~(1 << avoid):
        free &= ~(1 << avoid)
    ahead, level = hint_bits(hint, i)
    if free & ahead:
        pool = _extreme_height(free & ahead, True)
    elif free & level:
        pool = _extreme_height(free & level, False)
    else:
        pool = free
    return uniform_pick(rng, pool)


@kernel
def is_tail(neighbour_kind, i):
    """Is the chain module at row ``i`` the chain's tail? It touches exactly one module (so no
    crawler is holding on to it either)."""
    return BIT_COUNT[module_bits(neighbour_kind, i)] == 1


@kernel
def _blocked(neighbour_kind, neighbour_mode, i, growth):
    """Can the chain not grow into ``DIRECTIONS[growth]`` from row ``i`` any more? (solid, a
    wall, a chain module there, or a chain module seen next to the spot)"""
    kind = neighbour_kind[i, growth]
    if kind == KIND_MODULE:
        if neighbour_mode[i, growth] != CRAWL:
            return True
    elif kind != KIND_EMPTY:
        return True
    return spot_touches(neighbour_mode, i, growth, CHAIN_BITS) > 0


@kernel
def _head_action(neighbour_kind, neighbour_mode, hint, i, growth, fresh, waited, patience, rng, actions):
    """Write the action of the HEAD at row ``i`` (growth ``growth``, -1 none; ``waited`` cycles
    without a crawler at its spot) into ``actions[i]``; return the growth it keeps (-1: none, or
    it handed the head on). A growth spot that no crawler reached in ``patience`` cycles
    (walls and the ground can leave no roll into it) is given up for another."""
    if growth < 0 or _blocked(neighbour_kind, neighbour_mode, i, growth) or waited > patience:
        growth = head_growth(neighbour_kind, neighbour_mode, hint, i, rng, growth)
        fresh = True
    if growth < 0:
        write_action(actions, i, 0, HEAD, EMIT, EMIT, 0, 0)
        return -1
    if not fresh and neighbour_kind[i, growth] == KIND_MODULE:  # a CRAWL module at the spot
        write_action(actions, i, 0, BODY, RELAY, RELAY, growth, BECOME_HEAD)
        return -1
    write_action(actions, i, 0, HEAD, EMIT, EMIT, MESSAGE_TO_ALL, growth + 1)
    return growth


@kernel
def _crawl_move(neighbour_kind, neighbour_mode, neighbour_scent, messages, action_mask, hint, i, rules, rng):
    """``(move, asked)`` of the CRAWL module at row ``i``: ``asked`` says whether the rule had a
    roll to ask for (a random legal roll may still follow, by the caller)."""
    legal = legal_bits(action_mask, i)
    for k in range(12):  # next to the HEAD: to its growth spot, then hold there
        if neighbour_mode[i, k] == HEAD:
            v = messages[i, k]
            if not 1 <= v <= 12:  # the growth is not heard yet (or the head is being handed on)
                return 0, True
            g = v - 1
            face = SPOT_FACE[k, g]
            if g == OPPOSITE[k] or (face >= 0 and neighbour_kind[i, face] == KIND_MODULE):
                return 0, True  # at the spot, or another module holds it
            move = approach_spot(action_mask, i, k, g, rules.greedy_approach, rng)
            return move, move > 0
    smax = rules.scent_max
    key = np.empty(12, dtype=np.int64)
    here = np.iinfo(np.int64).max
    for k in range(12):  # climb the scent: a chain module counts lower than a crawler of equal scent
        raw = seen_scent(neighbour_kind, neighbour_scent, i, k, smax)
        key[k] = 2 * raw + (1 if neighbour_mode[i, k] == CRAWL else 0) if raw < smax else 2 * smax
        here = min(here, key[k])
    if here >= 2 * smax:
        return 0, False
    pool, low = lowest_rolls(key, legal)
    if pool == 0 or low > here:
        return 0, False
    if rules.prefer == PREFER_AHEAD:
        ahead, level = hint_bits(hint, i)
        if pool & ahead:
            pool &= ahead
        elif pool & level:
            pool &= level
    elif rules.prefer == PREFER_DOWNHILL and low == here:
        downhill = _downhill_bits(neighbour_kind, neighbour_scent, i, smax)
        if pool & downhill:
            pool &= downhill
    return random_pick(rng, pool) + 1, True


@kernel
def _downhill_bits(neighbour_kind, neighbour_scent, i, smax):
    """The face directions with a positive dot product with row ``i``'s downhill estimate
    (:func:`~baselines.primitives.downhill_bias`); 0 with fewer than 2 scented neighbours."""
    raw = np.empty(12, dtype=np.int64)
    for k in range(12):
        raw[k] = seen_scent(neighbour_kind, neighbour_scent, i, k, smax)
    bias = np.zeros(3)
    downhill_bias(raw, smax, bias)
    out = 0
    for k in range(12):
        if bias[0] * DIRECTIONS[k, 0] + bias[1] * DIRECTIONS[k, 1] + bias[2] * DIRECTIONS[k, 2] > 0:
            out |= 1 << k
    return out


@kernel
def crawl_actions(seen, slots, memory, rules, rng, actions):
    """Every agent's action under the crawl rule: the policy's ``rule``
    (:attr:`baselines.base.KernelPolicy.rule`; ``memory`` is ``(growth, idle)``, shapes and
    draws in the module docstring); writes ``actions`` (A, 5) and updates the memory."""
    own_mode, messages, action_mask, hint = seen.own_mode, seen.messages, seen.action_mask, seen.hint
    neighbour_kind, neighbour_mode, neighbour_scent = seen.neighbour_kind, seen.neighbour_mode, seen.neighbour_scent
    growth, idle = memory
    for i in range(own_mode.shape[0]):
        own = own_mode[i, 0]
        s = slots[i]
        promoted = False
        for k in range(12):
            if messages[i, k] == BECOME_HEAD:
                promoted = True
        if own == HEAD or (own == CRAWL and promoted):
            old = growth[s] if own == HEAD else -1
            growth[s] = _head_action(
                neighbour_kind, neighbour_mode, hint, i, old, own != HEAD, idle[s], rules.head_patience, rng, actions
            )
            idle[s] = idle[s] + 1 if growth[s] == old else 0
        elif own == BODY:
            growth[s] = -1
            tail = is_tail(neighbour_kind, i)
            write_action(actions, i, 0, CRAWL if tail else BODY, RELAY, RELAY, 0, 0)
        else:
            growth[s] = -1
            move, asked = _crawl_move(
                neighbour_kind, neighbour_mode, neighbour_scent, messages, action_mask, hint, i, rules, rng
            )
            idle[s] = 0 if asked else idle[s] + 1
            if rng.random() < rules.p_random or idle[s] > rules.patience:
                move = random_pick(rng, legal_bits(action_mask, i)) + 1
                idle[s] = 0
            write_action(actions, i, move, CRAWL, RELAY, RELAY, 0, 0)


class CrawlRuleParams(NamedTuple):
    """The crawl rule's parameters, :class:`CrawlPolicy`'s keywords (``scent_max``: the scent
    value that means "no scent").

    Attributes:
        p_random: probability of a uniformly random legal roll instead of the rule's.
        patience: cycles in a row without a roll to ask for after which a CRAWL module makes a
            random legal roll.
        head_patience: cycles a HEAD waits for a crawler at its growth spot before it gives the
            spot up for another (walls and the ground can leave no roll into a spot).
        greedy_approach: next to the HEAD, roll over its faces to the sites nearest the growth
            spot rather than to any.
        prefer: how a crawler picks among the rolls that keep its lowest neighbour: ``"none"``
            (any), ``"ahead"`` (ahead, then level with the goal direction) or ``"downhill"``
            (with a positive dot product with the downhill estimate, when the roll keeps the
            scent level).
    """

    scent_max: int = 65535
    p_random: float = 0.02
    patience: int = 10
    head_patience: int = 40
    greedy_approach: bool = True
    prefer: str = "downhill"

    CHOICES = {"prefer": ("none", "ahead", "downhill")}

    def check(self) -> None:
        """A ``ValueError`` for a value not allowed."""
        if isinstance(self.p_random, bool) or not 0.0 <= self.p_random <= 1.0:
            raise ValueError(f"p_random={self.p_random!r} is not allowed; allowed: a probability in [0, 1]")
        for name in ("patience", "head_patience"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}={value!r} is not allowed; allowed: an integer >= 1")


class CrawlMemory(SlotMemory):
    """The crawl rule's private memory of every module: ``growth`` (S,) int64, a HEAD's growth
    direction (-1: none); ``idle`` (S,) int64, cycles in a row without a roll to ask for."""

    FIELDS = {"growth": (np.int64, -1), "idle": (np.int64, 0)}


class CrawlPolicy(KernelPolicy):
    """A chain travelling head first (rules in the module docstring; parameters:
    :class:`CrawlRuleParams`)."""

    name = "crawl"
    Params = CrawlRuleParams
    Memory = CrawlMemory
    rule = staticmethod(crawl_actions)


__all__ = ["CrawlMemory", "CrawlPolicy"]

"""The hand-coded grasp rules as a numba kernel over stacked observation fields.

:func:`grasp_actions` is the one implementation of the grasp behaviour's decisions:
:class:`~baselines.grasp.GraspPolicy` calls it on the observations the environment hands out,
and :class:`baselines.compiled.CompiledRollout` calls it inside a compiled loop with the
engine. The rules and how they are carried out are in :mod:`baselines.grasp`.

The rows are decided in groups, and the draws from the policy's ``numpy.random.Generator``
come in this order:

1. SLEEP rows (no draws);
2. the climbing SEARCH rows (no SEED or TOUCHSEED next to them): one "random legal roll
   instead?" uniform each, then 12 uniforms each (:func:`~baselines.primitives.random_pick`);
3. the other SEARCH rows in row order: a roll towards a seed's growth spot or around a
   TOUCHSEED, one ``rng.integers`` pick when there are several;
4. SEED rows in row order: a new growth site, one ``rng.integers`` pick (``straight``) or one
   uniform for a pick with probability proportional to the dot product with the hint (as
   ``rng.choice(n, p=...)`` draws);
5. TOUCHSEED rows in row order: a TOUCH neighbour to pass the role to, one pick;
6. TOUCH rows told to take the role (no draws).

Array shapes (A agents, K neighbourhood sites, C = 2 scent channels, S memory slots,
L = 6 action fields): the chain's (:mod:`baselines.chain_rules`), plus ``contact`` (A, 2) int8
(``contact[:, 1]``: touching the object), ``hint`` (A, 3) float32, and the memory (S,) int64
``growth`` (-1 none), ``waited``, ``stuck``, ``age`` (0 none) and ``previous`` (-1 none).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from proteo_env.core.jit import kernel
from proteo_env.core.lattice import DIRECTIONS, OPPOSITE
from proteo_env.core.world import DIRECTION_ADJACENCY, MESSAGE_TO_ALL
from proteo_env.spaces import EMIT, KIND_EMPTY, KIND_MODULE, KIND_OBJECT, RELAY, SILENT
from proteo_env.tasks.grasp import FINAL, SEARCH, SEED, SLEEP, TOUCH, TOUCHSEED

from .primitives import (
    AROUND_BITS,
    FAR,
    approach_spot,
    legal_bits,
    lowest_rolls,
    random_pick,
    uniform_pick,
    write_action,
)

SET_FINAL = 13
"""Message value: "go FINAL" (the searcher that takes over to the SEED it replaces)."""
SET_TOUCH = 14
"""Message value: "go TOUCH" (a searcher touching the object to the SEED or TOUCHSEED it replaces)."""
PASS_SEED = 15
"""Message value: "become TOUCHSEED" (a stuck TOUCHSEED to a TOUCH neighbour; ``relocate`` only)."""


class GraspRuleParams(NamedTuple):
    """The grasp rule's parameters as the kernel reads them (see :class:`~baselines.grasp.GraspPolicy`);
    ``touch_channel`` is the touch scent's channel, -1 when the searchers ignore it."""

    scent_max: int
    p_random: float
    random_on_flat: bool
    patience: int
    touch_first: bool
    greedy_approach: bool
    relocate: bool
    touch_patience: int
    retire: bool
    retire_after: int
    touch_channel: int
    straight: bool
    wrap_forward: bool


@kernel
def _forget(s, growth, waited, stuck, age, previous):
    growth[s], waited[s], stuck[s], age[s], previous[s] = -1, 0, 0, 0, -1


@kernel
def _heard(messages, i, value):
    for k in range(12):
        if messages[i, k] == value:
            return True
    return False


@kernel
def _ahead(pool, hint, i):
    """The directions of the bit set ``pool`` with a positive dot product with row ``i``'s hint."""
    ahead = 0
    for k in range(12):
        if (pool >> k) & 1:
            dot = 0.0
            for axis in range(3):
                dot += DIRECTIONS[k, axis] * np.float64(hint[i, axis])
            if dot > 0:
                ahead |= 1 << k
    return ahead


@kernel
def _climb_pool(neighbour_kind, neighbour_scent, action_mask, i, rules):
    """The legal rolls of climbing row ``i`` that keep the lowest scent it sees next to the
    target (the touch scent when it smells it), or every legal roll when none does and
    ``random_on_flat``, as a bit set."""
    smax = rules.scent_max
    channel = 0
    if rules.touch_channel >= 0:
        for k in range(12):
            if neighbour_kind[i, k] == KIND_MODULE and neighbour_scent[i, k, rules.touch_channel] < smax:
                channel = rules.touch_channel
    scent = np.empty(12, dtype=np.int64)
    here = FAR
    for k in range(12):
        scent[k] = neighbour_scent[i, k, channel] if neighbour_kind[i, k] == KIND_MODULE else smax
        here = min(here, scent[k])
    legal = legal_bits(action_mask, i)
    pool, low = lowest_rolls(scent, legal)
    if low <= here and low < smax:
        return pool
    return legal if rules.random_on_flat else 0


@kernel
def _around(neighbour_kind, action_mask, hint, i, slot, rules, rng):
    """The paper's "random move" of row ``i`` next to the TOUCHSEED at ``slot``."""
    legal = legal_bits(action_mask, i)
    if legal == 0:
        return 0
    keep = legal & AROUND_BITS[slot]
    if keep and rules.touch_first:
        touching = 0
        for k in range(12):
            if (keep >> k) & 1:
                for a in range(4):
                    if neighbour_kind[i, DIRECTION_ADJACENCY[k, a]] == KIND_OBJECT:
                        touching |= 1 << k
        if touching:
            keep = touching
    if (keep & (keep - 1)) != 0 and rules.wrap_forward:
        ahead = _ahead(keep, hint, i)
        if ahead:
            keep = ahead
    return uniform_pick(rng, keep if keep else legal) + 1


@kernel
def _search_near_seed(
    messages, neighbour_kind, neighbour_mode, action_mask, contact, hint, i, s, previous, rules, rng, actions
):
    """A SEARCH row ``i`` next to a SEED or TOUCHSEED (module docstring of :mod:`baselines.grasp`)."""
    first, plain = -1, 0
    for k in range(12):
        m = neighbour_mode[i, k]
        if m == SEED or m == TOUCHSEED:
            if first < 0:
                first = k
            if m == SEED:
                plain |= 1 << k
    if contact[i, 1]:
        write_action(actions, i, 0, TOUCHSEED, EMIT, EMIT, first, SET_TOUCH)
        return
    if plain == 0:
        actions[i, 0] = _around(neighbour_kind, action_mask, hint, i, first, rules, rng)
        return
    for slot in range(12):
        if not (plain >> slot) & 1:
            continue
        value = messages[i, slot]
        if not 1 <= value <= 12:
            continue
        growth = value - 1
        if OPPOSITE[growth] == slot:  # this is the seed's growth site
            previous[s] = growth
            write_action(actions, i, 0, SEED, EMIT, RELAY, slot, SET_FINAL)
        else:
            actions[i, 0] = approach_spot(action_mask, i, slot, growth, rules.greedy_approach, rng)
        return
    # growth not heard from here yet: hold still (the default SEARCH action)


@kernel
def _growth_direction(neighbour_kind, hint, i, previous, avoid, rules, rng):
    """The growth site of a seed at row ``i`` (module docstring of :mod:`baselines.grasp`), -1
    when there is none."""
    h = np.empty(3)
    for axis in range(3):
        h[axis] = hint[i, axis]
    dots = np.empty(12)
    cand = 0
    for k in range(12):
        dots[k] = DIRECTIONS[k, 0] * h[0] + DIRECTIONS[k, 1] * h[1] + DIRECTIONS[k, 2] * h[2]
        if neighbour_kind[i, k] == KIND_EMPTY and dots[k] > 1e-9:
            cand |= 1 << k
    if (cand & (cand - 1)) != 0 and avoid >= 0:
        cand &= ~(1 << avoid)
    if cand == 0:
        return -1
    if rules.straight and previous >= 0:
        cos = np.full(12, -np.inf)
        best = -np.inf
        for k in range(12):
            if (cand >> k) & 1:
                dot, norm = 0.0, 0.0
                for axis in range(3):
                    two = DIRECTIONS[k, axis] + DIRECTIONS[previous, axis]
                    dot += two * h[axis]
                    norm += two * two
                cos[k] = dot / max(np.sqrt(norm), 1e-12)
                best = max(best, cos[k])
        pool = 0
        for k in range(12):
            if (cand >> k) & 1 and cos[k] >= best - 1e-9:
                pool |= 1 << k
        return uniform_pick(rng, pool)
    # rng.choice(n, p=w / w.sum()) over the candidates in ascending order, draw for draw
    n = 0
    w = np.empty(12)
    slots = np.empty(12, dtype=np.int64)
    for k in range(12):
        if (cand >> k) & 1:
            w[n] = dots[k]
            slots[n] = k
            n += 1
    rest = 0.0
    for j in range(1, n):
        rest += w[j]
    total = w[0] + rest
    cdf = np.cumsum(w[:n] / total)
    cdf = cdf / cdf[n - 1]
    u = rng.random()
    for j in range(n):
        if cdf[j] > u:
            return slots[j]
    return slots[n - 1]


@kernel
def _seed(
    messages,
    neighbour_kind,
    neighbour_mode,
    contact,
    hint,
    i,
    s,
    growth,
    waited,
    stuck,
    age,
    previous,
    rules,
    rng,
    actions,
):
    """A SEED row ``i`` (slot ``s``): obey a hand-over, keep or choose its growth site, retire."""
    if _heard(messages, i, SET_TOUCH) or _heard(messages, i, SET_FINAL):
        write_action(actions, i, 0, TOUCH if _heard(messages, i, SET_TOUCH) else FINAL, RELAY, RELAY, 0, 0)
        _forget(s, growth, waited, stuck, age, previous)
        return
    g = growth[s]
    w = waited[s] + 1
    avoid = -1
    if g >= 0:
        kind = neighbour_kind[i, g]
        m = neighbour_mode[i, g]
        taken = kind != KIND_EMPTY and not (kind == KIND_MODULE and (m == SLEEP or m == SEARCH))
        if taken or w > rules.patience:
            avoid = g if not taken else -1
            g = -1
    if g < 0:
        g = _growth_direction(neighbour_kind, hint, i, previous[s] if avoid < 0 else -1, avoid, rules, rng)
        w = 0
    age[s] += 1
    stuck[s] = stuck[s] + 1 if g < 0 else 0
    if rules.retire and not contact[i, 1] and (stuck[s] > rules.patience or age[s] > rules.retire_after):
        _forget(s, growth, waited, stuck, age, previous)
        write_action(actions, i, 0, FINAL, RELAY, RELAY, 0, 0)
        return
    growth[s] = g
    if g < 0:  # nowhere to grow (yet)
        write_action(actions, i, 0, SEED, EMIT, RELAY, 0, 0)
        return
    waited[s] = w
    write_action(actions, i, 0, SEED, EMIT, RELAY, MESSAGE_TO_ALL, g + 1)


@kernel
def _touch_seed(
    messages, neighbour_kind, neighbour_mode, hint, i, s, growth, waited, stuck, age, previous, rules, rng, actions
):
    """A TOUCHSEED row ``i`` (slot ``s``): obey a hand-over, or with ``relocate`` pass the role on."""
    if _heard(messages, i, SET_TOUCH):
        _forget(s, growth, waited, stuck, age, previous)
        write_action(actions, i, 0, TOUCH, RELAY, RELAY, 0, 0)
        return
    if rules.relocate:
        waited[s] += 1
        open_site = False
        touch = 0
        for k in range(12):
            if neighbour_kind[i, k] == KIND_EMPTY:
                for a in range(4):
                    if neighbour_kind[i, DIRECTION_ADJACENCY[k, a]] == KIND_OBJECT:
                        open_site = True
            if neighbour_mode[i, k] == TOUCH:
                touch |= 1 << k
        if touch and (not open_site or waited[s] > rules.touch_patience):
            _forget(s, growth, waited, stuck, age, previous)
            if (touch & (touch - 1)) != 0 and rules.wrap_forward:
                ahead = _ahead(touch, hint, i)
                if ahead:
                    touch = ahead
            write_action(actions, i, 0, TOUCH, RELAY, RELAY, uniform_pick(rng, touch), PASS_SEED)
            return
    write_action(actions, i, 0, TOUCHSEED, EMIT, EMIT, 0, 0)


@kernel
def grasp_actions(
    own_mode,
    messages,
    neighbour_kind,
    neighbour_mode,
    neighbour_scent,
    own_scent,
    action_mask,
    contact,
    hint,
    slots,
    growth,
    waited,
    stuck,
    age,
    previous,
    rules,
    rng,
    actions,
):
    """Write every row's grasp action into ``actions`` (A, 6) and update the memory of its slot.

    Shapes and the order of draws: module docstring. ``rules``: :class:`GraspRuleParams`.
    """
    n = own_mode.shape[0]
    near_seed = np.zeros(n, dtype=np.bool_)
    climbers = np.empty(n, dtype=np.int64)
    n_climbers = 0
    for i in range(n):
        mode = own_mode[i, 0]
        write_action(actions, i, 0, mode, RELAY, RELAY, 0, 0)
        if mode == SLEEP:
            detected = False
            for k in range(12):
                detected |= neighbour_scent[i, k, 0] < rules.scent_max
            role = RELAY if detected else SILENT
            write_action(actions, i, 0, SEARCH if detected else SLEEP, role, role, 0, 0)
        elif mode == SEARCH:
            for k in range(12):
                near_seed[i] |= neighbour_mode[i, k] == SEED or neighbour_mode[i, k] == TOUCHSEED
            if not near_seed[i]:
                climbers[n_climbers] = i
                n_climbers += 1
    pools = np.empty(n_climbers, dtype=np.int64)
    for j in range(n_climbers):
        pools[j] = _climb_pool(neighbour_kind, neighbour_scent, action_mask, climbers[j], rules)
    for j in range(n_climbers):
        if rng.random() < rules.p_random:
            pools[j] = legal_bits(action_mask, climbers[j])
    for j in range(n_climbers):
        actions[climbers[j], 0] = random_pick(rng, pools[j]) + 1
    for i in range(n):
        if near_seed[i]:
            _search_near_seed(
                messages,
                neighbour_kind,
                neighbour_mode,
                action_mask,
                contact,
                hint,
                i,
                slots[i],
                previous,
                rules,
                rng,
                actions,
            )
    for i in range(n):
        if own_mode[i, 0] == SEED:
            _seed(
                messages,
                neighbour_kind,
                neighbour_mode,
                contact,
                hint,
                i,
                slots[i],
                growth,
                waited,
                stuck,
                age,
                previous,
                rules,
                rng,
                actions,
            )
    for i in range(n):
        if own_mode[i, 0] == TOUCHSEED:
            _touch_seed(
                messages,
                neighbour_kind,
                neighbour_mode,
                hint,
                i,
                slots[i],
                growth,
                waited,
                stuck,
                age,
                previous,
                rules,
                rng,
                actions,
            )
    if rules.relocate:
        for i in range(n):
            if own_mode[i, 0] == TOUCH and _heard(messages, i, PASS_SEED):
                waited[slots[i]] = 0
                write_action(actions, i, 0, TOUCHSEED, EMIT, EMIT, 0, 0)


@kernel
def grasp_decide(seen, slots, memory, rules, rng, actions):
    """:func:`grasp_actions` as a policy's ``rule`` (:attr:`baselines.base.KernelPolicy.rule`):
    ``memory`` is ``(growth, waited, stuck, age, previous)``, ``rules`` a :class:`GraspRuleParams`."""
    growth, waited, stuck, age, previous = memory
    grasp_actions(
        seen.own_mode,
        seen.messages,
        seen.neighbour_kind,
        seen.neighbour_mode,
        seen.neighbour_scent,
        seen.own_scent,
        seen.action_mask,
        seen.contact,
        seen.hint,
        slots,
        growth,
        waited,
        stuck,
        age,
        previous,
        rules,
        rng,
        actions,
    )

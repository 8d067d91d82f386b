"""The hand-coded table rules as a numba kernel over stacked observation fields.

:func:`table_actions` is the one implementation of the table behaviour's decisions:
:class:`~baselines.table.TablePolicy` calls it on the observations the environment hands
out, and :class:`baselines.compiled.CompiledRollout` calls it inside a compiled loop with the
engine. The rules and how they are carried out are in :mod:`baselines.table`.

Draws from the policy's ``numpy.random.Generator``, in row order, then for the climbers:

- an IROOT over ``f_max``: one uniform ("grow a leg?"); a ROOT under ``f_min``: one uniform;
- a seed (AROOT or SEED) choosing a growth spot among several: one ``rng.integers`` pick
  (:func:`~baselines.primitives.uniform_pick`);
- a SEARCH module next to a seed it has heard: a pick among the lowest such seeds, a pick
  among the rolls towards the spot, and when it has none and ``p_random > 0`` one uniform
  and, if that says so and it has a legal roll, a pick among those;
- after all rows, the climbing SEARCH modules (no seed next to them): one "random legal roll
  instead?" uniform each, then 12 uniforms each (:func:`~baselines.primitives.random_pick`).

Array shapes (A agents, K neighbourhood sites, C = 1 scent channel, S memory slots,
L = 5 action fields): the chain's (:mod:`baselines.chain_rules`), plus

========== ======= ==================================================
``contact`` (A, 2) int8, ``contact[:, 0]``: touching the floor
``load``    (A, 1) float32, a root's load sensor
``spot``    (S,)   int64, growth spot of a SEED or AROOT, -1 none
``parent``  (S,)   int64, side of the seed a new SEED took over from, -1 none
``child``   (S,)   int64, side of the leg's next module, -1 none
========== ======= ==================================================
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from proteo_env.core.jit import kernel
from proteo_env.core.lattice import DIRECTIONS, OPPOSITE
from proteo_env.core.world import MESSAGE_TO_ALL
from proteo_env.spaces import EMIT, KIND_EMPTY, KIND_MODULE, RELAY
from proteo_env.tasks.table import AROOT, DISBAND, FINAL, IROOT, ROOT, SEARCH, SEED, SLEEP

from .primitives import (
    FAR,
    approach_spot,
    detects_scent,
    legal_bits,
    lowest_rolls,
    random_pick,
    uniform_pick,
    write_action,
)

SPOT_TAKEN = 13
"""Message: "I took your growth spot" (a SEED goes FINAL, an AROOT goes ROOT)."""
DISBAND_NOW = 14
"""Message: "go DISBAND" (obeyed by FINAL and SEED modules)."""

DOWN_BITS = sum(1 << int(k) for k in np.flatnonzero(DIRECTIONS[:, 2] == -1))
"""The 4 face directions one layer down (the candidate growth spots of a seed), as a bit set."""


def _zigzag() -> np.ndarray:
    index = {tuple(d): k for k, d in enumerate(DIRECTIONS)}
    return np.array([index[(d[0], d[1], -1)] if d[2] == 1 else -1 for d in DIRECTIONS], dtype=np.int64)


ZIGZAG = _zigzag()
"""For a parent in direction ``k`` (up), the down direction on the opposite side of the leg."""


class TableRuleParams(NamedTuple):
    """The table rule's parameters as the kernel reads them (see :class:`~baselines.table.TablePolicy`)."""

    scent_max: int
    p_max: float
    p_min: float
    f_max: float
    f_min: float
    p_random: float


@kernel
def _blocked(neighbour_kind, neighbour_mode, i, k):
    """Is face site ``k`` of row ``i`` no growth spot: a module not SLEEP or SEARCH, or solid?"""
    kind = neighbour_kind[i, k]
    if kind == KIND_MODULE:
        m = neighbour_mode[i, k]
        return m != SLEEP and m != SEARCH
    return kind != KIND_EMPTY


@kernel
def _choose_spot(neighbour_kind, neighbour_mode, i, parent, rng):
    """A growth spot one layer down for row ``i`` (its seed's ``parent`` side, -1 none); -1
    when all 4 are blocked. Waiting modules' spots first, then empty ones; the zigzag spot
    when it is among them, else a uniform pick."""
    free = 0
    occupied = 0
    for k in range(12):
        if (DOWN_BITS >> k) & 1 and not _blocked(neighbour_kind, neighbour_mode, i, k):
            free |= 1 << k
            if neighbour_kind[i, k] == KIND_MODULE:
                occupied |= 1 << k
    if free == 0:
        return -1
    pool = occupied if occupied else free
    if parent >= 0 and (pool >> ZIGZAG[parent]) & 1:
        return ZIGZAG[parent]
    return uniform_pick(rng, pool)


@kernel
def _seed(neighbour_kind, neighbour_mode, i, s, mode, spot, parent, rng, actions):
    """A SEED or AROOT at row ``i`` (slot ``s``) keeps, or chooses, its growth spot and
    broadcasts it; it emits scent."""
    sp = spot[s]
    if sp < 0 or _blocked(neighbour_kind, neighbour_mode, i, sp):
        sp = _choose_spot(neighbour_kind, neighbour_mode, i, parent[s], rng)
    elif neighbour_kind[i, sp] != KIND_MODULE:
        for k in range(12):  # a module already waits at another spot below
            if (
                (DOWN_BITS >> k) & 1
                and neighbour_kind[i, k] == KIND_MODULE
                and not _blocked(neighbour_kind, neighbour_mode, i, k)
            ):
                sp = _choose_spot(neighbour_kind, neighbour_mode, i, parent[s], rng)
                break
    spot[s] = sp
    if sp < 0:
        write_action(actions, i, 0, mode, EMIT, EMIT, 0, 0)
    else:
        write_action(actions, i, 0, mode, EMIT, EMIT, MESSAGE_TO_ALL, sp + 1)


@kernel
def _disband_leg(i, s, new_mode, spot, parent, child, actions):
    """Go ``new_mode`` and tell this leg's next module (if any) to disband; forget everything."""
    c = child[s]
    spot[s], parent[s], child[s] = -1, -1, -1
    if c < 0:
        write_action(actions, i, 0, new_mode, RELAY, RELAY, 0, 0)
    else:
        write_action(actions, i, 0, new_mode, RELAY, RELAY, c, DISBAND_NOW)


@kernel
def _search_near_seed(messages, neighbour_mode, action_mask, i, s, spot, parent, child, rules, rng, actions):
    """A SEARCH module at row ``i`` next to a SEED or AROOT: take over at its spot, or roll
    towards the spot of the lowest seed it has heard, or hold still."""
    seeds = 0
    for k in range(12):
        m = neighbour_mode[i, k]
        if m == SEED or m == AROOT:
            seeds |= 1 << k
    heard = 0
    lowest = 2
    for k in range(12):
        if (seeds >> k) & 1:
            growth = messages[i, k] - 1
            if growth == OPPOSITE[k]:  # at the seed's spot: become the SEED
                spot[s], child[s] = -1, -1
                parent[s] = k
                write_action(actions, i, 0, SEED, EMIT, EMIT, k, SPOT_TAKEN)
                return
            if 0 <= growth < 12:
                heard |= 1 << k
                lowest = min(lowest, DIRECTIONS[k, 2])
    if heard == 0:  # next to a seed not heard yet: hold still
        write_action(actions, i, 0, SEARCH, RELAY, RELAY, 0, 0)
        return
    pool = 0
    for k in range(12):
        if (heard >> k) & 1 and DIRECTIONS[k, 2] == lowest:
            pool |= 1 << k
    slot = uniform_pick(rng, pool)
    move = approach_spot(action_mask, i, slot, messages[i, slot] - 1, True, rng)
    if move == 0 and rules.p_random > 0 and rng.random() < rules.p_random:
        move = uniform_pick(rng, legal_bits(action_mask, i)) + 1
    write_action(actions, i, move, SEARCH, RELAY, RELAY, 0, 0)


@kernel
def _gradient_pool(neighbour_kind, neighbour_scent, action_mask, i, scent_max):
    """The legal rolls of row ``i`` that keep the lowest scent next to the target, when that is
    no worse than here (the chain's SEARCH rule, staying when stuck, no bias), as a bit set."""
    scent = np.empty(12, dtype=np.int64)
    here = FAR
    for k in range(12):
        scent[k] = neighbour_scent[i, k, 0] if neighbour_kind[i, k] == KIND_MODULE else scent_max
        here = min(here, scent[k])
    pool, low = lowest_rolls(scent, legal_bits(action_mask, i))
    return pool if low <= here else 0


@kernel
def table_actions(
    own_mode,
    messages,
    neighbour_kind,
    neighbour_mode,
    neighbour_scent,
    own_scent,
    action_mask,
    contact,
    load,
    slots,
    spot,
    parent,
    child,
    rules,
    rng,
    actions,
):
    """Write every row's table action into ``actions`` (A, 5) and update the memory of its slot.

    Shapes and draws: module docstring. ``rules``: :class:`TableRuleParams`.
    """
    n = own_mode.shape[0]
    climbers = np.empty(n, dtype=np.int64)
    n_climbers = 0
    f_max, f_min = np.float32(rules.f_max), np.float32(rules.f_min)
    for i in range(n):
        s = slots[i]
        mode = own_mode[i, 0]
        disband = False
        taken = -1
        for k in range(12):
            if messages[i, k] == DISBAND_NOW:
                disband = True
            if messages[i, k] == SPOT_TAKEN and taken < 0:
                taken = k
        if mode == SEARCH:
            near_seed = False
            for k in range(12):
                if neighbour_mode[i, k] == SEED or neighbour_mode[i, k] == AROOT:
                    near_seed = True
            if near_seed:
                _search_near_seed(messages, neighbour_mode, action_mask, i, s, spot, parent, child, rules, rng, actions)
            else:
                climbers[n_climbers] = i
                n_climbers += 1
                write_action(actions, i, 0, SEARCH, RELAY, RELAY, 0, 0)
        elif mode == FINAL:
            write_action(actions, i, 0, DISBAND if disband else FINAL, RELAY, RELAY, 0, 0)
        elif mode == IROOT:
            if load[i, 0] > f_max and rng.random() < rules.p_max:
                _seed(neighbour_kind, neighbour_mode, i, s, AROOT, spot, parent, rng, actions)
            else:
                write_action(actions, i, 0, IROOT, RELAY, RELAY, 0, 0)
        elif mode == ROOT:
            if load[i, 0] < f_min and rng.random() < rules.p_min:
                _disband_leg(i, s, IROOT, spot, parent, child, actions)
            else:
                write_action(actions, i, 0, ROOT, RELAY, RELAY, 0, 0)
        elif mode == AROOT or mode == SEED:
            if taken >= 0:  # the module below took the spot: it is this leg's next module
                child[s] = taken
            if mode == SEED and disband:
                spot[s], parent[s] = -1, -1
                write_action(actions, i, 0, DISBAND, RELAY, RELAY, 0, 0)
            elif taken >= 0 or (mode == SEED and contact[i, 0]):
                spot[s], parent[s] = -1, -1
                write_action(actions, i, 0, ROOT if mode == AROOT else FINAL, RELAY, RELAY, 0, 0)
            else:
                _seed(neighbour_kind, neighbour_mode, i, s, mode, spot, parent, rng, actions)
        elif mode == DISBAND:
            _disband_leg(i, s, SEARCH, spot, parent, child, actions)
        elif mode == SLEEP:
            awake = detects_scent(own_scent, neighbour_kind, neighbour_scent, i, rules.scent_max)
            write_action(actions, i, 0, SEARCH if awake else SLEEP, RELAY, RELAY, 0, 0)
        else:  # FIXED (board modules are passive; an agent never is)
            write_action(actions, i, 0, mode, RELAY, RELAY, 0, 0)
    pools = np.empty(n_climbers, dtype=np.int64)
    for j in range(n_climbers):
        pools[j] = _gradient_pool(neighbour_kind, neighbour_scent, action_mask, climbers[j], rules.scent_max)
    for j in range(n_climbers):
        if rng.random() < rules.p_random:
            pools[j] = legal_bits(action_mask, climbers[j])
    for j in range(n_climbers):
        actions[climbers[j], 0] = random_pick(rng, pools[j]) + 1


@kernel
def table_decide(seen, slots, memory, rules, rng, actions):
    """:func:`table_actions` as a policy's ``rule`` (:attr:`baselines.base.KernelPolicy.rule`):
    ``memory`` is ``(spot, parent, child)``, ``rules`` a :class:`TableRuleParams`."""
    spot, parent, child = memory
    table_actions(
        seen.own_mode,
        seen.messages,
        seen.neighbour_kind,
        seen.neighbour_mode,
        seen.neighbour_scent,
        seen.own_scent,
        seen.action_mask,
        seen.contact,
        seen.load,
        slots,
        spot,
        parent,
        child,
        rules,
        rng,
        actions,
    )

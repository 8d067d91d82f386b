"""The hand-coded locomotion rule as a numba kernel over stacked observation fields.

:func:`locomotion_actions` is the one implementation of the locomotion behaviour's decisions:
:class:`~baselines.locomotion.LocomotionPolicy` calls it on the observations the environment
hands out, and :class:`baselines.compiled.CompiledRollout` inside a compiled loop with the
engine. The rules are listed in :mod:`baselines.locomotion`; shared primitives:
:mod:`baselines.primitives`.

Draws from the policy's ``numpy.random.Generator``, row after row: one "random legal roll
instead?" uniform, then 12 uniforms (:func:`~baselines.primitives.random_pick`).

Array shapes (A agents, K neighbourhood sites, C = 1 scent channel, S memory slots, L = 5
action fields): ``neighbour_kind`` (A, K) int8 and ``neighbour_scent`` (A, K, C) int32 (only
the first 12 sites are read), ``action_mask`` (A, 13) int8, ``hint`` (A, 3) float32 (the goal
direction), ``slots`` (A,) int64, the memory ``idle`` (S,) int64, ``actions`` (A, L) int64.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from proteo_env.core.jit import kernel
from proteo_env.spaces import EMIT, KIND_SOLID, RELAY
from proteo_env.tasks.locomotion import SEARCH, SEED

from .primitives import (
    AROUND_BITS,
    BIT_COUNT,
    UP_BITS,
    detects_scent,
    hint_bits,
    kind_bits,
    legal_bits,
    lowest_rolls,
    module_bits,
    random_pick,
    seen_scent,
    write_action,
)


class LocomotionRuleParams(NamedTuple):
    """The locomotion rule's parameters as the kernel reads them (see
    :class:`~baselines.locomotion.LocomotionPolicy`)."""

    scent_max: int
    p_random: float
    patience: int
    seed_on_top: int
    low_first: int
    contacts: int


@kernel
def locomotion_actions(neighbour_kind, neighbour_scent, own_scent, action_mask, hint, slots, idle, rules, rng, actions):
    """Write every row's locomotion action into ``actions`` (A, 5) and update its ``idle`` count.

    Shapes and the order of draws: module docstring. ``rules``: :class:`LocomotionRuleParams`.
    """
    scent = np.empty(12, dtype=np.int64)
    for i in range(own_scent.shape[0]):
        ahead, level = hint_bits(hint, i)
        up = UP_BITS
        modules = module_bits(neighbour_kind, i)
        legal = legal_bits(action_mask, i)
        seed = (modules & ahead) == 0 and (rules.seed_on_top == 0 or (modules & up) == 0)
        if seed:  # the front: a directed random roll ahead, down first; against an obstacle, up
            pool = legal & ahead
            if pool & ~up & rules.low_first:
                pool &= ~up
            if pool == 0 and kind_bits(neighbour_kind, i, KIND_SOLID) & ahead:
                pool = legal & up & (ahead | level)
        elif detects_scent(own_scent, neighbour_kind, neighbour_scent, i, rules.scent_max):
            for k in range(12):
                scent[k] = seen_scent(neighbour_kind, neighbour_scent, i, k, rules.scent_max)
            pool, low = lowest_rolls(scent, legal)
            here = rules.scent_max
            for k in range(12):
                here = min(here, scent[k])
            if low > here or low >= rules.scent_max:
                pool = legal & (ahead | level)
            elif pool & ahead:
                pool &= ahead
                if pool & ~up & rules.low_first:
                    pool &= ~up
            elif pool & (ahead | level):
                pool &= ahead | level
        else:
            pool = legal & ahead
        held = 0  # no strands: rolls whose target keeps at least `contacts` of the modules seen next to it
        for k in range(12):
            if (pool >> k) & 1 and BIT_COUNT[modules & AROUND_BITS[k]] >= rules.contacts:
                held |= 1 << k
        if held:
            pool = held
        s = slots[i]
        idle[s] = idle[s] + 1 if pool == 0 else 0
        wild = rng.random() < rules.p_random or idle[s] > rules.patience
        if wild:
            pool = legal
            idle[s] = 0
        move = random_pick(rng, pool) + 1
        write_action(actions, i, move, SEED if seed else SEARCH, EMIT if seed else RELAY, RELAY, 0, 0)


@kernel
def locomotion_decide(seen, slots, memory, rules, rng, actions):
    """:func:`locomotion_actions` as a policy's ``rule`` (:attr:`baselines.base.KernelPolicy.rule`):
    ``memory`` is ``(idle,)``, ``rules`` a :class:`LocomotionRuleParams`."""
    (idle,) = memory
    locomotion_actions(
        seen.neighbour_kind,
        seen.neighbour_scent,
        seen.own_scent,
        seen.action_mask,
        seen.hint,
        slots,
        idle,
        rules,
        rng,
        actions,
    )

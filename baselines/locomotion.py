"""Locomotion over a step and through a tunnel (paper sections 1, 2.2 and 4.1) as a policy over
observations.

Rules (modes SEARCH, SEED), in the paper's style:

- A module at the front, with no module in any of its face sites ahead (a positive dot
  product with the goal direction, the observation ``hint``) nor, with ``seed_on_top``, above,
  is a SEED: it emits scent and makes a directed random move (paper 2.2): a random legal roll
  ahead, one that does not rise first (``low_first``). When it has none and sees solid ahead
  (the step, the end of a tunnel), it climbs: a random legal roll up that does not point back.
- Every other module is in SEARCH: it relays scent and moves along the scent gradient to the
  front: a random legal roll among those that keep the lowest scent it sees next to the
  target (:func:`~baselines.primitives.lowest_rolls`), preferring rolls ahead (not rising
  first, ``low_first``), then rolls across the goal direction. When every roll would lose the
  lowest scent, and with no scent in sight, it makes a random legal roll ahead or across.
- No strands: among the rolls a rule asks for, a module takes those whose target touches at
  least ``contacts`` modules it sees (of the 4 sites next to both here and the target) when
  there are any, so it lands on the robot's body, not at the end of a strand (every module of
  a one-module-thick strand is a cut vertex, and only its ends may move).
- With probability ``p_random``, and after ``patience`` cycles in a row without a roll to
  ask for, a module makes a uniformly random legal roll instead (the paper's randomness
  against getting stuck).

The modes are read afresh every cycle from what the module sees, so the front moves with the
robot: modules roll over the others to the front and down ahead of it, a tread. Against a
step the front piles up the step's face (each module that reaches the top of the pile is the
new SEED) until one can roll onto the step over the pile's top.

The rule runs as the numba kernel :func:`locomotion_actions` (the policy's ``rule``), here and
in the compiled rollout (:mod:`baselines.compiled`); every decision reads only that agent's
observation and its private memory (:class:`LocomotionMemory`, one row per module). Shared
primitives: :mod:`baselines.primitives`.

Draws from the policy's ``numpy.random.Generator``, row after row: one "random legal roll
instead?" uniform, then 12 uniforms (:func:`~baselines.primitives.random_pick`).

Array shapes (A agents, K neighbourhood sites, C = 1 scent channel, S memory slots, L = 5
action fields): ``neighbour_kind`` (A, K) int8 and ``neighbour_scent`` (A, K, C) int32 (only
the first 12 sites are read), ``own_scent`` (A, C) int32, ``action_mask`` (A, 13) int8,
``hint`` (A, 3) float32 (the goal direction), ``slots`` (A,) int64, the memory ``idle`` (S,)
int64, ``actions`` (A, L) int64.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from proteo_env.core.jit import kernel
from proteo_env.spaces import EMIT, KIND_SOLID, RELAY
from proteo_env.tasks.locomotion import SEARCH, SEED

from .base import KernelPolicy, SlotMemory
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


@kernel
def locomotion_actions(seen, slots, memory, rules, rng, actions):
    """Every agent's action under the locomotion rule: the policy's ``rule``
    (:attr:`baselines.base.KernelPolicy.rule`; ``memory`` is ``(idle,)``, shapes and draws in
    the module docstring); writes ``actions`` (A, 5) and updates each row's ``idle`` count."""
    neighbour_kind, neighbour_scent, own_scent = seen.neighbour_kind, seen.neighbour_scent, seen.own_scent
    action_mask, hint = seen.action_mask, seen.hint
    (idle,) = memory
    scent = np.empty(12, dtype=np.int64)
    for i in range(own_scent.shape[0]):
        ahead, level = hint_bits(hint, i)
        up = UP_BITS
        modules = module_bits(neighbour_kind, i)
        legal = legal_bits(action_mask, i)
        seed = (modules & ahead) == 0 and (not rules.seed_on_top or (modules & up) == 0)
        if seed:  # the front: a directed random roll ahead, down first; against an obstacle, up
            pool = legal & ahead
            if rules.low_first and pool & ~up:
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
                if rules.low_first and pool & ~up:
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


class LocomotionRuleParams(NamedTuple):
    """The locomotion rule's parameters, :class:`LocomotionPolicy`'s keywords (``scent_max``:
    the scent value that means "no scent").

    Attributes:
        p_random: probability of a uniformly random legal roll instead of the rule's.
        patience: cycles in a row without a roll to ask for after which a module makes a
            random legal roll.
        seed_on_top: a SEED must also have no module above it, so the front is the robot's
            upper front edge and the modules roll over the top (False: any module with none
            ahead; 2 of 8 instead of 7 of 8 robots of 20 crossed the flat in 2,000 cycles).
        low_first: among rolls ahead, take those that do not rise when there are any.
        contacts: among the rolls the rule asks for, take those whose target touches at least
            this many modules (of the 4 seen next to both here and there) when there are any,
            so the robot stays two layers thick rather than thinning into strands (0: off; 2:
            52 and 55 of 80 robots of 20 and 40 modules over a step 2 high, against 53 and 43
            with 0; docs/evidence/locomotion.md).
    """

    scent_max: int = 65535
    p_random: float = 0.02
    patience: int = 10
    seed_on_top: bool = True
    low_first: bool = True
    contacts: int = 2

    def check(self) -> None:
        """A ``ValueError`` for a value not allowed."""
        if isinstance(self.p_random, bool) or not 0.0 <= self.p_random <= 1.0:
            raise ValueError(f"p_random={self.p_random!r} is not allowed; allowed: a probability in [0, 1]")
        if isinstance(self.patience, bool) or not isinstance(self.patience, int) or self.patience < 1:
            raise ValueError(f"patience={self.patience!r} is not allowed; allowed: an integer >= 1")
        if isinstance(self.contacts, bool) or not isinstance(self.contacts, int) or not 0 <= self.contacts <= 4:
            raise ValueError(f"contacts={self.contacts!r} is not allowed; allowed: an integer in 0..4")


class LocomotionMemory(SlotMemory):
    """The locomotion rule's private memory of every module: ``idle`` (S,) int64, cycles in a
    row without a roll to ask for."""

    FIELDS = {"idle": (np.int64, 0)}


class LocomotionPolicy(KernelPolicy):
    """Hand-coded locomotion (rules in the module docstring; parameters:
    :class:`LocomotionRuleParams`)."""

    name = "locomotion"
    Params = LocomotionRuleParams
    Memory = LocomotionMemory
    rule = staticmethod(locomotion_actions)


__all__ = ["LocomotionMemory", "LocomotionPolicy"]

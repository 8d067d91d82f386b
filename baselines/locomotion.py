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

The rule runs as the numba kernel :func:`baselines.locomotion_rules.locomotion_actions`;
every decision reads only that agent's observation and its private memory
(:class:`LocomotionMemory`, one row per module).
"""

from __future__ import annotations

import numpy as np

from .base import KernelPolicy, SlotMemory
from .locomotion_rules import LocomotionRuleParams, locomotion_decide


class LocomotionMemory(SlotMemory):
    """The locomotion rule's private memory of every module: ``idle`` (S,) int64, cycles in a
    row without a roll to ask for."""

    FIELDS = {"idle": (np.int64, 0)}


class LocomotionPolicy(KernelPolicy):
    """Hand-coded locomotion (rules in the module docstring).

    Args:
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

    name = "locomotion"
    rule = staticmethod(locomotion_decide)

    def __init__(
        self,
        action_layout,
        modes,
        *,
        scent_max=65535,
        seed=None,
        p_random=0.02,
        patience=10,
        seed_on_top=True,
        low_first=True,
        contacts=2,
    ):
        super().__init__(action_layout, modes, scent_max=scent_max, seed=seed)
        if isinstance(p_random, bool) or not 0.0 <= p_random <= 1.0:
            raise ValueError(f"p_random={p_random!r} is not allowed; allowed: a probability in [0, 1]")
        if isinstance(patience, bool) or not isinstance(patience, int) or patience < 1:
            raise ValueError(f"patience={patience!r} is not allowed; allowed: an integer >= 1")
        self.p_random = p_random
        self.patience = patience
        self.seed_on_top = seed_on_top
        if isinstance(contacts, bool) or not isinstance(contacts, int) or not 0 <= contacts <= 4:
            raise ValueError(f"contacts={contacts!r} is not allowed; allowed: an integer in 0..4")
        self.low_first = low_first
        self.contacts = contacts
        self.memory = LocomotionMemory()
        """Private memory of every module (see :class:`LocomotionMemory`)."""

    @property
    def rule_params(self) -> LocomotionRuleParams:
        """The parameters as :func:`~baselines.locomotion_rules.locomotion_actions` reads them."""
        return LocomotionRuleParams(
            scent_max=int(self.scent_max),
            p_random=float(self.p_random),
            patience=int(self.patience),
            seed_on_top=int(bool(self.seed_on_top)),
            low_first=-1 if self.low_first else 0,
            contacts=int(self.contacts),
        )


__all__ = ["LocomotionMemory", "LocomotionPolicy"]

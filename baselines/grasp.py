"""The paper's grasping behaviour (section 4.4) as a policy over observations.

Rules, as the paper lists them (modes SLEEP, SEARCH, SEED, FINAL, TOUCHSEED, TOUCH):

- If in SLEEP mode, if scent is detected, go to SEARCH mode.
- If in SEARCH mode, propagate scent, and move along the scent gradient; if a seed has been
  found: if touching the object, then set seed to TOUCH mode, and go to TOUCHSEED mode;
  otherwise, if not touching the object, and seed is in SEED mode, find a spot next to the
  seed in the direction of the object, set seed to FINAL mode, and go to SEED mode;
  otherwise, make a random move.
- If in TOUCHSEED or SEED mode, emit scent.
- If in TOUCH or FINAL mode, propagate scent.

How each rule is carried out through the agent interface (one module's observation in, one
action out; nothing else is read). "The direction of the object" is the observation's
``hint``; "touching the object" is the contact sensor ``contact[1]``; "a seed has been
found" means a face neighbour shows mode SEED or TOUCHSEED; "set seed to X mode" is a
message to that neighbour, which changes its own mode when it reads it next cycle. "Scent"
is the seed scent (channel 0). The task has a second channel, the touch scent, which only
TOUCHSEEDs emit (see ``prefer_touch`` below); every module that relays, relays both.

- SLEEP: silent (the rule gives it no scent role); goes to SEARCH when a neighbour carries
  scent.
- SEARCH: relays scent. Next to a seed:

  * touching the object: sends ``SET_TOUCH`` to that seed and becomes TOUCHSEED;
  * else, next to a SEED: the spot next to the seed in the direction of the object is the
    seed's growth site ``seed + DIRECTIONS[g]``, which the seed picks and broadcasts
    (message ``g + 1``; the seed sees all 12 of its neighbour sites, a searcher only 4 of
    them). A searcher at that spot sends ``SET_FINAL`` to the seed and becomes SEED;
    elsewhere it rolls over the seed's faces towards the spot (greedily with
    ``greedy_approach``). It holds still while it has not heard the seed's growth from the
    seed's current slot (after a move, the slot of last cycle's message is stale);
  * else (next to a TOUCHSEED only): the random move, drawn among the rolls that keep the
    seed as a neighbour, preferring (``touch_first``) targets that visibly touch the object
    (one of the 4 sites next to both here and the target is object), then (``wrap_forward``)
    rolls with a positive dot product with the hint; with no roll around the seed, any
    random legal roll.

  Otherwise it moves along the gradient: among its legal rolls it takes, at random, one
  that keeps the lowest scent it sees next to the target (with radius-1 observations no
  single roll is seen to improve: the paper's random moves over a neighbour's faces until
  a lower neighbour appears); it stays when every roll would lose it (``on_flat``), and with
  probability ``p_random`` it rolls at random instead.
- SEED: emits scent. Picks its growth site among its empty neighbour sites whose direction
  has a positive dot product with the hint (the directed random move of paper section
  2.2): a fresh finger (an initial seed) draws one with probability proportional to the
  dot product (the expected step is then exactly along the hint: the sum over the 12
  directions of ``max(0, d.h) d`` is ``4 h``); a seed that knows the step that made it
  (``straight``) takes the site that makes its last two steps point most nearly along the
  hint (a lattice finger zig-zags along a direction no single lattice step points in,
  instead of drifting sideways). It keeps the site until it is taken by anything but a
  SLEEP or SEARCH module, or ``patience`` cycles pass without a hand-over, then draws
  another. On ``SET_FINAL`` it goes FINAL, on ``SET_TOUCH`` TOUCH.
- TOUCHSEED: emits scent (and touch scent); on ``SET_TOUCH`` goes TOUCH.
- FINAL, TOUCH: relay scent and never move.

Our additions to the paper's rules (all on by default; ``relocate=False, retire=False,
straight=False, wrap_forward=False, prefer_touch=False`` gives the paper's rules alone;
``docs/evidence/grasp.md`` measures both):

``retire``: a finger that misses the object grows on until it meets the wall of the box,
and a seed buried in the base (its growth sites are pockets no searcher can roll into)
never grows; either keeps emitting scent and the searchers near it pile up around it. With
``retire`` a SEED that does not touch the object and has had no growth site for
``patience`` cycles in a row, or has not been replaced for ``retire_after`` cycles, goes
FINAL (stops emitting).

``relocate``: the paper's TOUCHSEED can only hand its role to a searcher that touches the
object next to it, so a TOUCHSEED whose neighbour sites on the object are all taken stalls
its branch for good. With ``relocate`` a TOUCHSEED that sees no empty neighbour site
touching the object, or that has waited ``touch_patience`` cycles for a hand-over, passes
its role to a random TOUCH neighbour (message ``PASS_SEED``; with ``wrap_forward`` one in a
direction with a positive dot product with the hint if there is one) and goes TOUCH; the
seed thus wanders through the TOUCH patch to its rim, where growth can go on.

``prefer_touch``: a searcher that smells the touch scent climbs it instead of the seed
scent, so once the object is reached ("seeds transfer to the TOUCHSEED state", paper) the
searchers go to the grasp rather than to fingers that missed.

The rules run as the numba kernel :func:`baselines.grasp_rules.grasp_actions` on the
observation fields stacked over modules; every decision reads only that agent's own
observation and private memory (:class:`GraspMemory`, one row per module).
"""

from __future__ import annotations

import numpy as np

from proteo_env.tasks.grasp import FINAL, SEARCH, SEED, SLEEP, TOUCH, TOUCHSEED

from .base import KernelPolicy, SlotMemory
from .grasp_rules import PASS_SEED, SET_FINAL, SET_TOUCH, GraspRuleParams, grasp_decide


class GraspMemory(SlotMemory):
    """The grasp rule's private memory of every module, one entry per memory slot.

    Attributes (S slots, int64):
        growth: a SEED's growth direction (-1: none).
        waited: cycles a SEED or TOUCHSEED has waited for a hand-over.
        stuck: cycles in a row a SEED has had no growth site.
        age: cycles since the module became SEED.
        previous: the step that made a SEED (the direction it grew the finger; -1: none).
    """

    FIELDS = {
        "growth": (np.int64, -1),
        "waited": (np.int64, 0),
        "stuck": (np.int64, 0),
        "age": (np.int64, 0),
        "previous": (np.int64, -1),
    }


class GraspPolicy(KernelPolicy):
    """Hand-coded grasping (rules and how they are carried out in the module docstring).

    Args:
        p_random: probability that a climbing SEARCH module makes a uniformly random legal
            move instead of following the gradient.
        on_flat: what a climbing SEARCH module does when every legal roll would lose its
            lowest neighbour: ``"stay"`` or ``"random"`` (a random legal roll).
        patience: cycles a SEED waits for a hand-over at its growth site before drawing a new
            one.
        touch_first: next to a TOUCHSEED, prefer random moves to targets that visibly touch
            the object (False: uniform over the moves around the seed).
        greedy_approach: next to a SEED, roll over its faces towards the growth spot rather
            than at random.
        relocate: our addition to the paper's rules (module docstring): a stuck TOUCHSEED
            passes its role to a TOUCH neighbour.
        touch_patience: cycles a TOUCHSEED with ``relocate`` waits for a hand-over.
        retire: our addition (module docstring): a SEED that does not touch the object and has
            had no growth site for ``patience`` cycles in a row, or has not been replaced
            within ``retire_after`` cycles, goes FINAL.
        retire_after: see ``retire``.
        prefer_touch: with a second scent channel (the task's touch scent, emitted by
            TOUCHSEEDs only), a searcher that smells it climbs it instead of the seed scent.
        straight: a seed that knows the finger's previous step picks the growth site that
            makes the last two steps point most nearly along the hint (False: always draw with
            probability proportional to the dot product).
        wrap_forward: next to a TOUCHSEED, and when a TOUCHSEED passes its role on, prefer
            directions with a positive dot product with the hint (the directed random move of
            paper section 2.2: growth over the object heads round to its far side).
    """

    name = "grasp"
    rule = staticmethod(grasp_decide)

    def __init__(
        self,
        action_layout,
        modes,
        *,
        scent_max=65535,
        seed=None,
        p_random=0.05,
        on_flat="stay",
        patience=30,
        touch_first=True,
        greedy_approach=True,
        relocate=True,
        touch_patience=30,
        retire=True,
        retire_after=150,
        straight=True,
        wrap_forward=True,
        prefer_touch=True,
    ):
        super().__init__(action_layout, modes, scent_max=scent_max, seed=seed)
        if not 0.0 <= p_random <= 1.0:
            raise ValueError(f"p_random={p_random!r} is not allowed; allowed: a probability in [0, 1]")
        if on_flat not in ("stay", "random"):
            raise ValueError(f"on_flat={on_flat!r} is not allowed; allowed: stay, random")
        for name, value in (("patience", patience), ("touch_patience", touch_patience), ("retire_after", retire_after)):
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}={value!r} is not allowed; allowed: an integer >= 1")
        self.p_random = p_random
        self.on_flat = on_flat
        self.patience = patience
        self.touch_first = touch_first
        self.greedy_approach = greedy_approach
        self.relocate = relocate
        self.touch_patience = touch_patience
        self.retire = retire
        self.retire_after = retire_after
        self.prefer_touch = prefer_touch
        self.straight = straight
        self.wrap_forward = wrap_forward
        if action_layout.n_channels != 2:
            raise ValueError(
                f"action_layout with n_channels={action_layout.n_channels} is not allowed; allowed: 2 (the grasp "
                "task's seed and touch scents)"
            )
        self.memory = GraspMemory()
        """Private memory of every module (see :class:`GraspMemory`)."""

    @property
    def rule_params(self) -> GraspRuleParams:
        """The parameters as :func:`~baselines.grasp_rules.grasp_actions` reads them."""
        return GraspRuleParams(
            scent_max=int(self.scent_max),
            p_random=float(self.p_random),
            random_on_flat=self.on_flat == "random",
            patience=int(self.patience),
            touch_first=bool(self.touch_first),
            greedy_approach=bool(self.greedy_approach),
            relocate=bool(self.relocate),
            touch_patience=int(self.touch_patience),
            retire=bool(self.retire),
            retire_after=int(self.retire_after),
            touch_channel=1 if self.prefer_touch else -1,
            straight=bool(self.straight),
            wrap_forward=bool(self.wrap_forward),
        )


__all__ = [
    "FINAL",
    "PASS_SEED",
    "SEARCH",
    "SEED",
    "SET_FINAL",
    "SET_TOUCH",
    "SLEEP",
    "TOUCH",
    "TOUCHSEED",
    "GraspMemory",
    "GraspPolicy",
]

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
- SEARCH, "move along scent gradient" (``_climb`` in :mod:`baselines.chain_rules`): the value of a
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

The rules run as the numba kernels of :mod:`baselines.chain_rules` (:func:`~baselines.chain_rules.chain_actions`)
on the observation fields stacked over modules; the private memory is one row per module
(:class:`ModuleMemory`).
"""

from __future__ import annotations

import numpy as np

from .base import KernelPolicy, SlotMemory
from .chain_rules import OCTAHEDRA_ALL, OCTAHEDRA_CHAIN, OCTAHEDRA_OFF, ChainRuleParams, chain_decide

ON_STUCK = ("stay", "random")


class ModuleMemory(SlotMemory):
    """The chain rule's private memory of every module, one entry per memory slot.

    Attributes (S slots):
        heading: ``(S,)`` int64, direction of the module's last requested move (-1: none).
        growth: ``(S,)`` int64, a SEED's growth direction (-1: none).
        asked: ``(S,)`` bool, the module asked to move last cycle.
    """

    FIELDS = {"heading": (np.int64, -1), "growth": (np.int64, -1), "asked": (np.bool_, False)}


class ChainPolicy(KernelPolicy):
    """Hand-coded chain growth (rules and how they are carried out in the module docstring).

    Args:
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

    name = "chain"
    rule = staticmethod(chain_decide)

    def __init__(
        self,
        action_layout,
        modes,
        *,
        scent_max=65535,
        seed=None,
        p_seed=0.0,
        p_random=0.05,
        on_stuck="stay",
        fewer_neighbours=True,
        horizontal=True,
        clean_exit=True,
        turn=True,
        greedy_approach=True,
        wake_when_free=False,
        directed=True,
        momentum=1.0,
        queue=False,
        prefer_chain=True,
        avoid_octahedra=True,
    ):
        super().__init__(action_layout, modes, scent_max=scent_max, seed=seed)
        if not 0.0 <= p_seed <= 1.0:
            raise ValueError(f"p_seed={p_seed!r} is not allowed; allowed: a probability in [0, 1]")
        if not 0.0 <= p_random <= 1.0:
            raise ValueError(f"p_random={p_random!r} is not allowed; allowed: a probability in [0, 1]")
        if on_stuck not in ON_STUCK:
            raise ValueError(f"on_stuck={on_stuck!r} is not allowed; allowed: {', '.join(ON_STUCK)}")
        if momentum < 0:
            raise ValueError(f"momentum={momentum!r} is not allowed; allowed: a number >= 0")
        if avoid_octahedra not in (True, False, "all"):
            raise ValueError(f"avoid_octahedra={avoid_octahedra!r} is not allowed; allowed: True, False or 'all'")
        self.p_seed = p_seed
        self.p_random = p_random
        self.on_stuck = on_stuck
        self.fewer_neighbours = fewer_neighbours
        self.horizontal = horizontal
        self.clean_exit = clean_exit
        self.turn = turn
        self.greedy_approach = greedy_approach
        self.wake_when_free = wake_when_free
        self.directed = directed
        self.momentum = momentum
        self.queue = queue
        self.prefer_chain = prefer_chain
        self.avoid_octahedra = avoid_octahedra
        self.memory = ModuleMemory()
        """Private memory of every module (see :class:`ModuleMemory`)."""

    @property
    def rule_params(self) -> ChainRuleParams:
        """The parameters as the kernels of :mod:`baselines.chain_rules` read them."""
        octahedra = {False: OCTAHEDRA_OFF, True: OCTAHEDRA_CHAIN, "all": OCTAHEDRA_ALL}[self.avoid_octahedra]
        return ChainRuleParams(
            scent_max=int(self.scent_max),
            p_seed=float(self.p_seed),
            p_random=float(self.p_random),
            random_when_stuck=self.on_stuck == "random",
            fewer_neighbours=bool(self.fewer_neighbours),
            horizontal=bool(self.horizontal),
            clean_exit=bool(self.clean_exit),
            turn=bool(self.turn),
            greedy_approach=bool(self.greedy_approach),
            wake_when_free=bool(self.wake_when_free),
            directed=bool(self.directed),
            momentum=float(self.momentum),
            queue=bool(self.queue),
            prefer_chain=bool(self.prefer_chain),
            avoid_octahedra=octahedra,
        )

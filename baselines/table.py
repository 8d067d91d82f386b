"""The paper's table behaviour (section 4.3) as a policy over observations.

Rules, as the paper lists them. Root modules (ROOT, IROOT, AROOT; they never move):

- If in IROOT mode, if average weight per active root in its region is above a certain
  threshold F_max, with a small probability p_max: go to AROOT mode.
- If in AROOT mode, emit scent.
- If in ROOT mode, if average weight per active root in its region is below a certain
  threshold F_min, with a small probability p_min: set all FINAL and SEED neighbors to
  DISBAND mode, go to IROOT mode.

The other modules:

- If in SLEEP mode, if a scent is detected, go to SEARCH mode.
- If in SEARCH mode, propagate scent and move along its gradient; if there is a neighboring
  SEED or AROOT module and location is towards the ground with respect to this neighbor:
  if this neighbor is a SEED, set it to FINAL mode, otherwise set it to ROOT mode; go to
  SEED mode.
- If in SEED mode, if touching the ground, go to FINAL mode.
- If in FIXED or FINAL mode, transmit scent.
- If in DISBAND mode, set all FINAL and SEED neighbors to DISBAND mode, go to SEARCH mode.

How each rule is carried out through the agent interface (one module's observation in, one
action out; nothing else is read). Messages: ``1..12`` "my growth spot is
``DIRECTIONS[v - 1]`` from me", :data:`SPOT_TAKEN` "I took your growth spot",
:data:`DISBAND_NOW` "go DISBAND if you are FINAL or SEED".

- Average weight per active root: the root's ``load`` observation (the task's load sensor,
  the region's weight over its active roots). ``p_max``, ``p_min``, ``f_max`` and ``f_min``
  default to the task's parameters of the same names (static configuration, read once in
  :meth:`TablePolicy.for_env`).
- "Towards the ground" is made definite: a SEED or AROOT picks one of the 4 face sites one
  layer below it as its growth spot and broadcasts it every cycle (message ``spot + 1``), as
  the chain's seeds do. Spots that already hold a SLEEP or SEARCH module come first (that
  module takes over at once), then empty ones; a SEED prefers, among those, the zigzag spot
  on the side opposite its parent, so a leg is a two-column zigzag straight down. A spot
  that holds a module in another mode (FINAL, SEED, DISBAND) or ground is blocked and the
  seed picks another; a seed whose spot is empty switches to a spot below it where a module
  already waits. Without a single spot, two modules arriving under a seed at once would
  both become SEEDs and the leg would fork.
- SEARCH: a module at the broadcast spot of a SEED or AROOT neighbour (seen by the
  neighbour's mode and the broadcast from that side) goes SEED, emits scent, and sends
  :data:`SPOT_TAKEN` to it: "set it to FINAL / ROOT" is that message; the receiver changes
  its own mode next cycle. Next to a SEED or AROOT whose broadcast it heard, it rolls over
  that neighbour's faces towards the spot (the lowest such neighbour when there are
  several; a random legal roll with probability ``p_random`` when it is stuck); next to one
  it has not heard yet it holds still; otherwise it climbs the scent gradient with the chain's
  SEARCH rule (:class:`~baselines.chain.ChainPolicy`, staying put when stuck, no bias),
  computed for all such modules at once.
- "Set all FINAL and SEED neighbors to DISBAND" is :data:`DISBAND_NOW` sent to the leg's
  next module: the neighbour that took this module's spot (the side its
  :data:`SPOT_TAKEN` came from, kept in private memory). In a leg that is the only FINAL or
  SEED neighbour below; sending it there rather than to all neighbours keeps a disbanding
  leg from dissolving another leg that happens to touch it (which left a ROOT standing on
  nothing in early trials). A FINAL or SEED module told :data:`DISBAND_NOW` goes DISBAND;
  a DISBAND module passes the message on and goes SEARCH, so a leg dissolves from the top,
  one module per two cycles.
- SEED: a SEED touching the ground (``contact[0]``) or told :data:`SPOT_TAKEN` goes FINAL.
- Scent roles: AROOT and SEED emit; every other module relays (the passive FIXED board
  modules relay too).
- SLEEP relays scent and goes SEARCH when it or a neighbour carries scent.

Private memory per module (reset by :meth:`TablePolicy.reset`): its growth spot (SEED,
AROOT), the side of the seed it took over from (new SEED) and the side of its leg's next
module (ROOT, FINAL, DISBAND).

The rules run as the numba kernel :func:`baselines.table_rules.table_actions` on the
observation fields stacked over modules; the private memory is one row per module
(:class:`TableMemory`).
"""

from __future__ import annotations

import numpy as np

from proteo_env.tasks.table import AROOT, DISBAND, FINAL, FIXED, IROOT, ROOT, SEARCH, SEED, SLEEP

from .base import KernelPolicy, SlotMemory
from .table_rules import DISBAND_NOW, SPOT_TAKEN, TableRuleParams, table_decide

RULE_PARAMS = ("p_max", "p_min", "f_max", "f_min")


class TableMemory(SlotMemory):
    """The table rule's private memory of every module, one entry per memory slot.

    Attributes (S slots):
        spot: ``(S,)`` int64, the growth spot (a direction) of a SEED or AROOT (-1: none).
        parent: ``(S,)`` int64, the direction of the seed a new SEED took over from (-1: none).
        child: ``(S,)`` int64, the direction of the leg's next module (the one that took this
            module's spot), where its disband message goes (-1: none).
    """

    FIELDS = {"spot": (np.int64, -1), "parent": (np.int64, -1), "child": (np.int64, -1)}


class TablePolicy(KernelPolicy):
    """Hand-coded table legs (rules and how they are carried out in the module docstring).

    Args:
        p_max: probability per cycle that an IROOT over ``f_max`` goes AROOT (paper: 0.05).
        p_min: probability per cycle that a ROOT under ``f_min`` disbands its leg (paper: 0.05).
        f_max: load per active root above which an IROOT may go AROOT (paper: 2).
        f_min: load per active root below which a ROOT may disband (paper: 1).
        p_random: probability that a SEARCH module makes a random legal move instead of
            following the gradient (and that one stuck next to a seed moves at random).
    """

    name = "table"
    rule = staticmethod(table_decide)

    def __init__(
        self,
        action_layout,
        modes,
        *,
        scent_max=65535,
        seed=None,
        p_max=0.05,
        p_min=0.05,
        f_max=2.0,
        f_min=1.0,
        p_random=0.05,
    ):
        super().__init__(action_layout, modes, scent_max=scent_max, seed=seed)
        for name, value in (("p_max", p_max), ("p_min", p_min), ("p_random", p_random)):
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name}={value!r} is not allowed; allowed: a probability in [0, 1]")
        if not 0.0 <= f_min <= f_max:
            raise ValueError(f"f_min={f_min!r} is not allowed; allowed: a number in [0, f_max = {f_max}]")
        self.p_max, self.p_min, self.f_max, self.f_min = float(p_max), float(p_min), float(f_max), float(f_min)
        self.p_random = float(p_random)
        self.memory = TableMemory()
        """Private memory of every module (see :class:`TableMemory`)."""

    @classmethod
    def for_env(cls, env, *, seed=None, **params):
        """Build from the env's static interface; rule parameters default to the task's."""
        task_params = env.task.params
        rules = {k: getattr(task_params, k) for k in RULE_PARAMS if hasattr(task_params, k)}
        return super().for_env(env, seed=seed, **{**rules, **params})

    @property
    def rule_params(self) -> TableRuleParams:
        """The parameters as :func:`~baselines.table_rules.table_actions` reads them."""
        return TableRuleParams(
            scent_max=int(self.scent_max),
            p_max=self.p_max,
            p_min=self.p_min,
            f_max=self.f_max,
            f_min=self.f_min,
            p_random=self.p_random,
        )


__all__ = [
    "AROOT",
    "DISBAND",
    "DISBAND_NOW",
    "FINAL",
    "FIXED",
    "IROOT",
    "ROOT",
    "SEARCH",
    "SEED",
    "SLEEP",
    "SPOT_TAKEN",
    "TableMemory",
    "TablePolicy",
]

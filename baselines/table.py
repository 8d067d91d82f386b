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

The rules run as the numba kernel :func:`table_actions` (the policy's ``rule``) on the
observation fields stacked over modules; the private memory is one row per module
(:class:`TableMemory`).

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
L = 5 action fields): the chain's (:mod:`baselines.chain`), plus

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
from proteo_env.tasks.table import AROOT, DISBAND, FINAL, FIXED, IROOT, ROOT, SEARCH, SEED, SLEEP

from .base import KernelPolicy, SlotMemory
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
def table_actions(seen, slots, memory, rules, rng, actions):
    """Write every row's table action into ``actions`` (A, 5) and update the memory of its slot.

    Shapes and draws: module docstring. ``rules``: :class:`TableRuleParams`.
    """
    own_mode, messages, own_scent, action_mask = seen.own_mode, seen.messages, seen.own_scent, seen.action_mask
    contact, load = seen.contact, seen.load
    neighbour_kind, neighbour_mode, neighbour_scent = seen.neighbour_kind, seen.neighbour_mode, seen.neighbour_scent
    spot, parent, child = memory
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


RULE_PARAMS = ("p_max", "p_min", "f_max", "f_min")


class TableRuleParams(NamedTuple):
    """The table rule's parameters, :class:`TablePolicy`'s keywords (``scent_max``: the scent
    value that means "no scent").

    Attributes:
        p_max: probability per cycle that an IROOT over ``f_max`` goes AROOT (paper: 0.05).
        p_min: probability per cycle that a ROOT under ``f_min`` disbands its leg (paper: 0.05).
        f_max: load per active root above which an IROOT may go AROOT (paper: 2).
        f_min: load per active root below which a ROOT may disband (paper: 1).
        p_random: probability that a SEARCH module makes a random legal move instead of
            following the gradient (and that one stuck next to a seed moves at random).
    """

    scent_max: int = 65535
    p_max: float = 0.05
    p_min: float = 0.05
    f_max: float = 2.0
    f_min: float = 1.0
    p_random: float = 0.05

    def check(self) -> None:
        """A ``ValueError`` for a value not allowed."""
        for name in ("p_max", "p_min", "p_random"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name}={getattr(self, name)!r} is not allowed; allowed: a probability in [0, 1]")
        if not 0.0 <= self.f_min <= self.f_max:
            raise ValueError(f"f_min={self.f_min!r} is not allowed; allowed: a number in [0, f_max = {self.f_max}]")


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
    """Hand-coded table legs (rules and how they are carried out in the module docstring;
    parameters: :class:`TableRuleParams`)."""

    name = "table"
    Params = TableRuleParams
    Memory = TableMemory
    rule = staticmethod(table_actions)

    @classmethod
    def for_env(cls, env, *, seed=None, **params):
        """Build from the env's static interface; rule parameters default to the task's."""
        task_params = env.task.params
        rules = {k: getattr(task_params, k) for k in RULE_PARAMS if hasattr(task_params, k)}
        return super().for_env(env, seed=seed, **{**rules, **params})


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

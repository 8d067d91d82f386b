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

The rules run as the numba kernel :func:`grasp_actions` (the policy's ``rule``) on the
observation fields stacked over modules; every decision reads only that agent's own
observation and private memory (:class:`GraspMemory`, one row per module).

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
L = 6 action fields): the chain's (:mod:`baselines.chain`), plus ``contact`` (A, 2) int8
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

from .base import KernelPolicy, SlotMemory
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
TOUCH_CHANNEL = 1
"""The touch scent's channel (``GraspRuleParams.prefer_touch``)."""
FLAT_STAY, FLAT_RANDOM = range(2)
"""``GraspRuleParams.on_flat`` as the kernels read it: ``"stay"``, ``"random"``."""


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
    ``on_flat`` random, as a bit set."""
    smax = rules.scent_max
    channel = 0
    if rules.prefer_touch:
        for k in range(12):
            if neighbour_kind[i, k] == KIND_MODULE and neighbour_scent[i, k, TOUCH_CHANNEL] < smax:
                channel = TOUCH_CHANNEL
    scent = np.empty(12, dtype=np.int64)
    here = FAR
    for k in range(12):
        scent[k] = neighbour_scent[i, k, channel] if neighbour_kind[i, k] == KIND_MODULE else smax
        here = min(here, scent[k])
    legal = legal_bits(action_mask, i)
    pool, low = lowest_rolls(scent, legal)
    if low <= here and low < smax:
        return pool
    return legal if rules.on_flat == FLAT_RANDOM else 0


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
def grasp_actions(seen, slots, memory, rules, rng, actions):
    """Write every row's grasp action into ``actions`` (A, 6) and update the memory of its slot.

    Shapes and the order of draws: module docstring. ``rules``: :class:`GraspRuleParams`.
    """
    own_mode, messages, action_mask = seen.own_mode, seen.messages, seen.action_mask
    contact, hint = seen.contact, seen.hint
    neighbour_kind, neighbour_mode, neighbour_scent = seen.neighbour_kind, seen.neighbour_mode, seen.neighbour_scent
    growth, waited, stuck, age, previous = memory
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


class GraspRuleParams(NamedTuple):
    """The grasp rule's parameters, :class:`GraspPolicy`'s keywords (``scent_max``: the scent
    value that means "no scent").

    Attributes:
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

    scent_max: int = 65535
    p_random: float = 0.05
    on_flat: str = "stay"
    patience: int = 30
    touch_first: bool = True
    greedy_approach: bool = True
    relocate: bool = True
    touch_patience: int = 30
    retire: bool = True
    retire_after: int = 150
    straight: bool = True
    wrap_forward: bool = True
    prefer_touch: bool = True

    CHOICES = {"on_flat": ("stay", "random")}

    def check(self) -> None:
        """A ``ValueError`` for a value not allowed."""
        if not 0.0 <= self.p_random <= 1.0:
            raise ValueError(f"p_random={self.p_random!r} is not allowed; allowed: a probability in [0, 1]")
        for name in ("patience", "touch_patience", "retire_after"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}={value!r} is not allowed; allowed: an integer >= 1")


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
    """Hand-coded grasping (rules and how they are carried out in the module docstring;
    parameters: :class:`GraspRuleParams`)."""

    name = "grasp"
    Params = GraspRuleParams
    Memory = GraspMemory
    rule = staticmethod(grasp_actions)

    def __init__(self, action_layout, modes, **params):
        if action_layout.n_channels != 2:
            raise ValueError(
                f"action_layout with n_channels={action_layout.n_channels} is not allowed; allowed: 2 (the grasp "
                "task's seed and touch scents)"
            )
        super().__init__(action_layout, modes, **params)


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

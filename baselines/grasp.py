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
``docs/grasp_evidence.md`` measures both):

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

The policy decides for all agents of a cycle at once (the SLEEP, FINAL, TOUCH and climbing
SEARCH modules as arrays, the few modules next to a seed one by one); every decision reads
only that agent's own observation and private memory.
"""

from __future__ import annotations

import numpy as np

from proteo_env.core.lattice import DIRECTIONS, OPPOSITE
from proteo_env.core.world import DIRECTION_ADJACENCY
from proteo_env.spaces import EMIT, KIND_EMPTY, KIND_MODULE, KIND_OBJECT, MESSAGE_TO_ALL, RELAY, SILENT

from .base import Policy
from .primitives import face_index

SLEEP, SEARCH, SEED, FINAL, TOUCHSEED, TOUCH = range(6)

SET_FINAL = 13
"""Message value: "go FINAL" (the searcher that takes over to the SEED it replaces)."""
SET_TOUCH = 14
"""Message value: "go TOUCH" (a searcher touching the object to the SEED or TOUCHSEED it replaces)."""
PASS_SEED = 15
"""Message value: "become TOUCHSEED" (a stuck TOUCHSEED to a TOUCH neighbour; ``relocate`` only)."""
# values 1..12: a SEED's broadcast "my growth site is DIRECTIONS[value - 1]"


class GraspPolicy(Policy):
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

    def __init__(self, layout, modes, *, scent_max=65535, seed=None, p_random=0.05, on_flat="stay",
                 patience=30, touch_first=True, greedy_approach=True, relocate=True, touch_patience=30,
                 retire=True, retire_after=150, straight=True, wrap_forward=True, prefer_touch=True):
        super().__init__(layout, modes, scent_max=scent_max, seed=seed)
        if not 0.0 <= p_random <= 1.0:
            raise ValueError(f"p_random={p_random!r} is not allowed; allowed: a probability in [0, 1]")
        if on_flat not in ("stay", "random"):
            raise ValueError(f"on_flat={on_flat!r} is not allowed; allowed: stay, random")
        for name, value in (("patience", patience), ("touch_patience", touch_patience),
                            ("retire_after", retire_after)):
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
        self.growth: dict[str, int] = {}
        """Private memory of each SEED: its growth direction."""
        self.waited: dict[str, int] = {}
        """Private memory of each SEED and TOUCHSEED: cycles waited for a hand-over."""
        self.stuck: dict[str, int] = {}
        """Private memory of each SEED: cycles in a row without a growth site."""
        self.age: dict[str, int] = {}
        """Private memory of each SEED: cycles since it became SEED."""
        self.previous: dict[str, int] = {}
        """Private memory of each SEED: the step that made it (the direction it grew the finger)."""

        channels = layout.n_channels
        self._relay = [RELAY] * channels
        self._emit_seed = [EMIT] + [RELAY] * (channels - 1)
        self._emit_touch = [EMIT] * channels
        self._touch_channel = 1 if channels > 1 and prefer_touch else -1

    def reset(self, seed=None):
        super().reset(seed)
        self.growth.clear()
        self.waited.clear()
        self.stuck.clear()
        self.previous.clear()
        self.age.clear()

    # ------------------------------------------------------------------ all agents
    def act(self, observations):
        agents = list(observations)
        if not agents:
            return {}
        obs = [observations[a] for a in agents]
        lay = self.layout
        mode = np.array([o["own_mode"][0] for o in obs], dtype=np.int64)
        actions = np.zeros((len(agents), lay.length), dtype=np.int64)
        actions[:, lay.mode] = mode
        actions[:, lay.roles] = RELAY

        sleeping = np.flatnonzero(mode == SLEEP)
        if sleeping.size:
            smax = self.scent_max
            detected = np.array([o["neighbour_scent"][:12, 0].min() < smax for o in (obs[i] for i in sleeping)])
            actions[sleeping, lay.mode] = np.where(detected, SEARCH, SLEEP)
            actions[sleeping, lay.roles] = np.where(detected, RELAY, SILENT)[:, None]

        searching = np.flatnonzero(mode == SEARCH)
        if searching.size:
            self._search(agents, obs, searching, actions)
        for i in np.flatnonzero(mode == SEED):
            actions[i] = self._seed(agents[i], obs[i])
        for i in np.flatnonzero(mode == TOUCHSEED):
            actions[i] = self._touch_seed(agents[i], obs[i])
        if self.relocate:
            for i in np.flatnonzero(mode == TOUCH):
                if (obs[i]["messages"] == PASS_SEED).any():
                    self.waited[agents[i]] = 0
                    actions[i, lay.mode] = TOUCHSEED
                    actions[i, lay.roles] = self._emit_touch
        return dict(zip(agents, actions))

    # ------------------------------------------------------------------ SEARCH
    def _search(self, agents, obs, idx, actions) -> None:
        lay = self.layout
        nb_mode = np.array([obs[i]["neighbour_mode"][:12] for i in idx])
        is_seed = (nb_mode == SEED) | (nb_mode == TOUCHSEED)
        near_seed = is_seed.any(axis=1)
        climbers = idx[~near_seed]
        if climbers.size:
            actions[climbers, lay.move] = self._climb([obs[i] for i in climbers])
        for row in np.flatnonzero(near_seed):
            i = idx[row]
            o = obs[i]
            seeds = np.flatnonzero(is_seed[row])
            if o["contact"][1]:
                actions[i] = lay.encode(mode=TOUCHSEED, roles=self._emit_touch, message_target=int(seeds[0]),
                                        message_value=SET_TOUCH)
                continue
            plain = seeds[nb_mode[row, seeds] == SEED]
            if plain.size:
                actions[i] = self._near_seed(agents[i], o, plain)
            else:
                actions[i, lay.move] = self._around(o, int(seeds[0]))

    def _climb(self, obs: list) -> np.ndarray:
        """``(S,)`` gradient moves of the climbing searchers (module docstring)."""
        smax = self.scent_max
        mask = np.array([o["action_mask"][1:] for o in obs], dtype=bool)
        kind = np.array([o["neighbour_kind"][:12] for o in obs])
        scent = np.array([o["neighbour_scent"][:12, 0] for o in obs], dtype=np.int64)
        if self._touch_channel >= 0:  # follow the touch scent wherever it is smelt
            touch = np.array([o["neighbour_scent"][:12, self._touch_channel] for o in obs], dtype=np.int64)
            smelt = (np.where(kind == KIND_MODULE, touch, smax) < smax).any(axis=1)
            scent[smelt] = touch[smelt]
        scent[kind != KIND_MODULE] = smax
        here = scent.min(axis=1)
        there = scent[:, DIRECTION_ADJACENCY].min(axis=2)
        there[~mask] = np.iinfo(np.int64).max
        best = there.min(axis=1)
        keeps = (best <= here) & (best < smax)
        pool = (there == best[:, None]) & mask & keeps[:, None]
        rng = self.rng
        if self.on_flat == "random":
            stuck = ~keeps & mask.any(axis=1)
            pool[stuck] = mask[stuck]
        jump = rng.random(len(obs)) < self.p_random
        pool[jump] = mask[jump]
        keys = rng.random(pool.shape)
        keys[~pool] = -1.0
        return np.where(pool.any(axis=1), keys.argmax(axis=1) + 1, 0)

    def _near_seed(self, agent: str, o, plain: np.ndarray) -> np.ndarray:
        """Next to a SEED (not touching the object): take over at its growth site or go there."""
        lay = self.layout
        msgs = o["messages"]
        for slot in plain:
            slot = int(slot)
            value = int(msgs[slot])
            if not 1 <= value <= 12:
                continue
            growth = value - 1
            if OPPOSITE[growth] == slot:  # this is the seed's growth site
                self.previous[agent] = growth
                return lay.encode(mode=SEED, roles=self._emit_seed, message_target=slot, message_value=SET_FINAL)
            return lay.encode(move=self._approach(o, slot, growth), mode=SEARCH, roles=self._relay)
        return lay.encode(mode=SEARCH, roles=self._relay)  # growth not heard from here yet: hold still

    def _approach(self, o, slot: int, growth: int) -> int:
        """A roll towards the growth site ``seed + DIRECTIONS[growth]`` of the seed at ``slot``.

        If the site is a neighbour site and the roll there is legal, take it; otherwise roll
        over the seed's faces (rolls that keep the seed as a neighbour), with
        ``greedy_approach`` among those that end nearest the site, else at random; 0 if none.
        """
        spot = DIRECTIONS[slot] + DIRECTIONS[growth]
        mask = o["action_mask"]
        k = face_index(spot)
        if k >= 0 and mask[k + 1]:
            return k + 1
        legal = np.flatnonzero(mask[1:])
        legal = legal[(DIRECTION_ADJACENCY[legal] == slot).any(axis=1)]
        if legal.size == 0:
            return 0
        if self.greedy_approach:
            dist = ((spot[None, :] - DIRECTIONS[legal]) ** 2).sum(axis=1)
            legal = legal[dist == dist.min()]
        return int(legal[self.rng.integers(legal.size)]) + 1

    def _around(self, o, slot: int) -> int:
        """The paper's "random move" next to the TOUCHSEED at ``slot`` (module docstring)."""
        legal = np.flatnonzero(o["action_mask"][1:])
        if legal.size == 0:
            return 0
        keep = legal[(DIRECTION_ADJACENCY[legal] == slot).any(axis=1)]
        if keep.size and self.touch_first:
            kinds = o["neighbour_kind"][:12]
            touching = keep[(kinds[DIRECTION_ADJACENCY[keep]] == KIND_OBJECT).any(axis=1)]
            if touching.size:
                keep = touching
        if keep.size > 1 and self.wrap_forward:
            ahead = keep[DIRECTIONS[keep] @ o["hint"] > 0]
            if ahead.size:
                keep = ahead
        pool = keep if keep.size else legal
        return int(pool[self.rng.integers(pool.size)]) + 1

    # ------------------------------------------------------------------ seeds
    def _seed(self, agent: str, o) -> np.ndarray:
        lay = self.layout
        msgs = o["messages"]
        if (msgs == SET_TOUCH).any():
            self._forget(agent)
            return lay.encode(mode=TOUCH, roles=self._relay)
        if (msgs == SET_FINAL).any():
            self._forget(agent)
            return lay.encode(mode=FINAL, roles=self._relay)
        growth = self.growth.get(agent, -1)
        waited = self.waited.get(agent, 0) + 1
        avoid = -1
        if growth >= 0:
            kind = o["neighbour_kind"][growth]
            taken = kind != KIND_EMPTY and not (kind == KIND_MODULE and o["neighbour_mode"][growth] in (SLEEP, SEARCH))
            if taken or waited > self.patience:
                avoid = growth if not taken else -1
                growth = -1
        if growth < 0:
            growth = self._growth_direction(o, self.previous.get(agent, -1) if avoid < 0 else -1, avoid)
            waited = 0
        age = self.age.get(agent, 0) + 1
        self.age[agent] = age
        stuck = self.stuck.get(agent, 0) + 1 if growth < 0 else 0
        self.stuck[agent] = stuck
        if self.retire and not o["contact"][1] and (stuck > self.patience or age > self.retire_after):
            self._forget(agent)
            return lay.encode(mode=FINAL, roles=self._relay)
        if growth < 0:  # nowhere to grow (yet)
            self.growth.pop(agent, None)
            return lay.encode(mode=SEED, roles=self._emit_seed)
        self.growth[agent] = growth
        self.waited[agent] = waited
        return lay.encode(mode=SEED, roles=self._emit_seed, message_target=MESSAGE_TO_ALL, message_value=growth + 1)

    def _growth_direction(self, o, previous: int, avoid: int) -> int:
        """The growth site of a seed (module docstring), or -1 when there is none.

        Candidates are the empty neighbour sites whose direction has a positive dot product
        with the hint (``avoid`` excluded while there are others). With ``straight`` and the
        finger's previous step known, the site that makes the last two steps point most
        nearly along the hint (ties at random); otherwise one drawn with probability
        proportional to the dot product.
        """
        hint = o["hint"].astype(np.float64)
        dots = DIRECTIONS @ hint
        cand = np.flatnonzero((o["neighbour_kind"][:12] == KIND_EMPTY) & (dots > 1e-9))
        if cand.size > 1 and avoid >= 0:
            cand = cand[cand != avoid]
        if cand.size == 0:
            return -1
        if self.straight and previous >= 0:
            two = DIRECTIONS[cand] + DIRECTIONS[previous]
            cos = (two @ hint) / np.maximum(np.linalg.norm(two, axis=1), 1e-12)
            cand = cand[cos >= cos.max() - 1e-9]
            return int(cand[self.rng.integers(cand.size)])
        w = dots[cand]
        return int(cand[self.rng.choice(cand.size, p=w / w.sum())])

    def _touch_seed(self, agent: str, o) -> np.ndarray:
        lay = self.layout
        if (o["messages"] == SET_TOUCH).any():
            self._forget(agent)
            return lay.encode(mode=TOUCH, roles=self._relay)
        if self.relocate:
            waited = self.waited.get(agent, 0) + 1
            self.waited[agent] = waited
            kinds = o["neighbour_kind"][:12]
            empty = np.flatnonzero(kinds == KIND_EMPTY)
            open_site = bool((kinds[DIRECTION_ADJACENCY[empty]] == KIND_OBJECT).any()) if empty.size else False
            touch = np.flatnonzero(o["neighbour_mode"][:12] == TOUCH)
            if touch.size and (not open_site or waited > self.touch_patience):
                self._forget(agent)
                if touch.size > 1 and self.wrap_forward:
                    ahead = touch[DIRECTIONS[touch] @ o["hint"] > 0]
                    if ahead.size:
                        touch = ahead
                slot = int(touch[self.rng.integers(touch.size)])
                return lay.encode(mode=TOUCH, roles=self._relay, message_target=slot, message_value=PASS_SEED)
        return lay.encode(mode=TOUCHSEED, roles=self._emit_touch)

    def _forget(self, agent: str) -> None:
        self.growth.pop(agent, None)
        self.waited.pop(agent, None)
        self.stuck.pop(agent, None)
        self.previous.pop(agent, None)
        self.age.pop(agent, None)

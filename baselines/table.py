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
  computed for all such modules at once (:func:`climb_batch`).
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

Cheap paths: FINAL, FIXED, SLEEP without scent, IROOT and ROOT inside their thresholds
(most agents in a settled table) return a fixed action without further reading.
"""

from __future__ import annotations

import numpy as np

from proteo_env.core.lattice import DIRECTIONS, OPPOSITE
from proteo_env.core.world import DIRECTION_ADJACENCY
from proteo_env.spaces import EMIT, KIND_EMPTY, KIND_MODULE, MESSAGE_TO_ALL, RELAY

from .base import Policy
from .primitives import approach_growth_spot, face_index, scent_detected

FIXED, ROOT, IROOT, AROOT, SLEEP, SEARCH, SEED, FINAL, DISBAND = range(9)

SPOT_TAKEN = 13
"""Message: "I took your growth spot" (a SEED goes FINAL, an AROOT goes ROOT)."""
DISBAND_NOW = 14
"""Message: "go DISBAND" (obeyed by FINAL and SEED modules)."""

DOWN = np.flatnonzero(DIRECTIONS[:, 2] == -1)
"""The 4 face directions one layer down (the candidate growth spots of a seed)."""
UP = DIRECTIONS[:, 2] == 1
ZIGZAG = np.array([face_index((d[0], d[1], -1)) if d[2] == 1 else -1 for d in DIRECTIONS], dtype=np.int64)
"""For a parent in direction ``k`` (up), the down direction on the opposite side of the leg."""
RULE_PARAMS = ("p_max", "p_min", "f_max", "f_min")
MOVABLE_AT_SPOT = (SLEEP, SEARCH)


class TablePolicy(Policy):
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

    def __init__(self, layout, modes, *, scent_max=65535, seed=None, p_max=0.05, p_min=0.05, f_max=2.0,
                 f_min=1.0, p_random=0.05):
        super().__init__(layout, modes, scent_max=scent_max, seed=seed)
        for name, value in (("p_max", p_max), ("p_min", p_min), ("p_random", p_random)):
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name}={value!r} is not allowed; allowed: a probability in [0, 1]")
        if not 0.0 <= f_min <= f_max:
            raise ValueError(f"f_min={f_min!r} is not allowed; allowed: a number in [0, f_max = {f_max}]")
        self.p_max, self.p_min, self.f_max, self.f_min = p_max, p_min, f_max, f_min
        self.p_random = p_random
        self.spot: dict[str, int] = {}
        """Private memory of each SEED and AROOT: its growth spot (a direction)."""
        self.parent: dict[str, int] = {}
        """Private memory of each new SEED: the direction of the seed it took over from."""
        self.child: dict[str, int] = {}
        """Private memory of each ROOT and leg module: the direction of the leg's next module
        (the one that took its spot), where its disband message goes."""
        encode = layout.encode
        self._still = {m: encode(mode=m, roles=[RELAY]) for m in range(len(self.modes))}

    @classmethod
    def for_env(cls, env, *, seed=None, **params):
        """Build from the env's static interface; rule parameters default to the task's."""
        task_params = env.task.params
        rules = {k: getattr(task_params, k) for k in RULE_PARAMS if hasattr(task_params, k)}
        return cls(env.action_layout, env.task.modes, scent_max=env.config.physics.scent_max, seed=seed,
                   **{**rules, **params})

    def reset(self, seed=None):
        super().reset(seed)
        self.spot.clear()
        self.parent.clear()
        self.child.clear()

    def act(self, observations):
        actions = {}
        climbers = []
        for agent, obs in observations.items():
            if int(obs["own_mode"][0]) == SEARCH and not _next_to_seed(obs):
                climbers.append(agent)
            else:
                actions[agent] = self.decide(agent, obs)
        if climbers:
            moves = climb_batch([observations[a] for a in climbers], self.scent_max, self.rng, self.p_random)
            search = self._still[SEARCH]
            for agent, move in zip(climbers, moves.tolist()):
                action = search.copy()
                action[self.layout.move] = move
                actions[agent] = action
        return {agent: actions[agent] for agent in observations}

    # ------------------------------------------------------------------ one module
    def decide(self, agent: str, obs) -> np.ndarray:
        mode = int(obs["own_mode"][0])
        messages = obs["messages"]
        heard = bool(messages.any())
        disband = heard and bool((messages == DISBAND_NOW).any())
        if mode == FINAL:
            return self._still[DISBAND if disband else FINAL].copy()
        if mode == IROOT:
            if obs["load"][0] > self.f_max and self.rng.random() < self.p_max:
                return self._seed(agent, obs, AROOT)
            return self._still[IROOT].copy()
        if mode == ROOT:
            if obs["load"][0] < self.f_min and self.rng.random() < self.p_min:
                return self._disband_leg(agent, IROOT)
            return self._still[ROOT].copy()
        if mode in (AROOT, SEED):
            taken = _slot_of(messages, SPOT_TAKEN) if heard else -1
            if taken >= 0:  # the module below took the spot: it is this leg's next module
                self.child[agent] = taken
            if mode == SEED and disband:
                self._forget(agent, keep_child=True)
                return self._still[DISBAND].copy()
            if taken >= 0 or (mode == SEED and obs["contact"][0]):
                self._forget(agent, keep_child=True)
                return self._still[ROOT if mode == AROOT else FINAL].copy()
            return self._seed(agent, obs, mode)
        if mode == DISBAND:
            return self._disband_leg(agent, SEARCH)
        if mode == SLEEP:
            if scent_detected(obs, 0, self.scent_max):
                return self._still[SEARCH].copy()
            return self._still[SLEEP].copy()
        if mode == SEARCH:
            return self._search(agent, obs)
        return self._still[mode].copy()  # FIXED (board modules are passive; an agent never is)

    def _disband_leg(self, agent: str, new_mode: int) -> np.ndarray:
        """Go ``new_mode`` and tell this leg's next module (if any) to disband."""
        child = self.child.pop(agent, -1)
        self._forget(agent)
        if child < 0:
            return self._still[new_mode].copy()
        return self.layout.encode(mode=new_mode, roles=[RELAY], message_target=child, message_value=DISBAND_NOW)

    def _forget(self, agent: str, keep_child: bool = False) -> None:
        self.spot.pop(agent, None)
        self.parent.pop(agent, None)
        if not keep_child:
            self.child.pop(agent, None)

    # ------------------------------------------------------------------ SEARCH
    def _search(self, agent: str, obs) -> np.ndarray:
        encode = self.layout.encode
        shown = obs["neighbour_mode"][:12]
        seeds = np.flatnonzero((shown == SEED) | (shown == AROOT))
        if seeds.size == 0:
            move = int(climb_batch([obs], self.scent_max, self.rng, self.p_random)[0])
            return encode(move=move, mode=SEARCH, roles=[RELAY])
        messages = obs["messages"]
        spots = messages[seeds] - 1  # each seed's broadcast spot, -1 or other values if none heard
        at_spot = seeds[spots == OPPOSITE[seeds]]
        if at_spot.size:  # "towards the ground w.r.t. this neighbour": take its spot, become the SEED
            slot = int(at_spot[0])
            self._forget(agent)
            self.parent[agent] = slot
            return encode(mode=SEED, roles=[EMIT], message_target=slot, message_value=SPOT_TAKEN)
        heard = seeds[(spots >= 0) & (spots < 12)]
        if heard.size == 0:
            return encode(mode=SEARCH, roles=[RELAY])  # next to a seed not heard yet: hold still
        lowest = heard[DIRECTIONS[heard, 2] == DIRECTIONS[heard, 2].min()]
        slot = int(self.rng.choice(lowest))
        move = approach_growth_spot(obs, slot, int(messages[slot]) - 1, self.rng, greedy=True)
        if move == 0 and self.p_random > 0 and self.rng.random() < self.p_random:
            move = self.random_legal_move(obs["action_mask"])
        return encode(move=move, mode=SEARCH, roles=[RELAY])

    # ------------------------------------------------------------------ SEED and AROOT
    def _blocked(self, obs, k: int) -> bool:
        kind = obs["neighbour_kind"][k]
        if kind == KIND_MODULE:
            return int(obs["neighbour_mode"][k]) not in MOVABLE_AT_SPOT
        return kind != KIND_EMPTY

    def _choose_spot(self, agent: str, obs) -> int:
        """A growth spot one layer down; -1 when all 4 are blocked.

        Spots that already hold a SLEEP or SEARCH module come first (it takes over at once),
        then empty ones; within each, a SEED with a parent prefers the zigzag spot.
        """
        free = [int(k) for k in DOWN if not self._blocked(obs, int(k))]
        if not free:
            return -1
        occupied = [k for k in free if obs["neighbour_kind"][k] == KIND_MODULE]
        pool = occupied or free
        parent = self.parent.get(agent, -1)
        if parent >= 0 and int(ZIGZAG[parent]) in pool:
            return int(ZIGZAG[parent])
        return int(self.rng.choice(pool))

    def _seed(self, agent: str, obs, mode: int) -> np.ndarray:
        spot = self.spot.get(agent, -1)
        kind = obs["neighbour_kind"]
        if spot < 0 or self._blocked(obs, spot):
            spot = self._choose_spot(agent, obs)
        elif kind[spot] != KIND_MODULE and any(kind[k] == KIND_MODULE and not self._blocked(obs, int(k))
                                               for k in DOWN):
            spot = self._choose_spot(agent, obs)  # a module already waits at another spot below
        if spot < 0:
            self.spot.pop(agent, None)
            return self.layout.encode(mode=mode, roles=[EMIT])
        self.spot[agent] = spot
        return self.layout.encode(mode=mode, roles=[EMIT], message_target=MESSAGE_TO_ALL, message_value=spot + 1)


def _next_to_seed(obs) -> bool:
    shown = obs["neighbour_mode"][:12]
    return bool(((shown == SEED) | (shown == AROOT)).any())


def climb_batch(observations: list, scent_max: int, rng: np.random.Generator, p_random: float) -> np.ndarray:
    """``(Q,)`` moves (0 or ``k + 1``) along the scent gradient for ``Q`` observations at once.

    The chain's SEARCH rule (:class:`~baselines.chain.ChainPolicy`; staying when stuck), vectorised
    over modules so that a table with a hundred searching modules stays cheap: the value
    at a target site is one more than the smallest scent seen next to it (the 4 face sites
    adjacent to both here and there); a module takes a random legal roll among those of
    lowest value when that value is no worse than its value here, and stays otherwise; with
    probability ``p_random`` it takes a uniformly random legal roll instead.
    """
    kind = np.stack([o["neighbour_kind"][:12] for o in observations])
    scent = np.stack([o["neighbour_scent"][:12, 0] for o in observations]).astype(np.int64)
    legal = np.stack([o["action_mask"][1:] for o in observations]).astype(bool)
    scent = np.where(kind == KIND_MODULE, scent, scent_max)
    there = 1 + scent[:, DIRECTION_ADJACENCY].min(axis=2)
    here = 1 + scent.min(axis=1)
    big = np.iinfo(np.int64).max
    there = np.where(legal, there, big)
    best = there.min(axis=1)
    pool = legal & (there == best[:, None]) & (best <= here)[:, None]
    wild = rng.random(len(observations)) < p_random
    pool = np.where(wild[:, None], legal, pool)
    keys = rng.random(pool.shape) * pool
    moves = keys.argmax(axis=1) + 1
    return np.where(pool.any(axis=1), moves, 0)


def _slot_of(messages: np.ndarray, value: int) -> int:
    """The direction slot a message ``value`` came from, or -1."""
    hits = np.flatnonzero(messages == value)
    return int(hits[0]) if hits.size else -1

"""The paper's recursive branching behaviour (section 4.2) as a policy over observations.

Rules, as the paper lists them (modes SLEEP, SEARCH, SEED, FINAL, NODE, INODE; a *regular*
scent on channel 0 and a *node* scent on channel 1):

- If in SLEEP mode, if regular scent is detected, go to SEARCH mode.
- If in SEARCH mode, propagate both scents and move along the regular scent gradient.
- If in SEED mode, propagate the node scent, and emit a regular scent; if there is a
  neighbouring module in the direction of growth of the branch, set that module to be a
  seed, and go to FINAL mode.
- If in FINAL mode, propagate both scents; if the node scent is weak (i.e., has a value
  greater than some threshold ``T``), go to NODE mode.
- If in NODE mode, emit both scents, spawn seeds in random directions, until a certain count
  is reached ``B``, then go to INODE mode.
- If in INODE mode, emit a node scent and propagate the regular scent.

Growth starts from one NODE that the task places near the blob's centre (the paper's module
that "randomly decides to switch to the NODE mode", chosen centrally); with ``p_node > 0`` a
SLEEP module that detects no scent becomes a NODE with that probability each cycle instead.

How each rule is carried out through the agent interface (one module's observation in, one
action out, plus the module's own private memory; nothing else is read). SEARCH and SEED
reuse the chain behaviour (:class:`baselines.chain.ChainPolicy`) unchanged except that the
modes of the grown tree (SEED, FINAL, NODE, INODE) all count as "the structure":

- SLEEP: relays the regular scent (so that it spreads through the blob), is silent on the
  node scent (so that node distances are measured along the tree and the searching crowd,
  not through the unused blob), and goes SEARCH when it or a neighbour carries regular scent.
- SEARCH: relays both scents (with ``search_relays_node``, the paper's rule; off, it is
  silent on the node scent) and climbs the regular gradient exactly as the chain's SEARCH
  (:func:`baselines.kernels.search_moves`), seeing a NODE neighbour as a seed (it rolls over the
  node's faces to the growth spot the node broadcasts) and an INODE neighbour as FINAL.
- SEED: emits the regular scent, relays the node scent, and otherwise is the chain's seed:
  it broadcasts its growth direction; a SLEEP or SEARCH module at its growth site gets the
  message ``BECOME_SEED`` and the seed goes FINAL in the same action; the receiver grows on
  in the same direction. A seed whose growth site is blocked (solid, the wall, or a site
  touching a grown module other than itself: SEED, FINAL, NODE, INODE) turns by at most 90
  degrees; growth stays in the horizontal plane of the first node (``horizontal``).
- Refusal (not in the paper; ``refuse``): a seed sees only 4 of its growth site's 11 other
  neighbours, and in the horizontal plane none of the in-plane ones, so a branch could grow
  into the side of another. The module asked to become a seed sees its own neighbours: when
  one of them, other than the sender, is a grown module, it stays as it is and answers
  ``REFUSE`` (14) to the sender. A FINAL module that gets ``REFUSE`` becomes a SEED again and
  turns (it remembers the refused direction); a NODE or INODE counts one seed fewer (an
  INODE goes back to NODE) and does not use that direction again.
- FINAL: relays both scents; when its own node scent is known and greater than ``T`` and no
  neighbour is a NODE or INODE (so two adjacent modules never both turn into nodes while the
  new node's scent is still one hop away), it goes NODE.
- NODE: emits both scents. "Spawn seeds in random directions until a count B is reached":
  the node keeps in private memory the number of seeds spawned and its current growth spot,
  a uniformly random choice among the neighbour sites (horizontal ones with
  ``horizontal``) that hold no grown module and whose seen neighbours (the 4 sites next to
  both the node and the spot) hold no grown module; when its spot has stayed empty for
  ``patience`` cycles it chooses again (under the stricter motion models a module may have no roll into a given site).
  It broadcasts that direction (message ``growth + 1``, like a seed) so that searching
  modules come to the spot; when a SLEEP module, or a SEARCH module that has heard the
  broadcast and therefore holds still, is at the spot, the node sends it ``BECOME_SEED``:
  the receiver becomes a SEED growing straight away from the node (the message arrived from
  the opposite side). After ``B`` seeds, or when no site is left, the node goes INODE. In
  the horizontal plane a node has at most 4 free directions (3 on a branch), so ``B`` above
  that is capped by the geometry.
- INODE: emits the node scent, relays the regular scent, never moves.
"""

from __future__ import annotations

import numpy as np

from proteo_env.core.lattice import OPPOSITE
from proteo_env.spaces import EMIT, KIND_EMPTY, KIND_MODULE, MESSAGE_TO_ALL, RELAY, SILENT

from .chain import ChainPolicy, Observed
from .kernels import BECOME_SEED
from .primitives import HORIZONTAL, first_slot, growth_direction, spot_touches

REFUSE = 14
"""Message value: "I will not become your seed: I touch another part of the tree"."""

SLEEP, SEARCH, SEED, FINAL, NODE, INODE = range(6)
GROWN = (SEED, FINAL, NODE, INODE)


class BranchPolicy(ChainPolicy):
    """Hand-coded recursive branching (rules and how they are carried out in the module docstring).

    Args:
        T: node-scent threshold (paper 12); a FINAL module with node scent above it goes NODE.
        B: seeds a NODE spawns before going INODE (paper 6).
        p_node: per-cycle probability that a SLEEP module with no scent around becomes a NODE
            (0: rely on the task's central first node).
        search_relays_node: SEARCH modules relay the node scent (the paper's rule).
        patience: cycles a NODE waits for a module at an empty growth spot before choosing
            another spot.
        refuse: a module asked to become a seed refuses when it touches a grown module other
            than the sender (see the module docstring).
        **chain: the parameters of :class:`ChainPolicy` for SEARCH and SEED (``p_random``,
            ``horizontal``, ``turn``, ...).
    """

    name = "branch"

    def __init__(self, layout, modes, *, scent_max=65535, seed=None, T=12, B=6, p_node=0.0,
                 search_relays_node=True, refuse=True, patience=30, **chain):
        super().__init__(layout, modes, scent_max=scent_max, seed=seed, **chain)
        if T < 1:
            raise ValueError(f"T={T!r} is not allowed; allowed: an integer >= 1")
        if B < 1:
            raise ValueError(f"B={B!r} is not allowed; allowed: an integer >= 1")
        if not 0.0 <= p_node <= 1.0:
            raise ValueError(f"p_node={p_node!r} is not allowed; allowed: a probability in [0, 1]")
        self.T = int(T)
        self.B = int(B)
        self.p_node = p_node
        self.search_relays_node = search_relays_node
        self.refuse = refuse
        self.patience = patience
        self.spawned: dict = {}
        """Private memory of each NODE: seeds spawned so far."""
        self.spot: dict = {}
        """Private memory of each NODE: ``(direction, announced last cycle)`` of its current spot."""
        self.refused: dict = {}
        """Private memory of each SEED and NODE: directions whose module refused to become a seed."""

    @classmethod
    def for_env(cls, env, *, seed=None, **params):
        """Build from the environment's static interface; ``T`` and ``B`` default to the task's."""
        task_params = env.task.params
        params.setdefault("T", getattr(task_params, "T", 12))
        params.setdefault("B", getattr(task_params, "B", 6))
        return super().for_env(env, seed=seed, **params)

    def reset(self, seed=None):
        super().reset(seed)
        self.spawned.clear()
        self.spot.clear()
        self.refused.clear()

    def _stacked(self, obs: Observed):
        """The fields every rule reads, from the stacked observation ``obs``, and the default actions.

        Returns own modes, face-neighbour kinds, modes and channel-0 scents (``scent_max`` where
        no module), legal moves (12,), the default actions (relay every channel, keep the mode)
        and, per agent, the slot a ``BECOME_SEED`` came from (-1 when none, or when not SLEEP or
        SEARCH).
        """
        own = obs.own_mode[:, 0].astype(np.int64)
        kinds = obs.neighbour_kind[:, :12]
        nmode = obs.neighbour_mode[:, :12]
        scents = np.where(kinds == KIND_MODULE, obs.neighbour_scent[:, :12, 0], self.scent_max)
        legal = obs.action_mask[:, 1:].astype(bool)
        lay = self.layout
        actions = np.zeros((len(own), lay.length), dtype=np.int64)
        actions[:, lay.roles] = RELAY
        actions[:, lay.mode] = own
        promoted = first_slot(obs.messages == BECOME_SEED)
        promoted[(own != SLEEP) & (own != SEARCH)] = -1
        return own, kinds, nmode, scents, legal, actions, promoted

    def _act(self, slots, field, observation) -> np.ndarray:
        keys = slots.tolist()  # memory slots also key the branch's own memory
        smax = self.scent_max
        obs = Observed.read(field)
        msgs, own_scent = obs.messages, obs.own_scent
        own, kinds, nmode, scents, legal, actions, promoted = self._stacked(obs)
        is_mod = kinds == KIND_MODULE
        lay = self.layout
        grown_nb = is_mod & np.isin(nmode, GROWN)
        for i in np.flatnonzero(promoted >= 0):
            others = grown_nb[i].copy()
            others[promoted[i]] = False
            if self.refuse and others.any():  # joining would touch another part of the tree
                actions[i, lay.message_target] = promoted[i]
                actions[i, lay.message_value] = REFUSE
                promoted[i] = -2  # neither a seed nor moving this cycle
                continue
            actions[i] = self._seed(keys[i], observation(i), int(OPPOSITE[promoted[i]]), fresh=True)
        refused = first_slot(msgs == REFUSE)
        for i in np.flatnonzero((refused >= 0) & (own == FINAL)):  # the seed it made refused: seed again
            self.refused.setdefault(keys[i], set()).add(int(refused[i]))
            actions[i] = self._seed(keys[i], observation(i), -1, fresh=True, previous=int(refused[i]))
        for i in np.flatnonzero((refused >= 0) & ((own == NODE) | (own == INODE))):  # one seed fewer
            self.refused.setdefault(keys[i], set()).add(int(refused[i]))
            self.spawned[keys[i]] = min(self.spawned.get(keys[i], self.B), self.B) - 1
            self.spot.pop(keys[i], None)
        for i in np.flatnonzero(own == SEED):
            actions[i] = self._seed(keys[i], observation(i), int(self.memory.growth[keys[i]]), fresh=False)
        reverted = (refused >= 0) & (own == FINAL)

        sleep = (own == SLEEP) & (promoted == -1)
        actions[sleep, lay.roles.start + 1] = SILENT
        if sleep.any():
            detected = (own_scent[:, 0] < smax) | (scents < smax).any(axis=1)
            wake = sleep & detected
            if self.wake_when_free:
                wake &= legal.any(axis=1)
            actions[wake, lay.mode] = SEARCH
            if self.p_node > 0:
                for i in np.flatnonzero(sleep & ~detected):
                    if self.rng.random() < self.p_node:
                        actions[i] = self._node(keys[i], observation(i))

        # FINAL: relay both; a weak node scent (known, > T) with no node next to it: go NODE
        final = np.flatnonzero((own == FINAL) & ~reverted)
        if final.size:
            node_scent = own_scent[final, 1]
            near_node = ((nmode[final] == NODE) | (nmode[final] == INODE)).any(axis=1)
            become = (node_scent > self.T) & (node_scent < smax) & ~near_node
            for i in final[become]:
                actions[i] = self._node(keys[i], observation(i))
        inode = (own == INODE) & ~((refused >= 0) & (own == INODE))
        for i in np.flatnonzero((own == NODE) | ((own == INODE) & ~inode)):
            actions[i] = self._node(keys[i], observation(i))
        actions[inode, lay.roles.start + 1] = EMIT

        search = np.flatnonzero((own == SEARCH) & (promoted == -1))
        if search.size:
            if not self.search_relays_node:
                actions[search, lay.roles.start + 1] = SILENT
            seen = obs.neighbour_mode.copy()  # a NODE is a seed to approach, an INODE part of the chain
            seen[seen == NODE] = SEED
            seen[seen == INODE] = FINAL
            self._search_actions(actions, slots, search, obs, seen)
        grown = slots[own >= FINAL]
        self.memory.heading[grown] = -1
        self.memory.asked[grown] = False
        return actions

    # ------------------------------------------------------------------ NODE
    def _spot_free(self, obs, k: int) -> bool:
        """Can a new branch start at the neighbour site ``k``? It holds no grown module and
        the sites seen next to it hold no grown module."""
        kind = obs["neighbour_kind"][k]
        if kind == KIND_MODULE:
            if obs["neighbour_mode"][k] in GROWN:
                return False
        elif kind != KIND_EMPTY:
            return False
        return spot_touches(obs, k, GROWN) == 0

    def _node(self, agent: int, obs) -> np.ndarray:
        encode = self.layout.encode
        count = self.spawned.get(agent, 0)
        refused = self.refused.get(agent, ())
        if count >= self.B:
            return self._retire(agent)
        direction, announced, waited = self.spot.get(agent, (-1, False, 0))
        kinds = obs["neighbour_kind"]
        if (direction < 0 or not self._spot_free(obs, direction)
                or (kinds[direction] != KIND_MODULE and waited >= self.patience)):
            # (re)choose a free site; an empty one is chosen again after ``patience`` cycles
            allowed = HORIZONTAL if self.horizontal else np.ones(12, dtype=bool)
            pool = [k for k in np.flatnonzero(allowed) if k not in refused and self._spot_free(obs, k)]
            if not pool:
                return self._retire(agent)
            new = int(self.rng.choice(pool))
            direction, announced, waited = new, announced and new == direction, 0
        self.spawned[agent] = count
        kind, mode = obs["neighbour_kind"][direction], obs["neighbour_mode"][direction]
        if kind == KIND_MODULE and (mode == SLEEP or (mode == SEARCH and announced)):
            self.spawned[agent] = count + 1
            self.spot.pop(agent, None)
            if count + 1 >= self.B:  # the last seed: go INODE in the same action
                return encode(mode=INODE, roles=[RELAY, EMIT], message_target=direction,
                              message_value=BECOME_SEED)
            return encode(mode=NODE, roles=[EMIT, EMIT], message_target=direction, message_value=BECOME_SEED)
        self.spot[agent] = (direction, True, waited + 1)
        return encode(mode=NODE, roles=[EMIT, EMIT], message_target=MESSAGE_TO_ALL, message_value=direction + 1)

    def _retire(self, agent: int) -> np.ndarray:
        self.spawned.pop(agent, None)
        self.spot.pop(agent, None)
        self.refused.pop(agent, None)
        return self.layout.encode(mode=INODE, roles=[RELAY, EMIT])

    # ------------------------------------------------------------------ SEED
    def _blocked(self, obs, growth: int) -> bool:
        kind = obs["neighbour_kind"][growth]
        if kind == KIND_MODULE:
            if obs["neighbour_mode"][growth] not in (SLEEP, SEARCH):
                return True
        elif kind != KIND_EMPTY:
            return True
        return spot_touches(obs, growth, GROWN) > 0

    def _seed(self, agent: int, obs, growth: int, *, fresh: bool, previous: int = -1) -> np.ndarray:
        encode = self.layout.encode
        refused = self.refused.get(agent, ())
        if growth < 0 or growth in refused or (self.turn and self._blocked(obs, growth)):
            new = growth_direction(obs, self.rng, horizontal=self.horizontal,
                                   previous=growth if growth >= 0 else previous, avoid_modes=GROWN,
                                   clean=self.clean_exit)
            if new in refused:
                new = -1
            if new >= 0 or growth < 0 or growth in refused:
                growth = new
        if growth < 0:
            self.memory.growth[agent] = -1
            return encode(mode=SEED, roles=[EMIT, RELAY])
        self.memory.growth[agent] = growth
        if (not fresh and obs["neighbour_kind"][growth] == KIND_MODULE
                and obs["neighbour_mode"][growth] in (SLEEP, SEARCH)
                and not (self.turn and self._blocked(obs, growth))):
            self.memory.growth[agent] = -1
            return encode(mode=FINAL, roles=[RELAY, RELAY], message_target=growth, message_value=BECOME_SEED)
        return encode(mode=SEED, roles=[EMIT, RELAY], message_target=MESSAGE_TO_ALL, message_value=growth + 1)

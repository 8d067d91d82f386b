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
- SEARCH, "move along scent gradient" (:func:`~baselines.primitives.climb`): the value of a
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
"""

from __future__ import annotations

import numpy as np

from proteo_env.core.lattice import DIRECTIONS, OPPOSITE
from proteo_env.spaces import EMIT, KIND_MODULE, MESSAGE_TO_ALL, RELAY

from .base import Policy
from .primitives import (BECOME_SEED, EQUATORS, SPOT_FACE, approach_batch, climb_batch, descent_batch,
                         first_slot, growth_direction, random_pick, spot_touches)

SLEEP, SEARCH, SEED, FINAL = range(4)

ON_STUCK = ("stay", "random")


class ChainPolicy(Policy):
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

    def __init__(self, layout, modes, *, scent_max=65535, seed=None, p_seed=0.0, p_random=0.05,
                 on_stuck="stay", fewer_neighbours=True, horizontal=True, clean_exit=True, turn=True,
                 greedy_approach=True, wake_when_free=False, directed=True, momentum=1.0, queue=False,
                 prefer_chain=True, avoid_octahedra=True):
        super().__init__(layout, modes, scent_max=scent_max, seed=seed)
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
        self.asked: set = set()
        """Private memory: the SEARCH modules that asked to move last cycle."""
        self.heading: dict[str, int] = {}
        """Private memory of each SEARCH module: the direction index of its last requested move."""
        self.growth: dict[str, int] = {}
        """Private memory of each SEED: its growth direction."""

    def reset(self, seed=None):
        super().reset(seed)
        self.growth.clear()
        self.heading.clear()
        self.asked.clear()

    def act(self, observations):
        names = list(observations)
        if not names:
            return {}
        obs = [observations[a] for a in names]
        actions = self._act(names, lambda f: np.stack([o[f] for o in obs]), obs.__getitem__)
        return {a: actions[i] for i, a in enumerate(names)}

    def act_arrays(self, buffers) -> np.ndarray:
        """``(A, L)`` actions for all agents from stacked observations.

        ``buffers`` is an :class:`~proteo_env.spaces.ObservationBuffers` (what
        ``env.observe_arrays()`` returns): the same per-agent observations as :meth:`act`
        receives, one row per agent, so the result is the same rule; it only skips building
        dicts (use with ``env.step_arrays``). Private memory is keyed by row index here and
        by agent name in :meth:`act`; use one of the two within an episode.
        """
        return self._act(range(buffers.own_mode.shape[0]), lambda f: getattr(buffers, f), buffers.agent)

    def _stacked(self, field, n: int):
        """The fields every rule reads, stacked over ``n`` agents, and their default actions.

        Returns own modes, messages, face-neighbour kinds, modes and channel-0 scents
        (``scent_max`` where no module), own scents (all channels), legal moves (12,), the
        default actions (relay every channel, keep the mode) and, per agent, the slot a
        ``BECOME_SEED`` came from (-1 when none, or when not SLEEP or SEARCH).
        """
        own = field("own_mode")[:, 0].astype(np.int64)
        msgs = field("messages")
        kinds = field("neighbour_kind")[:, :12]
        nmode = field("neighbour_mode")[:, :12]
        scents = np.where(kinds == KIND_MODULE, field("neighbour_scent")[:, :12, 0], self.scent_max)
        legal = field("action_mask")[:, 1:].astype(bool)
        lay = self.layout
        actions = np.zeros((n, lay.length), dtype=np.int64)
        actions[:, lay.roles] = RELAY
        actions[:, lay.mode] = own
        promoted = first_slot(msgs == BECOME_SEED)
        promoted[(own != SLEEP) & (own != SEARCH)] = -1
        return own, msgs, kinds, nmode, scents, field("own_scent"), legal, actions, promoted

    def _act(self, keys, field, observation) -> np.ndarray:
        """Actions of the modules ``keys`` (memory keys, in row order); ``field(name)`` gives an
        observation field stacked over them, ``observation(i)`` one module's observation dict."""
        keys = list(keys)
        smax = self.scent_max
        own, msgs, kinds, nmode, scents, own_scent, legal, actions, promoted = self._stacked(field, len(keys))
        own_scent = own_scent[:, 0]
        lay = self.layout
        for i in np.flatnonzero(promoted >= 0):
            actions[i] = self._seed(keys[i], observation(i), int(OPPOSITE[promoted[i]]), fresh=True)
        for i in np.flatnonzero(own == SEED):
            actions[i] = self._seed(keys[i], observation(i), self.growth.get(keys[i], -1), fresh=False)

        sleep = (own == SLEEP) & (promoted < 0)
        if sleep.any():
            detected = (own_scent < smax) | (scents < smax).any(axis=1)
            wake = sleep & detected
            if self.wake_when_free:
                wake &= legal.any(axis=1)
            actions[wake, lay.mode] = SEARCH
            if self.p_seed > 0:
                for i in np.flatnonzero(sleep & ~detected):
                    if self.rng.random() < self.p_seed:
                        actions[i] = self._seed(keys[i], observation(i), -1, fresh=True)

        search = np.flatnonzero((own == SEARCH) & (promoted < 0))
        if search.size:
            self._search_actions(actions, keys, search, msgs[search], kinds[search], nmode[search],
                                 scents[search], legal[search])
        for i in np.flatnonzero(own == FINAL):
            self.heading.pop(keys[i], None)
            self.asked.discard(keys[i])
        return actions

    def decide(self, agent: str, obs) -> np.ndarray:
        """The action of one module from its observation alone."""
        return self.act({agent: obs})[agent]

    # ------------------------------------------------------------------ SEARCH, batched
    def _search_actions(self, actions, keys, search, msgs, kinds, seen_modes, scents, legal) -> None:
        """Write the moves and growth broadcasts of the SEARCH agents ``search`` into ``actions``
        (the other arguments are those agents' observation fields) and update their memory."""
        lay = self.layout
        moves, send = self._search_moves([keys[i] for i in search], msgs, kinds, seen_modes, scents, legal)
        actions[search, lay.move] = moves
        sending = send >= 0
        actions[search[sending], lay.message_target] = MESSAGE_TO_ALL
        actions[search[sending], lay.message_value] = send[sending] + 1
        for i, m in zip(search.tolist(), moves.tolist()):
            if m > 0:
                self.heading[keys[i]] = m - 1
                self.asked.add(keys[i])
            else:
                self.asked.discard(keys[i])

    def _search_moves(self, names, msgs, kinds, nmode, scents, legal):
        """Moves and growth broadcasts (-1: none) of the SEARCH modules.

        Rows are modules; each row uses only that module's observation and private memory.
        """
        q = len(names)
        rows = np.arange(q)
        moves = np.zeros(q, dtype=np.int64)
        send = np.full(q, -1, dtype=np.int64)
        todo = np.ones(q, dtype=bool)
        growth_msg = (msgs >= 1) & (msgs <= 12)
        heard = msgs - 1  # growth heard from each side (valid where growth_msg)

        # next to a SEED (seen by its mode, so its side is known now): its growth is the value
        # it broadcast (any side: the value does not go stale, only the side may)
        seed_slot = first_slot(nmode == SEED)
        near = seed_slot >= 0
        g_slot = first_slot(growth_msg)
        growth = np.where(g_slot >= 0, heard[rows, np.maximum(g_slot, 0)], -1)
        s, g = np.maximum(seed_slot, 0), np.maximum(growth, 0)
        at_spot = near & (growth >= 0) & (seed_slot == OPPOSITE[g])
        hold = near & ((growth < 0) | at_spot)  # at the spot, or growth not heard yet
        todo &= ~hold
        if self.queue:
            send[at_spot] = growth[at_spot]
        seed_face = SPOT_FACE[s, g]
        spot_taken = near & (growth >= 0) & (seed_face >= 0) & (kinds[rows, np.maximum(seed_face, 0)] == KIND_MODULE)

        if self.queue:
            # a SEARCH neighbour broadcasting a growth is holding a spot; its side is only
            # trusted when this module asked for no move last cycle (so it has not moved since)
            still = np.array([names[r] not in self.asked for r in range(q)], dtype=bool)
            holder = growth_msg & (nmode == SEARCH) & still[:, None]
            gy = np.maximum(heard, 0)
            at_pre = holder & (np.arange(12)[None, :] == OPPOSITE[gy])
            hold_pre = todo & at_pre.any(axis=1)
            y = first_slot(at_pre)
            send[hold_pre] = gy[rows, np.maximum(y, 0)][hold_pre]
            todo &= ~hold_pre

        go_seed = todo & near & ~spot_taken
        idx = np.flatnonzero(go_seed)
        if idx.size:
            target = DIRECTIONS[seed_slot[idx]] + DIRECTIONS[growth[idx]]
            moves[idx] = approach_batch(target, seed_slot[idx], legal[idx], self.rng,
                                        greedy=self.greedy_approach, p_random=self.p_random)
        todo &= ~go_seed

        if self.queue:
            idx = np.flatnonzero(todo & holder.any(axis=1))
            if idx.size:
                h = holder[idx]
                pre_face = SPOT_FACE[np.arange(12)[None, :], gy[idx]]
                free = h & (pre_face >= 0) & (np.take_along_axis(kinds[idx], np.maximum(pre_face, 0), axis=1) == 0)
                free |= h & (pre_face < 0)  # spot out of sight: try it
                pick = np.where(free.any(axis=1), first_slot(free), first_slot(h))
                gp = gy[idx, pick]
                beyond = ~free[np.arange(idx.size), pick]
                target = DIRECTIONS[pick] + DIRECTIONS[gp] * np.where(beyond, 2, 1)[:, None]
                moves[idx] = approach_batch(target, pick, legal[idx], self.rng, greedy=self.greedy_approach,
                                            p_random=self.p_random)
                todo[idx] = False
            # heard a holder but cannot trust the side (asked to move last cycle): wait a cycle
            wait = todo & (growth_msg & (nmode == SEARCH)).any(axis=1) & ~still
            todo &= ~wait

        idx = np.flatnonzero(todo & near)  # spot taken, no holder to follow: round the seed
        if idx.size:
            target = DIRECTIONS[seed_slot[idx]] + DIRECTIONS[growth[idx]]
            moves[idx] = approach_batch(target, seed_slot[idx], legal[idx], self.rng,
                                        greedy=self.greedy_approach, p_random=self.p_random)
        todo &= ~near

        climbers = np.flatnonzero(todo)
        if climbers.size:
            bias = None
            if self.directed:
                bias = descent_batch(scents[climbers], self.scent_max)
            if self.momentum > 0:
                last = np.array([self.heading.get(names[c], -1) for c in climbers])
                heading = np.where((last >= 0)[:, None], DIRECTIONS[np.maximum(last, 0)], 0)
                bias = (0 if bias is None else bias) + self.momentum * heading
            sc = scents[climbers]
            smax = self.scent_max
            if self.prefer_chain:  # equal scents: a chain module counts as slightly lower
                loose = (nmode[climbers] == SEARCH) | (nmode[climbers] == SLEEP)
                sc = np.where(sc < smax, 2 * sc + loose, 2 * smax)
                smax = 2 * smax
            moves[climbers] = climb_batch(sc, kinds[climbers], legal[climbers], smax,
                                          self.rng, self.p_random, on_stuck=self.on_stuck, bias=bias,
                                          fewer_neighbours=self.fewer_neighbours)
            if self.avoid_octahedra:
                # the 4 sites round one of its octahedral holes are all taken, one of them by the
                # chain: a module filling the last (unseen) vertex would lock an octahedron of
                # six, where no member can roll under sphere, rounded or rhombic; leave
                eq = EQUATORS
                full = (kinds[climbers][:, eq] == KIND_MODULE).all(axis=2)
                if self.avoid_octahedra != "all":
                    chain = (nmode[climbers][:, eq] == FINAL) | (nmode[climbers][:, eq] == SEED)
                    full &= chain.any(axis=2)
                leave = full.any(axis=1) & legal[climbers].any(axis=1)
                if leave.any():
                    moves[climbers[leave]] = random_pick(legal[climbers[leave]], self.rng) + 1
        return moves, send

    def _blocked(self, obs, growth: int) -> bool:
        """Can the chain not grow into ``DIRECTIONS[growth]`` from here?"""
        kind = obs["neighbour_kind"][growth]
        if kind == KIND_MODULE:
            if obs["neighbour_mode"][growth] not in (SLEEP, SEARCH):
                return True
        elif kind != 0:  # solid, wall or object
            return True
        return spot_touches(obs, growth, (FINAL,)) > 0

    def _seed(self, agent: str, obs, growth: int, *, fresh: bool) -> np.ndarray:
        encode = self.layout.encode
        if growth < 0 or (self.turn and self._blocked(obs, growth)):
            new = growth_direction(obs, self.rng, horizontal=self.horizontal, previous=growth,
                                   avoid_modes=(FINAL,), clean=self.clean_exit)
            if new < 0 and self.horizontal:  # nowhere to go in the plane: leave it
                new = growth_direction(obs, self.rng, horizontal=False, previous=growth,
                                       avoid_modes=(FINAL,), clean=self.clean_exit)
            if new >= 0 or growth < 0:
                growth = new
        if growth < 0:
            self.growth.pop(agent, None)
            return encode(mode=SEED, roles=[EMIT])
        self.growth[agent] = growth
        if (not fresh and obs["neighbour_kind"][growth] == KIND_MODULE
                and obs["neighbour_mode"][growth] in (SLEEP, SEARCH)
                and not (self.turn and self._blocked(obs, growth))):
            del self.growth[agent]
            return encode(mode=FINAL, roles=[RELAY], message_target=growth, message_value=BECOME_SEED)
        return encode(mode=SEED, roles=[EMIT], message_target=MESSAGE_TO_ALL, message_value=growth + 1)

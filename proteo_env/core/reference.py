"""A slow, obviously-correct reference of the world's cycle, for parity tests.

:class:`ReferenceWorld` takes the same inputs as :class:`proteo_env.core.world.World` and runs
the same cycle (docs/model.md, from "Lattice and world" to "Scents") with nothing but plain
Python: a dict from site to module, lists of modes, scents and messages, and the xorshift64
state as a Python ``int``. It shares no code with the kernels; the only engine pieces it reads
are the direction order (:data:`~proteo_env.core.lattice.DIRECTIONS`, which defines the
action encoding) and the swept-cell tables (:func:`~proteo_env.core.motion.swept_cells`,
derived from geometry and checked by ``tests/test_motion_geometry.py``). NumPy appears only where inputs are read and
outputs returned.

Model, as implemented here:

* Sites are integer triples; the box is ``0 <= x < X`` (etc.). A site is *empty* when it is
  inside the box and holds no module, obstacle or object site. Ground is every site with
  ``z < 0`` when ``floor`` is set (always outside the box).
* A roll of the module at ``p`` towards ``t = p + d`` is legal when ``t`` is empty and at least
  one of the 4 common neighbours ``q`` of ``p`` and ``t`` holds a module (the pivot) whose
  swept cells (``swept_cells(model)[(d, q - p)]``, offsets from ``p``) are all empty.
* With ``keep_connected`` the module must also be removable: a full breadth-first search over
  all the other modules reaches every one of them.
* One cycle: modes are set; the inbox is cleared and messages delivered in agent order; the
  movers (agents with a move and not anchored, in index order) are shuffled with Fisher-Yates
  driven by xorshift64 and tried one at a time against the occupancy of that moment; then each
  scent channel is recomputed (exact BFS distances, or ``scent_sweeps`` Jacobi sweeps).
"""

from __future__ import annotations

import numpy as np

from .lattice import DIRECTIONS
from .motion import swept_cells
from .records import Observation

MASK64 = 0xFFFF_FFFF_FFFF_FFFF
SILENT, RELAY, EMIT = 0, 1, 2
KIND_EMPTY, KIND_MODULE, KIND_SOLID, KIND_OBJECT = 0, 1, 2, 3

DIRS: list[tuple[int, int, int]] = [tuple(int(v) for v in d) for d in DIRECTIONS]
DIR_SET = set(DIRS)


def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def neg(a):
    return (-a[0], -a[1], -a[2])


def _ints(p) -> tuple[int, int, int]:
    return (int(p[0]), int(p[1]), int(p[2]))


def neighbourhood(radius: int) -> list[tuple[int, int, int]]:
    """Observation offsets: the 12 directions, then (radius 2) the other two-hop sites, sorted."""
    if radius == 1:
        return list(DIRS)
    ring = {add(a, b) for a in DIRS for b in DIRS if add(a, b) != (0, 0, 0)} - DIR_SET
    return list(DIRS) + sorted(ring)


# --------------------------------------------------------------------- random numbers
def xorshift64(x: int) -> int:
    """One xorshift64 (13, 7, 17) step on a 64-bit state."""
    x ^= (x << 13) & MASK64
    x ^= x >> 7
    x ^= (x << 17) & MASK64
    return x


def below(x: int, n: int) -> tuple[int, int]:
    """Advance state ``x``; return ``(new_state, uniform integer in [0, n))``."""
    x = xorshift64(x)
    return x, ((x >> 32) * n) >> 32


def shuffled(items: list, x: int) -> tuple[list, int]:
    """Fisher-Yates shuffle of a copy of ``items`` driven by state ``x``; returns (items, state)."""
    items = list(items)
    for i in range(len(items) - 1, 0, -1):
        x, j = below(x, i + 1)
        items[i], items[j] = items[j], items[i]
    return items, x


# --------------------------------------------------------------------- the world
class ReferenceWorld:
    """Plain-Python twin of :class:`~proteo_env.core.world.World` (same constructor keywords)."""

    def __init__(
        self,
        *,
        size,
        positions,
        n_agents,
        physics,
        anchored=None,
        solid=None,
        object_sites=None,
        floor=False,
        n_channels=1,
        surface_channels=None,
        passive_role=None,
        modes=None,
        obs_radius=1,
    ):
        self.size = tuple(int(s) for s in size)
        self.physics = physics
        self.sweeps = {
            (_ints(d), _ints(q)): [_ints(c) for c in cells]
            for (d, q), cells in swept_cells(physics.motion_model).items()
        }
        self.site_of = [tuple(int(v) for v in p) for p in np.asarray(positions).reshape(-1, 3)]
        self.n_modules = n = len(self.site_of)
        self.n_agents = int(n_agents)
        self.n_channels = c = int(n_channels)
        self.floor = bool(floor)
        self.module_at = {p: i for i, p in enumerate(self.site_of)}
        assert len(self.module_at) == n, "two modules on one site"
        self.anchored = [False] * n if anchored is None else [bool(v) for v in np.asarray(anchored)]
        self.solid = set() if solid is None else {tuple(int(v) for v in p) for p in np.asarray(solid).reshape(-1, 3)}
        self.object = (
            set()
            if object_sites is None
            else {tuple(int(v) for v in p) for p in np.asarray(object_sites).reshape(-1, 3)}
        )
        self.surface = [False] * c if surface_channels is None else [bool(v) for v in np.asarray(surface_channels)]
        self.passive_role = [RELAY] * c if passive_role is None else [int(v) for v in np.asarray(passive_role)]
        self.mode = [0] * n if modes is None else [int(v) for v in np.asarray(modes)]
        self.scent = [[physics.scent_max] * n for _ in range(c)]
        self.inbox = [[0] * 12 for _ in range(n)]
        self.rng_state = 1
        self.offsets = neighbourhood(obs_radius)
        self.last_order: list[int] = []
        """Movers of the last cycle in the order they were tried."""
        self.last_attempts: list[tuple[int, int, bool]] = []
        """(module, direction, moved) for each move tried last cycle, in order."""

    # ------------------------------------------------------------------ sites
    def inside(self, p) -> bool:
        return all(0 <= p[i] < self.size[i] for i in range(3))

    def is_ground(self, p) -> bool:
        return self.floor and p[2] < 0

    def is_solid(self, p) -> bool:
        """Ground or an obstacle (what the ground contact sensor feels)."""
        return p in self.solid or self.is_ground(p)

    def is_empty(self, p) -> bool:
        """Inside the box and holding no module, obstacle or object site."""
        return self.inside(p) and p not in self.module_at and p not in self.solid and p not in self.object

    def kind(self, p) -> int:
        if p in self.module_at:
            return KIND_MODULE
        if self.is_empty(p):
            return KIND_EMPTY
        if p in self.object:
            return KIND_OBJECT
        return KIND_SOLID  # ground, obstacle or outside the box

    def neighbour_modules(self, m) -> list[int]:
        p = self.site_of[m]
        return [self.module_at[add(p, d)] for d in DIRS if add(p, d) in self.module_at]

    # ------------------------------------------------------------------ rules
    def roll_is_legal(self, m: int, k: int) -> bool:
        """Geometry alone: may module ``m`` roll towards ``DIRS[k]`` now?"""
        p = self.site_of[m]
        d = DIRS[k]
        t = add(p, d)
        if not self.is_empty(t):
            return False
        for q_off in DIRS:
            if sub(d, q_off) not in DIR_SET:
                continue  # not a common neighbour of p and t
            if add(p, q_off) not in self.module_at:
                continue  # no pivot module there
            if all(self.is_empty(add(p, cell)) for cell in self.sweeps[(d, q_off)]):
                return True
        return False

    def connected_without(self, m: int | None) -> bool:
        """Plain BFS: are all modules other than ``m`` one connected piece?"""
        others = [i for i in range(self.n_modules) if i != m]
        if not others:
            return True
        seen = {others[0]}
        frontier = [others[0]]
        while frontier:
            nxt = []
            for i in frontier:
                for j in self.neighbour_modules(i):
                    if j != m and j not in seen:
                        seen.add(j)
                        nxt.append(j)
            frontier = nxt
        return len(seen) == len(others)

    def can_detach(self, m: int) -> bool:
        return self.connected_without(m)

    def n_components(self) -> int:
        seen: set = set()
        count = 0
        for start in range(self.n_modules):
            if start in seen:
                continue
            count += 1
            seen.add(start)
            stack = [start]
            while stack:
                i = stack.pop()
                for j in self.neighbour_modules(i):
                    if j not in seen:
                        seen.add(j)
                        stack.append(j)
        return count

    def move_is_legal(self, m: int, k: int) -> bool:
        """What the cycle checks for a tried move (the mover is already known not anchored)."""
        if not self.roll_is_legal(m, k):
            return False
        return not self.physics.keep_connected or self.can_detach(m)

    def legal_moves(self, m: int) -> set[int]:
        """Directions module ``m`` could roll towards now (anchored and passive modules: none)."""
        if self.anchored[m] or m >= self.n_agents:
            return set()
        legal = {k for k in range(12) if self.roll_is_legal(m, k)}
        if legal and self.physics.keep_connected and not self.can_detach(m):
            return set()
        return legal

    def apply_move(self, m: int, k: int) -> None:
        p = self.site_of[m]
        t = add(p, DIRS[k])
        del self.module_at[p]
        self.module_at[t] = m
        self.site_of[m] = t

    # ------------------------------------------------------------------ the cycle
    def seed(self, seed: int) -> None:
        self.rng_state = (int(seed) % MASK64) + 1

    def step(self, *, move, mode, scent_role, message_target, message_value) -> np.ndarray:
        """One cycle (same arguments as ``World.step``); returns ``(A,)`` bool, who moved."""
        a_count = self.n_agents
        move = [int(v) for v in np.asarray(move).reshape(-1)]
        mode = [int(v) for v in np.asarray(mode).reshape(-1)]
        roles = [[int(v) for v in row] for row in np.asarray(scent_role).reshape(a_count, self.n_channels)]
        target = [int(v) for v in np.asarray(message_target).reshape(-1)]
        value = [int(v) for v in np.asarray(message_value).reshape(-1)]

        # 1. modes
        for a in range(a_count):
            self.mode[a] = mode[a]

        # 2. messages: the receiver files the value under the direction pointing back to the sender
        self.inbox = [[0] * 12 for _ in range(self.n_modules)]
        for a in range(a_count):
            if value[a] == 0:
                continue
            p = self.site_of[a]
            for k, d in enumerate(DIRS):
                if target[a] != 12 and target[a] != k:
                    continue
                receiver = self.module_at.get(add(p, d))
                if receiver is not None:
                    self.inbox[receiver][DIRS.index(neg(d))] = value[a]

        # 3. moves, in a fresh random order, each against the occupancy of its moment
        movers = [a for a in range(a_count) if move[a] > 0 and not self.anchored[a]]
        order, self.rng_state = shuffled(movers, self.rng_state)
        moved = [False] * a_count
        self.last_order = order
        self.last_attempts = []
        for a in order:
            k = move[a] - 1
            if self.move_is_legal(a, k):
                self.apply_move(a, k)
                moved[a] = True
            self.last_attempts.append((a, k, moved[a]))

        # 4. scents
        for ch in range(self.n_channels):
            role = [roles[i][ch] if i < a_count else self.passive_role[ch] for i in range(self.n_modules)]
            if self.physics.exact_scent:
                self.scent[ch] = self.exact_scent(role, self.surface[ch])
            else:
                values = self.scent[ch]
                for _ in range(self.physics.scent_sweeps):
                    values = self.sweep(values, role, self.surface[ch])
                self.scent[ch] = values
        return np.array(moved, dtype=np.bool_)

    def on_surface(self, m: int) -> bool:
        p = self.site_of[m]
        return any(self.is_empty(add(p, d)) for d in DIRS)

    def sweep(self, previous: list[int], role: list[int], surface: bool) -> list[int]:
        """One Jacobi sweep: every new value reads only ``previous``."""
        top = self.physics.scent_max
        new = []
        for m in range(self.n_modules):
            if role[m] == EMIT:
                new.append(0)
            elif role[m] == SILENT or (surface and not self.on_surface(m)):
                new.append(top)
            else:
                near = [previous[j] for j in self.neighbour_modules(m)]
                new.append(min(top, 1 + min(near)) if near else top)
        return new

    def exact_scent(self, role: list[int], surface: bool) -> list[int]:
        """Hop distance from the nearest emitter through relaying modules, saturated."""
        top = self.physics.scent_max
        dist = {m: 0 for m in range(self.n_modules) if role[m] == EMIT}
        frontier = list(dist)
        hops = 0
        while frontier:
            hops += 1
            nxt = []
            for i in frontier:
                for j in self.neighbour_modules(i):
                    if j in dist or role[j] != RELAY or (surface and not self.on_surface(j)):
                        continue
                    dist[j] = hops
                    nxt.append(j)
            frontier = nxt
        return [min(dist.get(m, top), top) for m in range(self.n_modules)]

    # ------------------------------------------------------------------ reading
    def positions(self) -> np.ndarray:
        return np.array(self.site_of, dtype=np.int64).reshape(-1, 3)

    def state(self) -> dict:
        """The mutable state as arrays shaped like the engine's."""
        return {
            "positions": self.positions(),
            "mode": np.array(self.mode, dtype=np.int64),
            "scent": np.array(self.scent, dtype=np.int64).reshape(self.n_channels, self.n_modules),
            "inbox": np.array(self.inbox, dtype=np.int64).reshape(self.n_modules, 12),
            "rng_state": self.rng_state,
        }

    def observe(self) -> dict[str, np.ndarray]:
        """Observation fields of every agent (first axis: agent), as ``World.observe`` fills them."""
        top = self.physics.scent_max
        out: dict[str, list] = {f: [] for f in Observation._fields}
        for a in range(self.n_agents):
            p = self.site_of[a]
            kinds, modes, scents = [], [], []
            for off in self.offsets:
                s = add(p, off)
                kinds.append(self.kind(s))
                nb = self.module_at.get(s)
                modes.append(-1 if nb is None else self.mode[nb])
                scents.append([top if nb is None else self.scent[ch][nb] for ch in range(self.n_channels)])
            out["neighbour_kind"].append(kinds)
            out["neighbour_mode"].append(modes)
            out["neighbour_scent"].append(scents)
            out["own_mode"].append([self.mode[a]])
            out["own_scent"].append([self.scent[ch][a] for ch in range(self.n_channels)])
            out["messages"].append(list(self.inbox[a]))
            ground = any(self.is_solid(add(p, d)) for d in DIRS)
            touching = any(add(p, d) in self.object for d in DIRS)
            out["contact"].append([int(ground), int(touching)])
            legal = self.legal_moves(a)
            out["action_mask"].append([1] + [int(k in legal) for k in range(12)])
        a, k, c = self.n_agents, len(self.offsets), self.n_channels
        shapes = {
            "neighbour_kind": (a, k),
            "neighbour_mode": (a, k),
            "neighbour_scent": (a, k, c),
            "own_mode": (a, 1),
            "own_scent": (a, c),
            "messages": (a, 12),
            "contact": (a, 2),
            "action_mask": (a, 13),
        }
        return {f: np.array(v, dtype=np.int64).reshape(shapes[f]) for f, v in out.items()}

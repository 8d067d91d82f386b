"""Table: a board held up by legs that grow where the weight is and move when it shifts.

Roots of a fixed board grow legs of spare modules down to a floor, and disband them, as a schedule shifts the
weight between the board's two halves. Registered: ``table-v0``; ``table-v1`` (:class:`TableV1`: the ``settled``
reward term, and success needs the legs to carry the weight); ``table-v2``, the newest (:class:`TableV2`: no idle
leg, a stable configuration after every shift, the spares placed per world). Paper section 4.3 (Dynamically
Adapting to External Forces).

The contract (layout, agents, observation, actions, reward, metrics, termination, parameters): docs/tasks/table.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import numpy as np

from ..core.cycle import EMIT, RELAY
from ..core.jit import kernel
from ..core.lattice import DIRECTIONS
from ..layouts import Layout
from .base import Task, TaskKernels


class TableMode(IntEnum):
    """The table task's modes (paper section 4.3): the board (FIXED), the roots, the legs; the one definition the task and its rules share."""

    FIXED = 0
    ROOT = 1
    IROOT = 2
    AROOT = 3
    SLEEP = 4
    SEARCH = 5
    SEED = 6
    FINAL = 7
    DISBAND = 8


FIXED, ROOT, IROOT, AROOT, SLEEP, SEARCH, SEED, FINAL, DISBAND = (int(m) for m in TableMode)
"""The same modes as plain ints, for the numba kernels."""
CYCLE, SHIFT, SINCE, CREATIONS, DISBANDS = range(5)
"""Entries of :attr:`TableLedger.clock`: the last cycle, the schedule entry in force, the cycle the
signature last changed, leg creations and leg disbands so far."""


class TableLedger(NamedTuple):
    """The table episode's bookkeeping as the kernels below read and update it (R roots, K
    schedule entries, N modules); the compiled rollout of the hand-coded behaviour
    (:mod:`baselines.compiled`) runs the same kernels on a copy.

    Attributes:
        roots: ``(R,)`` int64 agent index of each root.
        left: ``(R,)`` bool, the root is in the left region.
        down_delta: ``(4,)`` int64 grid offsets of the face sites one layer down.
        shift_cycles: ``(K,)`` int64 cycles at which the schedule's entries start.
        schedule_weights: ``(K, 2)`` float64 weights (left, right) of each entry.
        depth, stable_window, load_cap, f_max: the task's parameters of those names.
        carry: a complete signature also needs the legs to carry the weight
            (:func:`weight_carried`; ``table-v1``); ``False`` in ``table-v0``.
        f_min: the task's parameter of that name.
        follow: the legs must follow the weight (``table-v2``): a complete signature also has no
            leg the weight does not need (:func:`no_idle_legs`), and success asks for a stable
            configuration after every shift of the schedule, not only the last.
        active: ``(R,)`` bool, the root is ROOT or AROOT (after the last cycle).
        grounded: ``(R,)`` bool, the root has a grounded leg (after the last cycle).
        signature: ``(2, R)`` bool, (active, grounded) since ``clock[SINCE]``.
        clock: ``(5,)`` int64, indexed by :data:`CYCLE`, :data:`SHIFT`, :data:`SINCE`,
            :data:`CREATIONS`, :data:`DISBANDS`.
        weights: ``(2,)`` float64 weights (left, right) now.
        restabilise: ``(K,)`` float64, cycles to re-stabilise after each shift (-1: not yet).
        scratch: ``(3, N)`` int64 scratch of :func:`grounded_legs`; ``stamp``: ``(1,)`` int64.
    """

    roots: np.ndarray
    left: np.ndarray
    down_delta: np.ndarray
    shift_cycles: np.ndarray
    schedule_weights: np.ndarray
    depth: int
    stable_window: int
    load_cap: float
    active: np.ndarray
    grounded: np.ndarray
    signature: np.ndarray
    clock: np.ndarray
    weights: np.ndarray
    restabilise: np.ndarray
    scratch: np.ndarray
    stamp: np.ndarray
    f_max: float
    carry: bool
    f_min: float
    follow: bool

    def copy(self) -> TableLedger:
        """A copy whose arrays are new."""
        return TableLedger(*(v.copy() if isinstance(v, np.ndarray) else v for v in self))


@kernel
def region_loads(book):
    """``(2,)`` the load sensor's reading in the left and the right region of
    :class:`TableLedger` ``book``: the region's weight per active root, ``load_cap`` with weight
    and no active root, at most ``load_cap``."""
    loads = np.zeros(2)
    for region in range(2):
        n_active = 0
        for r in range(book.roots.shape[0]):
            if book.active[r] and book.left[r] == (region == 0):
                n_active += 1
        if n_active > 0:
            loads[region] = min(book.weights[region] / n_active, book.load_cap)
        elif book.weights[region] > 0:
            loads[region] = book.load_cap
    return loads


@kernel
def weight_carried(book):
    """Whether the grounded legs of :class:`TableLedger` ``book`` carry the weight as far as
    the roots allow: in each region ``min(W, f_max * G) == min(W, f_max * R)``, ``G`` the roots
    with a grounded leg and ``R`` all roots of the region (a region whose roots cannot carry
    all of its weight needs every one of them grounded)."""
    for region in range(2):
        n_grounded = 0
        n_roots = 0
        for r in range(book.roots.shape[0]):
            if book.left[r] == (region == 0):
                n_roots += 1
                if book.grounded[r]:
                    n_grounded += 1
        weight = book.weights[region]
        if min(weight, book.f_max * n_grounded) < min(weight, book.f_max * n_roots):
            return False
    return True


@kernel
def legs_and_support(book):
    """``(legs_left, legs_right, support)`` of :class:`TableLedger` ``book``: its grounded legs in
    each region, and the share of the weight they can carry, ``sum(min(W, f_max * G)) / sum(W)``
    over the regions (``W`` the weight, ``G`` the grounded legs; 0 without weight)."""
    legs = np.zeros(2)
    for r in range(book.roots.shape[0]):
        if book.grounded[r]:
            legs[0 if book.left[r] else 1] += 1
    weights = book.weights
    total = weights[0] + weights[1]
    if total <= 0:
        return int(legs[0]), int(legs[1]), 0.0
    carried = min(weights[0], book.f_max * legs[0]) + min(weights[1], book.f_max * legs[1])
    return int(legs[0]), int(legs[1]), carried / total


@kernel
def no_idle_legs(book):
    """Whether :class:`TableLedger` ``book``'s grounded legs are no more than the weight needs: in
    each region ``W >= f_min * G`` (``G`` its roots with a grounded leg), the load per leg at least
    the one below which the paper's roots disband; a region without weight has no leg."""
    for region in range(2):
        n_grounded = 0
        for r in range(book.roots.shape[0]):
            if book.left[r] == (region == 0) and book.grounded[r]:
                n_grounded += 1
        if book.weights[region] < book.f_min * n_grounded:
            return False
    return True


@kernel
def root_loads(book, out):
    """Write each root's reading (:func:`region_loads`) into ``out[roots]`` (float32, (A,) or (A, 1))."""
    loads = region_loads(book)
    for r in range(book.roots.shape[0]):
        out[book.roots[r]] = loads[0] if book.left[r] else loads[1]


@kernel
def _legs_below(grid, cell, mode, anchored, above, n_above, down_delta, seen, stamp, below):
    """Write into ``below`` the leg modules (SEED or FINAL, not anchored) one layer below the
    modules ``above[:n_above]``, each once (``seen[v] == stamp``); return how many."""
    n_below = 0
    for j in range(n_above):
        for d in range(down_delta.shape[0]):
            v = grid[cell[above[j]] + down_delta[d]]
            if v >= 0 and (mode[v] == SEED or mode[v] == FINAL) and not anchored[v] and seen[v] != stamp:
                seen[v] = stamp
                below[n_below] = v
                n_below += 1
    return n_below


@kernel
def grounded_legs(grid, cell, mode, anchored, book):
    """Write ``book.grounded`` (R,): a chain of SEED or FINAL modules runs from the root down to
    the floor, one layer per module (``depth`` modules). ``stamp`` is bumped so that
    ``scratch[2]`` never needs clearing."""
    roots, down_delta, stamp = book.roots, book.down_delta, book.stamp
    level, below, seen = book.scratch[0], book.scratch[1], book.scratch[2]
    for r in range(roots.shape[0]):
        level[0] = roots[r]
        n_level = 1
        for _ in range(book.depth):
            stamp[0] += 1
            n_level = _legs_below(grid, cell, mode, anchored, level, n_level, down_delta, seen, stamp[0], below)
            level, below = below, level
            if n_level == 0:
                break
        book.grounded[r] = n_level > 0


@kernel
def signature_complete(book):
    """The signature of :class:`TableLedger` ``book`` is complete: every active root, and no
    other root, has a grounded leg; with ``carry`` the legs also carry the weight
    (:func:`weight_carried`), and with ``follow`` no leg is idle (:func:`no_idle_legs`)."""
    for r in range(book.roots.shape[0]):
        if book.active[r] != book.grounded[r]:
            return False
    if book.carry and not weight_carried(book):
        return False
    return not book.follow or no_idle_legs(book)


@kernel
def stable_start(book):
    """The cycle from which :class:`TableLedger` ``book``'s signature counts towards a stable
    period: its last change, or the shift of the schedule entry in force when that is later."""
    return max(book.clock[SINCE], book.shift_cycles[book.clock[SHIFT]])


@kernel
def in_stable_configuration(book):
    """The signature is complete and has stayed unchanged for ``stable_window`` cycles since
    :func:`stable_start`, as of the last cycle."""
    return signature_complete(book) and book.clock[CYCLE] - stable_start(book) >= book.stable_window


@kernel
def restabilised(book):
    """The table task's success: the configuration after the last scheduled shift has been stable
    (with ``follow``: after every shift, each before the next)."""
    if book.follow:
        return bool((book.restabilise >= 0).all())
    return book.restabilise[-1] >= 0


@kernel
def table_update(grid, cell, mode, anchored, cycle, book):
    """Update :class:`TableLedger` ``book`` after ``cycle``: active roots and grounded legs, leg
    creations and disbands, the signature and the cycle it last changed, ``restabilise`` of the
    schedule entry in force, and the schedule's next shift."""
    roots, active, grounded, signature, clock = book.roots, book.active, book.grounded, book.signature, book.clock
    shift_cycles, restabilise = book.shift_cycles, book.restabilise
    clock[CYCLE] = cycle
    changed = False
    for r in range(roots.shape[0]):
        now = mode[roots[r]] == ROOT or mode[roots[r]] == AROOT
        if now and not active[r]:
            clock[CREATIONS] += 1
        if active[r] and not now:
            clock[DISBANDS] += 1
        active[r] = now
    grounded_legs(grid, cell, mode, anchored, book)
    for r in range(roots.shape[0]):
        changed |= signature[0, r] != active[r] or signature[1, r] != grounded[r]
    if changed:
        signature[0] = active
        signature[1] = grounded
        clock[SINCE] = cycle
    k = clock[SHIFT]
    if restabilise[k] < 0 and in_stable_configuration(book):
        restabilise[k] = stable_start(book) - shift_cycles[k]
    if k + 1 < shift_cycles.shape[0] and cycle == shift_cycles[k + 1]:
        clock[SHIFT] = k + 1
        book.weights[:] = book.schedule_weights[k + 1]


@kernel
def table_sense(book, load):
    """The load sensor as a task's ``sense`` (:class:`~proteo_env.tasks.base.TaskKernels`): each
    root's share of its region's weight into ``load`` (A, 1) (:func:`root_loads`)."""
    root_loads(book, load[:, 0])


@kernel
def table_update_and_test(grid, cell, mode, anchored, dir_delta, cycle, book):
    """:func:`table_update`, then :func:`restabilised`, as a task's ``update_and_test``."""
    table_update(grid, cell, mode, anchored, cycle, book)
    return restabilised(book)


class TableReading(NamedTuple):
    """What the task reads of :class:`TableLedger` until the next cycle (:func:`table_cycle`):
    the grounded legs per region and their ``support`` (:func:`legs_and_support`), and the
    task's ``success`` (:func:`restabilised`)."""

    legs_left: int
    legs_right: int
    support: float
    success: bool


@kernel
def table_reading(book, loads):
    """Each root's load sensor into ``loads`` (A,) float32 (:func:`root_loads`); return the
    :class:`TableReading` fields of :class:`TableLedger` ``book``."""
    root_loads(book, loads)
    legs_left, legs_right, support = legs_and_support(book)
    return legs_left, legs_right, support, restabilised(book)


@kernel
def table_cycle(grid, cell, mode, anchored, cycle, book, loads):
    """:func:`table_update` after ``cycle``, then :func:`table_reading`, in one call; ``book`` is
    the :class:`TableLedger`'s fields as a plain tuple (numba types one at the call in half
    the time of a named tuple)."""
    book = TableLedger(*book)
    table_update(grid, cell, mode, anchored, cycle, book)
    return table_reading(book, loads)


MODES = tuple(TableMode.__members__)
ACTIVE = (ROOT, AROOT)
DOWN = np.flatnonzero(DIRECTIONS[:, 2] == -1)
"""The 4 face directions that go down one layer."""

PAPER_SCHEDULE = ((0, 8.0, 2.0), (400, 2.0, 8.0), (800, 5.0, 5.0))
"""The paper's sequences: little weight on the right (one leg there), the weight shifted to
the right half (sequence 1), then to the centre (sequence 2); ``W1 + W2 = 10``."""


@dataclass(frozen=True)
class TableParams:
    """Parameters of the table task (the rule parameters are read by the hand-coded policy).

    Attributes:
        board_size: the board covers ``0 <= x, y < board_size`` (paper: 30).
        root_spacing: roots every this many sites along x and y (paper: 3).
        depth: layers between the board and the floor, the number of modules in a leg.
        n_spares: spare modules hanging under the board's centre at the start.
        schedule: ``((cycle, W1, W2), ...)``: from ``cycle`` on, weight ``W1`` on the left
            half and ``W2`` on the right half. Cycles strictly increasing from 0; weights >= 0.
        p_max: probability per cycle that an IROOT reading more than ``f_max`` goes AROOT.
        p_min: probability per cycle that a ROOT reading less than ``f_min`` disbands its leg.
        f_max: load per active root above which roots grow legs; also a leg's capacity in the
            reward.
        f_min: load per active root below which roots disband legs (``f_min <= f_max``).
        load_cap: the sensor's saturation: the reading of a region with weight and no active
            root.
        stable_window: cycles a complete signature must stay unchanged to count as stable.
        leg_cost: reward lost per grounded leg per cycle.
    """

    board_size: int = 30
    root_spacing: int = 3
    depth: int = 6
    n_spares: int = 120
    schedule: tuple[tuple[int, float, float], ...] = PAPER_SCHEDULE
    p_max: float = 0.05
    p_min: float = 0.05
    f_max: float = 2.0
    f_min: float = 1.0
    load_cap: float = 100.0
    stable_window: int = 100
    leg_cost: float = 0.01

    def __post_init__(self):
        def bad(name, value, allowed):
            raise ValueError(f"{name}={value!r} is not allowed; allowed: {allowed}")

        if not isinstance(self.root_spacing, int) or self.root_spacing < 2:
            bad("root_spacing", self.root_spacing, "an integer >= 2")
        if not isinstance(self.board_size, int) or self.board_size < self.root_spacing + 1:
            bad("board_size", self.board_size, f"an integer >= root_spacing + 1 = {self.root_spacing + 1}")
        if not isinstance(self.depth, int) or self.depth < 1:
            bad("depth", self.depth, "an integer >= 1")
        room = (self.board_size**2 // 2) * self.depth
        if not isinstance(self.n_spares, int) or not 1 <= self.n_spares <= room // 2:
            bad("n_spares", self.n_spares, f"an integer in [1, {room // 2}] (half the room under the board)")
        schedule = _check_schedule(self.schedule)
        object.__setattr__(self, "schedule", schedule)
        for name in ("p_max", "p_min"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                bad(name, value, "a probability in [0, 1]")
        if not 0.0 <= self.f_min <= self.f_max:
            bad("f_min", self.f_min, f"a number in [0, f_max = {self.f_max}]")
        if self.f_max <= 0:
            bad("f_max", self.f_max, "a number > 0")
        if not self.load_cap > self.f_max:
            bad("load_cap", self.load_cap, f"a number > f_max = {self.f_max}")
        if not isinstance(self.stable_window, int) or self.stable_window < 1:
            bad("stable_window", self.stable_window, "an integer >= 1")
        if self.leg_cost < 0:
            bad("leg_cost", self.leg_cost, "a number >= 0")

    @property
    def shift_cycles(self) -> tuple[int, ...]:
        """The cycles at which the schedule's entries start (the first is 0)."""
        return tuple(entry[0] for entry in self.schedule)

    @property
    def root_offset(self) -> int:
        """First root row and column: centres the root sub-grid on the board."""
        span = self.root_spacing * ((self.board_size - 1) // self.root_spacing)
        return (self.board_size - 1 - span) // 2


def _check_schedule(schedule) -> tuple:
    allowed = "a non-empty sequence of (cycle, W1, W2) with cycles increasing from 0 and weights >= 0"
    try:
        entries = tuple((entry[0], entry[1], entry[2]) for entry in schedule if len(entry) == 3)
        ok = len(entries) == len(schedule) and len(entries) > 0
    except TypeError:
        ok = False
    if ok:
        ok = all(isinstance(c, int) and not isinstance(c, bool) for c, _, _ in entries)
        ok = ok and all(
            isinstance(w, (int, float)) and not isinstance(w, bool) and w >= 0
            for _, w1, w2 in entries
            for w in (w1, w2)
        )
        ok = ok and entries[0][0] == 0 and all(a[0] < b[0] for a, b in zip(entries, entries[1:]))
    if not ok:
        raise ValueError(f"schedule={schedule!r} is not allowed; allowed: {allowed}")
    return tuple((int(c), float(w1), float(w2)) for c, w1, w2 in entries)


def board_sites(p: TableParams) -> tuple[np.ndarray, np.ndarray]:
    """``(roots, fixed)``: the board's root sites and its other sites, each ``(K, 3)`` int64."""
    n, h = p.board_size, p.depth
    x, y = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    x, y = x.ravel(), y.ravel()
    on = (x + y + h) % 2 == 0
    x, y = x[on], y[on]
    o, s = p.root_offset, p.root_spacing
    is_root = ((x - o) % s == 0) & ((y - o) % s == 0) & (x >= o) & (y >= o)
    sites = np.stack([x, y, np.full_like(x, h)], axis=1).astype(np.int64)
    return sites[is_root], sites[~is_root]


def spare_sites(p: TableParams, under: tuple[float, float] | None = None) -> np.ndarray:
    """``(n_spares, 3)``: the sites under the board nearest the point ``(x, y, depth)`` of the board,
    ``under = (x, y)`` (default: the board's centre)."""
    n, h = p.board_size, p.depth
    g = np.mgrid[0:n, 0:n, 0:h].reshape(3, -1).T
    g = g[g.sum(axis=1) % 2 == 0]
    x, y = under if under is not None else ((n - 1) / 2, (n - 1) / 2)
    centre = np.array([x, y, h])
    d2 = ((g - centre) ** 2).sum(axis=1)
    order = np.lexsort((g[:, 1], g[:, 0], -g[:, 2], d2))
    return g[order[: p.n_spares]].astype(np.int64)


class Table(Task):
    name = "table"
    demo_settings = {
        "board_size": 18,
        "depth": 4,
        "n_spares": 60,
        "schedule": ((0, 8, 2), (250, 2, 8), (500, 5, 5)),
        "motion_model": "minimal",
    }
    version = 0
    modes = MODES
    Params = TableParams
    n_message_values = 15
    default_policy = "table"
    carry_weight = False
    """Success needs the legs to carry the weight (:func:`weight_carried`); True from v1."""
    follow_weight = False
    """The legs must follow the weight (``TableLedger.follow``); True from v2."""
    mode_roles = tuple((EMIT,) if m in (AROOT, SEED) else (RELAY,) for m in range(len(MODES)))
    """``move+mode``: an AROOT (a root growing a leg) and a leg's SEED emit; the rest relay."""
    plot_groups = {
        "legs and weight per region": ["legs_left", "legs_right", "weight_left", "weight_right"],
        "active roots per region": ["active_left", "active_right"],
        "leg decisions (cumulative)": ["leg_creations", "leg_disbands"],
    }

    # ------------------------------------------------------------------ layout
    def build_layout(self, rng):
        p = self.params
        roots, fixed = board_sites(p)
        modules = spare_sites(p, self.spares_under(rng))
        return Layout(
            size=(p.board_size, p.board_size, p.depth + 1), modules=modules, roots=roots, fixed=fixed, floor=True
        )

    def spares_under(self, rng) -> tuple[float, float] | None:
        """The point of the board the spares hang under (None: its centre, in every world)."""
        return None

    def initial_modes(self, layout):
        modes = np.full(len(layout.positions), FIXED, dtype=np.int32)
        n_spares, n_roots = len(layout.modules), len(layout.roots)
        modes[:n_spares] = SLEEP
        modes[n_spares : n_spares + n_roots] = IROOT
        return modes

    # ------------------------------------------------------------------ episode state
    def reset(self, world, rng):
        p = self.params
        roots = np.arange(p.n_spares, world.n_agents)
        r = len(roots)
        self.ledger = TableLedger(
            roots=roots,
            left=world.positions[roots, 0] < p.board_size / 2,
            down_delta=np.ascontiguousarray(world.dir_delta[DOWN]),
            shift_cycles=np.array(p.shift_cycles, dtype=np.int64),
            schedule_weights=np.array([entry[1:] for entry in p.schedule], dtype=np.float64),
            depth=p.depth,
            stable_window=p.stable_window,
            load_cap=float(p.load_cap),
            active=np.isin(world.mode[roots], ACTIVE),
            grounded=np.zeros(r, dtype=np.bool_),
            signature=np.zeros((2, r), dtype=np.bool_),
            clock=np.zeros(5, dtype=np.int64),
            weights=np.array(p.schedule[0][1:], dtype=np.float64),
            restabilise=np.full(len(p.schedule), -1.0),
            scratch=np.zeros((3, world.n_modules), dtype=np.int64),
            stamp=np.zeros(1, dtype=np.int64),
            f_max=float(p.f_max),
            carry=self.carry_weight,
            f_min=float(p.f_min),
            follow=self.follow_weight,
        )
        """The episode's bookkeeping (:class:`TableLedger`)."""
        book = self.ledger
        grounded_legs(world.grid, world.cell, world.mode, world.anchored, book)
        book.signature[0], book.signature[1] = book.active, book.grounded
        self._loads = np.zeros(world.n_agents, dtype=np.float32)
        self.reading = TableReading(*table_reading(book, self._loads))
        """The ledger's :class:`TableReading` after the last cycle."""
        self._ledger_fields = tuple(book)  # its arrays are updated in place

    def after_cycle(self, world, cycle):
        w = world
        reading = table_cycle(w.grid, w.cell, w.mode, w.anchored, cycle, self._ledger_fields, self._loads)
        self.reading = TableReading(*reading)

    # ------------------------------------------------------------------ sensors
    def load(self, world):
        return self._loads.copy()

    # ------------------------------------------------------------------ reward, metrics, success
    def reward_terms(self, world, moved):
        legs_left, legs_right, support, _ = self.reading
        return {"support": support, "legs": 0.0 - self.params.leg_cost * (legs_left + legs_right)}

    def metrics(self, world):
        book = self.ledger
        clock, active, left = book.clock, book.active, book.left
        legs_left, legs_right, support, success = self.reading
        load_left, load_right = region_loads(book)
        out = {
            "weight_left": float(book.weights[0]),
            "weight_right": float(book.weights[1]),
            "legs_left": float(legs_left),
            "legs_right": float(legs_right),
            "grounded_legs": float(legs_left + legs_right),
            "active_left": float((active & left).sum()),
            "active_right": float((active & ~left).sum()),
            "load_left": float(load_left),
            "load_right": float(load_right),
            "support": support,
            "stable": float(in_stable_configuration(book)),
            "leg_creations": float(clock[CREATIONS]),
            "leg_disbands": float(clock[DISBANDS]),
        }
        for k, value in enumerate(book.restabilise):
            out[f"restabilise_{k}"] = float(value)
        out["success"] = float(success)
        return out

    def kernels(self, world):
        return TaskKernels(table_sense, table_update_and_test, self.ledger.copy())

    def success(self, world):
        return bool(self.reading.success)


class TableV1(Table):
    """``table-v1``: settling never earns less than not settling, and the legs must carry the weight.

    ``table-v0`` paid ``support + legs`` every cycle and ended the episode at success, so a
    policy that never settles collected reward for the whole horizon and beat the rules
    (docs/tasks/table.md, "Reward against degenerate strategies"); and with no active root
    the empty signature counted as a stable configuration, so doing nothing succeeded. Here:

    - ``settled`` = ``(max_cycles - cycle) * (support + legs)`` on the cycle of success: the
      rest of the horizon paid at the stable configuration's rate, what holding it would have
      earned had the episode gone on (``max_cycles`` is the environment's cycle limit);
    - success also asks that the legs carry the weight: the stable configuration must be one
      in which each region's grounded legs carry ``min(W, f_max * R)`` of its weight ``W``
      (``R`` its roots; :func:`weight_carried`), tested with the rest of the stable period in
      :func:`table_update` (so the compiled rollout agrees, and a configuration that
      carries the weight only after the stable period was counted is not a success).

    Dynamics, observation, actions and the other terms are those of ``table-v0``.
    """

    version = 1
    carry_weight = True

    def reward_terms(self, world, moved):
        terms = super().reward_terms(world, moved)
        rest = self.max_cycles - int(self.ledger.clock[CYCLE])
        terms["settled"] = rest * (terms["support"] + terms["legs"]) if self.success(world) else 0.0
        return terms


class TableV2(TableV1):
    """``table-v2``: the legs must follow the weight, and every world starts from its own layout.

    In ``table-v1`` a table that grows a leg under every root and never disbands one succeeds
    whenever the final weights need every root (the benchmark's small board), and every world
    starts from the same layout, so held-out worlds differ only in their random streams. Here:

    - a stable configuration also has no idle leg: in each region the weight ``W`` is at least
      ``f_min`` per grounded leg (:func:`no_idle_legs`; the load below which the paper's roots
      disband), and success asks for a stable configuration after *every* shift of the schedule,
      each before the next (``restabilise_k`` known for every ``k``): when the weight leaves a
      half, its extra legs must go;
    - the spares hang under a point drawn from the world's seed, uniformly in the middle half of
      the board in x and in y (:meth:`spares_under`), instead of under its centre.

    Dynamics, observation, actions, reward and the other tests are those of ``table-v1``.
    """

    version = 2
    follow_weight = True

    def spares_under(self, rng) -> tuple[float, float]:
        n = self.params.board_size
        x, y = (n - 1) / 2 + rng.uniform(-n / 4, n / 4, size=2)
        return float(x), float(y)

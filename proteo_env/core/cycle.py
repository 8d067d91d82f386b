"""Numba kernels of one cycle: random numbers, roll legality, connectivity, scents, observations.

All state lives in plain arrays, carried by the named records of :mod:`proteo_env.core.records`
(:class:`~proteo_env.core.records.WorldState`, ``Settings``, ``Geometry``, ``Scratch``,
``Actions``, ``Observation``); kernels index the padded flat grid directly. The two entry
points are :func:`run_cycle` and :func:`observe_world`. These functions are internal: call them
through :mod:`proteo_env.core.world`.
"""

from __future__ import annotations

import numpy as np

from .jit import kernel
from .lattice import EMPTY, OBJECT, SOLID, WALL
from .motion import LOCAL_ADJACENCY_BITS
from .records import Actions, Geometry, Observation, Scratch, Settings, WorldState
from .structure import BARRED, UNREACHED, breadth_first

SILENT, RELAY, EMIT = 0, 1, 2
KIND_EMPTY, KIND_MODULE, KIND_SOLID, KIND_OBJECT = 0, 1, 2, 3
LABEL_BITS = 16  # connectivity search: mark = epoch * LABEL_BITS + group label (or REMOVED_LABEL)
REMOVED_LABEL = 15
LAST_EPOCH = (2**31 - 1) // LABEL_BITS - 1  # int32 marks: past it, marks are cleared and epochs restart
TABLE_SHIFT = -OBJECT
"""Grid value ``v`` (a module index, or EMPTY/WALL/SOLID/OBJECT) is row ``v + TABLE_SHIFT`` of a
table by grid value (:func:`site_tables`, the scent sweep), read instead of branching on ``v``."""


# ---------------------------------------------------------------- random numbers
@kernel
def rng_next(state):
    """xorshift64 (13, 7, 17): advance ``state[0]`` and return it."""
    x = state[0]
    x ^= x << np.uint64(13)
    x ^= x >> np.uint64(7)
    x ^= x << np.uint64(17)
    state[0] = x
    return x


@kernel
def rng_below(state, n):
    """Uniform integer in ``[0, n)`` for ``n < 2**31`` (multiply-high of the top 32 bits)."""
    return np.int64(((rng_next(state) >> np.uint64(32)) * np.uint64(n)) >> np.uint64(32))


@kernel
def shuffle(items, count, state):
    """Fisher-Yates shuffle of ``items[:count]`` in place."""
    for i in range(count - 1, 0, -1):
        j = rng_below(state, i + 1)
        items[i], items[j] = items[j], items[i]


# ---------------------------------------------------------------- rolls
@kernel
def legal_rolls(grid, c, roll_delta, roll_table, blocked, modules):
    """Bit ``k`` set when the body at cell ``c`` may roll towards direction ``k`` (geometry only).

    ``blocked`` and ``modules`` are the bits of the 12 face neighbours already read ("not
    empty", "holds a module"); the model's swept sites two hops away (``roll_delta[12:]``) are
    read here, and only when some target is empty. A roll is legal when its target is empty
    and some pivot holds a module whose swept cells are all empty; ``roll_table`` (see
    :func:`~proteo_env.core.motion.motion_bits`) decides the 12 directions a byte at a time.
    """
    if blocked == 0xFFF:
        return 0
    for i in range(12, roll_delta.shape[0]):
        if grid[c + roll_delta[i]] != EMPTY:
            blocked |= 1 << i
    low, high = modules & 255, modules >> 8
    legal = 0
    for j in range(4):
        swept = 0
        rest = blocked
        for i in range(2, roll_table.shape[1]):
            swept |= roll_table[j, i, rest & 255]
            rest >>= 8
        legal |= (roll_table[j, 0, low] | roll_table[j, 1, high]) & ~swept
    return legal & (0xFFF ^ (blocked & 0xFFF))


@kernel
def legal_directions(grid, c, roll_delta, roll_table):
    """:func:`legal_rolls` of the body at cell ``c``, reading its face neighbours first."""
    blocked = 0
    modules = 0
    for i in range(12):
        v = grid[c + roll_delta[i]]
        if v != EMPTY:
            blocked |= 1 << i
            if v >= 0:
                modules |= 1 << i
    return legal_rolls(grid, c, roll_delta, roll_table, blocked, modules)


# ---------------------------------------------------------------- connectivity
@kernel
def _flood(start, allowed, local_adjacent):
    """Bits of ``allowed`` local sites reachable from the ``start`` bits through ``allowed`` sites.

    ``local_adjacent[i, byte]`` is the union of the sites adjacent to the set bits of ``byte``
    at bits ``8 i .. 8 i + 7``, so a step of the flood costs one lookup per byte.
    """
    reached = start
    frontier = start
    while frontier:
        grown = 0
        i = 0
        f = frontier
        while f:
            grown |= local_adjacent[i, f & 255]
            f >>= 8
            i += 1
        frontier = grown & allowed & ~reached
        reached |= frontier
    return reached


LOWEST_BIT = np.array([0] + [(word & -word).bit_length() - 1 for word in range(1, 4096)], dtype=np.int8)
"""``(4096,)``: index of the lowest set bit of a 12-bit word (a table read instead of a loop)."""


_flood_in_python = getattr(_flood, "py_func", _flood)  # plain Python at import (also with NUMBA_DISABLE_JIT)
FACES_JOINED = np.array(
    [word & ~_flood_in_python(word & -word, word, LOCAL_ADJACENCY_BITS) == 0 for word in range(4096)], dtype=np.bool_
)
"""``(4096,)`` bool: whether a set of face neighbours (bit ``k``: direction ``k``) is connected
through face neighbours of the set alone (true for the empty set and one neighbour)."""

POSITION_SHIFT = 34
"""A connectivity search's stack entry packs a grid cell (the low 34 bits) and the cell's
position relative to the module that leaves (10 bits an axis, two's complement)."""


@kernel
def _pack(c, x, y, z):
    """Stack entry of cell ``c`` at position ``(x, y, z)``: a position beyond 511 sites wraps,
    which changes only the search's order, never its answer."""
    return (
        c
        | ((x & 1023) << POSITION_SHIFT)
        | ((y & 1023) << (POSITION_SHIFT + 10))
        | ((z & 1023) << (POSITION_SHIFT + 20))
    )


@kernel
def _unpack_axis(entry, axis):
    """Coordinate ``axis`` of the position packed in a stack entry."""
    return (((entry >> (POSITION_SHIFT + 10 * axis)) & 1023) ^ 512) - 512


@kernel
def detach_keeps_connected(grid, cell, m, geometry, scratch):
    """Do the other modules stay connected when module ``m`` leaves its cell?

    First local tests: if ``m``'s neighbours are connected to each other through ``m``'s other
    neighbours (:data:`FACES_JOINED`), or else through the modules within two hops of ``m``
    (read only then), yes; if a group of them reaches no module two hops away, that group is a
    whole piece, and no. Otherwise one depth-first search per group of neighbours runs in
    lockstep over the module graph (``m`` removed), each stepping first towards the next
    group's start. The searches stop when all groups have met (connected) or one group's
    stacks run out (that piece is cut off), so the cost is bounded by the size of the smallest
    piece.

    The search works on cells, so what it touches lies close together: ``mark`` (cells,) int32
    labels visited cells, and each group's stack in ``stacks`` (12, N) int64 holds entries that
    pack a cell with its position relative to ``m`` (:func:`_pack`). ``search`` (13,) holds the
    epoch in ``search[0]``, bumped so that ``mark`` needs clearing only when the epochs run out
    (:data:`LAST_EPOCH`), and the depth of each group's stack in ``search[1:13]``. Each group's
    merged root and start direction are packed in two integers, so a search allocates nothing.
    A visit classifies its module neighbours (new, or reached by another group) without
    branching on their labels.
    """
    dir_delta, directions = geometry.dir_delta, geometry.directions
    local_delta, local_adjacent = geometry.local_delta, geometry.local_adjacency
    mark, stacks, search = scratch.mark, scratch.stacks, scratch.search
    c = cell[m]
    touching = 0
    for i in range(12):
        touching |= np.int64(grid[c + local_delta[i]] >= 0) << i
    if FACES_JOINED[touching]:
        return True
    modules = touching
    for i in range(12, local_delta.shape[0]):
        modules |= np.int64(grid[c + local_delta[i]] >= 0) << i
    if touching & ~_flood(touching & -touching, modules, local_adjacent) == 0:
        return True

    if search[0] >= LAST_EPOCH:  # once in about 134 million searches
        mark.fill(-1)
        search[0] = 0
    search[0] += 1
    base = search[0] * LABEL_BITS
    depth = search[1:13]
    mark[c] = base + REMOVED_LABEL
    roots = 0
    start_directions = 0
    n_groups = 0
    remaining = touching
    while remaining:
        bit = remaining & -remaining
        reach = _flood(bit, modules, local_adjacent)
        if reach >> 12 == 0:  # face neighbours alone (bits 0-11), no module two hops away: a cut-off piece
            return False
        remaining &= ~reach
        k = LOWEST_BIT[bit]
        start = c + dir_delta[k]
        mark[start] = base + n_groups
        stacks[n_groups, 0] = _pack(start, directions[k, 0], directions[k, 1], directions[k, 2])
        depth[n_groups] = 1
        roots |= np.int64(n_groups) << (4 * n_groups)
        start_directions |= np.int64(k) << (4 * n_groups)
        n_groups += 1
    groups_left = n_groups
    while True:
        for g in range(n_groups):
            d = depth[g]
            if d == 0:
                continue
            d -= 1
            entry = stacks[g, d]
            cn = entry & ((np.int64(1) << POSITION_SHIFT) - 1)
            x, y, z = _unpack_axis(entry, 0), _unpack_axis(entry, 1), _unpack_axis(entry, 2)
            label = (roots >> (4 * g)) & 15
            around = 0
            for k in range(12):
                around |= np.int64(grid[cn + dir_delta[k]] >= 0) << k
            fresh = 0
            met = 0
            while around:  # the module neighbours: not reached yet, or reached by another group
                k = LOWEST_BIT[around]
                around &= around - 1
                seen_label = mark[cn + dir_delta[k]] - base
                seen = np.int64(seen_label >= 0)
                fresh |= (seen ^ 1) << k
                other = (roots >> (4 * (seen_label & 15))) & 15
                met |= (seen & np.int64(other != label) & np.int64(seen_label != REMOVED_LABEL)) << k
            while met:  # the groups join
                k = LOWEST_BIT[met]
                met &= met - 1
                other = (roots >> (4 * (mark[cn + dir_delta[k]] - base))) & 15
                if other == label:  # joined already through an earlier neighbour of this visit
                    continue
                groups_left -= 1
                if groups_left == 1:
                    return True
                for h in range(n_groups):
                    if (roots >> (4 * h)) & 15 == other:
                        roots ^= (other ^ label) << (4 * h)
            target = directions[(start_directions >> (4 * ((g + 1) % n_groups))) & 15]
            tx, ty, tz = x - target[0], y - target[1], z - target[2]
            best_at, best_score = -1, 1 << 62
            while fresh:  # pushed in direction order; the one nearest the target goes on top
                k = LOWEST_BIT[fresh]
                fresh &= fresh - 1
                nc = cn + dir_delta[k]
                mark[nc] = base + g
                dx, dy, dz = directions[k, 0], directions[k, 1], directions[k, 2]
                stacks[g, d] = _pack(nc, x + dx, y + dy, z + dz)
                score = dx * tx + dy * ty + dz * tz  # |p + d - t|^2 less what every d shares: same order
                if score < best_score:
                    best_at, best_score = d, score
                d += 1
            depth[g] = d
            if best_at >= 0:
                stacks[g, d - 1], stacks[g, best_at] = stacks[g, best_at], stacks[g, d - 1]
            elif d == 0:  # this group ran out: its piece is cut off if its joined groups did too
                left = 0
                for h in range(n_groups):
                    if (roots >> (4 * h)) & 15 == label:
                        left += depth[h]
                if left == 0:
                    return False


@kernel
def module_adjacency(grid, cell, n_modules, dir_delta, adjacency):
    """Fill ``adjacency`` (N, 13) int32: row ``n`` lists the module neighbours of module ``n``
    in direction order, and column 12 holds how many there are."""
    for n in range(n_modules):
        c = cell[n]
        degree = 0
        for k in range(12):
            v = grid[c + dir_delta[k]]
            adjacency[n, degree] = v
            degree += v >= 0
        adjacency[n, 12] = degree


@kernel
def articulation_points(grid, cell, n_modules, dir_delta, scratch):
    """Mark in ``scratch.is_cut`` (N,) the modules whose removal disconnects the module graph.

    Iterative Tarjan depth-first search over every component, on the neighbour lists of
    :func:`module_adjacency` (so each edge costs one read); it works in the scratch arrays
    ``adjacency`` (N, 13) and ``disc``, ``low``, ``stack_node``, ``stack_k`` (N,).
    """
    is_cut, adjacency, disc, low = scratch.is_cut, scratch.adjacency, scratch.disc, scratch.low
    stack_node, stack_k = scratch.stack_node, scratch.stack_k
    module_adjacency(grid, cell, n_modules, dir_delta, adjacency)
    for n in range(n_modules):
        disc[n] = -1
        is_cut[n] = False
    timer = 0
    for root in range(n_modules):
        if disc[root] >= 0:
            continue
        disc[root] = low[root] = timer
        timer += 1
        top = 0
        stack_node[0] = root
        stack_k[0] = 0
        root_children = 0
        while top >= 0:
            n = stack_node[top]
            k = stack_k[top]
            if k < adjacency[n, 12]:
                stack_k[top] = k + 1
                nb = adjacency[n, k]
                if disc[nb] < 0:
                    disc[nb] = low[nb] = timer
                    timer += 1
                    if n == root:
                        root_children += 1
                    top += 1
                    stack_node[top] = nb
                    stack_k[top] = 0
                elif top == 0 or nb != stack_node[top - 1]:
                    low[n] = min(low[n], disc[nb])
            else:
                top -= 1
                if top >= 0:
                    parent = stack_node[top]
                    low[parent] = min(low[parent], low[n])
                    if parent != root and low[n] >= disc[parent]:
                        is_cut[parent] = True
        if root_children > 1:
            is_cut[root] = True


@kernel
def out_of_room(cell, strides, guard):
    """Whether a module's padded-grid coordinates (from its ``cell`` (N,) and the grid's
    ``strides`` (3,)) leave ``guard`` (6,), ``(lo_x, hi_x, lo_y, hi_y, lo_z, hi_z)``: the
    window must grow before the next cycle (:meth:`~proteo_env.core.lattice.GridShape.guard`)."""
    for n in range(cell.shape[0]):
        x, rest = divmod(cell[n], strides[0])
        y, z = divmod(rest, strides[1])
        if x < guard[0] or x > guard[1] or y < guard[2] or y > guard[3] or z < guard[4] or z > guard[5]:
            return True
    return False


@kernel
def count_components(grid, cell, n_modules, dir_delta, mark, queue):
    """Number of connected components of the module graph (``mark``/``queue`` (N,) scratch)."""
    for n in range(n_modules):
        mark[n] = 0
    components = 0
    for root in range(n_modules):
        if mark[root]:
            continue
        components += 1
        mark[root] = 1
        queue[0] = root
        head, tail = 0, 1
        while head < tail:
            n = queue[head]
            head += 1
            for k in range(12):
                nb = grid[cell[n] + dir_delta[k]]
                if nb >= 0 and not mark[nb]:
                    mark[nb] = 1
                    queue[tail] = nb
                    tail += 1
    return components


# ---------------------------------------------------------------- the cycle
@kernel
def deliver_messages(state, n_agents, actions, dir_delta, opposite):
    """Clear ``state.inbox`` (N, 12) and deliver this cycle's messages, in agent order.

    ``actions.message_target[a]`` is a direction ``0..11`` or ``12`` for all neighbours; a
    value of 0 sends nothing. The receiver finds the value in the slot of the direction it
    came from.
    """
    grid, cell, inbox = state.grid, state.cell, state.inbox
    target, message = actions.message_target, actions.message_value
    inbox[:] = 0
    for a in range(n_agents):
        value = message[a]
        if value == 0:
            continue
        c = cell[a]
        first, last = (0, 12) if target[a] == 12 else (target[a], target[a] + 1)
        for k in range(first, last):
            receiver = grid[c + dir_delta[k]]
            if receiver >= 0:
                inbox[receiver, opposite[k]] = value


@kernel
def execute_moves(state, settings, geometry, move, moved, scratch):
    """Try the requested moves one by one in a fresh random order; set ``moved`` (A,) flags.

    ``move[a]`` (A,) is 0 (stay) or ``k + 1`` to roll towards direction ``k``. Each move is
    checked against the occupancy at the moment it is tried. Returns the number of modules
    moved.
    """
    grid, cell, anchored = state.grid, state.cell, state.anchored
    dir_delta, roll_delta, roll_table = geometry.dir_delta, geometry.roll_delta, geometry.roll_table
    movers = scratch.movers
    n_movers = 0
    for a in range(settings.n_agents):
        moved[a] = False
        if move[a] > 0 and not anchored[a]:
            movers[n_movers] = a
            n_movers += 1
    shuffle(movers, n_movers, state.rng_state)
    n_moved = 0
    for i in range(n_movers):
        a = movers[i]
        k = move[a] - 1
        c = cell[a]
        if grid[c + dir_delta[k]] != EMPTY:  # the common denial, decided by one read
            continue
        if not (legal_directions(grid, c, roll_delta, roll_table) >> k) & 1:
            continue
        if settings.keep_connected and not detach_keeps_connected(grid, cell, a, geometry, scratch):
            continue
        grid[c] = EMPTY
        grid[c + dir_delta[k]] = a
        cell[a] = c + dir_delta[k]
        moved[a] = True
        n_moved += 1
    return n_moved


@kernel
def _has_empty_neighbour(grid, c, dir_delta):
    for k in range(12):
        if grid[c + dir_delta[k]] == EMPTY:
            return True
    return False


@kernel
def relax_scent(grid, cell, n_modules, role, surface, values, buffer, sweeps, scent_max, dir_delta):
    """``sweeps`` Jacobi sweeps of one scent channel; ``values``/``buffer`` (N,), ``role`` (N,).

    Emitters hold 0, silent modules ``scent_max``; a relay takes one more than the smallest
    neighbour value of the previous sweep (saturating at ``scent_max``). On a surface channel
    a relay with no empty neighbour relays nothing. A sweep that changes no value has reached the
    fixed point, and the sweeps left would repeat it: they are skipped (the same values).
    """
    shown = np.empty(n_modules + TABLE_SHIFT, np.int32)  # a site's value by grid value: no branch on it
    shown[:TABLE_SHIFT] = scent_max
    for _ in range(sweeps):
        shown[TABLE_SHIFT:] = values[:n_modules]
        changed = False
        for n in range(n_modules):
            r = role[n]
            if r == EMIT:
                buffer[n] = 0
            elif r == SILENT or (surface and not _has_empty_neighbour(grid, cell[n], dir_delta)):
                buffer[n] = scent_max
            else:
                best = scent_max
                cn = cell[n]
                for k in range(12):
                    best = min(best, shown[grid[cn + dir_delta[k]] + TABLE_SHIFT])
                buffer[n] = min(best + 1, scent_max)
            changed |= buffer[n] != values[n]
        values[:n_modules] = buffer[:n_modules]
        if not changed:
            break


@kernel
def exact_scent(grid, cell, n_modules, role, surface, values, reach, queue, scent_max, dir_delta):
    """True hop distances from the emitters through relaying modules (multi-source
    :func:`~.structure.breadth_first`; ``reach`` and ``queue`` (N,) scratch)."""
    tail = 0
    for n in range(n_modules):
        values[n] = scent_max
        if role[n] == EMIT:
            values[n] = 0
            reach[n] = -1
            queue[tail] = n
            tail += 1
        elif role[n] == RELAY and (not surface or _has_empty_neighbour(grid, cell[n], dir_delta)):
            reach[n] = UNREACHED
        else:
            reach[n] = BARRED
    sources = tail
    tail = breadth_first(grid, cell, dir_delta, reach, queue, tail, scent_max - 1)
    for i in range(sources, tail):  # parents before children
        n = queue[i]
        values[n] = values[reach[n]] + 1


# ---------------------------------------------------------------- observations
@kernel
def site_tables(mode, scent, scent_max):
    """What a neighbour site shows, for every grid value: ``(kind_of, mode_of, scent_of)``,
    ``(N + TABLE_SHIFT,)`` int8, ``(N + TABLE_SHIFT,)`` int32 and ``(N + TABLE_SHIFT, C)``
    int32, row ``v + TABLE_SHIFT`` for grid value ``v``: a module's kind, mode and scents, and
    for the other values their kind, mode -1 and ``scent_max``. The observation reads them
    instead of branching on the value, which the processor cannot predict in a large world.
    """
    n_modules, n_channels = mode.shape[0], scent.shape[0]
    kind_of = np.empty(n_modules + TABLE_SHIFT, np.int8)
    mode_of = np.empty(n_modules + TABLE_SHIFT, np.int32)
    scent_of = np.empty((n_modules + TABLE_SHIFT, n_channels), np.int32)
    for v, kind in ((EMPTY, KIND_EMPTY), (WALL, KIND_SOLID), (SOLID, KIND_SOLID), (OBJECT, KIND_OBJECT)):
        kind_of[v + TABLE_SHIFT] = kind
        mode_of[v + TABLE_SHIFT] = -1
        scent_of[v + TABLE_SHIFT] = scent_max
    for n in range(n_modules):
        kind_of[n + TABLE_SHIFT] = KIND_MODULE
        mode_of[n + TABLE_SHIFT] = mode[n]
        for ch in range(n_channels):
            scent_of[n + TABLE_SHIFT, ch] = scent[ch, n]
    return kind_of, mode_of, scent_of


@kernel
def _show_site(out, a, s, row, kind_of, mode_of, scent_of):
    """Agent ``a``'s neighbour site ``s`` from row ``row`` of the :func:`site_tables`."""
    out.neighbour_kind[a, s] = kind_of[row]
    out.neighbour_mode[a, s] = mode_of[row]
    for ch in range(scent_of.shape[1]):
        out.neighbour_scent[a, s, ch] = scent_of[row, ch]


@kernel
def observe(state, settings, geometry, is_cut, out):
    """Fill the per-agent observation arrays of ``out`` (an :class:`~.records.Observation`,
    first axis: agent) from the world state.

    One pass over each agent's neighbourhood sites (``geometry.neighbourhood_delta``, the 12
    face neighbours first) fills the neighbour fields, the contacts and the face-neighbour
    bits from which the action mask follows (:func:`legal_rolls`). A module's moves are masked
    out when it may not leave its site: anchored, or, with ``keep_connected``, a cut module
    (``is_cut`` (N,) from :func:`articulation_points`).
    """
    grid, cell, mode, scent, inbox, anchored = (
        state.grid,
        state.cell,
        state.mode,
        state.scent,
        state.inbox,
        state.anchored,
    )
    n_agents, keep_connected, scent_max = settings.n_agents, settings.keep_connected, settings.scent_max
    nb_delta, roll_delta, roll_table = geometry.neighbourhood_delta, geometry.roll_delta, geometry.roll_table
    own_mode, own_scent, messages, contact, action_mask = (
        out.own_mode,
        out.own_scent,
        out.messages,
        out.contact,
        out.action_mask,
    )
    n_channels = scent.shape[0]
    n_sites = nb_delta.shape[0]
    kind_of, mode_of, scent_of = site_tables(mode, scent, scent_max)
    for a in range(n_agents):
        c = cell[a]
        blocked = 0
        modules = 0
        ground = False
        touching = False
        for s in range(12):  # the face neighbours: fields and bits, without branching on the value
            v = grid[c + nb_delta[s]]
            _show_site(out, a, s, v + TABLE_SHIFT, kind_of, mode_of, scent_of)
            blocked |= np.int64(v != EMPTY) << s
            modules |= np.int64(v >= 0) << s
            ground |= v == SOLID
            touching |= v == OBJECT
        for s in range(12, n_sites):
            _show_site(out, a, s, grid[c + nb_delta[s]] + TABLE_SHIFT, kind_of, mode_of, scent_of)
        own_mode[a, 0] = mode[a]
        for ch in range(n_channels):
            own_scent[a, ch] = scent[ch, a]
        for k in range(12):
            messages[a, k] = inbox[a, k]
        contact[a, 0] = ground
        contact[a, 1] = touching
        action_mask[a, 0] = 1
        legal = 0
        if not anchored[a] and not (keep_connected and is_cut[a]):
            legal = legal_rolls(grid, c, roll_delta, roll_table, blocked, modules)
        for k in range(12):
            action_mask[a, k + 1] = (legal >> k) & 1


# ---------------------------------------------------------------- whole cycle, whole observation
@kernel
def run_cycle(state, settings, geometry, actions, moved, scratch):
    """One cycle of one world (docs/model.md, "The cycle"); returns the number of modules moved.

    ``state`` (:class:`~.records.WorldState`), ``settings``, ``geometry``, ``actions`` and
    ``scratch`` are the records of :mod:`~proteo_env.core.records`, named or plain tuples in
    field order; ``moved`` (A,) bool is set to who moved.
    """
    state, settings, geometry = WorldState(*state), Settings(*settings), Geometry(*geometry)
    actions, scratch = Actions(*actions), Scratch(*scratch)
    grid, cell, scent = state.grid, state.cell, state.scent
    n_agents, n_modules = settings.n_agents, len(cell)
    state.mode[:n_agents] = actions.mode
    deliver_messages(state, n_agents, actions, geometry.dir_delta, geometry.opposite)
    n_moved = execute_moves(state, settings, geometry, actions.move, moved, scratch)
    channel_role = np.empty(n_modules, dtype=np.int8)
    for ch in range(scent.shape[0]):
        channel_role[:n_agents] = actions.scent_role[:, ch]
        channel_role[n_agents:] = settings.passive_role[ch]
        surface = settings.surface_channels[ch]
        if settings.exact_scent:
            exact_scent(
                grid,
                cell,
                n_modules,
                channel_role,
                surface,
                scent[ch],
                scratch.scent_buffer,
                scratch.queue,
                settings.scent_max,
                geometry.dir_delta,
            )
        else:
            relax_scent(
                grid,
                cell,
                n_modules,
                channel_role,
                surface,
                scent[ch],
                scratch.scent_buffer,
                settings.scent_sweeps,
                settings.scent_max,
                geometry.dir_delta,
            )
    return n_moved


@kernel
def observe_world(state, settings, geometry, scratch, out):
    """Every agent's observation of one world into ``out`` (an :class:`~.records.Observation`),
    cut modules found first when connectivity is kept; records as in :func:`run_cycle`."""
    state, settings, geometry = WorldState(*state), Settings(*settings), Geometry(*geometry)
    scratch, out = Scratch(*scratch), Observation(*out)
    if settings.keep_connected:
        articulation_points(state.grid, state.cell, len(state.cell), geometry.dir_delta, scratch)
    observe(state, settings, geometry, scratch.is_cut, out)

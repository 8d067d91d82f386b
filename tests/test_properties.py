"""Invariants of the engine under long random play, checked with hypothesis.

Each example builds a random world (a blob of 2 to 40 modules, optionally on a floor, among
obstacles and object sites, with some anchored modules), then plays random actions, half of
them legal by the action mask and half uniform over all 13 moves. After every cycle:

* no two modules share a site, the module count is kept, no module is outside the box or in
  a solid or object site, anchored modules never move;
* with ``keep_connected`` the robot stays one piece;
* every move happened exactly when it was legal at its moment: the engine's move order is
  recovered by replaying its xorshift64 shuffle, and the moves are replayed in that order on a
  :class:`~proteo_env.core.reference.ReferenceWorld`, whose plain-Python rules judge each one;
* a module whose move is tried before any other module has moved moves exactly when its
  action mask allowed that move.
"""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from proteo_env.core.motion import MOTION_MODELS
from proteo_env.core.reference import ReferenceWorld, shuffled
from proteo_env.core.world import LayoutError, Physics, World
from proteo_env.layouts import blob_sites, place_in_box
from proteo_env.spaces import ObservationBuffers

SETTINGS = dict(deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])


@st.composite
def worlds(draw, *, min_modules=2, max_modules=40):
    """World keyword arguments of a random layout (physics included)."""
    n = draw(st.integers(min_modules, max_modules))
    seed = draw(st.integers(0, 2**32 - 1))
    floor = draw(st.booleans())
    obstacles = draw(st.booleans())
    rng = np.random.default_rng(seed)
    sites, size = place_in_box(blob_sites(n, rng, flat=floor), margin=draw(st.integers(1, 3)), floor=floor)
    kw = dict(size=size, positions=sites, n_agents=n, floor=floor)
    if obstacles:
        taken = {tuple(p) for p in sites.tolist()}
        g = np.mgrid[0 : size[0], 0 : size[1], 0 : size[2]].reshape(3, -1).T
        free = np.array([p for p in g if p.sum() % 2 == 0 and tuple(p.tolist()) not in taken])
        pick = rng.permutation(len(free))
        kw["solid"] = free[pick[: len(free) // 5]]
        kw["object_sites"] = free[pick[len(free) // 5 : len(free) // 5 + 8]]
    n_anchored = draw(st.integers(0, min(3, n - 1)))
    anchored = np.zeros(n, dtype=bool)
    anchored[rng.choice(n, n_anchored, replace=False)] = True
    kw["anchored"] = anchored
    kw["physics"] = Physics(motion_model=draw(st.sampled_from(MOTION_MODELS)), keep_connected=draw(st.booleans()))
    return kw


def random_actions(rng, n_agents, mask):
    move = rng.integers(0, 13, n_agents)
    for a in np.flatnonzero(rng.random(n_agents) < 0.5):
        legal = np.flatnonzero(mask[a])
        move[a] = rng.choice(legal)
    return dict(
        move=move,
        mode=np.zeros(n_agents, dtype=np.int64),
        scent_role=np.ones((n_agents, 1), dtype=np.int64),
        message_target=np.zeros(n_agents, dtype=np.int64),
        message_value=np.zeros(n_agents, dtype=np.int64),
    )


def check_occupancy(world: World, kw: dict) -> None:
    pos = world.positions
    assert pos.shape == (len(kw["positions"]), 3)
    assert len({tuple(p) for p in pos.tolist()}) == len(pos), "two modules on one site"
    assert ((pos >= 0) & (pos < np.array(kw["size"]))).all(), "module outside the box"
    assert (pos.sum(axis=1) % 2 == 0).all(), "module off the FCC lattice"
    blocked = {tuple(p) for p in np.asarray(kw.get("solid", np.zeros((0, 3))), dtype=np.int64).tolist()}
    blocked |= {tuple(p) for p in np.asarray(kw.get("object_sites", np.zeros((0, 3))), dtype=np.int64).tolist()}
    assert not blocked & {tuple(p) for p in pos.tolist()}, "module in a solid or object site"


@settings(max_examples=250, **SETTINGS)
@given(kw=worlds(), cycles=st.integers(30, 100), action_seed=st.integers(0, 2**32 - 1))
def test_random_play_keeps_invariants_and_moves_only_legally(kw, cycles, action_seed):
    world = World(**kw)
    ref = ReferenceWorld(**kw)
    world.seed(action_seed)
    rng = np.random.default_rng(action_seed)
    buffers = ObservationBuffers(world.n_agents, 12, 1)
    anchored = np.asarray(kw["anchored"])
    start = world.positions
    keep = kw["physics"].keep_connected
    for t in range(cycles):
        world.observe(buffers)
        mask = buffers.action_mask.copy()
        actions = random_actions(rng, world.n_agents, mask)
        move = actions["move"]
        movers = [a for a in range(world.n_agents) if move[a] > 0 and not anchored[a]]
        order, state_after = shuffled(movers, int(world.rng_state[0]))

        moved = world.step(**actions)

        assert int(world.rng_state[0]) == state_after, "the shuffle used the generator differently"
        anyone_moved = False
        for a in order:
            k = int(move[a]) - 1
            legal = ref.move_is_legal(a, k)
            assert bool(moved[a]) == legal, (
                f"cycle {t}: module {a} towards {k}: engine moved={bool(moved[a])}, reference legal={legal}"
            )
            if not anyone_moved:
                assert bool(moved[a]) == bool(mask[a, k + 1]), f"cycle {t}: module {a} ignored its action mask"
            if legal:
                ref.apply_move(a, k)
                anyone_moved = True
        assert not moved[[a for a in range(world.n_agents) if a not in order]].any(), "a non-mover moved"
        np.testing.assert_array_equal(world.positions, ref.positions())
        check_occupancy(world, kw)
        np.testing.assert_array_equal(world.positions[anchored], start[anchored], err_msg="an anchored module moved")
        if keep:
            assert world.n_components() == 1, f"cycle {t}: the robot came apart"


@settings(max_examples=150, **SETTINGS)
@given(kw=worlds(min_modules=3), cycles=st.integers(0, 40), action_seed=st.integers(0, 2**32 - 1))
def test_detach_test_and_cut_modules_match_a_full_search(kw, cycles, action_seed):
    """The engine's local-then-lockstep detach test and its Tarjan cut set agree with a plain BFS."""
    kw["physics"] = Physics(motion_model="minimal", keep_connected=True)  # lively, stays one piece
    kw["anchored"] = np.zeros(len(kw["positions"]), dtype=bool)
    world = World(**kw)
    world.seed(action_seed)
    rng = np.random.default_rng(action_seed)
    buffers = ObservationBuffers(world.n_agents, 12, 1)
    for _ in range(cycles):
        world.observe(buffers)
        world.step(**random_actions(rng, world.n_agents, buffers.action_mask))
    ref = ReferenceWorld(**{**kw, "positions": world.positions})
    cut = world.cut_modules().copy()
    for m in range(world.n_modules):
        expected = ref.can_detach(m)
        assert world.can_detach(m) == expected, f"module {m}: can_detach disagrees with a full search"
        assert bool(cut[m]) == (not expected), f"module {m}: cut_modules disagrees with a full search"


def _thin_loop(length: int, closed: bool) -> list[tuple[int, int, int]]:
    """Two lines of ``length`` modules along (1, 1, 0), at z = 0 and z = 4, joined by a column at
    the near end and, when ``closed``, by another at the far end: a loop about ``2 * length`` long."""
    near = [(0, 0, 0), (1, 0, 1), (0, 0, 2), (1, 0, 3), (0, 0, 4)]
    lines = [(i, i, z) for i in range(1, length + 1) for z in (0, 4)]
    far = [(length + 1, length, 1), (length, length, 2), (length + 1, length, 3)] if closed else []
    return near + lines + far


def test_the_detach_search_is_exact_where_its_positions_pass_511_sites():
    """The search packs each cell's position relative to the leaving module in 10 bits an axis;
    beyond 511 sites they wrap, which may change the search's order but not its answer. The
    near column's middle module joins the two lines only locally: without it, the lines meet 600
    sites away (closed loop: it may leave) or not at all (open: a cut module)."""
    for closed in (True, False):
        positions = _thin_loop(600, closed)
        kw = dict(size=(603, 603, 5), positions=positions, n_agents=len(positions), physics=Physics())
        world, ref = World(**kw), ReferenceWorld(**kw)
        m = positions.index((0, 0, 2))
        assert world.n_components() == 1
        assert world.can_detach(m) == ref.can_detach(m) == closed
        assert bool(world.cut_modules()[m]) == (not closed)


def _relax_only(world, roles):
    """A cycle in which nobody moves or sends: only the scents change (agents keep their modes)."""
    a = world.n_agents
    world.step(
        move=np.zeros(a, np.int64),
        mode=world.mode[:a].copy(),
        scent_role=roles,
        message_target=np.zeros(a, np.int64),
        message_value=np.zeros(a, np.int32),
    )


@settings(max_examples=150, **SETTINGS)
@given(kw=worlds(), scent_max=st.integers(3, 30), surface=st.booleans(), role_seed=st.integers(0, 2**32 - 1))
def test_enough_sweeps_reach_the_exact_scent(kw, scent_max, surface, role_seed):
    """From any stale field, ``scent_max + N`` Jacobi sweeps give the exact hop distances."""
    n = len(kw["positions"])
    rng = np.random.default_rng(role_seed)
    common = dict(kw, n_channels=1, surface_channels=np.array([surface]))
    base = kw["physics"]
    exact = World(
        **{
            **common,
            "physics": Physics(
                motion_model=base.motion_model,
                keep_connected=base.keep_connected,
                exact_scent=True,
                scent_max=scent_max,
            ),
        }
    )
    sweeping = World(
        **{
            **common,
            "physics": Physics(
                motion_model=base.motion_model,
                keep_connected=base.keep_connected,
                scent_sweeps=scent_max + n,
                scent_max=scent_max,
            ),
        }
    )
    # a stale field first: values left over from other roles
    sweeping.scent[:] = rng.integers(0, scent_max + 1, (1, n))
    roles = rng.choice(3, size=(n, 1), p=[0.2, 0.7, 0.1])
    for world in (exact, sweeping):
        _relax_only(world, roles[: world.n_agents])
    np.testing.assert_array_equal(sweeping.scent, exact.scent)
    assert (exact.scent[0][roles[:, 0] == 2] == 0).all()
    assert (exact.scent[0][roles[:, 0] == 0] == scent_max).all()


@settings(max_examples=60, **SETTINGS)
@given(kw=worlds(), cycles=st.integers(5, 30), seed=st.integers(0, 2**64 - 1))
def test_same_seed_and_actions_give_the_same_trajectory(kw, cycles, seed):
    a, b = World(**kw), World(**kw)
    a.seed(seed)
    b.seed(seed)
    rng = np.random.default_rng(seed % 2**32)
    buffers = ObservationBuffers(a.n_agents, 12, 1)
    for _ in range(cycles):
        a.observe(buffers)
        actions = random_actions(rng, a.n_agents, buffers.action_mask)
        np.testing.assert_array_equal(a.step(**actions), b.step(**actions))
        sa, sb = a.snapshot(), b.snapshot()
        for key in sa:
            np.testing.assert_array_equal(sa[key], sb[key], err_msg=key)


CORRUPTIONS = ("odd_site", "outside_box", "duplicate", "on_solid", "on_object", "too_many_agents", "split")


@settings(max_examples=80, **SETTINGS)
@given(kw=worlds(min_modules=3), corruption=st.sampled_from(CORRUPTIONS), pick=st.integers(0, 2**16))
def test_bad_layouts_get_one_clear_error(kw, corruption, pick):
    """Bad input: a bad layout is refused with a ``LayoutError`` that says what is allowed."""
    pos = np.array(kw["positions"], dtype=np.int64)
    n = len(pos)
    m = pick % n
    size = kw["size"]
    if corruption == "odd_site":
        pos[m, 0] += 1 if pos[m, 0] + 1 < size[0] else -1
    elif corruption == "outside_box":
        axis = pick % 3
        pos[m, axis] = size[axis] + 2 * (pick % 2)  # just outside, or further
    elif corruption == "duplicate":
        pos[m] = pos[(m + 1) % n]
    elif corruption in ("on_solid", "on_object"):
        key = "solid" if corruption == "on_solid" else "object_sites"
        kw[key] = np.concatenate([np.asarray(kw.get(key, np.zeros((0, 3))), dtype=np.int64), pos[m : m + 1]])
    elif corruption == "too_many_agents":
        kw["n_agents"] = n + 1 + pick % 3
    elif corruption == "split":  # one module far away in a wider box, connectivity enforced
        kw["physics"] = Physics(motion_model=kw["physics"].motion_model, keep_connected=True)
        x = size[0] + 4 + size[0] % 2
        pos[m] = (x, 0, 0)
        kw["size"] = (x + 1, size[1], size[2])
    kw["positions"] = pos
    try:
        World(**kw)
    except LayoutError as error:
        assert "allowed" in str(error)
    else:
        raise AssertionError(f"{corruption}: the bad layout was accepted")

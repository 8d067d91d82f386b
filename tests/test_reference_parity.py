"""Parity: the engine (`World`, Numba kernels) and the plain-Python `ReferenceWorld` agree bit for bit.

Both are built from the same layout, seeded alike and driven by the same random actions; after
every cycle the positions, modes, scents, inboxes, moved flags, generator state and every
observation field must be identical. One test repeats a short run in a subprocess under
``NUMBA_DISABLE_JIT=1`` so the kernels are also checked as plain Python.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from conftest import run_without_jit

from proteo_env.core.cycle import LAST_EPOCH
from proteo_env.core.motion import MOTION_MODELS
from proteo_env.core.records import Observation
from proteo_env.core.reference import ReferenceWorld
from proteo_env.core.world import Physics, World
from proteo_env.layouts import ball_sites, blob_sites, line_sites, place_in_box
from proteo_env.spaces import ObservationBuffers


@dataclass(frozen=True)
class Case:
    layout: str
    model: str
    keep_connected: bool
    scent: str  # "sweep1", "sweep3" or "exact"
    n_channels: int
    surface: bool
    cycles: int
    seed: int


# ------------------------------------------------------------------ layouts
def make_layout(name: str, seed: int) -> dict:
    """World keyword arguments (minus physics and channels) of a named test layout."""
    rng = np.random.default_rng(seed)
    kw: dict = {}
    if name.startswith("blob"):
        sites, size = place_in_box(blob_sites(int(name[4:]), rng), margin=2)
    elif name == "ball":
        sites, size = place_in_box(ball_sites(19), margin=2)
    elif name == "line":
        sites, size = place_in_box(line_sites(8, (1, 0, 1)), margin=2)
    elif name == "floor":
        sites, size = place_in_box(blob_sites(25, rng, flat=True), margin=2, floor=True)
        kw["floor"] = True
    elif name == "obstacles":
        sites, size = place_in_box(blob_sites(25, rng), margin=2)
        free = _free_sites(size, sites)
        pick = rng.permutation(len(free))
        kw["solid"] = free[pick[: len(free) // 6]]
        kw["object_sites"] = free[pick[len(free) // 6 : len(free) // 6 + 12]]
        kw["floor"] = True
    elif name == "anchored":
        sites, size = place_in_box(blob_sites(30, rng), margin=2)
        n_passive = 8
        anchored = np.zeros(len(sites), dtype=bool)
        anchored[:3] = True  # three anchored agents (roots)
        anchored[len(sites) - n_passive :] = True  # passive board modules
        kw["anchored"] = anchored
        kw["n_agents"] = len(sites) - n_passive
        kw["modes"] = rng.integers(0, 4, len(sites))
    else:
        raise ValueError(name)
    kw.setdefault("n_agents", len(sites))
    return dict(size=size, positions=sites, **kw)


def _free_sites(size, sites) -> np.ndarray:
    taken = {tuple(p) for p in sites}
    g = np.mgrid[0 : size[0], 0 : size[1], 0 : size[2]].reshape(3, -1).T
    g = g[g.sum(axis=1) % 2 == 0]
    return np.array([p for p in g if tuple(p) not in taken], dtype=np.int64)


def build(case: Case, obs_radius: int = 1):
    kw = make_layout(case.layout, case.seed)
    physics = Physics(
        motion_model=case.model,
        keep_connected=case.keep_connected,
        scent_sweeps=3 if case.scent == "sweep3" else 1,
        exact_scent=case.scent == "exact",
        scent_max=(40, 65535, 2**31 - 2)[case.seed % 3],
    )
    c = case.n_channels
    kw.update(
        physics=physics,
        n_channels=c,
        surface_channels=np.array([case.surface and ch == c - 1 for ch in range(c)]),
        passive_role=np.array([1, 2][:c]) if c == 2 else np.array([1]),
        obs_radius=obs_radius,
    )
    return World(**kw), ReferenceWorld(**kw)


# ------------------------------------------------------------------ actions
def random_actions(rng: np.random.Generator, n_agents: int, n_channels: int, mask: np.ndarray) -> dict:
    move = rng.integers(0, 13, n_agents)
    # half the agents pick a move their mask allows, so that many moves really happen
    masked = rng.random(n_agents) < 0.5
    for a in np.flatnonzero(masked):
        legal = np.flatnonzero(mask[a])
        move[a] = rng.choice(legal)
    return dict(
        move=move,
        mode=rng.integers(0, 5, n_agents),
        scent_role=rng.choice(3, size=(n_agents, n_channels), p=[0.15, 0.75, 0.10]),
        message_target=rng.integers(0, 13, n_agents),
        message_value=rng.integers(0, 4, n_agents) * (rng.random(n_agents) < 0.4),
    )


# ------------------------------------------------------------------ comparison
def assert_same(world: World, ref: ReferenceWorld, buffers: ObservationBuffers, where: str) -> None:
    s = ref.state()
    np.testing.assert_array_equal(world.positions, s["positions"], err_msg=f"{where}: positions")
    np.testing.assert_array_equal(world.mode, s["mode"], err_msg=f"{where}: modes")
    np.testing.assert_array_equal(world.scent, s["scent"], err_msg=f"{where}: scents")
    np.testing.assert_array_equal(world.inbox, s["inbox"], err_msg=f"{where}: inbox")
    assert int(world.rng_state[0]) == s["rng_state"], f"{where}: rng state"
    world.observe(buffers)
    obs = ref.observe()
    for f in Observation._fields:
        np.testing.assert_array_equal(getattr(buffers, f), obs[f], err_msg=f"{where}: observation {f}")


def run_parity(case: Case, obs_radius: int = 1, first_epoch: int = 0) -> int:
    """Run one case; return how many moves happened (the test wants the runs to be lively).

    ``first_epoch`` starts the engine's connectivity-search epoch there (the reference has none).
    """
    world, ref = build(case, obs_radius)
    world.scratch.search[0] = first_epoch
    world.seed(case.seed * 7919 + 11)
    ref.seed(case.seed * 7919 + 11)
    buffers = ObservationBuffers(world.n_agents, 12 if obs_radius == 1 else 54, case.n_channels)
    rng = np.random.default_rng(case.seed)
    assert_same(world, ref, buffers, f"{case} start")
    n_moves = 0
    for t in range(case.cycles):
        actions = random_actions(rng, world.n_agents, case.n_channels, buffers.action_mask)
        moved_world = world.step(**actions)
        moved_ref = ref.step(**actions)
        np.testing.assert_array_equal(moved_world, moved_ref, err_msg=f"{case} cycle {t}: moved")
        assert_same(world, ref, buffers, f"{case} cycle {t}")
        n_moves += int(moved_world.sum())
    if case.keep_connected:
        assert world.n_components() == 1 == ref.n_components()
    if first_epoch:
        assert world.scratch.search[0] < first_epoch, "the searches never ran out of epochs"
    return n_moves


LAYOUTS = ("blob10", "blob25", "blob40", "ball", "line", "floor", "obstacles", "anchored")
SCENTS = (
    ("sweep1", 1, False),
    ("sweep3", 2, True),
    ("exact", 2, True),
    ("sweep1", 2, True),
    ("exact", 1, False),
    ("sweep3", 1, True),
)


def _cases() -> list[Case]:
    cases = []
    i = 0
    for layout in LAYOUTS:
        for model in MOTION_MODELS:
            for keep in (True, False):
                scent, c, surface = SCENTS[i % len(SCENTS)]
                cycles = 40 if layout in ("blob40", "anchored", "ball") else 60
                cases.append(Case(layout, model, keep, scent, c, surface, cycles, seed=100 + i))
                i += 1
    return cases


CASES = _cases()


@pytest.mark.parametrize(
    "case",
    CASES,
    ids=lambda c: (
        f"{c.layout}-{c.model}-{'keep' if c.keep_connected else 'free'}"
        f"-{c.scent}-c{c.n_channels}{'-surf' if c.surface else ''}"
    ),
)
def test_parity(case):
    n_moves = run_parity(case)
    assert n_moves > 0 or case.layout == "ball" or case.model == "rhombic"


def test_parity_long_minimal_blob():
    """One longer run where many modules move (minimal model, connectivity kept)."""
    assert run_parity(Case("blob30", "minimal", True, "sweep1", 2, True, 150, seed=7)) > 100


def test_parity_across_the_search_epoch_wrap():
    """The connectivity search's int32 marks are cleared when its epochs run out, mid-run."""
    case = Case("blob40", "minimal", True, "sweep1", 1, False, 40, seed=8)
    assert run_parity(case, first_epoch=LAST_EPOCH - 3) > 0


@pytest.mark.parametrize("layout", ["obstacles", "anchored"])
def test_parity_radius_two_observations(layout):
    """With ``obs_radius=2`` the 42 two-hop sites follow the 12 face neighbours."""
    assert run_parity(Case(layout, "sphere", True, "sweep1", 2, True, 40, seed=21), obs_radius=2) > 0


@pytest.mark.parametrize("model", MOTION_MODELS)
@pytest.mark.parametrize("fill", [0.12, 0.3])
def test_roll_table_decides_like_the_reference_rule(model, fill):
    """Every (module, direction) of a crowded random world, with modules, solids and object
    sites around: the engine's byte tables give the reference's pivot-and-sweep verdict."""
    rng = np.random.default_rng(int(fill * 10) + len(model))
    size = (11, 11, 11)
    g = np.mgrid[0:11, 0:11, 0:11].reshape(3, -1).T
    sites = g[g.sum(axis=1) % 2 == 0]
    kind = rng.random(len(sites))
    modules = sites[kind < fill]
    solid = sites[(kind >= fill) & (kind < fill + 0.08)]
    objects = sites[(kind >= fill + 0.08) & (kind < fill + 0.12)]
    physics = Physics(motion_model=model, keep_connected=False)
    kw = dict(size=size, positions=modules, n_agents=len(modules), physics=physics, solid=solid, object_sites=objects)
    world, ref = World(**kw), ReferenceWorld(**kw)
    verdicts = np.array([[world.roll_is_legal(m, k) for k in range(12)] for m in range(len(modules))])
    expected = np.array([[ref.roll_is_legal(m, k) for k in range(12)] for m in range(len(modules))])
    assert verdicts.any() and not verdicts.all()
    np.testing.assert_array_equal(verdicts, expected)


def test_seeding_matches_world():
    """``seed`` maps any non-negative integer to the same state as ``World.seed`` (never 0)."""
    world, ref = build(Case("blob10", "sphere", True, "sweep1", 1, False, 0, seed=1))
    for seed in (0, 1, 2**63, 2**64 - 2, 2**64 - 1, 2**64, 3 * 2**64 + 5):
        world.seed(seed)
        ref.seed(seed)
        assert int(world.rng_state[0]) == ref.rng_state != 0


def test_cases_cover_every_setting():
    covered = {(c.model, c.keep_connected) for c in CASES}
    assert covered == {(m, k) for m in MOTION_MODELS for k in (True, False)}
    assert {c.scent for c in CASES} == {"sweep1", "sweep3", "exact"}
    assert any(c.surface for c in CASES) and any(c.n_channels == 2 for c in CASES)


# ------------------------------------------------------------------ kernels as plain Python
NOJIT_CASES = [
    Case("blob12", "sphere", True, "sweep3", 2, True, 25, seed=3),
    Case("anchored", "minimal", True, "exact", 2, True, 15, seed=4),
    Case("obstacles", "rhombic", False, "sweep1", 1, False, 15, seed=5),
]


def nojit_child() -> None:
    """Entry point of the subprocess run with ``NUMBA_DISABLE_JIT=1``."""
    import numba

    assert numba.config.DISABLE_JIT, "NUMBA_DISABLE_JIT was not picked up"
    from proteo_env.core import cycle

    assert not hasattr(cycle.execute_moves, "signatures"), "kernels are still compiled"
    for case in NOJIT_CASES:
        run_parity(case)
    print("NOJIT-PARITY-OK")


@pytest.mark.slow
def test_parity_without_jit():
    result = run_without_jit("test_reference_parity", "nojit_child")
    assert result.returncode == 0 and "NOJIT-PARITY-OK" in result.stdout, result.stdout + result.stderr

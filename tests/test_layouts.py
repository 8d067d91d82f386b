"""Layout texts (legend, parser, writer) and the layout generators."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import proteo_env
from proteo_env import LayoutError
from proteo_env.core.world import Physics, World
from proteo_env.layouts import (
    LEGEND,
    Layout,
    ball_sites,
    blob_sites,
    format_layout,
    line_sites,
    parse_layout,
    place_in_box,
)

DIRECTION_SET = {tuple(int(c) for c in d) for d in proteo_env.DIRECTIONS}
HYPOTHESIS = settings(max_examples=40, deadline=None)


def _as_set(sites) -> set:
    return {tuple(int(c) for c in p) for p in np.asarray(sites).reshape(-1, 3)}


def _connected(sites) -> bool:
    points = _as_set(sites)
    if not points:
        return True
    start = next(iter(points))
    seen, queue = {start}, deque([start])
    while queue:
        p = queue.popleft()
        for d in DIRECTION_SET:
            q = (p[0] + d[0], p[1] + d[1], p[2] + d[2])
            if q in points and q not in seen:
                seen.add(q)
                queue.append(q)
    return len(seen) == len(points)


def _assert_fcc_distinct(sites, n):
    sites = np.asarray(sites)
    assert sites.shape == (n, 3)
    assert sites.dtype == np.int64
    assert np.all(sites.sum(axis=1) % 2 == 0), "every site has an even coordinate sum"
    assert len(_as_set(sites)) == n, "sites are distinct"


# ---------------------------------------------------------------------- legend and parser
def test_legend():
    assert LEGEND == {".": "empty", "m": "module", "F": "fixed", "R": "root", "#": "solid", "o": "object"}


def test_parse_every_legend_character():
    text = "; every character of the legend\nsize 4 4 2\nfloor\nz = 0\nm.F.\n.R.#\no...\n\nz = 1\n.m..\n"
    layout = parse_layout(text)
    assert layout.size == (4, 4, 2)
    assert layout.floor is True
    assert _as_set(layout.modules) == {(0, 0, 0), (1, 0, 1)}
    assert layout.modules.tolist() == [[0, 0, 0], [1, 0, 1]], "agents in reading order: z, then y, then x"
    assert _as_set(layout.fixed) == {(2, 0, 0)}
    assert _as_set(layout.roots) == {(1, 1, 0)}
    assert _as_set(layout.solid) == {(3, 1, 0)}
    assert _as_set(layout.object_sites) == {(0, 2, 0)}
    for name in ("modules", "roots", "fixed", "solid", "object_sites"):
        assert getattr(layout, name).shape[1] == 3 and getattr(layout, name).dtype == np.int64
    # agents are movable modules then roots; fixed board modules are last and passive
    assert layout.n_agents == 3
    assert layout.positions.tolist() == [[0, 0, 0], [1, 0, 1], [1, 1, 0], [2, 0, 0]]
    assert layout.anchored.tolist() == [False, False, True, True]


def test_parse_docstring_example_and_default_size():
    layout = parse_layout("floor\nz = 0\nm.m.m\n")
    assert layout.size == (5, 1, 1)
    assert layout.floor
    assert layout.modules.tolist() == [[0, 0, 0], [2, 0, 0], [4, 0, 0]]
    assert layout.roots.shape == layout.fixed.shape == layout.solid.shape == (0, 3)
    two_layers = parse_layout("z = 0\nm.\n.m\nz = 2\nm..\n")
    assert two_layers.size == (3, 2, 3)
    assert not two_layers.floor


def test_parse_empty_layers_and_comments():
    layout = parse_layout("size 3 3 2\n; nothing here\nz = 0\n...\n...\nz = 1\n.m.\n")
    assert layout.size == (3, 3, 2)
    assert layout.modules.tolist() == [[1, 0, 1]]


def _layout_from_blob(n, seed, floor, margin, kinds_seed):
    rng = np.random.default_rng(seed)
    sites, size = place_in_box(blob_sites(n, rng, flat=floor), margin=margin, floor=floor)
    kinds = np.random.default_rng(kinds_seed).integers(0, 5, size=n)
    parts = [sites[kinds == k] for k in range(5)]
    return Layout(
        size=size, modules=parts[0], roots=parts[1], fixed=parts[2], solid=parts[3], object_sites=parts[4], floor=floor
    )


@HYPOTHESIS
@given(
    n=st.integers(1, 40),
    seed=st.integers(0, 2**32 - 1),
    floor=st.booleans(),
    margin=st.integers(1, 3),
    kinds_seed=st.integers(0, 2**32 - 1),
)
def test_format_parse_round_trip(n, seed, floor, margin, kinds_seed):
    layout = _layout_from_blob(n, seed, floor, margin, kinds_seed)
    text = format_layout(layout)
    back = parse_layout(text)
    assert back.size == layout.size
    assert back.floor == layout.floor
    for name in ("modules", "roots", "fixed", "solid", "object_sites"):
        assert _as_set(getattr(back, name)) == _as_set(getattr(layout, name)), name
        assert len(getattr(back, name)) == len(getattr(layout, name)), name
    assert format_layout(back) == text, "the text is a fixed point"


def test_formatted_layout_runs_in_an_env(tmp_path):
    layout = parse_layout(format_layout(_layout_from_blob(15, 3, True, 2, 0)))
    path = tmp_path / "blob.txt"
    path.write_text(
        format_layout(
            Layout(
                size=layout.size,
                modules=np.concatenate([layout.modules, layout.roots, layout.fixed, layout.solid, layout.object_sites]),
                floor=True,
            )
        )
    )
    env = proteo_env.make("sandbox-v0", layout=str(path))
    env.reset(seed=0)
    assert len(env.agents) == 15
    assert env.world.floor and env.world.box == layout.size


# ---------------------------------------------------------------------- generators
@HYPOTHESIS
@given(n=st.integers(1, 80), seed=st.integers(0, 2**32 - 1), flat=st.booleans())
def test_blob_sites(n, seed, flat):
    sites = blob_sites(n, np.random.default_rng(seed), flat=flat)
    _assert_fcc_distinct(sites, n)
    assert _connected(sites)
    assert tuple(sites[0]) == (0, 0, 0)
    if flat:
        assert sites[:, 2].min() >= 0
    again = blob_sites(n, np.random.default_rng(seed), flat=flat)
    np.testing.assert_array_equal(sites, again)


def test_blob_sites_depend_on_the_generator():
    a = blob_sites(30, np.random.default_rng(0))
    b = blob_sites(30, np.random.default_rng(1))
    assert _as_set(a) != _as_set(b)


@pytest.mark.parametrize("n", [0, -3])
def test_blob_sites_rejects_empty(n):
    with pytest.raises(LayoutError, match=rf"n_modules={n} is not allowed; allowed: an integer >= 1"):
        blob_sites(n, np.random.default_rng(0))


@HYPOTHESIS
@given(n=st.integers(1, 300))
def test_ball_sites(n):
    sites = ball_sites(n)
    _assert_fcc_distinct(sites, n)
    assert _connected(sites)
    # compact: the n sites nearest the origin
    r = int(np.ceil((3 * n) ** (1 / 3))) + 3
    g = np.mgrid[-r : r + 1, -r : r + 1, -r : r + 1].reshape(3, -1).T
    g = g[g.sum(axis=1) % 2 == 0]
    outside = _as_set(g) - _as_set(sites)
    far = max(int((p**2).sum()) for p in sites)
    near_outside = min(sum(c * c for c in p) for p in outside)
    assert far <= near_outside


@pytest.mark.parametrize("k", range(12))
@pytest.mark.parametrize("n", [1, 2, 7])
def test_line_sites(n, k):
    direction = proteo_env.DIRECTIONS[k]
    sites = line_sites(n, direction)
    _assert_fcc_distinct(sites, n)
    assert _connected(sites)
    assert tuple(sites[0]) == (0, 0, 0)
    np.testing.assert_array_equal(np.diff(sites, axis=0), np.broadcast_to(direction, (n - 1, 3)))


def test_line_sites_default_direction():
    np.testing.assert_array_equal(line_sites(3), [[0, 0, 0], [1, 1, 0], [2, 2, 0]])


@HYPOTHESIS
@given(
    n=st.integers(1, 40),
    seed=st.integers(0, 2**32 - 1),
    floor=st.booleans(),
    margin=st.one_of(st.integers(1, 4), st.tuples(st.integers(1, 4), st.integers(1, 4), st.integers(1, 4))),
)
def test_place_in_box(n, seed, floor, margin):
    sites = blob_sites(n, np.random.default_rng(seed), flat=floor) + np.array([-7, 3, 0])
    placed, size = place_in_box(sites, margin=margin, floor=floor)
    m = np.broadcast_to(np.asarray(margin), (3,))
    shift = placed - sites
    assert np.all(shift == shift[0]), "a pure translation"
    assert shift[0].sum() % 2 == 0, "FCC parity kept"
    assert np.all(placed.sum(axis=1) % 2 == 0)
    lo, hi = placed.min(axis=0), placed.max(axis=0)
    assert lo[0] in (m[0], m[0] + 1), "x may take one more step to keep parity"
    assert lo[1] == m[1]
    assert lo[2] == (0 if floor else m[2]), "on the floor, nothing below"
    assert np.all(np.array(size) - 1 - hi >= m), "margin free sites above"
    assert len(size) == 3 and all(isinstance(s, int) for s in size)
    World(size=size, positions=placed, n_agents=n, physics=Physics(), floor=floor)  # the world accepts it


def test_place_in_box_keeps_a_given_size():
    placed, size = place_in_box(line_sites(3), margin=1, size=(10, 10, 4))
    assert size == (10, 10, 4)
    assert placed.min(axis=0).tolist() == [2, 1, 1], "shift (1, 1, 1) is odd, so x moves one more"


# ---------------------------------------------------------------------- the floor flag
@pytest.mark.parametrize("floor", [True, False])
def test_floor_flag(floor):
    layout = parse_layout(("floor\n" if floor else "") + "z = 0\nm.m.\n.m..\nz = 1\n.m..\n")
    assert layout.floor is floor
    assert ("floor" in format_layout(layout).splitlines()) is floor
    env = proteo_env.make("sandbox-v0", n_modules=20, floor=floor, layout="blob")
    obs, _ = env.reset(seed=2)
    world = env.world
    assert world.floor is floor
    z = world.positions[: world.n_agents, 2]
    if floor:
        assert z.min() == 0, "the blob rests on the floor"
    ground = np.array([obs[a]["contact"][0] for a in env.agents])
    np.testing.assert_array_equal(ground, (z == 0) if floor else np.zeros_like(z))
    # without a floor the sites below the box are walls (solid in observations) but not ground
    bottom = env.agents[int(np.argmin(z))]
    below = [k for k, d in enumerate(proteo_env.DIRECTIONS) if d[2] == -1]
    if z.min() == 0:
        assert np.all(obs[bottom]["neighbour_kind"][below] == 2)


def test_floor_in_the_world():
    world = World(
        size=(4, 4, 3),
        positions=[[1, 1, 0], [2, 2, 0], [1, 1, 2]],
        n_agents=3,
        physics=Physics(keep_connected=False),
        floor=True,
    )
    assert world.floor
    with pytest.raises(LayoutError, match="outside the box"):
        World(size=(4, 4, 3), positions=[[1, 1, -2]], n_agents=1, physics=Physics(), floor=True)

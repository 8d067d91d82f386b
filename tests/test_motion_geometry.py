"""Derive the swept-cell tables of the four motion models from geometry, independently of the engine.

Geometry
--------
Module centres sit on the FCC lattice (integer sites with an even coordinate sum). A full-size
module is the Voronoi cell of its site, a rhombic dodecahedron: 14 vertices (the 6 ``(+-1,0,0)``
and the 8 ``(+-1/2,+-1/2,+-1/2)``), 12 faces normal to the face directions ``(+-1,+-1,0)``
(6 up to sign) and 24 edges along the 4 body diagonals, each joining a 4-valent vertex to a
3-valent one (length ``sqrt(3)/2``).

A module M at the origin rolls to T = ``d`` (a face direction) about a pivot P at ``q``, a site
adjacent to both; every ``d`` has 4 such ``q``, 48 cases in all. M, P and T form an equilateral
triangle of side ``sqrt(2)``. The *hinge* is the line normal to the triangle's plane,
``n = (M - P) x (T - P)``, through the point of that plane at distance ``|d| / (2 sin 60)`` from
M and T on P's side, i.e. the triangle's centre ``(d + q) / 3``. The hinge contains an edge of P's
cell (also an edge of M's and T's cells), and turning M's body by +120 degrees about it maps M's
cell exactly onto T's cell: the roll is a lattice symmetry, checked here for all 48 cases.

What each model sweeps (a cell counts when the moving body and the body at that site
interpenetrate with a depth above ``TOL``, so face, edge or point contact does not count):

* ``rhombic``: the full cell turned about the hinge through (0, 120) degrees, tested against full
  cells.
* ``rounded``: every module's body is its cell scaled by 0.9 about its centre; the moving one
  turns about the same hinge, and is tested against the same scaled bodies at the other sites.
* ``sphere``: every module is a ball of diameter ``sqrt(2)`` (its cell's insphere, touching its
  neighbours). Rolling about P, M's ball stays in contact with P's ball: its centre runs along
  the circle of radius ``sqrt(2)`` about P's centre in the plane of M, P, T, from M to T
  (60 degrees of arc).
* ``minimal``: only the site nearest to the path of M's centre (M, T and P excluded), which is
  ``d - q`` (``2p + d - q`` for M at ``p``): the fourth corner of the rhombus M, P, T.

Convex polyhedra are tested with the separating axis theorem: the face normals of both bodies and
the cross products of their edge directions. Everything is vectorised over the sampled angles and
the candidate sites (every FCC site with max-abs coordinate <= 3 apart from M, T and P).
"""

from __future__ import annotations

import itertools
from functools import cache

import numpy as np
import pytest

from proteo_env.core.motion import swept_cells

TOL = 1e-6
"""Interpenetration depth that counts as overlap; contact alone does not."""
N_SAMPLES = 241
"""Sampled positions of the moving body, strictly inside the turn."""
TURN = 2 * np.pi / 3
ROUNDED_SCALE = 0.9
SITE_RADIUS = 3

Case = tuple[tuple[int, int, int], tuple[int, int, int]]

# --------------------------------------------------------------------------- lattice and cell


FACE_DIRECTIONS = np.array([v for v in itertools.product((-1, 0, 1), repeat=3) if sorted(map(abs, v)) == [0, 1, 1]])
CELL_VERTICES = np.array(
    [v for v in itertools.product((-1, 0, 1), repeat=3) if sum(map(abs, v)) == 1]
    + list(itertools.product((-0.5, 0.5), repeat=3)),
    dtype=float,
)
CELL_FACE_NORMALS = np.array([(1, 1, 0), (1, -1, 0), (1, 0, 1), (1, 0, -1), (0, 1, 1), (0, 1, -1)]) / np.sqrt(2)
CELL_EDGE_DIRECTIONS = np.array([(1, 1, 1), (1, 1, -1), (1, -1, 1), (-1, 1, 1)]) / np.sqrt(3)
CELL_EDGE_LENGTH = np.sqrt(3) / 2


def is_face_direction(v) -> bool:
    return sorted(abs(int(x)) for x in v) == [0, 1, 1]


def nearby_sites(d, q) -> np.ndarray:
    """``(S, 3)``: FCC sites with max-abs coordinate <= SITE_RADIUS, except M, T and P."""
    excluded = {(0, 0, 0), tuple(d), tuple(q)}
    box = itertools.product(range(-SITE_RADIUS, SITE_RADIUS + 1), repeat=3)
    return np.array([s for s in box if sum(s) % 2 == 0 and s not in excluded])


def roll_cases() -> list[Case]:
    """The 48 (direction, pivot) pairs: ``q`` adjacent to both ``0`` and ``d``."""
    return [
        (tuple(int(x) for x in d), tuple(int(x) for x in q))
        for d in FACE_DIRECTIONS
        for q in FACE_DIRECTIONS
        if is_face_direction(d - q)
    ]


# --------------------------------------------------------------------------- the roll


def rotations(axis, angles) -> np.ndarray:
    """``(N, 3, 3)``: rotations by ``angles`` about the unit vector along ``axis`` (Rodrigues)."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    angles = np.asarray(angles, dtype=float)[:, None, None]
    return np.eye(3) + np.sin(angles) * k + (1 - np.cos(angles)) * (k @ k)


def plane_normal(d, q) -> np.ndarray:
    """``(M - P) x (T - P)``: normal of the plane M, P, T, oriented so M turns towards T."""
    q = np.asarray(q, dtype=float)
    return np.cross(-q, np.asarray(d) - q)


def hinge_point(d, q) -> np.ndarray:
    """The point of plane M, P, T at distance ``|d| / (2 sin 60)`` from M and T, on P's side."""
    d, q = np.asarray(d, dtype=float), np.asarray(q, dtype=float)
    radius = np.linalg.norm(d) / (2 * np.sin(np.pi / 3))
    mid = d / 2
    towards_p = (q - mid) / np.linalg.norm(q - mid)
    return mid + np.sqrt(radius**2 - np.dot(mid, mid)) * towards_p


def hinge_roll(d, q, angles) -> tuple[np.ndarray, np.ndarray]:
    """Rotations ``(N, 3, 3)`` and centre positions ``(N, 3)`` of M's body turned about the hinge.

    A body point ``x`` (relative to M's centre) goes to ``R @ x + centre``.
    """
    c = hinge_point(d, q)
    r = rotations(plane_normal(d, q), angles)
    return r, r @ -c + c


def pivot_circle(d, q, fractions) -> np.ndarray:
    """``(N, 3)``: M's centre on the circle of radius ``|q|`` about P, ``fractions`` of the way to T."""
    q = np.asarray(q, dtype=float)
    arc = np.arccos(np.dot(-q, np.asarray(d) - q) / np.dot(q, q))
    return q + rotations(plane_normal(d, q), arc * np.asarray(fractions)) @ -q


def open_fractions(n_samples) -> np.ndarray:
    """``n_samples`` evenly spaced fractions of a move, both ends excluded."""
    return np.linspace(0, 1, n_samples + 2)[1:-1]


# --------------------------------------------------------------------------- overlap tests


def sat_axes(rot: np.ndarray) -> np.ndarray:
    """``(N, 28, 3)`` unit separating-axis candidates for a fixed cell and one turned by ``rot``.

    6 fixed face normals, 6 turned ones and the 16 cross products of edge directions; a cross
    product of parallel edges (the hinge diagonal stays fixed) is replaced by a face normal.
    """
    n = rot.shape[0]
    fixed = np.broadcast_to(CELL_FACE_NORMALS, (n, 6, 3))
    turned = CELL_FACE_NORMALS @ rot.transpose(0, 2, 1)
    turned_edges = CELL_EDGE_DIRECTIONS @ rot.transpose(0, 2, 1)
    cross = np.cross(CELL_EDGE_DIRECTIONS[None, :, None, :], turned_edges[:, None, :, :]).reshape(n, 16, 3)
    norm = np.linalg.norm(cross, axis=-1, keepdims=True)
    cross = np.where(norm > 1e-9, cross / np.maximum(norm, 1e-12), CELL_FACE_NORMALS[0])
    return np.concatenate([fixed, turned, cross], axis=1)


def polyhedron_depth(rot, centres, sites, scale) -> np.ndarray:
    """``(N, S)`` interpenetration depth of the turned body and the static body at each site.

    Both bodies are the cell scaled by ``scale``; the moving one is ``rot[i] @ x + centres[i]``.
    Depth is the smallest interval overlap over all separating-axis candidates (<= 0: apart).
    """
    axes = sat_axes(rot)  # (N, A, 3)
    moving = (scale * CELL_VERTICES) @ rot.transpose(0, 2, 1) + centres[:, None, :]  # (N, V, 3)
    moving_proj = np.einsum("nvk,nak->nav", moving, axes)
    static_proj = np.einsum("vk,nak->nav", scale * CELL_VERTICES, axes)
    shift = np.einsum("sk,nak->nsa", sites, axes)  # (N, S, A)
    lo = np.maximum(moving_proj.min(-1)[:, None, :], static_proj.min(-1)[:, None, :] + shift)
    hi = np.minimum(moving_proj.max(-1)[:, None, :], static_proj.max(-1)[:, None, :] + shift)
    return (hi - lo).min(-1)


def swept_by_polyhedron(d, q, scale) -> frozenset:
    sites = nearby_sites(d, q)
    rot, centres = hinge_roll(d, q, TURN * open_fractions(N_SAMPLES))
    hit = (polyhedron_depth(rot, centres, sites, scale) > TOL).any(axis=0)
    return frozenset(tuple(int(x) for x in s) for s in sites[hit])


def swept_by_sphere(d, q) -> frozenset:
    sites = nearby_sites(d, q)
    path = pivot_circle(d, q, open_fractions(N_SAMPLES))
    gap = np.linalg.norm(path[:, None, :] - sites[None, :, :], axis=-1)
    hit = (np.sqrt(2) - gap > TOL).any(axis=0)
    return frozenset(tuple(int(x) for x in s) for s in sites[hit])


def path_distances(d, q, path) -> tuple[np.ndarray, np.ndarray]:
    """Nearby sites sorted by their distance to the sampled ``path``, and those distances."""
    sites = nearby_sites(d, q)
    dist = np.linalg.norm(path[:, None, :] - sites[None, :, :], axis=-1).min(axis=0)
    order = np.argsort(dist)
    return sites[order], dist[order]


def swept_minimal(d, q) -> frozenset:
    """The site nearest to the hinge path of M's centre; asserted unique by a clear margin."""
    _, centres = hinge_roll(d, q, TURN * open_fractions(N_SAMPLES))
    sites, dist = path_distances(d, q, centres)
    assert dist[1] - dist[0] > 0.1, f"nearest cell to the path of {(d, q)} is not unique"
    return frozenset({tuple(int(x) for x in sites[0])})


SWEEPERS = {
    "rhombic": lambda d, q: swept_by_polyhedron(d, q, 1.0),
    "rounded": lambda d, q: swept_by_polyhedron(d, q, ROUNDED_SCALE),
    "sphere": swept_by_sphere,
    "minimal": swept_minimal,
}


@cache
def derived_table(model: str) -> dict[Case, frozenset]:
    return {case: SWEEPERS[model](*case) for case in roll_cases()}


# --------------------------------------------------------------------------- tests


def test_there_are_48_cases_with_4_pivots_each():
    cases = roll_cases()
    assert len(cases) == len(set(cases)) == 48
    for d in FACE_DIRECTIONS:
        assert sum(case[0] == tuple(d) for case in cases) == 4


@pytest.mark.parametrize("case", roll_cases(), ids=str)
def test_hinge_is_an_edge_of_the_pivot_cell(case):
    d, q = case
    c, n = hinge_point(d, q), plane_normal(d, q) / np.linalg.norm(plane_normal(d, q))
    assert np.allclose(np.linalg.norm(c), np.linalg.norm(c - d))  # equidistant from M and T
    assert np.allclose(c, (np.array(d) + np.array(q)) / 3)  # the centre of triangle M, P, T
    pivot_vertices = CELL_VERTICES + q
    off_axis = pivot_vertices - c - np.outer((pivot_vertices - c) @ n, n)
    on_axis = pivot_vertices[np.linalg.norm(off_axis, axis=1) < 1e-9]
    assert len(on_axis) == 2
    assert np.isclose(np.linalg.norm(on_axis[0] - on_axis[1]), CELL_EDGE_LENGTH)


@pytest.mark.parametrize("case", roll_cases(), ids=str)
def test_roll_by_120_degrees_maps_cell_of_m_onto_cell_of_t(case):
    d, q = case
    rot, centre = hinge_roll(d, q, [TURN])
    assert np.allclose(centre[0], d)
    moved = CELL_VERTICES @ rot[0].T + centre[0]
    target = CELL_VERTICES + d
    assert {tuple(v) for v in moved.round(9)} == {tuple(v) for v in target}
    assert np.allclose(rot[0], rot[0].round())  # a signed permutation: a lattice symmetry


@pytest.mark.parametrize("case", roll_cases(), ids=str)
def test_pivot_circle_runs_from_m_to_t_touching_p(case):
    d, q = case
    path = pivot_circle(d, q, open_fractions(N_SAMPLES))
    assert np.allclose(np.linalg.norm(path - q, axis=1), np.sqrt(2))
    assert np.allclose(pivot_circle(d, q, [0, 1]), [(0, 0, 0), d])


@pytest.mark.parametrize("model", list(SWEEPERS))
def test_engine_table_matches_independent_derivation(model):
    engine = swept_cells(model)
    derived = derived_table(model)
    assert set(engine) == set(derived)
    diffs = [
        f"{case}: engine-only {sorted(engine[case] - cells)}, derived-only {sorted(cells - engine[case])}"
        for case, cells in derived.items()
        if engine[case] != cells
    ]
    assert not diffs, f"{model}: {len(diffs)} of 48 cases differ\n" + "\n".join(diffs)


@pytest.mark.parametrize("case", roll_cases(), ids=str)
def test_minimal_cell_is_the_rhombus_corner_on_both_centre_paths(case):
    d, q = case
    corner = tuple(int(x) for x in np.subtract(d, q))
    assert derived_table("minimal")[case] == {corner}
    sites, dist = path_distances(d, q, pivot_circle(d, q, open_fractions(N_SAMPLES)))
    assert tuple(sites[0]) == corner and dist[1] - dist[0] > 0.1


@pytest.mark.parametrize("case", roll_cases(), ids=str)
def test_models_nest(case):
    tables = {model: derived_table(model)[case] for model in SWEEPERS}
    assert tables["rounded"] < tables["rhombic"]
    for model in ("rhombic", "rounded", "sphere"):
        assert tables["minimal"] < tables[model]

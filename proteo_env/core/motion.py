"""The four motion models: which cells a 120 degree roll about a pivot must find empty.

A module M at ``p`` rolls to ``t = p + d`` about a pivot module P at ``q``, one of the 4 sites
adjacent to both ``p`` and ``t``. In the canonical frame ``M = (0,0,0)``, ``P = (0,1,1)``,
``T = (1,1,0)`` each model lists the cells, besides ``T``, that the rolling body sweeps
through. The other 47 (direction, pivot) cases follow by the signed axis permutation that
maps the canonical ``P`` and ``T`` onto them; :func:`swept_cells` builds all 48 and checks
that each case is reached exactly once.
"""

from __future__ import annotations

import itertools
from functools import cache

import numpy as np

from .lattice import DIRECTIONS, neighbourhood_offsets

CANONICAL_PIVOT = (0, 1, 1)
CANONICAL_TARGET = (1, 1, 0)

CANONICAL_SWEEPS: dict[str, tuple[tuple[int, int, int], ...]] = {
    # exact rhombic dodecahedron swept through the turn
    "rhombic": (
        (1, 0, -1),
        (0, 1, -1),
        (2, 0, 0),
        (1, -1, 0),
        (0, -1, -1),
        (2, 1, -1),
        (1, 0, 1),
        (-1, 0, -1),
        (1, 2, -1),
    ),
    # the same body shrunk to 90 % of its cell
    "rounded": (
        (1, 0, -1),
        (0, 1, -1),
        (2, 0, 0),
        (1, -1, 0),
        (0, -1, -1),
        (2, 1, -1),
        (1, 0, 1),
    ),
    # equal spheres rolling about the pivot
    "sphere": ((1, 0, 1), (1, 0, -1), (0, 1, -1), (1, -1, 0), (2, 0, 0)),
    # only the cell the body's centre passes closest to: 2p + d - q
    "minimal": ((1, 0, -1),),
}

MOTION_MODELS: tuple[str, ...] = tuple(CANONICAL_SWEEPS)


def check_motion_model(name: str) -> str:
    """Return ``name`` if it is a motion model, else raise a ``ValueError`` listing them."""
    if name not in CANONICAL_SWEEPS:
        raise ValueError(f"motion_model={name!r} is not known; allowed: {', '.join(MOTION_MODELS)}")
    return name


def signed_permutations() -> list[np.ndarray]:
    """The 48 signed permutation matrices (the symmetry group of the cube), as ``(3, 3)`` ints."""
    mats = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1, -1), repeat=3):
            m = np.zeros((3, 3), dtype=np.int64)
            for row, (col, sign) in enumerate(zip(perm, signs)):
                m[row, col] = sign
            mats.append(m)
    return mats


def common_neighbours(direction) -> np.ndarray:
    """``(4, 3)``: the sites adjacent to both ``0`` and ``direction``, in :data:`DIRECTIONS` order."""
    d = np.asarray(direction)
    return np.array([q for q in DIRECTIONS if tuple(d - q) in {tuple(x) for x in DIRECTIONS}])


@cache
def swept_cells(model: str) -> dict[tuple[tuple[int, ...], tuple[int, ...]], frozenset]:
    """All 48 cases of a model: ``{(direction, pivot): frozenset of swept cells}``.

    Cells and pivot are offsets from the moving module; the target itself is not listed.
    Raises ``AssertionError`` if a case is reached twice with different cells or not at all.
    """
    check_motion_model(model)
    canonical = np.array(CANONICAL_SWEEPS[model])
    cases: dict = {}
    for m in signed_permutations():
        key = (tuple(m @ CANONICAL_TARGET), tuple(m @ CANONICAL_PIVOT))
        cells = frozenset(tuple(c) for c in canonical @ m.T)
        assert key not in cases or cases[key] == cells, f"{model}: mappings disagree on {key}"
        cases[key] = cells
    expected = {(tuple(d), tuple(q)) for d in DIRECTIONS for q in common_neighbours(d)}
    assert set(cases) == expected, f"{model}: cases reached are not the 48 (direction, pivot) pairs"
    return cases


LOCAL_OFFSETS = neighbourhood_offsets(2)
"""``(54, 3)``: every site a roll can involve (targets, pivots, swept cells) lies within 2 hops.

The first 12 are :data:`DIRECTIONS`, so bit ``k`` of a local occupancy word is the target of
move ``k``."""


def _local_adjacency_bits() -> np.ndarray:
    """``(7, 256)`` int64: entry ``[i, byte]`` holds the bits of the local sites (of the 54
    within two hops) adjacent to any of the sites ``8 i + j`` for the set bits ``j`` of ``byte``.
    """
    faces = {tuple(d) for d in DIRECTIONS}
    site_bits = np.zeros(len(LOCAL_OFFSETS), dtype=np.int64)
    for i, a in enumerate(LOCAL_OFFSETS):
        for j, b in enumerate(LOCAL_OFFSETS):
            if tuple(a - b) in faces:
                site_bits[i] |= 1 << j
    n_bytes = (len(LOCAL_OFFSETS) + 7) // 8
    bits = np.zeros((n_bytes, 256), dtype=np.int64)
    for i in range(n_bytes):
        for byte in range(256):
            for j in range(8):
                if (byte >> j) & 1 and 8 * i + j < len(LOCAL_OFFSETS):
                    bits[i, byte] |= site_bits[8 * i + j]
    return bits


LOCAL_ADJACENCY_BITS = _local_adjacency_bits()


def motion_bits(model: str) -> tuple[np.ndarray, np.ndarray]:
    """The model's tables as byte lookups over the sites its rolls involve, for the kernels.

    Returns ``roll_offsets (R, 3)``: the 12 :data:`DIRECTIONS` first, then the sites two hops
    away that some swept cell of this model lies on, in :data:`LOCAL_OFFSETS` order (R is 12
    for ``minimal``, 18 for ``sphere``, 42 for ``rounded`` and ``rhombic``), so a kernel reads
    only the sites that can matter; and ``roll_table (4, 2 + ceil(R / 8), 256)`` int16, which
    turns occupancy words over ``roll_offsets`` into words over the 12 directions, a byte at a
    time. For pivot slot ``j`` (the ``j``-th of the 4 sites next to both ends of a roll, in
    :func:`common_neighbours` order):

    * ``roll_table[j, i, byte]`` for ``i < 2``: bit ``k`` is set when the pivot of direction
      ``k`` is one of the set bits of ``byte``, read as bits ``8 i .. 8 i + 7`` of a word of
      occupied directions;
    * ``roll_table[j, 2 + i, byte]``: bit ``k`` is set when some swept cell of direction ``k``
      about that pivot is one of the set bits of ``byte``, read as bits ``8 i .. 8 i + 7``.

    So a roll towards ``k`` is legal when bit ``k`` of ``pivots & ~swept`` is set for some
    ``j`` (see :func:`~proteo_env.core.cycle.legal_rolls`): 4 x (2 + R / 8) lookups decide
    all 12 directions at once. The tables are built once per model; each call returns copies.
    """
    roll_offsets, roll_table = _motion_tables(model)
    return roll_offsets.copy(), roll_table.copy()


@cache
def _motion_tables(model: str) -> tuple[np.ndarray, np.ndarray]:
    cases = swept_cells(model)
    swept = {cell for cells in cases.values() for cell in cells}
    roll_offsets = [o for i, o in enumerate(LOCAL_OFFSETS) if i < 12 or tuple(o) in swept]
    index = {tuple(o): i for i, o in enumerate(roll_offsets)}
    n_bytes = (len(roll_offsets) + 7) // 8
    roll_table = np.zeros((4, 2 + n_bytes, 256), dtype=np.int16)
    byte = np.arange(256)
    for k, d in enumerate(DIRECTIONS):
        for j, q in enumerate(common_neighbours(d)):
            pivot = index[tuple(q)]  # a direction, so in byte 0 or 1
            roll_table[j, pivot // 8, (byte >> (pivot % 8)) & 1 == 1] |= 1 << k
            cells = sum(1 << index[cell] for cell in cases[(tuple(d), tuple(q))])
            for i in range(n_bytes):
                roll_table[j, 2 + i, (byte & ((cells >> (8 * i)) & 255)) != 0] |= 1 << k
    return np.array(roll_offsets, dtype=np.int64).reshape(-1, 3), roll_table

"""Rhombic dodecahedra on the FCC lattice: the 12 face quads and the visible-face test.

The Voronoi cell of an FCC site ``c`` is ``{x : |x_i - c_i| + |x_j - c_j| <= 1 for all i < j}``,
a rhombic dodecahedron. Its face towards the neighbour direction ``d`` (a permutation of
``(+-1, +-1, 0)``, in :data:`~proteo_env.core.lattice.DIRECTIONS` order) is the rhombus with
corners ``s_a e_a``, ``(s_a e_a + s_b e_b + e_c) / 2``, ``s_b e_b``,
``(s_a e_a + s_b e_b - e_c) / 2``, where ``a, b`` are the non-zero axes of ``d`` with signs
``s_a, s_b`` and ``c`` is the zero axis. Two cells that share a face hide it from the
viewer, so only faces towards sites that are not occupied are drawn.
"""

from __future__ import annotations

import numpy as np

from ..core.lattice import DIRECTIONS


def _face_quads() -> np.ndarray:
    quads = np.zeros((12, 4, 3))
    for k, d in enumerate(DIRECTIONS):
        a, b = np.flatnonzero(d)
        c = 3 - a - b
        ea, eb, ec = np.eye(3)[a] * d[a], np.eye(3)[b] * d[b], np.eye(3)[c]
        quads[k] = [ea, (ea + eb + ec) / 2, eb, (ea + eb - ec) / 2]
    return quads


FACE_QUADS: np.ndarray = _face_quads()
"""``(12, 4, 3)`` float: corners of the face towards ``DIRECTIONS[k]`` of a cell at the origin."""
FACE_QUADS.setflags(write=False)

FACE_NORMALS: np.ndarray = DIRECTIONS / np.sqrt(2.0)
"""``(12, 3)`` float: outward unit normal of each face."""
FACE_NORMALS.setflags(write=False)


def occupancy_grid(site_groups, *, floor: bool) -> tuple[np.ndarray, np.ndarray]:
    """A dense bool grid of the occupied sites, one cell of margin on every side.

    Args:
        site_groups: ``(K_i, 3)`` int site arrays that hide faces (modules, solid, object).
        floor: mark every site below ``z = 0`` as occupied (the ground).

    Returns:
        ``(grid, origin)``: ``grid[p - origin]`` is True where site ``p`` is occupied, for
        every ``p`` within one step of an occupied site.
    """
    sites = np.concatenate([np.asarray(s, dtype=np.int64).reshape(-1, 3) for s in site_groups])
    if len(sites) == 0:
        return np.zeros((1, 1, 1), dtype=np.bool_), np.zeros(3, dtype=np.int64)
    origin = sites.min(axis=0) - 1
    grid = np.zeros(tuple(sites.max(axis=0) - origin + 2), dtype=np.bool_)
    grid[tuple((sites - origin).T)] = True
    if floor and origin[2] < 0:
        grid[:, :, : -origin[2]] = True
    return grid, origin


def visible_faces(sites: np.ndarray, grid: np.ndarray, origin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The faces of the cells at ``sites`` that look onto unoccupied sites.

    Args:
        sites: ``(N, 3)`` int cell sites (all of them occupied in ``grid``).
        grid, origin: from :func:`occupancy_grid`.

    Returns:
        ``(cell, face)``: ``(F,)`` int arrays, the row in ``sites`` and the face index
        (``0..11``) of every visible face.
    """
    sites = np.asarray(sites, dtype=np.int64).reshape(-1, 3)
    neighbours = sites[:, None, :] - origin + DIRECTIONS[None, :, :]  # (N, 12, 3), inside the margin
    hidden = grid[neighbours[..., 0], neighbours[..., 1], neighbours[..., 2]]
    cell, face = np.nonzero(~hidden)
    return cell, face

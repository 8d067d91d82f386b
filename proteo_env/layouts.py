"""Start layouts: small text fixtures with one parser, and generators (blob, ball, line).

Text legend
-----------
A layout text lists the z-layers of the box from bottom to top. Each layer starts with a line
``z = K`` followed by one row per ``y`` (first row ``y = 0``), one character per ``x`` (first
column ``x = 0``). FCC sites are the points with ``x + y + z`` even, so a layer is a
checkerboard: characters at the other points must be ``.`` (nothing can be there).

====  ================================================================
char  meaning
====  ================================================================
``.`` empty site (or a non-site point)
``m`` a module (an agent that can move)
``F`` a fixed board module: never moves, never acts (passive)
``R`` a root: an agent that never moves (table task)
``#`` solid: an obstacle
``o`` a site of the object (grasp task)
====  ================================================================

Optional header lines before the first layer: ``size X Y Z`` (default: the extent of the
layers) and ``floor`` (ground under ``z = 0``). Lines starting with ``;`` are comments.

Example, a 3-module line on the floor::

    floor
    z = 0
    m.m.m
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .core.lattice import DIRECTIONS
from .core.world import LayoutError

LEGEND = {".": "empty", "m": "module", "F": "fixed", "R": "root", "#": "solid", "o": "object"}


@dataclass(frozen=True)
class Layout:
    """A start configuration: the box, the modules and the solid sites.

    Attributes:
        size: box extent ``(X, Y, Z)``.
        modules: ``(N, 3)`` int64 sites of the agents' modules (movable), in agent order.
        roots: ``(R, 3)`` sites of anchored agents (roots of the table).
        fixed: ``(F, 3)`` sites of passive board modules.
        solid: ``(S, 3)`` obstacle sites.
        object_sites: ``(O, 3)`` sites of the object.
        floor: ground below ``z = 0``.
    """

    size: tuple[int, int, int]
    modules: np.ndarray
    roots: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64))
    fixed: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64))
    solid: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64))
    object_sites: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64))
    floor: bool = False

    @property
    def n_agents(self) -> int:
        """Movable modules plus roots."""
        return len(self.modules) + len(self.roots)

    @property
    def positions(self) -> np.ndarray:
        """``(N, 3)`` all module sites in world order: movable, roots, fixed."""
        return np.concatenate([self.modules, self.roots, self.fixed]).astype(np.int64)

    @property
    def anchored(self) -> np.ndarray:
        """``(N,)`` bool: roots and fixed modules never move."""
        return np.arange(len(self.positions)) >= len(self.modules)


def parse_layout(text: str) -> Layout:
    """Parse a layout text (legend in the module docstring); errors name line and column."""
    size = None
    floor = False
    sites: dict[str, list] = {c: [] for c in "mFR#o"}
    z = None
    y = 0
    extent = [0, 0, 0]
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith(";"):
            continue
        if line.startswith("z"):
            try:
                z = int(line.split("=", 1)[1])
            except (IndexError, ValueError):
                raise LayoutError(f"line {lineno}: {line!r} is not a layer header; allowed: 'z = K'") from None
            y = 0
            extent[2] = max(extent[2], z + 1)
            continue
        if z is None:
            words = line.split()
            if words[0] == "size" and len(words) == 4 and all(w.isdigit() for w in words[1:]):
                size = tuple(int(w) for w in words[1:])
            elif words == ["floor"]:
                floor = True
            else:
                raise LayoutError(
                    f"line {lineno}: {line!r} is not a header; allowed: 'size X Y Z', 'floor', "
                    "or a layer starting with 'z = K'"
                )
            continue
        for x, ch in enumerate(line):
            if ch not in LEGEND:
                raise LayoutError(
                    f"line {lineno}, column {x + 1}: character {ch!r} is not in the legend; "
                    f"allowed: {', '.join(repr(c) for c in LEGEND)}"
                )
            if ch == ".":
                continue
            if (x + y + z) % 2:
                raise LayoutError(
                    f"line {lineno}, column {x + 1}: {ch!r} at ({x}, {y}, {z}) is not an FCC "
                    "site; allowed: '.' where x + y + z is odd"
                )
            sites[ch].append((x, y, z))
        extent[0] = max(extent[0], len(line))
        extent[1] = max(extent[1], y + 1)
        y += 1
    arr = {c: np.array(v, dtype=np.int64).reshape(-1, 3) for c, v in sites.items()}
    return Layout(
        size=size or tuple(extent),
        modules=arr["m"],
        roots=arr["R"],
        fixed=arr["F"],
        solid=arr["#"],
        object_sites=arr["o"],
        floor=floor,
    )


def format_layout(layout: Layout) -> str:
    """Write a layout as text that :func:`parse_layout` reads back to the same layout."""
    X, Y, Z = layout.size
    chars = np.full((Z, Y, X), ".")
    for ch, pts in (
        ("m", layout.modules),
        ("R", layout.roots),
        ("F", layout.fixed),
        ("#", layout.solid),
        ("o", layout.object_sites),
    ):
        for x, y, z in pts:
            chars[z, y, x] = ch
    lines = [f"size {X} {Y} {Z}"] + (["floor"] if layout.floor else [])
    for z in range(Z):
        lines.append(f"z = {z}")
        lines += ["".join(row) for row in chars[z]]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------- generators
_STEPS = tuple((int(x), int(y), int(z)) for x, y, z in DIRECTIONS)
"""The 12 face directions as tuples of Python ints (what the site-by-site growth adds)."""


def blob_sites(n: int, rng: np.random.Generator, *, flat: bool = False) -> np.ndarray:
    """``(n, 3)`` sites of a random connected blob grown from the origin.

    Each new module goes to a uniformly chosen empty neighbour site of the blob (Eden
    growth). ``flat=True`` keeps ``z >= 0`` so the blob can rest on a floor.
    """
    if n < 1:
        raise LayoutError(f"n_modules={n} is not allowed; allowed: an integer >= 1")
    occupied = {(0, 0, 0)}
    order = [(0, 0, 0)]
    frontier: list = []
    in_frontier: set = set()

    def add_frontier(p):
        for dx, dy, dz in _STEPS:
            q = (p[0] + dx, p[1] + dy, p[2] + dz)
            if q not in occupied and q not in in_frontier and (not flat or q[2] >= 0):
                frontier.append(q)
                in_frontier.add(q)

    add_frontier((0, 0, 0))
    while len(order) < n:
        i = int(rng.integers(len(frontier)))
        frontier[i], frontier[-1] = frontier[-1], frontier[i]
        q = frontier.pop()
        in_frontier.discard(q)
        occupied.add(q)
        order.append(q)
        add_frontier(q)
    return np.array(order, dtype=np.int64)


def ball_sites(n: int) -> np.ndarray:
    """``(n, 3)`` the ``n`` sites nearest the origin (ties broken by coordinates): a compact ball."""
    r = int(np.ceil((3 * n) ** (1 / 3))) + 2
    g = np.mgrid[-r : r + 1, -r : r + 1, -r : r + 1].reshape(3, -1).T
    g = g[g.sum(axis=1) % 2 == 0]
    order = np.lexsort((g[:, 2], g[:, 1], g[:, 0], (g**2).sum(axis=1)))
    return g[order[:n]].astype(np.int64)


def line_sites(n: int, direction=(1, 1, 0)) -> np.ndarray:
    """``(n, 3)`` a straight one-module-thick chain from the origin along a face direction."""
    return np.arange(n, dtype=np.int64)[:, None] * np.asarray(direction, dtype=np.int64)[None, :]


def place_in_box(sites: np.ndarray, *, margin, floor: bool = False, size=None) -> tuple[np.ndarray, tuple]:
    """Shift ``sites`` into a box with ``margin`` free sites around them (none below if ``floor``).

    ``margin`` is one integer or one per axis ``(mx, my, mz)``. The shift keeps FCC parity.
    Returns the shifted sites and the box size (``size`` if given).
    """
    margin = np.broadcast_to(np.asarray(margin, dtype=np.int64), (3,))
    shift = margin - sites.min(axis=0)
    if floor:
        shift[2] = -sites[:, 2].min()
    if shift.sum() % 2:
        shift[0] += 1
    placed = sites + shift
    if size is None:
        size = tuple(int(v) for v in placed.max(axis=0) + margin + 1)
    return placed, tuple(size)

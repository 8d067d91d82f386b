"""Quick pictures of a world: modules as shaded spheres coloured by mode (matplotlib).

Imported only when a picture is written. Colours follow the paper's figures: SEARCH red,
FINAL white, SEED and TOUCHSEED yellow, NODE purple, ROOT and TOUCH blue, SLEEP grey.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

MODE_COLOURS = {
    "SLEEP": "#9a9a9a", "SEARCH": "#d62728", "SEED": "#f2d40f", "FINAL": "#f4f4f4",
    "NODE": "#8e44ad", "INODE": "#b58acb", "ROOT": "#1f5fbf", "IROOT": "#6f8fbf", "AROOT": "#3f7fff",
    "FIXED": "#dcdcdc", "TOUCH": "#1f5fbf", "TOUCHSEED": "#f2d40f", "DISBAND": "#ff9f1c",
}
DEFAULT_COLOUR = "#4c9a2a"


def mode_colours(mode_names, modes: np.ndarray) -> list[str]:
    """One colour per module from its mode name."""
    return [MODE_COLOURS.get(mode_names[m], DEFAULT_COLOUR) for m in modes]


def save_snapshot(world, path, *, title: str = "", elev: float = 25.0, azim: float = -60.0) -> Path:
    """Write a PNG of a :class:`~proteo_env.env.WorldView` to ``path`` and return the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pos = world.positions.astype(float)
    fig = plt.figure(figsize=(6, 6), dpi=100)
    ax = fig.add_subplot(projection="3d")
    ax.scatter(pos[:, 0], pos[:, 1], pos[:, 2], c=mode_colours(world.mode_names, world.modes),
               s=120, edgecolors="#333333", linewidths=0.5, depthshade=True)
    if len(world.object_sites):
        o = world.object_sites.astype(float)
        ax.scatter(o[:, 0], o[:, 1], o[:, 2], c="#2ca02c", s=60, alpha=0.4)
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    centre, half = (lo + hi) / 2, max((hi - lo).max() / 2, 2.0)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.view_init(elev=elev, azim=azim)
    ax.set_title(title)
    used = sorted({world.mode_names[m] for m in np.unique(world.modes)})
    for name in used:
        ax.scatter([], [], [], c=MODE_COLOURS.get(name, DEFAULT_COLOUR), edgecolors="#333333", label=name)
    ax.legend(loc="upper right", fontsize=8)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp)
    plt.close(fig)
    tmp.replace(path)
    return path

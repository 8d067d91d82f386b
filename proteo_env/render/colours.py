"""Colours of modules by mode, as in the paper's figures, and of the rest of the scene.

SEARCH red shaded by its scent (deep red near the source, pale far away or without
scent), FINAL white, SEED yellow, NODE purple, ROOT and TOUCH blue, TOUCHSEED yellow,
SLEEP grey; the table's FIXED board white. Modes not named here (the sandbox's
``MODE_i``) take colours from a fixed palette in mode order.
"""

from __future__ import annotations

import numpy as np

MODE_COLOURS: dict[str, str] = {
    "SLEEP": "#8c8c8c",
    "SEARCH": "#d0202a",
    "SEED": "#f5cf10",
    "FINAL": "#f7f7f7",
    "NODE": "#8e3fb0",
    "INODE": "#b993d1",
    "ROOT": "#1f5fcf",
    "IROOT": "#7d9bd1",
    "AROOT": "#3f86ff",
    "FIXED": "#f0f0f0",
    "TOUCH": "#1f5fcf",
    "TOUCHSEED": "#f5cf10",
    "DISBAND": "#ff9f1c",
}
"""Base colour of each mode name (lit faces are this colour times the Lambert shade)."""

SEARCH_FAR = "#f4b6b6"
"""Colour of a SEARCH module at the far end of the scent scale (or with no scent)."""

PALETTE = ("#4c9a2a", "#d0202a", "#f5cf10", "#1f5fcf", "#8e3fb0", "#ff9f1c", "#17becf", "#8c564b")
"""Colours of modes without a paper colour, by mode index."""

OBJECT_COLOUR = "#3aa17e"
SOLID_COLOUR = "#6b5d52"
FLOOR_COLOUR = "#c9c4b8"
BACKGROUND = "#dfe5ec"


def rgb(hex_colour: str) -> np.ndarray:
    """``(3,)`` float in ``[0, 1]`` from ``#rrggbb``."""
    h = hex_colour.lstrip("#")
    return np.array([int(h[i : i + 2], 16) for i in (0, 2, 4)], dtype=float) / 255.0


def mode_palette(mode_names) -> np.ndarray:
    """``(M, 3)`` base colour of each mode."""
    return np.array([rgb(MODE_COLOURS.get(name, PALETTE[i % len(PALETTE)])) for i, name in enumerate(mode_names)])


def module_colours(mode_names, modes: np.ndarray, scent: np.ndarray | None, scent_scale: float) -> np.ndarray:
    """``(N, 3)`` base colour of each module.

    Args:
        mode_names: the task's mode names.
        modes: ``(N,)`` mode of each module.
        scent: ``(N,)`` scent on channel 0 (or None); shades SEARCH modules.
        scent_scale: scent value drawn palest; smaller values blend towards deep red.
    """
    colours = mode_palette(mode_names)[np.asarray(modes)]
    if scent is not None and "SEARCH" in mode_names:
        search = np.asarray(modes) == list(mode_names).index("SEARCH")
        t = np.clip(np.asarray(scent[search], dtype=float) / max(scent_scale, 1.0), 0.0, 1.0)[:, None]
        colours[search] = (1 - t) * rgb(MODE_COLOURS["SEARCH"]) + t * rgb(SEARCH_FAR)
    return colours

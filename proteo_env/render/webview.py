"""One self-contained HTML file that plays a recorded episode in 3D in the browser (three.js).

:func:`write_html` packs a :class:`~proteo_env.recording.Recording` into one page that opens
offline: the vendored three.js bundle (``web/three.bundle.js``, MIT, see ``web/README.md``),
the viewer (``web/viewer.js``, ``web/viewer.css``) and the episode, all inline.

The episode travels as JSON (``<script id="proteo-data" type="application/json">``) whose
per-cycle arrays are packed compactly (:func:`pack_array`): differences along time (frame 0
kept whole), in the smallest integer type that holds them, zlib-compressed, base64. A module
that does not change costs a zero, so a 2,000-module, 1,000-cycle episode is a few megabytes
at most. Scents equal to ``scent_max`` ("no scent") are stored as -1, so that their
differences stay small. The page inflates them with the browser's ``DecompressionStream``.

Per-module state on the page: ``positions`` ``(T, N, 3)``, ``modes`` ``(T, N)``, ``scents``
``(T, C, N)``; static: ``anchored`` ``(N,)``, ``solid_sites`` ``(S, 3)``, ``object_sites``
``(O, 3)``; ``series`` name -> ``(T,)`` floats (null where NaN). Colours come from
:mod:`.colours` and the cell shape from :data:`.geometry.FACE_QUADS`, so the page draws what
the matplotlib pictures draw.
"""

from __future__ import annotations

import base64
import json
import math
import zlib
from pathlib import Path

import numpy as np

from ..core.lattice import DIRECTIONS
from .camera import Camera, side_azimuth
from .colours import BACKGROUND, FLOOR_COLOUR, MODE_COLOURS, OBJECT_COLOUR, PALETTE, SEARCH_FAR, SOLID_COLOUR
from .geometry import FACE_QUADS
from .renderer import AMBIENT, FLOOR_LEVEL, LIGHT_IN_CAMERA

WEB = Path(__file__).with_name("web")
"""Folder of the page's parts: ``three.bundle.js``, ``viewer.js``, ``viewer.css``, ``viewer.html``."""

INT_TYPES = (np.int8, np.int16, np.int32)


def _smallest_int(a: np.ndarray):
    lo, hi = (int(a.min()), int(a.max())) if a.size else (0, 0)
    for dtype in INT_TYPES:
        info = np.iinfo(dtype)
        if info.min <= lo and hi <= info.max:
            return dtype
    raise ValueError(f"values {lo}..{hi} do not fit in int32; allowed: int32 values")


def pack_array(a: np.ndarray, *, along_time: bool) -> dict:
    """A compact JSON-ready form of an integer array.

    Args:
        a: integer array; with ``along_time`` its first axis is time.
        along_time: store differences along the first axis (the first row whole).

    Returns:
        ``{"shape", "dtype", "delta", "zlib_base64"}``: the (differenced) values in the smallest
        of int8/int16/int32 that holds them, little-endian, zlib-compressed and base64-encoded.
    """
    values = np.asarray(a, dtype=np.int64)
    if along_time and len(values):
        values = np.diff(values, axis=0, prepend=np.zeros((1,) + values.shape[1:], dtype=np.int64))
    dtype = _smallest_int(values)
    raw = values.astype(np.dtype(dtype).newbyteorder("<")).tobytes()
    return {
        "shape": list(values.shape),
        "dtype": np.dtype(dtype).name,
        "delta": bool(along_time),
        "zlib_base64": base64.b64encode(zlib.compress(raw, 9)).decode("ascii"),
    }


def unpack_array(packed: dict) -> np.ndarray:
    """The int64 array :func:`pack_array` packed (what the page computes, in numpy)."""
    raw = zlib.decompress(base64.b64decode(packed["zlib_base64"]))
    values = np.frombuffer(raw, dtype=np.dtype(packed["dtype"]).newbyteorder("<")).astype(np.int64)
    values = values.reshape(packed["shape"])
    return np.cumsum(values, axis=0) if packed["delta"] and len(values) else values


def episode_data(recording) -> dict:
    """Everything the page shows of ``recording``, JSON-ready (per-cycle arrays packed)."""
    names = list(recording.mode_names)
    scents = np.where(recording.scents >= recording.scent_max, -1, recording.scents)
    series = {
        k: [None if not math.isfinite(v) else float(v) for v in np.asarray(values, dtype=float)]
        for k, values in recording.series.items()
    }
    return {
        "format": "proteo-view",
        "format_version": 1,
        "task_id": recording.task_id,
        "policy": recording.policy,
        "seed": recording.seed,
        "success": bool(recording.success),
        "package_version": recording.package_version,
        "mode_names": names,
        "mode_colours": [MODE_COLOURS.get(name, PALETTE[i % len(PALETTE)]) for i, name in enumerate(names)],
        "search_mode": names.index("SEARCH") if "SEARCH" in names else -1,
        "search_far": SEARCH_FAR,
        "scent_scale": int(recording.scent_range()),
        "colours": {"object": OBJECT_COLOUR, "solid": SOLID_COLOUR, "floor": FLOOR_COLOUR, "background": BACKGROUND},
        "light": {"ambient": AMBIENT, "direction_in_camera": [float(v) for v in LIGHT_IN_CAMERA]},
        "view_direction": [float(v) for v in Camera(azimuth=side_azimuth(recording.positions[-1])).axes()[2]],
        "face_quads": FACE_QUADS.tolist(),
        "directions": DIRECTIONS.tolist(),
        "floor_level": FLOOR_LEVEL,
        "box": [int(v) for v in recording.box],
        "floor": bool(recording.floor),
        "n_frames": int(recording.n_frames),
        "n_modules": int(recording.positions.shape[1]),
        "n_channels": int(recording.scents.shape[1]),
        "cycles": [int(c) for c in recording.cycles],
        "metric_names": recording.metric_names(),
        "series": series,
        "positions": pack_array(recording.positions, along_time=True),
        "modes": pack_array(recording.modes, along_time=True),
        "scents": pack_array(scents, along_time=True),
        "anchored": pack_array(recording.anchored.astype(np.int64), along_time=False),
        "solid_sites": pack_array(recording.solid_sites.reshape(-1, 3), along_time=False),
        "object_sites": pack_array(recording.object_sites.reshape(-1, 3), along_time=False),
    }


def _inline_code(name: str) -> str:
    """The script ``web/<name>``, checked to hold nothing that would end or confuse an inline ``<script>``."""
    text = (WEB / name).read_text(encoding="utf-8")
    lowered = text.lower()
    for bad in ("</script", "<!--"):
        if bad in lowered:
            raise RuntimeError(f"web/{name} contains {bad!r}, which cannot stand inside an inline <script>")
    return text


def html_page(recording) -> str:
    """The whole page for ``recording``: one HTML string, no external references."""
    data = json.dumps(episode_data(recording), separators=(",", ":"), allow_nan=False)
    title = f"proteo · {recording.task_id} · {recording.policy}"
    page = (WEB / "viewer.html").read_text(encoding="utf-8")
    parts = {
        "{{TITLE}}": title.replace("&", "&amp;").replace("<", "&lt;"),
        "{{CSS}}": (WEB / "viewer.css").read_text(encoding="utf-8"),
        "{{THREE}}": _inline_code("three.bundle.js"),
        "{{VIEWER}}": _inline_code("viewer.js"),
        "{{DATA}}": data.replace("</", "<\\/").replace("<!--", "<\\u0021--"),
    }
    for key, value in parts.items():
        before, sep, after = page.partition(key)
        if not sep:
            raise RuntimeError(f"web/viewer.html lacks the placeholder {key}")
        page = before + value + after
    return page


def write_html(recording, path) -> Path:
    """Write the viewer page of ``recording`` to ``path`` (``.html``) and return the path."""
    path = Path(path)
    if path.suffix.lower() not in (".html", ".htm"):
        raise ValueError(f"viewer page {str(path)!r} is not allowed; allowed: a file name ending in .html")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(html_page(recording), encoding="utf-8")
    tmp.replace(path)
    return path

"""Camera settings of the renderer (no plotting library imported here)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np


@dataclasses.dataclass(frozen=True)
class Camera:
    """Where the picture is taken from (orthographic projection).

    Attributes:
        azimuth: degrees about the vertical ``z`` axis (matplotlib's convention: ``-50`` looks
            from the front right).
        elevation: degrees above the ``x-y`` plane; negative looks from underneath (the floor
            is then not drawn).
        zoom: magnification; 1 fits the framed region to the image.
        follow: frame the modules of each picture (True) or a fixed region: the whole
            recorded episode in replays, the world's box in a live environment (False).
        width, height: image size in pixels.
    """

    azimuth: float = -50.0
    elevation: float = 28.0
    zoom: float = 1.0
    follow: bool = True
    width: int = 800
    height: int = 600

    def __post_init__(self):
        for name in ("azimuth", "elevation", "zoom"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"camera {name}={value!r} is not allowed; allowed: a finite number")
        if not -90.0 <= self.elevation <= 90.0:
            raise ValueError(f"camera elevation={self.elevation!r} is not allowed; allowed: -90..90 degrees")
        if self.zoom <= 0:
            raise ValueError(f"camera zoom={self.zoom!r} is not allowed; allowed: a number > 0")
        if not isinstance(self.follow, bool):
            raise ValueError(f"camera follow={self.follow!r} is not allowed; allowed: True or False")
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 16 <= value <= 8192:
                raise ValueError(f"camera {name}={value!r} is not allowed; allowed: an integer 16..8192 (pixels)")

    @classmethod
    def from_options(cls, options) -> Camera:
        """A camera from ``None``, a :class:`Camera` or a dict of its fields (unknown keys raise)."""
        if options is None:
            return cls()
        if isinstance(options, cls):
            return options
        if not isinstance(options, dict):
            raise ValueError(
                f"camera={options!r} is not allowed; allowed: None, a Camera or a dict of "
                f"{', '.join(f.name for f in dataclasses.fields(cls))}"
            )
        allowed = [f.name for f in dataclasses.fields(cls)]
        unknown = [k for k in options if k not in allowed]
        if unknown:
            raise ValueError(f"unknown camera setting {unknown[0]!r}; allowed: {', '.join(allowed)}")
        return cls(**options)

    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(right, up, towards_viewer)``: unit vectors of the screen in world coordinates."""
        az, el = math.radians(self.azimuth), math.radians(self.elevation)
        view = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        right = np.array([-math.sin(az), math.cos(az), 0.0])
        up = np.cross(view, right)
        return right, up, view


def side_azimuth(positions, *, turn: float = 30.0, default: float = -50.0) -> float:
    """An azimuth that shows the modules' longest horizontal extent from the side.

    The camera looks across the main horizontal axis of ``positions``, turned ``turn``
    degrees off square so the depth still reads; ``default`` when the layout has no clear
    main axis (its spread along it is less than 1.5 times that across it).
    """
    xy = np.asarray(positions, dtype=float).reshape(-1, 3)[:, :2]
    xy = xy - xy.mean(axis=0) if len(xy) else xy
    if len(xy) < 2:
        return default
    values, vectors = np.linalg.eigh(xy.T @ xy)
    if values[1] < 1.5 * values[0]:
        return default
    ax, ay = vectors[:, 1]
    return float(np.degrees(np.arctan2(ay, ax)) - 90.0 + turn)

"""Movies and stills of a :class:`~proteo_env.recording.Recording`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .camera import Camera, side_azimuth
from .movie import MovieWriter
from .renderer import Renderer


def frame_indices(n_frames: int, max_frames: int | None) -> np.ndarray:
    """At most ``max_frames`` frame indices spread evenly over ``n_frames``, first and last included."""
    if max_frames is None or n_frames <= max_frames:
        return np.arange(n_frames)
    if max_frames < 2:
        return np.array([n_frames - 1])
    return np.unique(np.round(np.linspace(0, n_frames - 1, max_frames)).astype(np.int64))


def recording_renderer(recording, camera=None, *, follow: bool = False) -> Renderer:
    """A renderer for ``recording`` (with ``follow=False``: fixed framing of the whole episode).

    Settings a ``camera`` dict leaves out are chosen for the recording: ``follow`` as given
    here (False: a steady movie) and an ``azimuth`` that looks across the last frame's main
    horizontal axis (:func:`~proteo_env.render.camera.side_azimuth`).
    """
    if camera is None or isinstance(camera, dict):
        camera = {"follow": follow, "azimuth": side_azimuth(recording.positions[-1]), **(camera or {})}
    camera = Camera.from_options(camera)
    return Renderer(camera, frame_points=recording.sites_visited(), scent_scale=recording.scent_range())


def render_movie(
    recording, path, *, camera=None, fps: float = 20.0, max_frames: int | None = 300, progress=None
) -> Path:
    """Write a GIF or MP4 of ``recording`` and return its path.

    Args:
        recording: a :class:`~proteo_env.recording.Recording`.
        path: ``.gif`` or ``.mp4``.
        camera: a :class:`Camera` or a dict of its fields (default: fixed framing).
        fps: frames per second of the movie.
        max_frames: frames drawn at most, spread evenly over the episode (None: every cycle).
        progress: optional callable called once per frame drawn (for progress bars).
    """
    renderer = recording_renderer(recording, camera)
    try:
        with MovieWriter(path, fps=fps) as movie:
            for t in frame_indices(recording.n_frames, max_frames):
                movie.append(renderer.render(recording.scene(int(t))))
                if progress is not None:
                    progress()
    finally:
        renderer.close()
    return Path(path)


def render_still(recording, path, *, frame: int = -1, camera=None, caption: str | None = None) -> Path:
    """Write one frame of ``recording`` as an image (format from the suffix, e.g. ``.png``), framed on its modules."""
    renderer = recording_renderer(recording, camera, follow=True)
    try:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        renderer.savefig(recording.scene(frame % recording.n_frames, caption=caption), path)
    finally:
        renderer.close()
    return path

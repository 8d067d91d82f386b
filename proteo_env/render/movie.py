"""Movies of rendered frames: GIF with Pillow, MP4 (H.264) with the ffmpeg binary of ``imageio-ffmpeg``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

MOVIE_SUFFIXES = (".gif", ".mp4")


def check_movie_path(path) -> Path:
    """``path`` as a :class:`Path` if its suffix names a movie format, else ``ValueError``."""
    path = Path(path)
    if path.suffix.lower() not in MOVIE_SUFFIXES:
        raise ValueError(f"movie file {str(path)!r} has suffix {path.suffix!r}; allowed: {', '.join(MOVIE_SUFFIXES)}")
    return path


class MovieWriter:
    """Appends ``(H, W, 3)`` uint8 frames to a GIF or MP4 file (a context manager).

    The file is written to a temporary name and renamed when the writer closes without an
    error, so a failed run leaves no half-written movie.
    """

    def __init__(self, path, *, fps: float = 20.0):
        self.path = check_movie_path(path)
        if not fps > 0:
            raise ValueError(f"fps={fps!r} is not allowed; allowed: a number > 0")
        self.fps = float(fps)
        self.kind = self.path.suffix.lower()
        self._tmp = self.path.with_name(self.path.stem + ".tmp" + self.path.suffix)
        self._gif_frames: list = []
        self._ffmpeg = None
        self.n_frames = 0

    def __enter__(self):
        self.path.parent.mkdir(parents=True, exist_ok=True)
        return self

    def append(self, frame: np.ndarray) -> None:
        frame = np.ascontiguousarray(frame, dtype=np.uint8)
        if self.kind == ".gif":
            from PIL import Image

            self._gif_frames.append(
                Image.fromarray(frame).quantize(colors=255, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
            )
        else:
            if self._ffmpeg is None:
                import imageio_ffmpeg

                h, w = frame.shape[:2]
                self._ffmpeg = imageio_ffmpeg.write_frames(
                    str(self._tmp),
                    (w, h),
                    fps=self.fps,
                    codec="libx264",
                    pix_fmt_in="rgb24",
                    pix_fmt_out="yuv420p",
                    quality=8,
                    macro_block_size=2,
                    output_params=["-movflags", "+faststart"],
                )
                self._ffmpeg.send(None)
            self._ffmpeg.send(frame)
        self.n_frames += 1

    def __exit__(self, exc_type, exc, tb):
        try:
            if self.kind == ".gif" and self._gif_frames and exc_type is None:
                first, *rest = self._gif_frames
                first.save(
                    self._tmp,
                    format="GIF",
                    save_all=True,
                    append_images=rest,
                    duration=int(round(1000 / self.fps)),
                    loop=0,
                    optimize=False,
                    disposal=1,
                )
            if self._ffmpeg is not None:
                self._ffmpeg.close()
            if exc_type is None and self.n_frames:
                self._tmp.replace(self.path)
        finally:
            self._gif_frames = []
            if self._tmp.exists():
                self._tmp.unlink()
        return False

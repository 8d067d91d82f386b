"""What :meth:`ProteoEnv.render` calls for ``render_mode`` ``"rgb_array"`` and ``"human"``."""

from __future__ import annotations

import warnings

from .renderer import Renderer
from .scene import Scene


class Viewer:
    """Renders an environment's world: returns the picture (``rgb_array``) or shows it in a window (``human``).

    Args:
        render_mode: ``"rgb_array"`` or ``"human"``.
        camera: a :class:`~proteo_env.render.camera.Camera` or a dict of its fields.
        fps: frames per second a ``human`` window is paced at.
        caption: text before the cycle number (the task id).
    """

    def __init__(self, render_mode: str, camera=None, *, fps: float = 10.0, caption: str = ""):
        self.render_mode = render_mode
        self.renderer = Renderer(camera)
        self.fps = fps
        self.caption = caption
        self._window = None

    def render(self, world):
        """Draw a :class:`~proteo_env.env.WorldView`; the ``(H, W, 3)`` uint8 picture, or None in ``human`` mode."""
        caption = f"{self.caption} · cycle {world.cycle}" if self.caption else None
        frame = self.renderer.render(Scene.from_world(world, caption=caption))
        if self.render_mode == "rgb_array":
            return frame
        self._show(frame)
        return None

    def _show(self, frame) -> None:
        import matplotlib.pyplot as plt

        if self._window is None or not plt.fignum_exists(self._window[0].number):
            cam = self.renderer.camera
            fig = plt.figure(figsize=(cam.width / 100, cam.height / 100), dpi=100)
            ax = fig.add_axes((0, 0, 1, 1))
            ax.set_axis_off()
            self._window = (fig, ax.imshow(frame))
        else:
            self._window[1].set_data(frame)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*non-interactive.*")
            plt.pause(1.0 / self.fps)

    def close(self) -> None:
        if self._window is not None:
            import matplotlib.pyplot as plt

            plt.close(self._window[0])
            self._window = None
        self.renderer.close()

"""Pictures, movies and plots of lattice worlds (imported only when something is drawn).

* :class:`Renderer` draws a :class:`Scene` (one frame: modules, obstacles, object, floor) into
  an ``(H, W, 3)`` uint8 array: every module a true rhombic dodecahedron, only the faces that
  look onto unoccupied sites, Lambert-shaded, coloured by mode as in the paper
  (:mod:`.colours`). matplotlib's Agg rasteriser does the drawing; matplotlib itself is
  imported when the first :class:`Renderer` is built.
* :class:`Camera` holds the view: ``azimuth``, ``elevation``, ``zoom``, ``follow``, ``width``,
  ``height``.
* :class:`MovieWriter` writes frames to ``.gif`` (Pillow) or ``.mp4`` (imageio-ffmpeg).
* :mod:`.plots` draws the per-cycle series of a recording; :mod:`.figures` reproduces the
  paper's figures (``proteo figures``).

``ProteoEnv.render()`` uses :class:`~.viewer.Viewer` for ``render_mode="rgb_array"`` and
``"human"``; ``proteo replay`` renders a :class:`~proteo_env.recording.Recording`.
"""

from .camera import Camera
from .movie import MovieWriter, check_movie_path
from .renderer import Renderer
from .scene import Scene

__all__ = ["Camera", "MovieWriter", "Renderer", "Scene", "check_movie_path"]

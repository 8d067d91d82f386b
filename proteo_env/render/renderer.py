"""Pictures of lattice worlds with matplotlib: rhombic dodecahedra, their visible faces only.

Per frame, :class:`Renderer` selects the faces of modules, obstacles and the object that look
onto unoccupied sites (:mod:`.geometry`), drops those facing away from the camera, projects
the rest orthographically, shades each face with a Lambert term for a light fixed relative
to the camera, and hands them, farthest first, to one matplotlib ``PolyCollection`` drawn
by the Agg rasteriser. The figure is built once and reused, so a frame costs the face
selection plus one Agg draw.
"""

from __future__ import annotations

import numpy as np

from .camera import Camera
from .colours import BACKGROUND, FLOOR_COLOUR, MODE_COLOURS, OBJECT_COLOUR, PALETTE, SOLID_COLOUR, module_colours, rgb
from .geometry import FACE_NORMALS, FACE_QUADS, occupancy_grid, visible_faces
from .scene import Scene

AMBIENT = 0.45
"""Share of a face's colour lit by ambient light; the rest is the Lambert term."""
LIGHT_IN_CAMERA = np.array([-0.3, 0.7, 0.65])
"""Light direction in camera coordinates (right, up, towards viewer): from the upper left."""
EDGE_MIN_PIXELS = 8.0
"""Pixels per lattice unit from which faces are outlined when ``edges`` is None (automatic)."""
FLOOR_LEVEL = -0.5
"""Height of the drawn ground plane (the ground cells' faces lie between -1 and 0)."""


class Renderer:
    """Draws :class:`~proteo_env.render.scene.Scene` objects into RGB arrays.

    Args:
        camera: a :class:`~proteo_env.render.camera.Camera`, a dict of its fields, or None.
        frame_points: ``(K, 3)`` world points the picture frames when ``camera.follow`` is False
            (default: the corners of the scene's box).
        scent_scale: scent drawn palest on SEARCH modules (default: each frame's largest).
        legend: draw the mode legend.
        edges: outline faces (True, False, or None: only where a lattice unit spans at least
            :data:`EDGE_MIN_PIXELS` pixels; outlines of tiny faces cost time and add nothing).
    """

    def __init__(
        self,
        camera=None,
        *,
        frame_points=None,
        scent_scale: float | None = None,
        legend: bool = True,
        edges: bool | None = None,
    ):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.collections import LineCollection, PolyCollection
        from matplotlib.figure import Figure

        self.camera = Camera.from_options(camera)
        self.frame_points = None if frame_points is None else np.asarray(frame_points, float).reshape(-1, 3)
        self.scent_scale = scent_scale
        self.legend = legend
        self.edges = edges
        cam = self.camera
        self.figure = Figure(figsize=(cam.width / 100, cam.height / 100), dpi=100, facecolor=BACKGROUND)
        self.canvas = FigureCanvasAgg(self.figure)
        ax = self.ax = self.figure.add_axes((0, 0, 1, 1))
        ax.set_axis_off()
        ax.set_facecolor(BACKGROUND)
        self._floor = PolyCollection([], facecolors=FLOOR_COLOUR, edgecolors="none", zorder=1)
        self._grid = LineCollection([], colors="#b3ad9f", linewidths=0.5, zorder=1.5)
        self._faces = PolyCollection([], zorder=2, joinstyle="round")
        for c in (self._floor, self._grid, self._faces):
            ax.add_collection(c)
        self._caption = ax.text(
            0.015, 0.985, "", transform=ax.transAxes, va="top", ha="left", fontsize=11, color="#222222", zorder=5
        )
        self._legend_key = None
        self.n_faces = 0

    # ------------------------------------------------------------------ frame
    def render(self, scene: Scene) -> np.ndarray:
        """The picture of ``scene`` as an ``(height, width, 3)`` uint8 array."""
        self.draw(scene)
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()

    def draw(self, scene: Scene) -> None:
        """Update the figure to show ``scene`` (without rasterising it)."""
        cam = self.camera
        right, up, view = cam.axes()
        light = LIGHT_IN_CAMERA @ np.stack([right, up, view])
        light /= np.linalg.norm(light)
        to_screen = np.stack([right, up], axis=1)  # (3, 2)

        positions = np.asarray(scene.positions, dtype=np.int64).reshape(-1, 3)
        solid = np.asarray(scene.solid_sites, dtype=np.int64).reshape(-1, 3)
        obj = np.asarray(scene.object_sites, dtype=np.int64).reshape(-1, 3)
        grid, origin = occupancy_grid((positions, solid, obj), floor=scene.floor)
        scale = self.scent_scale if self.scent_scale is not None else scene.scent_range()
        groups = [
            (positions, module_colours(scene.mode_names, scene.modes, scene.scent, scale)),
            (solid, np.broadcast_to(rgb(SOLID_COLOUR), solid.shape)),
            (obj, np.broadcast_to(rgb(OBJECT_COLOUR), obj.shape)),
        ]
        facing = FACE_NORMALS @ view > 1e-9  # faces turned towards the camera
        centres, faces, colours = [], [], []
        for sites, base in groups:
            if not len(sites):
                continue
            cell, face = visible_faces(sites, grid, origin)
            keep = facing[face]
            cell, face = cell[keep], face[keep]
            centres.append(sites[cell])
            faces.append(face)
            colours.append(base[cell])
        if centres:
            centres, faces, colours = np.concatenate(centres), np.concatenate(faces), np.concatenate(colours)
        else:
            centres, faces, colours = np.zeros((0, 3)), np.zeros(0, dtype=np.int64), np.zeros((0, 3))
        self.n_faces = len(faces)

        # orthographic projection, painter's order (farthest face first)
        quad_screen = FACE_QUADS @ to_screen  # (12, 4, 2)
        verts = (centres @ to_screen)[:, None, :] + quad_screen[faces]
        depth = centres @ view + (FACE_NORMALS @ view)[faces] / np.sqrt(2.0)
        order = np.argsort(depth, kind="stable")
        shade = AMBIENT + (1 - AMBIENT) * np.clip(FACE_NORMALS[faces] @ light, 0.0, 1.0)
        face_rgb = np.clip(colours * shade[:, None], 0.0, 1.0)[order]
        self._faces.set_verts(verts[order])
        self._faces.set_facecolor(face_rgb)

        self._frame(scene, positions, obj, to_screen)
        pixels_per_unit = cam.height / (self.ax.get_ylim()[1] - self.ax.get_ylim()[0])
        edges = self.edges if self.edges is not None else pixels_per_unit >= EDGE_MIN_PIXELS
        if edges:
            self._faces.set_edgecolor(face_rgb * 0.55)
            self._faces.set_linewidth(float(np.clip(0.02 * pixels_per_unit, 0.1, 0.7)))
        else:
            self._faces.set_edgecolor("none")
            self._faces.set_linewidth(0.0)
        self._draw_floor(scene, to_screen, view)
        self._caption.set_text(scene.caption)
        if self.legend:
            self._draw_legend(scene, has_object=len(obj) > 0)

    def _frame(self, scene, positions, obj, to_screen) -> None:
        cam = self.camera
        if not cam.follow and self.frame_points is not None and len(self.frame_points):
            points = self.frame_points
        elif not cam.follow and any(scene.box):
            hi = np.asarray(scene.box, float) - 1
            points = np.array([[x, y, z] for x in (0, hi[0]) for y in (0, hi[1]) for z in (0, hi[2])])
        else:
            points = np.concatenate([positions, obj]).astype(float)
            if not len(points):
                points = np.zeros((1, 3))
        screen = points @ to_screen
        lo2, hi2 = screen.min(axis=0) - 1.2, screen.max(axis=0) + 1.2
        centre, half = (lo2 + hi2) / 2, (hi2 - lo2) / 2
        aspect = cam.width / cam.height
        half_y = max(half[1], half[0] / aspect, 2.0) * 1.04 / cam.zoom
        self.ax.set_xlim(centre[0] - half_y * aspect, centre[0] + half_y * aspect)
        self.ax.set_ylim(centre[1] - half_y, centre[1] + half_y)

    def _draw_floor(self, scene, to_screen, view) -> None:
        if not scene.floor or view[2] <= 0:
            self._floor.set_verts([])
            self._grid.set_segments([])
            return
        x_max, y_max = (scene.box[0] or 1) - 1, (scene.box[1] or 1) - 1
        lo, hi = np.array([-1.5, -1.5]), np.array([x_max + 1.5, y_max + 1.5])
        corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        floor3 = np.column_stack([corners, np.full(4, FLOOR_LEVEL)])
        self._floor.set_verts([floor3 @ to_screen])
        step = max(2, 2 * int(np.ceil(max(x_max, y_max) / 100)))
        xs, ys = np.arange(0, x_max + 1, step), np.arange(0, y_max + 1, step)
        segments = [[[x, lo[1], FLOOR_LEVEL], [x, hi[1], FLOOR_LEVEL]] for x in xs]
        segments += [[[lo[0], y, FLOOR_LEVEL], [hi[0], y, FLOOR_LEVEL]] for y in ys]
        self._grid.set_segments(np.asarray(segments) @ to_screen)

    def _draw_legend(self, scene, *, has_object: bool) -> None:
        present = tuple(sorted(int(m) for m in np.unique(scene.modes)))
        key = (tuple(scene.mode_names), present, has_object)
        if key == self._legend_key:
            return
        from matplotlib.patches import Patch

        if self.ax.get_legend() is not None:
            self.ax.get_legend().remove()
        handles = [
            Patch(
                facecolor=MODE_COLOURS.get(scene.mode_names[m], PALETTE[m % len(PALETTE)]),
                edgecolor="#444444",
                label=scene.mode_names[m],
            )
            for m in present
        ]
        if has_object:
            handles.append(Patch(facecolor=OBJECT_COLOUR, edgecolor="#444444", label="object"))
        if handles:
            self.ax.legend(handles=handles, loc="upper right", fontsize=9, framealpha=0.85)
        self._legend_key = key

    def savefig(self, scene: Scene, path) -> None:
        """Write the picture of ``scene`` to an image file (format from the suffix)."""
        self.draw(scene)
        self.figure.savefig(path, facecolor=BACKGROUND)

    def close(self) -> None:
        """Release the figure."""
        self.figure.clear()

"""Rendering: visible-face geometry, pictures with the paper's mode colours, cameras, env render
modes of every task, movies and plots."""

from __future__ import annotations

import subprocess
import sys

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from conftest import small_overrides  # noqa: E402

import proteo_env  # noqa: E402
from proteo_env.core.lattice import DIRECTIONS  # noqa: E402
from proteo_env.render import Camera, MovieWriter, Renderer, Scene  # noqa: E402
from proteo_env.render.colours import BACKGROUND, MODE_COLOURS, SEARCH_FAR, rgb  # noqa: E402
from proteo_env.render.geometry import FACE_QUADS, occupancy_grid, visible_faces  # noqa: E402

PAPER_MODES = ("SLEEP", "SEARCH", "SEED", "FINAL", "NODE", "ROOT", "TOUCH", "TOUCHSEED")


# ---------------------------------------------------------------------- geometry
def test_face_quads_are_the_voronoi_cell_faces():
    for k, d in enumerate(DIRECTIONS):
        corners = FACE_QUADS[k]
        # every corner lies on the bisecting plane x . d = 1 and inside the cell |x_i| + |x_j| <= 1
        assert np.allclose(corners @ d, 1.0)
        for i, j in ((0, 1), (0, 2), (1, 2)):
            assert (np.abs(corners[:, i]) + np.abs(corners[:, j]) <= 1 + 1e-12).all()
        # a rhombus: equal sides, diagonals sqrt(2) and 1
        sides = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)
        assert np.allclose(sides, sides[0])
        assert np.isclose(np.linalg.norm(corners[0] - corners[2]), np.sqrt(2))
        assert np.isclose(np.linalg.norm(corners[1] - corners[3]), 1.0)


def test_only_faces_onto_unoccupied_sites_are_visible():
    sites = np.array([[0, 0, 0], [1, 1, 0], [5, 5, 0]])
    grid, origin = occupancy_grid([sites], floor=False)
    cell, face = visible_faces(sites, grid, origin)
    counts = np.bincount(cell, minlength=3)
    assert counts.tolist() == [11, 11, 12]
    shared = [k for k, d in enumerate(DIRECTIONS) if tuple(d) == (1, 1, 0)][0]
    assert shared not in face[cell == 0]

    # on the floor the 4 downward faces of a module at z = 0 touch the ground
    grid, origin = occupancy_grid([sites], floor=True)
    cell, _ = visible_faces(sites, grid, origin)
    assert np.bincount(cell, minlength=3).tolist() == [7, 7, 8]


# ---------------------------------------------------------------------- pictures
def _spread_scene(mode_names=PAPER_MODES, caption="test") -> Scene:
    """One isolated module per mode, in a row, plus a second SEARCH module with a far scent."""
    n = len(mode_names)
    positions = np.array([[2 * i, 0, 0] for i in range(n + 1)])  # touching at corners only
    modes = np.array(list(range(n)) + [mode_names.index("SEARCH")])
    scent = np.zeros(n + 1, dtype=np.int64)
    scent[-1] = 10
    return Scene(
        positions=positions, modes=modes, mode_names=mode_names, scent=scent, box=(2 * n + 1, 1, 1), caption=caption
    )


def _has_colour(image: np.ndarray, colour, *, min_pixels: int = 20, tol: float = 3 / 255) -> bool:
    """True when at least ``min_pixels`` pixels are ``colour`` lit by some shade in [0.4, 1]."""
    c = rgb(colour) if isinstance(colour, str) else np.asarray(colour)
    p = image.reshape(-1, 3) / 255.0
    shade = (p @ c) / (c @ c)
    residual = np.abs(p - shade[:, None] * c).max(axis=1)
    return int(((residual < tol) & (shade > 0.4) & (shade < 1.02)).sum()) >= min_pixels


def test_small_scene_renders_with_the_mode_colours():
    renderer = Renderer({"width": 480, "height": 200, "azimuth": -80.0}, legend=False, edges=False)
    image = renderer.render(_spread_scene())
    assert image.shape == (200, 480, 3) and image.dtype == np.uint8
    background = np.all(np.abs(image.astype(int) - (rgb(BACKGROUND) * 255).round()) <= 2, axis=-1)
    assert 0.05 < 1 - background.mean() < 0.9, "the modules cover part of the picture, not none or all"
    for mode in ("SEARCH", "SEED", "NODE", "ROOT"):  # TOUCH, TOUCHSEED share ROOT, SEED colours
        assert _has_colour(image, MODE_COLOURS[mode]), mode
    assert _has_colour(image, SEARCH_FAR), "a SEARCH module far from the scent source is pale"
    grey = np.abs(image.astype(int) - image.mean(axis=-1, keepdims=True)).max(axis=-1) <= 2
    brightness = image.mean(axis=-1)
    assert (grey & (brightness > 215)).sum() >= 20, "FINAL modules are white"
    assert (grey & (brightness < 150) & (brightness > 50)).sum() >= 20, "SLEEP modules are grey"
    renderer.close()


def test_faces_are_lit_from_a_fixed_direction():
    scene = Scene(positions=np.array([[0, 0, 0]]), modes=np.array([0]), mode_names=("SEED",), box=(1, 1, 1))
    image = Renderer({"width": 200, "height": 200}, legend=False, edges=False).render(scene)
    yellow = rgb(MODE_COLOURS["SEED"])
    p = image.reshape(-1, 3) / 255.0
    shade = (p @ yellow) / (yellow @ yellow)
    on_module = np.abs(p - shade[:, None] * yellow).max(axis=1) < 3 / 255
    levels = np.unique(np.round(shade[on_module], 2))
    assert len(levels) >= 3, "the visible faces get different Lambert shades"


def test_object_solid_and_floor_are_drawn():
    scene = Scene(
        positions=np.array([[0, 0, 0]]),
        modes=np.array([0]),
        mode_names=("SLEEP",),
        solid_sites=np.array([[4, 0, 0]]),
        object_sites=np.array([[0, 4, 0]]),
        box=(6, 6, 2),
        floor=True,
    )
    image = Renderer({"width": 300, "height": 240}, legend=False, edges=False).render(scene)
    from proteo_env.render.colours import FLOOR_COLOUR, OBJECT_COLOUR, SOLID_COLOUR

    for colour in (OBJECT_COLOUR, SOLID_COLOUR):
        assert _has_colour(image, colour)
    floor = np.all(np.abs(image.astype(int) - (rgb(FLOOR_COLOUR) * 255).round()) <= 2, axis=-1)
    assert floor.mean() > 0.05


def test_camera_settings_change_the_picture():
    scene = _spread_scene()
    base = Renderer({"width": 160, "height": 120}).render(scene)
    turned = Renderer({"width": 160, "height": 120, "azimuth": 40.0}).render(scene)
    below = Renderer({"width": 160, "height": 120, "elevation": -30.0}).render(scene)
    assert not np.array_equal(base, turned) and not np.array_equal(base, below)
    far = Renderer({"width": 160, "height": 120, "zoom": 0.5}, legend=False).render(scene)
    near = Renderer({"width": 160, "height": 120, "zoom": 2.0}, legend=False).render(scene)
    bg = (rgb(BACKGROUND) * 255).round()
    covered = [np.mean(np.any(np.abs(img.astype(int) - bg) > 2, axis=-1)) for img in (far, near)]
    assert covered[1] > covered[0]
    # a fixed camera frames the box, a following one the modules
    small = Scene(positions=np.array([[0, 0, 0]]), modes=np.array([0]), mode_names=("SLEEP",), box=(40, 40, 10))
    fixed = Renderer({"width": 160, "height": 120, "follow": False}, legend=False).render(small)
    follow = Renderer({"width": 160, "height": 120, "follow": True}, legend=False).render(small)
    coverage = [np.mean(np.any(np.abs(img.astype(int) - bg) > 2, axis=-1)) for img in (fixed, follow)]
    assert coverage[1] > 5 * coverage[0]


@pytest.mark.parametrize(
    "options, field",
    [
        ({"zoom": 0}, "zoom"),
        ({"elevation": 120}, "elevation"),
        ({"width": 3}, "width"),
        ({"follow": "yes"}, "follow"),
        ({"azimut": 3}, "azimut"),
    ],
)
def test_bad_camera_settings_are_refused(options, field):
    with pytest.raises(ValueError, match=field) as err:
        Camera.from_options(options)
    assert "allowed" in str(err.value)
    with pytest.raises(ValueError, match=field):
        proteo_env.make("sandbox-v0", n_modules=4, render_mode="rgb_array", camera=options)


# ---------------------------------------------------------------------- environment
@pytest.mark.parametrize("task_id", sorted(proteo_env.TASKS))
def test_every_task_renders_rgb_array(task_id):
    env = proteo_env.make(
        task_id, render_mode="rgb_array", camera={"width": 200, "height": 150}, **small_overrides(task_id)
    )
    env.reset(seed=0)
    env.step({a: np.zeros(env.action_layout.length, dtype=np.int64) for a in env.agents})
    image = env.render()
    assert image.shape == (150, 200, 3) and image.dtype == np.uint8
    assert image.std() > 5, "not a blank picture"
    env.close()


def test_human_and_ansi_modes():
    env = proteo_env.make("chain-v0", n_modules=6, render_mode="human", camera={"width": 120, "height": 90})
    env.reset(seed=0)
    assert env.render() is None
    env.close()
    env = proteo_env.make("chain-v0", n_modules=6, render_mode="ansi")
    env.reset(seed=0)
    assert env.render().startswith("cycle 0")
    with pytest.raises(ValueError, match="render_mode"):
        proteo_env.make("chain-v0", render_mode="rgb")


def test_rendering_is_imported_only_when_used():
    code = (
        "import sys, proteo_env\n"
        "env = proteo_env.make('sandbox-v0', n_modules=5)\n"
        "env.reset(seed=0)\n"
        "assert not any(m.startswith(('matplotlib', 'proteo_env.render')) for m in sys.modules), 'imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


# ---------------------------------------------------------------------- movies
def test_gif_and_mp4_movies(tmp_path):
    frames = [Renderer({"width": 96, "height": 64, "azimuth": a}).render(_spread_scene()) for a in (0.0, 30.0, 60.0)]
    with MovieWriter(tmp_path / "m.gif", fps=10) as movie:
        for f in frames:
            movie.append(f)
    from PIL import Image

    with Image.open(tmp_path / "m.gif") as gif:
        assert gif.n_frames == 3 and gif.size == (96, 64)
    with MovieWriter(tmp_path / "m.mp4", fps=10) as movie:
        for f in frames:
            movie.append(f)
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(tmp_path / "m.mp4"))
    meta = next(reader)
    assert meta["size"] == (96, 64) and sum(1 for _ in reader) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.gif", "m.mp4"], "no temporary files left"
    with pytest.raises(ValueError, match=r"\.gif, \.mp4"):
        MovieWriter(tmp_path / "m.avi")

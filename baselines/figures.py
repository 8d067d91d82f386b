"""The paper's figures, reproduced: ``proteo figures`` writes them into ``docs/figures``.

For each figure whose task is registered, one episode runs with the task's default policy
(``baselines.make_policy(env.task.default_policy, env, seed=...)``), is recorded, and gives:

* ``<name>.png``: the picture(s) the paper shows, side by side when there are several;
* ``<name>_plots.png``: the metrics behind it against cycles (:mod:`.plots`);
* ``<name>.gif``: a short movie of the episode; ``<name>.npz``: the recording itself
  (``proteo replay docs/figures/<name>.npz --out movie.mp4`` renders it again);
* ``README.md``: the gallery of what was produced, with captions.

A figure whose task is not registered yet is skipped with a printed note; it is picked up
as soon as the task is in :data:`proteo_env.TASKS`. With ``redraw=True`` (``proteo figures
--redraw``) the pictures, plots and movies are drawn again from the recordings already in the
folder, without running the episodes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np

from proteo_env.render.camera import Camera, side_azimuth


@dataclasses.dataclass(frozen=True)
class Still:
    """One picture of a figure: a frame of the recording seen by a camera."""

    frame: int
    caption: str
    camera: dict = dataclasses.field(default_factory=dict)


@dataclasses.dataclass(frozen=True)
class PaperFigure:
    """How to reproduce one of the paper's figures.

    Attributes:
        name: file stem in ``docs/figures`` and the ``--only`` name.
        task: the task's name (``Task.name``); the figure is skipped while it is not registered.
        title: the paper's figure title.
        caption: what the picture shows (written under it in the gallery).
        overrides: settings given to :func:`proteo_env.make` (besides ``params``).
        params: task parameters by paper symbol -> candidate field names; set where the task has one.
        stills: recording -> the pictures to draw.
        panel: ``(width, height)`` of each picture in pixels.
    """

    name: str
    task: str
    title: str
    caption: str
    overrides: dict
    stills: Callable
    params: dict = dataclasses.field(default_factory=dict)
    panel: tuple = (800, 600)


def _mode_count(recording, mode: str) -> np.ndarray:
    """``(T,)`` number of modules in ``mode`` per frame (zeros if the task has no such mode)."""
    if mode not in recording.mode_names:
        return np.zeros(recording.n_frames, dtype=np.int64)
    return (recording.modes == recording.mode_names.index(mode)).sum(axis=1)


def _chain_stills(rec) -> list[Still]:
    settled = _mode_count(rec, "FINAL") + _mode_count(rec, "SEED")
    half = np.flatnonzero(settled >= rec.positions.shape[1] / 2)
    frame = int(half[0]) if len(half) else rec.n_frames // 2
    return [
        Still(
            frame,
            f"half-way: cycle {int(rec.cycles[frame])}, {int(settled[frame])} of "
            f"{rec.positions.shape[1]} modules in the chain",
            {"azimuth": side_azimuth(rec.positions[frame]), "elevation": 25.0},
        )
    ]


def _last_still(what: str):
    def stills(rec) -> list[Still]:
        return [Still(-1, f"{what}: cycle {int(rec.cycles[-1])}")]

    return stills


def _branch_stills(rec) -> list[Still]:
    """The grown tree at the end, from above at an angle and from the side (it grows in 3D)."""
    cycle = int(rec.cycles[-1])
    return [
        Still(-1, f"branching: cycle {cycle}", {"elevation": 35.0}),
        Still(-1, f"from the side: cycle {cycle}", {"elevation": 0.0}),
    ]


def _table_stills(rec) -> list[Still]:
    from proteo_env.render.plots import weight_shifts

    shifts = weight_shifts(rec)
    if shifts:
        before = int(np.flatnonzero(rec.cycles < shifts[0])[-1])
        after_cycle = shifts[1] - 1 if len(shifts) > 1 else int(rec.cycles[-1])
        after = int(np.flatnonzero(rec.cycles <= after_cycle)[-1])
    else:
        before, after = rec.n_frames // 2, rec.n_frames - 1
    c = rec.cycles
    return [
        Still(before, f"before the weight shift: cycle {int(c[before])}"),
        Still(after, f"after the weight shift: cycle {int(c[after])}"),
        Still(after, f"after, from underneath: cycle {int(c[after])}", {"elevation": -25.0}),
    ]


FIGURES: tuple[PaperFigure, ...] = (
    PaperFigure(
        "chain",
        "chain",
        "Chain Behavior",
        "The Proteo system half-way to a complete chain: white modules have settled (FINAL), red "
        "ones are still looking for a place (SEARCH, darker nearer the seed's scent), the yellow "
        "module is the current SEED.",
        {"n_modules": 80, "max_cycles": 4000},
        _chain_stills,
        panel=(1000, 500),
    ),
    PaperFigure(
        "branch",
        "branch",
        "Branching Behavior",
        "Recursive branching in three dimensions with node-scent threshold T = 12 and branch count "
        "B = 6: purple NODE modules spawn yellow seeds in random directions; white modules have settled.",
        {},
        _branch_stills,
        params={
            "T": (12, ("T", "threshold", "node_threshold", "node_scent_threshold")),
            "B": (6, ("B", "branches", "branch_count", "max_branches", "n_branches")),
        },
    ),
    PaperFigure(
        "table",
        "table",
        "Adaptive Behavior",
        "The table before and after the weight shift: white FIXED board, blue roots, legs grown to "
        "the floor where the weight is; red modules are available for more legs.",
        {},
        _table_stills,
    ),
    PaperFigure(
        "grasp",
        "grasp",
        "Grasping Behavior",
        "Eight fingers grown towards the object and around it: white FINAL fingers, blue TOUCH "
        "modules on the object, yellow TOUCHSEEDs.",
        {},
        _last_still("grasp"),
    ),
)


def _paper_params(figure: PaperFigure, cls) -> dict:
    """The paper's parameter values for the task's fields that carry them (a note for those it lacks)."""
    fields = {f.name for f in dataclasses.fields(cls.Params)}
    chosen = {}
    for symbol, (value, candidates) in figure.params.items():
        name = next((c for c in candidates if c in fields), None)
        if name is not None:
            chosen[name] = value
        else:
            print(
                f"note: {cls.task_id()} has no parameter for the paper's {symbol} (looked for "
                f"{', '.join(candidates)}); its default is used, not {symbol} = {value}"
            )
    return chosen


def record_figure(figure: PaperFigure, seed: int):
    """Run the figure's episode with the task's default policy; return the recording."""
    from tqdm import tqdm

    from baselines import make_policy
    from proteo_env.recording import Recorder
    from proteo_env.registry import make, task_class
    from proteo_env.rollout import run_episode

    cls = task_class(figure.task)
    overrides = {**figure.overrides, **_paper_params(figure, cls)}
    env = make(cls.task_id(), **overrides)
    policy = make_policy(env.task.default_policy, env, seed=seed)
    recorder = Recorder(env, task_id=cls.task_id(), overrides=overrides, seed=seed, policy=policy.name)
    with tqdm(
        total=env.max_cycles, desc=f"{figure.name}: {cls.task_id()} / {policy.name}", unit="cycle", leave=False
    ) as bar:
        result = run_episode(env, policy, seed=seed, progress=lambda info: bar.update(1), observe=recorder)
    return recorder.recording(success=result.success)


def draw_figure(figure: PaperFigure, recording, out: Path) -> Path:
    """Write ``<name>.png``: the figure's stills side by side."""
    from PIL import Image

    from proteo_env.render.renderer import Renderer

    panels = []
    for still in figure.stills(recording):
        frame = still.frame % recording.n_frames
        camera = Camera.from_options(
            {"width": figure.panel[0], "height": figure.panel[1], "follow": True, **still.camera}
        )
        renderer = Renderer(camera)
        panels.append(renderer.render(recording.scene(frame, caption=f"{figure.title} · {still.caption}")))
        renderer.close()
    path = out / f"{figure.name}.png"
    Image.fromarray(np.concatenate(panels, axis=1)).save(path)
    return path


def make_figures(out: Path, *, seed: int = 0, only=None, redraw: bool = False) -> list[Path]:
    """Reproduce every figure whose task is registered (or those named in ``only``) into ``out``.

    ``redraw``: draw from ``out/<name>.npz`` where it exists instead of running the episode.
    """
    from proteo_env.recording import load
    from proteo_env.registry import TASKS
    from proteo_env.render.plots import plot_overview
    from proteo_env.render.replay import render_movie

    names = [f.name for f in FIGURES]
    unknown = [n for n in only or [] if n not in names]
    if unknown:
        raise ValueError(f"unknown figure {unknown[0]!r}; allowed: {', '.join(names)}")
    registered = {cls.name for cls in TASKS.values()}
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for figure in FIGURES:
        if only and figure.name not in only:
            continue
        if figure.task not in registered:
            print(
                f"skipping the {figure.title} figure: task {figure.task!r} is not registered yet "
                f"(registered: {', '.join(sorted(TASKS))})"
            )
            continue
        if redraw and (out / f"{figure.name}.npz").is_file():
            recording = load(out / f"{figure.name}.npz")
        else:
            recording = record_figure(figure, seed)
            recording.save(out / f"{figure.name}.npz")
        picture = draw_figure(figure, recording, out)
        pictured = sorted({int(recording.cycles[s.frame % recording.n_frames]) for s in figure.stills(recording)})
        plots = plot_overview(recording, out / f"{figure.name}_plots.png", marks={"pictured": pictured})
        movie = render_movie(
            recording, out / f"{figure.name}.gif", camera={"width": 480, "height": 300}, fps=12, max_frames=80
        )
        written += [picture, plots, movie]
        print(
            f"{figure.title}: {picture}, {plots}, {movie} ({recording.task_id}, {int(recording.cycles[-1])} cycles, "
            f"{'success' if recording.success else 'no success'})"
        )
    gallery = [(f, load(out / f"{f.name}.npz")) for f in FIGURES if (out / f"{f.name}.npz").is_file()]
    if gallery:
        _write_gallery(out, gallery)
    return written


def _write_gallery(out: Path, gallery) -> None:
    """``README.md`` in ``out``: every figure found there, with its caption and settings."""
    lines = [
        "# The paper's figures, reproduced",
        "",
        "Written by `proteo figures` (each episode runs the task's default policy; "
        "`proteo replay docs/figures/NAME.npz --out NAME.mp4` renders one again).",
        "",
    ]
    for figure, rec in gallery:
        settings = ", ".join(f"{k}={v}" for k, v in rec.overrides.items()) or "task defaults"
        lines += [
            f"## {figure.title}",
            "",
            f"![{figure.title}]({figure.name}.png)",
            "",
            figure.caption,
            "",
            f"`{rec.task_id}`, policy `{rec.policy}`, seed {rec.seed}, {settings}; "
            f"{rec.positions.shape[1]} modules, {int(rec.cycles[-1])} cycles, "
            f"{'success' if rec.success else 'no success'}. Movie: [{figure.name}.gif]({figure.name}.gif).",
            "",
            f"![{figure.title}: metrics against cycles]({figure.name}_plots.png)",
            "",
        ]
    (out / "README.md").write_text("\n".join(lines))

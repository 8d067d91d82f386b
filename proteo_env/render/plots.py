"""Plots (PNG) of a recording's per-cycle series: the task's metrics, reward, moves, connectivity.

Which series share a plot:

1. the task's ``plot_groups`` (``{title: [metric, ...]}``, a class attribute of the task);
2. metrics named ``legs_region_*`` together, as "legs per region";
3. every other metric alone; then the built-in series: connected pieces (connectivity),
   modules moved, team reward.

Weight shifts are marked on every plot with dashed vertical lines: the cycles where a metric
whose name starts with ``weight`` changes value, or, for a metric named ``*_shift``, where it
is non-zero.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

BUILTIN_TITLES = {"components": "connected pieces", "moved": "modules moved", "reward": "team reward"}


def plot_groups(recording) -> dict[str, list[str]]:
    """Plot title -> the series drawn in it, in drawing order."""
    from ..config import ConfigError
    from ..registry import task_class

    try:
        declared = dict(getattr(task_class(recording.task_id), "plot_groups", {}) or {})
    except ConfigError:  # a task that is not registered here: the generic rules only
        declared = {}
    metrics = recording.metric_names()
    groups: dict[str, list[str]] = {}
    used: set[str] = set()
    for title, names in declared.items():
        present = [n for n in names if n in recording.series]
        if present:
            groups[title] = present
            used.update(present)
    legs = [n for n in metrics if n.startswith("legs_region_") and n not in used]
    if legs:
        groups["legs per region"] = legs
        used.update(legs)
    for name in metrics:
        if name not in used:
            groups[name.replace("_", " ")] = [name]
    for name, title in BUILTIN_TITLES.items():
        if name in recording.series and name not in used:
            groups[title] = [name]
    return groups


def weight_shifts(recording) -> list[int]:
    """Cycles at which the weight moved (from metrics named ``weight*`` or ``*_shift``)."""
    cycles = recording.cycles
    marks = np.zeros(len(cycles), dtype=bool)
    for name, values in recording.series.items():
        v = np.nan_to_num(np.asarray(values, dtype=float), nan=0.0)
        if name.endswith("_shift"):
            marks |= v != 0
        elif name.startswith("weight") and len(v) > 1:
            marks[1:] |= v[1:] != v[:-1]
    return [int(c) for c in cycles[marks]]


def _draw(ax, recording, names, shifts, marks=None) -> None:
    cycles = recording.cycles
    for name in names:
        ax.plot(cycles, recording.series[name], label=name, linewidth=1.4)
    for k, c in enumerate(shifts):
        ax.axvline(c, color="#444444", linestyle="--", linewidth=1.0, label="weight shift" if k == 0 else None)
    for label, at in (marks or {}).items():
        for k, c in enumerate(at):
            ax.axvline(c, color="#c0392b", linestyle=":", linewidth=1.4, label=label if k == 0 else None)
    ax.grid(True, alpha=0.3)
    ax.margins(x=0)
    values = np.concatenate([np.asarray(recording.series[n], dtype=float) for n in names])
    if np.nanmin(values, initial=0.0) >= 0:  # counts and shares: start the axis at zero
        ax.set_ylim(bottom=0, top=max(ax.get_ylim()[1], 1.0))
    if len(names) > 1 or shifts or marks:
        ax.legend(fontsize=8, loc="best")


def plot_overview(recording, path, *, marks: dict[str, list[int]] | None = None) -> Path:
    """Write one PNG with every plot group stacked over a shared cycle axis.

    ``marks``: label -> cycles marked with dotted lines (the cycles a figure pictures).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    groups = plot_groups(recording)
    shifts = weight_shifts(recording)
    fig = Figure(figsize=(8, 1.2 + 1.9 * len(groups)), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(groups), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (group, names) in zip(axes, groups.items()):
        _draw(ax, recording, names, shifts, marks)
        ax.set_ylabel(group, fontsize=9)
    axes[-1].set_xlabel("cycle")
    fig.suptitle(_title(recording))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def plot_recording(recording, out_dir) -> list[Path]:
    """Write ``overview.png`` (:func:`plot_overview`) and one PNG per plot group into ``out_dir``.

    Returns the paths written, the overview first.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    out = Path(out_dir)
    paths = [plot_overview(recording, out / "overview.png")]
    shifts = weight_shifts(recording)
    for group, names in plot_groups(recording).items():
        fig = Figure(figsize=(7, 3.2), dpi=100, layout="constrained")
        FigureCanvasAgg(fig)
        ax = fig.subplots()
        _draw(ax, recording, names, shifts)
        ax.set_xlabel("cycle")
        ax.set_ylabel(group)
        ax.set_title(_title(recording), fontsize=10)
        path = out / f"{_file_name(group)}.png"
        fig.savefig(path)
        paths.append(path)
    return paths


def _title(recording) -> str:
    return f"{recording.task_id} · {recording.policy} · seed {recording.seed}"


def _file_name(title: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in title).strip("_") or "plot"

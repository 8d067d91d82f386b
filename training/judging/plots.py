"""Learning curves from the ``progress.csv`` of training runs.

    python -m training.judging.plots runs/sb3_ppo_chain_s0 runs/torchrl_ippo_chain_s0 --out docs/learning/curves.png
    python -m training.judging.plots "MaskablePPO=docs/learning/progress/sb3_ppo_chain_s0.csv" --out curves.png
    python -m training.judging.plots --evolution "evolve=docs/benchmark/v3/learning/progress/evolve_chain_full_s*.csv" --out e.png

One figure: episode return, success rate and cycles per episode against agent-steps, and the
return against wall-clock minutes; each run is a line (smoothed over ``--window`` log rows),
with the hand-coded policy's mean as a dashed reference when ``--reference`` is given.

With ``--evolution`` each argument is ``LABEL=GLOB``, the progress of one evolution recipe's
seeds (training/trainers/evolve.py): the best and the median fitness of each generation against the
programs scored so far, the mean over seeds with a 95 % t band.
"""

from __future__ import annotations

import argparse
import csv
from glob import glob
from pathlib import Path

import numpy as np

from training.judging.statistics import t_quantile


def read_progress(run_dir) -> dict[str, np.ndarray]:
    path = Path(run_dir) if str(run_dir).endswith(".csv") else Path(run_dir) / "progress.csv"
    if not path.is_file():
        raise ValueError(f"{str(path)!r} does not exist; allowed: a run folder written by a script in training/")
    with path.open() as fh:
        rows = list(csv.DictReader(fh))
    return {k: np.array([float(r[k]) if r.get(k) not in ("", None) else np.nan for r in rows]) for k in rows[0]}


def _smooth(y: np.ndarray, window: int) -> np.ndarray:
    out = np.full_like(y, np.nan)
    for i in range(len(y)):
        part = y[max(0, i - window + 1) : i + 1]
        part = part[np.isfinite(part)]
        if part.size:
            out[i] = part.mean()
    return out


def plot_runs(
    runs: dict[str, str], out, *, window: int = 5, reference: dict | None = None, title: str | None = None
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 4, figsize=(17, 3.6))
    panels = [
        ("agent_steps", "episode/return", "return"),
        ("agent_steps", "episode/success", "success rate"),
        ("agent_steps", "episode/cycles", "cycles per episode"),
        ("seconds", "episode/return", "return"),
    ]
    for label, run in runs.items():
        data = read_progress(run)
        for ax, (x, y, _) in zip(axes, panels):
            xs, ys = data[x] / (60.0 if x == "seconds" else 1.0), _smooth(data[y], window)
            shown = np.isfinite(ys)  # log rows in which no episode ended carry no episode measures
            ax.plot(xs[shown], ys[shown], label=label)
    for ax, (x, y, panel_title) in zip(axes, panels):
        if reference and y in reference:
            ax.axhline(reference[y], color="k", ls="--", lw=1, label="hand-coded")
        ax.set_xlabel("wall-clock minutes" if x == "seconds" else "agent-steps")
        ax.set_title(panel_title)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    _save(fig, out, title)


def _save(fig, out, title: str | None) -> None:
    """Title ``fig``, write it to ``out`` (its folder made) and close it."""
    import matplotlib.pyplot as plt

    if title:
        fig.suptitle(title)
    fig.tight_layout()
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def plot_mean_band(ax, x: np.ndarray, ys: np.ndarray, label: str, *, color=None, clip=None) -> None:
    """Plot ``ys`` ``(seeds, points)`` against ``x`` ``(points,)`` as the mean over seeds with a
    95 % Student t band (with two or more seeds), the band cut to ``clip`` ``(low, high)`` if given."""
    colour = {} if color is None else {"color": color}
    mean = ys.mean(axis=0)
    if len(ys) > 1:
        half = t_quantile(len(ys) - 1) * ys.std(axis=0, ddof=1) / np.sqrt(len(ys))
        low, high = mean - half, mean + half
        if clip is not None:
            low, high = np.clip(low, *clip), np.clip(high, *clip)
        ax.fill_between(x, low, high, alpha=0.2, **colour)
    ax.plot(x, mean, label=label, **colour)


def plot_evolution(recipes: dict[str, list[str]], out, *, title: str | None = None) -> None:
    """Best and median fitness per generation against programs scored, the mean over each recipe's
    seeds (its ``progress.csv`` files) with a 95 % t band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=True)
    for colour, (label, paths) in enumerate(recipes.items()):
        runs = [read_progress(path) for path in paths]
        scored = [np.cumsum(run["evolve/candidates"]) for run in runs]
        grid = np.linspace(max(s[0] for s in scored), min(s[-1] for s in scored), 100)
        for ax, column in zip(axes, ("fitness/best", "fitness/median")):
            ys = np.stack([np.interp(grid, s, run[column]) for s, run in zip(scored, runs)])
            plot_mean_band(ax, grid, ys, f"{label} ({len(runs)} seeds)", color=f"C{colour}")
    for ax, panel in zip(axes, ("best fitness of a generation", "median fitness of a generation")):
        ax.set_xlabel("programs scored")
        ax.set_title(panel)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("fitness (mean episode score - complexity penalty)")
    axes[0].legend(fontsize=8)
    _save(fig, out, title)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "runs", nargs="+", help="run folders (label=folder to name a line), or LABEL=GLOB with --evolution"
    )
    parser.add_argument("--evolution", action="store_true", help="fitness curves of evolution recipes, mean over seeds")
    parser.add_argument("--out", default="out/learning_curves.png")
    parser.add_argument("--window", type=int, default=5)
    parser.add_argument("--reference", default=None, help="hand-coded means, e.g. 'return=1.6,success=1,cycles=91'")
    parser.add_argument("--title", default=None, help="figure title (the task and its size, for example)")
    args = parser.parse_args(argv)
    if args.evolution:
        groups = dict(r.split("=", 1) for r in args.runs)
        recipes = {label: sorted(glob(pattern)) for label, pattern in groups.items()}
        for label, paths in recipes.items():
            if not paths:
                raise ValueError(f"{label}={groups[label]!r} matches no file; allowed: a glob of progress.csv files")
        plot_evolution(recipes, args.out, title=args.title)
        print(args.out)
        return 0
    runs = dict(r.split("=", 1) if "=" in r else (Path(r).name, r) for r in args.runs)
    reference = None
    if args.reference:
        reference = {f"episode/{k}": float(v) for k, v in (p.split("=") for p in args.reference.split(","))}
    plot_runs(runs, args.out, window=args.window, reference=reference, title=args.title)
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

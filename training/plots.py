"""Learning curves from the ``progress.csv`` of training runs.

    python -m training.plots runs/sb3_ppo_chain_s0 runs/torchrl_ippo_chain_s0 --out docs/learning/curves.png
    python -m training.plots "MaskablePPO=docs/learning/progress/sb3_ppo_chain_s0.csv" --out curves.png

One figure: episode return, success rate and cycles per episode against agent-steps, and the
return against wall-clock minutes; each run is a line (smoothed over ``--window`` log rows),
with the hand-coded policy's mean as a dashed reference when ``--reference`` is given.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np


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
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="run folders (label=folder to name a line)")
    parser.add_argument("--out", default="out/learning_curves.png")
    parser.add_argument("--window", type=int, default=5)
    parser.add_argument("--reference", default=None, help="hand-coded means, e.g. 'return=1.6,success=1,cycles=91'")
    parser.add_argument("--title", default=None, help="figure title (the task and its size, for example)")
    args = parser.parse_args(argv)
    runs = dict(r.split("=", 1) if "=" in r else (Path(r).name, r) for r in args.runs)
    reference = None
    if args.reference:
        reference = {f"episode/{k}": float(v) for k, v in (p.split("=") for p in args.reference.split(","))}
    plot_runs(runs, args.out, window=args.window, reference=reference, title=args.title)
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

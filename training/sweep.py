"""``proteo sweep CONFIG.yaml``: one task over a grid of settings, policies and seeds; a tidy table and a plot.

A sweep config (YAML, every key checked; see ``configs/sweeps/``)::

    task: chain-v1
    env: {max_cycles: 2000}             # fixed overrides of proteo_env.make
    grid:                               # one list of values per setting: the grid is their product
      n_modules: [10, 20, 40]
      motion_model: [minimal, sphere]
      p_max=p_min: [0.02, 0.05]         # "a=b": one value sets both (tied settings)
    policies: [default, random]         # registered policy names; default: the task's hand-coded one
    seeds: 5                            # episodes per point and policy: first_seed .. first_seed + seeds - 1
    first_seed: 0
    search: grid                        # or random: `samples` points drawn from the grid (sample_seed)
    samples: 0
    sample_seed: 0
    plot: {x: n_modules, y: cycles_to_success, hue: motion_model}

The episodes run in batches of worlds (:func:`training.machinery.evaluator.run_episodes`: on ``--workers``
local processes, default every core, or as Ray tasks with ``--ray``; the same results either way),
journaled in ``OUT/episodes.jsonl`` as each batch lands so that an interrupted sweep resumes. Every point of the grid is checked (an environment is
built) before any episode runs. Written into ``--out`` when every episode has finished:

- ``episodes.csv``: one row per episode: the grid's settings, ``policy``, ``seed``, ``return``,
  ``success``, ``cycles``, ``cycles_to_success`` (empty without success) and the task's metrics;
- ``summary.csv``: one row per point and policy: ``episodes``, ``success_rate``, ``return_mean``,
  ``return_ci`` and, for the plotted ``y``, ``y_mean``, ``y_ci`` (95 % t half-width) and ``y_n``
  (episodes where ``y`` is known: a negative metric such as ``restabilise_k = -1`` or an empty
  ``cycles_to_success`` means "never reached" and is left out of the mean);
- ``sweep.png``: ``y`` against ``x``, one line per ``hue`` (and policy when there are several).
"""

from __future__ import annotations

import csv
import itertools
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import proteo_env
from baselines import POLICIES
from proteo_env.config import ConfigError, build, load_yaml
from proteo_env.registry import task_class
from training.judging.statistics import mean_ci
from training.machinery.distributed import Journal, ray_options
from training.machinery.evaluator import Controller, Episode, run_episodes, settings_json
from training.machinery.runs import out_folder


@dataclass(frozen=True)
class SweepConfig:
    """A sweep (see the module docstring)."""

    task: str
    grid: dict
    env: dict = field(default_factory=dict)
    policies: tuple[str, ...] = ("default",)
    seeds: int = 5
    first_seed: int = 0
    search: str = "grid"
    samples: int = 0
    sample_seed: int = 0
    plot: dict = field(default_factory=dict)

    def points(self) -> list[dict]:
        """The settings of every point to run (``search: random`` draws ``samples`` of them)."""
        keys = list(self.grid)
        product = [dict(zip(keys, values)) for values in itertools.product(*(self.grid[k] for k in keys))]
        if self.search == "random":
            rng = np.random.default_rng(self.sample_seed)
            product = [product[i] for i in sorted(rng.choice(len(product), size=self.samples, replace=False))]
        return product


def overrides_of(point: dict) -> dict:
    """The ``proteo_env.make`` overrides of a point: a tied key ``"a=b"`` sets ``a`` and ``b``."""
    out = {}
    for key, value in point.items():
        for name in key.split("="):
            out[name.strip()] = value
    return out


def load_sweep(path) -> SweepConfig:
    """The checked :class:`SweepConfig` in ``path``; any problem is one :class:`ConfigError`
    naming the field, its value and what is allowed."""
    p = Path(path)
    data = load_yaml(p, "sweep config", "a YAML file such as configs/sweeps/chain_cycles.yaml")
    if not isinstance(data, dict):
        raise ConfigError(
            f"sweep config {str(p)!r}: a mapping of keys is required; allowed keys: "
            "task, grid, env, policies, seeds, first_seed, search, samples, sample_seed, plot"
        )
    where = f"sweep config {str(p)!r}: "
    for key in ("task", "grid"):
        if key not in data:
            raise ConfigError(
                f"{where}{key!r} is missing; allowed: a {'task id' if key == 'task' else 'mapping of setting: [values]'}"
            )
    cfg = build(SweepConfig, data, where=where)
    task_class(cfg.task)  # an unknown task lists the registered ones
    if not isinstance(cfg.grid, dict) or not cfg.grid:
        raise ConfigError(
            f"{where}grid={cfg.grid!r} is empty; allowed: a mapping of setting: [value, ...] with at least one setting"
        )
    for key, values in cfg.grid.items():
        if not isinstance(values, list) or not values:
            raise ConfigError(f"{where}grid.{key}={values!r} is not allowed; allowed: a non-empty list of values")
        clash = set(overrides_of({key: 0})) & set(cfg.env)
        if clash:
            raise ConfigError(
                f"{where}grid.{key} and env.{sorted(clash)[0]} both set {sorted(clash)[0]!r}; allowed: "
                "each setting in one of them"
            )
    if cfg.search not in ("grid", "random"):
        raise ConfigError(f"{where}search={cfg.search!r} is not allowed; allowed: grid, random")
    size = int(np.prod([len(v) for v in cfg.grid.values()]))
    if cfg.search == "random" and not 1 <= cfg.samples <= size:
        raise ConfigError(
            f"{where}samples={cfg.samples!r} is not allowed with search: random; allowed: 1..{size} (the grid's points)"
        )
    if cfg.seeds < 1:
        raise ConfigError(f"{where}seeds={cfg.seeds!r} is not allowed; allowed: an integer >= 1")
    if not cfg.policies:
        raise ConfigError(f"{where}policies=[] is empty; allowed: registered policy names or 'default'")

    for name in cfg.policies:
        if name != "default" and name not in POLICIES:
            raise ConfigError(
                f"{where}policies: {name!r} is not allowed; allowed: default, {', '.join(sorted(POLICIES))}"
            )
    bad = sorted(set(cfg.plot) - {"x", "y", "hue"})
    if bad:
        raise ConfigError(f"{where}plot.{bad[0]} is not allowed; allowed: x, y, hue")
    for axis in ("x", "hue"):
        if axis in cfg.plot and cfg.plot[axis] not in (*cfg.grid, "policy"):
            raise ConfigError(
                f"{where}plot.{axis}={cfg.plot[axis]!r} is not allowed; allowed: {', '.join([*cfg.grid, 'policy'])}"
            )
    return cfg


def sweep(
    config, *, out, ray: dict | None = None, workers: int | None = None, progress: bool = True, fresh: bool = False
) -> list[dict]:
    """Run the sweep in ``config`` (a path) and write its tables and plot into ``out``.

    Returns:
        the rows of ``summary.csv`` (one dict per point and policy).
    """
    cfg = load_sweep(config)
    points = cfg.points()
    seeds = list(range(cfg.first_seed, cfg.first_seed + cfg.seeds))
    jobs: list[tuple[dict, str, Episode]] = []
    for point in points:
        overrides = {**cfg.env, **overrides_of(point)}
        try:
            env = proteo_env.make(cfg.task, **overrides)  # every point is checked before any episode runs
        except ConfigError as err:
            raise ConfigError(f"sweep config {str(config)!r}: grid point {point}: {err}") from None
        policies = [env.task.default_policy if name == "default" else name for name in cfg.policies]
        env.close()
        settings = settings_json(overrides)
        for policy in dict.fromkeys(policies):
            jobs += [(point, policy, Episode(cfg.task, settings, "full", Controller.rules(policy), s)) for s in seeds]
    out = out_folder(out)
    fingerprint = {"config": json.loads(json.dumps(cfg.__dict__, default=list)), "jobs": len(jobs)}
    journal = Journal(out / "episodes.jsonl", fingerprint, fresh=fresh, what="sweep")
    episodes = run_episodes(
        [e for _, _, e in jobs], ray=ray, workers=workers, journal=journal, desc="episodes", progress=progress
    )

    rows = []
    for (point, policy, episode), e in zip(jobs, episodes):
        rows.append(
            {
                **point,
                "policy": policy,
                "seed": episode.seed,
                "return": float(e.total_reward),
                "success": int(e.success),
                "cycles": int(e.cycles),
                "cycles_to_success": int(e.cycles) if e.success else "",
                **{k: float(v) for k, v in e.metrics.items()},
            }
        )
    y = cfg.plot.get("y", "cycles_to_success")
    if y not in rows[0]:
        raise ConfigError(
            f"sweep config {str(config)!r}: plot.y={y!r} is not allowed; allowed: "
            f"{', '.join(k for k in rows[0] if k not in (*cfg.grid, 'policy', 'seed'))}"
        )
    summary = []
    for point in points:
        for policy in dict.fromkeys(r["policy"] for r in rows):
            mine = [r for r in rows if r["policy"] == policy and all(r[k] == v for k, v in point.items())]
            if not mine:
                continue
            ret, ret_ci = mean_ci([r["return"] for r in mine])
            known = [float(r[y]) for r in mine if r[y] != "" and float(r[y]) >= 0]
            y_mean, y_ci = mean_ci(known)
            summary.append(
                {
                    **point,
                    "policy": policy,
                    "episodes": len(mine),
                    "success_rate": float(np.mean([r["success"] for r in mine])),
                    "return_mean": ret,
                    "return_ci": ret_ci,
                    "y": y,
                    "y_mean": y_mean,
                    "y_ci": y_ci,
                    "y_n": len(known),
                }
            )
    out.mkdir(parents=True, exist_ok=True)
    _write_csv(out / "episodes.csv", rows)
    _write_csv(out / "summary.csv", summary)
    if "x" in cfg.plot:
        plot_sweep(summary, cfg, out / "sweep.png", title=f"{cfg.task}: {y} ({cfg.seeds} seeds per point)")
    journal.complete()
    return summary


def _write_csv(path: Path, rows: list[dict]) -> None:
    columns = list(dict.fromkeys(k for r in rows for k in r))
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns)
        writer.writeheader()
        writer.writerows([{k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()} for r in rows])


def plot_sweep(summary: list[dict], cfg: SweepConfig, path: Path, *, title: str) -> None:
    """``y_mean ± y_ci`` against ``plot.x``, one line per ``plot.hue`` value (and policy); each
    point labelled with ``y_n/episodes`` (how many episodes reached ``y``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x, hue = cfg.plot["x"], cfg.plot.get("hue")
    several = len({r["policy"] for r in summary}) > 1
    lines: dict = {}
    for r in summary:
        label = " / ".join(str(v) for v in ((r[hue],) if hue else ()) + ((r["policy"],) if several else ()))
        lines.setdefault(label or r["policy"], []).append(r)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for label, rs in lines.items():
        rs = sorted(rs, key=lambda r: r[x])
        xs = [r[x] for r in rs]
        ys = [r["y_mean"] for r in rs]
        err = [0.0 if not np.isfinite(r["y_ci"]) else r["y_ci"] for r in rs]
        ax.errorbar(xs, ys, yerr=err, marker="o", capsize=3, label=label)
        for xv, yv, r in zip(xs, ys, rs):
            if np.isfinite(yv):
                ax.annotate(
                    f"{r['y_n']}/{r['episodes']}", (xv, yv), textcoords="offset points", xytext=(4, 4), fontsize=7
                )
    ax.set_xlabel(x)
    ax.set_ylabel(f"{summary[0]['y']} (mean ± 95 % CI over the episodes that reached it)")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(title=hue, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(args) -> int:
    """Entry point of ``proteo sweep`` (arguments parsed in :mod:`training.cli`)."""
    out = args.out or str(Path("out/sweeps") / Path(args.config).stem)
    summary = sweep(
        args.config, out=out, ray=ray_options(args), workers=None if args.ray else args.workers, fresh=args.fresh
    )
    print(f"{len(summary)} rows; tables: {Path(out).resolve()}/summary.csv, episodes.csv")
    return 0

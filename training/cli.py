"""The ``proteo`` command line.

``proteo demo`` (the main job), ``proteo run TASK|CONFIG`` (run, record, render, plot),
``proteo replay FILE`` (movie, still or plots of a recorded episode), ``proteo view FILE`` (an
interactive 3D page of a recorded episode), ``proteo figures`` (the paper's figures into
``docs/figures``), ``proteo eval`` (the comparison table), ``proteo sweep CONFIG`` (a grid
of settings, policies and seeds) and ``proteo train TRAINER [flags]`` (a trainer of
``training/``, the flags passed on unchanged). ``proteo --version`` prints the version.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

STILL_SUFFIXES = (".png", ".jpg", ".jpeg", ".svg", ".pdf")


def _run(
    task_id: str,
    overrides: dict,
    policy_name: str | None,
    seed: int,
    out: Path | None,
    *,
    record: Path | None = None,
    movie: Path | None = None,
    plots: Path | None = None,
    camera=None,
    fps: float = 20.0,
    max_frames: int | None = 300,
    view: Path | None = None,
    program: str | None = None,
):
    from tqdm import tqdm

    from baselines import make_policy
    from proteo_env import make
    from proteo_env.recording import Recorder
    from proteo_env.rollout import run_episode

    env = make(task_id, **overrides)
    if program is not None:
        policy = make_policy("program", env, seed=seed, program=program)
    else:
        policy = make_policy(policy_name or env.task.default_policy, env, seed=seed)
    label = f"{env.task.task_id()} / {policy.name}"
    wants_recording = any(x is not None for x in (out, record, movie, plots, view))
    recorder = (
        Recorder(env, task_id=env.task.task_id(), overrides=overrides, seed=seed, policy=policy.name)
        if wants_recording
        else None
    )
    # numba compiles the kernels during the reset and the first cycle (once per machine: the
    # cache is on disk); the bar says so, then restarts its clock so its estimate is the cycles'
    with tqdm(total=env.max_cycles, desc=f"{label}: compiling (first run only)", unit="cycle", leave=False) as bar:
        compiling = True

        def progress(info) -> None:
            nonlocal compiling
            if compiling:  # the first cycle is done, so is the compiling
                compiling = False
                bar.set_description(label)
                bar.reset()
            bar.update(1)

        started = time.perf_counter()
        result = run_episode(env, policy, seed=seed, progress=progress, observe=recorder)
        seconds = time.perf_counter() - started
    if recorder is not None:
        recording = recorder.recording(success=result.success)
        _outputs(
            recording,
            label=label,
            out=out,
            record=record,
            movie=movie,
            plots=plots,
            camera=camera,
            fps=fps,
            max_frames=max_frames,
            view=view,
        )
    return {
        "task": env.task.task_id(),
        "policy": policy.name,
        "modules": env.engine.n_modules,
        "cycles": result.cycles,
        "success": result.success,
        "reward": result.total_reward,
        "seconds": seconds,
        "metrics": result.metrics,
    }


def _outputs(
    recording,
    *,
    label: str,
    out=None,
    record=None,
    movie=None,
    plots=None,
    camera=None,
    fps=20.0,
    max_frames=300,
    still=None,
    still_frame=-1,
    view=None,
) -> None:
    """Write what was asked for from a recording: the file, demo pictures, a movie, a still, plots, a viewer page."""
    if record is not None:
        recording.save(record)
    if view is not None:
        from proteo_env.render.webview import write_html

        write_html(recording, view)
    if out is not None:
        from proteo_env.render.replay import render_still

        name = recording.task_id.rsplit("-v", 1)[0]
        render_still(recording, out / f"{name}_start.png", frame=0, camera=camera, caption=f"{label}: start")
        end = f"{label}: cycle {int(recording.cycles[-1])}{' (success)' if recording.success else ''}"
        render_still(recording, out / f"{name}_end.png", frame=-1, camera=camera, caption=end)
        plots = plots if plots is not None else out / f"{name}_plots"
    if movie is not None:
        from tqdm import tqdm

        from proteo_env.render.replay import frame_indices, render_movie

        total = len(frame_indices(recording.n_frames, max_frames))
        with tqdm(total=total, desc=f"rendering {movie.name}", unit="frame", leave=False) as bar:
            render_movie(
                recording, movie, camera=camera, fps=fps, max_frames=max_frames, progress=lambda: bar.update(1)
            )
    if still is not None:
        from proteo_env.render.replay import render_still

        render_still(recording, still, frame=still_frame, camera=camera)
    if plots is not None:
        from proteo_env.render.plots import plot_recording

        plot_recording(recording, plots)


def _table(rows: list[dict]) -> str:
    head = ["task", "policy", "modules", "cycles", "success", "reward", "seconds", "metrics"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        metrics = ", ".join(f"{k}={v:g}" for k, v in r["metrics"].items())
        lines.append(
            f"| {r['task']} | {r['policy']} | {r['modules']} | {r['cycles']} | "
            f"{'yes' if r['success'] else 'no'} | {r['reward']:.3f} | {r['seconds']:.1f} | {metrics} |"
        )
    return "\n".join(lines)


def demo(args) -> int:
    from proteo_env.registry import newest_tasks

    out = Path(args.out)
    rows = []
    for task_id, cls in sorted(newest_tasks().items()):
        overrides = dict(cls.demo_settings)
        if args.motion_model:
            overrides["motion_model"] = args.motion_model
        rows.append(_run(task_id, overrides, None, args.seed, out))
    print(_table(rows))
    print(f"\npictures and plots: {out.resolve()}")
    return 0


# ---------------------------------------------------------------------- run
def _parse_sets(items) -> dict:
    """``["KEY=VALUE", ...]`` to a dict; values are read as YAML scalars (``40``, ``true``, ``sphere``)."""
    import yaml

    overrides = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"--set {item!r} is not allowed; allowed: KEY=VALUE, e.g. --set n_modules=40")
        overrides[key.strip()] = yaml.safe_load(value) if value.strip() else ""
    return overrides


def _resolve_target(target: str, sets) -> tuple[str, dict]:
    """A task id or a YAML config path to ``(task_id, overrides)``, with ``--set`` overrides applied."""
    from proteo_env.config import ConfigError, load_run_config
    from proteo_env.registry import task_class

    path = Path(target)
    if path.suffix in (".yaml", ".yml") or path.is_file():
        task_id, overrides = load_run_config(path)
    else:
        try:
            task_id, overrides = task_class(target).task_id(), {}
        except ConfigError as err:
            raise ConfigError(f"{err}, or a path to a YAML config (see configs/)") from None
    return task_id, {**overrides, **_parse_sets(sets)}


def _per_episode(path, seed: int, many: bool) -> Path | None:
    """``path`` itself, or with ``-seed<N>`` before its suffix when several episodes run."""
    if path is None:
        return None
    path = Path(path)
    return path.with_name(f"{path.stem}-seed{seed}{path.suffix}") if many else path


def _camera(args) -> dict | None:
    """Camera settings given on the command line (checked by the renderer's Camera)."""
    camera = {k: getattr(args, k) for k in ("azimuth", "elevation", "zoom", "follow") if getattr(args, k) is not None}
    if args.size is not None:
        width, sep, height = args.size.lower().partition("x")
        if not (sep and width.isdigit() and height.isdigit()):
            raise ValueError(f"--size {args.size!r} is not allowed; allowed: WIDTHxHEIGHT in pixels, e.g. 800x600")
        camera.update(width=int(width), height=int(height))
    if camera:
        from proteo_env.render.camera import Camera

        Camera.from_options(camera)  # bad settings fail now, before the episode runs
    return camera or None


def _check_paths(record=None, movie=None, view=None) -> None:
    if record is not None and Path(record).suffix != ".npz":
        raise ValueError(f"--record {str(record)!r} is not allowed; allowed: a file name ending in .npz")
    if view is not None and Path(view).suffix.lower() not in (".html", ".htm"):
        raise ValueError(f"--view {str(view)!r} is not allowed; allowed: a file name ending in .html")
    if movie is not None:
        from proteo_env.render.movie import check_movie_path

        check_movie_path(movie)


def run(args) -> int:
    task_id, overrides = _resolve_target(args.target, args.set)
    _check_paths(args.record, args.render, args.view)
    camera = _camera(args)
    many = args.episodes > 1
    rows = []
    for seed in range(args.seed, args.seed + args.episodes):
        rows.append(
            _run(
                task_id,
                overrides,
                args.policy,
                seed,
                Path(args.out) if args.out else None,
                record=_per_episode(args.record, seed, many),
                movie=_per_episode(args.render, seed, many),
                plots=_per_episode(args.plots, seed, many),
                camera=camera,
                fps=args.fps,
                max_frames=args.max_frames,
                view=_per_episode(args.view, seed, many),
                program=args.program,
            )
        )
    print(_table(rows))
    successes = sum(r["success"] for r in rows)
    print(f"\nsuccess {successes}/{len(rows)}")
    for what, path in (
        ("recording", args.record),
        ("movie", args.render),
        ("plots", args.plots),
        ("viewer page", args.view),
    ):
        if path is not None:
            print(f"{what}: {path}" + (" (one per seed: -seed<N>)" if many else ""))
    return 0


# ---------------------------------------------------------------------- replay
def replay(args) -> int:
    from proteo_env import __version__
    from proteo_env.recording import load

    if args.out is None and args.plots is None:
        raise ValueError(
            "replay needs --out (a .gif/.mp4 movie or a .png still) or --plots DIR; allowed: either or both"
        )
    movie = still = None
    if args.out is not None:
        suffix = Path(args.out).suffix.lower()
        if suffix in STILL_SUFFIXES:
            still = Path(args.out)
        else:
            _check_paths(movie=args.out)
            movie = Path(args.out)
    camera = _camera(args)
    recording = load(args.file)
    frame = -1
    if args.cycle is not None:
        hits = (recording.cycles == args.cycle).nonzero()[0]
        if not len(hits):
            raise ValueError(
                f"--cycle {args.cycle} is not in the recording; allowed: "
                f"{int(recording.cycles[0])}..{int(recording.cycles[-1])}"
            )
        frame = int(hits[0])
    print(
        f"{args.file}: {recording.task_id} / {recording.policy}, seed {recording.seed}, "
        f"{recording.positions.shape[1]} modules, {int(recording.cycles[-1])} cycles, "
        f"{'success' if recording.success else 'no success'}, written by proteo {recording.package_version}"
        + ("" if recording.package_version == __version__ else f" (this is {__version__})")
    )
    _outputs(
        recording,
        label=recording.task_id,
        movie=movie,
        plots=Path(args.plots) if args.plots else None,
        camera=camera,
        fps=args.fps,
        max_frames=args.max_frames,
        still=still,
        still_frame=frame,
    )
    for what, path in (("movie", movie), ("picture", still), ("plots", args.plots)):
        if path is not None:
            print(f"{what}: {path}")
    return 0


def view(args) -> int:
    from proteo_env.recording import load
    from proteo_env.render.webview import write_html

    out = Path(args.out) if args.out else Path(args.file).with_suffix(".html")
    _check_paths(view=out)
    recording = load(args.file)
    write_html(recording, out)
    print(
        f"viewer page: {out} ({out.stat().st_size / 1e6:.1f} MB; {recording.positions.shape[1]} modules, "
        f"{recording.n_frames} frames): open it in a browser, no network needed"
    )
    if args.screenshot:
        from proteo_env.render.browser import Chromium

        width, sep, height = args.size.lower().partition("x")
        if not (sep and width.isdigit() and height.isdigit()):
            raise ValueError(f"--size {args.size!r} is not allowed; allowed: WIDTHxHEIGHT in pixels, e.g. 1200x800")
        with Chromium(width=int(width), height=int(height)) as browser:
            browser.open(out.resolve().as_uri() + (f"#cycle={args.cycle}" if args.cycle is not None else "#frame=-1"))
            browser.evaluate(
                "new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))", await_promise=True
            )
            problems = browser.errors() + (
                [browser.evaluate("document.body.dataset.error")]
                if browser.evaluate("document.body.dataset.errors") != "0"
                else []
            )
            if problems:
                raise RuntimeError(f"the viewer page reported errors: {problems}")
            browser.screenshot(args.screenshot)
        print(f"screenshot: {args.screenshot}")
    return 0


def evaluate(args) -> int:
    from training import benchmark
    from training.evaluate import main as evaluate_main

    if args.benchmark:
        return benchmark.main(args)
    benchmark.check_flags(args)
    return evaluate_main(args)


def sweep(args) -> int:
    from training.sweep import main as sweep_main

    return sweep_main(args)


TRAINERS = {
    "ppo": "native PPO over the array API (training/ppo.py)",
    "imitate": "clone the rules: behaviour cloning + DAgger (training/imitate.py)",
    "cma_es": "CMA-ES on the rules' parameters or a small network (training/cma_es.py)",
    "evolve": "evolution of programs of the paper's primitives (training/evolve.py)",
    "sb3_ppo": "MaskablePPO, Stable-Baselines3 (training/sb3_ppo.py)",
    "torchrl_ppo": "IPPO / MAPPO, TorchRL (training/torchrl_ppo.py)",
    "rllib_ppo": "RLlib's PPO (training/rllib_ppo.py; the distributed extra)",
    "study": "recipes x tasks x seeds, kept in checkpoints/ (training/study.py)",
}
"""The trainers ``proteo train`` runs: the ``training.<name>`` modules with a ``main(argv)``."""


def train(args) -> int:
    """``proteo train NAME FLAGS...``: ``python -m training.NAME FLAGS...`` (the flags unchanged)."""
    import importlib

    name = args.trainer.replace("-", "_")
    if name not in TRAINERS:
        raise ValueError(f"trainer {args.trainer!r} is not allowed; allowed: {', '.join(TRAINERS)}")
    flags = list(args.flags)
    if flags[:1] == ["--"]:
        flags = flags[1:]
    module = importlib.import_module(f"training.{name}")
    program = sys.argv[0]
    sys.argv[0] = f"proteo train {name}"  # the trainer's usage and messages name the command that ran it
    try:
        result = module.main(flags)
    finally:
        sys.argv[0] = program
    if isinstance(result, int):
        return result
    if result is not None:
        print(f"checkpoint: {result}")
    return 0


def version() -> str:
    from training.common import package_version

    return package_version()


def figures(args) -> int:
    from baselines.figures import make_figures

    make_figures(Path(args.out), seed=args.seed, only=args.only, redraw=args.redraw)
    return 0


# ---------------------------------------------------------------------- parser
def _picture_args(p, *, movie_default_frames: int = 300) -> None:
    g = p.add_argument_group("pictures")
    g.add_argument("--azimuth", type=float, default=None, help="camera azimuth in degrees (default -50)")
    g.add_argument(
        "--elevation",
        type=float,
        default=None,
        help="camera elevation in degrees (default 28; negative looks from underneath)",
    )
    g.add_argument("--zoom", type=float, default=None, help="magnification (default 1: fit)")
    g.add_argument(
        "--follow",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="frame the modules of each frame instead of the whole episode",
    )
    g.add_argument("--size", default=None, help="image size WIDTHxHEIGHT (default 800x600)")
    g.add_argument("--fps", type=float, default=20.0, help="movie frames per second (default 20)")
    g.add_argument(
        "--max-frames",
        type=int,
        default=movie_default_frames,
        help=f"movie frames at most, spread over the episode (default {movie_default_frames})",
    )
    g.add_argument("--plots", default=None, help="folder for the PNG plots of the metrics against cycles")


def main(argv=None) -> int:
    from training.distributed import add_ray_flags

    parser = argparse.ArgumentParser(prog="proteo", description="Proteo lattice robot simulator")
    parser.add_argument("--version", action="version", version=f"proteo {version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("demo", help="run every registered task with its default policy")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="out/demo", help="folder for the pictures and plots")
    p.add_argument("--motion-model", default=None, help="override the motion model of every task")
    p.set_defaults(func=demo)

    p = sub.add_parser("run", help="run a task (or a YAML config); record, render and plot it")
    p.add_argument("target", help="a registered task id (e.g. chain-v0) or a path to a YAML run config")
    p.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="override a setting (repeatable), e.g. --set n_modules=40 --set max_cycles=3000",
    )
    p.add_argument("--policy", default=None, help="policy name (default: the task's hand-coded one)")
    p.add_argument(
        "--program", default=None, help="run a program of the paper's primitives: a YAML file or a name such as chain"
    )
    p.add_argument("--seed", type=int, default=0, help="first seed")
    p.add_argument("--episodes", type=int, default=1)
    p.add_argument("--out", default=None, help="folder for start and end pictures (none if omitted)")
    p.add_argument("--record", default=None, help="write the episode to this .npz file")
    p.add_argument("--render", default=None, help="write a movie of the episode (.gif or .mp4)")
    p.add_argument("--view", default=None, help="write an interactive 3D viewer page of the episode (.html)")
    _picture_args(p)
    p.set_defaults(func=run)

    p = sub.add_parser("replay", help="movie, picture or plots of a recorded episode")
    p.add_argument("file", help="a recording written by proteo run --record")
    p.add_argument("--out", default=None, help="movie (.gif, .mp4) or picture (.png, .jpg, .svg, .pdf)")
    p.add_argument("--cycle", type=int, default=None, help="cycle drawn in a picture (default: the last)")
    _picture_args(p)
    p.set_defaults(func=replay)

    p = sub.add_parser("view", help="an interactive 3D page (one offline .html file) of a recorded episode")
    p.add_argument("file", help="a recording written by proteo run --record")
    p.add_argument("--out", default=None, help="the page to write (default: the recording's name with .html)")
    p.add_argument("--screenshot", default=None, help="also write a PNG of the page (needs headless Chromium)")
    p.add_argument("--cycle", type=int, default=None, help="cycle shown in the screenshot (default: the last)")
    p.add_argument("--size", default="1200x800", help="screenshot size WIDTHxHEIGHT (default 1200x800)")
    p.set_defaults(func=view)

    p = sub.add_parser("figures", help="reproduce the paper's figures (pictures and plots) into docs/figures")
    p.add_argument("--out", default="docs/figures")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--only", action="append", default=None, help="only this figure (repeatable): chain, branch, table, grasp"
    )
    p.add_argument("--redraw", action="store_true", help="draw again from the recordings in --out (no episodes run)")
    p.set_defaults(func=figures)

    p = sub.add_parser("eval", help="compare hand-coded, random, learned and evolved policies over seeds")
    p.add_argument(
        "--config",
        default=None,
        help="per-task settings and checkpoints (YAML; default: configs/eval.yaml when it exists)",
    )
    p.add_argument("--tasks", default=None, help="comma-separated task names (default: every task with a reward)")
    p.add_argument("--seeds", type=int, default=None, help="episodes per policy (default: the config's)")
    p.add_argument("--checkpoint", action="append", default=None, help="a checkpoint to add (repeatable)")
    p.add_argument("--out", default="out/eval", help="folder for results.md, results.json and eval.png")
    p.add_argument("--deterministic", action="store_true", help="neural policies take arg-max actions")
    p.add_argument("--no-plots", action="store_true")
    p.add_argument(
        "--publish",
        action="append",
        default=None,
        metavar="FILE.md",
        help="also put the table into this markdown file, between its '<!-- proteo eval --out OUT -->' "
        "and '<!-- end of proteo eval table -->' markers (repeatable)",
    )
    p.add_argument(
        "--pictures",
        action="store_true",
        help="draw the end of each policy's first episode into OUT/pictures/ (what it builds)",
    )
    p.add_argument(
        "--fresh", action="store_true", help="discard the episodes of an interrupted run in --out (default: resume it)"
    )
    p.add_argument(
        "--from-results",
        default=None,
        metavar="RESULTS.json",
        help="run no episode: write the tables of this results.json into --out again (and --publish them)",
    )
    b = p.add_argument_group("benchmark protocol (docs/guides/benchmark.md)")
    b.add_argument(
        "--benchmark",
        default=None,
        metavar="VERSION",
        help="judge --checkpoint (one recipe's training seeds) or --policy on every split of "
        "configs/benchmark/VERSION.yaml; writes OUT/benchmark.json and benchmark.md",
    )
    b.add_argument("--policy", default=None, help="with --benchmark: rules or random (every task, or --tasks)")
    b.add_argument("--level", default=None, help="with --benchmark --policy: only this control level")
    b.add_argument(
        "--worlds-cap",
        type=int,
        default=None,
        metavar="N",
        help="with --benchmark: at most N worlds per split (quick checks only; the result is marked incomplete)",
    )
    add_ray_flags(p)
    p.set_defaults(func=evaluate)

    p = sub.add_parser("sweep", help="a task over a grid of settings, policies and seeds: tidy tables and a plot")
    p.add_argument("config", help="a sweep config (YAML; see configs/sweeps/)")
    p.add_argument(
        "--out",
        default=None,
        help="folder for episodes.csv, summary.csv and sweep.png (default: out/sweeps/<config name>)",
    )
    p.add_argument(
        "--fresh",
        action="store_true",
        help="discard the episodes of an interrupted sweep in --out (default: resume it)",
    )
    add_ray_flags(p)
    p.set_defaults(func=sweep)

    p = sub.add_parser(
        "train",
        help="train a controller: proteo train TRAINER [flags] runs python -m training.TRAINER [flags]",
        description="Run a trainer of training/ with the flags that follow, unchanged "
        "(see docs/guides/training.md; 'proteo train ppo --help' lists ppo's). Trainers: "
        + "; ".join(f"{name}: {what}" for name, what in TRAINERS.items()),
    )
    p.add_argument("trainer", metavar="TRAINER", help=f"one of {', '.join(TRAINERS)}")
    p.add_argument("flags", nargs=argparse.REMAINDER, help="the trainer's flags, e.g. --config FILE.yaml")
    p.set_defaults(func=train)
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ValueError as err:
        print(f"proteo: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

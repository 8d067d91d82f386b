"""Run episodes and show them: the code of ``proteo demo``, ``proteo run``, ``proteo replay`` and
``proteo view`` (:mod:`training.cli` parses their flags).

``demo`` runs the paper's behaviours with progress bars, a summary table and pictures; ``run``
runs any task with any policy, program or settings and records, renders, plots or writes the
viewer page of each episode; ``replay`` makes a movie, a still or plots of a recorded episode;
``view`` writes the self-contained 3D page of one (and optionally its screenshot).
"""

from __future__ import annotations

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
    from proteo_env.config import parse_yaml

    overrides = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"--set {item!r} is not allowed; allowed: KEY=VALUE, e.g. --set n_modules=40")
        overrides[key.strip()] = parse_yaml(value, f"--set {item!r}") if value.strip() else ""
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
    if args.cycle is not None and not args.screenshot:
        raise ValueError(
            f"--cycle {args.cycle} without --screenshot is not allowed; allowed: --cycle with --screenshot (the "
            "page itself has a slider over every cycle)"
        )
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

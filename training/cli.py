"""The ``proteo`` command line: it parses, and the commands' code lives with what they do
(:mod:`training.playback` for ``demo``, ``run``, ``replay`` and ``view``).

``proteo demo`` (the main job), ``proteo run TASK|CONFIG`` (run, record, render, plot),
``proteo replay FILE`` (movie, still or plots of a recorded episode), ``proteo view FILE`` (an
interactive 3D page of a recorded episode), ``proteo figures`` (the paper's figures into
``docs/figures``), ``proteo eval`` (the comparison table), ``proteo sweep CONFIG`` (a grid
of settings, policies and seeds) and ``proteo train TRAINER [flags]`` (a trainer of
``training/``, the flags passed on unchanged), ``proteo migrate PATH`` (version-1 checkpoints to
version 2). ``proteo --version`` prints the version.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

from training.machinery.registry import TRAINERS, trainer
from training.playback import demo, replay, run, view


def evaluate_command(args) -> int:
    from training.judging import judge
    from training.judging.evaluate import main as evaluate_main

    if args.benchmark:
        return judge.main(args)
    judge.check_flags(args)
    return evaluate_main(args)


def sweep_command(args) -> int:
    from training.sweep import main as sweep_main

    return sweep_main(args)


def train_command(args) -> int:
    """``proteo train NAME FLAGS...``: the registered trainer's ``main(FLAGS)`` (the flags unchanged)."""
    entry = trainer(args.trainer)
    name = entry.name
    flags = list(args.flags)
    if flags[:1] == ["--"]:
        flags = flags[1:]
    module = importlib.import_module(entry.module)
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


def migrate_command(args) -> int:
    """``proteo migrate PATH...``: :func:`training.machinery.checkpoints.migrate` on every checkpoint under the paths."""
    from training.machinery.checkpoints import META_FILE
    from training.machinery.checkpoints import migrate as migrate_one

    folders = []
    for path in map(Path, args.paths):
        found = [path] if (path / META_FILE).is_file() else sorted(m.parent for m in path.rglob(META_FILE))
        if not found:
            raise ValueError(
                f"path {str(path)!r} holds no checkpoint (no {META_FILE} in it or below); allowed: checkpoint folders"
            )
        folders += found
    changed = sum(migrate_one(folder) for folder in folders)
    print(f"{changed} of {len(folders)} checkpoints migrated to version 2 (the others were already)")
    return 0


def at_least(least: int):
    """An argparse type: an integer >= ``least``; otherwise argparse's error names the flag, the
    value and what is allowed."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < least:
            raise argparse.ArgumentTypeError(f"{text!r} is not allowed; allowed: an integer >= {least}")
        return value

    return parse


def version() -> str:
    from training.machinery.checkpoints import package_version

    return package_version()


def figures_command(args) -> int:
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
        type=at_least(1),
        default=movie_default_frames,
        help=f"movie frames at most, spread over the episode (default {movie_default_frames})",
    )
    g.add_argument("--plots", default=None, help="folder for the PNG plots of the metrics against cycles")


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    try:
        return args.func(args)
    except ValueError as err:
        print(f"proteo: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(
            f"proteo {args.command}: interrupted; what finished is kept: proteo eval and sweep resume from "
            "OUT/episodes.jsonl with the same command, a study from its runs folder, a trainer with --resume "
            "RUN/checkpoints/step_N",
            file=sys.stderr,
        )
        return 130


def parser() -> argparse.ArgumentParser:
    """The command line: ``proteo COMMAND``, its commands added by topic."""
    parser = argparse.ArgumentParser(prog="proteo", description="Proteo lattice robot simulator")
    parser.add_argument("--version", action="version", version=f"proteo {version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_playback_commands(sub)
    _add_judging_commands(sub)
    _add_training_commands(sub)
    return parser


def _add_playback_commands(sub) -> None:
    """``demo``, ``run``, ``replay``, ``view`` and ``figures``: episodes played, recorded and shown."""
    p = sub.add_parser("demo", help="run every registered task with its default policy")
    p.add_argument("--seed", type=at_least(0), default=0)
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
    p.add_argument("--seed", type=at_least(0), default=0, help="first seed")
    p.add_argument("--episodes", type=at_least(1), default=1)
    p.add_argument("--out", default=None, help="folder for start and end pictures (none if omitted)")
    p.add_argument("--record", default=None, help="write the episode to this .npz file")
    p.add_argument("--render", default=None, help="write a movie of the episode (.gif or .mp4)")
    p.add_argument("--view", default=None, help="write an interactive 3D viewer page of the episode (.html)")
    _picture_args(p)
    p.set_defaults(func=run)

    p = sub.add_parser("replay", help="movie, picture or plots of a recorded episode")
    p.add_argument("file", help="a recording written by proteo run --record")
    p.add_argument("--out", default=None, help="movie (.gif, .mp4) or picture (.png, .jpg, .svg, .pdf)")
    p.add_argument("--cycle", type=at_least(0), default=None, help="cycle drawn in a picture (default: the last)")
    _picture_args(p)
    p.set_defaults(func=replay)

    p = sub.add_parser("view", help="an interactive 3D page (one offline .html file) of a recorded episode")
    p.add_argument("file", help="a recording written by proteo run --record")
    p.add_argument("--out", default=None, help="the page to write (default: the recording's name with .html)")
    p.add_argument("--screenshot", default=None, help="also write a PNG of the page (needs headless Chromium)")
    p.add_argument("--cycle", type=at_least(0), default=None, help="cycle shown in the screenshot (default: the last)")
    p.add_argument("--size", default="1200x800", help="screenshot size WIDTHxHEIGHT (default 1200x800)")
    p.set_defaults(func=view)

    p = sub.add_parser("figures", help="reproduce the paper's figures (pictures and plots) into docs/figures")
    p.add_argument("--out", default="docs/figures")
    p.add_argument("--seed", type=at_least(0), default=0)
    p.add_argument(
        "--only", action="append", default=None, help="only this figure (repeatable): chain, branch, table, grasp"
    )
    p.add_argument("--redraw", action="store_true", help="draw again from the recordings in --out (no episodes run)")
    p.set_defaults(func=figures_command)


def _add_judging_commands(sub) -> None:
    """``eval`` (with ``--benchmark``) and ``sweep``: many episodes, tables and plots."""
    from training.machinery.distributed import add_ray_flags

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
        help="judge --checkpoint (one recipe's training seeds), --entrant or --policy on every split of "
        "configs/benchmark/VERSION.yaml; writes OUT/benchmark.json and benchmark.md",
    )
    b.add_argument(
        "--entrant",
        default=None,
        help="with --benchmark: a policy from outside, its entrant.yaml (or folder), or a factory module:function "
        "with --tasks and --level (docs/guides/entering.md)",
    )
    b.add_argument("--policy", default=None, help="with --benchmark: rules or random (every task, or --tasks)")
    b.add_argument("--level", default=None, help="with --benchmark --policy (or a factory): only this control level")
    b.add_argument(
        "--splits",
        default=None,
        metavar="A,B",
        help="with --benchmark: only these splits (such as the ones a protocol adds to the one it extends)",
    )
    b.add_argument(
        "--worlds-cap",
        type=int,
        default=None,
        metavar="N",
        help="with --benchmark: at most N worlds per split (quick checks only; the result is marked incomplete)",
    )
    add_ray_flags(p)
    p.set_defaults(func=evaluate_command)

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
    p.set_defaults(func=sweep_command)


def _add_training_commands(sub) -> None:
    """``train`` (any registered trainer) and ``migrate`` (old checkpoints)."""
    p = sub.add_parser(
        "train",
        help="train a controller: proteo train TRAINER [flags] runs python -m training.trainers.TRAINER [flags]",
        description="Run a trainer of training/ with the flags that follow, unchanged "
        "(see docs/guides/learning.md; 'proteo train ppo --help' lists ppo's). Trainers: "
        + "; ".join(f"{t.name}: {t.summary}" for t in TRAINERS),
    )
    p.add_argument("trainer", metavar="TRAINER", help=f"one of {', '.join(t.name for t in TRAINERS)}")
    p.add_argument("flags", nargs=argparse.REMAINDER, help="the trainer's flags, e.g. --config FILE.yaml")
    p.set_defaults(func=train_command)

    p = sub.add_parser(
        "migrate",
        help="rewrite version-1 checkpoints' proteo.json as version 2 (each file's SHA-256, the network's fields)",
    )
    p.add_argument("paths", nargs="+", help="checkpoint folders, or folders holding checkpoints at any depth")
    p.set_defaults(func=migrate_command)


if __name__ == "__main__":
    sys.exit(main())

"""What every trainer's run shares: typed options from YAML and the command line, seeding and
threads, the run folder and its progress log, resuming, and for the trainers that work in
generations the whole run around their loop.

Run folder (``--run-dir``, default ``runs/<algorithm>_<task>_<seed>``)::

    args.yaml          the arguments the run was started with
    progress.csv       one row per log step: agent_steps, seconds, episode return, success, ...
    tb/                TensorBoard event files (``tensorboard --logdir runs``)
    checkpoints/step_<N>/  a checkpoint every ``checkpoint_every`` agent-steps (PPO's also keep the
                       training worlds, ``worlds.pkl.gz``, for a resume that goes on bit for bit)
    final/             the checkpoint at the end (its format: :mod:`training.machinery.checkpoints`)

:class:`RunArgs` holds the options of every trainer's run (seed, run folder, time limit, threads,
logs); a trainer's ``Args`` derives from it and declares only its own, and :class:`PPOArgs` adds
what the PPO trainers share. :class:`GenerationalArgs` adds what a population-based trainer
(training/trainers/cma_es.py, training/trainers/evolve.py) needs, and :class:`GenerationalRun`
does the rest of such a run, so that the trainer writes only its generation:

- the run folder (``--run-dir``, default ``runs/<name>``) and its ``args.yaml``;
- resume: rerun the same command after an interruption (the run continues from ``state.pkl``
  after its last finished generation), or ``--resume CHECKPOINT`` to go on from a checkpoint
  (every checkpoint holds the same ``state.pkl``); either way the arguments the results depend
  on (all but :data:`RUN_INDEPENDENT`) must be the run's, checked against the state's
  fingerprint;
- the journal of finished episodes (``episodes.jsonl``: an interrupted generation resumes
  without playing its finished episodes again), the progress log (``progress.csv`` and
  TensorBoard), the progress bar, the time limit, a checkpoint every ``checkpoint_every``
  generations and ``final/`` at the end, each with ``proteo.json``.

The loop of a trainer::

    run = GenerationalRun(args, algorithm="program-evolution", name=f"evolve_{task}_s{seed}",
                          what="evolution run", counter="evolve/generation")
    state = run.resumed or {"generation": 0, ...}       # the state to go on from
    run.start(state["generation"])
    while state["generation"] < args.generations:
        ... score a generation with run.journal, update state ...
        if run.end_generation(state["generation"], agent_steps, values, state, write):
            break                                        # the time limit
    run.finish(state, write)

where ``write(folder, agent_steps)`` writes the trainer's payload and calls :meth:`GenerationalRun.write_meta`.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import csv
import dataclasses
import gzip
import inspect
import os
import pickle
import random
import sys
import time
import typing
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numba
import numpy as np
import yaml

from proteo_env.config import ConfigError, build, load_yaml, parse_yaml
from training.machinery.checkpoints import WORLDS_STATE, CheckpointError, read_meta, write_checkpoint_meta
from training.machinery.distributed import Journal
from training.machinery.registry import ALGORITHMS


# ---------------------------------------------------------------------- args
def field_docs(args_cls) -> dict[str, str]:
    """The docstring written under each field of the dataclass ``args_cls`` (and its bases), by
    field name, whitespace folded: what ``--help`` says about each option."""
    docs: dict[str, str] = {}
    for cls in reversed(args_cls.__mro__):
        if not dataclasses.is_dataclass(cls):
            continue
        try:
            tree = ast.parse(inspect.cleandoc("\n" + inspect.getsource(cls)))
        except (OSError, TypeError, SyntaxError):
            continue
        body = tree.body[0].body
        for statement, following in zip(body, body[1:]):
            if (
                isinstance(statement, ast.AnnAssign)
                and isinstance(statement.target, ast.Name)
                and isinstance(following, ast.Expr)
                and isinstance(following.value, ast.Constant)
                and isinstance(following.value.value, str)
            ):
                docs[statement.target.id] = " ".join(following.value.value.split())
    return docs


def parse_args(args_cls, argv=None, *, description: str = "", retired: dict | None = None, saved_args: bool = False):
    """Build ``args_cls`` (a frozen dataclass) from ``--config FILE.yaml`` and ``--<field> VALUE`` flags.

    Values on the command line are read as YAML (``--env "{n_modules: 16}"``, ``--total-steps
    2e5`` needs ``200000``). The config file and flags may name only fields of ``args_cls``;
    anything else is an error that lists the allowed keys. ``retired`` maps options that were
    removed to the value that made them do nothing: a config file (an older checkpoint's
    ``args.yaml``) that holds that value is read without them. With ``saved_args``, ``--resume
    CHECKPOINT`` without ``--config`` reads the checkpoint's ``args.yaml`` (the arguments it was
    trained with) as the config file.
    """
    parser = argparse.ArgumentParser(description=description or args_cls.__doc__.splitlines()[0])
    parser.add_argument("--config", help="YAML file of arguments (see configs/train/)")
    hints = typing.get_type_hints(args_cls)
    docs = field_docs(args_cls)
    own = vars(args_cls).get("__annotations__", {})
    fields = dataclasses.fields(args_cls)
    for f in [f for f in fields if f.name in own] + [f for f in fields if f.name not in own]:  # its own first
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        kind = f"{getattr(hints[f.name], '__name__', hints[f.name])}, default: {default!r}"
        parser.add_argument(
            f"--{f.name.replace('_', '-')}",
            dest=f.name,
            default=None,
            metavar="VALUE",
            help=(f"{docs[f.name]} ({kind})" if f.name in docs else kind).replace("%", "%%"),
        )
    ns = parser.parse_args(argv)
    if saved_args and ns.resume and not ns.config:
        meta = read_meta(ns.resume)
        if "args.yaml" not in meta["files"]:
            raise CheckpointError(
                f"--resume {ns.resume!r} is a {meta['algorithm']!r} checkpoint without args.yaml; allowed: a checkpoint "
                "this trainer wrote (RUN/checkpoints/step_N or RUN/final), or --config with the arguments"
            )
        ns.config = Path(meta["dir"]) / "args.yaml"
    values: dict = {}
    if ns.config:
        path = Path(ns.config)
        loaded = load_yaml(path) or {}
        if not isinstance(loaded, dict):
            raise ConfigError(f"config file {str(path)!r}: a mapping of argument names is required")
        values.update({k: v for k, v in loaded.items() if k not in (retired or {}) or v != retired[k]})
    for f in dataclasses.fields(args_cls):
        raw = getattr(ns, f.name)
        if raw is not None:
            values[f.name] = raw if hints[f.name] is str else parse_yaml(raw, f"--{f.name.replace('_', '-')} {raw!r}")
    for key, value in list(values.items()):  # YAML reads 1e6 as a string; accept it for ints and floats
        if isinstance(value, str) and key in hints and hints[key] in (int, float):
            try:
                values[key] = hints[key](float(value))
            except ValueError:
                pass
    return build(args_cls, values, where=f"{args_cls.__name__}: ")


def save_args(args, run_dir: Path) -> None:
    (run_dir / "args.yaml").write_text(yaml.safe_dump(dataclasses.asdict(args), sort_keys=False))


# ---------------------------------------------------------------------- seeding and threads
def seed_everything(seed: int, *, threads: int | None = 1) -> None:
    """Seed Python, NumPy and (if installed) torch; pin torch's and numba's thread counts.

    One thread is the right default on these 2-core machines: with two, OpenMP (torch) and
    numba worker threads spin against each other and against the other core's work; a small
    MLP's forward pass measured 20 times slower, a 12-module environment step 100 times
    slower (docs/journal/throughput-training.md).
    """
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
        raise ConfigError(f"seed={seed!r} is not allowed; allowed: an integer from 0 to 2**32 - 1")
    random.seed(seed)
    np.random.seed(seed)
    limit_threads(threads)
    try:
        import torch
    except ImportError:
        return
    torch.manual_seed(seed)


def limit_threads(n: int | None = 1) -> None:
    """Use at most ``n`` threads in numba's parallel kernels and in torch (``None``: leave them)."""
    if not n:
        return
    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
    try:
        import torch
    except ImportError:
        return
    torch.set_num_threads(n)


@contextlib.contextmanager
def torch_threads(n: int):
    """Run the block with ``n`` torch threads, then restore the count before it (numba's is not touched)."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def check_integers(args, least: dict[str, int]) -> None:
    """A :class:`ConfigError` naming the first field of ``args`` in ``least`` whose value is not an
    integer (bools are not) at least as large as its bound."""
    for name, bound in least.items():
        value = getattr(args, name)
        if not isinstance(value, int) or isinstance(value, bool) or value < bound:
            raise ConfigError(f"{name}={value!r} is not allowed; allowed: an integer >= {bound}")


def check_numbers(args, bounds: dict[str, tuple[float, float | None]]) -> None:
    """A :class:`ConfigError` naming the first field of ``args`` in ``bounds`` whose value is not a
    number in its ``(low, high)`` range (``high`` ``None``: no upper bound)."""
    for name, (low, high) in bounds.items():
        value = getattr(args, name)
        if not isinstance(value, (int, float)) or value < low or (high is not None and value > high):
            allowed = f"a number in [{low}, {high}]" if high is not None else f"a number >= {low}"
            raise ConfigError(f"{name}={value!r} is not allowed; allowed: {allowed}")


def run_script(main, argv=None) -> int:
    """Run a training script's ``main(argv)`` from the command line: bad input (a
    :class:`ConfigError` or :class:`CheckpointError`, both ``ValueError``) is one line on stderr
    naming the field, the value and what is allowed, and exit status 2, not a traceback."""
    name = Path(sys.argv[0]).stem if argv is None else "training"
    try:
        main(argv)
    except ValueError as err:
        print(f"{name}: error: {err}", file=sys.stderr)
        return 2
    return 0


def torch_device(name: str):
    """The ``torch.device`` for a trainer's ``device`` argument (``cpu``, ``cuda``, ``cuda:N``,
    ``mps``); a :class:`ConfigError` naming the value when it is not a device or this machine
    lacks it. CPU is the default and the tested path; nothing needs an accelerator."""
    import torch

    try:
        device = torch.device(name)
    except (RuntimeError, TypeError) as error:
        raise ConfigError(f"device={name!r} is not a device ({error}); allowed: cpu, cuda, cuda:N or mps") from None
    if device.type == "cpu":
        return device
    if device.type == "cuda" and torch.cuda.is_available():
        if device.index is None or device.index < torch.cuda.device_count():
            return device
    elif device.type == "mps" and torch.backends.mps.is_available():
        return device
    raise ConfigError(
        f"device={name!r} is not available on this machine; allowed: cpu"
        + "".join(f", cuda:{i}" for i in range(torch.cuda.device_count()))
    )


def out_folder(out, flag: str = "--out") -> Path:
    """``out`` as a folder to write results into (new, or an existing folder); a path that names a
    file is a :class:`ConfigError` before anything runs."""
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise ConfigError(f"{flag} {str(path)!r} is not allowed: it is a file; allowed: a folder (new or existing)")
    return path


def make_run_dir(run_dir: str | None, default_name: str, *, resume: bool) -> Path:
    path = Path(run_dir or Path("runs") / default_name)
    if path.exists() and any(path.iterdir()) and not resume:
        raise ConfigError(f"run_dir {str(path)!r} is not empty; allowed: a new folder, or resume=<checkpoint>")
    (path / "checkpoints").mkdir(parents=True, exist_ok=True)
    return path


# ---------------------------------------------------------------------- progress log
class ProgressLog:
    """Appends rows to ``progress.csv`` (columns fixed by the first row) and to TensorBoard.

    ``resumed_at``: a run resumed from the checkpoint of that many agent-steps first drops the rows
    logged after it (a run killed between checkpoints logged them, and logs them again), so that
    every step is in the file once whatever the interruptions."""

    def __init__(self, run_dir: Path, *, tensorboard: bool = True, resumed_at: int | None = None):
        self.path = run_dir / "progress.csv"
        self.started = time.perf_counter()
        self.offset = 0.0
        if resumed_at is not None:
            self.drop_after("agent_steps", resumed_at)
        elif self.path.exists():  # resumed: wall-clock continues from the last row
            with self.path.open() as fh:
                rows = list(csv.DictReader(fh))
            if rows:
                self.offset = float(rows[-1]["seconds"])
        self.writer = None
        if tensorboard:
            try:
                from torch.utils.tensorboard import SummaryWriter
            except ImportError:  # pragma: no cover - torch is part of the train extra
                SummaryWriter = None
            if SummaryWriter is not None:
                self.writer = SummaryWriter(str(run_dir / "tb"))

    @property
    def seconds(self) -> float:
        return self.offset + time.perf_counter() - self.started

    def drop_after(self, column: str, value: float) -> None:
        """Remove the rows whose ``column`` exceeds ``value`` (logged after the state a run resumes from)."""
        if not self.path.exists():
            return
        with self.path.open() as fh:
            reader = csv.DictReader(fh)
            header, rows = reader.fieldnames, list(reader)
        kept = [r for r in rows if not r.get(column) or float(r[column]) <= value]
        tmp = self.path.with_suffix(".tmp")
        with tmp.open("w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=header)
            writer.writeheader()
            writer.writerows(kept)
        os.replace(tmp, self.path)  # whole or not at all
        self.offset = float(kept[-1]["seconds"]) if kept else 0.0

    def log(self, agent_steps: int, values: dict) -> None:
        row = {
            "agent_steps": agent_steps,
            "seconds": round(self.seconds, 3),
            **{k: (float(v) if v is not None else "") for k, v in values.items()},
        }
        new = not self.path.exists()
        if not new:
            with self.path.open() as fh:
                header = next(csv.reader(fh), None)
            row = {k: row.get(k, "") for k in header} if header else row
        with self.path.open("a", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(row))
            if new:
                writer.writeheader()
            writer.writerow(row)
        if self.writer is not None:
            for k, v in values.items():
                if v is not None and np.isfinite(v):
                    self.writer.add_scalar(k, float(v), agent_steps)
            self.writer.flush()

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


def read_resume(path, algorithm: str, script: str, needs=()) -> dict | None:
    """The checked ``proteo.json`` of the checkpoint a run resumes from (``None`` without one),
    refused unless ``algorithm`` (the trainer ``script``) wrote it with the files ``needs`` (what
    going on needs beside the policy: a kept checkpoint has only the policy)."""
    if not path:
        return None
    meta = read_meta(path)
    if meta["algorithm"] != algorithm:
        raise CheckpointError(
            f"resume={path!r} is a {meta['algorithm']!r} checkpoint; allowed: a checkpoint of {script}"
        )
    missing = [name for name in needs if name not in meta["files"]]
    if missing:
        raise CheckpointError(
            f"resume={path!r} has no {', '.join(missing)} (a checkpoint kept for judging holds the policy alone); "
            f"allowed: a checkpoint of a run of {script}, RUN/checkpoints/step_N or RUN/final"
        )
    return meta


def save_network_checkpoint(folder: Path, net, args, run_dir: Path, *, trainer: dict | None = None, **meta) -> None:
    """Write a checkpoint of a torch network: ``policy.pt`` (its weights, on the CPU), ``trainer.pt``
    (``trainer``, what ``--resume`` needs, when given), ``args.yaml`` (``args`` with ``run_dir`` set
    and ``resume`` cleared) and ``proteo.json`` (:func:`write_checkpoint_meta` with ``meta``)."""
    import torch

    folder.mkdir(parents=True, exist_ok=True)
    torch.save({k: v.cpu() for k, v in net.state_dict().items()}, folder / "policy.pt")
    if trainer is not None:
        torch.save(trainer, folder / "trainer.pt")
    cleared = {"resume": None} if hasattr(args, "resume") else {}
    save_args(dataclasses.replace(args, run_dir=str(run_dir), **cleared), folder)
    write_checkpoint_meta(folder, **meta)


def trainer_state(optimiser, **extra) -> dict:
    """What ``trainer.pt`` holds: the optimiser's state, torch's random state and ``extra``."""
    import torch

    return {"optimiser": optimiser.state_dict(), "torch_rng": torch.get_rng_state(), **extra}


def load_trainer_state(meta: dict, net, optimiser, *, learning_rate: float, device) -> dict:
    """Restore a run from the checkpoint of ``meta`` (:func:`read_resume`): the network from
    ``policy.pt``, the optimiser (at ``learning_rate``) and torch's random state from ``trainer.pt``;
    returns that file's dict (for what the trainer added with :func:`trainer_state`)."""
    import torch

    folder = Path(meta["dir"])
    net.load_state_dict(torch.load(folder / "policy.pt", map_location=device, weights_only=True))
    state = torch.load(folder / "trainer.pt", map_location="cpu", weights_only=False)
    optimiser.load_state_dict(state["optimiser"])
    for group in optimiser.param_groups:
        group["lr"] = learning_rate
    torch.set_rng_state(state["torch_rng"])
    return state


def save_worlds_state(folder: Path, fingerprint: dict, worlds) -> None:
    """Keep the training ``worlds`` in the middle of their episodes in checkpoint ``folder``, with
    the ``fingerprint`` of the settings that built them, so that a run resumed from it goes on as
    the uninterrupted run would (:func:`load_worlds_state`). Written whole or not at all."""
    tmp = folder / f"{WORLDS_STATE}.tmp"
    with gzip.open(tmp, "wb", compresslevel=1) as f:
        pickle.dump({"fingerprint": fingerprint, "worlds": worlds}, f, protocol=pickle.HIGHEST_PROTOCOL)
    os.replace(tmp, folder / WORLDS_STATE)


def load_worlds_state(meta: dict, fingerprint: dict):
    """The worlds :func:`save_worlds_state` kept in the checkpoint of ``meta`` (:func:`read_resume`),
    or ``None`` where it kept none or the settings differ from ``fingerprint`` (then the run goes
    on from fresh worlds, which is said on stdout)."""
    path = Path(meta["dir"]) / WORLDS_STATE
    if not path.exists():
        return None
    with gzip.open(path, "rb") as f:
        kept = pickle.load(f)
    if kept["fingerprint"] != fingerprint:
        print(f"{path}: the worlds were built with other settings; the run goes on from fresh worlds")
        return None
    return kept["worlds"]


def finish_run(run_dir: Path, save, log: ProgressLog, agent_steps: int) -> Path:
    """End a run: its final checkpoint written by ``save(folder)`` to ``RUN/final``, its progress log
    closed, and where the checkpoint is said; returns ``RUN/final``."""
    final = run_dir / "final"
    save(final)
    log.close()
    print(f"final checkpoint: {final}  ({agent_steps} agent-steps, {log.seconds:.0f} s)")
    return final


def checkpoint_folder(run_dir: Path, agent_steps: int) -> Path:
    return run_dir / "checkpoints" / f"step_{agent_steps:010d}"


def episode_stats(episodes: list[dict]) -> dict:
    """Mean return, success rate and mean cycles of finished episodes (``None`` when there are none)."""
    if not episodes:
        return {"episode/return": None, "episode/success": None, "episode/cycles": None}
    return {
        "episode/return": float(np.mean([e["r"] for e in episodes])),
        "episode/success": float(np.mean([e["success"] for e in episodes])),
        "episode/cycles": float(np.mean([e["l"] for e in episodes])),
    }


# ---------------------------------------------------------------------- runs
@dataclass(frozen=True)
class RunArgs:
    """The options of every trainer's run."""

    seed: int = 0
    """The run's seed: every random stream of the run (worlds, policy, optimiser) derives from it."""
    run_dir: str | None = None
    """The run folder (progress.csv, args.yaml, checkpoints/, final/); default: runs/<trainer>_<task>_s<seed>."""
    time_limit_minutes: float = 0.0
    """Stop early, with a final checkpoint, after this much wall-clock time; 0: no limit."""
    threads: int = 1
    """Threads of torch and of numba's parallel kernels in this process (one is fastest on 2 cores)."""
    tensorboard: bool = True
    """Also log the progress to TensorBoard (tb/ in the run folder)."""
    progress_bar: bool = True
    """Show a progress bar on the terminal."""


@dataclass(frozen=True)
class PPOArgs(RunArgs):
    """The options every PPO trainer over proteo's worlds shares (training/trainers/ppo.py,
    training/trainers/sb3_ppo.py, training/trainers/torchrl_ppo.py); each trainer sets its own defaults and adds
    its own options."""

    task: str = "chain-v0"
    """The task: a registered id such as chain-v1 (a bare name such as chain: its newest version)."""
    env: dict = field(default_factory=lambda: {"n_modules": 12, "max_cycles": 300})
    """Overrides of the worlds' settings as ``proteo_env.make`` takes them (size, cycle limit, physics, task parameters)."""
    total_steps: int = 200_000
    """Agent-steps (module-cycles) to train for, counted across all worlds."""
    n_envs: int = 4
    """Worlds stepped together; samples per cycle = n_envs * modules."""
    n_steps: int = 128
    """Cycles per world in one rollout (rollout = n_steps * n_envs * modules agent-steps)."""
    minibatch_size: int = 1024
    """Agent-steps per minibatch of the update."""
    n_epochs: int = 4
    """Passes over each rollout's samples per update."""
    learning_rate: float = 3e-4
    """Adam's learning rate (constant)."""
    gamma: float = 0.99
    """Discount factor per cycle."""
    gae_lambda: float = 0.95
    """The lambda of GAE (0: one-step TD advantages, 1: Monte Carlo returns)."""
    clip_range: float = 0.2
    """PPO's clip range: the probability ratio is clipped to [1 - clip_range, 1 + clip_range]."""
    ent_coef: float = 0.01
    """Weight of the entropy bonus in the loss."""
    checkpoint_every: int = 50_000
    """Agent-steps between checkpoints (checkpoints/step_<N>/ in the run folder)."""
    resume: str | None = None
    """A checkpoint of this trainer to continue from (its run folder is reused unless run_dir is set)."""


@dataclass(frozen=True)
class GenerationalArgs(RunArgs):
    """The options of a trainer that works in generations (and runs its episodes in batches)."""

    generations: int = 50
    """Generations to run (with ``--resume``: in all, counting the checkpoint's)."""
    checkpoint_every: int = 10
    """Generations between checkpoints."""
    resume: str | None = None
    """A checkpoint of this trainer to go on from (an interrupted run resumes by rerunning its command)."""
    ray: bool = False
    """Run the batches of episodes as Ray tasks (the same results as on this machine)."""
    address: str | None = None
    """A running Ray cluster (``HOST:PORT`` or ``auto``); default: a local Ray instance (with ``ray``)."""
    workers: int | None = None
    """Worker processes (default: every core); with ``ray``, CPUs of the local Ray instance or tasks at
    once on a cluster. The results do not depend on it."""


RUN_INDEPENDENT = (
    "generations",
    "time_limit_minutes",
    "checkpoint_every",
    "run_dir",
    "resume",
    "threads",
    "tensorboard",
    "progress_bar",
    "ray",
    "address",
    "workers",
)
"""Options of :class:`GenerationalArgs` a resumed run may change: the results do not depend on them."""


class GenerationalRun:
    """The run of a population-based trainer around its loop (see the module docstring).

    Args:
        args: the trainer's arguments (a :class:`GenerationalArgs`).
        algorithm: the ``algorithm`` of its checkpoints, registered in :mod:`training.machinery.registry`
            (``--resume`` accepts only those).
        name: the run folder's default name, under ``runs/``.
        what: the run in messages (``"evolution run"``).
        counter: the progress log's generation column (rows after a resumed state are dropped).
        independent: more options a resumed run may change, beside :data:`RUN_INDEPENDENT`.

    Attributes:
        run_dir: the run folder.
        resumed: the state to go on from (what the trainer passed to :meth:`end_generation`),
            or ``None`` for a new run.
        journal: the run's :class:`~training.machinery.distributed.Journal` of finished episodes.
        log: its :class:`~training.machinery.runs.ProgressLog`.
    """

    def __init__(self, args, *, algorithm: str, name: str, what: str, counter: str, independent: tuple = ()):
        self.args, self.algorithm, self.counter = args, algorithm, counter
        script = f"proteo train {ALGORITHMS[algorithm].name}"
        resume_meta = read_resume(args.resume, algorithm, script)
        run_dir = Path(args.run_dir or (resume_meta or {}).get("run_dir") or Path("runs") / name)
        self.state_file = run_dir / "state.pkl"
        interrupted = self.state_file.is_file() and not (run_dir / "final").exists() and resume_meta is None
        skip = set(RUN_INDEPENDENT) | set(independent)
        self.fingerprint = {k: v for k, v in asdict(args).items() if k not in skip}
        self.resumed = None
        if interrupted or resume_meta is not None:
            source = self.state_file if interrupted else Path(resume_meta["dir"]) / "state.pkl"
            if not source.is_file():
                raise ConfigError(
                    f"resume={args.resume!r} has no state.pkl (a checkpoint written before runs could go on "
                    f"from it); allowed: a checkpoint of {script} that holds state.pkl"
                )
            self.resumed = pickle.loads(source.read_bytes())
            if self.resumed["fingerprint"] != self.fingerprint:
                saved = self.resumed["fingerprint"]
                diff = sorted(k for k in set(saved) | set(self.fingerprint) if saved.get(k) != self.fingerprint.get(k))
                where = (
                    f"run_dir {str(run_dir)!r} holds an interrupted run"
                    if interrupted
                    else f"resume={args.resume!r} is"
                )
                raise ConfigError(
                    f"{where} with other arguments (differing: {', '.join(diff)}); allowed: the same arguments "
                    "to resume it, or another run_dir"
                )
            print(f"resuming the {what} in {run_dir}")
        self.run_dir = make_run_dir(str(run_dir), run_dir.name, resume=self.resumed is not None)
        save_args(args, self.run_dir)
        self.log = ProgressLog(self.run_dir, tensorboard=args.tensorboard)
        self.journal = Journal(self.run_dir / "episodes.jsonl", self.fingerprint, what=what)
        self.bar = None

    def start(self, generation: int) -> None:
        """Open the progress bar at ``generation`` (the one the run goes on from) and drop the
        progress rows logged after it by an interrupted run."""
        from tqdm import tqdm

        self.log.drop_after(self.counter, generation)
        self.bar = tqdm(
            total=self.args.generations,
            initial=generation,
            unit="generation",
            desc=self.algorithm,
            disable=not self.args.progress_bar,
        )

    def end_generation(self, generation: int, agent_steps: int, values: dict, state: dict, write) -> bool:
        """Log the finished ``generation`` (``values``, with the counter column set, at the end
        unless ``values`` places it), write a
        checkpoint when it is due (``write(folder, agent_steps)`` and ``state.pkl``) and the run's
        state; whether the time limit says stop."""
        self.bar.update(1)
        self.log.log(agent_steps, {**values, self.counter: float(generation)})
        if generation % self.args.checkpoint_every == 0:
            self.checkpoint(checkpoint_folder(self.run_dir, agent_steps), agent_steps, state, write)
        tmp = self.state_file.with_suffix(".tmp")
        tmp.write_bytes(pickle.dumps({**state, "fingerprint": self.fingerprint}))
        os.replace(tmp, self.state_file)
        limit = self.args.time_limit_minutes
        return bool(limit and self.log.seconds > 60 * limit)

    def checkpoint(self, folder: Path, agent_steps: int, state: dict, write) -> Path:
        """Write a checkpoint into ``folder``: the trainer's files (``write``) and ``state.pkl``."""
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "state.pkl").write_bytes(pickle.dumps({**state, "fingerprint": self.fingerprint}))
        write(folder, agent_steps)
        return folder

    def write_meta(self, folder: Path, *, agent_steps: int, generation: int, extra: dict, **meta) -> None:
        """``proteo.json`` of a checkpoint: :func:`~training.machinery.checkpoints.write_checkpoint_meta` with this
        run's algorithm, seed, folder and arguments (``meta``: task, env_overrides, encoder_spec, nvec)."""
        write_checkpoint_meta(
            folder,
            algorithm=self.algorithm,
            agent_steps=agent_steps,
            seed=self.args.seed,
            extra={
                "label": self.algorithm,
                "run_dir": str(self.run_dir),
                "generation": generation,
                **extra,
                "args": asdict(self.args),
            },
            **meta,
        )

    def finish(self, agent_steps: int, state: dict, write) -> Path:
        """Write ``final/``, mark the journal complete and close the logs; the final checkpoint's folder."""
        self.bar.close()
        final = self.checkpoint(self.run_dir / "final", agent_steps, state, write)
        self.journal.complete()
        self.log.close()
        return final

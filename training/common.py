"""What every training script shares: typed args from YAML and the command line, seeding,
the run folder, a progress log, and the checkpoint folder format.

Run folder (``--run-dir``, default ``runs/<algorithm>_<task>_<seed>``)::

    args.yaml          the arguments the run was started with
    progress.csv       one row per log step: agent_steps, seconds, episode return, success, ...
    tb/                TensorBoard event files (``tensorboard --logdir runs``)
    checkpoints/step_<N>/  a checkpoint every ``checkpoint_every`` agent-steps
    final/             the checkpoint at the end

Checkpoint folder: ``proteo.json`` (format, algorithm, task, env overrides, observation
encoding and its version, action ``nvec``, steps, seed, what rebuilds the network exactly (the
fields its trainer registers: layer sizes, activation, ...), the SHA-256 of every payload file
(``files``), and the ``proteo_version`` and git ``commit`` that wrote it) beside the algorithm's
own files. Any checkpoint loads by path with :func:`training.checkpoints.load_policy`, after
:func:`read_meta` has checked every field and every file's digest.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import hashlib
import json
import os
import random
import sys
import time
import typing
from pathlib import Path

import numpy as np
import yaml

from proteo_env.config import ConfigError, build, load_yaml, parse_yaml
from training.trainers import ALGORITHMS, CHECKPOINT_FIELDS

CHECKPOINT_FORMAT = "proteo-checkpoint"
CHECKPOINT_VERSION = 2
"""Version 2 records each payload file's SHA-256 and every field that rebuilds the network (version 1:
neither; :func:`training.checkpoints.migrate` turns one into the other)."""
META_FILE = "proteo.json"


# ---------------------------------------------------------------------- args
def field_docs(args_cls) -> dict[str, str]:
    """The docstring written under each field of the dataclass ``args_cls`` (and its bases), by
    field name, whitespace folded: what ``--help`` says about each option."""
    import ast
    import inspect

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
    import numba

    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
    try:
        import torch
    except ImportError:
        return
    torch.set_num_threads(n)


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


# ---------------------------------------------------------------------- checkpoints
def checkpoint_kind(meta: dict) -> str:
    """``"evolved"`` or ``"learned"``: what kind of controller the checkpoint ``meta`` holds (its
    trainer's registration, :mod:`training.trainers`)."""
    return "evolved" if ALGORITHMS[meta["algorithm"]].evolved else "learned"


class CheckpointError(ValueError):
    """A checkpoint that cannot be loaded (the message names the path and the problem)."""


def checkpoint_dir(path) -> Path:
    """The checkpoint folder that ``path`` names (folder, file inside it, or run folder)."""
    p = Path(path)
    if not p.exists():
        raise CheckpointError(
            f"checkpoint {str(p)!r} does not exist; allowed: a checkpoint folder "
            f"(with {META_FILE}), a file in one, or a run folder with final/"
        )
    if p.is_file():
        p = p.parent
    if not (p / META_FILE).is_file() and (p / "final" / META_FILE).is_file():
        p = p / "final"
    if not (p / META_FILE).is_file():
        raise CheckpointError(
            f"checkpoint {str(path)!r} is not a proteo checkpoint: no {META_FILE} in {str(p)!r}; "
            "allowed: a folder written by a script in training/"
        )
    return p


def read_meta(path) -> dict:
    """The checked ``proteo.json`` of the checkpoint at ``path`` (with ``"dir"`` added): its format
    and version, its algorithm, every field the algorithm's trainer registers
    (:data:`training.trainers.CHECKPOINT_FIELDS`) and the SHA-256 of every file it lists; anything
    else is one :class:`CheckpointError` naming the file and the field."""
    folder = checkpoint_dir(path)
    try:
        meta = json.loads((folder / META_FILE).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise CheckpointError(f"checkpoint {str(folder)!r}: {META_FILE} is not valid JSON ({err})") from None
    return {**check_meta(meta, folder), "dir": str(folder)}


def check_meta(meta, folder: Path) -> dict:
    """``meta``, the contents of the ``proteo.json`` of checkpoint ``folder``, if it passes
    :func:`read_meta`'s checks (else one :class:`CheckpointError`)."""
    where = f"checkpoint {str(folder)!r}: {META_FILE}"
    if not isinstance(meta, dict) or meta.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(
            f"{where} has format {meta.get('format') if isinstance(meta, dict) else None!r}; "
            f"allowed: {CHECKPOINT_FORMAT!r}"
        )
    if meta.get("version") != CHECKPOINT_VERSION:
        migrate = " (migrate it: proteo migrate PATH)" if meta.get("version") == 1 else ""
        raise CheckpointError(
            f"{where}: version = {meta.get('version')!r} is not allowed; allowed: {CHECKPOINT_VERSION}{migrate}"
        )
    if meta.get("algorithm") not in ALGORITHMS:
        raise CheckpointError(
            f"{where}: algorithm = {meta.get('algorithm')!r} is not allowed; allowed: {', '.join(ALGORITHMS)}"
        )
    for key in ("task", "nvec", "files", *CHECKPOINT_FIELDS[meta["algorithm"]]):
        if key not in meta:
            raise CheckpointError(
                f"{where} lacks {key!r}; allowed: a {meta['algorithm']!r} checkpoint records "
                f"{', '.join(('task', 'nvec', 'files', *CHECKPOINT_FIELDS[meta['algorithm']]))}"
            )
    for key, (ok, allowed) in _field_checks().items():
        if key in meta and not ok(meta[key]):
            raise CheckpointError(f"{where}: {key} = {meta[key]!r} is not allowed; allowed: {allowed}")
    files = meta["files"]
    if not isinstance(files, dict) or not all(isinstance(v, str) for v in files.values()):
        raise CheckpointError(f"{where}: files = {files!r} is not allowed; allowed: {{file name: sha256 hex digest}}")
    for name, digest in files.items():
        file = folder / name
        if Path(name).name != name or not file.is_file():
            raise CheckpointError(
                f"{where}: files lists {name!r}, which is not a file in {str(folder)!r}; allowed: the payload files "
                "the trainer wrote beside proteo.json"
            )
        if sha256_of(file) != digest:
            raise CheckpointError(
                f"checkpoint {str(file)!r}: SHA-256 {sha256_of(file)[:16]}... differs from the "
                f"{digest[:16]}... that {META_FILE} records: the file changed after it was written (damaged or "
                "edited); allowed: the file as its trainer wrote it"
            )
    return meta


def _field_checks() -> dict:
    """``{field: (test, what is allowed)}`` of the ``proteo.json`` fields :func:`check_meta` checks
    (a loader then builds from them without a default)."""
    from proteo_env.config import CONTROL_LEVELS
    from proteo_env.registry import TASKS
    from training.policies import MEMORIES, SAMPLED

    def sizes(value) -> bool:
        return isinstance(value, list) and bool(value) and all(_positive_int(v) for v in value)

    return {
        "task": (lambda v: isinstance(v, str) and v in TASKS, f"a registered task id ({', '.join(sorted(TASKS))})"),
        "nvec": (sizes, "the action fields' sizes, a list of integers >= 1"),
        "control": (lambda v: v in CONTROL_LEVELS, ", ".join(CONTROL_LEVELS)),
        "hidden": (sizes, "the hidden layers' sizes, a list of integers >= 1"),
        "activation": (
            lambda v: v in ACTIVATIONS,
            f"{', '.join(ACTIVATIONS)} (what training/ builds; a network of another activation enters the benchmark "
            "as a TorchScript or ONNX file, docs/guides/entering.md)",
        ),
        "memory": (lambda v: v in MEMORIES, ", ".join(MEMORIES)),
        "sampled": (lambda v: v in SAMPLED, ", ".join(SAMPLED)),
        "encoder": (lambda v: v is None or isinstance(v, dict), "the observation encoding's spec, a mapping"),
        "env": (lambda v: isinstance(v, dict), "the proteo_env.make settings, a mapping"),
        "params": (lambda v: isinstance(v, dict), "the evolved parameters, a mapping"),
    }


def _positive_int(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 1


ACTIVATIONS = ("tanh",)
"""The activations of the networks ``training/`` builds (:mod:`training.networks`,
:class:`training.policies.NumpyMLP`, the SB3 and TorchRL actors)."""


def sha256_of(file: Path) -> str:
    """The SHA-256 hex digest of ``file``'s bytes."""
    digest = hashlib.sha256()
    with open(file, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def mlp_meta(control: str, hidden) -> dict:
    """What a checkpoint records of a plain network (:data:`~training.trainers.NETWORK_FIELDS` but
    the encoder): control level ``control``, tanh layers of sizes ``hidden``, no memory, every field
    sampled."""
    return {"control": control, "hidden": list(hidden), "activation": "tanh", "memory": "none", "sampled": "all"}


def payload_digests(folder: Path) -> dict[str, str]:
    """``{name: sha256}`` of every file directly in a checkpoint ``folder`` but ``proteo.json``
    (what ``files`` in ``proteo.json`` records)."""
    return {
        p.name: sha256_of(p)
        for p in sorted(Path(folder).iterdir())
        if p.is_file() and p.name != META_FILE and not p.name.endswith(".tmp")
    }


def write_checkpoint_meta(
    folder: Path,
    *,
    algorithm: str,
    task: str,
    env_overrides: dict,
    encoder_spec: dict | None,
    nvec,
    agent_steps: int,
    seed: int,
    extra: dict | None = None,
) -> None:
    """Write ``proteo.json`` into a checkpoint folder, after its payload files (the caller's): it
    records their SHA-256 (``files``), so the caller writes them first."""
    folder.mkdir(parents=True, exist_ok=True)
    meta = {
        "format": CHECKPOINT_FORMAT,
        "version": CHECKPOINT_VERSION,
        "algorithm": algorithm,
        "task": task,
        "env": env_overrides,
        "encoder": encoder_spec,
        "nvec": [int(n) for n in nvec],
        "agent_steps": int(agent_steps),
        "seed": seed,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S"),
        **provenance(),
        **(extra or {}),
        "files": payload_digests(folder),
    }
    missing = [key for key in CHECKPOINT_FIELDS[algorithm] if key not in meta]
    if missing:  # a trainer's own mistake: its checkpoint would not load
        raise ValueError(f"a {algorithm!r} checkpoint must record {', '.join(missing)}")
    tmp = folder / (META_FILE + ".tmp")
    tmp.write_text(json.dumps(meta, indent=2, default=_json_default))
    os.replace(tmp, folder / META_FILE)


def provenance() -> dict:
    """What wrote a checkpoint: ``{"proteo_version": ..., "commit": ...}``.

    ``proteo_version`` is the installed ``proteo-env`` distribution's version (the package's own
    ``__version__`` when it is not installed); ``commit`` is ``git rev-parse HEAD`` of the
    repository holding the working directory, or ``None`` when there is none or git is missing
    (never an error). Every trainer's ``proteo.json`` has both (through
    :func:`write_checkpoint_meta`); checkpoints written before lack them and load all the same.
    """
    return {"proteo_version": package_version(), "commit": git_commit()}


def package_version() -> str:
    """The version of the installed ``proteo-env`` distribution (``proteo --version``)."""
    from importlib import metadata

    try:
        return metadata.version("proteo-env")
    except metadata.PackageNotFoundError:  # run from a source tree that is not installed
        from proteo_env import __version__

        return __version__


def git_commit(cwd=None) -> str | None:
    """``git rev-parse HEAD`` in ``cwd`` (default: the working directory); ``None`` outside a
    repository, without git, or on any failure."""
    import subprocess

    try:
        done = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=cwd,
            capture_output=True,
            text=True,
            timeout=10,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    commit = done.stdout.strip()
    return commit if done.returncode == 0 and len(commit) >= 40 else None


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {value!r}")


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


def keep_checkpoint(source: Path, dest: Path, *, drop=("trainer.pt",), **fields) -> None:
    """Copy the checkpoint ``source`` to ``dest`` (replaced) without the files ``drop`` (what only a
    resumed run needs), its ``proteo.json`` with ``fields`` added and ``files`` left without them."""
    import shutil

    if dest.exists():
        shutil.rmtree(dest)
    shutil.copytree(source, dest, ignore=shutil.ignore_patterns(*drop))
    meta = json.loads((dest / META_FILE).read_text())
    meta.update(fields, files={k: v for k, v in meta["files"].items() if k not in drop})
    (dest / META_FILE).write_text(json.dumps(meta, indent=2, default=_json_default))


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

"""The checkpoint folder: its format, written and checked, and every checkpoint loaded by path as a
:class:`~baselines.base.Policy`.

A checkpoint folder holds ``proteo.json`` (format, algorithm, task, env overrides, observation
encoding and its version, action ``nvec``, steps, seed, what rebuilds the network exactly (the
fields its trainer registers in :mod:`training.machinery.registry`: layer sizes, activation, ...),
the SHA-256 of every payload file (``files``), and the ``proteo_version`` and git ``commit`` that
wrote it; :func:`write_checkpoint_meta`) beside the algorithm's own files; :func:`read_meta` checks
every field and every file's digest before anything loads. The algorithms and their files:

===================== ======================= ===========================================
``algorithm``         files                   policy
===================== ======================= ===========================================
``sb3-maskable-ppo``  ``model.zip``           the SB3 policy network (MaskablePPO)
``torchrl-ppo``       ``policy.pt``           the TorchRL actor (IPPO or MAPPO)
``cma-neural``        ``genome.npy``          the evolved :class:`~training.machinery.policies.NumpyMLP`
``cma-rules``         (in ``proteo.json``)    the hand-coded policy with evolved parameters
``program-evolution`` ``program.yaml``        the evolved program (:mod:`training.trainers.evolve`)
``ppo``               ``policy.pt``           the network of :mod:`training.trainers.ppo` (shared trunk or MLPs)
``rllib-ppo``         ``policy.pt``           the policy MLP of :mod:`training.trainers.rllib_ppo` (move only)
``imitation``         ``policy.pt``           the network of :mod:`training.trainers.imitate` (as ``ppo``'s)
===================== ======================= ===========================================

``load_policy(path, env)`` accepts the folder, a file inside it, or a run folder (its
``final/`` checkpoint is used). :func:`load_controller` builds the environment too, from the
checkpoint's own settings, or names the hand-coded rules or the random policy of a task
(``"rules:chain-v1"``, ``"random:grasp-v0"``)::

    env, policy = load_controller("checkpoints/v1/chain/ppo_move/seed_0")
    result = run_episode(env, policy, seed=0)   # proteo_env.rollout.run_episode

Anything wrong (no such path, not a checkpoint, a damaged file, a checkpoint of another task,
control level or observation encoding) raises :class:`CheckpointError`, one message naming the
path, what was found and what is allowed.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import time
import warnings
from importlib import metadata
from pathlib import Path

import numpy as np

import proteo_env
from baselines import POLICIES, make_policy
from baselines.base import constructor_parameters
from proteo_env.adapters.flatten import ENCODING_VERSION, ObservationEncoder
from proteo_env.config import CONTROL_LEVELS, ConfigError
from proteo_env.registry import TASKS, task_name
from training.machinery.policies import MEMORIES, SAMPLED, LogitsPolicy, NumpyMLP, torch_mlp
from training.machinery.registry import ALGORITHMS, CHECKPOINT_FIELDS, loader

CHECKPOINT_FORMAT = "proteo-checkpoint"
CHECKPOINT_VERSION = 2
"""Version 2 records each payload file's SHA-256 and every field that rebuilds the network (version 1:
neither; :func:`training.machinery.checkpoints.migrate` turns one into the other)."""
META_FILE = "proteo.json"


# ---------------------------------------------------------------------- checkpoints
def checkpoint_kind(meta: dict) -> str:
    """``"evolved"`` or ``"learned"``: what kind of controller the checkpoint ``meta`` holds (its
    trainer's registration, :mod:`training.machinery.registry`)."""
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
    (:data:`training.machinery.registry.CHECKPOINT_FIELDS`) and the SHA-256 of every file it lists; anything
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
    if not isinstance(meta.get("algorithm"), str) or meta["algorithm"] not in ALGORITHMS:
        raise CheckpointError(
            f"{where}: algorithm = {meta.get('algorithm')!r} is not allowed; allowed: {', '.join(ALGORITHMS)}"
        )
    for key in ("task", "nvec", "files", *CHECKPOINT_FIELDS[meta["algorithm"]]):
        if key not in meta:
            raise CheckpointError(
                f"{where} lacks {key!r}; allowed: a {meta['algorithm']!r} checkpoint records "
                f"{', '.join(('task', 'nvec', 'files', *CHECKPOINT_FIELDS[meta['algorithm']]))}"
            )
    for key, (ok, allowed) in _field_checks(ALGORITHMS[meta["algorithm"]].activations).items():
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


def _field_checks(activations: tuple[str, ...]) -> dict:
    """``{field: (test, what is allowed)}`` of the ``proteo.json`` fields :func:`check_meta` checks
    (a loader then builds from them without a default); ``activations``: those the checkpoint's
    trainer builds (:class:`~training.machinery.registry.Trainer`)."""

    def sizes(value) -> bool:
        return isinstance(value, list) and bool(value) and all(_positive_int(v) for v in value)

    return {
        "task": (lambda v: isinstance(v, str) and v in TASKS, f"a registered task id ({', '.join(sorted(TASKS))})"),
        "nvec": (sizes, "the action fields' sizes, a list of integers >= 1"),
        "control": (lambda v: v in CONTROL_LEVELS, ", ".join(CONTROL_LEVELS)),
        "hidden": (sizes, "the hidden layers' sizes, a list of integers >= 1"),
        "activation": (
            lambda v: v in activations,
            f"{', '.join(activations)} (what this trainer builds; a network of another activation enters the "
            "benchmark as a TorchScript or ONNX file, docs/guides/entering.md)",
        ),
        "memory": (lambda v: v in MEMORIES, ", ".join(MEMORIES)),
        "sampled": (lambda v: v in SAMPLED, ", ".join(SAMPLED)),
        "encoder": (lambda v: v is None or isinstance(v, dict), "the observation encoding's spec, a mapping"),
        "env": (lambda v: isinstance(v, dict), "the proteo_env.make settings, a mapping"),
        "params": (lambda v: isinstance(v, dict), "the evolved parameters, a mapping"),
    }


def _positive_int(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 1


def sha256_of(file: Path) -> str:
    """The SHA-256 hex digest of ``file``'s bytes."""
    digest = hashlib.sha256()
    with open(file, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def mlp_meta(control: str, hidden) -> dict:
    """What a checkpoint records of a plain network (:data:`~training.machinery.registry.NETWORK_FIELDS` but
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
    try:
        return metadata.version("proteo-env")
    except metadata.PackageNotFoundError:  # run from a source tree that is not installed
        from proteo_env import __version__

        return __version__


def git_commit(cwd=None) -> str | None:
    """``git rev-parse HEAD`` in ``cwd`` (default: the working directory); ``None`` outside a
    repository, without git, or on any failure."""
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


WORLDS_STATE = "worlds.pkl.gz"
"""The file of a PPO checkpoint that holds its training worlds as they were, so that a resumed run
goes on bit for bit (:func:`training.machinery.runs.save_worlds_state`); only a resumed run reads it."""


def keep_checkpoint(source: Path, dest: Path, *, drop=("trainer.pt", WORLDS_STATE), **fields) -> None:
    """Copy the checkpoint ``source`` to ``dest`` (replaced) without the files ``drop`` (what only a
    resumed run needs), its ``proteo.json`` with ``fields`` added and ``files`` left without them."""
    if dest.exists():
        shutil.rmtree(dest)
    shutil.copytree(source, dest, ignore=shutil.ignore_patterns(*drop))
    meta = json.loads((dest / META_FILE).read_text())
    meta.update(fields, files={k: v for k, v in meta["files"].items() if k not in drop})
    (dest / META_FILE).write_text(json.dumps(meta, indent=2, default=_json_default))


# ---------------------------------------------------------------------- loading


def _check_compatible(meta: dict, env) -> ObservationEncoder:
    """The env's encoder, after checking the checkpoint was made for this task, control level and encoding."""
    where = f"checkpoint {meta['dir']!r}"
    task = env.task.task_id()
    if task_name(meta["task"]) != env.task.name:
        raise CheckpointError(
            f"{where} was trained on task {meta['task']!r}; it cannot control {task!r}; allowed: an env of "
            f"{task_name(meta['task'])}"
        )
    trained, level = meta["control"], getattr(env, "control", "full")
    if trained != level:
        raise CheckpointError(
            f"{where} was trained at control level {trained!r}; it cannot control {task!r} at "
            f"control level {level!r}; allowed: an env made with control={trained!r}"
        )
    nvec = [int(n) for n in getattr(env, "control_nvec", env.action_layout.nvec)]
    if meta["nvec"] != nvec:
        raise CheckpointError(f"{where}: action nvec {meta['nvec']} does not match the environment's {nvec}")
    saved = meta["encoder"]
    options = ("scent_scale", "message_encoding")
    if not isinstance(saved, dict) or any(k not in saved for k in options):
        raise CheckpointError(
            f"{where}: encoder = {saved!r} is not allowed; allowed: the observation encoding's spec "
            "(proteo_env.adapters.flatten.ObservationEncoder.spec)"
        )
    try:
        encoder = ObservationEncoder.for_env(env, **{k: saved[k] for k in options})
    except (TypeError, ValueError) as err:
        raise CheckpointError(f"{where}: encoder = {saved!r} is not allowed: {err}") from None
    if saved != encoder.spec():
        diff = {k: (saved.get(k), v) for k, v in encoder.spec().items() if saved.get(k) != v}
        raise CheckpointError(
            f"{where}: observation encoding does not match the environment (field: (checkpoint, env)) {diff}"
        )
    return encoder


def load_policy(path, env, *, seed: int | None = None, deterministic: bool = False):
    """The policy stored at ``path``, ready to act in ``env`` (same task and observation encoding):
    built by the loader its trainer registered (:mod:`training.machinery.registry`)."""
    meta = read_meta(path)
    return loader(meta["algorithm"])(meta, env, seed=seed, deterministic=deterministic)


def cma_policy(meta: dict, env, *, seed: int | None, deterministic: bool):
    """The hand-coded policy with evolved parameters (``cma-rules``), or the evolved network
    (``cma-neural``, ``genome.npy``)."""
    if meta["algorithm"] == "cma-neural":
        return network_policy(meta, env, seed, deterministic, _numpy_logits)

    folder = meta["dir"]
    if not isinstance(meta.get("policy"), str) or meta["policy"] not in POLICIES:
        raise CheckpointError(
            f"checkpoint {folder!r}: policy {meta.get('policy')!r} is not registered; "
            f"allowed: {', '.join(sorted(POLICIES))}"
        )
    accepted = set(constructor_parameters(POLICIES[meta["policy"]]))
    params = dict(meta.get("params", {}))
    dropped = sorted(set(params) - accepted)
    if dropped:  # the hand-coded policy changed since: say so loudly, in the warning and the name
        warnings.warn(
            f"checkpoint {folder!r}: evolved parameters {dropped} are no longer parameters of "
            f"policy {meta['policy']!r} and are ignored; evolve again with training/trainers/cma_es.py",
            stacklevel=3,
        )
        params = {k: v for k, v in params.items() if k not in dropped}
    try:
        policy = make_policy(meta["policy"], env, seed=seed, **params)
    except (KeyError, TypeError, ValueError) as err:
        raise CheckpointError(f"checkpoint {folder!r}: cannot build the evolved rules: {err}") from None
    policy.name = f"{meta['policy']} (cma-rules{'; ignored: ' + ', '.join(dropped) if dropped else ''})"
    return policy


def ppo_policy(meta: dict, env, *, seed: int | None, deterministic: bool):
    """The network of training/trainers/ppo.py or training/trainers/imitate.py (``policy.pt``)."""
    return network_policy(meta, env, seed, deterministic, _ppo_logits)


def mlp_policy(meta: dict, env, *, seed: int | None, deterministic: bool):
    """The policy MLP of training/trainers/torchrl_ppo.py or training/trainers/rllib_ppo.py (``policy.pt``)."""
    return network_policy(meta, env, seed, deterministic, _torch_logits)


def sb3_policy(meta: dict, env, *, seed: int | None, deterministic: bool):
    """The MaskablePPO policy of training/trainers/sb3_ppo.py (``model.zip``)."""
    return network_policy(meta, env, seed, deterministic, _sb3_logits)


def network_policy(meta: dict, env, seed: int | None, deterministic: bool, logits_of):
    """A :class:`~training.machinery.policies.LogitsPolicy` over the network of a checkpoint, after checking it
    was made for ``env``'s task, control level and observation encoding; ``logits_of(folder, meta,
    encoder)`` loads the network as a function from features ``(N, F)`` to logits ``(N, sum(nvec))``."""
    encoder = _check_compatible(meta, env)
    return LogitsPolicy.over(
        env,
        logits_of(Path(meta["dir"]), meta, encoder),
        encoder,
        seed=seed,
        label=meta.get("label", meta["algorithm"]),
        deterministic=deterministic,
        nvec=meta["nvec"],
        memory=meta["memory"],
        sampled=meta["sampled"],
    )


RULES = "rules"
"""The policy name in ``"rules:<task>"``: the task's own hand-coded policy (its ``default_policy``)."""


def controller_names() -> list[str]:
    """The policy names :func:`load_controller` accepts before ``:<task>``: ``rules`` and every
    registered policy (``random`` among them)."""
    return [RULES, *sorted(POLICIES)]


def load_controller(source, *, seed: int | None = 0, **env_overrides):
    """An environment and the policy that controls it, from one name: ``(env, policy)``.

    Args:
        source: a checkpoint (its folder, a file in it, or a run folder with ``final/``; the env
            is built from its ``proteo.json``: task, settings and control level, then the policy
            with :func:`load_policy`), or ``"<policy>:<task>"``: ``"rules:chain-v1"`` (the task's
            hand-coded policy), ``"random:grasp-v0"`` or any other registered policy name.
        seed: the policy's seed (episodes are seeded by ``env.reset(seed=...)`` or
            :func:`~proteo_env.rollout.run_episode`).
        **env_overrides: settings over the checkpoint's (or the task's defaults), as for
            :func:`proteo_env.make`, e.g. ``max_cycles=1000``.

    Raises:
        ConfigError: ``source`` is neither an existing path nor ``<policy>:<task>`` with a known
            policy and task (the message names the value and what is allowed).
        CheckpointError: the path is not a loadable checkpoint, or the overrides make an env
            the checkpoint cannot control (another control level or observation encoding).
    """
    allowed = controller_names()
    what = (
        "allowed: a checkpoint folder (with proteo.json), a file in one or a run folder with final/, "
        f"or '<policy>:<task>' with policy one of {', '.join(allowed)} (e.g. 'rules:chain-v1')"
    )
    if not isinstance(source, str | os.PathLike):
        raise ConfigError(f"controller {source!r} is not allowed; {what}")
    if Path(source).exists():
        meta = read_meta(source)
        overrides = {**meta.get("env", {}), "control": meta.get("control", "full"), **env_overrides}
        env = proteo_env.make(meta["task"], **overrides)
        return env, load_policy(meta["dir"], env, seed=seed)
    name, sep, task_id = str(source).partition(":")
    if isinstance(source, os.PathLike) or not sep or name not in allowed or not task_id:
        raise ConfigError(
            f"controller {str(source)!r} is neither an existing checkpoint path nor '<policy>:<task>' "
            f"with a known policy; {what}"
        )

    try:
        env = proteo_env.make(task_id, **env_overrides)
    except ConfigError as err:
        raise ConfigError(f"controller {source!r}: {err}") from None
    return env, make_policy(env.task.default_policy if name == RULES else name, env, seed=seed)


def program_policy(meta: dict, env, *, seed: int | None, deterministic: bool):
    """The program policy of an evolved program's checkpoint (``program.yaml``; a program of
    another task than ``env``'s is a :class:`CheckpointError`)."""
    folder = Path(meta["dir"])
    try:
        policy = make_policy("program", env, program=str(_need(folder / "program.yaml", meta)), seed=seed)
    except ConfigError as err:
        raise CheckpointError(f"checkpoint {str(folder)!r}: program.yaml is not a valid program: {err}") from None
    policy.name = "program (program-evolution)"
    return policy


def _need(file: Path, meta: dict) -> Path:
    """``file`` of the checkpoint of ``meta``, if ``proteo.json`` lists it (:func:`~training.machinery.checkpoints.read_meta`
    has checked its SHA-256 then)."""
    if file.name not in meta["files"]:
        raise CheckpointError(
            f"checkpoint {str(file.parent)!r}: {file.name} is not among the files proteo.json records "
            f"({', '.join(meta['files']) or 'none'}); allowed: a checkpoint whose trainer wrote {file.name}"
        )
    return file


def _sb3_logits(folder: Path, meta: dict, encoder: ObservationEncoder):
    file = folder / "model.zip"
    from sb3_contrib import MaskablePPO

    try:
        model = MaskablePPO.load(_need(file, meta), device="cpu")
    except CheckpointError:
        raise
    except Exception as err:  # a damaged zip raises many kinds of errors
        raise CheckpointError(
            f"checkpoint {str(file)!r} is not a loadable MaskablePPO model: {type(err).__name__}: {err}; allowed: "
            "a model.zip written by MaskablePPO.save"
        ) from None
    if model.observation_space.shape != (encoder.size,):
        raise CheckpointError(
            f"checkpoint {str(file)!r}: observation size {model.observation_space.shape} "
            f"does not match the encoder's ({encoder.size},)"
        )
    return maskable_ppo_logits(model)


def maskable_ppo_logits(model):
    """A MaskablePPO model's policy as ``features (N, D) -> logits (N, sum(nvec))`` (every action
    field's logits, side by side)."""
    import torch

    policy = model.policy
    policy.set_training_mode(False)

    def logits_fn(features: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            dist = policy.get_distribution(torch.as_tensor(features))
            return torch.cat([d.logits for d in dist.distributions], dim=1).numpy()

    return logits_fn


def _torch_logits(folder: Path, meta: dict, encoder: ObservationEncoder):
    file = folder / "policy.pt"
    import torch

    try:
        state = torch.load(_need(file, meta), map_location="cpu", weights_only=True)
        net = torch_mlp(encoder.size, int(sum(meta["nvec"])), tuple(meta["hidden"]))
        net.load_state_dict(state)
    except CheckpointError:
        raise
    except Exception as err:
        raise CheckpointError(
            f"checkpoint {str(file)!r} is not a loadable actor for layer sizes "
            f"{meta.get('hidden')}: {type(err).__name__}: {err}; allowed: weights of the layer sizes proteo.json records"
        ) from None
    net.eval()

    def logits_fn(features: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return net(torch.as_tensor(features)).numpy()

    return logits_fn


def _ppo_logits(folder: Path, meta: dict, encoder: ObservationEncoder):
    file = folder / "policy.pt"
    import torch

    from training.machinery.networks import ARCHS, ActorCritic

    arch = meta["arch"]
    if meta.get("recurrent", 0) or arch not in ARCHS:
        raise CheckpointError(
            f"checkpoint {str(file)!r} has arch={arch!r}, recurrent={meta.get('recurrent', 0)!r}; allowed: a "
            f"feed-forward network of arch {', '.join(ARCHS)} (the lattice and recurrent networks were removed)"
        )
    try:
        net = ActorCritic(
            encoder, meta["nvec"], arch, tuple(meta["hidden"]), memory=meta["memory"], activation=meta["activation"]
        )
        net.load_state_dict(torch.load(_need(file, meta), map_location="cpu", weights_only=True))
    except CheckpointError:
        raise
    except Exception as err:
        raise CheckpointError(
            f"checkpoint {str(file)!r} is not a loadable ppo network (arch {arch!r}, "
            f"layer sizes {meta.get('hidden')}): {type(err).__name__}: {err}; allowed: weights of the architecture, "
            "layer sizes and memory proteo.json records"
        ) from None
    net.eval()

    def logits_fn(features: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return net.logits(torch.as_tensor(features)).numpy()

    return logits_fn


def network_weights(path, task_id: str, network: dict, encoder_spec: dict, *, where: str) -> dict:
    """The network weights of checkpoint ``path``, after checking that training/trainers/imitate.py or
    training/trainers/ppo.py trained it on task ``task_id`` (any version) with the network settings
    ``network`` (:func:`training.machinery.networks.network_meta`) and the observation encoding
    ``encoder_spec``; a :class:`CheckpointError` that starts with ``where`` and names what differs."""
    import torch

    meta = read_meta(path)
    if meta["algorithm"] not in ("imitation", "ppo"):
        raise CheckpointError(
            f"{where} is a {meta['algorithm']!r} checkpoint; allowed: a checkpoint of "
            "training/trainers/imitate.py or training/trainers/ppo.py"
        )
    wanted = {"task": task_name(task_id), **network, "encoder": encoder_spec}
    found = {
        "task": task_name(meta["task"]),
        **{key: meta[key] for key in network},
        "encoder": meta["encoder"],
    }
    for key, value in wanted.items():
        if found[key] != value:
            raise CheckpointError(
                f"{where} was trained with {key}={found[key]!r}; this run has {key}={value!r}; "
                f"allowed: a checkpoint with {key}={value!r}"
            )
    return torch.load(_need(Path(meta["dir"]) / "policy.pt", meta), map_location="cpu", weights_only=True)


def _numpy_logits(folder: Path, meta: dict, encoder: ObservationEncoder):
    file = folder / "genome.npy"
    net = NumpyMLP(encoder.size, int(sum(meta["nvec"])), tuple(meta["hidden"]))
    try:
        genome = np.load(_need(file, meta), allow_pickle=False)
        net.set_flat(genome)
    except CheckpointError:
        raise
    except Exception as err:
        raise CheckpointError(
            f"checkpoint {str(file)!r} is not a genome for layer sizes {net.sizes}: {type(err).__name__}: {err}; "
            "allowed: a genome of the layer sizes proteo.json records"
        ) from None
    return net


V1_DEFAULTS = {"control": "full", "arch": "mlp", "memory": "none", "sampled": "all", "activation": "tanh"}
"""What the version-1 loaders assumed where a version-1 ``proteo.json`` says nothing (every network
that training/ wrote then had tanh layers): :func:`migrate` writes it down."""


def migrate(path) -> bool:
    """Turn the version-1 checkpoint at ``path`` (a folder with ``proteo.json``) into version 2, in
    place: the fields its loader assumed (:data:`V1_DEFAULTS`, the encoder's ``message_encoding``
    and ``version``) written down, and the SHA-256 of every payload file (``files``). The payload
    files are not touched, so the policy plays the same episodes. Returns whether it changed
    anything (``False`` for a version-2 checkpoint); a checkpoint of neither version, or one that
    does not load as version 2 afterwards, is a :class:`CheckpointError` and nothing is written.

    Only for checkpoints that proteo's trainers wrote: it records what they built (tanh layers),
    which a checkpoint assembled by hand need not have."""
    folder = checkpoint_dir(path)
    file = folder / META_FILE
    try:
        meta = json.loads(file.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise CheckpointError(f"checkpoint {str(folder)!r}: {META_FILE} is not valid JSON ({err})") from None
    if not isinstance(meta, dict) or meta.get("version") not in (1, CHECKPOINT_VERSION):
        raise CheckpointError(
            f"checkpoint {str(folder)!r}: {META_FILE} version = "
            f"{meta.get('version') if isinstance(meta, dict) else None!r} is not allowed; allowed: 1 (to migrate) or "
            f"{CHECKPOINT_VERSION}"
        )
    if meta["version"] == CHECKPOINT_VERSION:
        read_meta(folder)
        return False
    if meta.get("activation", V1_DEFAULTS["activation"]) != V1_DEFAULTS["activation"]:
        raise CheckpointError(
            f"checkpoint {str(folder)!r}: {META_FILE} activation = {meta['activation']!r} is not allowed; allowed: "
            f"{V1_DEFAULTS['activation']} (every version-1 network was built with it)"
        )
    fields = CHECKPOINT_FIELDS.get(meta.get("algorithm"), ())
    for key in fields:
        if key in V1_DEFAULTS:
            meta.setdefault(key, V1_DEFAULTS[key])
    if isinstance(meta.get("encoder"), dict):
        encoder = meta["encoder"]
        meta["encoder"] = {
            **encoder,
            "message_encoding": encoder.get("message_encoding", "per_direction"),
            "version": ENCODING_VERSION,
        }
    meta["version"] = CHECKPOINT_VERSION
    meta["files"] = payload_digests(folder)
    check_meta(meta, folder)
    tmp = folder / (META_FILE + ".tmp")
    tmp.write_text(json.dumps(meta, indent=2))
    os.replace(tmp, file)
    return True

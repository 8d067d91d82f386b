"""Entering the benchmark from outside: a policy trained anywhere, judged exactly as ours are.

An **entrant** is one of:

- a **saved network**: a TorchScript (``torch.jit.save``) or ONNX file of a network from the flat
  observation of one agent (:class:`~proteo_env.adapters.flatten.ObservationEncoder`, encoding
  version :data:`~proteo_env.adapters.flatten.ENCODING_VERSION`) to action logits, ``(N, F_in)``
  float32 to ``(N, sum(nvec))``; the judge masks the illegal moves and samples each field (or
  takes its arg-max), every world with its own generator, as it does for our networks;
- a **factory** ``module:function``: ``function(spec: EntrantSpec)`` returns an object with
  ``reset(world: int, seed: int)`` and ``act(observation: dict) -> actions`` (the interface
  below), which may do anything (a network of any framework, rules, a search).

Either is described by an ``entrant.yaml`` (:func:`load_entrant`; the format in
docs/guides/entering.md) and judged with ``proteo eval --benchmark VERSION --entrant
PATH/entrant.yaml``; a bare factory with ``--entrant mypkg.policy:make --tasks TASK --level
LEVEL``. Its training (seeds, budget, code) is declared, not verified, and every table says so.

**The interface, version** :data:`ENTRANT_INTERFACE` (a factory's object): each cycle of a batch
of ``B`` worlds of ``A`` agents, ``act(observation)`` receives a dict of the observation fields
of :mod:`proteo_env.spaces`, each an array ``(B, A, ...)`` (``neighbour_kind (B, A, K)`` int8,
``neighbour_mode (B, A, K)`` int32, ``neighbour_scent (B, A, K, C)`` int32, ``own_mode (B, A,
1)``, ``own_scent (B, A, C)``, ``messages (B, A, 12)`` int32, ``contact (B, A, 2)`` int8, ``load
(B, A, 1)`` float32, ``hint (B, A, 3)`` float32, ``action_mask (B, A, 13)`` int8: the legal
moves), read-only views valid during the call; it returns integer actions ``(B, A, F)``, the
fields of the control level (``spec.action_fields``, each ``0 .. spec.nvec[k] - 1``; at ``move``
``F = 1``: the move alone). A move the mask forbids, a value out of range, another shape or a
float is refused (:class:`EntrantError`, naming the world seed, the agent and the cycle): the
judge never lets an illegal action count. ``reset(world, seed)`` comes before a new episode in
row ``world`` of the batch: ``seed`` is the world seed, and an entrant whose choices depend only
on the seed and the observations gets the same episodes whatever the batch (so a judge run
resumes exactly and the number of workers does not matter).
"""

from __future__ import annotations

import contextlib
import importlib
import io
import json
import math
import sys
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import proteo_env
from baselines.base import Policy
from proteo_env.adapters.flatten import ENCODING_VERSION, MESSAGE_ENCODINGS, SCENT_SCALE, ObservationEncoder
from proteo_env.config import CONTROL_LEVELS, ConfigError, load_yaml
from proteo_env.spaces import N_MOVES, OBSERVATION_FIELDS
from training.machinery.checkpoints import maskable_ppo_logits, sha256_of
from training.machinery.policies import LogitsPolicy

ENTRANT_INTERFACE = 1
"""The version of the interface above and of ``entrant.yaml``'s format (its ``entrant:`` key)."""
ENTRANT_FILE = "entrant.yaml"
FORMATS = ("torchscript", "onnx", "sb3", "benchmarl", "factory")
ACTIONS = ("sample", "argmax")
KINDS = ("learned", "evolved", "hand-coded")
"""What an entrant is; a hand-coded one is judged at the levels the protocol judges the rules at."""
ENTRANT_KEYS = ("entrant", "name", "task", "control", "kind", "format", "factory", "seeds", "observation",
                "actions", "budget", "code", "about")  # fmt: skip
REQUIRED_KEYS = ("entrant", "name", "task", "control", "format", "seeds", "budget", "code")


class EntrantError(ConfigError):
    """An entrant that cannot be judged: a bad ``entrant.yaml``, a file that is not what it claims,
    a factory that fails, actions that break the interface (the message names which)."""


@dataclass(frozen=True)
class EntrantSpec:
    """What a factory is given: the worlds its policy will act in.

    Attributes:
        interface: :data:`ENTRANT_INTERFACE`.
        task: the task id (``chain-v1``).
        settings: the :func:`proteo_env.make` settings of these worlds (a split's).
        level: the control level (``move``, ``move+mode`` or ``full``).
        n_agents: agents per world ``A``.
        action_fields: the names of the ``F`` action fields at this level.
        nvec: each field's number of values.
        observation_shapes: each observation field's shape per agent (``(K,)``, ``(K, C)``, ...).
        training_seed: the training seed this policy was trained with (``entrant.yaml``'s
            ``seeds``), or ``None``.
        file: the file ``entrant.yaml`` names for that seed (its path as the entrant.yaml was given, joined with the name), or ``None``.
    """

    interface: int
    task: str
    settings: dict
    level: str
    n_agents: int
    action_fields: tuple
    nvec: tuple
    observation_shapes: dict
    training_seed: int | None = None
    file: str | None = None

    def encoder(self, *, message_encoding: str = "per_direction", scent_scale: int = SCENT_SCALE) -> ObservationEncoder:
        """The flat observation encoding of these worlds (a public, versioned function: its
        ``encode_fields`` turns ``(N, ...)`` observation fields into ``(N, size)`` float32 features)."""
        env = _env(self.task, self.settings, self.level)
        return ObservationEncoder.for_env(env, message_encoding=message_encoding, scent_scale=scent_scale)


_ENVS: dict = {}


def _env(task: str, settings: dict, level: str):
    """A single env of these settings (cached per process): the static interface entrants are built from."""
    key = (task, json.dumps(settings, sort_keys=True), level)
    if key not in _ENVS:
        _ENVS[key] = proteo_env.make(task, **settings, **({} if level == "full" else {"control": level}))
    return _ENVS[key]


def spec_for(env, settings: dict, *, training_seed=None, file=None) -> EntrantSpec:
    """The :class:`EntrantSpec` of ``env`` (made with ``settings``)."""
    space = env.observation_space(env.possible_agents[0])
    return EntrantSpec(
        interface=ENTRANT_INTERFACE,
        task=env.task.task_id(),
        settings=dict(settings),
        level=env.control,
        n_agents=len(env.possible_agents),
        action_fields=tuple(env.control_fields),
        nvec=tuple(int(n) for n in env.control_nvec),
        observation_shapes={f: tuple(space[f].shape) for f in OBSERVATION_FIELDS},
        training_seed=training_seed,
        file=file,
    )


# ---------------------------------------------------------------------- entrant.yaml
@dataclass(frozen=True)
class EntrantFile:
    """A checked ``entrant.yaml`` (:func:`load_entrant`)."""

    path: Path
    name: str
    task: str
    level: str
    kind: str
    format: str
    factory: str | None
    seeds: dict
    """``{training seed: path of its file (beside the entrant.yaml), or None}``."""
    observation: dict
    """``{"message_encoding", "scent_scale"}`` of the flat encoding (saved networks)."""
    actions: str
    budget: dict
    code: str
    about: str

    def declared(self) -> dict:
        """What the entrant declares of its training (the results say it is declared, not verified)."""
        return {"name": self.name, "training_seeds": sorted(self.seeds), "budget": self.budget, "code": self.code}


def _bad(where: str, field: str, value, allowed: str) -> EntrantError:
    return EntrantError(f"{where}: {field} = {value!r} is not allowed; allowed: {allowed}")


def load_entrant(path) -> EntrantFile:
    """The checked ``entrant.yaml`` at ``path`` (the file, or a folder holding it). Every bad field
    is one :class:`EntrantError` naming the file, the field, the value and what is allowed; the
    files it names must exist (their contents are checked when they load)."""
    path = Path(path)
    file = path / ENTRANT_FILE if path.is_dir() else path
    if not file.is_file():
        raise EntrantError(
            f"--entrant {str(path)!r} is not allowed: no such file; allowed: an {ENTRANT_FILE} (or its folder), "
            "or a factory 'module:function'"
        )
    where = f"entrant {str(file)!r}"
    data = load_yaml(file, "entrant file", f"an {ENTRANT_FILE} (docs/guides/entering.md)")
    if not isinstance(data, dict):
        raise _bad(where, "top level", data, f"a mapping with keys {', '.join(ENTRANT_KEYS)}")
    unknown = [k for k in data if k not in ENTRANT_KEYS]
    if unknown:
        raise _bad(where, f"key {unknown[0]!r}", data[unknown[0]], f"the keys {', '.join(ENTRANT_KEYS)}")
    missing = [k for k in REQUIRED_KEYS if k not in data]
    if missing:
        raise EntrantError(f"{where}: {missing[0]} is missing; allowed: a file with {', '.join(REQUIRED_KEYS)}")
    if data["entrant"] != ENTRANT_INTERFACE:
        raise _bad(where, "entrant", data["entrant"], f"{ENTRANT_INTERFACE} (the interface version)")
    for key in ("name", "task", "code"):
        if not isinstance(data[key], str) or not data[key].strip():
            raise _bad(where, key, data[key], "a non-empty string")
    if data["control"] not in CONTROL_LEVELS:
        raise _bad(where, "control", data["control"], ", ".join(CONTROL_LEVELS))
    kind = data.get("kind", "learned")
    if kind not in KINDS:
        raise _bad(where, "kind", kind, ", ".join(KINDS))
    fmt = data["format"]
    if fmt not in FORMATS:
        raise _bad(where, "format", fmt, ", ".join(FORMATS))
    factory = data.get("factory")
    if (fmt == "factory") != (factory is not None):
        raise _bad(where, "factory", factory, "'module:function' with format: factory, and only then")
    if factory is not None:
        check_factory_name(factory, where=f"{where}: factory")
    seeds = data["seeds"]
    if not isinstance(seeds, dict) or not seeds:
        raise _bad(where, "seeds", seeds, "a mapping of training seeds to files ({0: seed_0.pt, ...})")
    resolved = {}
    for seed, name in seeds.items():
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise _bad(where, "seeds", seed, "training seeds: integers >= 0")
        if name is None and fmt == "factory":
            resolved[seed] = None
            continue
        if not isinstance(name, str) or not (file.parent / name).is_file():
            raise _bad(where, f"seeds.{seed}", name, f"a file beside {file.name} (or null with format: factory)")
        resolved[seed] = str(file.parent / name)
    observation = data.get("observation") or {}
    if not isinstance(observation, dict) or set(observation) - {"message_encoding", "scent_scale", "version"}:
        raise _bad(where, "observation", observation, "a mapping with message_encoding, scent_scale, version")
    if observation.get("version", ENCODING_VERSION) != ENCODING_VERSION:
        raise _bad(where, "observation.version", observation["version"], f"{ENCODING_VERSION}")
    encoding = observation.get("message_encoding", "per_direction")
    if encoding not in MESSAGE_ENCODINGS:
        raise _bad(where, "observation.message_encoding", encoding, ", ".join(MESSAGE_ENCODINGS))
    scale = observation.get("scent_scale", SCENT_SCALE)
    if isinstance(scale, bool) or not isinstance(scale, int) or scale < 1:
        raise _bad(where, "observation.scent_scale", scale, "an integer >= 1")
    actions = data.get("actions", "sample")
    if actions not in ACTIONS:
        raise _bad(where, "actions", actions, ", ".join(ACTIONS))
    budget = data["budget"]
    if not isinstance(budget, dict) or not budget:
        raise _bad(where, "budget", budget, "a mapping of what training used ({agent_steps: 1000000, ...})")
    for key, value in budget.items():
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value < 0:
            raise _bad(where, f"budget.{key}", value, "a number >= 0")
    about = data.get("about", "")
    if not isinstance(about, str):
        raise _bad(where, "about", about, "a string")
    return EntrantFile(
        path=file,
        name=data["name"].strip(),
        task=data["task"],
        level=data["control"],
        kind=kind,
        format=fmt,
        factory=factory,
        seeds=resolved,
        observation={"message_encoding": encoding, "scent_scale": scale},
        actions=actions,
        budget=dict(budget),
        code=data["code"],
        about=about,
    )


def check_factory_name(name, *, where: str = "--entrant") -> str:
    """``name`` if it reads ``module:function`` (a :class:`EntrantError` otherwise)."""
    module, sep, function = str(name).partition(":")
    if not isinstance(name, str) or not sep or not module or not function.isidentifier():
        raise EntrantError(f"{where} {name!r} is not allowed; allowed: a factory 'module:function' (mypkg.policy:make)")
    return name


def factory_function(name: str, *, search: str | None = None):
    """The function ``module:function`` names (``search``: a folder tried first for the module)."""
    module, _, function = check_factory_name(name).partition(":")
    if search is not None and search not in sys.path:
        sys.path.insert(0, search)
    try:
        found = getattr(importlib.import_module(module), function)
    except (ImportError, AttributeError) as err:
        raise EntrantError(
            f"--entrant factory {name!r} is not allowed: {type(err).__name__}: {err}; allowed: a function "
            "of a module Python can import (on sys.path, or beside the entrant.yaml)"
        ) from None
    if not callable(found):
        raise EntrantError(f"--entrant factory {name!r} is not allowed: not callable; allowed: a function")
    return found


# ---------------------------------------------------------------------- building a policy
def entrant_policy(source: str, env, *, seed: int, training_seed=None, settings: dict | None = None):
    """The policy of entrant ``source`` (an ``entrant.yaml`` path or a factory ``module:function``)
    for ``env``: a :class:`~training.machinery.policies.LogitsPolicy` for a saved network, an
    :class:`EntrantPolicy` for a factory."""
    settings = {} if settings is None else settings
    if Path(source).suffix in (".yaml", ".yml") or Path(source).is_dir():
        entry = load_entrant(source)
        file = entry.seeds.get(training_seed)
        if training_seed not in entry.seeds:
            raise _bad(f"entrant {str(entry.path)!r}", "training seed", training_seed, f"one of {sorted(entry.seeds)}")
        if entry.format == "factory":
            factory = factory_function(entry.factory, search=str(entry.path.parent.resolve()))
            spec = spec_for(env, settings, training_seed=training_seed, file=file)
            return EntrantPolicy.build(factory, spec, env, seed=seed, label=entry.name)
        return saved_network_policy(entry, Path(file), env, seed=seed)
    factory = factory_function(source)
    return EntrantPolicy.build(factory, spec_for(env, settings), env, seed=seed, label=source)


def saved_network_policy(entry: EntrantFile, file: Path, env, *, seed: int):
    """A :class:`~training.machinery.policies.LogitsPolicy` over the saved network ``file`` (``entry.format``)."""
    encoder = ObservationEncoder.for_env(env, **entry.observation)
    nvec = [int(n) for n in env.control_nvec]
    logits_fn = checked_network(load_network(file, entry.format), file, encoder.size, sum(nvec))
    return LogitsPolicy.over(
        env, logits_fn, encoder, seed=seed, label=entry.name, deterministic=entry.actions == "argmax", nvec=nvec
    )


def load_network(file: Path, fmt: str):
    """A function ``features (N, D) float32 -> logits`` from a saved network of format ``fmt``
    (:data:`NETWORK_FORMATS`); a file that is not what it claims is an :class:`EntrantError`."""
    where = f"entrant network {str(file)!r}"
    try:
        return NETWORK_FORMATS[fmt][0](file)
    except EntrantError:
        raise
    except Exception as err:  # each framework raises many kinds on a file that is not its own
        raise EntrantError(
            f"{where} is not {NETWORK_FORMATS[fmt][1]} ({type(err).__name__}: {str(err).splitlines()[0][:200]}); "
            f"allowed: {NETWORK_FORMATS[fmt][2]}"
        ) from None


def _torchscript(file: Path):
    import torch

    with warnings.catch_warnings():  # torch 2.10+ calls TorchScript deprecated; it loads all the same
        warnings.simplefilter("ignore", DeprecationWarning)
        net = torch.jit.load(str(file), map_location="cpu")
    net.eval()

    def forward(features: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return net(torch.from_numpy(features)).numpy()

    return forward


def _onnx(file: Path):
    import onnxruntime

    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = options.inter_op_num_threads = 1
    session = onnxruntime.InferenceSession(str(file), options, providers=["CPUExecutionProvider"])
    inputs = session.get_inputs()
    if len(inputs) != 1:
        raise EntrantError(
            f"entrant network {str(file)!r} has {len(inputs)} inputs; allowed: one, the flat observation (N, F_in)"
        )
    name = inputs[0].name

    def forward(features: np.ndarray) -> np.ndarray:
        return session.run(None, {name: features})[0]

    return forward


def _sb3(file: Path):
    from sb3_contrib import MaskablePPO

    return maskable_ppo_logits(MaskablePPO.load(str(file), device="cpu"))


def _benchmarl(file: Path):
    """The actor of a BenchMARL experiment restored from its checkpoint by BenchMARL itself
    (``Experiment.reload_from_file``, which reads ``config.pkl`` two folders up): the network that
    every agent shares, from one agent's observation to its logits."""
    import torch

    try:
        from benchmarl.experiment import Experiment
        from torchrl.modules.models.multiagent import MultiAgentNetBase
    except ImportError:
        raise EntrantError(
            f"entrant network {str(file)!r} has format: benchmarl, and BenchMARL is not installed here; allowed: "
            "judge it in BenchMARL's own environment (make benchmarl, then .venv-benchmarl/bin/proteo eval ...)"
        ) from None
    experiment_folder = file.parent.parent
    if file.parent.name != "checkpoints" or not (experiment_folder / "config.pkl").is_file():
        raise EntrantError(
            f"entrant network {str(file)!r} is not allowed: no config.pkl at {str(experiment_folder)!r}; allowed: a "
            "checkpoint where BenchMARL saves it, EXPERIMENT/checkpoints/checkpoint_N.pt beside EXPERIMENT/config.pkl"
        )
    with tempfile.TemporaryDirectory() as scratch, contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # torchrl's deprecations of what BenchMARL 1.5 calls; it restores all the same
        experiment = Experiment.reload_from_file(str(file), experiment_patch={"save_folder": scratch, "loggers": []})
    nets = [m for m in experiment.policy.modules() if isinstance(m, MultiAgentNetBase)]
    if len(nets) != 1 or not nets[0].share_params or nets[0].centralized:
        raise EntrantError(
            f"entrant network {str(file)!r} is not allowed: its actor is not one network shared by every agent; "
            "allowed: a decentralised actor with shared parameters (BenchMARL's share_param_policy: true), which "
            "the judge runs on robots of any size"
        )
    net = nets[0].get_stateful_net(copy=True).eval()

    def forward(features: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return net(torch.from_numpy(features)).numpy()

    return forward


NETWORK_FORMATS = {
    "torchscript": (_torchscript, "a TorchScript file", "a file written by torch.jit.save"),
    "onnx": (_onnx, "an ONNX model", "a file written by torch.onnx.export or any ONNX writer"),
    "sb3": (_sb3, "a MaskablePPO model", "a model.zip written by sb3-contrib's MaskablePPO.save"),
    "benchmarl": (_benchmarl, "a BenchMARL checkpoint", "a checkpoint_N.pt written by a BenchMARL Experiment"),
}
"""``format: (loader, what it is, what is allowed)`` of the saved networks an entrant may be."""


def checked_network(forward, file: Path, n_in: int, n_out: int):
    """``forward`` after one check of its sizes on zeros, wrapped so that every call's logits are
    ``(N, n_out)`` finite floats (an :class:`EntrantError` naming the file otherwise)."""
    where = f"entrant network {str(file)!r}"

    def logits_fn(features: np.ndarray) -> np.ndarray:
        try:
            out = np.asarray(forward(np.ascontiguousarray(features, dtype=np.float32)))
        except EntrantError:
            raise
        except Exception as err:
            raise EntrantError(
                f"{where} failed on features of shape {features.shape} ({type(err).__name__}: "
                f"{str(err).splitlines()[0][:200]}); allowed: a network from (N, {n_in}) float32 "
                f"features (the flat encoding, docs/guides/entering.md) to (N, {n_out}) logits"
            ) from None
        if out.shape != (len(features), n_out):
            raise EntrantError(
                f"{where} gave logits of shape {out.shape} for features {features.shape}; allowed: "
                f"({len(features)}, {n_out}), one logit per value of each action field"
            )
        if not np.isfinite(out).all():
            raise EntrantError(f"{where} gave logits that are not finite (NaN or inf); allowed: finite numbers")
        return out

    logits_fn(np.zeros((1, n_in), dtype=np.float32))
    return logits_fn


class EntrantPolicy(Policy):
    """A factory's object as a :class:`~baselines.base.Policy`: one world through :meth:`act`
    (``run_episode``, the PettingZoo API), many through the evaluator, which calls the object once
    a cycle for every world of its batch (:meth:`act_batch`)."""

    name = "entrant"

    def __init__(self, entrant, spec: EntrantSpec, env, *, seed: int, label: str):
        super().__init__(env.action_layout, env.task.modes, scent_max=env.config.physics.scent_max, seed=seed)
        self.entrant, self.spec, self.name, self.label = entrant, spec, label, label
        self.levels = (spec.level,)
        self.seed, self.cycle, self.fresh_episode = seed, 0, True

    @classmethod
    def build(cls, factory, spec: EntrantSpec, env, *, seed: int, label: str) -> EntrantPolicy:
        try:
            entrant = factory(spec)
        except Exception as err:
            raise EntrantError(f"--entrant factory {label!r} raised {type(err).__name__}: {err}") from None
        for method in ("act", "reset"):
            if not callable(getattr(entrant, method, None)):
                raise EntrantError(
                    f"--entrant factory {label!r} returned {type(entrant).__name__!r} without {method}(); allowed: "
                    "an object with reset(world, seed) and act(observation) (docs/guides/entering.md)"
                )
        return cls(entrant, spec, env, seed=seed, label=label)

    def reset(self, seed=None) -> None:
        super().reset(seed)
        self.seed, self.cycle, self.fresh_episode = seed, 0, True

    def act(self, observations: dict) -> dict:
        """One world's actions ``{agent: (F,) array}`` from its observations ``{agent: {field: array}}``."""
        names = list(observations)
        if self.fresh_episode:
            self.entrant.reset(0, self.seed)
            self.fresh_episode = False
        fields = {f: np.stack([observations[n][f] for n in names])[None] for f in OBSERVATION_FIELDS}
        actions = self.act_batch(fields, [self.seed], [self.cycle])
        self.cycle += 1
        return {n: actions[0, i] for i, n in enumerate(names)}

    def act_batch(self, fields: dict, seeds, cycles) -> np.ndarray:
        """``(B, A, F)`` int64 actions of the object for the observation ``fields`` ``(B, A, ...)``
        of worlds ``seeds`` at ``cycles``, checked (:func:`check_actions`)."""
        try:
            actions = self.entrant.act(fields)
        except EntrantError:
            raise
        except Exception as err:
            raise EntrantError(
                f"entrant {self.label!r} raised {type(err).__name__} in act() (world seed {seeds[0]}, cycle "
                f"{cycles[0]}): {err}"
            ) from err
        return check_actions(actions, fields["action_mask"], self.spec, seeds, cycles, self.label)


def check_actions(actions, mask: np.ndarray, spec: EntrantSpec, seeds, cycles, label: str) -> np.ndarray:
    """``actions`` as ``(B, A, F)`` int64 if they keep the interface: that shape, integers, every
    field in ``0 .. nvec - 1``, every move legal under ``mask (B, A, 13)``; else one
    :class:`EntrantError` naming the first offending world seed, agent and cycle."""
    b, a = mask.shape[:2]
    shape = (b, a, len(spec.nvec))
    where = f"entrant {label!r}"
    actions = np.asarray(actions)
    if actions.shape != shape:
        raise EntrantError(
            f"{where} returned actions of shape {actions.shape}; allowed: {shape} (worlds, agents, the fields "
            f"{', '.join(spec.action_fields)} of control level {spec.level!r})"
        )
    if actions.dtype.kind not in "iu":
        raise EntrantError(f"{where} returned actions of dtype {actions.dtype}; allowed: integers")
    actions = actions.astype(np.int64)
    nvec = np.asarray(spec.nvec, dtype=np.int64)
    bad = (actions < 0) | (actions >= nvec)
    if bad.any():
        w, i, k = np.argwhere(bad)[0]
        raise EntrantError(
            f"{where}: world seed {seeds[w]}, agent module_{i}, cycle {cycles[w]}: {spec.action_fields[k]} = "
            f"{actions[w, i, k]} is not allowed; allowed: 0 to {nvec[k] - 1}"
        )
    moves = actions[..., 0]
    illegal = np.take_along_axis(np.asarray(mask), moves[..., None], axis=2)[..., 0] == 0
    if illegal.any():
        w, i = np.argwhere(illegal)[0]
        legal = np.flatnonzero(mask[w, i]).tolist()
        raise EntrantError(
            f"{where}: world seed {seeds[w]}, agent module_{i}, cycle {cycles[w]}: move = {moves[w, i]} is not "
            f"allowed: the action mask forbids it; allowed: a move of {legal} (of 0 to {N_MOVES - 1})"
        )
    return actions


def file_digests(entry: EntrantFile) -> dict:
    """``{training seed: sha256 of its file}`` (``None`` where a factory has no file): what the
    results record, so that "this is the network that was judged" can be checked."""
    return {seed: None if file is None else sha256_of(Path(file)) for seed, file in entry.seeds.items()}

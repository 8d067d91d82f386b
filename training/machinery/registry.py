"""The registry of trainers: each registers once what the command line, checkpoint loading, the
tables and the study need to know of it.

``proteo train NAME`` runs the ``main(argv)`` of the trainer's ``module`` (one module each in
:mod:`training.trainers`); a checkpoint whose ``proteo.json``
says ``algorithm: A`` is loaded by the ``loader`` of the trainer that lists ``A``
(:func:`training.machinery.checkpoints.load_policy`) and is shown as ``evolved`` or ``learned`` in tables.
docs/guides/adding_a_trainer.md walks through adding one.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass


@dataclass(frozen=True)
class Trainer:
    """One trainer script and the checkpoints it writes.

    Attributes:
        name: ``proteo train NAME``.
        module: the trainer's script, a module with ``main(argv)`` (``python -m MODULE`` runs it too).
        summary: one line for ``proteo train --help``.
        algorithms: the ``algorithm`` values its checkpoints record (none: it writes no
            checkpoint of its own, as the study).
        evolved: its controllers are evolved (a population scored on episodes), not learned.
        loader: ``"module:function"`` that builds the policy of one of its checkpoints,
            ``function(meta, env, *, seed, deterministic) -> Policy`` (``meta``: the checked
            ``proteo.json`` with ``"dir"``).
        activations: the hidden layers' activations its loader builds (a network checkpoint
            recording another is refused, not played with the wrong one).
    """

    name: str
    module: str
    summary: str
    algorithms: tuple[str, ...] = ()
    evolved: bool = False
    loader: str = ""
    activations: tuple[str, ...] = ("tanh",)


TRAINERS = (
    Trainer(
        "ppo",
        "training.trainers.ppo",
        "native PPO over the array API (training/trainers/ppo.py)",
        ("ppo",),
        loader="training.machinery.checkpoints:ppo_policy",
        activations=("tanh", "relu"),
    ),
    Trainer(
        "imitate",
        "training.trainers.imitate",
        "clone the rules: behaviour cloning + DAgger (training/trainers/imitate.py)",
        ("imitation",),
        loader="training.machinery.checkpoints:ppo_policy",
        activations=("tanh", "relu"),
    ),
    Trainer(
        "cma_es",
        "training.trainers.cma_es",
        "CMA-ES on the rules' parameters or a small network (training/trainers/cma_es.py)",
        ("cma-rules", "cma-neural"),
        evolved=True,
        loader="training.machinery.checkpoints:cma_policy",
    ),
    Trainer(
        "evolve",
        "training.trainers.evolve",
        "evolution of programs of the paper's primitives (training/trainers/evolve.py)",
        ("program-evolution",),
        evolved=True,
        loader="training.machinery.checkpoints:program_policy",
    ),
    Trainer(
        "sb3_ppo",
        "training.trainers.sb3_ppo",
        "MaskablePPO, Stable-Baselines3 (training/trainers/sb3_ppo.py)",
        ("sb3-maskable-ppo",),
        loader="training.machinery.checkpoints:sb3_policy",
    ),
    Trainer(
        "torchrl_ppo",
        "training.trainers.torchrl_ppo",
        "IPPO / MAPPO, TorchRL (training/trainers/torchrl_ppo.py)",
        ("torchrl-ppo",),
        loader="training.machinery.checkpoints:mlp_policy",
    ),
    Trainer(
        "rllib_ppo",
        "training.trainers.rllib_ppo",
        "RLlib's PPO (training/trainers/rllib_ppo.py; the distributed extra)",
        ("rllib-ppo",),
        loader="training.machinery.checkpoints:mlp_policy",
    ),
    Trainer(
        "study", "training.trainers.study", "recipes x tasks x seeds, kept in checkpoints/ (training/trainers/study.py)"
    ),
)
"""Every trainer, in the order ``proteo train --help`` lists them."""

ALGORITHMS = {algorithm: trainer for trainer in TRAINERS for algorithm in trainer.algorithms}
"""The trainer of each checkpoint ``algorithm``."""

NETWORK_FIELDS = ("control", "encoder", "hidden", "activation", "memory", "sampled")
"""What a network checkpoint records to rebuild its network and feed it exactly: the control level,
the observation encoding (:meth:`~proteo_env.adapters.flatten.ObservationEncoder.spec`, with its
version), the hidden layer sizes, the activation, the memory inputs and the fields it samples."""
CHECKPOINT_FIELDS = {
    "ppo": (*NETWORK_FIELDS, "arch"),
    "imitation": (*NETWORK_FIELDS, "arch"),
    "cma-rules": ("control", "policy", "params"),
    "cma-neural": NETWORK_FIELDS,
    "program-evolution": ("control",),
    "sb3-maskable-ppo": NETWORK_FIELDS,
    "torchrl-ppo": NETWORK_FIELDS,
    "rllib-ppo": NETWORK_FIELDS,
}
"""The fields of ``proteo.json`` every checkpoint of an ``algorithm`` must have (besides ``task``,
``nvec`` and ``files``): :func:`training.machinery.checkpoints.read_meta` refuses one without them, and no loader
fills one in with a default."""


def trainer(name: str) -> Trainer:
    """The registered trainer ``name`` (``-`` read as ``_``); a ``ValueError`` naming the allowed ones."""
    for t in TRAINERS:
        if t.name == name.replace("-", "_"):
            return t
    raise ValueError(f"trainer {name!r} is not allowed; allowed: {', '.join(t.name for t in TRAINERS)}")


def loader(algorithm: str):
    """The function that loads a checkpoint of ``algorithm`` (a registered one)."""
    module, _, function = ALGORITHMS[algorithm].loader.partition(":")
    return getattr(importlib.import_module(module), function)

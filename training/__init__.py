"""Training and evaluation of learned and evolved controllers (outside the env package).

One script per trainer, each readable end to end, every one registered in
:data:`training.trainers.TRAINERS` (``proteo train --help`` lists them: native PPO, imitation,
MaskablePPO, TorchRL's IPPO/MAPPO, RLlib's PPO, CMA-ES, program evolution, the study).
Checkpoints load by path as ordinary policies with :func:`training.checkpoints.load_policy`;
:func:`load_controller` gives the environment and the policy of a checkpoint (or of the rules
or the random policy of a task, ``"rules:chain-v1"``) in one call; :mod:`training.judging` is
``proteo eval`` and the benchmark's judge. Needs the ``train`` extra (``pip install -e ".[train]"``).
"""

from __future__ import annotations

__all__ = ["load_controller"]


def __getattr__(name: str):
    # loaded on first use, so that importing a training module does not load the checkpoint code
    if name == "load_controller":
        from .checkpoints import load_controller

        return load_controller
    raise AttributeError(f"module 'training' has no attribute {name!r}")

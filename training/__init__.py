"""Training and judging of learned and evolved controllers (outside the env package), in three rooms:

- :mod:`training.trainers`: one script per trainer, each readable end to end, every one registered
  in :data:`training.machinery.registry.TRAINERS` (``proteo train --help`` lists them: native PPO,
  imitation, MaskablePPO, TorchRL's IPPO/MAPPO, RLlib's PPO, CMA-ES, program evolution, the study);
- :mod:`training.machinery`: what they and the judge share (the registry, a run's folder and
  options, the checkpoint format and its loaders, networks, the batched evaluator, distributed jobs);
- :mod:`training.judging`: ``proteo eval``, the benchmark's protocols, judge, statistics and pages,
  and the entrants from outside.

Beside them: the command line (:mod:`training.cli`), playback (``proteo demo``/``run``/``replay``/
``view``, :mod:`training.playback`) and ``proteo sweep`` (:mod:`training.sweep`). Imports run one
way: trainers -> judging -> machinery (``tests/test_layers.py``), and stand at the top of each module
but those of the optional or heavy packages listed in that test's ``LAZY_PACKAGES`` (torch, Ray,
SB3, TorchRL, ONNX Runtime, BenchMARL, matplotlib, ...) and of our modules that load them, imported
where used so that ``proteo --help`` and the judge of the rules start without them.

Checkpoints load by path as ordinary policies with :func:`training.machinery.checkpoints.load_policy`; :func:`load_controller` gives the environment
and the policy of a checkpoint (or of the rules or the random policy of a task,
``"rules:chain-v1"``) in one call. Needs the ``train`` extra (``pip install -e ".[train]"``).
"""

from __future__ import annotations

__all__ = ["load_controller"]


def __getattr__(name: str):
    # loaded on first use, so that importing a training module does not load the checkpoint code
    if name == "load_controller":
        from training.machinery.checkpoints import load_controller

        return load_controller
    raise AttributeError(f"module 'training' has no attribute {name!r}")

"""What the trainers and the judge share: the registry of trainers (:mod:`~training.machinery.registry`),
a run's options, folder, progress log and resume (:mod:`~training.machinery.runs`), the checkpoint
format and its loaders (:mod:`~training.machinery.checkpoints`), the networks
(:mod:`~training.machinery.networks`) and the policies that play them
(:mod:`~training.machinery.policies`), the batched evaluator (:mod:`~training.machinery.evaluator`)
and the journaled jobs it runs here or on Ray (:mod:`~training.machinery.distributed`).

Nothing here imports a trainer (:mod:`training.trainers`) or the judge (:mod:`training.judging`).
"""

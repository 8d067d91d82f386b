"""The trainers: one module each, a script with ``main(argv)`` that ``proteo train NAME`` runs.

Each is registered once in :data:`training.machinery.registry.TRAINERS` (its name, module, the
``algorithm`` its checkpoints record and their loader) and reads end to end: native PPO
(:mod:`~training.trainers.ppo`, with its curricula in :mod:`~training.trainers.curriculum` and its
worlds in :mod:`~training.trainers.worlds`), imitation of the rules (:mod:`~training.trainers.imitate`,
its teachers in :mod:`~training.trainers.teachers`), MaskablePPO (:mod:`~training.trainers.sb3_ppo`),
TorchRL's IPPO and MAPPO (:mod:`~training.trainers.torchrl_ppo`), RLlib's PPO
(:mod:`~training.trainers.rllib_ppo`), CMA-ES (:mod:`~training.trainers.cma_es`), evolution of
programs (:mod:`~training.trainers.evolve`, its variation operators in
:mod:`~training.trainers.program_variation`) and the study that runs the others over recipes,
tasks and seeds (:mod:`~training.trainers.study`). What they share is in :mod:`training.machinery`;
docs/guides/adding_a_trainer.md walks through adding one.
"""

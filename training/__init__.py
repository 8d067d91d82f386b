"""Training and evaluation of learned and evolved controllers (outside the env package).

One script per algorithm, each readable end to end: :mod:`training.sb3_ppo` (MaskablePPO,
Stable-Baselines3), :mod:`training.torchrl_ppo` (IPPO/MAPPO, TorchRL) and :mod:`training.cma_es`
(CMA-ES over the hand-coded rules' parameters or a small neural controller). Checkpoints load
by path as ordinary policies with :func:`training.checkpoints.load_policy`;
:mod:`training.evaluate` is ``proteo eval``. Needs the ``train`` extra (``pip install -e ".[train]"``).
"""

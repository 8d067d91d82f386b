"""Adapters from :class:`~proteo_env.env.ProteoEnv` to learning libraries.

============================ ==============================================================
module                       what
============================ ==============================================================
:mod:`.flatten`              the Dict observation as one named float vector (NumPy only)
:mod:`.sb3`                  Stable-Baselines3 ``VecEnv``: every agent of every env copy is
                             one sub-env (parameter sharing); a single-agent ``gymnasium.Env``
                             view for SB3's ``env_checker``
:mod:`.torchrl`              a native TorchRL ``EnvBase`` over the array API (multi-agent
                             keys under ``"agents"``)
============================ ==============================================================

Nothing here is imported by :mod:`proteo_env` itself: :mod:`.sb3` needs ``stable-baselines3``
and :mod:`.torchrl` needs ``torchrl`` (``pip install -e ".[train]"``).
"""

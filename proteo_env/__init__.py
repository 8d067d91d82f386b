"""proteo: simulator and multi-agent RL benchmark for Proteo-style lattice robots.

Quick start::

    import proteo_env
    env = proteo_env.make("sandbox-v0", n_modules=30)
    observations, infos = env.reset(seed=0)
"""

from .batched import BatchedEnv
from .config import ConfigError, EnvConfig
from .core.lattice import DIRECTIONS
from .core.motion import MOTION_MODELS
from .core.world import LayoutError, Physics
from .env import ProteoEnv, WorldView
from .registry import TASKS, make, make_batched, register

__all__ = [
    "BatchedEnv",
    "ConfigError",
    "DIRECTIONS",
    "EnvConfig",
    "LayoutError",
    "MOTION_MODELS",
    "Physics",
    "ProteoEnv",
    "TASKS",
    "WorldView",
    "make",
    "make_batched",
    "register",
]
__version__ = "0.1.0"

"""Snake: a blob that forms a chain and travels as a chain, head first, through a tunnel.

On locomotion's course (:mod:`proteo_env.tasks.locomotion`; by default a tunnel 2 layers high through a wall, no
step), the modules first form a chain by the paper's chain rules, then crawl: modules leave the chain's tail, travel
along it and join it at its head (:mod:`proteo_env.tasks.crawl`). Reward, metrics and termination are locomotion's.
Registered: ``snake-v0``. Paper sections 1 and 4.1 ("snaking into holes or squeezing through narrow passages").

The contract (layout, agents, observation, actions, reward, metrics, termination, parameters): docs/tasks/snake.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from ..core.cycle import EMIT, RELAY
from .chain import ChainMode
from .crawl import CrawlMode
from .locomotion import Locomotion, LocomotionParams

SnakeMode = IntEnum(
    "SnakeMode",
    [(m.name, int(m)) for m in ChainMode] + [(m.name, len(ChainMode) + int(m)) for m in CrawlMode],
)
SnakeMode.__doc__ = "The snake's modes: the chain's (0-3), then the crawl's (4-6)."


@dataclass(frozen=True)
class SnakeParams(LocomotionParams):
    """Parameters of the snake task: :class:`~proteo_env.tasks.locomotion.LocomotionParams`
    with, by default, no step and a tunnel of 2 free layers over 6 sites through a wall
    (``closed_above``), so the only way on is through it."""

    step_height: int = 0
    tunnel_height: int = 2
    closed_above: bool = True


class Snake(Locomotion):
    name = "snake"
    version = 0
    modes = tuple(SnakeMode.__members__)
    Params = SnakeParams
    default_policy = "snake"
    demo_settings = {"max_cycles": 3000}
    mode_roles = tuple((EMIT,) if name in ("SEED", "HEAD") else (RELAY,) for name in SnakeMode.__members__)
    """``move+mode``: the chain's SEED and the crawl's HEAD emit the scent, every other module relays it."""

    def initial_modes(self, layout):
        """SLEEP, and one SEED: the foremost module on the ground (the first such in the layout)."""
        sites = layout.modules
        modes = np.full(len(sites), SnakeMode.SLEEP, dtype=np.int32)
        on_ground = np.flatnonzero(sites[:, 2] == 0)
        modes[on_ground[int(np.argmax(sites[on_ground, 0]))]] = SnakeMode.SEED
        return modes

"""Snake: a blob that forms a chain and travels as a chain, head first, through a tunnel.

Description
    The paper's reason for chains, taken literally: "moving over steps, snaking into holes or
    squeezing through narrow passages". The course is locomotion's (:mod:`proteo_env.tasks.locomotion`):
    a random connected blob on a floor, and ahead of it, ``distance`` empty sites from its
    foremost module, a tunnel (a hole through a wall, ``tunnel_height`` free layers high over
    ``tunnel_length`` sites; by default 2 layers, 6 sites), a step, or a narrow slot. The
    robot must get every module beyond the finish line (the tunnel's exit). All modules start
    in SLEEP except one SEED picked by the task, the foremost module lying on the ground (the
    paper's "initial seed determined centrally"). The behaviour is composed
    (:mod:`baselines.compose`): the modules first form a chain by the paper's chain rules,
    then hand over, module by module, to a crawl in which modules leave the chain's tail,
    travel along the chain and join it at its head, so the chain moves head first, one
    module thick.
Agents
    Every module (``module_0`` ... ``module_{N-1}``).
Observation
    The common observation (:mod:`proteo_env.spaces`) with one scent channel; ``hint`` is the
    goal direction ``(1, 0, 0)``; ``contact[0]`` fires next to the ground, the step, the roof
    or the slot's walls.
Actions
    The common action. Modes: the chain's 0 SLEEP, 1 SEARCH, 2 SEED, 3 FINAL, then the crawl's
    (:mod:`proteo_env.tasks.crawl`) 4 CRAWL, 5 HEAD, 6 BODY. Message values 1..15.
Reward, metrics, termination
    Locomotion's: ``progress``, ``success`` and ``time``; ``distance``, ``speed``, ``beyond``,
    ``components``, ``success``; success when every module is beyond the finish line,
    truncation at ``max_cycles``.
Parameters
    See :class:`SnakeParams` (locomotion's, with a tunnel 2 layers high and no step by
    default).
Paper section
    1 and 4.1 (chains "for moving over steps, snaking into holes or squeezing through narrow
    passages").
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

"""What a picture shows: one frame of a world, detached from the engine."""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class Scene:
    """One frame to draw.

    Attributes:
        positions: ``(N, 3)`` int module sites.
        modes: ``(N,)`` int mode of each module; ``mode_names[m]`` names mode ``m``.
        mode_names: the task's mode names.
        scent: ``(N,)`` int scent on channel 0 (shades SEARCH modules), or None.
        scent_max: the scent value that means "no scent".
        solid_sites: ``(S, 3)`` obstacle sites.
        object_sites: ``(O, 3)`` sites of the object.
        box: ``(X, Y, Z)`` box size.
        floor: ground below ``z = 0``.
        caption: text drawn in the top-left corner.
    """

    positions: np.ndarray
    modes: np.ndarray
    mode_names: tuple
    scent: np.ndarray | None = None
    scent_max: int = 65535
    solid_sites: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64))
    object_sites: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64))
    box: tuple = (0, 0, 0)
    floor: bool = False
    caption: str = ""

    @classmethod
    def from_world(cls, world, caption: str | None = None) -> Scene:
        """The scene of a :class:`~proteo_env.env.WorldView` (caption: the cycle by default)."""
        return cls(
            positions=world.positions,
            modes=world.modes,
            mode_names=tuple(world.mode_names),
            scent=world.scents[0] if world.scents.shape[0] else None,
            scent_max=world.scent_max,
            solid_sites=world.solid_sites,
            object_sites=world.object_sites,
            box=tuple(world.box),
            floor=world.floor,
            caption=f"cycle {world.cycle}" if caption is None else caption,
        )

    def scent_range(self) -> int:
        """The largest scent below ``scent_max`` on a SEARCH module (1 if none): the palest SEARCH shade."""
        if self.scent is None or "SEARCH" not in self.mode_names:
            return 1
        s = np.asarray(self.scent)[np.asarray(self.modes) == self.mode_names.index("SEARCH")]
        s = s[s < self.scent_max]
        return max(int(s.max()), 1) if s.size else 1

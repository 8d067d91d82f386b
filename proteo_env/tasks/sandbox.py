"""Sandbox: any layout, no reward, nothing to achieve.

The bare lattice: modules on any start layout (a generated blob, ball or line, or a layout text file), moving under
the chosen motion model; for exploring the physics, benchmarking, and writing new behaviours before defining a
task. Registered: ``sandbox-v0``. Paper section 2 (the robot system and its simulator).

The contract (layout, agents, observation, actions, reward, metrics, termination, parameters): docs/tasks/sandbox.md.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..core.world import LayoutError, check_module_memory
from ..layouts import Layout, ball_sites, blob_sites, line_sites, parse_layout, place_in_box
from .base import Task

GENERATORS = ("blob", "ball", "line")


@dataclass(frozen=True)
class SandboxParams:
    """Parameters of the sandbox.

    Attributes:
        layout: ``blob`` (random connected, new each episode), ``ball``, ``line``, or a path to a
            layout text file (see :mod:`proteo_env.layouts`).
        n_modules: number of modules of a generated layout.
        margin: free sites around a generated layout.
        floor: ground below the generated layout.
        n_modes: number of modes agents may show.
        n_channels: number of scent channels.
    """

    layout: str = "blob"
    n_modules: int = 30
    margin: int = 4
    floor: bool = False
    n_modes: int = 4
    n_channels: int = 1

    def __post_init__(self):
        if self.n_modules < 1:
            raise ValueError(f"n_modules={self.n_modules!r} is not allowed; allowed: an integer >= 1")
        check_module_memory(self.n_modules)
        if self.margin < 1:
            raise ValueError(f"margin={self.margin!r} is not allowed; allowed: an integer >= 1")
        if not 1 <= self.n_modes <= 64:
            raise ValueError(f"n_modes={self.n_modes!r} is not allowed; allowed: 1..64")
        if not 1 <= self.n_channels <= 4:
            raise ValueError(f"n_channels={self.n_channels!r} is not allowed; allowed: 1..4")
        if self.layout not in GENERATORS and not self.layout.endswith(".txt"):
            raise ValueError(
                f"layout={self.layout!r} is not allowed; allowed: {', '.join(GENERATORS)} "
                "or a path to a .txt layout file"
            )


class Sandbox(Task):
    name = "sandbox"
    demo_settings = {"n_modules": 40, "max_cycles": 200}
    version = 0
    Params = SandboxParams

    def __init__(self, params=None):
        super().__init__(params)
        p = self.params
        self.modes = tuple(f"MODE_{i}" for i in range(p.n_modes))
        self.n_channels = p.n_channels
        self.surface_channels = (False,) * p.n_channels
        self.passive_role = (1,) * p.n_channels

    def build_layout(self, rng):
        p = self.params
        if p.layout.endswith(".txt"):
            from pathlib import Path

            path = Path(p.layout)
            if not path.is_file():
                raise LayoutError(f"layout={p.layout!r}: no such file; allowed: a path to a layout text file")
            return parse_layout(path.read_text())
        if p.layout == "blob":
            sites = blob_sites(p.n_modules, rng, flat=p.floor)
        elif p.layout == "ball":
            sites = ball_sites(p.n_modules)
        else:
            sites = line_sites(p.n_modules)
        sites, size = place_in_box(sites, margin=p.margin, floor=p.floor)
        return Layout(size=size, modules=sites, floor=p.floor)

    def metrics(self, world):
        return {"components": float(world.n_components())}

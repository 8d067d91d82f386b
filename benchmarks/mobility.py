"""Mobility per motion model: the share of modules with at least one legal move.

Measured on a compact 300-module ball, random connected 300-module blobs (mean over seeds)
and a straight 20-module chain, with connectivity kept (the action mask's definition).

Usage::

    python benchmarks/mobility.py --blob-seeds 10
"""

from __future__ import annotations

import argparse

import numpy as np

from proteo_env.core.motion import MOTION_MODELS
from proteo_env.core.world import Physics, World
from proteo_env.layouts import ball_sites, blob_sites, line_sites, place_in_box
from proteo_env.spaces import ObservationBuffers


def mobile_share(sites: np.ndarray, motion_model: str) -> float:
    """Share of modules of a free-floating structure with at least one legal move."""
    sites, size = place_in_box(sites, margin=3)
    world = World(size=size, positions=sites, n_agents=len(sites), physics=Physics(motion_model=motion_model))
    buffers = ObservationBuffers(len(sites), 12, 1)
    world.observe(buffers)
    return float((buffers.action_mask[:, 1:].sum(axis=1) > 0).mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--blob-seeds", type=int, default=10)
    args = parser.parse_args()
    shapes = {
        "300-module ball": [ball_sites(300)],
        f"300-module random blob (mean of {args.blob_seeds})": [
            blob_sites(300, np.random.default_rng(s)) for s in range(args.blob_seeds)
        ],
        "20-module straight chain": [line_sites(20)],
    }
    print("| motion model | " + " | ".join(shapes) + " |")
    print("|---|" + "---|" * len(shapes))
    for model in MOTION_MODELS:
        cells = [np.mean([mobile_share(s, model) for s in group]) for group in shapes.values()]
        print(f"| `{model}` | " + " | ".join(f"{100 * c:.1f} %" for c in cells) + " |")


if __name__ == "__main__":
    main()

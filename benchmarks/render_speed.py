"""Rendering speed: frames per second of ``proteo_env.render.Renderer`` against scene size.

For each size N it builds a random connected blob of N modules resting on the floor, gives
the modules random chain modes (SLEEP, SEARCH, SEED, FINAL) and scents, and renders it to an
RGB array repeatedly while the camera turns 7 degrees a frame (so nothing is reused between
frames but the figure). The first frame (figure set-up, matplotlib's first draw) is timed
apart; the rate is over the frames after it. Every frame selects the visible faces,
projects and sorts them and rasterises them with matplotlib's Agg.

Usage::

    python benchmarks/render_speed.py --sizes 200 2000 20000 --frames 10 --markdown docs/speed/render.md

Results go to stdout as a markdown table and, with ``--json``/``--markdown``, to files together
with the machine and library versions.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np
from machine_info import describe


def scene_of_size(n: int, seed: int):
    from proteo_env.layouts import blob_sites, place_in_box
    from proteo_env.render import Scene

    rng = np.random.default_rng(seed)
    sites, size = place_in_box(blob_sites(n, rng, flat=True), margin=2, floor=True)
    return Scene(
        positions=sites,
        modes=rng.integers(0, 4, n),
        mode_names=("SLEEP", "SEARCH", "SEED", "FINAL"),
        scent=rng.integers(0, 20, n),
        box=size,
        floor=True,
        caption=f"{n} modules",
    )


def bench_size(n: int, frames: int, width: int, height: int, seed: int) -> dict:
    from proteo_env.render import Renderer

    scene = scene_of_size(n, seed)
    started = time.perf_counter()
    renderer = Renderer({"width": width, "height": height, "azimuth": -50.0})
    image = renderer.render(scene)
    first = time.perf_counter() - started
    assert image.shape == (height, width, 3)
    faces = []
    started, cpu_started = time.perf_counter(), time.process_time()
    for k in range(frames):
        renderer.camera = dataclasses.replace(renderer.camera, azimuth=-50.0 + 7.0 * (k + 1))
        renderer.render(scene)
        faces.append(renderer.n_faces)
    seconds, cpu_seconds = time.perf_counter() - started, time.process_time() - cpu_started
    renderer.close()
    return {
        "modules": n,
        "frames": frames,
        "first_frame_s": first,
        "seconds": seconds,
        "fps": frames / seconds,
        "fps_cpu_time": frames / cpu_seconds,
        "faces_per_frame": float(np.mean(faces)),
        "image": f"{width}x{height}",
    }


def table(rows: list[dict]) -> str:
    lines = [
        "| modules | faces drawn per frame | frames per second | per CPU second | first frame (s) | image |",
        "|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['modules']:,} | {r['faces_per_frame']:,.0f} | {r['fps']:.2f} | {r['fps_cpu_time']:.2f} | "
            f"{r['first_frame_s']:.2f} | {r['image']} |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[200, 2000, 20000])
    parser.add_argument("--frames", type=int, default=10, help="timed frames per size")
    parser.add_argument("--width", type=int, default=800)
    parser.add_argument("--height", type=int, default=600)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", default=None, help="write results and machine to this JSON file")
    parser.add_argument("--markdown", default=None, help="write the table and machine to this markdown file")
    args = parser.parse_args(argv)

    rows = [bench_size(n, args.frames, args.width, args.height, args.seed) for n in args.sizes]
    info = describe("numpy", "matplotlib", "PIL", rasteriser="matplotlib Agg")
    text = table(rows)
    described = ", ".join(f"{k} {v}" for k, v in info.items())
    print(text)
    print(f"\nmachine: {described}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"machine": info, "results": rows}, f, indent=2)
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write(
                "# Rendering speed\n\n"
                "From `python benchmarks/render_speed.py --sizes "
                f"{' '.join(map(str, args.sizes))} --frames {args.frames}`: random connected blobs "
                "on the floor, modules in random chain modes, the camera turning 7 degrees a frame; "
                "each frame selects the visible faces, projects, sorts, shades and rasterises them "
                "(matplotlib Agg) into an RGB array. The first frame (figure set-up) is timed apart. "
                "Frames per second is wall-clock; per CPU second divides by the process's CPU time, "
                "what one idle core would give (the machine may be shared: its load is recorded).\n\n"
                f"{text}\n\nMachine: {described}.\n"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

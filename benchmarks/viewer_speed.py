"""Playback speed of the browser viewer (``proteo view``) in headless Chromium against episode size.

For each size N it builds an episode of N modules: a random connected blob resting on the floor
(as ``benchmarks/render_speed.py``), then ``--frames`` cycles in which 5% of the modules step to a
neighbour site, 1% change mode (chain modes SLEEP, SEARCH, SEED, FINAL) and every scent changes by
-1, 0 or 1. It writes the viewer page, opens it in headless Chromium (WebGL on SwiftShader, the
CPU rasteriser: no GPU) and measures:

* load time: from navigation start to the page being ready (data inflated, first picture drawn),
  as the page reports it (``performance.now()``), and the page's size;
* playback: for ``--seconds`` the page advances one cycle per animation frame (looping), through
  the same path as the play button (seek, instance update, chart cursor, draw); frames per
  second is the pictures drawn per wall-clock second; the frame time is the mean interval
  between animation frames, and the script time the part spent in JavaScript (seek + draw calls).

Usage::

    python benchmarks/viewer_speed.py --sizes 200 2000 20000 --markdown docs/speed/viewer.md

Results go to stdout as a markdown table and, with ``--json``/``--markdown``, to files together
with the machine, the browser and the load average.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
from machine_info import describe

PLAYBACK = """
new Promise((resolve) => {
  const viewer = window.proteoViewer, frames = viewer.state().frames;
  const intervals = [], scripts = [];
  let start = null, last = null;
  function next(now) {
    if (start === null) start = now;
    if (last !== null) intervals.push(now - last);
    last = now;
    if (now - start >= SECONDS * 1000) {
      resolve({ frames: intervals.length, seconds: (now - start) / 1000, intervals, scripts });
      return;
    }
    const t0 = performance.now();
    viewer.seek((viewer.state().frame + 1) % frames);
    viewer.render();
    scripts.push(performance.now() - t0);
    requestAnimationFrame(next);
  }
  requestAnimationFrame(next);
})
"""


def episode_of_size(n: int, frames: int, seed: int):
    """A synthetic :class:`~proteo_env.recording.Recording` of ``n`` modules and ``frames`` cycles."""
    from proteo_env.core.lattice import DIRECTIONS
    from proteo_env.layouts import blob_sites, place_in_box
    from proteo_env.recording import Recording

    rng = np.random.default_rng(seed)
    sites, box = place_in_box(blob_sites(n, rng, flat=True), margin=2, floor=True)
    t = frames + 1
    steps = np.zeros((t, n, 3), dtype=np.int32)
    movers = rng.random((t, n)) < 0.05
    movers[0] = False
    steps[movers] = DIRECTIONS[rng.integers(0, 12, int(movers.sum()))]
    positions = sites[None].astype(np.int32) + np.cumsum(steps, axis=0)
    positions[..., 2] = np.maximum(positions[..., 2], 0)
    changes = rng.random((t, n)) < 0.01
    modes = (rng.integers(0, 4, (1, n)) + np.cumsum(changes * rng.integers(1, 4, (t, n)), axis=0)) % 4
    scents = np.clip(rng.integers(0, 20, (1, 1, n)) + np.cumsum(rng.integers(-1, 2, (t, 1, n)), axis=0), 0, 40)
    return Recording(
        task_id="sandbox-v0",
        overrides={},
        config={},
        seed=seed,
        policy="synthetic",
        success=False,
        package_version="benchmark",
        mode_names=("SLEEP", "SEARCH", "SEED", "FINAL"),
        n_agents=n,
        box=tuple(box),
        floor=True,
        scent_max=65535,
        cycles=np.arange(t, dtype=np.int64),
        positions=positions,
        modes=modes.astype(np.int32),
        scents=scents.astype(np.int32),
        anchored=np.zeros(n, dtype=bool),
        solid_sites=np.zeros((0, 3), dtype=np.int64),
        object_sites=np.zeros((0, 3), dtype=np.int64),
        series={"moved": movers.sum(axis=1).astype(float), "components": np.ones(t)},
    )


def bench_size(browser, n: int, frames: int, seconds: float, seed: int, folder: Path) -> dict:
    from proteo_env.render.webview import write_html

    page = write_html(episode_of_size(n, frames, seed), folder / f"episode_{n}.html")
    browser.open(page, timeout=300)
    if browser.evaluate("document.body.dataset.errors") != "0" or browser.errors():
        raise RuntimeError(
            f"the page reported errors: {browser.errors()} {browser.evaluate('document.body.dataset.error')}"
        )
    load_ms = float(browser.evaluate("document.body.dataset.loadMs"))
    result = browser.evaluate(PLAYBACK.replace("SECONDS", repr(float(seconds))), await_promise=True)
    intervals, scripts = np.array(result["intervals"]), np.array(result["scripts"])
    return {
        "modules": n,
        "cycles": frames,
        "page_mb": page.stat().st_size / 1e6,
        "load_s": load_ms / 1000,
        "frames": result["frames"],
        "fps": result["frames"] / result["seconds"],
        "frame_ms": float(intervals.mean()),
        "frame_ms_p95": float(np.percentile(intervals, 95)),
        "script_ms": float(scripts.mean()),
    }


def table(rows: list[dict]) -> str:
    lines = [
        "| modules | cycles | page (MB) | load (s) | frames per second | frame time (ms, mean / p95) | "
        "script per frame (ms) |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['modules']:,} | {r['cycles']:,} | {r['page_mb']:.2f} | {r['load_s']:.2f} | {r['fps']:.1f} | "
            f"{r['frame_ms']:.1f} / {r['frame_ms_p95']:.1f} | {r['script_ms']:.1f} |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[200, 2000, 20000])
    parser.add_argument("--frames", type=int, default=200, help="cycles in each episode")
    parser.add_argument("--seconds", type=float, default=5.0, help="playback time measured per size")
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=800)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", default=None, help="write results and machine to this JSON file")
    parser.add_argument("--markdown", default=None, help="write the table and machine to this markdown file")
    args = parser.parse_args(argv)

    from proteo_env.render.browser import Chromium

    with tempfile.TemporaryDirectory() as folder, Chromium(width=args.width, height=args.height) as browser:
        version = browser.call("Browser.getVersion")["product"]
        rows = []
        for n in args.sizes:
            rows.append(bench_size(browser, n, args.frames, args.seconds, args.seed, Path(folder)))
            print(table(rows[-1:]).splitlines()[-1], flush=True)
    info = describe("numpy", browser=version, webgl="SwiftShader (CPU)", window=f"{args.width}x{args.height}")
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
                "# Viewer playback speed\n\n"
                "From `python benchmarks/viewer_speed.py --sizes "
                f"{' '.join(map(str, args.sizes))} --frames {args.frames} --seconds {args.seconds:g}`: the page "
                "`proteo view` writes, opened in headless Chromium with WebGL on SwiftShader (software "
                "rendering on the CPU, no GPU), playing a synthetic episode one cycle per animation frame "
                "(5% of the modules step and 1% change mode each cycle, every scent changes). Load is "
                "from navigation start to the first picture (data inflated). Frames per second counts "
                "pictures drawn per wall-clock second; script is the JavaScript part of a frame (seek, "
                "instance update, draw calls); the rest is rasterising and compositing. The machine may "
                "be shared: its load is recorded. See `docs/guides/viewer.md` for the viewer and "
                "`docs/speed/render.md` for the matplotlib pictures.\n\n"
                f"{text}\n\nMachine: {described}.\n"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

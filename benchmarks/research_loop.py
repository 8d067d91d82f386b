"""The research loop against the engine: program evolution and the benchmark judge, before and
after the batched evaluator (:mod:`training.machinery.evaluator`), measured in one run.

Rows (module-cycles per second: the cycles of every episode times its modules, over wall-clock):

* ``engine``: the batched engine alone, one core: ``make_batched("sandbox-v0", 341, n_modules=12)``,
  random actions (uniform on every field, or each move drawn among the legal ones), step and
  observation, ``--cycles`` cycles; the faster of the two is the reference of ``of the engine``.
* ``evolution, per episode``: one generation's episodes of chain evolution
  (``configs/train/evolve_chain_full.yaml``: 12-module worlds, 300 cycles, variations of 10, 12
  and 14 modules) as evolution ran them before the evaluator: one world at a time through the
  per-agent dict API (:func:`~proteo_env.rollout.run_episode`), one core. The programs: the
  paper's chain program, ``--programs`` - 1 random ones and mutants of the paper's (the mix of
  a generation from random programs and from the paper's), each on ``--worlds`` worlds per
  variation.
* ``evolution, evaluator (W workers)``: the same episodes through :func:`training.machinery.evaluator.run_episodes`
  (after a first call that starts the worker processes and compiles); the results are checked
  equal to the per-episode ones, episode by episode.
* ``judge, per episode`` and ``judge, evaluator``: ``proteo eval --benchmark VERSION`` of each recipe
  of ``--recipes`` (every training seed, every split), with its episodes run one by one
  (:func:`training.judging.episodes.run_alone`, what the judge ran before) and through the
  evaluator; the two benchmark files are compared row by row (networks: the batched forward
  pass can differ in the last bits of a logit).

Usage::

    NUMBA_NUM_THREADS=1 python benchmarks/research_loop.py --out docs/speed/research_loop

prints the table and with ``--out`` writes ``<out>.json`` and ``<out>.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from machine_info import describe

EVOLVE_CONFIG = "configs/train/evolve_chain_full.yaml"


def engine_speed(cycles: int, legal: bool) -> float:
    """Module-cycles per second of the batched engine alone (one core); ``legal``: each move drawn
    among the legal ones (the action mask of the cycle's observation), else uniform on every field."""
    import proteo_env

    env = proteo_env.make_batched("sandbox-v0", 341, n_modules=12, max_cycles=10**9)
    nvec, rng = env.action_layout.nvec, np.random.default_rng(0)
    buffers = env.reset(seed=0)
    env.step_arrays(np.zeros((341, 12, len(nvec)), dtype=np.int64))
    started = time.perf_counter()
    for _ in range(cycles):
        actions = rng.integers(0, nvec, size=(341, 12, len(nvec)))
        if legal:
            actions[..., 0] = (
                (rng.random(buffers.action_mask.shape) * buffers.action_mask).argmax(axis=1).reshape(341, 12)
            )
        env.step_arrays(actions)
        buffers = env.observe_arrays()
    return 341 * 12 * cycles / (time.perf_counter() - started)


def evolution_episodes(
    n_programs: int, worlds: int, config: str = EVOLVE_CONFIG, seed: int = 0, task: str | None = None
) -> tuple[list, list[int]]:
    """One generation's episodes of the evolution ``config`` (its settings and variations, on its
    task or on the version ``task``) and each episode's module count: the paper's program of the task, random programs and
    mutants of the paper's in turn (drawn from ``seed``), each on ``worlds`` worlds per variation."""
    import proteo_env
    from baselines.program import format_program, load_program
    from proteo_env.config import load_yaml
    from training.trainers.evolve import generation_seeds, program_episodes
    from training.trainers.program_variation import ProgramSpace, mutate, random_program

    cfg = load_yaml(Path(config))
    cfg["task"] = task or cfg["task"]
    env = proteo_env.make(cfg["task"], **cfg["env"])
    name = type(env.task).name
    rng = np.random.default_rng(seed)
    paper = load_program(name, env)
    space = ProgramSpace.for_program(paper, type(env.task))
    programs = [paper]
    while len(programs) < n_programs:
        programs.append(random_program(space, rng, name) if len(programs) % 2 else mutate(programs[-1], space, rng))
    variations = [json.dumps({**cfg["env"], **v}, sort_keys=True) for v in cfg["variations"]]
    seeds = generation_seeds(np.random.SeedSequence(seed).spawn(3)[0], 0, worlds)
    episodes = program_episodes(cfg["task"], variations, [format_program(p) for p in programs], seeds)
    modules = {v: proteo_env.make_batched(cfg["task"], 1, **json.loads(v)).n_modules for v in variations}
    return episodes, [modules[e.overrides] for e in episodes]


def per_episode(episodes) -> list:
    """Every episode through the per-agent dict API, one world at a time (the path before the evaluator)."""
    import proteo_env
    from proteo_env.rollout import run_episode

    envs, out = {}, []
    for e in episodes:
        if e.overrides not in envs:
            envs[e.overrides] = proteo_env.make(e.task, **json.loads(e.overrides))
        env = envs[e.overrides]
        out.append(run_episode(env, e.controller.build(env, e.seed), seed=e.seed))
    return out


def same(a, b) -> bool:
    return (a.cycles, a.success, a.total_reward, a.metrics) == (b.cycles, b.success, b.total_reward, b.metrics)


def judge_once(version: str, recipe: Path, out: Path, per_episode_path: bool, workers: int) -> tuple[float, dict]:
    """Seconds of ``proteo eval --benchmark`` of ``recipe``'s seeds, and its document."""
    from training.judging import episodes, judge

    original = episodes.run_episodes
    if per_episode_path:

        def one_by_one(jobs, out_dir, *, ray, journal, progress, workers=None):
            from training.machinery.distributed import run_jobs
            from training.machinery.evaluator import episode_key

            alone = [(episode, "") for _, episode, _ in jobs]
            keys = [episode_key(episode) for episode, _ in alone]
            for (run, episode, _), result in zip(jobs, run_jobs(episodes.run_alone, alone, keys, progress=False)):
                run.add(episode.seed, result)

        episodes.run_episodes = one_by_one
    try:
        started = time.perf_counter()
        document = judge.judge(
            version, checkpoints=sorted(recipe.glob("seed_*")), out=out, workers=workers, progress=False, fresh=True
        )
        return time.perf_counter() - started, document
    finally:
        episodes.run_episodes = original


def rows_of(document: dict) -> list:
    """Each judged row's episodes: split, and per training seed its successes, cycles and returns."""
    return [
        (row["split"], [(run["successes"], run["cycles"], run["returns"]) for run in row["runs"]])
        for row in document["rows"]
    ]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--programs", type=int, default=24, help="programs of the generation (default 24)")
    parser.add_argument("--worlds", type=int, default=10, help="worlds per variation and program (default 10)")
    parser.add_argument("--cycles", type=int, default=300, help="cycles of the engine row (default 300)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="worker counts (default 1 2)")
    parser.add_argument(
        "--recipes",
        nargs="+",
        default=["v1:checkpoints/v1/grasp/kickstart_move", "v4:checkpoints/v4/grasp/evolve-paper_full"],
        help="judged recipes as PROTOCOL:FOLDER (default: grasp's kickstart networks under v1 and its "
        "programs evolved from the paper's under v4)",
    )
    parser.add_argument("--out", default=None, help="write <out>.json and <out>.md")
    args = parser.parse_args(argv)
    from training.machinery.evaluator import run_episodes

    rows = []
    engines = {legal: engine_speed(args.cycles, legal) for legal in (False, True)}
    engine = max(engines.values())
    """The reference: the faster of the two workloads."""
    for legal, speed in engines.items():
        rows.append(
            {
                "loop": f"engine (batched, sandbox, 341 x 12 modules, {'legal' if legal else 'uniform'} random actions, 1 core)",
                "seconds": None,
                "module_cycles_per_s": speed,
            }
        )
        print(f"{rows[-1]['loop']}: {speed / 1e3:.0f} k module-cycles/s", flush=True)

    episodes, modules = evolution_episodes(args.programs, args.worlds)
    per_episode(episodes[:3])  # compile
    started = time.perf_counter()
    reference = per_episode(episodes)
    seconds = time.perf_counter() - started
    work = sum(r.cycles * n for r, n in zip(reference, modules))
    rows.append(
        {
            "loop": f"evolution, per episode ({len(episodes)} chain episodes, 1 core)",
            "seconds": seconds,
            "episodes_per_s": len(episodes) / seconds,
            "module_cycles_per_s": work / seconds,
        }
    )
    print(f"{rows[-1]['loop']}: {work / seconds / 1e3:.0f} k module-cycles/s", flush=True)
    for w in args.workers:
        run_episodes(episodes, workers=w)  # start the workers, compile
        started = time.perf_counter()
        batched = run_episodes(episodes, workers=w)
        seconds = time.perf_counter() - started
        agree = sum(same(a, b) for a, b in zip(reference, batched))
        rows.append(
            {
                "loop": f"evolution, evaluator ({w} worker{'s' if w > 1 else ''})",
                "seconds": seconds,
                "episodes_per_s": len(episodes) / seconds,
                "module_cycles_per_s": work / seconds,
                "identical_episodes": f"{agree}/{len(episodes)}",
            }
        )
        print(
            f"{rows[-1]['loop']}: {work / seconds / 1e3:.0f} k module-cycles/s, {agree}/{len(episodes)} identical",
            flush=True,
        )

    for spec in args.recipes:
        version, _, folder = spec.partition(":")
        recipe = Path(folder)
        with tempfile.TemporaryDirectory() as tmp:
            before, reference_doc = judge_once(version, recipe, Path(tmp) / "before", True, 1)
            rows.append({"loop": f"judge {version}, per episode ({recipe}, 1 core)", "seconds": before})
            print(f"{rows[-1]['loop']}: {before:.1f} s", flush=True)
            for w in args.workers:
                judge_once(version, recipe, Path(tmp) / f"warm{w}", False, w)
                after, document = judge_once(version, recipe, Path(tmp) / f"after{w}", False, w)
                equal = sum(a == b for a, b in zip(rows_of(reference_doc), rows_of(document)))
                rows.append(
                    {
                        "loop": f"judge {version}, evaluator ({recipe.name}, {w} worker{'s' if w > 1 else ''})",
                        "seconds": after,
                        "speedup": before / after,
                        "identical_rows": f"{equal}/{len(document['rows'])}",
                    }
                )
                print(f"{rows[-1]['loop']}: {after:.1f} s ({before / after:.1f}x), rows identical {equal}", flush=True)
    for row in rows:
        if "module_cycles_per_s" in row:
            row["of_engine"] = row["module_cycles_per_s"] / engine
    info = describe("numpy", "numba", numba_threads=os.environ.get("NUMBA_NUM_THREADS"))
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.with_suffix(".json").write_text(json.dumps({"machine": info, "args": vars(args), "rows": rows}, indent=2))
        out.with_suffix(".md").write_text(markdown(rows, info))
    print(markdown(rows, info))
    return 0


def markdown(rows: list, info: dict) -> str:
    lines = [
        "# The research loop against the engine",
        "",
        "`NUMBA_NUM_THREADS=1 python benchmarks/research_loop.py --out docs/speed/research_loop` (what each row "
        "runs: the script's docstring). Module-cycles per second: the episodes' cycles times their modules "
        "over wall-clock; *of the engine*: over the faster engine row of the same run; *identical*: episodes "
        "(evolution) or judged rows (every training seed's episodes of a split) equal to the per-episode path's.",
        "",
        f"Machine: {info['cpu']}, {info['cores']} cores, load average {info['load_average_1min']} at the end; "
        f"numba {info['numba']}.",
        "",
        "| loop | seconds | module-cycles/s | of the engine | speed-up | identical |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['loop']} | {'-' if r['seconds'] is None else format(r['seconds'], '.1f')} | "
            f"{r['module_cycles_per_s'] / 1e3:,.0f} k | {r['of_engine']:.3f} |"
            if "module_cycles_per_s" in r
            else f"| {r['loop']} | {r['seconds']:.1f} | - | - |"
        )
        lines[-1] += f" {r['speedup']:.1f}x |" if "speedup" in r else " - |"
        lines[-1] += f" {r.get('identical_episodes', r.get('identical_rows', '-'))} |"
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())

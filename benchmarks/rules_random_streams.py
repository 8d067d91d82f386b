"""How often do the hand-coded rules succeed, and how much does it depend on their random draws?
The same worlds, the rules with several random streams.

    python benchmarks/rules_random_streams.py --task branch-v0 --env "{n_modules: 40, T: 4, B: 3, max_cycles: 200}" --seeds 50
    python benchmarks/rules_random_streams.py --task grasp-v0 --env "{n_modules: 100, distance: 3, max_cycles: 300}" --seeds 50

For every world seed ``s`` of ``--first-seed .. --first-seed + --seeds - 1`` (the study's
held-out seeds by default), four episodes of the task's rules:

- ``full, as proteo eval seeds them``: the rules at control level ``full``, their generator
  seeded with ``s``, the seed the world's own generator gets (what ``proteo eval`` does for
  every policy: ``run_episode`` resets env and policy with the episode's seed);
- ``full, independent stream``: the same, the rules' generator seeded from
  ``SeedSequence([s, 1])``, a stream unrelated to the world's;
- ``full, the autopilot's stream``: the same, the rules' generator the one that world ``s``'s
  autopilot gets at level ``move`` (the autopilot itself, copied at the episode's start, acting
  at ``full``);
- ``move, the rules' own moves``: control level ``move``, an instance of the rules (seeded as
  the second line) chooses every module's move and the level's autopilot (another instance,
  seeded from the world's generator) the rest: what a perfect clone of the rules' moves
  would do, the reference for learned ``move`` controllers. Where it matches the line above
  world for world, the autopilot's draws decide the world and the moves do not.

Prints a table (successes, median cycles to success) and, with ``--out``, writes it as JSON.

``--split RESULTS`` (the ``results.json`` of a ``proteo eval`` run of the same task, settings
and seeds) also splits every ``move`` row of that evaluation by the third variant's verdict:
its successes on the worlds where the rules succeed with the autopilot's generator and on the
worlds where they fail, and on how many worlds it agrees with them.

    proteo eval --config my_eval.yaml --tasks branch --out out/branch   # seeds: 50, first_seed: 1000
    python benchmarks/rules_random_streams.py --seeds 50 --split out/branch/results.json
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path

import numpy as np

import proteo_env
from baselines import make_policy
from proteo_env.config import ConfigError, parse_yaml
from training.judging import record
from training.judging.report import Run

VARIANTS = (
    "full, as proteo eval seeds them",
    "full, independent stream",
    "full, the autopilot's stream",
    "move, the rules' own moves",
)


def independent_seed(seed: int) -> int:
    """A seed for the rules' generator unrelated to the stream ``default_rng(seed)`` gives the world."""
    return int(np.random.SeedSequence([seed, 1]).generate_state(1, np.uint64)[0] >> 1)


def autopilot_of(move, seed: int):
    """A copy of the autopilot that world ``seed`` gets in ``move`` (an env at level ``move``), as
    it stands at the episode's start: the rules with the generator seeded from the world's."""
    move.reset(seed=seed)
    return copy.deepcopy(move.batch.autopilots[0])


def episode(env, policy, world_seed: int, policy_seed: int | None = None) -> tuple[bool, int]:
    """One episode of world ``world_seed`` with ``policy`` choosing the fields of ``env``'s control
    level (its generator seeded with ``policy_seed``; ``None``: the one it has): ``(success, cycles)``."""
    env.reset(seed=world_seed)
    policy.reset(policy_seed)
    while True:
        result = env.step_arrays(policy.act_arrays(env.observe_arrays()))
        if result.terminated[0] or result.truncated[0]:
            return bool(result.terminated[0]), env.cycle


def measure(task: str, overrides: dict, seeds: list[int]) -> dict:
    """``{variant: {"success": [bool per seed], "cycles": [int per seed]}}`` for :data:`VARIANTS`."""
    full = proteo_env.make(task, **overrides)
    move = proteo_env.make(task, **overrides, control="move")
    at_full, at_move = make_policy(full.task.name, full), make_policy(move.task.name, move)
    out = {name: {"success": [], "cycles": []} for name in VARIANTS}
    for seed in seeds:
        runs = (
            episode(full, at_full, seed, seed),
            episode(full, at_full, seed, independent_seed(seed)),
            episode(full, autopilot_of(move, seed), seed),
            episode(move, at_move, seed, independent_seed(seed)),
        )
        for name, (success, cycles) in zip(VARIANTS, runs):
            out[name]["success"].append(success)
            out[name]["cycles"].append(cycles)
    return out


def table(results: dict, n: int) -> str:
    """The markdown table of :func:`measure`'s results over ``n`` seeds."""
    lines = ["| rules | success | median cycles to success |", "|---|---|---|"]
    for name, r in results.items():
        cycles = [c for c, s in zip(r["cycles"], r["success"]) if s]
        median = f"{np.median(cycles):.0f}" if cycles else "–"
        lines.append(f"| {name} | {sum(r['success'])}/{n} | {median} |")
    return "\n".join(lines)


def load_evaluation(path: Path, task: str, overrides: dict) -> list[Run]:
    """The runs of the rows of ``proteo eval``'s ``results.json`` at ``path`` that run ``task`` at
    level ``move`` (random moves left out), checked against ``overrides``; raises ``ValueError``."""
    try:
        rows = record.results_of(record.load(path, field="--split"))
    except ConfigError as error:
        raise ValueError(str(error)) from None
    rows = [r for r in rows if r.task == task and r.level == "move" and r.kind != "random"]
    if not rows:
        raise ValueError(f"--split={str(path)!r} has no row of {task} at control level move; allowed: one that has")
    if any(r.env != overrides for r in rows):
        raise ValueError(
            f"--split={str(path)!r} evaluated other settings ({rows[0].env}); allowed: an evaluation with --env {overrides}"
        )
    return [run for r in rows for run in r.runs]


def split(results: dict, seeds: list[int], runs: list[Run]) -> list[dict]:
    """Each run's successes split by the verdict of ``full, the autopilot's stream`` on the
    worlds both ran: ``{"policy", "where_rules_succeed": [successes, worlds], "where_rules_fail":
    [successes, worlds], "agree": [worlds agreeing, worlds]}``."""
    verdict = dict(zip(seeds, results[VARIANTS[2]]["success"]))
    out = []
    for run in runs:
        pairs = [(verdict[s], ok) for s, ok in zip(run.seeds, run.successes) if s in verdict]
        succeed = [ok for v, ok in pairs if v]
        fail = [ok for v, ok in pairs if not v]
        agree = [v == ok for v, ok in pairs]
        out.append(
            {
                "policy": run.source,
                "where_rules_succeed": [sum(succeed), len(succeed)],
                "where_rules_fail": [sum(fail), len(fail)],
                "agree": [sum(agree), len(agree)],
            }
        )
    return out


def split_table(rows: list[dict]) -> str:
    """The markdown table of :func:`split`'s rows."""
    lines = [
        "| policy at `move` | successes where the autopilot's rules succeed | where they fail | worlds agreeing |",
        "|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['policy']} | {'/'.join(map(str, r['where_rules_succeed']))} "
            f"| {'/'.join(map(str, r['where_rules_fail']))} "
            f"| {'/'.join(map(str, r['agree']))} |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="branch-v0")
    parser.add_argument("--env", default="{n_modules: 40, T: 4, B: 3, max_cycles: 200}", help="overrides, as YAML")
    parser.add_argument("--first-seed", type=int, default=1000)
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--out", type=Path, default=None, help="write the results as JSON here")
    parser.add_argument("--split", type=Path, default=None, help="a results.json of proteo eval to split")
    args = parser.parse_args(argv)
    try:
        overrides = parse_yaml(args.env, "--env") or {}
    except ConfigError:
        overrides = None
    if not isinstance(overrides, dict):
        parser.error(f"--env={args.env!r} is not allowed; allowed: a YAML mapping of env overrides")
    if args.seeds < 1:
        parser.error(f"--seeds={args.seeds} is not allowed; allowed: an integer >= 1")
    try:
        proteo_env.make(args.task, **overrides, control="move")
    except (ConfigError, ValueError) as error:
        parser.error(f"--task/--env: {error}")
    runs = None
    if args.split is not None:
        try:
            runs = load_evaluation(args.split, args.task, overrides)
        except ValueError as error:
            parser.error(str(error))
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    results = measure(args.task, overrides, seeds)
    print(table(results, len(seeds)))
    measured = {"task": args.task, "env": overrides, "seeds": seeds, "results": results}
    if runs is not None:
        measured["split"] = split(results, seeds, runs)
        print()
        print(split_table(measured["split"]))
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(measured, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Native PPO's throughput: agent-steps per second of the trainer's settings that buy speed (worlds
split over worker processes, the update on both cores, ReLU hidden layers), beside the batched
engine on the same worlds, measured in one run.

    NUMBA_NUM_THREADS=1 python benchmarks/ppo_throughput.py --out docs/speed/ppo_throughput

The worlds are those of ``configs/train/ppo_chain_move.yaml`` (64 chain-v1 worlds of 12
modules at ``move``). Each run (:data:`RUNS`: a label, the trainer's flags on top of the config's
and seed 0, and a group) trains ``training/trainers/ppo.py`` for ``--steps`` agent-steps with one
torch thread for the rollouts and takes its rate from ``progress.csv`` over the rows after
``--warmup`` agent-steps (before them each process compiles its worlds' batched autopilot:
:data:`proteo_env.batched.ONE_CALL_AFTER` world-cycles, the more the fewer worlds it holds), split
as the trainer logs it into the environment step (with the encoding of the observations), the
forward passes of the rollouts and the update. Runs of one group must end with the same network,
bit for bit (the script fails otherwise): worker processes do not change a run. The engine's
rate is the batched env alone (``step_arrays`` and ``observe_arrays`` of the same 64 worlds at
``full``, one process), timed after a warm-up of the same length, with uniformly random actions
(the speed suite's workload: most moves are refused at once) and with the move drawn among the
legal ones (every module that can move does: more connectivity checks); the ratio "of the
engine" is taken against the faster of the two. Beside them, 341 sandbox worlds of 12 modules
with uniformly random actions: the engine without a task's scoring. The machine and its load
average at the end are written beside the figures.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from machine_info import describe

from proteo_env.config import load_yaml

CONFIG = "configs/train/ppo_chain_move.yaml"
RUNS = (
    ("the config", (), "tanh, 1 thread"),
    ("2 workers", ("--workers", "2"), "tanh, 1 thread"),
    ("2 threads everywhere", ("--threads", "2"), "tanh, 2 threads everywhere"),
    ("update on 2 threads", ("--update-threads", "2"), "tanh, 2 threads"),
    ("relu", ("--activation", "relu"), "relu, 1 thread"),
    ("relu, update on 2 threads", ("--activation", "relu", "--update-threads", "2"), "relu, 2 threads"),
    (
        "relu, update on 2 threads, 2 workers",
        ("--activation", "relu", "--update-threads", "2", "--workers", "2"),
        "relu, 2 threads",
    ),
)
"""``(label, flags, group)`` of every run: the trainer's flags on top of the config's; runs of a group
make the same run."""


def engine_rate(cycles: int, legal: bool, sandbox: bool = False) -> float:
    """Module-cycles per second of the config's worlds stepped and observed by the batched env
    alone, with uniformly random actions (``legal``: the move drawn among the legal ones); with
    ``sandbox``, 341 worlds of the sandbox task of the same size instead (no task to score)."""
    import proteo_env

    cfg = load_yaml(Path(CONFIG))
    if sandbox:
        env = proteo_env.make_batched("sandbox-v0", 341, n_modules=cfg["env"]["n_modules"], max_cycles=10**9)
    else:
        env = proteo_env.make_batched(cfg["task"], cfg["n_envs"], **{**cfg["env"], "max_cycles": 10**9})
    rng = np.random.default_rng(0)
    mask = env.reset(seed=0).action_mask
    nvec = env.action_layout.nvec

    def run(n: int) -> None:
        nonlocal mask
        for _ in range(n):
            actions = rng.integers(0, nvec, size=(env.n_envs, env.n_agents, len(nvec)))
            if legal:
                moves = np.argmax(mask * rng.random(mask.shape), axis=1)
                actions[..., 0] = moves.reshape(env.n_envs, env.n_agents)
            env.step_arrays(actions)
            mask = env.observe_arrays().action_mask

    run(cycles)
    started = time.perf_counter()
    run(cycles)
    return cycles * env.n_envs * env.n_agents / (time.perf_counter() - started)


def train(flags: tuple[str, ...], steps: int, run_dir: Path) -> dict:
    """One PPO run of the config with the trainer's ``flags`` on top; its rows of ``progress.csv``."""
    cmd = [sys.executable, "-m", "training.trainers.ppo", "--config", CONFIG, "--seed", "0", "--run-dir", str(run_dir)]
    cmd += [
        "--total-steps",
        str(steps),
        "--time-limit-minutes",
        "0",
        "--threads",
        "1",
        *flags,
    ]  # a flag given twice: the last
    cmd += ["--progress-bar", "false", "--tensorboard", "false", "--checkpoint-every", str(10 * steps)]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    with open(run_dir / "progress.csv") as f:
        return list(csv.DictReader(f))


def steady(rows: list[dict], warmup: int) -> dict:
    """Agent-steps per second over the rows after ``warmup`` agent-steps, and the split of that time."""
    done = [int(r["agent_steps"]) for r in rows]
    kept = [r for r, previous in zip(rows[1:], done) if previous >= warmup]
    parts = {
        name: sum(float(r[f"time/{name}_seconds"]) for r in kept) for name in ("env", "encode", "forward", "update")
    }
    steps = int(kept[-1]["agent_steps"]) - int(rows[len(rows) - len(kept) - 1]["agent_steps"])
    return {"agent_steps": steps, "agent_steps_per_s": steps / sum(parts.values()), "seconds": parts}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", nargs="+", default=[label for label, _, _ in RUNS], help="labels of RUNS to run")
    parser.add_argument("--steps", type=int, default=4_000_000, help="agent-steps of each run")
    parser.add_argument("--warmup", type=int, default=2_000_000, help="agent-steps left out of the rate")
    parser.add_argument("--engine-cycles", type=int, default=2000)
    parser.add_argument("--out", default="docs/speed/ppo_throughput", help="writes OUT.json and OUT.md")
    args = parser.parse_args(argv)
    engines = {"uniform": engine_rate(args.engine_cycles, False), "legal": engine_rate(args.engine_cycles, True)}
    engine = max(engines.values())
    engines["sandbox"] = engine_rate(args.engine_cycles, False, sandbox=True)
    unknown = sorted(set(args.runs) - {label for label, _, _ in RUNS})
    if unknown:
        parser.error(f"--runs {unknown} is not allowed; allowed: {', '.join(label for label, _, _ in RUNS)}")
    runs, digests = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for i, (label, flags, group) in enumerate(RUNS):
            if label not in args.runs:
                continue
            rows = train(flags, args.steps, Path(tmp) / str(i))
            runs[label] = {**steady(rows, args.warmup), "flags": list(flags), "group": group}
            digest = hashlib.sha256((Path(tmp) / str(i) / "final" / "policy.pt").read_bytes()).hexdigest()
            digests.setdefault(group, set()).add(digest)
    same = all(len(d) == 1 for d in digests.values())
    machine = describe("torch", "numba")
    result = {"engine_module_cycles_per_s": engines, "runs": runs, "same_network": same, "machine": machine}
    result["config"], result["steps"], result["warmup"] = CONFIG, args.steps, args.warmup
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(result, indent=1))
    one = next(iter(runs.values()))["agent_steps_per_s"]
    lines = [
        "# Native PPO's throughput",
        "",
        f"`NUMBA_NUM_THREADS=1 python benchmarks/ppo_throughput.py --out {args.out}` (one run; {machine['cpu']}, "
        f"{machine['cores']} cores, load average {machine['load_average_1min']} at the end; torch {machine['torch']}, "
        f"numba {machine['numba']}). `{CONFIG}`, seed 0, {args.steps:,} agent-steps a run, the rate over those after "
        f"{args.warmup:,}; the batched engine alone on the same 64 worlds (one process): {engines['uniform']:,.0f} "
        f"module-cycles/s with uniformly random actions, {engines['legal']:,.0f} with random legal moves "
        f"(the chain task scores every world after every cycle, in one kernel call); 341 sandbox worlds of 12 modules, "
        f"which no task scores: {engines['sandbox']:,.0f}.",
        "",
        "| run | the trainer's flags | agent-steps/s | x the first | of the engine | of the sandbox engine "
        "| env step + encoding s | forward s | update s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for label, run in runs.items():
        s = run["seconds"]
        flags = " ".join(run["flags"]) or "none"
        lines.append(
            f"| {label} | `{flags}` | {run['agent_steps_per_s']:,.0f} | {run['agent_steps_per_s'] / one:.2f} | "
            f"{run['agent_steps_per_s'] / engine:.3f} | {run['agent_steps_per_s'] / engines['sandbox']:.3f} | "
            f"{s['env'] + s['encode']:.2f} | {s['forward']:.2f} | "
            f"{s['update']:.2f} |"
        )
    lines += [
        "",
        "Runs that must make the same run (the same activation and update threads, any workers) end with the same "
        "network, bit for bit: " + ("yes." if same else "**no**."),
        "",
    ]
    out.with_suffix(".md").write_text("\n".join(lines))
    print("\n".join(lines))
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())

"""The ``proteo`` command line: ``proteo demo`` (the main job) and ``proteo run CONFIG``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

DEMO_SETTINGS = {
    "sandbox": {"n_modules": 40, "max_cycles": 200},
    "chain": {"n_modules": 40, "max_cycles": 3000},
}
"""Per-task settings of ``proteo demo`` (tasks not listed run with their defaults)."""


def _run(task_id: str, overrides: dict, policy_name: str | None, seed: int, out: Path | None):
    from baselines import make_policy

    from . import make
    from .rollout import run_episode
    from .snapshot import save_snapshot

    from tqdm import tqdm

    env = make(task_id, **overrides)
    policy = make_policy(policy_name or env.task.default_policy, env, seed=seed)
    label = f"{env.task.task_id()} / {policy.name}"
    with tqdm(total=env.max_cycles, desc=label, unit="cycle", leave=False) as bar:
        started = time.perf_counter()
        env.reset(seed=seed)
        if out is not None:
            save_snapshot(env.world, out / f"{env.task.name}_start.png", title=f"{label}: start")
        result = run_episode(env, policy, seed=seed, progress=lambda info: bar.update(1))
        seconds = time.perf_counter() - started
    if out is not None:
        save_snapshot(env.world, out / f"{env.task.name}_end.png",
                      title=f"{label}: cycle {result.cycles}{' (success)' if result.success else ''}")
    return {"task": env.task.task_id(), "policy": policy.name, "modules": env.engine.n_modules,
            "cycles": result.cycles, "success": result.success, "reward": result.total_reward,
            "seconds": seconds, "metrics": result.metrics}


def _table(rows: list[dict]) -> str:
    head = ["task", "policy", "modules", "cycles", "success", "reward", "seconds", "metrics"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        metrics = ", ".join(f"{k}={v:g}" for k, v in r["metrics"].items())
        lines.append(f"| {r['task']} | {r['policy']} | {r['modules']} | {r['cycles']} | "
                     f"{'yes' if r['success'] else 'no'} | {r['reward']:.3f} | {r['seconds']:.1f} | {metrics} |")
    return "\n".join(lines)


def demo(args) -> int:
    from .registry import TASKS

    out = Path(args.out)
    rows = []
    for task_id, cls in sorted(TASKS.items()):
        overrides = dict(DEMO_SETTINGS.get(cls.name, {}))
        if args.motion_model:
            overrides["motion_model"] = args.motion_model
        rows.append(_run(task_id, overrides, None, args.seed, out))
    print(_table(rows))
    print(f"\npictures: {out.resolve()}")
    return 0


def run(args) -> int:
    from .config import load_run_config

    task_id, overrides = load_run_config(args.config)
    rows = [_run(task_id, overrides, args.policy, seed, Path(args.out) if args.out else None)
            for seed in range(args.seed, args.seed + args.episodes)]
    print(_table(rows))
    successes = sum(r["success"] for r in rows)
    print(f"\nsuccess {successes}/{len(rows)}")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="proteo", description="Proteo lattice robot simulator")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("demo", help="run every registered task with its default policy")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="out/demo", help="folder for the pictures")
    p.add_argument("--motion-model", default=None, help="override the motion model of every task")
    p.set_defaults(func=demo)
    p = sub.add_parser("run", help="run a YAML config and report its metrics")
    p.add_argument("config", help="path to a YAML run config (see configs/)")
    p.add_argument("--policy", default=None, help="policy name (default: the task's hand-coded one)")
    p.add_argument("--seed", type=int, default=0, help="first seed")
    p.add_argument("--episodes", type=int, default=1)
    p.add_argument("--out", default=None, help="folder for pictures (none if omitted)")
    p.set_defaults(func=run)
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ValueError as err:
        print(f"proteo: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

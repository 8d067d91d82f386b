"""Does the reward prefer the paper's behaviour? The hand-coded policy against degenerate strategies.

    python benchmarks/degenerate_strategies.py                      # every task with rules, every version
    python benchmarks/degenerate_strategies.py --tasks chain --seeds 20

For each task, at the settings of ``configs/eval.yaml`` (the training sizes), on the held-out
seeds 1000..1009, it runs the hand-coded policy and strategies a reward must not prefer:

- ``idle``: every module stays and keeps its mode, relays scent, sends nothing;
- ``random``: uniform over legal moves and every other field;
- per task: the winding chain (the MaskablePPO checkpoint that folds the blob into a winding
  path), every module switching to NODE (the branch shortcut the evolved network found), the
  table that never settles (the MaskablePPO checkpoint that keeps creating and disbanding
  legs), the table rules that never grow a leg (``p_max = p_min = 0``) and those that never
  disband one (``p_min = 0``: a static table once grown), the grasp learner that
  approaches and never wraps (MaskablePPO).

and prints one markdown table per task id (every registered version of the task): mean return
with a 95 % t interval, return per cycle, successes and cycles to success. ``--out FILE`` also
writes the tables as JSON.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

import proteo_env  # noqa: E402
from baselines import POLICIES, make_policy  # noqa: E402
from baselines.base import Policy  # noqa: E402
from proteo_env.config import load_yaml
from proteo_env.rollout import run_episode  # noqa: E402
from training.judging.statistics import mean_ci  # noqa: E402
from training.machinery.checkpoints import load_policy  # noqa: E402


class FixedModePolicy(Policy):
    """Every module relays scent, sends nothing, and takes mode ``mode`` (``None``: keeps its own);
    it moves at random over its legal moves when ``moving``, else stays."""

    name = "fixed-mode"

    def __init__(self, action_layout, modes, *, scent_max=65535, seed=None, mode=None, moving=False):
        super().__init__(action_layout, modes, scent_max=scent_max, seed=seed)
        self.mode, self.moving = mode, moving

    def act(self, observations):
        actions = {}
        for agent, obs in observations.items():
            mode = int(obs["own_mode"][0]) if self.mode is None else self.mode
            move = self.random_legal_move(obs["action_mask"]) if self.moving else 0
            actions[agent] = self.action_layout.encode(move=move, mode=mode)
        return actions


def strategies(name: str, env) -> dict:
    """``{label: factory(seed) -> policy}`` of the strategies measured on task ``name``."""

    def fixed(**kw):
        return lambda seed: FixedModePolicy.for_env(env, seed=seed, **kw)

    def checkpoint(path):
        return lambda seed: load_policy(path, env, seed=seed)

    out = {
        "hand-coded": lambda seed: make_policy(name, env, seed=seed),
        "idle": fixed(),
        "random": lambda seed: make_policy("random", env, seed=seed),
    }
    if name == "chain":
        out["winding chain (MaskablePPO, checkpoints/exhibits/winding_chain)"] = checkpoint(
            "checkpoints/exhibits/winding_chain"
        )
    if name == "branch":
        node = env.task.mode_index("NODE")
        out["every module NODE, staying"] = fixed(mode=node)
        out["every module NODE, random moves"] = fixed(mode=node, moving=True)
    if name == "table":
        out["never settle (MaskablePPO, checkpoints/exhibits/never_settling_table)"] = checkpoint(
            "checkpoints/exhibits/never_settling_table"
        )
        out["rules that never grow a leg (p_max = p_min = 0)"] = lambda seed: make_policy(
            "table", env, seed=seed, p_max=0.0, p_min=0.0
        )
        out["rules that never disband a leg (p_min = 0)"] = lambda seed: make_policy("table", env, seed=seed, p_min=0.0)
    if name == "grasp":
        out["approach, never wrap (MaskablePPO, checkpoints/exhibits/approach_never_wrap)"] = checkpoint(
            "checkpoints/exhibits/approach_never_wrap"
        )
    return out


def measure(task_id: str, overrides: dict, seeds: list[int]) -> list[dict]:
    env = proteo_env.make(task_id, **overrides)
    rows = []
    for label, factory in strategies(env.task.name, env).items():
        policy = factory(seeds[0])
        episodes = [run_episode(env, policy, seed=s) for s in seeds]
        returns = [e.total_reward for e in episodes]
        mean, half = mean_ci(returns)
        won = [e.cycles for e in episodes if e.success]
        rows.append(
            {
                "task": task_id,
                "strategy": label,
                "return": mean,
                "return_ci": half,
                "per_cycle": float(np.mean([e.total_reward / e.cycles for e in episodes])),
                "successes": len(won),
                "episodes": len(episodes),
                "cycles_to_success": float(np.mean(won)) if won else None,
            }
        )
    return rows


def markdown(rows: list[dict]) -> str:
    lines = [
        "| strategy | return (95 % CI) | return per cycle | success | cycles to success |",
        "|---|---|---|---|---|",
    ]
    best = max(r["return"] for r in rows if r["strategy"] != "hand-coded")
    for r in rows:
        mark = " **(beats the rules)**" if r["strategy"] != "hand-coded" and r["return"] > rows[0]["return"] else ""
        cycles = "–" if r["cycles_to_success"] is None else f"{r['cycles_to_success']:.0f}"
        lines.append(
            f"| {r['strategy']}{mark} | {r['return']:.3f} ± {r['return_ci']:.3f} | {r['per_cycle']:.4f} | "
            f"{r['successes']}/{r['episodes']} | {cycles} |"
        )
    verdict = (
        "the hand-coded policy earns the most"
        if rows[0]["return"] > best
        else "a degenerate strategy earns more than the hand-coded policy"
    )
    return "\n".join(lines) + f"\n\n{rows[0]['task']}: {verdict}."


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--tasks",
        default=",".join(sorted({cls.name for cls in proteo_env.TASKS.values()} & set(POLICIES))),
        help="comma-separated task names (default: every task with a hand-coded policy)",
    )
    parser.add_argument("--seeds", type=int, default=10, help="episodes per strategy (seeds 1000..)")
    parser.add_argument("--config", default="configs/eval.yaml", help="per-task settings (the eval config)")
    parser.add_argument("--out", default=None, help="also write the rows as JSON here")
    args = parser.parse_args(argv)
    settings = load_yaml(Path(args.config))["tasks"]
    seeds = list(range(1000, 1000 + args.seeds))
    every = []
    for name in args.tasks.split(","):
        for task_id in sorted(tid for tid, cls in proteo_env.TASKS.items() if cls.name == name):
            rows = measure(task_id, dict(settings.get(name, {}).get("env") or {}), seeds)
            print(f"\n### {task_id}\n\n{markdown(rows)}\n", flush=True)
            every += rows
    if args.out:
        Path(args.out).write_text(json.dumps(every, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

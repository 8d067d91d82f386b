"""Does the reward rank the paper's behaviour first? The hand-coded rules against degenerate strategies.

    python benchmarks/degenerate_strategies.py --tasks chain-v0,chain-v1,branch,table-v0,table-v1,grasp \\
        --out docs/rewards/degenerate_eval.md

For each task id, the task's hand-coded policy and a set of degenerate strategies run one
episode per held-out seed at the settings of an eval config (``configs/eval.yaml`` by default:
the training sizes; ``configs/eval_larger.yaml`` for larger robots), the same seeds for every
strategy. Per strategy: mean return with its 95 % t interval, successes, cycles to success
(mean over the successful episodes) and return per cycle (mean over episodes of return /
cycles). A reward is wrong when a degenerate strategy's return is above the hand-coded one.

Degenerate strategies (the checkpoints are those named in ``docs/learning.md``):

- every task: ``stay`` (never move, keep every mode: :class:`baselines.stay.StayPolicy`) and
  ``random`` (:class:`baselines.random_policy.RandomPolicy`);
- chain: the winding chain of MaskablePPO (``checkpoints/chain/sb3_ppo``) and of the evolved
  network (``checkpoints/chain/cma_neural``);
- branch: every module NODE at once (:class:`AllNode`), and the evolved network
  (``checkpoints/branch/cma_neural``) that does nearly that;
- table: never settle, as MaskablePPO does (``checkpoints/table/sb3_ppo``) and as the rules do
  with thresholds that make every root grow and disband legs forever (:class:`Churn`); and
  doing nothing, the rules with ``p_max = p_min = 0``;
- grasp: approach with the rules, then retreat (:class:`ApproachRetreat`).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

from baselines import make_policy
from baselines.base import Policy
from baselines.table import TablePolicy
from baselines.table_kernels import TableRules
from proteo_env.core.lattice import DIRECTIONS

CHECKPOINTS = {
    "chain": [("winding chain (MaskablePPO)", "checkpoints/chain/sb3_ppo"),
              ("winding chain (evolved network)", "checkpoints/chain/cma_neural")],
    "branch": [("nearly all NODE (evolved network)", "checkpoints/branch/cma_neural")],
    "table": [("never settle (MaskablePPO)", "checkpoints/table/sb3_ppo")],
}
"""Checkpoints that embody a degenerate strategy, per task name: (label, path)."""


class AllNode(Policy):
    """Branch: every module switches to NODE at once and never moves (the evolved network's
    shortcut: the whole blob counts as grown structure)."""

    name = "all NODE"

    def act(self, observations):
        node = self.modes.index("NODE")
        return {agent: self.layout.encode(move=0, mode=node) for agent in observations}


class Churn(TablePolicy):
    """Table: the rules with thresholds no load can satisfy (``f_max = 0``, ``f_min`` above any
    reading): every inactive root grows a leg with probability ``p_max`` per cycle and every
    active one disbands its leg with probability ``p_min``, forever; the legs never settle."""

    name = "never settle (rules, churning roots)"

    @property
    def rules(self) -> TableRules:
        return TableRules(scent_max=int(self.scent_max), p_max=self.p_max, p_min=self.p_min, f_max=0.0,
                          f_min=math.inf, p_random=self.p_random)


class ApproachRetreat(Policy):
    """Grasp: the hand-coded rules for ``approach`` cycles, then every module rolls away from
    the object (the legal move most against the hint, keeping its mode), to collect the
    approach's reward and see whether the reward takes it back."""

    name = "approach, then retreat"

    def __init__(self, layout, modes, *, scent_max=65535, seed=None, approach=60, rules=None):
        super().__init__(layout, modes, scent_max=scent_max, seed=seed)
        self.approach = approach
        self.rules = rules
        self.cycle = 0

    def reset(self, seed=None):
        super().reset(seed)
        self.rules.reset(seed)
        self.cycle = 0

    def act(self, observations):
        self.cycle += 1
        if self.cycle <= self.approach:
            return self.rules.act(observations)
        actions = {}
        for agent, obs in observations.items():
            away = -(DIRECTIONS @ obs["hint"].astype(np.float64))  # (12,) how far each move goes from the object
            away[obs["action_mask"][1:] == 0] = -np.inf
            move = int(np.argmax(away)) + 1 if np.isfinite(away).any() and away.max() > 0 else 0
            actions[agent] = self.layout.encode(move=move, mode=int(obs["own_mode"][0]))
        return actions


def strategies(env, seed: int, root: Path):
    """``[(label, kind, policy)]`` for the task of ``env``: hand-coded first, then the degenerate ones."""
    from training.checkpoints import load_policy

    name = env.task.name
    out = [("hand-coded rules", "hand-coded", make_policy(env.task.default_policy, env, seed=seed)),
           ("stay (never move)", "degenerate", make_policy("stay", env, seed=seed)),
           ("random", "degenerate", make_policy("random", env, seed=seed))]
    if name == "branch":
        out.append((AllNode.name, "degenerate", AllNode.for_env(env, seed=seed)))
    if name == "table":
        out.append((Churn.name, "degenerate", Churn.for_env(env, seed=seed)))
        out.append(("do nothing (rules, p_max = p_min = 0)", "degenerate",
                    make_policy("table", env, seed=seed, p_max=0.0, p_min=0.0)))
    if name == "grasp":
        rules = make_policy("grasp", env, seed=seed)
        out.append((ApproachRetreat.name, "degenerate", ApproachRetreat.for_env(env, seed=seed, rules=rules)))
    for label, path in CHECKPOINTS.get(name, []):
        if (root / path).exists():
            out.append((label, "checkpoint", load_policy(root / path, env, seed=seed)))
    return out


def measure(task_id: str, overrides: dict, seeds: list[int], root: Path) -> list[dict]:
    """One row per strategy: returns, successes, cycles over ``seeds``."""
    import proteo_env
    from proteo_env.rollout import run_episode

    env = proteo_env.make(task_id, **overrides)
    rows = []
    for label, kind, policy in strategies(env, seeds[0], root):
        started = time.perf_counter()
        episodes = [run_episode(env, policy, seed=s) for s in seeds]
        rows.append({"task": env.task.task_id(), "strategy": label, "kind": kind,
                     "returns": [e.total_reward for e in episodes], "successes": [e.success for e in episodes],
                     "cycles": [e.cycles for e in episodes], "seconds": time.perf_counter() - started})
    env.close()
    return rows


def markdown(rows: list[dict]) -> str:
    """The rows as a markdown table (the columns of the module docstring)."""
    from training.evaluate import mean_ci

    def fmt(mean, half, digits):
        return f"{mean:.{digits}f}" + ("" if not np.isfinite(half) else f" ± {half:.{digits}f}")

    lines = ["| task | strategy | return (95 % CI) | successes | cycles to success | return per cycle |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        won = [c for c, s in zip(r["cycles"], r["successes"]) if s]
        cycles = fmt(*mean_ci(won), 0) if won else "–"
        per_cycle = float(np.mean(np.array(r["returns"]) / np.array(r["cycles"])))
        lines.append(f"| {r['task']} | {r['strategy']} | {fmt(*mean_ci(r['returns']), 3)} | "
                     f"{sum(r['successes'])}/{len(r['returns'])} | {cycles} | {per_cycle:.4f} |")
    return "\n".join(lines)


def beaten_by(rows: list[dict]) -> list[str]:
    """The degenerate strategies whose mean return is at least the hand-coded one, per task."""
    out = []
    for task in dict.fromkeys(r["task"] for r in rows):
        mine = [r for r in rows if r["task"] == task]
        rules = np.mean(mine[0]["returns"])
        out += [f"{task}: {r['strategy']}" for r in mine[1:] if np.mean(r["returns"]) >= rules]
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", default="chain,branch,table,grasp",
                        help="comma-separated task ids or names (a name: its newest version)")
    parser.add_argument("--config", default="configs/eval.yaml",
                        help="eval config giving each task's settings and held-out seeds")
    parser.add_argument("--seeds", type=int, default=None, help="episodes per strategy (default: the config's)")
    parser.add_argument("--out", default=None, help="also write the table to this markdown file")
    args = parser.parse_args(argv)

    from training.common import limit_threads
    from training.evaluate import load_config

    limit_threads(1)
    root = Path(__file__).resolve().parent.parent
    cfg = load_config(args.config)
    n = args.seeds if args.seeds is not None else cfg["seeds"]
    seeds = list(range(cfg["first_seed"], cfg["first_seed"] + n))
    rows = []
    for task_id in args.tasks.split(","):
        overrides = dict((cfg["tasks"].get(task_id.split("-v")[0]) or {}).get("env") or {})
        rows += measure(task_id, overrides, seeds, root)
    table = markdown(rows)
    losers = beaten_by(rows)
    verdict = ("every degenerate strategy earns less than the hand-coded rules" if not losers
               else "earn at least the hand-coded rules' return: " + "; ".join(losers))
    text = f"{table}\n\nSeeds {seeds[0]}..{seeds[-1]}, settings of {args.config}; {verdict}.\n"
    print(text)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

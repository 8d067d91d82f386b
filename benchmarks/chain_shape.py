"""What shape of chain each policy builds: straight (the paper's) or a winding snake.

    python benchmarks/chain_shape.py --checkpoint checkpoints/exhibits/winding_chain

The chain task counts any connected, one-module-thick path as success. For every policy and
seed this prints the end-to-end span of the final structure in lattice steps (``N - 1`` for a
straight chain of ``N`` modules) and the extent of its bounding box.
"""

from __future__ import annotations

import argparse

import numpy as np


def shape(positions: np.ndarray) -> tuple[int, tuple[int, ...]]:
    """End-to-end span (Chebyshev distance between the two degree-1 modules, -1 if not a path) and extent."""
    delta = np.abs(positions[:, None] - positions[None])
    touching = (delta.sum(-1) == 2) & (delta.max(-1) == 1)
    ends = np.flatnonzero(touching.sum(1) == 1)
    span = int(np.abs(positions[ends[0]] - positions[ends[-1]]).max()) if len(ends) == 2 else -1
    return span, tuple(int(x) for x in positions.max(0) - positions.min(0))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", action="append", default=[])
    parser.add_argument("--modules", type=int, default=12)
    parser.add_argument("--max-cycles", type=int, default=300)
    parser.add_argument("--seeds", type=int, default=10)
    args = parser.parse_args(argv)

    import proteo_env
    from baselines import make_policy
    from proteo_env.rollout import run_episode
    from training.machinery.checkpoints import load_policy
    from training.machinery.runs import limit_threads

    limit_threads(1)
    env = proteo_env.make("chain-v0", n_modules=args.modules, max_cycles=args.max_cycles, motion_model="sphere")
    policies = [make_policy(env.task.default_policy, env, seed=0), make_policy("random", env, seed=0)]
    policies += [load_policy(path, env, seed=0) for path in args.checkpoint]
    print(
        f"| policy | successes | end-to-end span of successful chains (straight = {args.modules - 1}) | "
        "mean bounding box |"
    )
    print("|---|---|---|---|")
    for policy in policies:
        spans, boxes, wins = [], [], 0
        for seed in range(args.seeds):
            result = run_episode(env, policy, seed=seed)
            if result.success:
                wins += 1
                span, box = shape(env.world.positions)
                spans.append(span)
                boxes.append(box)
        box = " x ".join(f"{v:.1f}" for v in np.mean(boxes, axis=0)) if boxes else "–"
        span = f"{np.mean(spans):.1f} (min {min(spans)}, max {max(spans)})" if spans else "–"
        print(f"| {policy.name} | {wins}/{args.seeds} | {span} | {box} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

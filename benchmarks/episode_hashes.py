"""One hash per task and policy of recorded episodes, to show that an engine change keeps every trajectory.

    python benchmarks/episode_hashes.py --out docs/speed/episode_hashes.json     # record
    python benchmarks/episode_hashes.py --check docs/speed/episode_hashes.json   # compare

For every registered task and version (the sandbox included), with its default settings
and ``max_cycles`` capped at ``--cycles``, it plays ``--seeds`` episodes (seeds 0, 1, ...) of
the task's hand-coded rules and of uniformly random actions through the PettingZoo API,
recording each (:class:`proteo_env.recording.Recorder`), and hashes (SHA-256) every cycle's
actions, then every recording's cycles, positions, modes, scents and series (the team reward,
the modules moved, the pieces and the task's metrics). ``--check`` recomputes the hashes and
lists the task and policy of each one that differs (exit status 1), so a faster kernel is
kept only when it changes none.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np


class HashedActions:
    """A policy that feeds every action it passes on, agent by agent in name order, to ``digest``."""

    def __init__(self, policy, digest):
        self.policy, self.digest = policy, digest

    def reset(self, seed):
        self.policy.reset(seed)

    def act(self, observations):
        actions = self.policy.act(observations)
        for name in sorted(actions):
            self.digest.update(np.asarray(actions[name], dtype=np.int64).tobytes())
        return actions


def task_hashes(task_id: str, seeds: int, cycles: int) -> dict[str, str]:
    """``{policy: hex digest}`` of the task's rules (when it has some) and of random actions."""
    import proteo_env
    from baselines import POLICIES, make_policy
    from proteo_env.recording import Recorder
    from proteo_env.rollout import run_episode

    env = proteo_env.make(task_id)
    env = proteo_env.make(task_id, max_cycles=min(cycles, env.config.max_cycles))
    names = [n for n in (env.task.default_policy, "random") if n in POLICIES]
    out = {}
    for name in dict.fromkeys(names):
        digest = hashlib.sha256()
        for seed in range(seeds):
            recorder = Recorder(env, task_id=task_id, overrides={}, seed=seed, policy=name)
            policy = HashedActions(make_policy(name, env, seed=seed), digest)
            result = run_episode(env, policy, seed=seed, observe=recorder)
            recording = recorder.recording(success=result.success)
            for array in (recording.cycles, recording.positions, recording.modes, recording.scents):
                digest.update(np.ascontiguousarray(array).tobytes())
            for series in sorted(recording.series):
                digest.update(series.encode() + np.asarray(recording.series[series], dtype=np.float64).tobytes())
        out[name] = digest.hexdigest()
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=2, help="episodes per task and policy (seeds 0, 1, ...)")
    parser.add_argument("--cycles", type=int, default=200, help="cap on each episode's cycles")
    parser.add_argument("--out", default=None, help="write the hashes to this JSON file")
    parser.add_argument("--check", default=None, help="compare with the hashes of this JSON file")
    args = parser.parse_args(argv)
    from proteo_env.registry import TASKS

    hashes = {}
    for task_id in sorted(TASKS):
        hashes[task_id] = task_hashes(task_id, args.seeds, args.cycles)
        print(task_id, hashes[task_id], flush=True)
    result = {"seeds": args.seeds, "cycles": args.cycles, "hashes": hashes}
    if args.out:
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    if args.check:
        expected = json.loads(Path(args.check).read_text())
        if (expected["seeds"], expected["cycles"]) != (args.seeds, args.cycles):
            print(f"{args.check} was made with --seeds {expected['seeds']} --cycles {expected['cycles']}")
            return 1
        differ = [
            f"{task} {policy}"
            for task, policies in expected["hashes"].items()
            for policy, digest in policies.items()
            if hashes.get(task, {}).get(policy) != digest
        ]
        print("every episode the same" if not differ else "differ: " + ", ".join(differ))
        return 1 if differ else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())

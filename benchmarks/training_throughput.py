"""Training throughput against raw environment speed, measured in one process, and where the time goes.

    python benchmarks/training_throughput.py --modules 12 --steps 60000
    python benchmarks/training_throughput.py --task branch-v0 --env "{n_modules: 40, T: 4, B: 3}" --out docs/learning/throughput_branch.json

Prints (and writes to ``--out`` as JSON) agent-steps per second of:

1. the raw engine: ``env.step_arrays`` + ``env.observe_arrays`` with random legal moves;
2. the SB3 adapter (``ProteoVecEnv.step``: engine + observation encoding + resets);
3. the TorchRL env (``ProteoTorchRLEnv.rollout`` with random actions);
4. MaskablePPO training (rollouts + updates), with a cProfile breakdown of one run into
   engine cycle, observation kernel, encoding, policy forward passes and PPO updates.

Any task runs with ``--task`` and its overrides in ``--env`` (YAML); ``--modules`` sets
``n_modules`` (chain's size; for tasks without that parameter give the size in ``--env``).
Torch and numba run one thread each (see training.common.limit_threads). The machine's load
average is recorded with the results: on a shared 2-core machine the absolute numbers move
with it, the ratios much less.
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import platform
import pstats
import time
from pathlib import Path

import numpy as np


def raw_env(task: str, overrides: dict, cycles: int) -> float:
    import proteo_env

    env = proteo_env.make(task, **{**overrides, "max_cycles": 10**6})
    env.reset(seed=0)
    n_modules = len(env.agents)
    lay, rng = env.action_layout, np.random.default_rng(0)
    env.step_arrays(np.zeros((n_modules, lay.length), dtype=np.int64))  # compile
    started = time.perf_counter()
    for _ in range(cycles):
        buffers = env.observe_arrays()
        actions = rng.integers(0, lay.nvec, size=(n_modules, lay.length))
        actions[:, 0] = (rng.random(buffers.action_mask.shape) * buffers.action_mask).argmax(axis=1)
        env.step_arrays(actions)
    return cycles * n_modules / (time.perf_counter() - started)


def sb3_adapter(task: str, overrides: dict, cycles: int, n_copies: int) -> float:
    from proteo_env.adapters.sb3 import ProteoVecEnv

    venv = ProteoVecEnv(task, n_copies=n_copies, seed=0, **overrides)
    venv.reset()
    rng = np.random.default_rng(0)
    started = time.perf_counter()
    for _ in range(cycles):
        masks = venv.action_masks()[:, :13]
        actions = rng.integers(0, venv.nvec, size=(venv.num_envs, len(venv.nvec)))
        actions[:, 0] = (rng.random(masks.shape) * masks).argmax(axis=1)
        venv.step(actions)
    return cycles * venv.num_envs / (time.perf_counter() - started)


def torchrl_env(task: str, overrides: dict, cycles: int, n_copies: int) -> float:
    from proteo_env.adapters.torchrl import ProteoTorchRLEnv

    env = ProteoTorchRLEnv(task, n_copies=n_copies, seed=0, **overrides)
    env.rollout(2)
    started = time.perf_counter()
    td = env.rollout(cycles, break_when_any_done=False)
    return cycles * n_copies * td["agents", "observation"].shape[-2] / (time.perf_counter() - started)


def sb3_training(task: str, overrides: dict, steps: int, n_copies: int, *, profile: bool):
    from sb3_contrib import MaskablePPO

    from proteo_env.adapters.sb3 import ProteoVecEnv

    venv = ProteoVecEnv(task, n_copies=n_copies, seed=0, **overrides)
    model = MaskablePPO("MlpPolicy", venv, n_steps=128, batch_size=1024, n_epochs=4, seed=0, device="cpu")
    model.learn(venv.num_envs * 128)  # warm-up rollout and update
    profiler = cProfile.Profile() if profile else None
    started = time.perf_counter()
    if profiler:
        profiler.enable()
    model.learn(steps, reset_num_timesteps=False)
    if profiler:
        profiler.disable()
    seconds = time.perf_counter() - started
    if not profiler:
        return steps / seconds, None
    stats = pstats.Stats(profiler).stats
    cum = {}
    for (file, _, func), (_, _, _, ct, _) in stats.items():
        key = f"{Path(file).name}:{func}"
        cum[key] = max(cum.get(key, 0.0), ct)
    parts = {"engine cycle (env.step_arrays)": cum.get("env.py:step_arrays", 0.0),
             "observation kernel (env.observe_arrays)": cum.get("env.py:observe_arrays", 0.0),
             "observation encoding (flatten)": cum.get("flatten.py:encode_fields", 0.0),
             "adapter step total (ProteoVecEnv.step_wait)": cum.get("sb3.py:step_wait", 0.0),
             "rollout collection total": cum.get("ppo_mask.py:collect_rollouts", 0.0),
             "PPO update (train)": cum.get("ppo_mask.py:train", 0.0)}
    parts["policy forward + buffer (collection minus adapter)"] = (parts["rollout collection total"]
                                                                    - parts["adapter step total (ProteoVecEnv.step_wait)"])
    total = seconds
    return steps / seconds, {k: {"seconds": round(v, 2), "share": round(v / total, 3)} for k, v in parts.items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="chain-v0")
    parser.add_argument("--env", default="{}", help="overrides of proteo_env.make, as YAML (max_cycles default 300)")
    parser.add_argument("--modules", type=int, default=None, help="n_modules (default 12 for chain)")
    parser.add_argument("--copies", type=int, default=4)
    parser.add_argument("--cycles", type=int, default=2000, help="cycles for the environment-only measurements")
    parser.add_argument("--steps", type=int, default=60000, help="agent-steps of MaskablePPO training")
    parser.add_argument("--out", default="docs/learning/throughput.json")
    args = parser.parse_args(argv)

    import torch
    import yaml

    from training.common import limit_threads

    overrides = yaml.safe_load(args.env) or {}
    if not isinstance(overrides, dict):
        parser.error(f"--env {args.env!r} is not allowed; allowed: a YAML mapping such as \"{{n_modules: 40}}\"")
    overrides.setdefault("max_cycles", 300)
    if args.modules is not None or args.task.startswith("chain"):
        overrides.setdefault("n_modules", args.modules or 12)

    limit_threads(1)
    torch.manual_seed(0)
    result = {"machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(),
                          "python": platform.python_version(), "torch": torch.__version__,
                          "load_average_before": os.getloadavg()},
              "task": args.task, "env": overrides, "modules": overrides.get("n_modules"), "copies": args.copies}
    task = (args.task, overrides)
    result["raw_env_agent_steps_per_s"] = raw_env(*task, args.cycles)
    result["sb3_adapter_agent_steps_per_s"] = sb3_adapter(*task, args.cycles // args.copies, args.copies)
    result["torchrl_env_agent_steps_per_s"] = torchrl_env(*task, args.cycles // args.copies, args.copies)
    result["sb3_training_agent_steps_per_s"], _ = sb3_training(*task, args.steps, args.copies, profile=False)
    result["sb3_training_profiled_agent_steps_per_s"], result["sb3_profile"] = sb3_training(
        *task, args.steps, args.copies, profile=True)
    result["raw_env_agent_steps_per_s_after"] = raw_env(*task, args.cycles)
    result["machine"]["load_average_after"] = os.getloadavg()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=2))
    for k, v in result.items():
        if k.endswith("per_s"):
            print(f"{k:45s} {v:10.0f}")
    for k, v in (result["sb3_profile"] or {}).items():
        print(f"  {k:55s} {v['seconds']:8.2f} s  {100 * v['share']:5.1f} %")
    print(f"load average before/after: {result['machine']['load_average_before']} / "
          f"{result['machine']['load_average_after']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

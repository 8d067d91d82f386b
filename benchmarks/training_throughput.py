"""Training throughput against raw environment speed, measured in one process, and where the time goes.

    python benchmarks/training_throughput.py --modules 12 --steps 60000

Prints (and writes to ``--out`` as JSON) agent-steps per second of:

1. the raw engine: ``env.step_arrays`` + ``env.observe_arrays`` with random legal moves;
2. the SB3 adapter (``ProteoVecEnv.step``: engine + observation encoding + resets);
3. the TorchRL env (``ProteoTorchRLEnv.rollout`` with random actions);
4. MaskablePPO training (rollouts + updates), with a cProfile breakdown of one run into
   engine cycle, observation kernel, encoding, policy forward passes and PPO updates.

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


def raw_env(n_modules: int, cycles: int) -> float:
    import proteo_env

    env = proteo_env.make("chain-v0", n_modules=n_modules, max_cycles=10**6)
    env.reset(seed=0)
    lay, rng = env.action_layout, np.random.default_rng(0)
    env.step_arrays(np.zeros((n_modules, lay.length), dtype=np.int64))  # compile
    started = time.perf_counter()
    for _ in range(cycles):
        buffers = env.observe_arrays()
        actions = rng.integers(0, lay.nvec, size=(n_modules, lay.length))
        actions[:, 0] = (rng.random(buffers.action_mask.shape) * buffers.action_mask).argmax(axis=1)
        env.step_arrays(actions)
    return cycles * n_modules / (time.perf_counter() - started)


def sb3_adapter(n_modules: int, cycles: int, n_copies: int) -> float:
    from proteo_env.adapters.sb3 import ProteoVecEnv

    venv = ProteoVecEnv("chain-v0", n_copies=n_copies, seed=0, n_modules=n_modules, max_cycles=300)
    venv.reset()
    rng = np.random.default_rng(0)
    started = time.perf_counter()
    for _ in range(cycles):
        masks = venv.action_masks()[:, :13]
        actions = rng.integers(0, venv.nvec, size=(venv.num_envs, len(venv.nvec)))
        actions[:, 0] = (rng.random(masks.shape) * masks).argmax(axis=1)
        venv.step(actions)
    return cycles * venv.num_envs / (time.perf_counter() - started)


def torchrl_env(n_modules: int, cycles: int, n_copies: int) -> float:
    from proteo_env.adapters.torchrl import ProteoTorchRLEnv

    env = ProteoTorchRLEnv("chain-v0", n_copies=n_copies, seed=0, n_modules=n_modules, max_cycles=300)
    env.rollout(2)
    started = time.perf_counter()
    env.rollout(cycles, break_when_any_done=False)
    return cycles * n_copies * n_modules / (time.perf_counter() - started)


def sb3_training(n_modules: int, steps: int, n_copies: int, *, profile: bool):
    from sb3_contrib import MaskablePPO

    from proteo_env.adapters.sb3 import ProteoVecEnv

    venv = ProteoVecEnv("chain-v0", n_copies=n_copies, seed=0, n_modules=n_modules, max_cycles=300)
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
    parser.add_argument("--modules", type=int, default=12)
    parser.add_argument("--copies", type=int, default=4)
    parser.add_argument("--cycles", type=int, default=2000, help="cycles for the environment-only measurements")
    parser.add_argument("--steps", type=int, default=60000, help="agent-steps of MaskablePPO training")
    parser.add_argument("--out", default="docs/learning/throughput.json")
    args = parser.parse_args(argv)

    import torch
    from training.common import limit_threads

    limit_threads(1)
    torch.manual_seed(0)
    result = {"machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(),
                          "python": platform.python_version(), "torch": torch.__version__,
                          "load_average_before": os.getloadavg()},
              "modules": args.modules, "copies": args.copies}
    result["raw_env_agent_steps_per_s"] = raw_env(args.modules, args.cycles)
    result["sb3_adapter_agent_steps_per_s"] = sb3_adapter(args.modules, args.cycles // args.copies, args.copies)
    result["torchrl_env_agent_steps_per_s"] = torchrl_env(args.modules, args.cycles // args.copies, args.copies)
    result["sb3_training_agent_steps_per_s"], _ = sb3_training(args.modules, args.steps, args.copies, profile=False)
    result["sb3_training_profiled_agent_steps_per_s"], result["sb3_profile"] = sb3_training(
        args.modules, args.steps, args.copies, profile=True)
    result["raw_env_agent_steps_per_s_after"] = raw_env(args.modules, args.cycles)
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

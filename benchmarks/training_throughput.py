"""Training throughput against raw environment speed, measured in one process, and where the time goes.

    python benchmarks/training_throughput.py --modules 12 --steps 60000
    python benchmarks/training_throughput.py --task branch-v0 --env "{n_modules: 40, T: 4, B: 3}" --out docs/learning/throughput_branch.json
    NUMBA_NUM_THREADS=1 python benchmarks/training_throughput.py --only training --out docs/learning/throughput_ppo_chain.json

Prints (and writes to ``--out`` as JSON) agent-steps per second of:

1. the raw engine: ``env.step_arrays`` + ``env.observe_arrays`` with random legal moves;
2. the SB3 adapter (``ProteoVecEnv.step``: engine + observation encoding + resets);
3. the TorchRL env (``ProteoTorchRLEnv.rollout`` with random actions);
4. MaskablePPO training (rollouts + updates), with a cProfile breakdown of one run into
   engine cycle, observation kernel, encoding, policy forward passes and PPO updates;
5. the native trainer ``training/trainers/ppo.py`` at control level ``full`` (the level MaskablePPO
   runs at: the same environment) and at ``move``, with its own split into environment step,
   observation encoding, rollout forward passes and PPO update (from its ``progress.csv``,
   after two warm-up updates). Its hyper-parameters come from ``--ppo-config`` (default
   ``configs/train/ppo_<task>_move.yaml``), the environment from ``--env``; with
   ``--former-network`` also at ``move`` with the networks the configs used before (separate
   MLP actor and critic, two epochs, messages one-hot per direction); with ``--variants`` also
   at ``move`` with the distillation term of kickstarting on (``distill_coef=1``: the rules
   label every module every cycle; their time counts as forward passes), with
   ``memory=last_move`` (the previous move as 13 more inputs), with ``value_norm`` (the critic
   on scaled returns) and with ``n_envs=256`` (four times the worlds per forward pass), and at
   ``full`` with ``memory=last_action`` (the whole previous action as inputs), in the same run. With ``--devices cpu cuda`` each of these runs on every device in turn (the
   environment stays on the CPU; the networks, their forward passes and updates move). The machine's description
   (CPU model, torch's vector instruction set, the GPU's name, load average) is written beside
   the figures.

Any task runs with ``--task`` and its overrides in ``--env`` (YAML); ``--modules`` sets
``n_modules`` (chain's size; for tasks without that parameter give the size in ``--env``).
Torch and numba run one thread each (see training.machinery.runs.limit_threads). The machine's load
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
from machine_info import describe


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
    parts = {
        "engine cycle (env.step_arrays)": cum.get("env.py:step_arrays", 0.0),
        "observation kernel (env.observe_arrays)": cum.get("env.py:observe_arrays", 0.0),
        "observation encoding (flatten)": cum.get("flatten.py:encode_fields", 0.0),
        "adapter step total (ProteoVecEnv.step_wait)": cum.get("sb3.py:step_wait", 0.0),
        "rollout collection total": cum.get("ppo_mask.py:collect_rollouts", 0.0),
        "PPO update (train)": cum.get("ppo_mask.py:train", 0.0),
    }
    parts["policy forward + buffer (collection minus adapter)"] = (
        parts["rollout collection total"] - parts["adapter step total (ProteoVecEnv.step_wait)"]
    )
    total = seconds
    return steps / seconds, {k: {"seconds": round(v, 2), "share": round(v / total, 3)} for k, v in parts.items()}


def ppo_training(
    task: str, overrides: dict, steps: int, *, control: str, config: str, variant=None, device: str = "cpu"
) -> dict:
    """Agent-steps/s of ``training/trainers/ppo.py`` on ``device`` and the share of its time in each part (after
    two warm-up updates); ``variant``: arguments that replace the config's (for example
    ``{"arch": "shared"}``)."""
    import csv
    import dataclasses
    import tempfile

    from proteo_env import batched
    from training.machinery.runs import parse_args
    from training.trainers import ppo

    # a long run's steady state: the rules of every world in one call (compiled in the warm-up)
    batched.ONE_CALL_AFTER = 0
    base = parse_args(ppo.Args, ["--config", config], retired=ppo.RETIRED) if Path(config).is_file() else ppo.Args()
    with tempfile.TemporaryDirectory() as tmp:
        args = dataclasses.replace(
            base,
            task=task,
            control=control,
            env=overrides,
            run_dir=f"{tmp}/run",
            total_steps=steps,
            checkpoint_every=10**12,
            time_limit_minutes=0.0,
            tensorboard=False,
            progress_bar=False,
            device=device,
            **(variant or {}),
        )
        ppo.train(args)
        with open(f"{tmp}/run/progress.csv") as fh:
            rows = list(csv.DictReader(fh))
    if len(rows) < 4:
        raise ValueError(f"steps={steps} gave {len(rows)} updates; allowed: enough steps for at least 4")
    first, timed = rows[1], rows[2:]
    seconds = float(timed[-1]["seconds"]) - float(first["seconds"])
    parts = {
        name: sum(float(r[f"time/{name}_seconds"]) for r in timed) for name in ("env", "encode", "forward", "update")
    }
    return {
        "control": control,
        "device": device,
        "config": config,
        "arch": args.arch,
        "hidden": list(args.hidden),
        "n_envs": args.n_envs,
        "n_steps": args.n_steps,
        "minibatch_size": args.minibatch_size,
        "n_epochs": args.n_epochs,
        "message_encoding": args.message_encoding,
        "agent_steps": int(float(timed[-1]["agent_steps"]) - float(first["agent_steps"])),
        "seconds": round(seconds, 2),
        "agent_steps_per_s": (float(timed[-1]["agent_steps"]) - float(first["agent_steps"])) / seconds,
        "share": {k: round(v / seconds, 3) for k, v in parts.items()},
    }


FORMER_NETWORK = "move, arch=mlp, n_epochs=2, per-direction messages"


def run_key(name: str, device: str) -> str:
    """The key of a run of ``training/trainers/ppo.py`` in the results: its name, with the device unless it is the CPU."""
    return name if device == "cpu" else f"{name}, device={device}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="chain-v0")
    parser.add_argument("--env", default="{}", help="overrides of proteo_env.make, as YAML (max_cycles default 300)")
    parser.add_argument("--modules", type=int, default=None, help="n_modules (default 12 for chain)")
    parser.add_argument("--copies", type=int, default=4)
    parser.add_argument("--cycles", type=int, default=2000, help="cycles for the environment-only measurements")
    parser.add_argument("--steps", type=int, default=60000, help="agent-steps of MaskablePPO training")
    parser.add_argument(
        "--ppo-steps", type=int, default=1_500_000, help="agent-steps of training/trainers/ppo.py per level"
    )
    parser.add_argument(
        "--ppo-config",
        default=None,
        help="hyper-parameters of training/trainers/ppo.py (default configs/train/ppo_<task>_move.yaml)",
    )
    parser.add_argument(
        "--only",
        choices=("all", "training", "native"),
        default="all",
        help="training: only the two trainers (MaskablePPO and training/trainers/ppo.py), no env-only rates; "
        "native: only training/trainers/ppo.py",
    )
    parser.add_argument(
        "--devices",
        nargs="+",
        default=["cpu"],
        help="devices that time training/trainers/ppo.py, each with every level and variant (cpu, cuda, cuda:N); "
        "figures on a device other than cpu are keyed '<name>, device=<device>'",
    )
    parser.add_argument(
        "--former-network",
        action="store_true",
        help="also time training/trainers/ppo.py at move with arch=mlp, n_epochs=2 and per-direction "
        "message features (the configs' former networks; same run)",
    )
    parser.add_argument(
        "--variants",
        action="store_true",
        help="also time training/trainers/ppo.py with the distillation term, the memories, value_norm, a GRU and 256 worlds "
        "(same run)",
    )
    parser.add_argument("--out", default="docs/learning/throughput.json")
    args = parser.parse_args(argv)

    import torch

    from proteo_env import ConfigError
    from proteo_env.config import parse_yaml
    from proteo_env.registry import task_name
    from training.machinery.runs import limit_threads, torch_device

    overrides = parse_yaml(args.env, "--env") or {}
    if not isinstance(overrides, dict):
        parser.error(f'--env {args.env!r} is not allowed; allowed: a YAML mapping such as "{{n_modules: 40}}"')
    overrides.setdefault("max_cycles", 300)
    if args.modules is not None or args.task.startswith("chain"):
        overrides.setdefault("n_modules", args.modules or 12)
    ppo_config = args.ppo_config or f"configs/train/ppo_{task_name(args.task)}_move.yaml"

    limit_threads(1)
    torch.manual_seed(0)
    try:
        devices = {d: torch_device(d) for d in args.devices}
    except ConfigError as error:
        parser.error(f"--devices: {error}")
    gpus = {d: torch.cuda.get_device_name(device) for d, device in devices.items() if device.type == "cuda"}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    result = {
        "machine": describe(
            "torch",
            *(() if args.only == "native" else ("sb3_contrib",)),
            "numpy",
            **({"gpus": gpus, "cuda": torch.version.cuda} if gpus else {}),
            platform=platform.platform(),
            torch_cpu_capability=torch.backends.cpu.get_cpu_capability(),
            numba_num_threads=os.environ.get("NUMBA_NUM_THREADS"),
            load_average_before=os.getloadavg(),
        ),
        "task": args.task,
        "env": overrides,
        "modules": overrides.get("n_modules"),
        "copies": args.copies,
    }
    task = (args.task, overrides)
    if args.only == "all":
        result["raw_env_agent_steps_per_s"] = raw_env(*task, args.cycles)
        result["sb3_adapter_agent_steps_per_s"] = sb3_adapter(*task, args.cycles // args.copies, args.copies)
        result["torchrl_env_agent_steps_per_s"] = torchrl_env(*task, args.cycles // args.copies, args.copies)
    if args.only != "native":
        result["sb3_training_agent_steps_per_s"], _ = sb3_training(*task, args.steps, args.copies, profile=False)
    runs = [("full", {}), ("move", {})]
    if args.former_network:
        runs.append((FORMER_NETWORK, {"arch": "mlp", "n_epochs": 2, "message_encoding": "per_direction"}))
    if args.variants:
        runs += [
            ("move, distillation term", {"distill_coef": 1.0, "distill_steps": 0}),
            ("move, memory=last_move", {"memory": "last_move"}),
            ("move, value_norm", {"value_norm": True}),
            ("move, n_envs=256", {"n_envs": 256}),
            ("full, memory=last_action", {"memory": "last_action"}),
        ]
    result["ppo"] = {}
    for name, variant in runs:  # the devices alternate, so that each pair shares the machine's state
        for device in args.devices:
            result["ppo"][run_key(name, device)] = ppo_training(
                *task, args.ppo_steps, control=name.split(",")[0], config=ppo_config, variant=variant, device=device
            )
            out.write_text(json.dumps(result, indent=2))  # what is done so far, should a later run fail
    for device in args.devices:
        suffix = "" if device == "cpu" else f"_{device}"
        for level in ("full", "move"):
            result[f"ppo_{level}_agent_steps_per_s{suffix}"] = result["ppo"][run_key(level, device)][
                "agent_steps_per_s"
            ]
    if args.former_network and "cpu" in args.devices:
        result["ppo_move_former_network_agent_steps_per_s"] = result["ppo"][FORMER_NETWORK]["agent_steps_per_s"]
    if "sb3_training_agent_steps_per_s" in result and "cpu" in args.devices:
        result["ppo_full_over_sb3"] = result["ppo_full_agent_steps_per_s"] / result["sb3_training_agent_steps_per_s"]
    if args.only == "all":
        result["sb3_training_profiled_agent_steps_per_s"], result["sb3_profile"] = sb3_training(
            *task, args.steps, args.copies, profile=True
        )
        result["raw_env_agent_steps_per_s_after"] = raw_env(*task, args.cycles)
    result["machine"]["load_average_after"] = os.getloadavg()
    out.write_text(json.dumps(result, indent=2))
    for k, v in result.items():
        if k.endswith("per_s") or k.endswith("over_sb3"):
            print(f"{k:45s} {v:10.2f}")
    for level, r in result["ppo"].items():
        print(
            f"  training/trainers/ppo.py at {level}: {r['agent_steps_per_s']:.0f} agent-steps/s; "
            + ", ".join(f"{k} {100 * v:.0f} %" for k, v in r["share"].items())
        )
    for k, v in (result.get("sb3_profile") or {}).items():
        print(f"  {k:55s} {v['seconds']:8.2f} s  {100 * v['share']:5.1f} %")
    print(
        f"load average before/after: {result['machine']['load_average_before']} / "
        f"{result['machine']['load_average_after']}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

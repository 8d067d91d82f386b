"""Train a policy for proteo's chain task in plain PyTorch, save it as TorchScript and ONNX, and
describe it in an entrant.yaml that `proteo eval --benchmark v7 --entrant` judges.

Written as an outside researcher would: it uses proteo's public batched API and flat observation
encoding only, and its own network (ReLU layers) and learner (PPO with one network shared by every
module, a team reward, GAE per world).

    python examples/plain_pytorch/train.py --seeds 0 1 --agent-steps 2000000 --out my_entrant
    proteo eval --benchmark v7 --entrant my_entrant --out my_entrant/judged
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
import yaml
from torch import nn

import proteo_env
from proteo_env.adapters.flatten import ObservationEncoder

TASK, LEVEL = "chain-v1", "move"
SETTINGS = {"n_modules": 12, "max_cycles": 300, "motion_model": "sphere"}  # protocol v7's chain
ENCODING = {"message_encoding": "compact"}


def network(n_in: int, n_out: int) -> nn.Module:
    return nn.Sequential(nn.Linear(n_in, 64), nn.ReLU(), nn.Linear(64, 64), nn.ReLU(), nn.Linear(64, n_out))


def train(seed: int, agent_steps: int, n_envs: int = 32, horizon: int = 32) -> tuple[nn.Module, int, float]:
    """An actor trained for about ``agent_steps`` agent-steps; returns it, the steps taken and the seconds."""
    torch.manual_seed(seed)
    envs = proteo_env.make_batched(TASK, n_envs, **SETTINGS, control=LEVEL)
    encoder = ObservationEncoder.for_env(proteo_env.make(TASK, **SETTINGS, control=LEVEL), **ENCODING)
    a = envs.n_agents
    actor, critic = network(encoder.size, 13), network(encoder.size, 1)
    optimiser = torch.optim.Adam([*actor.parameters(), *critic.parameters()], lr=1e-3)
    obs = envs.reset(seed=seed)
    steps, started = 0, time.perf_counter()
    while steps < agent_steps:
        feats, masks, actions, logps, values, rewards, dones = [], [], [], [], [], [], []
        for _ in range(horizon):
            x = torch.from_numpy(encoder.encode_buffers(obs))
            mask = torch.from_numpy(obs.action_mask.astype(bool))
            with torch.no_grad():
                dist = torch.distributions.Categorical(logits=actor(x).masked_fill(~mask, -1e9))
                move = dist.sample()
                values.append(critic(x)[:, 0])
            result = envs.step_arrays(move.numpy().reshape(n_envs, a, 1))
            feats.append(x), masks.append(mask), actions.append(move), logps.append(dist.log_prob(move))
            rewards.append(torch.from_numpy(np.repeat(result.reward, a)).float())
            done = result.done
            dones.append(torch.from_numpy(np.repeat(done, a)).float())
            obs = envs.reset_worlds(np.flatnonzero(done)) if done.any() else envs.observe_arrays()
            steps += n_envs * a
        with torch.no_grad():
            next_value = critic(torch.from_numpy(encoder.encode_buffers(obs)))[:, 0]
        advantages, gae = [], torch.zeros_like(next_value)
        for t in reversed(range(horizon)):
            following = next_value if t == horizon - 1 else values[t + 1]
            delta = rewards[t] + 0.99 * following * (1 - dones[t]) - values[t]
            gae = delta + 0.99 * 0.95 * (1 - dones[t]) * gae
            advantages.insert(0, gae)
        x, mask, move = torch.cat(feats), torch.cat(masks), torch.cat(actions)
        old_logp, adv = torch.cat(logps), torch.cat(advantages)
        returns = adv + torch.cat(values)
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        for _ in range(4):
            dist = torch.distributions.Categorical(logits=actor(x).masked_fill(~mask, -1e9))
            ratio = (dist.log_prob(move) - old_logp).exp()
            policy_loss = -torch.min(ratio * adv, ratio.clamp(0.8, 1.2) * adv).mean()
            value_loss = (critic(x)[:, 0] - returns).pow(2).mean()
            loss = policy_loss + 0.5 * value_loss - 0.01 * dist.entropy().mean()
            optimiser.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_([*actor.parameters(), *critic.parameters()], 0.5)
            optimiser.step()
    return actor.eval(), steps, time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="training seeds, one network each")
    parser.add_argument("--agent-steps", type=int, default=2_000_000, help="agent-steps per training seed")
    parser.add_argument("--out", default="out/plain_pytorch_entrant", help="folder for the networks and entrant.yaml")
    args = parser.parse_args()
    torch.set_num_threads(1)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    n_in = ObservationEncoder.for_env(proteo_env.make(TASK, **SETTINGS, control=LEVEL), **ENCODING).size
    steps, seconds = 0, 0.0
    for seed in args.seeds:
        actor, steps, took = train(seed, args.agent_steps)
        seconds += took
        example = torch.zeros(1, n_in)
        torch.jit.save(torch.jit.trace(actor, example), out / f"seed_{seed}.pt")
        torch.onnx.export(
            actor, (example,), str(out / f"seed_{seed}.onnx"), input_names=["features"],
            dynamic_axes={"features": {0: "n"}}, dynamo=False,
        )  # fmt: skip
        print(f"seed {seed}: {steps} agent-steps in {took:.0f} s")
    entrant = {
        "entrant": 1,
        "name": "plain-pytorch-ppo",
        "task": TASK,
        "control": LEVEL,
        "format": "torchscript",  # or onnx, with the seed_<k>.onnx files below
        "seeds": {seed: f"seed_{seed}.pt" for seed in args.seeds},
        "observation": ENCODING,
        "actions": "sample",
        "budget": {"agent_steps": steps, "wall_clock_minutes": round(seconds / 60 / len(args.seeds), 2)},
        "code": "examples/plain_pytorch/train.py in the proteo repository",
        "about": "PPO in plain PyTorch over proteo_env.make_batched; ReLU layers 64-64; one network for every module",
    }
    (out / "entrant.yaml").write_text(yaml.safe_dump(entrant, sort_keys=False))
    print(f"judge it: proteo eval --benchmark v7 --entrant {out} --out {out / 'judged'}")


if __name__ == "__main__":
    main()

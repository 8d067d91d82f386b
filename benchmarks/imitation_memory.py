"""How much of the rules' move does their private memory explain? Held-out agreement of clones
with and without memory inputs.

    python benchmarks/imitation_memory.py --task branch-v0 --env "{n_modules: 40, T: 4, B: 3, max_cycles: 200}"
    python benchmarks/imitation_memory.py --task chain-v1 --env "{n_modules: 12, max_cycles: 300, motion_model: sphere}" --worlds 32

The rules (the teacher of :mod:`training.trainers.imitate`) drive ``--worlds`` worlds for ``--cycles``
cycles, once with seed 0 (training states) and once with seed 777 (held-out states); every
module with a choice (two or more legal moves) is a sample labelled with the rules' move. The
same network (shared 128 x 128 trunk) is trained by cross-entropy on three inputs:

- the observation's features alone (what ``memory: none`` sees);
- plus the move the module played in the previous cycle (``memory: last_move``);
- plus the rules' own private memory before they decide (the chain family's ``heading``,
  ``growth`` and ``asked``; chain and branch only): an upper bound for any memory of the
  module's own past.

Prints the held-out agreement (arg-max move = the rules' move) and negative log-likelihood of
each. The rules draw random moves, so no input reaches agreement 1.
"""

from __future__ import annotations

import argparse
from types import SimpleNamespace

import numpy as np
import torch

from proteo_env.config import parse_yaml
from training.machinery.networks import ActorCritic, masked_log_probs, teacher_cross_entropy
from training.machinery.policies import with_memory
from training.machinery.runs import seed_everything
from training.trainers.teachers import Teachers
from training.trainers.worlds import TrainingEnvs


def collect(task: str, env: dict, n_envs: int, cycles: int, seed: int) -> dict[str, np.ndarray]:
    """Samples of rules-driven worlds: features, masks, labels, previous moves and the rules' memory."""
    worlds = TrainingEnvs(task, "move", env, n_envs, seed)
    teachers = Teachers(worlds.batch, worlds.n_envs, seed=seed)
    n = worlds.n_envs * worlds.n_agents
    features, mask = np.zeros((n, worlds.size), np.float32), np.zeros((n, 13), bool)
    out: dict[str, list] = {k: [] for k in ("x", "mask", "label", "previous", "heading", "growth", "asked")}
    for _ in range(cycles):
        worlds.encode(features, mask)
        memory = [p.memory_rows(range(worlds.n_agents)) for p in teachers.policies]
        labels = teachers.labels([worlds.buffers])
        keep = (mask.sum(axis=1) > 1) & mask[np.arange(n), labels[:, 0]]
        previous = worlds.previous_actions[:, 0]
        for name, value in (("x", features), ("mask", mask), ("label", labels), ("previous", previous)):
            out[name].append(value[keep].copy())
        for name in ("heading", "growth", "asked"):
            out[name].append(np.concatenate([getattr(m, name) for m in memory])[keep])
        _, terminal, truncated = worlds.step(labels.reshape(worlds.n_envs, worlds.n_agents, 1), [])
        teachers.restart(terminal | truncated)
    return {k: np.concatenate(v) for k, v in out.items()}


def one_hot(values: np.ndarray) -> np.ndarray:
    return np.eye(13, dtype=np.float32)[values]


def held_out(train: dict, test: dict, inputs, epochs: int) -> tuple[float, float]:
    """(agreement, NLL) on ``test`` of a network trained on ``train``, both seen through ``inputs``."""
    x, x_test = torch.from_numpy(inputs(train)), torch.from_numpy(inputs(test))
    mask, labels = torch.from_numpy(train["mask"]), torch.from_numpy(train["label"])
    net = ActorCritic(SimpleNamespace(size=x.shape[1]), [13], "shared", (128, 128))
    optimiser = torch.optim.Adam(net.parameters(), 1e-3)
    for _ in range(epochs):
        order = torch.randperm(len(x))
        for start in range(0, len(order), 4096):
            mb = order[start : start + 4096]
            loss = teacher_cross_entropy(masked_log_probs(net.logits(x[mb]), mask[mb], [13]), labels[mb], mask[mb])
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
    with torch.no_grad():
        log_probs = masked_log_probs(net.logits(x_test), torch.from_numpy(test["mask"]), [13])[0]
    truth = torch.from_numpy(test["label"][:, :1])
    return (
        float((log_probs.argmax(dim=1, keepdim=True) == truth).float().mean()),
        float(-log_probs.gather(1, truth).mean()),
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="branch-v0")
    parser.add_argument("--env", default="{n_modules: 40, T: 4, B: 3, max_cycles: 200}", help="overrides, as YAML")
    parser.add_argument("--worlds", type=int, default=16)
    parser.add_argument("--cycles", type=int, default=200)
    parser.add_argument("--epochs", type=int, default=8)
    args = parser.parse_args(argv)
    seed_everything(0)
    env = parse_yaml(args.env, "--env") or {}
    train, test = (collect(args.task, env, args.worlds, args.cycles, seed) for seed in (0, 777))
    variants = {
        "observation (memory: none)": lambda d: d["x"],
        "+ previous move (memory: last_move)": lambda d: with_memory(d["x"], d["previous"], "last_move"),
        "+ the rules' heading, growth, asked": lambda d: np.hstack(
            [d["x"], one_hot(d["heading"] + 1), one_hot(d["growth"] + 1), d["asked"][:, None].astype(np.float32)]
        ),
    }
    print(f"{args.task} {env}: {len(train['x'])} training samples, {len(test['x'])} held-out")
    for name, inputs in variants.items():
        agreement, nll = held_out(train, test, inputs, args.epochs)
        print(f"  {name:40s} held-out agreement {agreement:.3f}  NLL {nll:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Imitation of the hand-coded rules: behaviour cloning with DAgger over the batched array API.

Every module of ``n_envs`` worlds is one sample, as in :mod:`training.trainers.ppo`, and the network is
the same :class:`~training.machinery.networks.ActorCritic` (its policy head is trained here; its value head is
left for PPO), so a checkpoint of this script is evaluated by ``proteo eval --checkpoint`` and
starts ``training/trainers/ppo.py --init`` (kickstarting).

    python -m training.trainers.imitate --config configs/train/bc_grasp_move.yaml
    python -m training.trainers.imitate --config configs/train/bc_grasp_move.yaml --rounds 2 --run-dir runs/try
    proteo eval --config configs/eval.yaml --tasks grasp --checkpoint runs/try

The loop (Ross, Gordon & Bagnell's DAgger, with one policy shared by all modules):

- round 0: the teacher (:mod:`training.trainers.teachers`, the task's rules by default) drives every
  world for ``cycles_per_round`` cycles; every module's observation is stored with the
  teacher's action for it (plain behaviour cloning);
- round ``i >= 1``: the learner drives, except that each module plays the teacher's action
  with probability ``beta * beta_decay ** (i - 1)``; the teacher labels every visited state
  (also those the learner chose), the new samples join the aggregate, and the network is
  trained on the whole aggregate again;
- training: ``n_epochs`` passes of cross-entropy between the network's masked logits
  (illegal moves get probability zero, as when acting) and the teacher's action, summed over
  the controlled fields.

At control level ``move`` only modules with a choice (at least two legal moves) are stored: a
module that can only stay teaches nothing. ``samples_per_round`` caps what one round adds
(a uniform subsample).

Measured each round and logged (``progress.csv``, TensorBoard): the **agreement** of the
network trained so far with the teacher on the new round's states before they are trained on
(states of worlds and seeds it has not seen: a held-out measure; the arg-max move against the
teacher's move, and the whole action at other levels), the loss, and the success rate and
cycles of the episodes that ended during the round (the learner driving, mixed with the
teacher at the round's ``beta``).

Writes ``runs/<name>/`` like every training script (:mod:`training.machinery.runs`), with
``final/policy.pt`` (the :class:`~training.machinery.networks.ActorCritic` weights) and ``proteo.json``
(algorithm ``imitation``).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from proteo_env.registry import task_name
from proteo_env.spaces import N_MOVES
from training.machinery.networks import (
    ActorCritic,
    check_activation,
    check_arch,
    masked_log_probs,
    network_meta,
    sample,
    teacher_cross_entropy,
)
from training.machinery.policies import check_memory, check_sampled
from training.machinery.runs import (
    ProgressLog,
    RunArgs,
    check_integers,
    check_numbers,
    make_run_dir,
    parse_args,
    save_args,
    save_network_checkpoint,
    seed_everything,
    torch_device,
)
from training.trainers.teachers import DEFAULT_TEACHER, Teachers
from training.trainers.worlds import TrainingEnvs, WorkerEnvs, WorkerTeachers, check_workers

ALGORITHM = "imitation"


@dataclass(frozen=True)
class Args(RunArgs):
    """Behaviour cloning with DAgger from the hand-coded rules (arguments of training/trainers/imitate.py)."""

    task: str = "chain-v0"
    """The task: a registered id such as chain-v1 (a bare name such as chain: its newest version)."""
    control: str = "move"
    """Control level: move, move+mode or full (the fields the network chooses and is taught)."""
    env: dict = field(default_factory=lambda: {"n_modules": 12, "max_cycles": 300})
    """Overrides passed to ``proteo_env.make_batched`` (size, cycle limit, physics, task parameters)."""
    teacher: str = DEFAULT_TEACHER
    """The policy imitated: ``rules`` (the task's hand-coded policy), the task's name, or a checkpoint of
    the task at this control level (training/trainers/teachers.py)."""
    n_envs: int = 16
    """Worlds stepped together."""
    workers: int = 1
    """Processes that step the worlds and label them with the teacher, each its share at the same time
    (training/trainers/worlds.py: WorkerEnvs); the same run on any number. Not with a checkpoint as the teacher."""
    rounds: int = 4
    """DAgger rounds after round 0 (0: behaviour cloning only)."""
    cycles_per_round: int = 300
    """Cycles of every world per round (worlds restart as their episodes end)."""
    beta: float = 0.5
    """Probability that a module plays the teacher's action in round 1 (round 0: 1)."""
    beta_decay: float = 0.5
    """Factor on ``beta`` per later round."""
    samples_per_round: int = 200_000
    """At most this many samples join the aggregate per round (a uniform subsample)."""
    n_epochs: int = 4
    """Passes over the aggregate after each round."""
    minibatch_size: int = 4096
    """Samples (a module's observation and the teacher's action) per minibatch."""
    learning_rate: float = 1e-3
    """Adam's learning rate (constant)."""
    message_encoding: str = "compact"
    """How the features encode the messages received (proteo_env.adapters.flatten)."""
    arch: str = "shared"
    """Network: shared or mlp (training/machinery/networks.py)."""
    hidden: tuple[int, ...] = (128, 128)
    """Widths of the hidden layers: of the shared trunk (arch=shared) or of the actor's and of the
    critic's MLP each (arch=mlp)."""
    activation: str = "tanh"
    """The hidden layers' activation: tanh or relu (training/machinery/networks.py: ACTIVATIONS)."""
    memory: str = "none"
    """What the network remembers between cycles: none, last_move or last_action (training/machinery/policies.py)."""
    sampled: str = "move"
    """Which fields the clone samples when it acts, here and in ``proteo eval``: move (the others take
    their arg-max, as the rules' mode, roles and messages are deterministic) or all."""
    device: str = "cpu"
    """Where the network runs: cpu (the default), cuda, cuda:N or mps; the worlds stay on the CPU."""

    def __post_init__(self):
        check_integers(
            self,
            {
                "rounds": 0,
                "cycles_per_round": 1,
                "samples_per_round": 1,
                "n_epochs": 1,
                "minibatch_size": 1,
                "n_envs": 1,
                "workers": 1,
            },
        )
        check_numbers(self, {"beta": (0, 1), "beta_decay": (0, 1)})
        check_workers(self.workers, self.n_envs, teacher=self.teacher)
        check_arch(self.arch)
        check_activation(self.activation)
        check_memory(self.memory)
        check_sampled(self.sampled)


def round_beta(args: Args, round_index: int) -> float:
    """Probability that a module plays the teacher's action in round ``round_index``."""
    return 1.0 if round_index == 0 else args.beta * args.beta_decay ** (round_index - 1)


def agreement(net: ActorCritic, features, move_mask, labels, nvec) -> tuple[float, float, np.ndarray]:
    """``(move, whole action, per field (F,))``: the share of samples whose arg-max move, whose
    arg-max of every field, and whose arg-max of each field equals the label ``(N, F)``."""
    device = next(net.parameters()).device
    with torch.no_grad():
        log_probs = masked_log_probs(net.logits(features.to(device)), move_mask.to(device), nvec)
        best = torch.stack([lp.argmax(dim=1) for lp in log_probs], 1).cpu()
    same = best == labels
    return float(same[:, 0].float().mean()), float(same.all(dim=1).float().mean()), same.float().mean(0).numpy()


def collect_labelled(
    worlds: TrainingEnvs | WorkerEnvs,
    teachers: Teachers | WorkerTeachers,
    net: ActorCritic,
    beta: float,
    cycles: int,
    rng,
    args: Args,
    bar,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
    """``cycles`` cycles of every world with each module playing the teacher's action with
    probability ``beta``, else the network's sample. Returns the stored samples' features
    ``(S, D)``, move masks ``(S, 13)``, teacher labels ``(S, F)``, and the episodes that ended."""
    n, a, nvec = worlds.n_envs * worlds.n_agents, worlds.n_agents, [int(v) for v in worlds.nvec]
    features = np.zeros((n, worlds.size), dtype=np.float32)
    move_mask = np.zeros((n, N_MOVES), dtype=bool)
    kept_x, kept_m, kept_y, finished = [], [], [], []
    for _ in range(cycles):
        worlds.encode(features, move_mask)
        labels = worlds.teacher_labels(teachers)
        legal_label = move_mask[np.arange(n), labels[:, 0]]
        keep = legal_label & (move_mask.sum(axis=1) > 1 if args.control == "move" else True)
        kept_x.append(features[keep].copy())
        kept_m.append(move_mask[keep].copy())
        kept_y.append(labels[keep])
        actions = labels.copy()
        if beta < 1.0:
            device = next(net.parameters()).device
            with torch.no_grad():
                log_probs = masked_log_probs(
                    net.logits(torch.from_numpy(features).to(device)), torch.from_numpy(move_mask).to(device), nvec
                )
                learned = sample(log_probs, args.sampled)[0].cpu()
            play_learned = rng.random(n) >= beta
            actions[play_learned] = learned.numpy()[play_learned]
        _, terminal, truncated = worlds.step(actions.reshape(worlds.n_envs, a, -1), finished)
        teachers.restart(terminal | truncated)
        bar.update(1)
    x, m, y = np.concatenate(kept_x), np.concatenate(kept_m), np.concatenate(kept_y)
    if len(x) > args.samples_per_round:
        pick = np.sort(rng.choice(len(x), args.samples_per_round, replace=False))
        x, m, y = x[pick], m[pick], y[pick]
    return x, m, y, finished


def main(argv=None) -> Path:
    """Parse the arguments (``--config FILE`` and ``--<field> VALUE``) and train."""
    return train(parse_args(Args, argv, retired={"n_groups": 1}))


def train(args: Args) -> Path:
    """Run round 0 and ``args.rounds`` DAgger rounds; returns the final checkpoint's folder."""
    seed_everything(args.seed, threads=args.threads)
    device = torch_device(args.device)
    run_dir = make_run_dir(
        args.run_dir, f"imitate_{task_name(args.task)}_{args.control.replace('+', '-')}_s{args.seed}", resume=False
    )
    save_args(args, run_dir)
    worlds = TrainingEnvs.for_run(args, args.env)
    enc, nvec = worlds.encoder, [int(n) for n in worlds.nvec]
    fields = worlds.control_fields
    teachers = worlds.make_teachers(args.teacher, seed=args.seed, n_fields=len(nvec))
    net = ActorCritic(enc, nvec, args.arch, args.hidden, args.memory, args.activation).to(device)
    optimiser = torch.optim.Adam(net.parameters(), lr=args.learning_rate)
    rng = np.random.default_rng(args.seed)
    log = ProgressLog(run_dir, tensorboard=args.tensorboard)
    data_x, data_m, data_y = [], [], []
    agent_steps = 0
    measured: dict = {}
    bar = tqdm(
        total=(args.rounds + 1) * args.cycles_per_round, unit="cycle", desc="imitate", disable=not args.progress_bar
    )
    for round_index in range(args.rounds + 1):
        started = time.perf_counter()
        beta = round_beta(args, round_index)
        net.eval()
        x, m, y, finished = collect_labelled(worlds, teachers, net, beta, args.cycles_per_round, rng, args, bar)
        agent_steps += args.cycles_per_round * worlds.n_envs * worlds.n_agents
        x_t, m_t, y_t = torch.from_numpy(x), torch.from_numpy(m), torch.from_numpy(y)
        held_out = (
            agreement(net, x_t, m_t, y_t, nvec)
            if round_index
            else (float("nan"), float("nan"), np.full(len(nvec), np.nan))
        )
        data_x.append(x_t)
        data_m.append(m_t)
        data_y.append(y_t)
        all_x, all_m, all_y = torch.cat(data_x), torch.cat(data_m), torch.cat(data_y)
        collected = time.perf_counter()
        net.train()
        losses = []
        for _ in range(args.n_epochs):
            order = torch.randperm(len(all_x))
            for start in range(0, len(order), args.minibatch_size):
                mb = order[start : start + args.minibatch_size]
                x_mb, m_mb, y_mb = (torch.index_select(t, 0, mb).to(device) for t in (all_x, all_m, all_y))
                loss = teacher_cross_entropy(masked_log_probs(net.logits(x_mb), m_mb, nvec), y_mb, m_mb)
                optimiser.zero_grad(set_to_none=True)
                loss.backward()
                optimiser.step()
                losses.append(loss.item())
        successes = [e["success"] for e in finished]
        measured = {
            "round": round_index,
            "beta": beta,
            "samples/new": len(x),
            "samples/total": len(all_x),
            "imitation/loss": float(np.mean(losses)),
            "imitation/agreement_move": held_out[0],
            "imitation/agreement_action": held_out[1],
            **(
                {f"imitation/agreement_{name}": float(share) for name, share in zip(fields, held_out[2])}
                if len(fields) > 1
                else {}
            ),
            "episode/return": float(np.mean([e["r"] for e in finished])) if finished else None,
            "episode/success": float(np.mean(successes)) if successes else None,
            "episode/cycles": float(np.mean([e["l"] for e in finished])) if finished else None,
            "episode/count": len(finished),
            "time/collect_seconds": collected - started,
            "time/train_seconds": time.perf_counter() - collected,
        }
        log.log(agent_steps, measured)
        bar.set_postfix(agreement=f"{held_out[0]:.3f}", success=measured["episode/success"])
        if args.time_limit_minutes and log.seconds > 60 * args.time_limit_minutes:
            break  # the network trained on every round collected so far
    bar.close()
    worlds.close()
    final = run_dir / "final"
    save_network_checkpoint(
        final,
        net,
        args,
        run_dir,
        algorithm=ALGORITHM,
        task=worlds.task_id,
        env_overrides=dict(args.env),
        encoder_spec=enc.spec(),
        nvec=nvec,
        agent_steps=agent_steps,
        seed=args.seed,
        extra={
            "label": "imitation",
            **network_meta(args),
            "run_dir": str(run_dir),
            "teacher": args.teacher,
            "sampled": args.sampled,
            "last_round": measured,
            "args": asdict(args),
        },
    )
    log.close()
    print(
        f"final checkpoint: {final}  ({agent_steps} agent-steps, {log.seconds:.0f} s, held-out agreement "
        f"{measured['imitation/agreement_move']:.3f})"
    )
    return final


if __name__ == "__main__":
    from training.machinery.runs import run_script

    raise SystemExit(run_script(main))

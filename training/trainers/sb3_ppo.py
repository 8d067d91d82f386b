"""MaskablePPO (sb3-contrib) with one policy shared by every module.

Every module of ``n_envs`` worlds (copies of the task) is one sub-env of
:class:`~proteo_env.adapters.sb3.ProteoVecEnv`; the policy sees one module's flattened
observation, illegal moves are masked out of its move distribution, and every module gets
the team reward. ``total_steps`` counts agent-steps (module-cycles).

    python -m training.trainers.sb3_ppo --config configs/train/sb3_ppo_chain.yaml
    python -m training.trainers.sb3_ppo --config configs/train/sb3_ppo_chain.yaml --total-steps 20000 --run-dir runs/try
    python -m training.trainers.sb3_ppo --resume runs/try/checkpoints/step_0000010240 --total-steps 40000
    tensorboard --logdir runs

Writes ``runs/<name>/`` (see :mod:`training.machinery.runs`): ``progress.csv``, TensorBoard logs,
checkpoints every ``checkpoint_every`` agent-steps and ``final/``; ``proteo eval --checkpoint
runs/<name>`` evaluates the result.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

from tqdm import tqdm

from proteo_env.control import check_level
from proteo_env.registry import task_name
from training.machinery.checkpoints import mlp_meta, read_meta, write_checkpoint_meta
from training.machinery.runs import (
    PPOArgs,
    ProgressLog,
    checkpoint_folder,
    episode_stats,
    finish_run,
    make_run_dir,
    parse_args,
    save_args,
    seed_everything,
    torch_device,
)

ALGORITHM = "sb3-maskable-ppo"


@dataclass(frozen=True)
class Args(PPOArgs):
    """MaskablePPO with parameter sharing over all modules (arguments of training/trainers/sb3_ppo.py);
    ``minibatch_size`` is MaskablePPO's ``batch_size``."""

    vf_coef: float = 0.5
    """Weight of the value loss in the loss."""
    control: str = "full"
    """The control level: full, move+mode or move (the fields the policy chooses; the task's rules fill in the rest)."""
    hidden: tuple[int, ...] = (64, 64)
    """Widths of the tanh hidden layers of the policy's and of the value's separate MLPs (SB3's ``net_arch``)."""
    device: str = "cpu"
    """Where the networks run: cpu (the default), cuda, cuda:N or mps."""


def main(argv=None) -> Path:
    args = parse_args(Args, argv)
    check_level(args.control)
    seed_everything(args.seed, threads=args.threads)
    device = torch_device(args.device)

    from sb3_contrib import MaskablePPO
    from stable_baselines3.common.callbacks import BaseCallback

    from proteo_env.adapters.sb3 import ProteoVecEnv

    resume_meta = read_meta(args.resume) if args.resume else None
    run_dir = make_run_dir(
        args.run_dir or (resume_meta or {}).get("run_dir"),
        f"sb3_ppo_{task_name(args.task)}_s{args.seed}",
        resume=resume_meta is not None,
    )
    save_args(args, run_dir)
    venv = ProteoVecEnv(args.task, n_copies=args.n_envs, seed=args.seed, control=args.control, **args.env)
    tb_dir = str(run_dir / "tb") if args.tensorboard else None
    if resume_meta is not None:
        model = MaskablePPO.load(
            Path(resume_meta["dir"]) / "model.zip", env=venv, device=device, tensorboard_log=tb_dir
        )
    else:
        model = MaskablePPO(
            "MlpPolicy",
            venv,
            n_steps=args.n_steps,
            batch_size=args.minibatch_size,
            n_epochs=args.n_epochs,
            learning_rate=args.learning_rate,
            gamma=args.gamma,
            gae_lambda=args.gae_lambda,
            clip_range=args.clip_range,
            ent_coef=args.ent_coef,
            vf_coef=args.vf_coef,
            policy_kwargs={"net_arch": list(args.hidden)},
            tensorboard_log=tb_dir,
            seed=args.seed,
            device=device,
            verbose=0,
        )
    resumed_at = int(resume_meta["agent_steps"]) if resume_meta is not None else None
    log = ProgressLog(run_dir, tensorboard=False, resumed_at=resumed_at)  # SB3 writes TensorBoard itself

    def save(folder: Path) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        model.save(folder / "model.zip")
        write_checkpoint_meta(
            folder,
            algorithm=ALGORITHM,
            task=venv.task_id,
            env_overrides=dict(args.env),
            encoder_spec=venv.encoder.spec(),
            nvec=venv.nvec,
            agent_steps=model.num_timesteps,
            seed=args.seed,
            extra={
                "label": "sb3-ppo",
                **mlp_meta(args.control, args.hidden),
                "run_dir": str(run_dir),
                "args": asdict(args),
            },
        )

    class Progress(BaseCallback):
        """Progress bar, episode statistics, the time split, and periodic checkpoints."""

        def _on_training_start(self):
            self.bar = tqdm(
                total=args.total_steps,
                initial=self.num_timesteps,
                unit="agent-step",
                desc=ALGORITHM,
                disable=not args.progress_bar,
            )
            self.episodes, self.next_checkpoint = (
                [],
                (self.num_timesteps // args.checkpoint_every + 1) * args.checkpoint_every,
            )
            self.rollout_started = self.rollout_ended = time.perf_counter()
            self.env_seconds = venv.step_seconds

        def _on_rollout_start(self):
            now = time.perf_counter()
            self.update_seconds = now - self.rollout_ended  # the PPO update between two rollouts
            self.rollout_started = now
            self.env_seconds = venv.step_seconds

        def _on_step(self) -> bool:
            for info in self.locals["infos"]:
                if "episode" in info:
                    self.episodes.append({**info["episode"], "success": info["is_success"]})
            self.bar.update(venv.num_envs)
            if self.num_timesteps >= self.next_checkpoint:
                save(checkpoint_folder(run_dir, self.num_timesteps))
                self.next_checkpoint += args.checkpoint_every
            return not (args.time_limit_minutes and log.seconds > 60 * args.time_limit_minutes)

        def _on_rollout_end(self):
            self.rollout_ended = time.perf_counter()
            collect = self.rollout_ended - self.rollout_started
            env_s = venv.step_seconds - self.env_seconds
            steps = args.n_steps * venv.num_envs
            values = {
                **episode_stats(self.episodes),
                "time/env_seconds": env_s,
                "time/policy_seconds": collect - env_s,
                "time/update_seconds": getattr(self, "update_seconds", None),
                "throughput/collect_agent_steps_per_s": steps / collect,
                "throughput/env_agent_steps_per_s": steps / env_s if env_s else None,
            }
            for k, v in values.items():
                if v is not None:
                    self.logger.record(k, v)
            log.log(self.num_timesteps, values)
            self.episodes = []

        def _on_training_end(self):
            self.bar.close()

    model.learn(
        total_timesteps=max(args.total_steps - model.num_timesteps, 1),
        callback=Progress(),
        reset_num_timesteps=resume_meta is None,
        tb_log_name="sb3_ppo",
    )
    final = finish_run(run_dir, save, log, model.num_timesteps)
    venv.close()
    return final


if __name__ == "__main__":
    from training.machinery.runs import run_script

    raise SystemExit(run_script(main))

"""What every trainer's run shares: its options, and for the trainers that work in generations the
whole run around their loop.

:class:`RunArgs` holds the options of every trainer's run (seed, run folder, time limit, threads,
logs); a trainer's ``Args`` derives from it and declares only its own, and :class:`PPOArgs` adds
what the PPO trainers share. :class:`GenerationalArgs`
adds what a population-based trainer (training/cma_es.py, training/evolve.py) needs, and
:class:`GenerationalRun` does the rest of such a run, so that the trainer writes only its
generation:

- the run folder (``--run-dir``, default ``runs/<name>``) and its ``args.yaml``;
- resume: rerun the same command after an interruption (the run continues from ``state.pkl``
  after its last finished generation), or ``--resume CHECKPOINT`` to go on from a checkpoint
  (every checkpoint holds the same ``state.pkl``); either way the arguments the results depend
  on (all but :data:`RUN_INDEPENDENT`) must be the run's, checked against the state's
  fingerprint;
- the journal of finished episodes (``episodes.jsonl``: an interrupted generation resumes
  without playing its finished episodes again), the progress log (``progress.csv`` and
  TensorBoard), the progress bar, the time limit, a checkpoint every ``checkpoint_every``
  generations and ``final/`` at the end, each with ``proteo.json``.

The loop of a trainer::

    run = GenerationalRun(args, algorithm="program-evolution", name=f"evolve_{task}_s{seed}",
                          what="evolution run", counter="evolve/generation")
    state = run.resumed or {"generation": 0, ...}       # the state to go on from
    run.start(state["generation"])
    while state["generation"] < args.generations:
        ... score a generation with run.journal, update state ...
        if run.end_generation(state["generation"], agent_steps, values, state, write):
            break                                        # the time limit
    run.finish(state, write)

where ``write(folder, agent_steps)`` writes the trainer's payload and calls :meth:`GenerationalRun.write_meta`.
"""

from __future__ import annotations

import os
import pickle
from dataclasses import asdict, dataclass, field
from pathlib import Path

from proteo_env.config import ConfigError
from training.common import (
    ProgressLog,
    checkpoint_folder,
    make_run_dir,
    read_resume,
    save_args,
    write_checkpoint_meta,
)
from training.trainers import ALGORITHMS


@dataclass(frozen=True)
class RunArgs:
    """The options of every trainer's run."""

    seed: int = 0
    """The run's seed: every random stream of the run (worlds, policy, optimiser) derives from it."""
    run_dir: str | None = None
    """The run folder (progress.csv, args.yaml, checkpoints/, final/); default: runs/<trainer>_<task>_s<seed>."""
    time_limit_minutes: float = 0.0
    """Stop early, with a final checkpoint, after this much wall-clock time; 0: no limit."""
    threads: int = 1
    """Threads of torch and of numba's parallel kernels in this process (one is fastest on 2 cores)."""
    tensorboard: bool = True
    """Also log the progress to TensorBoard (tb/ in the run folder)."""
    progress_bar: bool = True
    """Show a progress bar on the terminal."""


@dataclass(frozen=True)
class PPOArgs(RunArgs):
    """The options every PPO trainer over proteo's worlds shares (training/ppo.py,
    training/sb3_ppo.py, training/torchrl_ppo.py); each trainer sets its own defaults and adds
    its own options."""

    task: str = "chain-v0"
    """The task: a registered id such as chain-v1 (a bare name such as chain: its newest version)."""
    env: dict = field(default_factory=lambda: {"n_modules": 12, "max_cycles": 300})
    """Overrides of the worlds' settings as ``proteo_env.make`` takes them (size, cycle limit, physics, task parameters)."""
    total_steps: int = 200_000
    """Agent-steps (module-cycles) to train for, counted across all worlds."""
    n_envs: int = 4
    """Worlds stepped together; samples per cycle = n_envs * modules."""
    n_steps: int = 128
    """Cycles per world in one rollout (rollout = n_steps * n_envs * modules agent-steps)."""
    minibatch_size: int = 1024
    """Agent-steps per minibatch of the update."""
    n_epochs: int = 4
    """Passes over each rollout's samples per update."""
    learning_rate: float = 3e-4
    """Adam's learning rate (constant)."""
    gamma: float = 0.99
    """Discount factor per cycle."""
    gae_lambda: float = 0.95
    """The lambda of GAE (0: one-step TD advantages, 1: Monte Carlo returns)."""
    clip_range: float = 0.2
    """PPO's clip range: the probability ratio is clipped to [1 - clip_range, 1 + clip_range]."""
    ent_coef: float = 0.01
    """Weight of the entropy bonus in the loss."""
    checkpoint_every: int = 50_000
    """Agent-steps between checkpoints (checkpoints/step_<N>/ in the run folder)."""
    resume: str | None = None
    """A checkpoint of this trainer to continue from (its run folder is reused unless run_dir is set)."""


@dataclass(frozen=True)
class GenerationalArgs(RunArgs):
    """The options of a trainer that works in generations (and runs its episodes in batches)."""

    generations: int = 50
    """Generations to run (with ``--resume``: in all, counting the checkpoint's)."""
    checkpoint_every: int = 10
    """Generations between checkpoints."""
    resume: str | None = None
    """A checkpoint of this trainer to go on from (an interrupted run resumes by rerunning its command)."""
    ray: bool = False
    """Run the batches of episodes as Ray tasks (the same results as on this machine)."""
    address: str | None = None
    """A running Ray cluster (``HOST:PORT`` or ``auto``); default: a local Ray instance (with ``ray``)."""
    workers: int | None = None
    """Worker processes (default: every core); with ``ray``, CPUs of the local Ray instance or tasks at
    once on a cluster. The results do not depend on it."""


RUN_INDEPENDENT = (
    "generations",
    "time_limit_minutes",
    "checkpoint_every",
    "run_dir",
    "resume",
    "threads",
    "tensorboard",
    "progress_bar",
    "ray",
    "address",
    "workers",
)
"""Options of :class:`GenerationalArgs` a resumed run may change: the results do not depend on them."""


class GenerationalRun:
    """The run of a population-based trainer around its loop (see the module docstring).

    Args:
        args: the trainer's arguments (a :class:`GenerationalArgs`).
        algorithm: the ``algorithm`` of its checkpoints, registered in :mod:`training.trainers`
            (``--resume`` accepts only those).
        name: the run folder's default name, under ``runs/``.
        what: the run in messages (``"evolution run"``).
        counter: the progress log's generation column (rows after a resumed state are dropped).
        independent: more options a resumed run may change, beside :data:`RUN_INDEPENDENT`.

    Attributes:
        run_dir: the run folder.
        resumed: the state to go on from (what the trainer passed to :meth:`end_generation`),
            or ``None`` for a new run.
        journal: the run's :class:`~training.distributed.Journal` of finished episodes.
        log: its :class:`~training.common.ProgressLog`.
    """

    def __init__(self, args, *, algorithm: str, name: str, what: str, counter: str, independent: tuple = ()):
        from training.distributed import Journal

        self.args, self.algorithm, self.counter = args, algorithm, counter
        script = f"training/{ALGORITHMS[algorithm].name}.py"
        resume_meta = read_resume(args.resume, algorithm, script)
        run_dir = Path(args.run_dir or (resume_meta or {}).get("run_dir") or Path("runs") / name)
        self.state_file = run_dir / "state.pkl"
        interrupted = self.state_file.is_file() and not (run_dir / "final").exists() and resume_meta is None
        skip = set(RUN_INDEPENDENT) | set(independent)
        self.fingerprint = {k: v for k, v in asdict(args).items() if k not in skip}
        self.resumed = None
        if interrupted or resume_meta is not None:
            source = self.state_file if interrupted else Path(resume_meta["dir"]) / "state.pkl"
            if not source.is_file():
                raise ConfigError(
                    f"resume={args.resume!r} has no state.pkl (a checkpoint written before runs could go on "
                    f"from it); allowed: a checkpoint of {script} that holds state.pkl"
                )
            self.resumed = pickle.loads(source.read_bytes())
            if self.resumed["fingerprint"] != self.fingerprint:
                saved = self.resumed["fingerprint"]
                diff = sorted(k for k in set(saved) | set(self.fingerprint) if saved.get(k) != self.fingerprint.get(k))
                where = (
                    f"run_dir {str(run_dir)!r} holds an interrupted run"
                    if interrupted
                    else f"resume={args.resume!r} is"
                )
                raise ConfigError(
                    f"{where} with other arguments (differing: {', '.join(diff)}); allowed: the same arguments "
                    "to resume it, or another run_dir"
                )
            print(f"resuming the {what} in {run_dir}")
        self.run_dir = make_run_dir(str(run_dir), run_dir.name, resume=self.resumed is not None)
        save_args(args, self.run_dir)
        self.log = ProgressLog(self.run_dir, tensorboard=args.tensorboard)
        self.journal = Journal(self.run_dir / "episodes.jsonl", self.fingerprint, what=what)
        self.bar = None

    def start(self, generation: int) -> None:
        """Open the progress bar at ``generation`` (the one the run goes on from) and drop the
        progress rows logged after it by an interrupted run."""
        from tqdm import tqdm

        self.log.drop_after(self.counter, generation)
        self.bar = tqdm(
            total=self.args.generations,
            initial=generation,
            unit="generation",
            desc=self.algorithm,
            disable=not self.args.progress_bar,
        )

    def end_generation(self, generation: int, agent_steps: int, values: dict, state: dict, write) -> bool:
        """Log the finished ``generation`` (``values``, with the counter column set, at the end
        unless ``values`` places it), write a
        checkpoint when it is due (``write(folder, agent_steps)`` and ``state.pkl``) and the run's
        state; whether the time limit says stop."""
        self.bar.update(1)
        self.log.log(agent_steps, {**values, self.counter: float(generation)})
        if generation % self.args.checkpoint_every == 0:
            self.checkpoint(checkpoint_folder(self.run_dir, agent_steps), agent_steps, state, write)
        tmp = self.state_file.with_suffix(".tmp")
        tmp.write_bytes(pickle.dumps({**state, "fingerprint": self.fingerprint}))
        os.replace(tmp, self.state_file)
        limit = self.args.time_limit_minutes
        return bool(limit and self.log.seconds > 60 * limit)

    def checkpoint(self, folder: Path, agent_steps: int, state: dict, write) -> Path:
        """Write a checkpoint into ``folder``: the trainer's files (``write``) and ``state.pkl``."""
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "state.pkl").write_bytes(pickle.dumps({**state, "fingerprint": self.fingerprint}))
        write(folder, agent_steps)
        return folder

    def write_meta(self, folder: Path, *, agent_steps: int, generation: int, extra: dict, **meta) -> None:
        """``proteo.json`` of a checkpoint: :func:`~training.common.write_checkpoint_meta` with this
        run's algorithm, seed, folder and arguments (``meta``: task, env_overrides, encoder_spec, nvec)."""
        write_checkpoint_meta(
            folder,
            algorithm=self.algorithm,
            agent_steps=agent_steps,
            seed=self.args.seed,
            extra={
                "label": self.algorithm,
                "run_dir": str(self.run_dir),
                "generation": generation,
                **extra,
                "args": asdict(self.args),
            },
            **meta,
        )

    def finish(self, agent_steps: int, state: dict, write) -> Path:
        """Write ``final/``, mark the journal complete and close the logs; the final checkpoint's folder."""
        self.bar.close()
        final = self.checkpoint(self.run_dir / "final", agent_steps, state, write)
        self.journal.complete()
        self.log.close()
        return final

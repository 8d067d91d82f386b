"""The episodes of ``proteo eval`` and ``proteo sweep``: one :class:`EpisodeJob` per episode.

:func:`run_episode_job` runs one job (building its env and policy once per process, cached
in :data:`_BUILT`) and returns what the tables need; :func:`run_episodes` runs a list of
jobs serially or as Ray tasks (:mod:`training.distributed`), writing each finished episode to a
journal as it arrives, so an interrupted run resumes with the missing episodes only.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

from proteo_env.registry import task_name


def _picture_png(env, caption: str) -> str:
    """The world of ``env`` as it is now, as a base64-encoded PNG."""
    import base64
    import tempfile

    from proteo_env.render.renderer import Renderer
    from proteo_env.render.scene import Scene

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "picture.png"
        renderer = Renderer()
        renderer.savefig(Scene.from_world(env.world, caption=caption), path)
        renderer.close()
        return base64.b64encode(path.read_bytes()).decode()


@dataclass(frozen=True)
class EpisodeJob:
    """One episode: everything its result depends on (picklable; sent to Ray workers as it is).

    ``policy`` is a registered policy name (``checkpoint=False``) or a checkpoint path;
    ``overrides`` is the JSON of the ``proteo_env.make`` overrides; ``picture`` the name of what
    acts (a policy, a checkpoint folder, a group's label): when not empty the end of the episode is
    drawn under it and returned.
    """

    task_id: str
    overrides: str
    level: str
    policy: str
    checkpoint: bool
    seed: int
    policy_seed: int
    deterministic: bool = False
    picture: str = ""

    @property
    def key(self) -> str:
        """The job's name in a journal: task, settings, level, policy and seed."""
        return f"{self.task_id}|{self.overrides}|{self.level}|{self.policy}|{self.seed}"


_BUILT: dict = {}
"""(env, policy) per (task, overrides, level, policy): built once per process, reused across episodes."""


def built(job: EpisodeJob):
    """The environment and policy ``job`` runs (cached per process; at most 4 kept)."""
    spec = (job.task_id, job.overrides, job.level, job.policy, job.checkpoint, job.policy_seed, job.deterministic)
    if spec not in _BUILT:
        import proteo_env
        from baselines import make_policy
        from training.checkpoints import load_policy
        from training.common import limit_threads

        limit_threads(1)
        while len(_BUILT) >= 4:
            _BUILT.pop(next(iter(_BUILT)))[0].close()
        overrides = json.loads(job.overrides)
        env = proteo_env.make(job.task_id, **overrides, **({} if job.level == "full" else {"control": job.level}))
        policy = (
            load_policy(job.policy, env, seed=job.policy_seed, deterministic=job.deterministic)
            if job.checkpoint
            else make_policy(job.policy, env, seed=job.policy_seed)
        )
        _BUILT[spec] = (env, policy)
    return _BUILT[spec]


def run_episode_job(job: EpisodeJob) -> dict:
    """Run one episode: ``{"return", "success", "cycles", "metrics", "seconds", "picture"}`` (JSON-ready)."""
    from proteo_env.rollout import run_episode

    env, policy = built(job)
    started = time.perf_counter()
    episode = run_episode(env, policy, seed=job.seed)
    out = {
        "return": float(episode.total_reward),
        "success": bool(episode.success),
        "cycles": int(episode.cycles),
        "metrics": {k: float(v) for k, v in episode.metrics.items()},
        "seconds": time.perf_counter() - started,
        "picture": None,
    }
    if job.picture:
        out["picture"] = _picture_png(
            env,
            f"{job.task_id} · {job.picture} ({job.level}) · seed {job.seed} · cycle {episode.cycles}"
            + (" · success" if episode.success else ""),
        )
    return out


def run_episodes(jobs: list, out_dir: Path, *, ray, journal, progress: bool, workers=None) -> None:
    """Run the planned ``jobs`` (``[(Run, EpisodeJob)]``) and add each episode to its run; pictures
    go to ``out_dir/pictures/<task>_<picture>_<level>.png``.

    The episodes run in batches of worlds (:func:`training.evaluator.run_episodes`, on
    ``workers`` processes, default every core, or on Ray); a job with a picture runs on its own
    (:func:`run_episode_job`), since its world is drawn at its end. Each finished episode is
    recorded in ``journal`` under its job's key. An episode's ``seconds`` is its batch's
    wall-clock time shared equally among its episodes.
    """
    import base64

    from training.distributed import run_jobs
    from training.evaluator import Controller, Episode
    from training.evaluator import run_episodes as run_batched

    pictured = [i for i, (_, j) in enumerate(jobs) if j.picture]
    plain = [i for i, (_, j) in enumerate(jobs) if not j.picture]
    episodes: list = [None] * len(jobs)
    if pictured:
        for i, episode in zip(
            pictured,
            run_jobs(
                run_episode_job,
                [jobs[i][1] for i in pictured],
                [jobs[i][1].key for i in pictured],
                ray=ray,
                journal=journal,
                desc="pictured episodes",
                progress=progress,
            ),
        ):
            episodes[i] = episode
    if plain:
        started = time.perf_counter()
        batched = run_batched(
            [
                Episode(
                    j.task_id, j.overrides, j.level, Controller(j.policy, (), j.checkpoint, j.deterministic), j.seed
                )
                for _, j in (jobs[i] for i in plain)
            ],
            keys=[jobs[i][1].key for i in plain],
            ray=ray,
            workers=workers,
            journal=journal,
            progress=progress,
        )
        seconds = (time.perf_counter() - started) / len(plain)
        for i, r in zip(plain, batched):
            episodes[i] = {
                "return": float(r.total_reward),
                "success": bool(r.success),
                "cycles": int(r.cycles),
                "metrics": {k: float(v) for k, v in r.metrics.items()},
                "seconds": seconds,
                "picture": None,
            }
    for (run, job), episode in zip(jobs, episodes):
        run.add(job.seed, episode)
        if episode["picture"]:
            file = out_dir / "pictures" / f"{task_name(job.task_id)}_{job.picture}_{job.level}.png".replace("+", "-")
            file.parent.mkdir(parents=True, exist_ok=True)
            file.write_bytes(base64.b64decode(episode["picture"]))

"""The one way ``proteo eval`` and ``proteo eval --benchmark`` judge: a :class:`Plan` of rows and
their episodes, run once.

A planner (:func:`training.judging.evaluate.plan_episodes` for an evaluation, the judge's
:func:`~training.judging.judge.plan_protocol` for a protocol) adds each row's record (a
:class:`~training.judging.report.Result`) and, for each of its runs, the episodes to play
(:meth:`Plan.add_run`): each is ``(Run, Episode, picture)``, the
:class:`~training.judging.report.Run` it adds to, the :class:`training.machinery.evaluator.Episode` (task,
settings, level, controller, world seed) and a label to draw its end under (``""``: none).
:meth:`Plan.execute` runs them in batches of worlds (:func:`training.machinery.evaluator.run_episodes`),
writing each finished episode to a journal as its batch lands, so an interrupted run resumes with
the missing episodes only (an episode whose end is drawn runs on its own, :func:`run_alone`),
then lets the caller write its files before the journal is closed.
"""

from __future__ import annotations

import base64
import json
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import proteo_env
from proteo_env.registry import task_name
from proteo_env.render.renderer import Renderer
from proteo_env.render.scene import Scene
from proteo_env.rollout import run_episode
from training.judging.report import Result, Run
from training.machinery.distributed import Journal, run_jobs
from training.machinery.evaluator import Episode, episode_key, run_episodes
from training.machinery.runs import limit_threads


def _picture_png(env, caption: str) -> str:
    """The world of ``env`` as it is now, as a base64-encoded PNG."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "picture.png"
        renderer = Renderer()
        renderer.savefig(Scene.from_world(env.world, caption=caption), path)
        renderer.close()
        return base64.b64encode(path.read_bytes()).decode()


_BUILT: dict = {}
"""(env, policy) per (task, settings, level, controller): built once per process, reused across episodes."""


def built(episode):
    """The environment and policy ``episode`` runs on its own (cached per process; at most 4 kept)."""
    spec = (episode.task, episode.overrides, episode.level, episode.controller)
    if spec not in _BUILT:
        limit_threads(1)
        while len(_BUILT) >= 4:
            _BUILT.pop(next(iter(_BUILT)))[0].close()
        level = {} if episode.level == "full" else {"control": episode.level}
        env = proteo_env.make(episode.task, **json.loads(episode.overrides), **level)
        _BUILT[spec] = (env, episode.controller.build(env, episode.seed))
    return _BUILT[spec]


def _record(result, seconds: float) -> dict:
    """An episode's result (an ``EpisodeResult``) as the JSON-ready record a run adds (no picture)."""
    return {
        "return": float(result.total_reward),
        "success": bool(result.success),
        "cycles": int(result.cycles),
        "metrics": {k: float(v) for k, v in result.metrics.items()},
        "seconds": seconds,
        "picture": None,
    }


def run_alone(job: tuple) -> dict:
    """Run one episode on its own, through the per-agent dict API (:func:`proteo_env.rollout.run_episode`;
    the policy is reset with the world seed), and with a label draw its end: ``job`` is
    ``(Episode, label)``. Returns ``{"return", "success", "cycles", "metrics", "seconds", "picture"}``
    (JSON-ready; ``picture`` ``None`` without a label, else a base64-encoded PNG captioned
    ``task · label (level) · seed · cycle``)."""
    episode, label = job
    env, policy = built(episode)
    started = time.perf_counter()
    result = run_episode(env, policy, seed=episode.seed)
    out = _record(result, time.perf_counter() - started)
    if label:
        caption = f"{episode.task} · {label} ({episode.level}) · seed {episode.seed} · cycle {result.cycles}"
        out["picture"] = _picture_png(env, caption + (" · success" if result.success else ""))
    return out


def play_jobs(jobs: list, out_dir: Path, *, ray, journal, progress: bool, workers=None) -> None:
    """Run the planned ``jobs`` (``[(Run, Episode, picture)]``) and add each episode to its run;
    pictures go to ``out_dir/pictures/<task>_<picture>_<level>.png``.

    The episodes run in batches of worlds (:func:`training.machinery.evaluator.run_episodes`, on
    ``workers`` processes, default every core, or on Ray); one with a picture runs on its own
    (:func:`run_alone`), since its world is drawn at its end. Each finished episode is
    recorded in ``journal`` under its :func:`~training.machinery.evaluator.episode_key`. An episode's
    ``seconds`` is its batch's wall-clock time shared equally among its episodes.
    """
    pictured = [i for i, (_, _, picture) in enumerate(jobs) if picture]
    plain = [i for i, (_, _, picture) in enumerate(jobs) if not picture]
    episodes: list = [None] * len(jobs)
    if pictured:
        items = [(jobs[i][1], jobs[i][2]) for i in pictured]
        keys = [episode_key(e) for e, _ in items]
        for i, episode in zip(
            pictured,
            run_jobs(run_alone, items, keys, ray=ray, journal=journal, desc="pictured episodes", progress=progress),
        ):
            episodes[i] = episode
    if plain:
        started = time.perf_counter()
        batched = run_episodes(
            [jobs[i][1] for i in plain], ray=ray, workers=workers, journal=journal, progress=progress
        )
        seconds = (time.perf_counter() - started) / len(plain)
        for i, r in zip(plain, batched):
            episodes[i] = _record(r, seconds)
    for (run, episode, picture), result in zip(jobs, episodes):
        run.add(episode.seed, result)
        if result["picture"]:
            file = out_dir / "pictures" / f"{task_name(episode.task)}_{picture}_{episode.level}.png".replace("+", "-")
            file.parent.mkdir(parents=True, exist_ok=True)
            file.write_bytes(base64.b64decode(result["picture"]))


@dataclass
class Plan:
    """Rows to judge and the episodes of their runs, in the order they are played (the order fixes
    the batches of worlds, so a plan played again plays the same episodes)."""

    rows: list[Result] = field(default_factory=list)
    """One record per row (a policy, or a recipe's training seeds, on one task and split)."""
    jobs: list[tuple[Run, Episode, str]] = field(default_factory=list)
    """``(Run, Episode, picture)`` of every episode (:func:`play_jobs`)."""

    def add_run(self, run: Run, controller, task: str, settings: str, level: str, seeds, *, picture: str = ""):
        """``run``'s episodes: ``controller`` on each world seed of ``seeds`` of ``task`` with
        ``settings`` (:func:`training.machinery.evaluator.settings_json`) at ``level``; ``picture``: a label
        to draw the end of its first episode under."""
        for k, seed in enumerate(seeds):
            self.jobs.append((run, Episode(task, settings, level, controller, seed), picture if k == 0 else ""))

    def execute(self, out_dir: Path, *, fingerprint: dict, fresh: bool, what: str, ray, workers, progress: bool,
                write: Callable[[float], object]):  # fmt: skip
        """Play every episode (resuming the journal ``out_dir/episodes.jsonl`` of an unfinished run
        with the same ``fingerprint``, unless ``fresh``), then ``write(seconds)`` the caller's files
        and close the journal; returns what ``write`` returns. ``what`` names the run in errors."""
        journal = Journal(out_dir / "episodes.jsonl", fingerprint, fresh=fresh, what=what)
        started = time.perf_counter()
        play_jobs(self.jobs, out_dir, ray=ray, workers=workers, journal=journal, progress=progress)
        written = write(time.perf_counter() - started)
        journal.complete()
        return written

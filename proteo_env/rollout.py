"""Run one episode of an environment with a policy and collect what happened."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class EpisodeResult:
    """Outcome of one episode.

    Attributes:
        cycles: cycles run.
        success: the task's success flag at the end (``terminated``).
        total_reward: sum over cycles of the team reward.
        metrics: the task's metrics after the last cycle.
        history: one dict per cycle with ``cycle``, ``reward`` and the ``metric/...`` values.
    """

    cycles: int
    success: bool
    total_reward: float
    metrics: dict
    history: list = field(default_factory=list)


def run_episode(env, policy, *, seed: int, progress=None, observe=None) -> EpisodeResult:
    """Reset ``env`` and ``policy`` with ``seed`` and step until the episode ends.

    ``policy`` needs ``reset(seed)`` and ``act(observations) -> actions``. ``progress`` is an
    optional callable receiving each cycle's shared info dict (for progress bars).
    ``observe`` is an optional callable ``observe(env, info)`` called after the reset and
    after every cycle (a :class:`~proteo_env.recording.Recorder`, for example).
    """
    observations, infos = env.reset(seed=seed)
    policy.reset(seed)
    total = 0.0
    success = False
    history = []
    info = next(iter(infos.values()))
    if observe is not None:
        observe(env, info)
    while env.agents:
        observations, rewards, terminations, truncations, infos = env.step(policy.act(observations))
        reward = next(iter(rewards.values()))
        info = next(iter(infos.values()))
        success = next(iter(terminations.values()))
        total += reward
        history.append(
            {"cycle": info["cycle"], "reward": reward, **{k: v for k, v in info.items() if k.startswith("metric/")}}
        )
        if observe is not None:
            observe(env, info)
        if progress is not None:
            progress(info)
    metrics = {k.removeprefix("metric/"): v for k, v in info.items() if k.startswith("metric/")}
    return EpisodeResult(cycles=env.cycle, success=bool(success), total_reward=total, metrics=metrics, history=history)

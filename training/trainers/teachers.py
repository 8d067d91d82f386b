"""A teacher for every world of a batch: the hand-coded rules' action for every module's observation.

Imitation (:mod:`training.trainers.imitate`) labels the states the learner visits with the teacher's
action, and kickstarting (:mod:`training.trainers.ppo` with ``distill_coef``) pulls the learner towards
it. The teacher is a policy of :data:`baselines.POLICIES` by name: ``"rules"`` (the default)
is the task's own hand-coded policy with the task's rule parameters, as the ``move`` level's
autopilot builds it (:func:`baselines.autopilot.hand_coded_rules`); naming the task
(``"grasp"`` for ``grasp-v0``) is the same. Another behaviour's rules do not fit the task and
are refused. A path to a checkpoint (any that ``proteo eval`` loads, of the same task and
control level) makes that policy the teacher: for example PPO's locomotion moves, which beat
the rules, taught to a new network; a checkpoint of another task or level is refused.

Each world has its own teacher instance with its own private memory (the rules' heading,
growth direction, whether they asked to move), fed every cycle with that world's
observation, and reset with the world's episode. That memory records the moves the teacher
*proposed*, not the ones the learner made: the label is what the rules would do next from
where they believe they are, the same convention as the autopilot's (:mod:`proteo_env.control`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from baselines import POLICIES
from baselines.autopilot import hand_coded_rules
from baselines.base import PolicyBatch
from proteo_env.config import ConfigError
from proteo_env.env import ProteoEnv
from training.machinery.checkpoints import load_policy

DEFAULT_TEACHER = "rules"


def is_checkpoint(name: str) -> bool:
    """Whether teacher ``name`` is a path (a checkpoint) rather than a policy name."""
    return "/" in name or Path(name).exists()


def check_teacher(name: str, task_name: str) -> str:
    """The policy name ``name`` stands for on task ``task_name``; a :class:`ConfigError` naming
    the teacher, the task and the allowed names when it does not fit."""
    allowed = (DEFAULT_TEACHER, task_name)
    if name in allowed and task_name in POLICIES:
        return task_name
    if task_name not in POLICIES:
        raise ConfigError(
            f"teacher={name!r}: task {task_name!r} has no hand-coded rules to teach; allowed: a task "
            f"with rules ({', '.join(sorted(set(POLICIES) - {'random'}))})"
        )
    raise ConfigError(
        f"teacher={name!r} does not fit task {task_name!r}; allowed: "
        f"{', '.join(map(repr, allowed))} (the task's hand-coded rules) or a checkpoint of the task"
    )


class Teachers:
    """One teacher per world of a :class:`~proteo_env.batched.BatchedEnv` (``n_envs`` worlds of
    ``n_agents`` modules; observation rows world-major, as the batch hands them out).

    Args:
        env: a batched env of the task (its task, full action layout and physics build the teachers).
        n_envs: worlds taught (those of one or several such envs, in order).
        name: the teacher (:func:`check_teacher`).
        seed: teacher ``b``'s ``e``-th episode is seeded from ``(seed, first_world + b, e)``.
        n_fields: how many leading fields of the full action a label holds (the control level's).
        first_world: the number of the first world taught among all the run's worlds (a share of
            them taught in another process: :class:`training.trainers.worlds.WorkerEnvs`).
    """

    def __init__(
        self, env, n_envs: int, name: str = DEFAULT_TEACHER, *, seed: int = 0, n_fields: int = 1, first_world: int = 0
    ):
        self.n_agents, self.n_fields, self.seed, self.first_world = env.n_agents, n_fields, seed, first_world
        self.episodes = np.zeros(n_envs, dtype=np.int64)
        self.checkpoint = None
        """The learned teacher (a :class:`~training.machinery.policies.LogitsPolicy`), when ``name`` is a checkpoint."""
        if is_checkpoint(name):
            task = env.tasks[0]
            self.checkpoint = load_policy(name, ProteoEnv(type(task)(task.params), env.config), seed=seed)
            self.policies = []
            return
        check_teacher(name, env.task.name)
        self.policies = [hand_coded_rules(env) for _ in range(n_envs)]
        self._batches: dict[int, PolicyBatch] = {}
        """The teachers of each group of worlds, by its first world."""
        for b in range(n_envs):
            self._reset(b)

    def _reset(self, b: int) -> None:
        if self.checkpoint is not None:  # the learned teacher's memory is kept by row
            self.checkpoint.forget(range(b * self.n_agents, (b + 1) * self.n_agents))
            return
        self.policies[b].reset(
            seed=int(
                np.random.SeedSequence([self.seed, self.first_world + b, int(self.episodes[b])]).generate_state(
                    1, np.uint64
                )[0]
                >> 1
            )
        )
        self.episodes[b] += 1

    def labels(self, groups) -> np.ndarray:
        """``(n_envs * n_agents, n_fields)`` int64: every module's teacher action for the
        observations ``groups`` (a list of :class:`~proteo_env.spaces.ObservationBuffers`, one
        per env, world-major, together ``n_envs`` worlds). Call once per cycle, in order: the
        teachers' memory advances with each call."""
        a = self.n_agents
        if self.checkpoint is not None:  # one call over every module of every world
            encoder = self.checkpoint.encoder
            features = np.concatenate([encoder.encode_buffers(buffers) for buffers in groups])
            mask = np.concatenate([buffers.action_mask for buffers in groups]).astype(bool)
            return self.checkpoint.act_arrays(features, mask)[:, : self.n_fields]
        sizes = [len(buffers.own_mode) // a for buffers in groups]
        if sum(sizes) != len(self.policies):
            raise ValueError(
                f"observations of {sum(sizes)} worlds are not allowed; allowed: {len(self.policies)} worlds"
            )
        labels, first = [], 0
        for buffers, n in zip(groups, sizes):
            if first not in self._batches:
                self._batches[first] = PolicyBatch(self.policies[first : first + n])
            labels.append(self._batches[first].act_arrays(buffers)[:, : self.n_fields])
            first += n
        return np.concatenate(labels)

    def restart(self, worlds) -> None:
        """New episodes for the teachers of ``worlds`` (indices or ``(n_envs,)`` bool)."""
        worlds = np.asarray(worlds)
        for b in np.flatnonzero(worlds) if worlds.dtype == np.bool_ else worlds:
            self._reset(int(b))

"""Stable-Baselines3 adapters: one shared policy for every module.

:class:`ProteoVecEnv` is an SB3 ``VecEnv`` in which every agent of every environment copy is
one sub-environment. An SB3 algorithm trained on it learns one policy that all modules share
(parameter sharing); each module sees only its own observation, flattened by
:class:`~proteo_env.adapters.flatten.ObservationEncoder`, and gets the team reward. It steps
the copies through the array API (``env.step_arrays`` / ``env.observe_arrays``), with no
per-agent dicts and no SuperSuit.

Sub-env ``i`` is agent ``i % A`` of copy ``i // A`` (``A`` agents per copy). When a copy's
episode ends (task success or ``max_cycles``) all its ``A`` sub-envs report ``done``, carry
``terminal_observation`` and ``TimeLimit.truncated`` in their infos, and the copy resets. The
info of the copy's first agent also carries ``episode`` (``r``: team return, ``l``: cycles,
``t``: seconds), ``is_success`` and the task's metrics as ``metric/<name>``, so SB3's logger
counts every episode once.

:meth:`ProteoVecEnv.action_masks` gives the masks sb3-contrib's ``MaskablePPO`` wants:
the 13-long move mask followed by all-ones for the other action fields.

:class:`ProteoAgentEnv` is a single-agent ``gymnasium.Env`` view (one module learns, the
others follow a fixed policy) with the same spaces and encoding; it exists so that SB3's
``env_checker.check_env`` can check the encoding, spaces and masks.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from ..config import world_seeds
from ..registry import make
from .flatten import ObservationEncoder, flat_action_mask


def _observation_box(encoder: ObservationEncoder) -> gym.spaces.Box:
    return gym.spaces.Box(low=-1.0, high=np.inf, shape=(encoder.size,), dtype=np.float32)


class ProteoVecEnv(VecEnv):
    """Every agent of ``n_copies`` copies of a task as one sub-env of an SB3 ``VecEnv``.

    Args:
        task_id: a registered task id (``"chain-v0"``).
        n_copies: independent copies of the environment stepped one after another.
        seed: copy ``c`` is seeded with child ``c`` of ``SeedSequence(seed)``
            (:func:`proteo_env.config.world_seeds`) at the first reset (``None``: random).
        **overrides: passed to :func:`proteo_env.make` (``n_modules``, ``max_cycles``, ...).

    Spaces:
        observation ``Box(float32, (D,))`` with ``D = encoder.size``; action the ``MultiDiscrete``
        of the fields the agent chooses at the env's control level (``overrides["control"]``):
        ``[move, mode, role_0..role_{C-1}, message_target, message_value]`` at ``full``, ``[move]``
        at ``move``, ``[move, mode]`` at ``move+mode`` (the task's rules fill in the rest).
    """

    def __init__(self, task_id: str, *, n_copies: int = 1, seed: int | None = None, **overrides):
        if n_copies < 1:
            raise ValueError(f"n_copies={n_copies!r} is not allowed; allowed: an integer >= 1")
        self.envs = [make(task_id, **overrides) for _ in range(n_copies)]
        first = self.envs[0]
        self.task_id = first.task.task_id()
        self.overrides = dict(overrides)
        self.n_agents = len(first.possible_agents)
        self.n_copies = n_copies
        self.encoder = ObservationEncoder.for_env(first)
        self.nvec = first.control_nvec
        action_space = gym.spaces.MultiDiscrete(self.nvec)
        super().__init__(n_copies * self.n_agents, _observation_box(self.encoder), action_space)
        if seed is not None:
            self.seed(seed)
        self._obs = np.zeros((self.num_envs, self.encoder.size), dtype=np.float32)
        self._masks = np.ones((self.num_envs, int(self.nvec.sum())), dtype=bool)
        self._actions: np.ndarray | None = None
        self._returns = np.zeros(n_copies)
        self._started = np.zeros(n_copies)
        self.step_seconds = 0.0
        """Wall-clock seconds spent in :meth:`step_wait` (environment, encoding, resets)."""

    # ------------------------------------------------------------------ helpers
    def _rows(self, copy: int) -> slice:
        return slice(copy * self.n_agents, (copy + 1) * self.n_agents)

    def _observe(self, copy: int) -> None:
        buffers = self.envs[copy].observe_arrays()
        rows = self._rows(copy)
        self._obs[rows] = self.encoder.encode_buffers(buffers)
        self._masks[rows] = flat_action_mask(buffers.action_mask, self.nvec)

    def seed(self, seed: int | None = None) -> list:
        """Seed copy ``c`` with child ``c`` of ``SeedSequence(seed)`` at the next reset (SB3's own
        ``seed + row`` would let the copies of seeds ``s`` and ``s + A`` share streams)."""
        if seed is None:
            seed = int(np.random.default_rng().integers(2**31))
        children = world_seeds(int(seed), self.n_copies)
        self._seeds = [children[row // self.n_agents] for row in range(self.num_envs)]
        return self._seeds

    def _reset_copy(self, copy: int, seed) -> None:
        self.envs[copy].reset(seed=seed)
        self._returns[copy] = 0.0
        self._started[copy] = time.perf_counter()
        self._observe(copy)

    # ------------------------------------------------------------------ VecEnv API
    def reset(self):
        for c in range(self.n_copies):
            seed = self._seeds[c * self.n_agents]
            self._reset_copy(c, seed)
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return self._obs.copy()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.int64).reshape(self.num_envs, len(self.nvec))

    def step_wait(self):
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async(); call step(actions)")
        started = time.perf_counter()
        rewards = np.zeros(self.num_envs, dtype=np.float32)
        dones = np.zeros(self.num_envs, dtype=bool)
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for c, env in enumerate(self.envs):
            rows = self._rows(c)
            result = env.step_arrays(self._actions[rows])
            reward = float(result.reward[0])
            self._returns[c] += reward
            rewards[rows] = reward
            self._observe(c)
            success, truncated = bool(result.terminated[0]), bool(result.truncated[0])
            if success or truncated:
                dones[rows] = True
                for i in range(rows.start, rows.stop):
                    infos[i] = {"terminal_observation": self._obs[i].copy(), "TimeLimit.truncated": truncated}
                first = infos[rows.start]
                first["episode"] = {
                    "r": float(self._returns[c]),
                    "l": int(env.cycle),
                    "t": round(time.perf_counter() - self._started[c], 6),
                }
                first["is_success"] = success
                first.update({f"metric/{k}": v for k, v in env.task.metrics(env.engine).items()})
                self._reset_copy(c, None)
        self._actions = None
        self.step_seconds += time.perf_counter() - started
        return self._obs.copy(), rewards, dones, infos

    def action_masks(self) -> np.ndarray:
        """``(num_envs, sum(nvec))`` bool: the move mask then all-ones (sb3-contrib layout)."""
        return self._masks.copy()

    def close(self) -> None:
        for env in self.envs:
            env.close()

    def has_attr(self, attr_name: str) -> bool:
        return attr_name == "action_masks" or hasattr(self.envs[0], attr_name)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        if attr_name == "render_mode":
            return [None for _ in self._get_indices(indices)]
        return [getattr(self.envs[i // self.n_agents], attr_name) for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        for c in sorted({i // self.n_agents for i in self._get_indices(indices)}):
            setattr(self.envs[c], attr_name, value)

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        indices = list(self._get_indices(indices))
        if method_name == "action_masks":
            return list(self._masks[indices])
        return [getattr(self.envs[i // self.n_agents], method_name)(*method_args, **method_kwargs) for i in indices]

    def env_is_wrapped(self, wrapper_class, indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None for _ in range(self.num_envs)]


class ProteoAgentEnv(gym.Env):
    """One module of a task as a single-agent ``gymnasium.Env`` (for SB3's ``check_env``).

    The learning module is ``module_{agent}``; every other module acts by ``co_policy``
    (a callable ``(env, buffers, rng) -> (A, L)`` actions; default: random legal moves with
    the other fields uniform). Observation, action space and ``action_masks()`` are those of
    :class:`ProteoVecEnv`.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        task_id: str,
        *,
        agent: int = 0,
        co_policy: Callable[[Any, Any, np.random.Generator], np.ndarray] | None = None,
        **overrides,
    ):
        self.env = make(task_id, **overrides)
        self.agent = agent
        self.encoder = ObservationEncoder.for_env(self.env)
        self.nvec = self.env.control_nvec
        self.observation_space = _observation_box(self.encoder)
        self.action_space = gym.spaces.MultiDiscrete(self.nvec)
        self.co_policy = co_policy or _random_legal
        self._rng = np.random.default_rng()
        self._buffers = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.env.reset(seed=seed)
        self._buffers = self.env.observe_arrays()
        return self.encoder.encode_buffers(self._buffers)[self.agent], {}

    def step(self, action):
        actions = np.asarray(self.co_policy(self.env, self._buffers, self._rng), dtype=np.int64)
        actions[self.agent] = np.asarray(action, dtype=np.int64)
        result = self.env.step_arrays(actions)
        self._buffers = self.env.observe_arrays()
        info = {f"reward/{k}": v for k, v in result.terms[0].items()}
        obs = self.encoder.encode_buffers(self._buffers)[self.agent]
        return obs, float(result.reward[0]), bool(result.terminated[0]), bool(result.truncated[0]), info

    def action_masks(self) -> np.ndarray:
        """``(sum(nvec),)`` bool: the learning module's move mask then all-ones."""
        return flat_action_mask(self._buffers.action_mask[self.agent : self.agent + 1], self.nvec)[0]


def _random_legal(env, buffers, rng: np.random.Generator) -> np.ndarray:
    """Uniform legal moves, every other field of the control level uniform (the random baseline, vectorised)."""
    nvec = env.control_nvec
    actions = rng.integers(0, nvec, size=(buffers.action_mask.shape[0], len(nvec)))
    actions[:, 0] = (rng.random(buffers.action_mask.shape) * buffers.action_mask).argmax(axis=1)
    return actions

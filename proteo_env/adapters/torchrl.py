"""A native TorchRL ``EnvBase`` over the array API: ``n_copies`` copies of a task, batched.

TorchRL's ``PettingZooWrapper`` works on :class:`~proteo_env.env.ProteoEnv` too, but it goes
through per-agent dicts every cycle; this env reads ``env.observe_arrays()`` and calls
``env.step_arrays()`` directly (docs/journal/learning-first-round.md compares the two).

Batch size ``(n_copies,)``; the ``A`` modules of a copy form the agent group ``"agents"``. The
action is the control level's (``control`` among the overrides, default ``full``; ``nvec`` is the
level's ``control_nvec``): at ``move`` one ``Categorical(13)`` per module with its 13-wide move
mask (the form of TorchRL's ``MaskedCategorical`` and of BenchMARL's masked IPPO and MAPPO); at
``move+mode`` and ``full`` a ``MultiCategorical(nvec)`` of the level's ``L`` fields with one flat
mask over their concatenated choices (moves masked, every other choice allowed: the layout of
sb3-contrib's ``MaskablePPO``; :func:`training.trainers.torchrl_ppo.make_distribution_class` samples it):

==================================== ========================= ==============================================
key                                  shape                     meaning
==================================== ========================= ==============================================
``("agents", "observation")``        (n_copies, A, D)          float32, :class:`~.flatten.ObservationEncoder`
``("agents", "action_mask")``        (n_copies, A, 13) at      bool, the legal moves (``move``), or the move
                                     ``move``, else            mask then all-ones
                                     (n_copies, A, sum(nvec))
``("agents", "action")``             (n_copies, A) at          int64 ``Categorical(13)`` (``move``), else
                                     ``move``, else            ``MultiCategorical(nvec)``
                                     (n_copies, A, L)
``("agents", "reward")``             (n_copies, A, 1)          float32, the team reward (same for every module)
``"done"``, ``"terminated"``,        (n_copies, 1)             bool: terminated = task success, truncated =
``"truncated"``                                                ``max_cycles`` reached, done = either
``"state"``                          (n_copies, S)             float32 global state (``env.state()``), for MAPPO
==================================== ========================= ==============================================

A partial reset (``"_reset"`` in the reset tensordict, as TorchRL's collectors send when
some copies are done) resets only those copies. ``set_seed(s)`` seeds copy ``c`` with child
``c`` of ``numpy.random.SeedSequence(s)`` (:func:`proteo_env.config.world_seeds`) at its next
reset, so no two copies and no two seeds share a stream.
"""

from __future__ import annotations

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Binary, Categorical, Composite, MultiCategorical, Unbounded
from torchrl.envs import EnvBase

from ..config import ConfigError, check_seed, world_seeds
from ..registry import make
from .flatten import ObservationEncoder, flat_action_mask


class ProteoTorchRLEnv(EnvBase):
    """``n_copies`` copies of a task as one batched multi-agent TorchRL environment.

    Args:
        task_id: a registered task id (``"chain-v0"``).
        n_copies: copies stepped one after another (the batch dimension).
        seed: copy ``c`` is seeded with child ``c`` of ``SeedSequence(seed)`` at the first reset (``None``: random).
        **overrides: passed to :func:`proteo_env.make` (``control="move"`` chooses the level).
    """

    def __init__(self, task_id: str, *, n_copies: int = 1, seed: int | None = None, device="cpu", **overrides):
        if isinstance(n_copies, bool) or not isinstance(n_copies, int | np.integer) or n_copies < 1:
            raise ConfigError(f"n_copies={n_copies!r} is not allowed; allowed: an integer >= 1")
        super().__init__(batch_size=torch.Size([n_copies]), device=device)
        self.envs = [make(task_id, **overrides) for _ in range(n_copies)]
        first = self.envs[0]
        self.task_id = first.task.task_id()
        self.n_agents = len(first.possible_agents)
        self.n_copies = n_copies
        self.encoder = ObservationEncoder.for_env(first)
        self.control = first.control
        self.nvec = np.asarray(first.control_nvec)
        """The level's action fields' sizes (``[13]`` at ``move``)."""
        self.single = self.control == "move"
        """One categorical per module (``move``), else one field per column."""
        self._seeds: list = [None] * n_copies
        if seed is not None:
            self._set_seed(seed)
        b, a, d = n_copies, self.n_agents, self.encoder.size
        n = int(self.nvec[0]) if self.single else int(self.nvec.sum())
        self.state_size = first.state_space.shape[0]
        self.observation_spec = Composite(
            agents=Composite(
                observation=Unbounded(shape=(b, a, d), dtype=torch.float32, device=device),
                action_mask=Binary(n=n, shape=(b, a, n), dtype=torch.bool, device=device),
                shape=(b, a),
            ),
            state=Unbounded(shape=(b, self.state_size), dtype=torch.float32, device=device),
            shape=(b,),
        )
        if self.single:
            action = Categorical(n, shape=(b, a), dtype=torch.int64, device=device)
        else:
            action = MultiCategorical(
                nvec=torch.as_tensor(self.nvec), shape=(b, a, len(self.nvec)), dtype=torch.int64, device=device
            )
        self.action_spec = Composite(agents=Composite(action=action, shape=(b, a)), shape=(b,))
        self.reward_spec = Composite(
            agents=Composite(reward=Unbounded(shape=(b, a, 1), dtype=torch.float32, device=device), shape=(b, a)),
            shape=(b,),
        )
        self.done_spec = Composite(
            done=Categorical(2, shape=(b, 1), dtype=torch.bool, device=device),
            terminated=Categorical(2, shape=(b, 1), dtype=torch.bool, device=device),
            truncated=Categorical(2, shape=(b, 1), dtype=torch.bool, device=device),
            shape=(b,),
        )
        self._obs = np.zeros((b, a, d), dtype=np.float32)
        self._mask = np.ones((b, a, n), dtype=bool)
        self._state = np.zeros((b, self.state_size), dtype=np.float32)
        self.step_seconds = 0.0

    # ------------------------------------------------------------------ helpers
    def _observe(self, c: int) -> None:
        env = self.envs[c]
        buffers = env.observe_arrays()
        self._obs[c] = self.encoder.encode_buffers(buffers)
        self._mask[c] = buffers.action_mask if self.single else flat_action_mask(buffers.action_mask, self.nvec)
        self._state[c] = env.state()

    def _observation_td(self, reward: np.ndarray | None = None) -> dict:
        agents = {"observation": torch.from_numpy(self._obs.copy()), "action_mask": torch.from_numpy(self._mask.copy())}
        if reward is not None:
            agents["reward"] = torch.from_numpy(reward)
        return {
            "agents": TensorDict(agents, batch_size=(self.n_copies, self.n_agents), device=self.device),
            "state": torch.from_numpy(self._state.copy()),
        }

    # ------------------------------------------------------------------ EnvBase API
    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        which = range(self.n_copies)
        if tensordict is not None and "_reset" in tensordict.keys():
            flags = tensordict.get("_reset").reshape(self.n_copies).cpu().numpy()
            which = np.flatnonzero(flags)
        for c in which:
            seed, self._seeds[c] = self._seeds[c], None
            self.envs[c].reset(seed=seed)
            self._observe(c)
        false = torch.zeros((self.n_copies, 1), dtype=torch.bool)
        return TensorDict(
            {**self._observation_td(), "done": false.clone(), "terminated": false.clone(), "truncated": false.clone()},
            batch_size=self.batch_size,
            device=self.device,
        )

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        import time

        started = time.perf_counter()
        actions = tensordict.get(("agents", "action")).cpu().numpy()
        if actions.dtype.kind not in "iu":
            raise ValueError(
                f"('agents', 'action') of dtype {actions.dtype} is not allowed; allowed: integers (the spec's int64), "
                "not values to round"
            )
        actions = actions.astype(np.int64)
        if self.single:
            actions = actions[..., None]  # (n_copies, A) -> the level's (n_copies, A, 1)
        reward = np.zeros((self.n_copies, self.n_agents, 1), dtype=np.float32)
        terminated = np.zeros((self.n_copies, 1), dtype=bool)
        truncated = np.zeros((self.n_copies, 1), dtype=bool)
        for c, env in enumerate(self.envs):
            result = env.step_arrays(actions[c])
            reward[c] = result.reward[0]
            self._observe(c)
            terminated[c], truncated[c] = result.terminated[0], result.truncated[0]
        out = TensorDict(
            {
                **self._observation_td(reward),
                "done": torch.from_numpy(terminated | truncated),
                "terminated": torch.from_numpy(terminated),
                "truncated": torch.from_numpy(truncated),
            },
            batch_size=self.batch_size,
            device=self.device,
        )
        self.step_seconds += time.perf_counter() - started
        return out

    def _set_seed(self, seed: int | None) -> None:
        if seed is None:
            seed = int(np.random.default_rng().integers(2**31))
        self._seeds = world_seeds(check_seed(seed), self.n_copies)

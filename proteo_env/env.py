"""The PettingZoo parallel environment over the lattice world."""

from __future__ import annotations

import dataclasses

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from .batched import BatchedEnv, StepResult
from .config import EnvConfig, check_seed
from .core.world import World
from .spaces import ModuleActionSpace, ObservationBuffers, observation_space
from .tasks.base import Task


@dataclasses.dataclass(frozen=True)
class WorldView:
    """Read-only snapshot of the world for tools and users (arrays are read-only copies).

    Attributes:
        positions: ``(N, 3)`` int64 module sites, agents first (``module_i`` is row ``i``).
        modes: ``(N,)`` int32 modes; ``mode_names[m]`` names mode ``m``.
        scents: ``(C, N)`` int32 scent values (``scent_max``: no scent).
        anchored: ``(N,)`` bool, modules that never move.
        n_agents: number of agents (the first rows).
        solid_sites: ``(S, 3)`` obstacle sites (the floor is ``z < 0`` when ``floor``).
        object_sites: ``(O, 3)`` object sites.
        box: ``(X, Y, Z)`` box size.
        floor: ground below ``z = 0``.
        motion_model, keep_connected, scent_max: the physics in force.
        mode_names: the task's mode names.
        cycle: cycles run since reset.
    """

    positions: np.ndarray
    modes: np.ndarray
    scents: np.ndarray
    anchored: np.ndarray
    n_agents: int
    solid_sites: np.ndarray
    object_sites: np.ndarray
    box: tuple
    floor: bool
    motion_model: str
    keep_connected: bool
    scent_max: int
    mode_names: tuple
    cycle: int


def env_name(task_id: str) -> str:
    """The PettingZoo name (``metadata["name"]``) of a task's env: ``"chain-v1"`` -> ``"proteo_chain_v1"``."""
    return "proteo_" + task_id.replace("-", "_")


def _read_only(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


class ProteoEnv(ParallelEnv):
    """Modules of a Proteo lattice robot as agents of a PettingZoo parallel environment.

    Each cycle every agent sends one action, the world runs the paper's cycle (modes and
    messages applied, moves tried one by one in a fresh random order, scents relaxed), and
    every agent gets its local observation back.

    Args:
        task: a :class:`~proteo_env.tasks.base.Task` instance (start layout, rules, reward).
        config: :class:`~proteo_env.config.EnvConfig` (cycle limit, radius, physics).
        render_mode: ``None``, ``"ansi"`` (text layers), ``"rgb_array"`` (:meth:`render` returns an
            ``(H, W, 3)`` uint8 picture) or ``"human"`` (a matplotlib window).
        camera: settings of the pictures: a :class:`~proteo_env.render.camera.Camera` or a dict
            of its fields (``azimuth``, ``elevation``, ``zoom``, ``follow``, ``width``, ``height``).

    Spaces (the same objects on every call):
        observation ``Dict`` and action ``MultiDiscrete``, documented in :mod:`proteo_env.spaces`;
        ``action_layout`` names the fields of the task's full action. At the control level
        ``config.control`` (:mod:`proteo_env.control`) the action holds only the chosen fields:
        ``Discrete(13)`` (an int, the move) at ``"move"``, ``MultiDiscrete([13, n_modes])`` at
        ``"move+mode"``, the full ``MultiDiscrete`` at ``"full"`` (the default);
        ``control_fields`` names them.

    Returns of :meth:`step` (dicts keyed by agent name):
        observations, rewards (the task's team reward: the sum of its terms), terminations
        (task success), truncations (``max_cycles`` reached), infos (one shared dict per
        cycle with ``reward/<term>``, ``metric/<name>``, ``cycle`` and ``moved``, the number
        of modules that moved).

    ``env.world`` is a read-only :class:`WorldView`; ``env.engine`` is the underlying
    :class:`~proteo_env.core.world.World`. The array API (no per-agent dicts) is
    :meth:`step_arrays` / :meth:`observe_arrays`.
    """

    metadata = {
        "name": "proteo",  # each env's own: proteo_<task>_v<version> (e.g. proteo_chain_v1)
        "render_modes": ["ansi", "rgb_array", "human"],
        "render_fps": 10,
        "is_parallelizable": True,
    }

    def __init__(self, task: Task, config: EnvConfig | None = None, render_mode: str | None = None, camera=None):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode={render_mode!r} is not allowed; allowed: None or "
                f"{', '.join(self.metadata['render_modes'])}"
            )
        self.task = task
        self.metadata = {**type(self).metadata, "name": env_name(task.task_id())}
        self.config = config or EnvConfig()
        self.render_mode = render_mode
        self.camera = camera
        if render_mode in ("rgb_array", "human"):
            from .render.camera import Camera

            self.camera = Camera.from_options(camera)  # checked now, not at the first render
        self._viewer = None
        self.max_cycles = self.config.max_cycles
        self.batch = BatchedEnv([task], self.config)
        self.action_layout = self.batch.action_layout
        self.possible_agents = [f"module_{i}" for i in range(self.batch.n_agents)]
        self.agents: list[str] = []
        self._action_space = self._level_space()
        self._observation_space = observation_space(
            n_sites=self.batch.n_sites,
            n_channels=task.n_channels,
            n_modes=len(task.modes),
            n_message_values=task.n_message_values,
            scent_max=self.config.physics.scent_max,
        )
        n_state = self.batch.n_modules * (4 + task.n_channels)
        self.state_space = spaces.Box(low=-1, high=np.iinfo(np.int32).max, shape=(n_state,), dtype=np.int32)

    @property
    def engine(self) -> World | None:
        """The underlying :class:`~proteo_env.core.world.World` (``None`` before :meth:`reset`)."""
        return None if self.batch.world_batch is None else self.batch.worlds[0]

    @property
    def cycle(self) -> int:
        return int(self.batch.cycles[0])

    @property
    def last_moved(self) -> np.ndarray:
        """``(A,)`` bool: who moved in the last cycle."""
        return self.batch.last_moved[0]

    @property
    def control(self) -> str:
        """The control level (``"move"``, ``"move+mode"`` or ``"full"``)."""
        return self.batch.control

    @property
    def control_fields(self) -> tuple[str, ...]:
        """The action fields the agent chooses at this level (a prefix of ``action_layout``'s)."""
        return self.batch.control_fields

    @property
    def control_nvec(self) -> np.ndarray:
        return self.batch.control_nvec

    # ------------------------------------------------------------------ spaces
    def _level_space(self):
        if self.control == "move":
            return spaces.Discrete(int(self.control_nvec[0]))
        return ModuleActionSpace(self.control_nvec)

    def observation_space(self, agent):
        return self._observation_space

    def action_space(self, agent):
        return self._action_space

    # ------------------------------------------------------------------ episode
    def reset(self, seed=None, options=None):
        seed = check_seed(seed)
        buffers = self.batch.reset(world_seeds=None if seed is None else [seed])
        self.agents = list(self.possible_agents)
        # the same keys as every step's info (TorchRL builds its info spec from the reset's)
        world = self.batch.worlds[0]
        terms = self.task.reward_terms(world, np.zeros(world.n_agents, dtype=np.bool_))
        info = {
            "cycle": 0,
            "moved": 0,
            **{f"reward/{k}": 0.0 for k in terms},
            **{f"metric/{k}": v for k, v in self.batch.metrics()[0].items()},
        }
        return buffers.per_agent(self.agents), {a: info for a in self.agents}

    def step(self, actions):
        self._need_world()
        if not self.agents:
            raise RuntimeError("step() called after the episode ended; call reset() first")
        batch = self._action_batch(actions)
        result = self.step_arrays(batch)
        buffers = self.observe_arrays()
        metrics = self.batch.metrics()[0]
        success, truncated, reward = bool(result.terminated[0]), bool(result.truncated[0]), float(result.reward[0])
        info = {
            "cycle": self.cycle,
            "moved": int(self.last_moved.sum()),
            **{f"reward/{k}": v for k, v in result.terms[0].items()},
            **{f"metric/{k}": v for k, v in metrics.items()},
        }
        agents = self.agents
        observations = buffers.per_agent(self.agents)
        rewards = dict.fromkeys(agents, reward)
        terminations = dict.fromkeys(agents, success)
        truncations = dict.fromkeys(agents, truncated)
        infos = dict.fromkeys(agents, info)
        if success or truncated:
            self.agents = []
        return observations, rewards, terminations, truncations, infos

    def _action_batch(self, actions: dict) -> np.ndarray:
        """Stack the per-agent actions into ``(A, F)`` (``F`` fields of the control level; an int,
        or a ``(1,)`` array, per agent at ``"move"``); any problem raises a ``ValueError`` naming
        the agent."""
        fields = self.control_fields
        scalar = self.control == "move"
        if not isinstance(actions, dict):
            raise ValueError(
                f"actions of type {type(actions).__name__} are not allowed; allowed: a dict {{agent: action}} for every "
                "agent in env.agents (env.step_arrays takes an (A, F) array)"
            )
        if len(actions) != len(self.agents) or not all(a in actions for a in self.agents):
            missing = [a for a in self.agents if a not in actions]
            if missing:
                raise ValueError(
                    f"actions missing for {len(missing)} agents (first: {missing[0]}); "
                    "allowed: one action for every agent in env.agents"
                )
            unknown = [a for a in actions if a not in set(self.agents)]
            raise ValueError(
                f"actions for {len(unknown)} unknown agents (first: {unknown[0]!r}); allowed: the agents in env.agents"
            )
        shapes = [(), (1,)] if scalar else [(len(fields),)]
        try:
            batch = np.asarray([actions[a] for a in self.agents])
        except (ValueError, TypeError):
            batch = None
        if batch is None or batch.shape[1:] not in shapes or batch.dtype.kind not in "iu":
            allowed = "an int, the move" if scalar else f"{shapes[0]} = {list(fields)}"
            for a in self.agents:
                value = np.asarray(actions[a])
                if value.shape not in shapes:
                    raise ValueError(
                        f"action of {a}: shape {value.shape} is not allowed{self.batch.at_level}; allowed: {allowed}"
                    )
                if value.dtype.kind not in "iu":
                    raise ValueError(f"action of {a}: dtype {value.dtype} is not allowed; allowed: integers")
        return batch.reshape(len(self.agents), len(fields)).astype(np.int64, copy=False)

    # ------------------------------------------------------------------ array API
    def step_arrays(self, actions: np.ndarray) -> StepResult:
        """One cycle from an ``(A, F)`` int array of actions (rows in agent order; ``F`` fields
        of the control level, ``F = L`` at ``"full"``).

        Checks the batch first (a bad one raises ``ValueError`` and changes nothing), runs
        the cycle, and returns its :class:`~proteo_env.batched.StepResult` (``B = 1``: the
        team reward ``reward[0]``, ``terminated[0]``, ``truncated[0]``, the reward terms
        ``terms[0]``). ``self.last_moved`` says who moved. Once the episode has ended (success or
        ``max_cycles``) another step is a ``RuntimeError`` until :meth:`reset`.
        """
        self._need_world()
        if self.batch.ended[0]:
            raise RuntimeError(
                f"step_arrays() called after the episode ended at cycle {self.cycle}; call reset() first"
            )
        actions = np.asarray(actions)
        expected = (self.batch.n_agents, len(self.control_fields))
        if actions.shape != expected:
            raise ValueError(
                f"actions shape {actions.shape} is not allowed{self.batch.at_level}; "
                f"allowed: {expected}, one row per agent of {list(self.control_fields)}"
            )
        return self.batch.step_arrays(actions[None])

    def observe_arrays(self) -> ObservationBuffers:
        """Fresh :class:`~proteo_env.spaces.ObservationBuffers` with every agent's observation."""
        self._need_world()
        return self.batch.observe_arrays()

    # ------------------------------------------------------------------ views
    def _need_world(self) -> World:
        """The current world; a ``RuntimeError`` saying to call :meth:`reset` when there is none yet."""
        w = self.engine
        if w is None:
            raise RuntimeError("no world yet; call reset() first")
        return w

    @property
    def world(self) -> WorldView:
        """A read-only :class:`WorldView` of the current world (after :meth:`reset`)."""
        w = self._need_world()
        p = w.physics
        return WorldView(
            positions=_read_only(w.positions),
            modes=_read_only(w.mode),
            scents=_read_only(w.scent),
            anchored=_read_only(w.anchored),
            n_agents=w.n_agents,
            solid_sites=_read_only(w.solid_sites),
            object_sites=_read_only(w.object_sites),
            box=w.shape.size,
            floor=w.floor,
            motion_model=p.motion_model,
            keep_connected=p.keep_connected,
            scent_max=p.scent_max,
            mode_names=tuple(self.task.modes),
            cycle=self.cycle,
        )

    def state(self) -> np.ndarray:
        """Global state: per module ``x, y, z, mode, scent_0 .. scent_{C-1}``, flattened (int32)."""
        w = self._need_world()
        per_module = np.concatenate([w.positions, w.mode[:, None], w.scent.T], axis=1)
        return per_module.astype(np.int32).reshape(-1)

    def render(self):
        """The picture of the current world in ``render_mode`` (see :mod:`proteo_env.render`)."""
        if self.render_mode is None:
            return None
        self._need_world()
        if self.render_mode != "ansi":
            if self._viewer is None:
                from .render.viewer import Viewer

                self._viewer = Viewer(
                    self.render_mode, self.camera, fps=self.metadata["render_fps"], caption=self.task.task_id()
                )
            return self._viewer.render(self.world)
        from .layouts import Layout, format_layout

        w = self.engine
        pos = w.positions
        text = format_layout(
            Layout(
                size=w.shape.size,
                modules=pos[~w.anchored],
                fixed=pos[w.anchored],
                solid=w.solid_sites,
                object_sites=w.object_sites,
                floor=w.floor,
            )
        )
        return f"cycle {self.cycle}\n{text}"

    def close(self):
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None

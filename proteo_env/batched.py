"""The batched environment: ``B`` copies of one task stepped together on arrays.

:class:`BatchedEnv` is the array API of proteo: actions in as one ``(B, A, L)`` int array,
observations out as :class:`~proteo_env.spaces.ObservationBuffers` with ``B * A`` rows
(world-major: row ``b * A + i`` is agent ``module_i`` of world ``b``), rewards, success and
metrics per world. The worlds run in parallel threads (``NUMBA_NUM_THREADS``).
:class:`~proteo_env.env.ProteoEnv` is a view of a ``BatchedEnv`` with ``B = 1`` that adds
PettingZoo's per-agent dicts.

Seeding: ``reset(seed=s)`` gives world ``b`` child ``b`` of ``numpy.random.SeedSequence(s)``
(:func:`~proteo_env.config.world_seeds`), so no two worlds of a batch, and no two worlds of
batches reset with different seeds, share a stream; world ``b`` follows exactly the trajectory
of a single ``ProteoEnv`` reset with that child (``reset(seed=world_seeds(s, B)[b])``) and fed
the same actions. ``reset(world_seeds=[s_0, ..., s_{B-1}])`` instead gives world ``b`` the
stream of a single env reset with seed ``s_b`` (what an evaluation over listed seeds uses).
:meth:`BatchedEnv.reset_worlds` starts a new episode in some worlds while the others run on
(what a trainer does when an episode ends); world ``b``'s next episode is then the one a single
env gets from ``reset()`` without a seed, from the same generator.

Control levels (:mod:`proteo_env.control`): at ``config.control`` = ``"move"`` or
``"move+mode"`` an action row holds only the chosen fields (``(B, A, 1)`` or ``(B, A, 2)``),
and the environment fills in the rest before the cycle.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .config import ConfigError, EnvConfig, check_seed
from .config import world_seeds as spawn_worlds
from .control import ControlLevel, autopilot_factory
from .core.batch import WorldBatch
from .core.world import World, place_window, shared_windows, window_around
from .layouts import Layout
from .spaces import ActionLayout, ObservationBuffers, all_below
from .tasks.base import Task

ONE_CALL_AFTER = 50_000
"""World-cycles after which a batched env at ``move`` runs every world's autopilot in one call
per cycle, when the autopilots offer ``batch`` (:mod:`proteo_env.control`; the same actions,
draw for draw). Before, it calls each world's autopilot: the one call costs a compile of 4-8 s
per behaviour and process and saves about 80 µs per world-cycle, so only long runs (training)
gain from it."""


class StepResult(NamedTuple):
    """What one cycle gives for each of ``B`` worlds (:meth:`BatchedEnv.step_arrays`; a
    :class:`~proteo_env.env.ProteoEnv`'s ``step_arrays`` gives one with ``B = 1``).

    Attributes:
        reward: ``(B,)`` float64, each world's team reward (the sum of its terms; every module
            of the world receives it).
        terminated: ``(B,)`` bool, the task succeeded: the episode ends.
        truncated: ``(B,)`` bool, the episode reached ``max_cycles`` without success.
        terms: ``B`` dicts of the named reward terms (name -> value).
    """

    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    terms: list[dict[str, float]]

    @property
    def done(self) -> np.ndarray:
        """``(B,)`` bool: the episode ended (terminated or truncated)."""
        return self.terminated | self.truncated


class BatchedEnv:
    """``B`` worlds of one task (one task instance per world), stepped together.

    Args:
        tasks: ``B`` task instances of the same class and parameters.
        config: :class:`~proteo_env.config.EnvConfig`.

    Attributes:
        action_layout: names the fields of the task's full action (:class:`~proteo_env.spaces.ActionLayout`).
        level: the :class:`~proteo_env.control.ControlLevel` in force (``config.control``);
            ``control``, ``control_fields`` and ``control_nvec`` are its name, the fields an
            action row holds and their number of values.
        n_envs, n_agents: ``B`` and ``A``.
        world_batch: the :class:`~proteo_env.core.batch.WorldBatch` (after :meth:`reset`).
        cycles: ``(B,)`` int, cycles of each world's current episode (the cycle number the
            task sees); all equal unless :meth:`reset_worlds` restarted some worlds.
        last_moved: ``(B, A)`` bool, who moved in the last cycle.
    """

    def __init__(self, tasks: list[Task], config: EnvConfig | None = None):
        if not tasks:
            raise ValueError("n_envs=0 is not allowed; allowed: an integer >= 1")
        self.tasks = list(tasks)
        self.config = config or EnvConfig()
        self.n_envs = len(tasks)
        for task in self.tasks:
            task.max_cycles = self.config.max_cycles
        task = tasks[0]
        self.action_layout = ActionLayout(len(task.modes), task.n_channels, task.n_message_values)
        self.level = ControlLevel(self.config.control, self.action_layout)
        self._mode_roles = task.mode_role_table()
        self._has_load, self._has_hint = type(task).load is not Task.load, type(task).hint is not Task.hint
        """Whether the task has a load or hint sensor (else those observation fields stay zero)."""
        self._autopilots, self._autopilot_batch, self._autopilot_calls = [], None, 0
        self._batch_autopilots = None
        """The autopilots' ``batch`` (:mod:`~proteo_env.control`), when their class has one."""
        if self.level.name == "move":
            factory = autopilot_factory(task.name)
            self._autopilots = [factory(self, None) for _ in tasks]
            self._batch_autopilots = getattr(type(self._autopilots[0]), "batch", None)
        self._observed: ObservationBuffers | None = None
        """The observation of the current cycle, once taken (what the autopilots read)."""
        self.n_sites = 12 if self.config.obs_radius == 1 else 54
        probe = task.build_layout(np.random.default_rng(0))
        extent, (origin,) = shared_windows([self._start_region(probe)], [probe.size])
        self.build_world(task, probe, extent, origin)  # checks the layout now, not at the first reset
        self.n_agents = probe.n_agents
        self.n_modules = len(probe.positions)
        self.world_batch: WorldBatch | None = None
        self.cycles = np.zeros(self.n_envs, dtype=np.int64)
        self.ended = np.zeros(self.n_envs, dtype=bool)
        """``(B,)``: the world's episode ended at its last step (success or ``max_cycles``) and no
        reset came since. A batch steps on regardless (a trainer resets worlds when it chooses); a
        single env refuses to (:meth:`~proteo_env.env.ProteoEnv.step_arrays`)."""
        self.last_moved = np.zeros((self.n_envs, self.n_agents), dtype=np.bool_)
        self._rngs = [np.random.default_rng() for _ in tasks]

    def build_world(self, task: Task, layout: Layout, extent=None, origin=None) -> World:
        """The world of ``layout`` under this env's physics and the task's scent set-up, on a grid
        over the window ``origin + extent`` of its box (default: the whole box)."""
        return World(
            size=layout.size,
            positions=layout.positions,
            n_agents=layout.n_agents,
            anchored=layout.anchored,
            solid=layout.solid,
            object_sites=layout.object_sites,
            floor=layout.floor,
            n_channels=task.n_channels,
            surface_channels=task.surface_channels,
            passive_role=task.passive_role,
            modes=task.initial_modes(layout),
            physics=self.config.physics,
            obs_radius=self.config.obs_radius,
            extent=extent,
            origin=origin,
        )

    @property
    def worlds(self) -> list[World]:
        return self.world_batch.worlds

    @property
    def task(self) -> Task:
        """The task of world 0 (every world runs the same task class and parameters)."""
        return self.tasks[0]

    @property
    def autopilots(self) -> tuple:
        """Each world's autopilot at control level ``move`` (:mod:`~proteo_env.control`), in world
        order; empty at the other levels. Read it, do not step it: the env calls it every cycle."""
        return tuple(self._autopilots)

    @property
    def control(self) -> str:
        return self.level.name

    @property
    def control_fields(self) -> tuple[str, ...]:
        return self.level.fields

    @property
    def control_nvec(self) -> np.ndarray:
        return self.level.nvec

    @property
    def at_level(self) -> str:
        """`` at control level '<name>'`` for error messages, empty at ``full`` (the default)."""
        return "" if self.control == "full" else f" at control level {self.control!r}"

    def reset(self, seed=None, *, world_seeds=None) -> ObservationBuffers:
        """New start layouts for every world.

        ``seed``: ``None`` (each world continues its generator), an integer >= 0 or a
        :class:`numpy.random.SeedSequence`; world ``b`` is seeded with child ``b`` of it
        (:func:`~proteo_env.config.world_seeds`). ``world_seeds``: instead, one seed per world
        (``B`` integers >= 0 or seed sequences), world ``b`` seeded exactly as a single env reset
        with ``world_seeds[b]``. Anything else is a :class:`~proteo_env.config.ConfigError`.
        """
        if world_seeds is not None:
            if seed is not None:
                raise ConfigError(f"seed={seed!r} is not allowed with world_seeds; allowed: one of the two")
            if (
                not hasattr(world_seeds, "__len__")
                or isinstance(world_seeds, (str, bytes))
                or len(world_seeds) != self.n_envs
            ):
                raise ConfigError(
                    f"world_seeds={world_seeds!r} is not allowed; allowed: a list of {self.n_envs} seeds (one per world)"
                )
            self._rngs = [np.random.default_rng(check_seed(s, f"world_seeds[{b}]")) for b, s in enumerate(world_seeds)]
        elif seed is not None:
            self._rngs = [np.random.default_rng(child) for child in spawn_worlds(seed, self.n_envs)]
        layouts = [self._build_layout(b) for b in range(self.n_envs)]
        extent, origins = shared_windows(
            [self._start_region(layout) for layout in layouts], [lay.size for lay in layouts]
        )
        worlds = [
            self.build_world(task, layout, extent, origin) for task, layout, origin in zip(self.tasks, layouts, origins)
        ]
        for world, rng in zip(worlds, self._rngs):
            world.seed(int(rng.integers(2**63)))
        self.world_batch = WorldBatch(worlds)
        for b in range(self.n_envs):
            self._start_episode(b)
        self.cycles[:] = 0
        self.ended[:] = False
        self.last_moved = np.zeros((self.n_envs, self.n_agents), dtype=np.bool_)
        return self.observe_arrays()

    def reset_worlds(self, which, *, world_seeds=None) -> ObservationBuffers:
        """New episodes in the worlds ``which`` (``(B,)`` bool or world indices); the others run on.

        World ``b``'s new episode is drawn from its own generator, as a single env's ``reset()``
        without a seed would draw it; with ``world_seeds`` (one seed per world of ``which``, in
        order) it is seeded instead exactly as a single env reset with that seed. A start layout larger than the batch's grid moves every
        running world onto a larger grid first (:meth:`~proteo_env.core.world.World.regrid`;
        their trajectories do not change). Returns fresh observations of every world: when the
        current cycle was observed already, only the restarted worlds are observed anew (into a
        copy; buffers returned before are not changed).
        """
        if self.world_batch is None:
            raise RuntimeError("no world yet; call reset() first")
        which = np.asarray(which)
        rows = np.flatnonzero(which) if which.dtype == np.bool_ else which.astype(np.int64).reshape(-1)
        if rows.size and (rows.min() < 0 or rows.max() >= self.n_envs):
            raise ValueError(
                f"world {int(rows.max() if rows.max() >= self.n_envs else rows.min())} is not "
                f"allowed; allowed: 0..{self.n_envs - 1}"
            )
        if len(np.unique(rows)) != len(rows):
            raise ValueError(
                f"worlds {rows.tolist()} are not allowed: a world listed twice; allowed: each world once (one new "
                "episode per world)"
            )
        if world_seeds is not None:
            if (
                not hasattr(world_seeds, "__len__")
                or isinstance(world_seeds, (str, bytes))
                or len(world_seeds) != len(rows)
            ):
                raise ConfigError(
                    f"world_seeds={world_seeds!r} is not allowed; allowed: a list of {len(rows)} seeds "
                    "(one per world restarted)"
                )
            seeded = [np.random.default_rng(check_seed(s, f"world_seeds[{i}]")) for i, s in enumerate(world_seeds)]
            for b, rng in zip(rows.tolist(), seeded):
                self._rngs[b] = rng
        layouts = {int(b): self._build_layout(int(b)) for b in rows}
        starts = {b: self._start_region(layout) for b, layout in layouts.items()}
        extent = self.worlds[0].shape.extent
        if all((high - low <= extent).all() for low, high in starts.values()):  # the others stay where they are
            origins = [
                place_window(starts[b][0], layouts[b].size, extent) if b in starts else w.shape.origin
                for b, w in enumerate(self.worlds)
            ]
        else:
            regions = [starts[b] if b in starts else w.window() for b, w in enumerate(self.worlds)]
            sizes = [layouts[b].size if b in layouts else w.shape.size for b, w in enumerate(self.worlds)]
            extent, origins = shared_windows(regions, sizes)
        starting = {}
        for b, layout in layouts.items():
            starting[b] = self.build_world(self.tasks[b], layout, extent, origins[b])
            starting[b].seed(int(self._rngs[b].integers(2**63)))
        moved = self._regrid(extent, origins, starting)
        observed = None if moved or self._observed is None else self._observed.copy()
        for b in layouts:
            self._start_episode(b)
        self.cycles[rows] = 0
        self.ended[rows] = False
        self.last_moved[rows] = False
        if observed is None:
            return self.observe_arrays()
        a = self.n_agents
        for b in layouts:
            self.worlds[b].observe(observed.rows(b * a, (b + 1) * a))
            self._sense(b, observed)
        self._observed = observed
        return observed

    def _build_layout(self, b: int) -> Layout:
        """World ``b``'s next start layout, from its generator; its module and agent counts checked."""
        layout = self.tasks[b].build_layout(self._rngs[b])
        if layout.n_agents != self.n_agents or len(layout.positions) != self.n_modules:
            raise ValueError(
                f"task {self.tasks[0].task_id()} built {layout.n_agents} agents and "
                f"{len(layout.positions)} modules after {self.n_agents} and "
                f"{self.n_modules} at construction; the counts must stay fixed"
            )
        return layout

    def _start_region(self, layout: Layout) -> tuple[np.ndarray, np.ndarray]:
        """The ``(low, high)`` box sites a new world's grid must cover: the whole box, or for a
        task with a ``window_room`` the start layout and that many sites around it."""
        room = self.task.window_room
        if room is None:
            return np.zeros(3, dtype=np.int64), np.asarray(layout.size, dtype=np.int64)
        return window_around(layout.positions, layout.size, room)

    def _regrid(self, extent, origins, starting=None) -> bool:
        """Lay the batch out on grids of ``extent`` at ``origins``: the worlds in ``starting``
        (row: a new world built on that layout) replace theirs; the running ones not already
        there move (:meth:`~proteo_env.core.world.World.regrid`; their trajectories do not
        change). Return whether the layout changed."""
        starting = starting or {}
        moving = [
            b
            for b, world in enumerate(self.worlds)
            if b not in starting and (world.shape.extent, world.shape.origin) != (extent, origins[b])
        ]
        changed = bool(moving) or self.worlds[0].shape.extent != extent
        if changed:
            self.world_batch = WorldBatch(
                [
                    starting[b] if b in starting else world.regrid(extent, origins[b]) if b in moving else world
                    for b, world in enumerate(self.worlds)
                ]
            )
            for b in moving:
                self.tasks[b].regrid(self.worlds[b])
        else:
            for b, world in starting.items():
                self.world_batch.replace(b, world)
        return changed

    def _make_room(self) -> None:
        """Grow the windows of the worlds whose modules came near their edge
        (:meth:`~proteo_env.core.world.World.grown_window`) and lay the batch out again."""
        out = self.world_batch.out_of_room()
        if out.any():
            room = self.task.window_room
            regions = [w.grown_window(room) if grow else w.window() for w, grow in zip(self.worlds, out)]
            self._regrid(*shared_windows(regions, [w.shape.size for w in self.worlds]))

    def _start_episode(self, b: int) -> None:
        """The task's and the autopilot's episode state of world ``b`` (its world seeded and in place)."""
        self.tasks[b].reset(self.worlds[b], self._rngs[b])
        if self._autopilots:
            self._autopilots[b].reset(seed=int(self._rngs[b].integers(2**63)))

    def check_actions(self, actions) -> np.ndarray:
        """Validate a ``(B, A, F)`` batch (``F`` fields of the control level); a bad one raises
        ``ValueError`` naming world, agent and field."""
        fields, nvec = self.control_fields, self.control_nvec
        actions = np.asarray(actions)
        if actions.dtype.kind not in "iu":
            raise ValueError(f"actions dtype {actions.dtype} is not allowed; allowed: integers")
        expected = (self.n_envs, self.n_agents, len(fields))
        if actions.shape != expected:
            raise ValueError(
                f"actions shape {actions.shape} is not allowed{self.at_level}; allowed: {expected} "
                f"(worlds, agents, {list(fields)})"
            )
        if not all_below(actions.reshape(-1, len(fields)), nvec):
            b, a, f = np.argwhere((actions < 0) | (actions >= nvec))[0]
            where = f"world {b}, " if self.n_envs > 1 else ""
            raise ValueError(
                f"action of {where}module_{a}: {fields[f]}={actions[b, a, f]} is not allowed; allowed: 0..{nvec[f] - 1}"
            )
        return actions.astype(np.int64, copy=False)

    def full_actions(self, actions: np.ndarray) -> np.ndarray:
        """``(B, A, L)`` full actions from a checked ``(B, A, F)`` batch at the control level:
        the chosen fields, and the rest from the autopilot (``move``) or the task's
        mode-role table (``move+mode``)."""
        if self.control == "full":
            return actions
        lay = self.action_layout
        if self.control == "move+mode":
            full = np.zeros(actions.shape[:2] + (lay.length,), dtype=np.int64)
            full[..., :2] = actions
            full[..., lay.roles] = self._mode_roles[actions[..., 1]]
            return full
        observed = self.last_observation()
        a = self.n_agents
        if self._autopilot_batch is None and self._batch_autopilots and self._autopilot_calls >= ONE_CALL_AFTER:
            self._autopilot_batch = self._batch_autopilots(self._autopilots)
        self._autopilot_calls += self.n_envs
        if self._autopilot_batch is not None:
            full = self._autopilot_batch.act_arrays(observed).reshape(actions.shape[:2] + (lay.length,))
        else:
            full = np.empty(actions.shape[:2] + (lay.length,), dtype=np.int64)
            for b, pilot in enumerate(self._autopilots):
                full[b] = pilot.act_arrays(observed.rows(b * a, (b + 1) * a))
        full[..., lay.move] = actions[..., 0]
        return full

    def last_observation(self) -> ObservationBuffers:
        """The observation of the current cycle: the one :meth:`observe_arrays` last returned,
        or a fresh one when the world has stepped since."""
        if self._observed is None:
            self.observe_arrays()
        return self._observed

    def step_arrays(self, actions) -> StepResult:
        """One cycle of every world from a ``(B, A, F)`` action array (``F`` fields of the
        control level; ``F = L`` at ``full``): each world's reward, end and reward terms.

        A bad batch raises ``ValueError`` and changes nothing.
        """
        if self.world_batch is None:
            raise RuntimeError("no world yet; call reset() first")
        actions = self.full_actions(self.check_actions(actions))
        lay = self.action_layout
        self.last_moved = self.world_batch.step(
            move=actions[..., lay.move],
            mode=actions[..., lay.mode],
            scent_role=actions[..., lay.roles],
            message_target=actions[..., lay.message_target],
            message_value=actions[..., lay.message_value],
        )
        self._make_room()
        self.cycles += 1
        self._observed = None
        scores = type(self.tasks[0]).score_cycle(self.tasks, self.world_batch, self.last_moved, self.cycles)
        truncated = (self.cycles >= self.config.max_cycles) & ~scores.success
        self.ended = scores.success | truncated
        return StepResult(scores.reward, scores.success, truncated, scores.terms)

    def observe_arrays(self) -> ObservationBuffers:
        """Fresh observation arrays of every agent of every world (``B * A`` rows, world-major)."""
        a = self.n_agents
        buffers = ObservationBuffers(self.n_envs * a, self.n_sites, self.tasks[0].n_channels)
        self.world_batch.observe(buffers)
        for b in range(self.n_envs):
            self._sense(b, buffers)
        self._observed = buffers
        return buffers

    def _sense(self, b: int, buffers: ObservationBuffers) -> None:
        """The task's sensors of world ``b`` (load, hint) into its rows of ``buffers`` (every
        world's rows; a sensor the task does not have stays zero)."""
        if not (self._has_load or self._has_hint):
            return
        rows = slice(b * self.n_agents, (b + 1) * self.n_agents)
        task = self.tasks[b]
        if self._has_load:
            buffers.load[rows, 0] = task.load(self.worlds[b])
        if self._has_hint:
            buffers.hint[rows] = task.hint(self.worlds[b])

    def metrics(self) -> list[dict[str, float]]:
        """The task's metrics of every world."""
        return [task.metrics(world) for task, world in zip(self.tasks, self.worlds)]

    def success(self) -> np.ndarray:
        """``(B,)`` bool: the task's success flag of every world."""
        return np.array([task.success(world) for task, world in zip(self.tasks, self.worlds)])

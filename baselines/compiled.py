"""Whole rollouts of a hand-coded behaviour or a program inside compiled code.

:class:`CompiledRollout` runs the loop that ``env.step_arrays(policy.act_arrays(env.observe_arrays()))``
runs in Python, cycle after cycle, as one numba kernel: the engine's observation kernel, the
task's sensor, the policy's rule kernel (the same code its :meth:`~baselines.base.KernelPolicy.act`
runs), the engine's cycle kernel, and the task's bookkeeping and success test. Same environment
state, policy parameters, generator state and memory give the same trajectory as the Python
loop, cycle for cycle (``tests/test_compiled_rollout.py``).

A behaviour plugs in through two small protocols and nothing here names one:

- the policy is a :class:`~baselines.base.KernelPolicy`: its ``rule`` kernel, its
  ``rule_params`` and its memory
  (:meth:`~baselines.base.SlotMemory.arrays`);
- the task gives :meth:`~proteo_env.tasks.base.Task.kernels`: a ``sense`` and an ``update_and_test``
  kernel and the state they read (:class:`~proteo_env.tasks.base.TaskKernels`).

:func:`rollout_loop` makes the loop for one (rule, sense, update_and_test) triple, closing over the three
kernels, and keeps it for the process (numba compiles it at the first call).

Example::

    env = proteo_env.make("chain-v0", n_modules=200, motion_model="sphere", max_cycles=5000)
    env.reset(seed=3)
    result = compiled_rollout(env, ChainPolicy.for_env(env, seed=3))
    result.success, result.cycles, result.positions
"""

from __future__ import annotations

import copy
import functools
from dataclasses import dataclass

import numpy as np

from proteo_env.core import cycle as engine
from proteo_env.core.jit import generated_kernel
from proteo_env.core.paged import copy_grid
from proteo_env.core.records import Actions, Geometry, Observation, Scratch, Settings, WorldState
from proteo_env.env import ProteoEnv
from proteo_env.spaces import ObservationBuffers

from .base import KernelPolicy, Observed


@dataclass(frozen=True)
class Rollout:
    """Outcome of a compiled rollout (N modules, R recorded cycles).

    Attributes:
        cycles: the cycle count reached, counted like ``env.cycle`` (the cycle of success when
            ``success``).
        success: the task's success test held after the last cycle.
        positions: ``(N, 3)`` int64 module sites after the last cycle.
        modes: ``(N,)`` int32 modes after the last cycle.
        recorded_cycles: ``(R,)`` the cycles after which the state was recorded: every
            ``record_every``-th of the call, and the last when it ends in success.
        recorded_positions: ``(R, N, 3)`` module sites after those cycles.
        recorded_modes: ``(R, N)`` modes after those cycles.
        rng: the rollout's copy of the policy's generator, as the cycles run left it (the
            policy's own generator is unchanged).
    """

    cycles: int
    success: bool
    positions: np.ndarray
    modes: np.ndarray
    recorded_cycles: np.ndarray
    recorded_positions: np.ndarray
    recorded_modes: np.ndarray
    rng: np.random.Generator


@functools.cache
def rollout_loop(rule, sense, update_and_test):
    """The compiled loop of one behaviour: ``rule`` (a policy's :attr:`~baselines.base.KernelPolicy.rule`),
    ``sense`` and ``update_and_test`` (a task's :class:`~proteo_env.tasks.base.TaskKernels`).

    Returns a kernel ``cycles(state, settings, geometry, scratch, seen, slots, memory, rules, rng,
    task, room, start_cycle, max_cycles, record_every, first, recorded_cycles, recorded_cell,
    recorded_mode) -> (cycles, success, recorded, out_of_room)`` that runs up to ``max_cycles``
    cycles of observe, sense, decide, step, update and test, and stops early after a cycle
    that brought a module near the edge of the grid's window (``room``: the grid's ``strides``
    and :meth:`~proteo_env.core.lattice.GridShape.guard`; ``out_of_room`` True: regrid, then
    go on): ``state``, ``settings``, ``geometry`` and ``scratch`` are the engine's records
    (:mod:`proteo_env.core.records`, named or plain tuples), ``seen`` an :class:`~baselines.base.Observed` (``hint``
    filled), ``slots`` (A,) the memory slot of each agent row, ``memory``, ``rules`` and ``rng``
    as the rule reads them, ``task`` the task's kernel state, ``start_cycle`` the env's cycle
    before the first; ``recorded_*`` (R, ...) are filled in order, after every cycle whose
    number counted from ``first`` + 1 is a multiple of ``record_every``.
    """

    @generated_kernel
    def cycles(
        state,
        settings,
        geometry,
        scratch,
        seen,
        slots,
        memory,
        rules,
        rng,
        task,
        room,
        start_cycle,
        max_cycles,
        record_every,
        first,
        recorded_cycles,
        recorded_cell,
        recorded_mode,
    ):
        state, settings, geometry, scratch = (
            WorldState(*state),
            Settings(*settings),
            Geometry(*geometry),
            Scratch(*scratch),
        )
        n_agents, n_channels = settings.n_agents, state.scent.shape[0]
        out = Observation(
            seen.neighbour_kind,
            seen.neighbour_mode,
            seen.neighbour_scent,
            seen.own_mode,
            seen.own_scent,
            seen.messages,
            seen.contact,
            seen.action_mask,
        )
        actions = np.empty((n_agents, 4 + n_channels), dtype=np.int64)
        step = Actions(
            np.empty(n_agents, dtype=np.int64),
            np.empty(n_agents, dtype=np.int32),
            np.empty((n_agents, n_channels), dtype=np.int8),
            np.empty(n_agents, dtype=np.int64),
            np.empty(n_agents, dtype=np.int32),
        )
        moved = np.empty(n_agents, dtype=np.bool_)
        recorded = 0
        for cycle in range(1, max_cycles + 1):
            engine.observe_world(state, settings, geometry, scratch, out)
            sense(task, seen.load)
            rule(seen, slots, memory, rules, rng, actions)
            for a in range(n_agents):
                step.move[a] = actions[a, 0]
                step.mode[a] = actions[a, 1]
                for ch in range(n_channels):
                    step.scent_role[a, ch] = actions[a, 2 + ch]
                step.message_target[a] = actions[a, 2 + n_channels]
                step.message_value[a] = actions[a, 3 + n_channels]
            engine.run_cycle(state, settings, geometry, step, moved, scratch)
            success = update_and_test(
                state.grid, state.cell, state.mode, state.anchored, geometry.dir_delta, start_cycle + cycle, task
            )
            if record_every > 0 and ((first + cycle) % record_every == 0 or success):
                recorded_cycles[recorded] = cycle
                recorded_cell[recorded] = state.cell
                recorded_mode[recorded] = state.mode
                recorded += 1
            if success:
                return cycle, True, recorded, False
            if engine.out_of_room(state.cell, room[0], room[1]):
                return cycle, False, recorded, True
        return max_cycles, False, recorded, False

    return cycles


CHANGED_FIELDS = ("grid", "cell", "mode", "scent", "inbox", "rng_state")
"""The world's state arrays a rollout changes (it runs on copies of them)."""


class CompiledRollout:
    """A hand-coded behaviour or a program from a copy of ``env``'s state, run inside compiled code.

    :meth:`run` advances it by up to a given number of cycles (stopping at the task's
    success); every call continues where the last one ended. The cycles are those that
    driving ``env`` with ``env.step_arrays(policy.act_arrays(env.observe_arrays()))`` would
    run: same trajectory, same draws from the policy's generator. Neither ``env`` nor
    ``policy`` changes: the rollout works on copies of the world's state, of the task's
    bookkeeping, of the policy's generator and of its memory.

    Args:
        env: a :class:`~proteo_env.env.ProteoEnv` after ``reset``, of a task with
            :meth:`~proteo_env.tasks.base.Task.kernels` (chain, branch, table, grasp, locomotion).
        policy: a :class:`~baselines.base.KernelPolicy` built for ``env`` whose rule is written
            for its task (:meth:`~baselines.base.KernelPolicy.runs_on`): the task's hand-coded
            policy, or a :class:`~baselines.program_policy.ProgramPolicy` of a program for the
            task; its parameters, generator state and memory are read.

    Attributes:
        cycle: the cycle count reached, counted like ``env.cycle`` (starts at the env's).
        success: the task's success test held after the last cycle.
        rng: the rollout's copy of the policy's generator, as the cycles run so far left it.
    """

    def __init__(self, env, policy):
        if not isinstance(env, ProteoEnv):
            raise ValueError(f"env={type(env).__name__} is not allowed; allowed: a ProteoEnv from proteo_env.make")
        task = env.task
        if not isinstance(policy, KernelPolicy) or policy.rule is None or not policy.runs_on(task):
            raise ValueError(
                f"policy={type(policy).__name__} on task={task.task_id()!r} is not allowed; allowed: "
                f"the task's hand-coded policy (a KernelPolicy named {task.name!r}, from "
                f"baselines.make_policy) or a program for {task.name!r} (make_policy('program', env, program=...))"
            )
        world = env.engine
        if world is None:
            raise ValueError("env has no world yet; allowed: an env after reset(seed=...)")
        kernels = task.kernels(world)
        if kernels is None:
            raise ValueError(
                f"task={task.task_id()!r} is not allowed; allowed: a task with compiled kernels "
                "(Task.kernels returns a TaskKernels)"
            )
        if policy.action_layout != env.action_layout:
            raise ValueError(
                f"policy action layout {policy.action_layout} is not allowed; allowed: the env's {env.action_layout}"
            )
        self.world = world
        self.room = task.window_room
        self.loop = rollout_loop(policy.rule, kernels.sense, kernels.update_and_test)
        self.task_state = kernels.state
        self.rule_params = policy.rule_params
        self.rng = copy.deepcopy(policy.rng)
        self.memory = policy.memory_rows(env.possible_agents).arrays()
        copies = {name: getattr(world, name).copy() for name in CHANGED_FIELDS if name != "grid"}
        self.state = world.state._replace(grid=copy_grid(world.grid, copies["cell"]), **copies)
        self.scratch = Scratch.allocate(world.n_modules, self.state.grid)
        observation = ObservationBuffers(world.n_agents, len(world.neighbourhood_delta), world.n_channels)
        observation.hint[:] = task.hint(world)
        self.seen = Observed(*(getattr(observation, name) for name in Observed._fields))
        self.cycle = env.cycle
        self.success = False

    def run(self, max_cycles: int, *, record_every: int = 0) -> Rollout:
        """Run up to ``max_cycles`` more cycles (none once the task has succeeded).

        ``record_every``: record positions and modes after every ``record_every``-th cycle of
        this call and at success (0: none). Returns the :class:`Rollout` of this call (its
        ``cycles`` is :attr:`cycle`).
        """
        for name, value in (("max_cycles", max_cycles), ("record_every", record_every)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise ValueError(f"{name}={value!r} is not allowed; allowed: an integer >= 0")
        n = self.world.n_modules
        capacity = max_cycles // record_every + 1 if record_every else 0
        recorded_cycles = np.zeros(capacity, dtype=np.int64)
        recorded_cell = np.zeros((capacity, n), dtype=self.state.cell.dtype)
        recorded_positions = np.zeros((capacity, n, 3), dtype=np.int64)
        recorded_mode = np.zeros((capacity, n), dtype=self.state.mode.dtype)
        done, recorded = 0, 0
        while done < max_cycles and not self.success:
            w, st = self.world, self.state
            ran, self.success, got, out_of_room = self.loop(  # records as plain tuples: see proteo_env.core.records
                tuple(st),
                tuple(w.settings),
                tuple(w.geometry),
                tuple(self.scratch),
                self.seen,
                np.arange(w.n_agents, dtype=np.int64),
                self.memory,
                self.rule_params,
                self.rng,
                self.task_state,
                (w.shape.strides, w.shape.guard()),
                int(self.cycle),
                int(max_cycles - done),
                int(record_every),
                int(done),
                recorded_cycles[recorded:],
                recorded_cell[recorded:],
                recorded_mode[recorded:],
            )
            part = slice(recorded, recorded + got)
            recorded_cycles[part] += self.cycle
            recorded_positions[part] = w.shape.point(recorded_cell[part])
            recorded += got
            self.cycle += int(ran)
            done += int(ran)
            if out_of_room:
                self._make_room()
        return Rollout(
            cycles=self.cycle,
            success=bool(self.success),
            positions=self.world.shape.point(self.state.cell),
            modes=self.state.mode.copy(),
            recorded_cycles=recorded_cycles[:recorded],
            recorded_positions=recorded_positions[:recorded],
            recorded_modes=recorded_mode[:recorded],
            rng=self.rng,
        )

    def _make_room(self) -> None:
        """Move the rollout's copy of the world onto a grown window of its box
        (:meth:`~proteo_env.core.world.World.grown_window`); the env's world is not touched."""
        running = copy.copy(self.world)
        running.state = self.state
        low, high = running.grown_window(self.room)
        self.world = running.regrid(tuple(high - low), tuple(low))
        self.state, self.scratch = self.world.state, self.world.scratch


def compiled_rollout(env, policy, *, max_cycles: int | None = None, record_every: int = 0) -> Rollout:
    """Run a hand-coded behaviour or a program from ``env``'s current state inside compiled code.

    ``CompiledRollout(env, policy).run(max_cycles, record_every=record_every)``: the result is
    what driving ``env`` with ``env.step_arrays(policy.act_arrays(env.observe_arrays()))``
    until the task's success (or ``max_cycles``) would give. Neither ``env`` nor ``policy``
    changes.

    Args:
        env: a :class:`~proteo_env.env.ProteoEnv` after ``reset``, of a task with compiled kernels.
        policy: the task's hand-coded policy or a program's policy built for ``env`` (see :class:`CompiledRollout`).
        max_cycles: cycles to run at most (default: the env's cycles left, ``max_cycles - cycle``).
        record_every: record positions and modes after every ``record_every``-th cycle and at
            success (0: only the final state).

    Returns:
        a :class:`Rollout`.
    """
    rollout = CompiledRollout(env, policy)
    return rollout.run(env.max_cycles - env.cycle if max_cycles is None else max_cycles, record_every=record_every)


__all__ = ["CompiledRollout", "Rollout", "compiled_rollout", "rollout_loop"]

"""Whole rollouts of the paper's hand-coded behaviours (chain, branch, table, grasp) inside compiled code.

:class:`CompiledRollout` runs the loop that ``env.step_arrays(policy.act_arrays(env.observe_arrays()))``
runs in Python, cycle after cycle, as one numba kernel: the engine's observation kernel, the
behaviour's rule (:func:`baselines.kernels.chain_actions`,
:func:`baselines.kernels.branch_actions`, :func:`baselines.table_kernels.table_actions` or
:func:`baselines.grasp_kernels.grasp_actions`, the same code :class:`~baselines.chain.ChainPolicy`,
:class:`~baselines.branch.BranchPolicy`, :class:`~baselines.table.TablePolicy` and
:class:`~baselines.grasp.GraspPolicy` run), the engine's cycle kernel and the task's
bookkeeping and success test (for the table and the grasp, the task's own kernels: the load
sensor before the observation and :func:`~proteo_env.tasks.table.table_after_cycle` after the
cycle; :func:`~proteo_env.tasks.grasp.grasp_hold`). Same environment state, policy parameters, generator state and memory give the
same trajectory as the Python loop, cycle for cycle (``tests/test_compiled_rollout.py``).

Example::

    env = proteo_env.make("chain-v0", n_modules=200, motion_model="sphere", max_cycles=5000)
    env.reset(seed=3)
    result = compiled_rollout(env, ChainPolicy.for_env(env, seed=3))
    result.success, result.cycles, result.positions
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from proteo_env.core import kernels as engine
from proteo_env.core.jit import kernel
from proteo_env.core.lattice import DIRECTIONS, OPPOSITE
from proteo_env.core.structure import largest_thin_piece
from proteo_env.core.world import LOCAL_ADJACENCY_BITS, Scratch
from proteo_env.env import ProteoEnv
from proteo_env.spaces import ObservationBuffers
from proteo_env.tasks.branch import measure_tree
from proteo_env.tasks.grasp import GraspSurface, grasp_hold
from proteo_env.tasks.table import TableLedger, root_loads, table_after_cycle

from .branch import BranchMemory, BranchPolicy
from .chain import ChainPolicy
from .grasp import GraspMemory, GraspPolicy
from .grasp_kernels import GraspRules, grasp_actions
from .kernels import INODE, NODE, BranchRules, branch_actions, chain_actions
from .table import TableMemory, TablePolicy
from .table_kernels import TableRules, table_actions

CHAIN, BRANCH, TABLE, GRASP = 0, 1, 2, 3
"""The behaviours a rollout runs (the task and policy pairs of :data:`BEHAVIOURS`)."""
BEHAVIOURS = {("chain", ChainPolicy): CHAIN, ("branch", BranchPolicy): BRANCH, ("table", TablePolicy): TABLE,
              ("grasp", GraspPolicy): GRASP}
"""``(task name, policy class)`` of each behaviour."""
TEST_SCRATCH = 9
"""(N,) scratch arrays of the success tests (:func:`measure_tree` takes 9)."""


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


@kernel
def is_chain(grid, cell, n_modules, dir_delta, degree, mark, queue):
    """The chain task's success test: connected, ``N - 1`` contacts, every module with at most
    2 neighbours. Stops at the first module with 3 or more (``degree``, ``mark``, ``queue``:
    (N,) scratch)."""
    contacts = 0
    for n in range(n_modules):
        d = 0
        for k in range(12):
            if grid[cell[n] + dir_delta[k]] >= 0:
                d += 1
        if d > 2:
            return False
        degree[n] = d
        contacts += d
    if contacts // 2 != n_modules - 1:
        return False
    return largest_thin_piece(grid, cell, n_modules, dir_delta, degree, mark, queue) == n_modules


@kernel
def is_branched_tree(grid, cell, mode, n_modules, dir_delta, first_node, min_gap, target_levels, scratch):
    """The branch task's success test: the grown piece from the root is a tree with at least
    ``target_levels`` levels of branching (:func:`measure_tree`). The root is ``first_node``,
    or when it is -1 the lowest-index NODE or INODE (module 0 when there is none);
    ``scratch`` is ``(9, N)``."""
    root = first_node
    if root < 0:
        root = 0
        for n in range(n_modules):
            if mode[n] == NODE or mode[n] == INODE:
                root = n
                break
    size, edges, _, levels, _, _, _, _ = measure_tree(
        grid, cell, mode, n_modules, dir_delta, root, min_gap, scratch[0], scratch[1], scratch[2], scratch[3],
        scratch[4], scratch[5], scratch[6], scratch[7], scratch[8])
    return size > 0 and edges == size - 1 and levels >= target_levels


@kernel
def _rollout_cycles(behaviour, grid, cell, n_agents, anchored, mode, scent, inbox, rng_state, passive_role, surface,
                    keep_connected, exact, sweeps, scent_max, nb_delta, dir_delta, roll_delta, local_delta, roll_table,
                    movers, mark, queue, stacks, search, scent_buffer, is_cut, adjacency, disc, low, stack_node,
                    stack_k, neighbour_kind, neighbour_mode, neighbour_scent, own_mode, own_scent, messages, contact,
                    load, hint, action_mask, slots, heading, growth, asked, spawned, spot_direction, spot_announced,
                    spot_waited, refused, spot, parent, child, seed_growth, waited, stuck, age, previous, rules,
                    branch, table, grasp, rng, first_node, min_gap, target_levels, ledger, object_surface, start_cycle,
                    max_cycles, record_every, recorded_cycles, recorded_cell, recorded_mode, test_scratch):
    """Run up to ``max_cycles`` cycles of observe, decide (``behaviour``: :data:`CHAIN`,
    :data:`BRANCH`, :data:`TABLE` or :data:`GRASP`), step, test; return ``(cycles, success,
    recorded)``. Arrays as in :class:`~proteo_env.core.world.World`, its scratch,
    :class:`~proteo_env.spaces.ObservationBuffers` (``hint`` filled), :class:`~baselines.branch.BranchMemory`
    (``heading`` .. ``refused``), :class:`~baselines.table.TableMemory` (``spot``, ``parent``,
    ``child``) and :class:`~baselines.grasp.GraspMemory` (``seed_growth`` is its ``growth``,
    .. ``previous``); ``rules``, ``branch``, ``table``, ``grasp``: the rule parameters;
    ``ledger``: the table task's :class:`~proteo_env.tasks.table.TableLedger`, ``object_surface`` the
    grasp task's :class:`~proteo_env.tasks.grasp.GraspSurface`, ``start_cycle`` the env's
    cycle before the first (what a behaviour does not use is a placeholder); ``recorded_*``
    (R, ...) are filled in order."""
    n_modules = cell.shape[0]
    n_channels = scent.shape[0]
    actions = np.empty((n_agents, 4 + n_channels), dtype=np.int64)
    move = np.empty(n_agents, dtype=np.int64)
    new_mode = np.empty(n_agents, dtype=np.int32)
    role = np.empty((n_agents, n_channels), dtype=np.int8)
    target = np.empty(n_agents, dtype=np.int64)
    value = np.empty(n_agents, dtype=np.int32)
    moved = np.empty(n_agents, dtype=np.bool_)
    recorded = 0
    for cycle in range(1, max_cycles + 1):
        engine.observe_world(grid, cell, n_agents, mode, scent, inbox, anchored, keep_connected, nb_delta,
                             dir_delta, roll_delta, roll_table, scent_max, is_cut, adjacency, disc, low,
                             stack_node, stack_k, neighbour_kind, neighbour_mode, neighbour_scent, own_mode,
                             own_scent, messages, contact, action_mask)
        if behaviour == CHAIN:
            chain_actions(own_mode, messages, neighbour_kind, neighbour_mode, neighbour_scent, own_scent,
                          action_mask, slots, heading, growth, asked, rules, rng, actions)
        elif behaviour == TABLE:
            root_loads(ledger, load[:, 0])
            table_actions(own_mode, messages, neighbour_kind, neighbour_mode, neighbour_scent, own_scent,
                          action_mask, contact, load, slots, spot, parent, child, table, rng, actions)
        elif behaviour == GRASP:
            grasp_actions(own_mode, messages, neighbour_kind, neighbour_mode, neighbour_scent, own_scent,
                          action_mask, contact, hint, slots, seed_growth, waited, stuck, age, previous, grasp, rng,
                          actions)
        else:
            branch_actions(own_mode, messages, neighbour_kind, neighbour_mode, neighbour_scent, own_scent,
                           action_mask, slots, heading, growth, asked, spawned, spot_direction, spot_announced,
                           spot_waited, refused, rules, branch, rng, actions)
        for a in range(n_agents):
            move[a] = actions[a, 0]
            new_mode[a] = actions[a, 1]
            for ch in range(n_channels):
                role[a, ch] = actions[a, 2 + ch]
            target[a] = actions[a, 2 + n_channels]
            value[a] = actions[a, 3 + n_channels]
        engine.run_cycle(grid, cell, n_agents, anchored, mode, scent, inbox, rng_state, passive_role, surface,
                         keep_connected, exact, sweeps, scent_max, move, new_mode, role, target, value, moved,
                         dir_delta, DIRECTIONS, OPPOSITE, roll_delta, local_delta, LOCAL_ADJACENCY_BITS,
                         roll_table, movers, mark, queue, stacks, search, scent_buffer)
        if behaviour == CHAIN:
            success = is_chain(grid, cell, n_modules, dir_delta, test_scratch[0], test_scratch[1], test_scratch[2])
        elif behaviour == TABLE:
            table_after_cycle(grid, cell, mode, anchored, start_cycle + cycle, ledger)
            success = ledger.restabilise[-1] >= 0
        elif behaviour == GRASP:
            success = grasp_hold(grid, object_surface)[3]
        else:
            success = is_branched_tree(grid, cell, mode, n_modules, dir_delta, first_node, min_gap, target_levels,
                                       test_scratch)
        if record_every > 0 and (cycle % record_every == 0 or success):
            recorded_cycles[recorded] = cycle
            recorded_cell[recorded] = cell
            recorded_mode[recorded] = mode
            recorded += 1
        if success:
            return cycle, True, recorded
    return max_cycles, False, recorded


def _placeholder_ledger() -> TableLedger:
    """A :class:`~proteo_env.tasks.table.TableLedger` of the right types for the behaviours
    that have no table (never read)."""
    none = np.zeros(0, dtype=np.int64)
    return TableLedger(roots=none, left=np.zeros(0, dtype=np.bool_), down_delta=none, shift_cycles=np.zeros(1, np.int64),
                       schedule_weights=np.zeros((0, 2)), depth=0, stable_window=0, load_cap=0.0,
                       active=np.zeros(0, dtype=np.bool_), grounded=np.zeros(0, dtype=np.bool_),
                       signature=np.zeros((2, 0), dtype=np.bool_), clock=np.zeros(5, dtype=np.int64),
                       weights=np.zeros(2), restabilise=np.zeros(1), scratch=np.zeros((3, 0), dtype=np.int64),
                       stamp=np.zeros(1, dtype=np.int64), f_max=0.0, carry=False)


def _placeholder_surface() -> GraspSurface:
    """A :class:`~proteo_env.tasks.grasp.GraspSurface` of the right types for the behaviours
    that grasp nothing (never read)."""
    none = np.zeros(0, dtype=np.int64)
    return GraspSurface(cell=none, side=none, n_sides=0, coverage_threshold=0.0, surround_threshold=0.0)


def _memory_copy(memory_type, rows, n_slots):
    """A ``memory_type`` of ``n_slots`` empty slots holding the fields of ``rows`` it shares."""
    memory = memory_type()
    memory.reserve(n_slots)
    for name in memory.FIELDS:
        if name in rows.FIELDS:
            getattr(memory, name)[:] = getattr(rows, name)
    return memory


class CompiledRollout:
    """A hand-coded behaviour from a copy of ``env``'s state, run inside compiled code.

    :meth:`run` advances it by up to a given number of cycles (stopping at the task's
    success); every call continues where the last one ended. The cycles are those that
    driving ``env`` with ``env.step_arrays(policy.act_arrays(env.observe_arrays()))`` would
    run: same trajectory, same draws from the policy's generator. Neither ``env`` nor
    ``policy`` changes: the rollout works on copies of the world's state, of the task's
    bookkeeping, of the policy's generator and of its memory.

    Args:
        env: a :class:`~proteo_env.env.ProteoEnv` after ``reset``, of the chain, branch, table or
            grasp task.
        policy: the task's hand-coded policy built for ``env``, exactly a
            :class:`~baselines.chain.ChainPolicy` (chain), a :class:`~baselines.branch.BranchPolicy`
            (branch), a :class:`~baselines.table.TablePolicy` (table) or a
            :class:`~baselines.grasp.GraspPolicy` (grasp); its parameters, generator state and
            memory are read.

    Attributes:
        cycle: the cycle count reached, counted like ``env.cycle`` (starts at the env's).
        success: the task's success test held after the last cycle.
        rng: the rollout's copy of the policy's generator, as the cycles run so far left it.
    """

    def __init__(self, env, policy):
        task = env.task.name if isinstance(env, ProteoEnv) else None
        self.behaviour = BEHAVIOURS.get((task, type(policy)))
        if self.behaviour is None:
            allowed = ", ".join(f"{cls.__name__} on {name}-v0" for name, cls in BEHAVIOURS)
            raise ValueError(f"policy={type(policy).__name__} on task={task!r} is not allowed; allowed: {allowed} "
                             "(env: a ProteoEnv from proteo_env.make)")
        world = env.engine
        if world is None:
            raise ValueError("env has no world yet; allowed: an env after reset(seed=...)")
        if policy.layout != env.action_layout:
            raise ValueError(f"policy layout {policy.layout} is not allowed; allowed: the env's {env.action_layout}")
        self.world = world
        scent_max = int(world.physics.scent_max)
        chained = self.behaviour in (CHAIN, BRANCH)
        self.rules = policy.rules if chained else ChainPolicy(policy.layout, policy.modes, scent_max=scent_max).rules
        self.table = policy.rules if self.behaviour == TABLE else TableRules(scent_max, 0.0, 0.0, 0.0, 0.0, 0.0)
        self.ledger = env.task.ledger.copy() if self.behaviour == TABLE else _placeholder_ledger()
        self.grasp = policy.rules if self.behaviour == GRASP else GraspRules(scent_max, 0.0, False, 1, False, False,
                                                                             False, 1, False, 1, -1, False, False)
        self.surface = env.task.surface if self.behaviour == GRASP else _placeholder_surface()
        if self.behaviour == BRANCH:
            p = env.task.params
            self.branch = policy.branch_rules
            self.first_node = env.task.first_node if p.initial_node else -1
            self.min_gap, self.target_levels = p.min_gap, p.target_levels
        else:  # the branch fields are unused
            self.branch = BranchRules(T=0, B=0, p_node=0.0, search_relays_node=False, refuse=False, patience=0)
            self.first_node, self.min_gap, self.target_levels = -1, 0, 0
        self.rng = copy.deepcopy(policy.rng)
        rows = policy.memory_rows(env.possible_agents)
        self.memory = _memory_copy(BranchMemory, rows, world.n_agents)
        self.table_memory = _memory_copy(TableMemory, rows, world.n_agents)
        self.grasp_memory = _memory_copy(GraspMemory, rows, world.n_agents)  # each behaviour reads its own
        self.state = {name: getattr(world, name).copy() for name in ("grid", "cell", "mode", "scent", "inbox",
                                                                        "rng_state")}
        n = world.n_modules
        self.scratch = Scratch(n, len(world.grid))
        self.observation = ObservationBuffers(world.n_agents, len(world.neighbourhood_delta), world.n_channels)
        self.observation.hint[:] = env.task.hint(world)
        self.test_scratch = np.zeros((TEST_SCRATCH, n), dtype=np.int64)
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
        w, st, s, obs, m, t = self.world, self.state, self.scratch, self.observation, self.memory, self.table_memory
        g = self.grasp_memory
        n = w.n_modules
        capacity = max_cycles // record_every + 1 if record_every else 0
        recorded_cycles = np.zeros(capacity, dtype=np.int64)
        recorded_cell = np.zeros((capacity, n), dtype=st["cell"].dtype)
        recorded_mode = np.zeros((capacity, n), dtype=st["mode"].dtype)
        ran, recorded = 0, 0
        if not self.success:
            p = w.physics
            ran, self.success, recorded = _rollout_cycles(
                self.behaviour, st["grid"], st["cell"], w.n_agents, w.anchored, st["mode"], st["scent"], st["inbox"],
                st["rng_state"], w.passive_role, w.surface_channels, p.keep_connected, p.exact_scent, p.scent_sweeps,
                int(p.scent_max), w.neighbourhood_delta, w.dir_delta, w.roll_delta, w.local_delta, w.roll_table,
                s.movers, s.mark, s.queue, s.stacks, s.search, s.scent_buffer, s.is_cut, s.adjacency, s.disc,
                s.low, s.stack_node, s.stack_k, obs.neighbour_kind, obs.neighbour_mode, obs.neighbour_scent,
                obs.own_mode, obs.own_scent, obs.messages, obs.contact, obs.load, obs.hint, obs.action_mask,
                np.arange(w.n_agents, dtype=np.int64), m.heading, m.growth, m.asked, m.spawned, m.spot_direction,
                m.spot_announced, m.spot_waited, m.refused, t.spot, t.parent, t.child, g.growth, g.waited, g.stuck,
                g.age, g.previous, self.rules, self.branch, self.table, self.grasp, self.rng, self.first_node,
                self.min_gap, self.target_levels, self.ledger, self.surface, int(self.cycle),
                int(max_cycles), int(record_every), recorded_cycles, recorded_cell, recorded_mode, self.test_scratch)
        recorded_cycles[:recorded] += self.cycle
        self.cycle += int(ran)
        shape = w.shape
        return Rollout(cycles=self.cycle, success=bool(self.success), positions=shape.point(st["cell"]),
                       modes=st["mode"].copy(), recorded_cycles=recorded_cycles[:recorded],
                       recorded_positions=shape.point(recorded_cell[:recorded]),
                       recorded_modes=recorded_mode[:recorded], rng=self.rng)


def compiled_rollout(env, policy, *, max_cycles: int | None = None, record_every: int = 0) -> Rollout:
    """Run a hand-coded behaviour from ``env``'s current state inside compiled code.

    ``CompiledRollout(env, policy).run(max_cycles, record_every=record_every)``: the result is
    what driving ``env`` with ``env.step_arrays(policy.act_arrays(env.observe_arrays()))``
    until the task's success (or ``max_cycles``) would give. Neither ``env`` nor ``policy``
    changes.

    Args:
        env: a :class:`~proteo_env.env.ProteoEnv` of the chain, branch, table or grasp task, after ``reset``.
        policy: a :class:`~baselines.chain.ChainPolicy` (chain), :class:`~baselines.branch.BranchPolicy`
            (branch), :class:`~baselines.table.TablePolicy` (table) or :class:`~baselines.grasp.GraspPolicy`
            (grasp) built for ``env``.
        max_cycles: cycles to run at most (default: the env's cycles left, ``max_cycles - cycle``).
        record_every: record positions and modes after every ``record_every``-th cycle and at
            success (0: only the final state).

    Returns:
        a :class:`Rollout`.
    """
    rollout = CompiledRollout(env, policy)
    return rollout.run(env.max_cycles - env.cycle if max_cycles is None else max_cycles, record_every=record_every)


__all__ = ["BEHAVIOURS", "CompiledRollout", "Rollout", "compiled_rollout", "is_branched_tree", "is_chain"]

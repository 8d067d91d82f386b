"""A policy that runs a program (:mod:`baselines.program`) for every module.

:class:`ProgramPolicy` runs the program as tables (:func:`~baselines.program_rules.encode`)
through the one kernel :func:`~baselines.program_rules.run_program`, the same code in its
``act``, in a :class:`~baselines.base.PolicyBatch` and inside the compiled rollout
(:mod:`baselines.compiled`). :func:`interpret` is the program's reading in plain Python, the
reference the kernel follows (:class:`ProgramReading` runs it as a policy, to read or step
through a program cycle by cycle); the tests hold the two to the same actions, cycle for cycle.

Each cycle, module by module in row order, a program is read so:

1. reads its messages: a direction (values ``1..12``) is remembered as the *heard* growth; a
   mode set (value ``13 + j``, pair ``j`` of :attr:`~baselines.program.Program.mode_sets`)
   sets the module's mode when the module is in the pair's first mode, and its growth to the
   direction the message travelled (so a new seed grows on straight);
2. counts the cycles it has been in its mode (``waited``; on a new mode ``waited`` and ``sent``
   start again at 0);
3. fires the first rule of its mode whose conditions all hold (they are checked in the order
   written, up to the first that fails), drawing from the policy's generator in the order
   the conditions and actions are written, and writes the action: the rule's roll (stay by
   default), ``go`` mode (its mode by default), the scent roles (relay by default) and one
   message (``tell growth`` or ``set``; a ``set`` that goes out adds one to ``sent``).

The conditions and actions are the primitives of :mod:`baselines.primitives` that the
hand-written rules use (legal rolls, the gradient's lowest rolls, growth directions, the
approach to a growth spot, uniform picks). Private memory per module: :class:`ProgramMemory`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from proteo_env.config import ConfigError
from proteo_env.core.lattice import OPPOSITE
from proteo_env.core.world import MESSAGE_TO_ALL
from proteo_env.registry import task_name
from proteo_env.spaces import EMIT, KIND_EMPTY, KIND_MODULE, RELAY, SILENT

from .base import KernelPolicy, SlotMemory
from .primitives import (
    ALL_BITS,
    AROUND_BITS,
    HORIZONTAL_BITS,
    UP_BITS,
    approach_spot,
    hint_bits,
    kind_bits,
    legal_bits,
    lowest_rolls,
    outward_pick,
    random_pick,
)
from .program import DIRECTION_MESSAGES, PROGRAMS_DIR, Program, load_program
from .program_rules import DOWN_BITS, ProgramTables, encode, run_program

ROLE_OF = {"emit {channel}": EMIT, "relay {channel}": RELAY, "block {channel}": SILENT}
PICK_CLASS = {"pick growth": "any", "pick level growth": "level", "pick hint growth": "hint"}
"""The direction class each ``pick`` chooses the growth direction in."""


class ProgramMemory(SlotMemory):
    """A program's private memory of every module, one entry per memory slot.

    Attributes (S slots):
        growth: ``(S,)`` int64 the module's growth direction (-1: none).
        heard: ``(S,)`` int64 the last growth direction a neighbour told it (-1: none).
        last_mode: ``(S,)`` int64 its mode last cycle (-1: none yet).
        waited: ``(S,)`` int64 cycles it has been in its mode.
        sent: ``(S,)`` int64 mode sets it has sent since it entered its mode.
    """

    FIELDS = {
        "growth": (np.int64, -1),
        "heard": (np.int64, -1),
        "last_mode": (np.int64, -1),
        "waited": (np.int64, 0),
        "sent": (np.int64, 0),
    }


class ProgramParams(NamedTuple):
    """A program as :func:`interpret` reads it: the program, the task's modes and the scent value of "none"."""

    program: Program
    modes: tuple[str, ...]
    scent_max: int


class _Module:
    """One module's view in one cycle: its observation row ``i``, memory slot ``s``, and the generator."""

    def __init__(self, seen, memory, i: int, s: int, params: ProgramParams, rng):
        self.seen, self.i, self.s, self.params, self.rng = seen, i, s, params, rng
        self.growth, self.heard, self.last_mode, self.waited, self.sent = memory
        self.legal = legal_bits(seen.action_mask, i)

    def channel(self, name: str) -> int:
        return self.params.program.channels.index(name)

    def mode_index(self, name: str) -> int:
        return self.params.modes.index(name)

    def class_bits(self, name: str) -> int:
        """The face directions of a direction class, as a bit set."""
        if name == "growth":
            g = self.growth[self.s]
            return 0 if g < 0 else 1 << int(g)
        if name == "hint":
            return hint_bits(self.seen.hint, self.i)[0]
        return {"any": ALL_BITS, "down": DOWN_BITS, "up": UP_BITS, "level": HORIZONTAL_BITS}[name]

    def slot_scents(self, c: int) -> np.ndarray:
        """``(12,)`` int64 the channel-``c`` scent of each face neighbour (``scent_max`` where no module)."""
        seen = self.seen
        modules = seen.neighbour_kind[self.i, :12] == KIND_MODULE
        return np.where(modules, seen.neighbour_scent[self.i, :12, c], self.params.scent_max).astype(np.int64)

    def holds(self, condition) -> bool:
        truth = self.sense(condition.pattern, condition.arguments)
        return truth != condition.negated

    def sense(self, pattern: str, args: tuple) -> bool:
        seen, i, value = self.seen, self.i, self.params.program.value
        if pattern == "detects {channel}":
            c = self.channel(args[0])
            return seen.own_scent[i, c] < self.params.scent_max or bool(
                (self.slot_scents(c) < self.params.scent_max).any()
            )
        if pattern == "scent {channel} above {count}":
            return seen.own_scent[i, self.channel(args[0])] > value(args[1])
        if pattern == "scent {channel} below {count}":
            return seen.own_scent[i, self.channel(args[0])] < value(args[1])
        if pattern in ("neighbour {mode}", "neighbour {mode} at {class}"):
            bits = self.class_bits(args[1] if len(args) > 1 else "any")
            mode = self.mode_index(args[0])
            return any((bits >> k) & 1 and seen.neighbour_mode[i, k] == mode for k in range(12))
        if pattern == "at spot {mode}":
            mode = self.mode_index(args[0])
            return any(
                1 <= seen.messages[i, k] <= DIRECTION_MESSAGES
                and OPPOSITE[seen.messages[i, k] - 1] == k
                and seen.neighbour_mode[i, k] == mode
                for k in range(12)
            )
        if pattern == "touching ground":
            return bool(seen.contact[i, 0])
        if pattern == "touching object":
            return bool(seen.contact[i, 1])
        if pattern == "load above {number}":
            return seen.load[i, 0] > value(args[0])
        if pattern == "load below {number}":
            return seen.load[i, 0] < value(args[0])
        if pattern == "can move":
            return self.legal != 0
        if pattern == "waited {count}":
            return self.waited[self.s] >= value(args[0])
        if pattern == "chance {probability}":
            return self.rng.random() < value(args[0])
        if pattern == "sent {count}":
            return self.sent[self.s] >= value(args[0])
        raise AssertionError(f"condition {pattern!r} has no meaning here")  # the loader admits none other

    def act(self, pattern: str, args: tuple, action: np.ndarray) -> None:
        """Write the action phrase into ``action`` (L,) (and the module's memory)."""
        seen, i, s = self.seen, self.i, self.s
        if pattern in ROLE_OF:
            action[2 + self.channel(args[0])] = ROLE_OF[pattern]
        elif pattern == "move {class}":
            action[0] = random_pick(self.rng, self.legal & self.class_bits(args[0])) + 1
        elif pattern == "move gradient {channel}":
            scents = self.slot_scents(self.channel(args[0]))
            pool, lowest = lowest_rolls(scents, self.legal)
            action[0] = 0 if self.legal == 0 or lowest > scents.min() else random_pick(self.rng, pool) + 1
        elif pattern == "move spot {mode}":
            slots = np.flatnonzero(seen.neighbour_mode[i, :12] == self.mode_index(args[0]))
            if slots.size and self.heard[s] >= 0:
                action[0] = approach_spot(seen.action_mask, i, int(slots[0]), int(self.heard[s]), True, self.rng)
        elif pattern == "move around {mode}":
            around = 0
            for k in np.flatnonzero(seen.neighbour_mode[i, :12] == self.mode_index(args[0])):
                around |= int(AROUND_BITS[k])
            action[0] = random_pick(self.rng, self.legal & around) + 1
        elif pattern == "stay":
            action[0] = 0
        elif pattern in PICK_CLASS:
            if self.growth[s] < 0:
                empty = kind_bits(seen.neighbour_kind, i, KIND_EMPTY)
                self.growth[s] = outward_pick(
                    seen.neighbour_kind, i, self.rng, empty & self.class_bits(PICK_CLASS[pattern])
                )
        elif pattern == "drop growth":
            self.growth[s] = -1
        elif pattern == "tell growth":
            if self.growth[s] >= 0:
                action[-2:] = MESSAGE_TO_ALL, self.growth[s] + 1
        else:
            raise AssertionError(f"action {pattern!r} has no meaning here")  # the loader admits none other


def interpret(seen, slots, memory, params: ProgramParams, rng, actions) -> None:
    """Every module's action under ``params.program``, read in plain Python (the
    :attr:`~baselines.base.KernelPolicy.rule` of :class:`ProgramReading`): ``seen`` an :class:`~baselines.base.Observed` of A rows, ``slots``
    (A,) memory slots, ``memory`` the arrays of :class:`ProgramMemory`; writes ``actions`` (A, L)."""
    program = params.program
    rules_of = dict(program.modes)
    mode_sets = program.mode_sets
    for i, s in enumerate(slots):
        module = _Module(seen, memory, i, int(s), params, rng)
        mode = int(seen.own_mode[i, 0])
        for k in range(12):
            v = int(seen.messages[i, k])
            if 1 <= v <= DIRECTION_MESSAGES:
                module.heard[s] = v - 1
            elif DIRECTION_MESSAGES < v <= DIRECTION_MESSAGES + len(mode_sets):
                neighbour_mode, to = mode_sets[v - DIRECTION_MESSAGES - 1]
                if mode == module.mode_index(neighbour_mode):
                    mode = module.mode_index(to)
                    module.growth[s] = OPPOSITE[k]
        if mode == module.last_mode[s]:
            module.waited[s] += 1
        else:
            module.waited[s] = 0
            module.sent[s] = 0
        module.last_mode[s] = mode
        action = actions[i]
        action[:] = 0
        action[1] = mode
        action[2 : 2 + len(seen.own_scent[i])] = RELAY
        rule = next((r for r in rules_of.get(params.modes[mode], ()) if all(map(module.holds, r.conditions))), None)
        if rule is None:
            continue
        for a in rule.actions:
            module.act(a.pattern, a.arguments, action)
        if rule.go is not None:
            action[1] = module.mode_index(rule.go)
        if rule.set is not None:
            target = MESSAGE_TO_ALL if rule.set.at == "any" else int(module.growth[s])
            if rule.set.at == "one":  # the first neighbour in the mode the set applies to
                slots_in_mode = np.flatnonzero(
                    seen.neighbour_mode[i, :12] == module.mode_index(rule.set.neighbour_mode)
                )
                target = int(slots_in_mode[0]) if slots_in_mode.size else -1
            if target >= 0:
                pair = mode_sets.index((rule.set.neighbour_mode, rule.set.to))
                action[-2:] = target, DIRECTION_MESSAGES + 1 + pair
                module.sent[s] += 1


class ProgramPolicy(KernelPolicy):
    """Runs a program (:mod:`baselines.program`) on every module, at control level ``full``.

    Build it with ``make_policy("program", env, program="chain", seed=0)``: ``program`` is
    program text, a path to a YAML file or the name of a program in ``baselines/programs/``,
    checked against the env's task (:func:`~baselines.program.load_program`). Its rule is the
    kernel :func:`~baselines.program_rules.run_program` over the program's tables, so it runs
    in a :class:`~baselines.base.PolicyBatch` and in the compiled rollout like the hand-written rules.

    Args:
        program: the checked :class:`~baselines.program.Program`.
    """

    name = "program"
    levels = ("full",)
    rule = staticmethod(run_program)

    @classmethod
    def for_env(cls, env, *, seed: int | None = None, program=None):
        if program is None:
            raise ConfigError(
                "program = None is not allowed; allowed: a program's name in baselines/programs/ "
                f"({', '.join(sorted(p.stem for p in PROGRAMS_DIR.glob('*.yaml')))}), a path to a YAML file, "
                "or the program's text"
            )
        return super().for_env(env, seed=seed, program=load_program(program, env))

    def __init__(self, action_layout, modes, *, scent_max=65535, seed=None, program: Program):
        super().__init__(action_layout, modes, scent_max=scent_max, seed=seed)
        self.program = program
        self.memory = ProgramMemory()
        """Private memory of every module (see :class:`ProgramMemory`)."""
        self.tables = encode(program, self.modes, int(scent_max))

    @property
    def rule_params(self) -> ProgramTables:
        return self.tables

    def runs_on(self, task) -> bool:
        """Whether the program is written for ``task``."""
        return task_name(self.program.task) == task.name


class ProgramReading(ProgramPolicy):
    """The same policy with the program read in plain Python (:func:`interpret`): the reference
    :class:`ProgramPolicy`'s kernel follows, action for action, to read or step through a
    program in a debugger. Slow (Python per module), so it takes no part in a
    :class:`~baselines.base.PolicyBatch` or the compiled rollout; build it with
    ``ProgramReading.for_env(env, program=..., seed=...)``."""

    rule = staticmethod(interpret)

    @property
    def rule_params(self) -> ProgramParams:
        return ProgramParams(self.program, self.modes, int(self.scent_max))

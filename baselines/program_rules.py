"""Any program (:mod:`baselines.program`) as integer and float tables, and the one numba kernel that runs them.

:func:`encode` turns a :class:`~baselines.program.Program` into :class:`ProgramTables`: per
mode a range of rules, per rule a range of conditions and of actions, each an opcode and its
arguments, and the mode sets. :func:`run_program` is a policy's
:attr:`~baselines.base.KernelPolicy.rule` that interprets those tables for every module, so
one compiled kernel runs every program, through a policy's ``act``, in a
:class:`~baselines.base.PolicyBatch` and inside the compiled rollout
(:mod:`baselines.compiled`).

It reads a program exactly as the plain-Python reading
(:func:`baselines.program_policy.interpret`) does, step for step and draw for draw (one
uniform per ``chance``; the draws of :mod:`baselines.primitives` for rolls and picks; a rule's
conditions stop at the first that fails), so both give the same actions from the same
observations, memory and generator state (``tests/test_programs.py``).

Shapes (A agents, S memory slots, M task modes, R rules, Q conditions, P actions, J mode sets,
C channels, L = 4 + C action fields): the observation fields as
:class:`~baselines.base.Observed` gives them, ``slots`` (A,) int64, the memory
``(growth, heard, last_mode, waited, sent)`` of :class:`~baselines.program_policy.ProgramMemory`,
each (S,) int64, ``actions`` (A, L) int64 written.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from proteo_env.core.jit import kernel
from proteo_env.core.lattice import OPPOSITE
from proteo_env.core.world import MESSAGE_TO_ALL
from proteo_env.spaces import EMIT, KIND_EMPTY, KIND_MODULE, RELAY, SILENT

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
from .program import DIRECTION_MESSAGES, Program

DOWN_BITS = ALL_BITS & ~(UP_BITS | HORIZONTAL_BITS)
"""The 4 face directions pointing down (``z < 0``), as a bit set."""

(
    IF_DETECTS,
    IF_SCENT_ABOVE,
    IF_SCENT_BELOW,
    IF_NEIGHBOUR,
    IF_AT_SPOT,
    IF_GROUND,
    IF_OBJECT,
    IF_LOAD_ABOVE,
    IF_LOAD_BELOW,
    IF_CAN_MOVE,
    IF_WAITED,
    IF_CHANCE,
    IF_SENT,
) = range(13)
CONDITION_CODES = {
    "detects {channel}": IF_DETECTS,
    "scent {channel} above {count}": IF_SCENT_ABOVE,
    "scent {channel} below {count}": IF_SCENT_BELOW,
    "neighbour {mode}": IF_NEIGHBOUR,
    "neighbour {mode} at {class}": IF_NEIGHBOUR,
    "at spot {mode}": IF_AT_SPOT,
    "touching ground": IF_GROUND,
    "touching object": IF_OBJECT,
    "load above {number}": IF_LOAD_ABOVE,
    "load below {number}": IF_LOAD_BELOW,
    "can move": IF_CAN_MOVE,
    "waited {count}": IF_WAITED,
    "chance {probability}": IF_CHANCE,
    "sent {count}": IF_SENT,
}
"""The opcode of each condition phrase of :data:`~baselines.program.CONDITIONS`."""

CLASS_CODES = {name: code for code, name in enumerate(("any", "growth", "hint", "down", "up", "level"))}
"""The code of each direction class of :data:`~baselines.program.DIRECTION_CLASSES`."""
CLASS_ANY, CLASS_GROWTH, CLASS_HINT, CLASS_DOWN, CLASS_UP, CLASS_LEVEL = CLASS_CODES.values()

DO_ROLE, DO_MOVE, DO_GRADIENT, DO_SPOT, DO_AROUND, DO_STAY, DO_PICK_GROWTH, DO_DROP_GROWTH, DO_TELL_GROWTH = range(9)
ACTION_CODES = {
    "emit {channel}": (DO_ROLE, EMIT),
    "relay {channel}": (DO_ROLE, RELAY),
    "block {channel}": (DO_ROLE, SILENT),
    "move {class}": (DO_MOVE, 0),
    "move gradient {channel}": (DO_GRADIENT, 0),
    "move spot {mode}": (DO_SPOT, 0),
    "move around {mode}": (DO_AROUND, 0),
    "stay": (DO_STAY, 0),
    "pick growth": (DO_PICK_GROWTH, CLASS_ANY),
    "pick level growth": (DO_PICK_GROWTH, CLASS_LEVEL),
    "pick hint growth": (DO_PICK_GROWTH, CLASS_HINT),
    "drop growth": (DO_DROP_GROWTH, 0),
    "tell growth": (DO_TELL_GROWTH, 0),
}
"""The ``(opcode, fixed argument)`` of each action phrase of :data:`~baselines.program.ACTIONS`
(the scent role of ``emit``/``relay``/``block``; the direction class a ``pick`` chooses in)."""

SET_AT_GROWTH, SET_AT_ANY, SET_AT_ONE = range(3)
"""``ProgramTables.set_at``: where a rule's mode set goes (-1: the rule sets nothing)."""


class ProgramTables(NamedTuple):
    """A program as :func:`run_program` reads it (M task modes, R rules, Q conditions, P actions,
    J mode sets), rules stored mode by mode, conditions and actions rule by rule, in the
    program's order.

    Attributes:
        mode_rules: ``(M + 1,)`` int64, the rules of mode ``m`` are ``mode_rules[m] .. mode_rules[m + 1] - 1``.
        rule_conditions: ``(R + 1,)`` int64, the same for each rule's conditions.
        rule_actions: ``(R + 1,)`` int64, the same for each rule's actions (rows of ``steps``).
        go: ``(R,)`` int64, the mode a rule goes to (-1: the module's mode).
        set_at: ``(R,)`` int64, where the rule's mode set goes (``SET_AT_*``; -1: none).
        set_value: ``(R,)`` int64, the message value of the rule's mode set.
        conditions: ``(Q, 4)`` int64, per condition its opcode (``IF_*``), 1 when negated, its
            channel or mode, and its direction class (``CLASS_*``).
        condition_numbers: ``(Q,)`` float64, a condition's number (a parameter's value).
        steps: ``(P, 3)`` int64, per action its opcode (``DO_*``), its fixed argument (the
            role, the class a pick chooses in) and its channel, mode or direction class.
        mode_sets: ``(J, 2)`` int64, the mode a set applies to and the mode it sets; set ``j``
            travels as message value ``DIRECTION_MESSAGES + 1 + j``.
        scent_max: the scent value of "no scent".
    """

    mode_rules: np.ndarray
    rule_conditions: np.ndarray
    rule_actions: np.ndarray
    go: np.ndarray
    set_at: np.ndarray
    set_value: np.ndarray
    conditions: np.ndarray
    condition_numbers: np.ndarray
    steps: np.ndarray
    mode_sets: np.ndarray
    scent_max: int


def encode(program: Program, modes, scent_max: int) -> ProgramTables:
    """``program`` (checked by :func:`~baselines.program.load_program`) as :class:`ProgramTables`
    for a task with the mode names ``modes``, whose scent value of "none" is ``scent_max``."""
    modes = tuple(modes)
    rules_of = dict(program.modes)
    mode_sets = program.mode_sets

    def argument(kind: str, value) -> int:
        if kind == "channel":
            return program.channels.index(value)
        return modes.index(value) if kind == "mode" else CLASS_CODES[value]

    mode_rules, rule_conditions, rule_actions = [0], [0], [0]
    go, set_at, set_value, conditions, numbers, actions = [], [], [], [], [], []
    for mode in modes:
        for rule in rules_of.get(mode, ()):
            for condition in rule.conditions:
                kinds = [w[1:-1] for w in condition.pattern.split() if w.startswith("{")]
                named = dict(zip(kinds, condition.arguments))
                subject = next((k for k in ("channel", "mode") if k in named), None)
                conditions.append(
                    (
                        CONDITION_CODES[condition.pattern],
                        int(condition.negated),
                        argument(subject, named[subject]) if subject else 0,
                        CLASS_CODES[named.get("class", "any")],
                    )
                )
                number = next((v for k, v in named.items() if k in ("count", "number", "probability")), 0.0)
                numbers.append(float(program.value(number)))
            for action in rule.actions:
                code, fixed = ACTION_CODES[action.pattern]
                kind = next((w[1:-1] for w in action.pattern.split() if w.startswith("{")), None)
                actions.append((code, fixed, argument(kind, action.arguments[0]) if kind else 0))
            go.append(-1 if rule.go is None else modes.index(rule.go))
            if rule.set is None:
                set_at.append(-1)
                set_value.append(0)
            else:
                set_at.append({"growth": SET_AT_GROWTH, "any": SET_AT_ANY, "one": SET_AT_ONE}[rule.set.at])
                set_value.append(DIRECTION_MESSAGES + 1 + mode_sets.index((rule.set.neighbour_mode, rule.set.to)))
            rule_conditions.append(len(conditions))
            rule_actions.append(len(actions))
        mode_rules.append(len(go))

    def table(rows, columns=None, dtype=np.int64):
        shape = (len(rows), columns) if columns else (len(rows),)
        return np.array(rows, dtype=dtype).reshape(shape)

    return ProgramTables(
        mode_rules=table(mode_rules),
        rule_conditions=table(rule_conditions),
        rule_actions=table(rule_actions),
        go=table(go),
        set_at=table(set_at),
        set_value=table(set_value),
        conditions=table(conditions, 4),
        condition_numbers=table(numbers, dtype=np.float64),
        steps=table(actions, 3),
        mode_sets=table([(modes.index(a), modes.index(b)) for a, b in mode_sets], 2),
        scent_max=int(scent_max),
    )


@kernel
def class_bits(code, growth, hint, i):
    """The face directions of direction class ``code`` (``CLASS_*``) of row ``i``, a module with
    the growth direction ``growth`` (-1: none) and the hint ``hint[i]``, as a bit set."""
    if code == CLASS_GROWTH:
        return 0 if growth < 0 else 1 << growth
    if code == CLASS_HINT:
        return hint_bits(hint, i)[0]
    if code == CLASS_DOWN:
        return DOWN_BITS
    if code == CLASS_UP:
        return UP_BITS
    if code == CLASS_LEVEL:
        return HORIZONTAL_BITS
    return ALL_BITS


@kernel
def run_program(seen, slots, memory, tables, rng, actions):
    """Every module's action under the program of ``tables`` (a :class:`ProgramTables`), module
    by module in row order, as :func:`baselines.program_policy.interpret` reads it: messages
    (heard growth, mode sets), ``waited``, the first rule of the mode whose conditions all hold
    (its actions, ``go`` and ``set``; defaults: stay, keep the mode, relay, no message).
    ``memory`` is ``(growth, heard, last_mode, waited, sent)`` (shapes in the module docstring).

    One loop with the opcodes' meanings written in it: a call with array arguments per
    condition or action would cost more than the opcode's work."""
    growth, heard, last_mode, waited, sent = memory
    own_mode, messages, own_scent, action_mask = seen.own_mode, seen.messages, seen.own_scent, seen.action_mask
    neighbour_kind, neighbour_mode, neighbour_scent = seen.neighbour_kind, seen.neighbour_mode, seen.neighbour_scent
    contact, load, hint = seen.contact, seen.load, seen.hint
    mode_rules, rule_conditions, rule_actions, go, set_at, set_value, conditions, numbers, steps, mode_sets, smax = (
        tables
    )
    n_channels, n_fields, n_sets = own_scent.shape[1], actions.shape[1], mode_sets.shape[0]
    scents = np.empty(12, dtype=np.int64)
    for i in range(slots.shape[0]):
        s = slots[i]
        mode = np.int64(own_mode[i, 0])
        for k in range(12):
            v = messages[i, k]
            if 1 <= v <= DIRECTION_MESSAGES:
                heard[s] = v - 1
            elif DIRECTION_MESSAGES < v <= DIRECTION_MESSAGES + n_sets:
                j = v - DIRECTION_MESSAGES - 1
                if mode == mode_sets[j, 0]:
                    mode = mode_sets[j, 1]
                    growth[s] = OPPOSITE[k]
        if mode == last_mode[s]:
            waited[s] += 1
        else:
            waited[s] = 0
            sent[s] = 0
        last_mode[s] = mode
        actions[i, :] = 0
        actions[i, 1] = mode
        actions[i, 2 : 2 + n_channels] = RELAY
        legal = legal_bits(action_mask, i)
        for r in range(mode_rules[mode], mode_rules[mode + 1]):
            fires = True
            for q in range(rule_conditions[r], rule_conditions[r + 1]):  # up to the first that fails
                code, subject, number = conditions[q, 0], conditions[q, 2], numbers[q]
                truth = False
                if code == IF_DETECTS:
                    truth = own_scent[i, subject] < smax
                    for k in range(12):
                        if neighbour_kind[i, k] == KIND_MODULE and neighbour_scent[i, k, subject] < smax:
                            truth = True
                elif code == IF_SCENT_ABOVE:
                    truth = own_scent[i, subject] > number
                elif code == IF_SCENT_BELOW:
                    truth = own_scent[i, subject] < number
                elif code == IF_NEIGHBOUR:
                    bits = class_bits(conditions[q, 3], growth[s], hint, i)
                    for k in range(12):
                        if (bits >> k) & 1 and neighbour_mode[i, k] == subject:
                            truth = True
                elif code == IF_AT_SPOT:
                    for k in range(12):
                        v = messages[i, k]
                        if 1 <= v <= DIRECTION_MESSAGES and OPPOSITE[v - 1] == k and neighbour_mode[i, k] == subject:
                            truth = True
                elif code == IF_GROUND:
                    truth = contact[i, 0] != 0
                elif code == IF_OBJECT:
                    truth = contact[i, 1] != 0
                elif code == IF_LOAD_ABOVE:
                    truth = load[i, 0] > number
                elif code == IF_LOAD_BELOW:
                    truth = load[i, 0] < number
                elif code == IF_CAN_MOVE:
                    truth = legal != 0
                elif code == IF_WAITED:
                    truth = waited[s] >= number
                elif code == IF_CHANCE:
                    truth = rng.random() < number
                elif code == IF_SENT:
                    truth = sent[s] >= number
                if truth == (conditions[q, 1] != 0):
                    fires = False
                    break
            if not fires:
                continue
            for p in range(rule_actions[r], rule_actions[r + 1]):
                code, fixed, argument = steps[p, 0], steps[p, 1], steps[p, 2]
                if code == DO_ROLE:
                    actions[i, 2 + argument] = fixed
                elif code == DO_MOVE:
                    actions[i, 0] = random_pick(rng, legal & class_bits(argument, growth[s], hint, i)) + 1
                elif code == DO_GRADIENT:
                    for k in range(12):
                        scents[k] = neighbour_scent[i, k, argument] if neighbour_kind[i, k] == KIND_MODULE else smax
                    pool, lowest = lowest_rolls(scents, legal)
                    actions[i, 0] = 0 if legal == 0 or lowest > scents.min() else random_pick(rng, pool) + 1
                elif code == DO_SPOT:
                    for k in range(12):
                        if neighbour_mode[i, k] == argument:
                            if heard[s] >= 0:
                                actions[i, 0] = approach_spot(action_mask, i, k, heard[s], True, rng)
                            break
                elif code == DO_AROUND:
                    around = 0
                    for k in range(12):
                        if neighbour_mode[i, k] == argument:
                            around |= AROUND_BITS[k]
                    actions[i, 0] = random_pick(rng, legal & around) + 1
                elif code == DO_STAY:
                    actions[i, 0] = 0
                elif code == DO_PICK_GROWTH:
                    if growth[s] < 0:
                        empty = kind_bits(neighbour_kind, i, KIND_EMPTY)
                        growth[s] = outward_pick(neighbour_kind, i, rng, empty & class_bits(fixed, -1, hint, i))
                elif code == DO_DROP_GROWTH:
                    growth[s] = -1
                elif code == DO_TELL_GROWTH:
                    if growth[s] >= 0:
                        actions[i, n_fields - 2] = MESSAGE_TO_ALL
                        actions[i, n_fields - 1] = growth[s] + 1
            if go[r] >= 0:
                actions[i, 1] = go[r]
            if set_at[r] >= 0:
                target = MESSAGE_TO_ALL if set_at[r] == SET_AT_ANY else growth[s]
                if set_at[r] == SET_AT_ONE:  # the first neighbour in the mode the set applies to
                    target = -1
                    for k in range(11, -1, -1):
                        if neighbour_mode[i, k] == mode_sets[set_value[r] - DIRECTION_MESSAGES - 1, 0]:
                            target = k
                if target >= 0:
                    actions[i, n_fields - 2] = target
                    actions[i, n_fields - 1] = set_value[r]
                    sent[s] += 1
            break

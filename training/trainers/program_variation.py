"""Random programs, mutation and crossover of programs (:mod:`baselines.program`) for evolution.

Every program these functions return is valid: it is built, then passed through
``load_program(format_program(program), task)`` and returned as loaded; an operator whose
result the loader rejects (too many distinct mode sets, for example) is tried again with new
draws, and after :data:`ATTEMPTS` failures the parent comes back unchanged. Modes that no rule
reaches any more are dropped, and so are parameters no condition uses.

Mutations (:data:`MUTATIONS`, one picked uniformly among those that apply): add, remove,
replace or reorder a rule; add, remove, replace or negate a condition; add, remove or replace
an action; change a rule's ``go`` or ``set`` target; perturb a number (a parameter or a
literal threshold, count or probability); add a mode (reached by a rule's ``go``) or remove
one. Crossover exchanges one whole mode, or the tail of one mode's rules, between two parents.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from baselines.program import (
    ACTIONS,
    CONDITIONS,
    DIRECTION_CLASSES,
    MESSAGES,
    MOVES,
    ROLES,
    SET_TARGETS,
    Action,
    Condition,
    ModeSet,
    Program,
    Rule,
    format_program,
    load_program,
)
from proteo_env.config import ConfigError

ATTEMPTS = 50
"""Draws an operator gets to produce a valid program before the parent is returned unchanged."""


@dataclass(frozen=True)
class ProgramSpace:
    """What evolved programs of one task are made of, and how big they may grow.

    Attributes:
        task: the task class (its ``modes``, channels and message values bound the programs).
        channels: the programs' channel names (``channels[c]`` is the task's channel ``c``).
        start: the modes modules start in (the modes the task's worlds begin with).
        max_rules: rules per mode.
        max_conditions: conditions per rule.
        max_actions: actions per rule.
        max_count: the largest count (``waited``, scent thresholds) a random draw gives.
        max_load: the largest load threshold a random draw gives.
    """

    task: type
    channels: tuple[str, ...]
    start: tuple[str, ...]
    max_rules: int = 4
    max_conditions: int = 3
    max_actions: int = 3
    max_count: int = 12
    max_load: float = 4.0

    @classmethod
    def for_env(cls, env, seeds=range(8), **limits) -> ProgramSpace:
        """The space of ``env``'s task: channels ``scent`` (``scent0``, ``scent1``, ... when the
        task has several) and the start modes seen in the worlds of ``seeds``."""
        n = env.task.n_channels
        channels = ("scent",) if n == 1 else tuple(f"scent{c}" for c in range(n))
        seen = set()
        for seed in seeds:
            env.reset(seed=int(seed))
            seen.update(int(m) for m in env.world.modes)
        start = tuple(env.task.modes[m] for m in sorted(seen))
        return cls(type(env.task), channels, start, **limits)

    @classmethod
    def for_program(cls, program: Program, task, **limits) -> ProgramSpace:
        """The space of a seed program: its channels and start modes."""
        return cls(task, program.channels, program.start, **limits)


def complexity(program: Program) -> int:
    """The program's size: rules + conditions + actions."""
    rules = [rule for _, mode_rules in program.modes for rule in mode_rules]
    return len(rules) + sum(len(r.conditions) + len(r.actions) for r in rules)


def _pick(rng: np.random.Generator, items):
    """One of ``items`` (a sequence), uniformly."""
    return items[int(rng.integers(len(items)))]


def _placeholders(pattern: str) -> list[str]:
    """The kinds of a phrase's placeholders, in order (``"channel"``, ``"count"`` ...)."""
    return [word[1:-1] for word in pattern.split() if word.startswith("{")]


def _random_argument(kind: str, space: ProgramSpace, rng: np.random.Generator):
    if kind == "channel":
        return _pick(rng, space.channels)
    if kind == "mode":
        return _pick(rng, space.task.modes)
    if kind == "class":
        return _pick(rng, tuple(DIRECTION_CLASSES))
    if kind == "count":
        return int(rng.integers(space.max_count + 1))
    if kind == "probability":
        return round(float(rng.uniform(0.0, 1.0)), 3)
    return round(float(rng.uniform(0.0, space.max_load)), 3)


def _perturb(value, kind: str, rng: np.random.Generator):
    """A nearby number of the same kind: a count moves by 1 or 2, a probability by about 0.1
    (kept in [0, 1]), another number by about 30 % (kept >= 0)."""
    if kind == "count":
        return max(0, int(value) + int(_pick(rng, (-2, -1, 1, 2))))
    if kind == "probability":
        return round(float(np.clip(value + rng.normal(0.0, 0.1), 0.0, 1.0)), 3)
    return round(max(0.0, float(value) * float(np.exp(rng.normal(0.0, 0.3))) + float(rng.normal(0.0, 0.1))), 3)


def random_condition(space: ProgramSpace, rng: np.random.Generator) -> Condition:
    """A condition phrase with random arguments, negated with probability 1/4."""
    pattern = _pick(rng, tuple(CONDITIONS))
    arguments = tuple(_random_argument(kind, space, rng) for kind in _placeholders(pattern))
    return Condition(pattern, arguments, bool(rng.random() < 0.25))


def random_action(space: ProgramSpace, rng: np.random.Generator) -> Action:
    """An action phrase with random arguments."""
    pattern = _pick(rng, tuple(ACTIONS))
    return Action(pattern, tuple(_random_argument(kind, space, rng) for kind in _placeholders(pattern)))


def random_mode_set(space: ProgramSpace, rng: np.random.Generator) -> ModeSet:
    """A ``set`` of random modes and target."""
    return ModeSet(_pick(rng, space.task.modes), _pick(rng, SET_TARGETS), _pick(rng, space.task.modes))


def _slot(action: Action):
    """What an action occupies in a rule: the roll, the message, a channel's role, or itself."""
    if action.pattern in MOVES:
        return "roll"
    if action.pattern in MESSAGES:
        return "message"
    if action.pattern in ROLES:
        return ("role", action.arguments[0])
    return action.pattern


def _with_action(rule: Rule, action: Action, index: int | None = None) -> Rule:
    """``rule`` with ``action`` inserted at ``index`` (default: the end), replacing an action of
    the same slot (and the ``set``, when the action is a message)."""
    kept = [a for a in rule.actions if _slot(a) != _slot(action)]
    kept.insert(len(kept) if index is None else min(index, len(kept)), action)
    mode_set = None if _slot(action) == "message" else rule.set
    return dataclasses.replace(rule, actions=tuple(kept), set=mode_set)


def _with_mode_set(rule: Rule, mode_set: ModeSet | None) -> Rule:
    """``rule`` sending ``mode_set`` (dropping its other message)."""
    actions = rule.actions if mode_set is None else tuple(a for a in rule.actions if _slot(a) != "message")
    return dataclasses.replace(rule, actions=actions, set=mode_set)


def random_rule(space: ProgramSpace, rng: np.random.Generator) -> Rule:
    """A rule of 0-2 conditions, 1 to ``max_actions`` actions, a ``go`` with probability 0.3
    and a ``set`` with probability 0.1."""
    conditions = tuple(random_condition(space, rng) for _ in range(int(rng.integers(min(2, space.max_conditions) + 1))))
    rule = Rule(conditions)
    for _ in range(int(rng.integers(1, space.max_actions + 1))):
        rule = _with_action(rule, random_action(space, rng))
    if rng.random() < 0.3:
        rule = dataclasses.replace(rule, go=_pick(rng, space.task.modes))
    if rng.random() < 0.1:
        rule = _with_mode_set(rule, random_mode_set(space, rng))
    return rule


def random_program(space: ProgramSpace, rng: np.random.Generator, task: str) -> Program:
    """A valid random program for the task named ``task``: 1-2 rules for every start mode and
    for each other mode with probability 1/2 (kept when a rule reaches it)."""
    for _ in range(ATTEMPTS):
        modes = {
            mode: [random_rule(space, rng) for _ in range(int(rng.integers(1, min(2, space.max_rules) + 1)))]
            for mode in space.task.modes
            if mode in space.start or rng.random() < 0.5
        }
        try:
            return _finish(Program(task, space.channels, space.start, (), ()), modes, {}, space)
        except ConfigError:
            continue
    raise ValueError(f"no valid random program for task {task!r} in {ATTEMPTS} draws")


# ---------------------------------------------------------------------- building and checking
def _reachable(modes: dict[str, list[Rule]], start) -> set[str]:
    reached, todo = set(start), list(start)
    while todo:
        for rule in modes.get(todo.pop(), ()):
            for mode in (rule.go, rule.set and rule.set.to):
                if mode and mode not in reached:
                    reached.add(mode)
                    todo.append(mode)
    return reached


def _finish(parent: Program, modes: dict[str, list[Rule]], parameters: dict, space: ProgramSpace) -> Program:
    """The program of ``modes`` (with ``parent``'s task, channels and start): unreachable modes
    and unused parameters dropped, checked by the loader (``ConfigError`` when not allowed)."""
    reached = _reachable(modes, parent.start)
    order = [m for m in space.task.modes if modes.get(m) and m in reached]
    used = {
        a
        for m in order
        for rule in modes[m]
        for c in rule.conditions
        for a in c.arguments
        if isinstance(a, str) and a in parameters
    }
    program = Program(
        parent.task,
        parent.channels,
        parent.start,
        tuple((name, value) for name, value in parameters.items() if name in used),
        tuple((m, tuple(modes[m])) for m in order),
    )
    for _, rules in program.modes:
        for rule in rules:
            if len(rule.conditions) > space.max_conditions or len(rule.actions) > space.max_actions:
                raise ConfigError("a rule over the space's size limits")
        if len(rules) > space.max_rules:
            raise ConfigError("a mode over the space's size limit")
    return load_program(format_program(program), space.task)


def _parts(program: Program) -> tuple[dict[str, list[Rule]], dict]:
    """The program's modes (as lists of rules) and parameters, as mutable copies."""
    return {mode: list(rules) for mode, rules in program.modes}, dict(program.parameters)


def _any_rule(modes: dict[str, list[Rule]], rng, where=lambda rule: True):
    """``(mode, index)`` of a random rule for which ``where`` holds, or ``None``."""
    places = [(m, i) for m, rules in modes.items() for i, rule in enumerate(rules) if where(rule)]
    return _pick(rng, places) if places else None


# ---------------------------------------------------------------------- mutations
def _add_rule(modes, parameters, space, rng):
    mode = _pick(rng, [m for m, rules in modes.items() if len(rules) < space.max_rules] or [None])
    if mode is None:
        return False
    modes[mode].insert(int(rng.integers(len(modes[mode]) + 1)), random_rule(space, rng))
    return True


def _remove_rule(modes, parameters, space, rng):
    mode = _pick(rng, [m for m, rules in modes.items() if len(rules) > 1] or [None])
    if mode is None:
        return False
    del modes[mode][int(rng.integers(len(modes[mode])))]
    return True


def _replace_rule(modes, parameters, space, rng):
    mode, index = _any_rule(modes, rng)
    modes[mode][index] = random_rule(space, rng)
    return True


def _swap_rules(modes, parameters, space, rng):
    mode = _pick(rng, [m for m, rules in modes.items() if len(rules) > 1] or [None])
    if mode is None:
        return False
    i = int(rng.integers(len(modes[mode]) - 1))
    modes[mode][i], modes[mode][i + 1] = modes[mode][i + 1], modes[mode][i]
    return True


def _edit_rule(modes, rng, where, edit):
    """Replace a random rule for which ``where`` holds by ``edit(rule)``; False when none holds."""
    place = _any_rule(modes, rng, where)
    if place is None:
        return False
    mode, index = place
    modes[mode][index] = edit(modes[mode][index])
    return True


def _add_condition(modes, parameters, space, rng):
    def edit(rule):
        conditions = list(rule.conditions)
        conditions.insert(int(rng.integers(len(conditions) + 1)), random_condition(space, rng))
        return dataclasses.replace(rule, conditions=tuple(conditions))

    return _edit_rule(modes, rng, lambda r: len(r.conditions) < space.max_conditions, edit)


def _remove_condition(modes, parameters, space, rng):
    def edit(rule):
        i = int(rng.integers(len(rule.conditions)))
        return dataclasses.replace(rule, conditions=rule.conditions[:i] + rule.conditions[i + 1 :])

    return _edit_rule(modes, rng, lambda r: r.conditions, edit)


def _replace_condition(modes, parameters, space, rng):
    def edit(rule):
        i = int(rng.integers(len(rule.conditions)))
        new = random_condition(space, rng)
        return dataclasses.replace(rule, conditions=rule.conditions[:i] + (new,) + rule.conditions[i + 1 :])

    return _edit_rule(modes, rng, lambda r: r.conditions, edit)


def _negate_condition(modes, parameters, space, rng):
    def edit(rule):
        i = int(rng.integers(len(rule.conditions)))
        flipped = dataclasses.replace(rule.conditions[i], negated=not rule.conditions[i].negated)
        return dataclasses.replace(rule, conditions=rule.conditions[:i] + (flipped,) + rule.conditions[i + 1 :])

    return _edit_rule(modes, rng, lambda r: r.conditions, edit)


def _add_action(modes, parameters, space, rng):
    return _edit_rule(
        modes, rng, lambda r: len(r.actions) < space.max_actions, lambda r: _with_action(r, random_action(space, rng))
    )


def _remove_action(modes, parameters, space, rng):
    def edit(rule):
        i = int(rng.integers(len(rule.actions)))
        return dataclasses.replace(rule, actions=rule.actions[:i] + rule.actions[i + 1 :])

    return _edit_rule(modes, rng, lambda r: r.actions, edit)


def _replace_action(modes, parameters, space, rng):
    def edit(rule):
        i = int(rng.integers(len(rule.actions)))
        rest = dataclasses.replace(rule, actions=rule.actions[:i] + rule.actions[i + 1 :])
        return _with_action(rest, random_action(space, rng), i)

    return _edit_rule(modes, rng, lambda r: r.actions, edit)


def _change_go(modes, parameters, space, rng):
    return _edit_rule(
        modes, rng, lambda r: True, lambda r: dataclasses.replace(r, go=_pick(rng, (None, *space.task.modes)))
    )


def _change_set(modes, parameters, space, rng):
    def edit(rule):
        return _with_mode_set(rule, None if rule.set and rng.random() < 0.5 else random_mode_set(space, rng))

    return _edit_rule(modes, rng, lambda r: True, edit)


def _numbers(modes, parameters) -> list[tuple]:
    """Every number of a program: ``("parameter", name, kind)`` for a parameter (the kind of its
    first use) and ``("literal", mode, rule, condition, argument, kind)`` for a literal."""
    found, kinds = [], {}
    for mode, rules in modes.items():
        for r, rule in enumerate(rules):
            for c, condition in enumerate(rule.conditions):
                for a, (kind, value) in enumerate(zip(_placeholders(condition.pattern), condition.arguments)):
                    if kind in ("count", "probability", "number"):
                        if isinstance(value, str):
                            kinds.setdefault(value, kind)
                        else:
                            found.append(("literal", mode, r, c, a, kind))
    return found + [("parameter", name, kind) for name, kind in kinds.items() if name in parameters]


def _perturb_number(modes, parameters, space, rng):
    numbers = _numbers(modes, parameters)
    if not numbers:
        return False
    number = _pick(rng, numbers)
    if number[0] == "parameter":
        _, name, kind = number
        parameters[name] = _perturb(parameters[name], kind, rng)
        return True
    _, mode, r, c, a, kind = number
    rule = modes[mode][r]
    condition = rule.conditions[c]
    arguments = list(condition.arguments)
    arguments[a] = _perturb(arguments[a], kind, rng)
    changed = dataclasses.replace(condition, arguments=tuple(arguments))
    modes[mode][r] = dataclasses.replace(rule, conditions=rule.conditions[:c] + (changed,) + rule.conditions[c + 1 :])
    return True


def _add_mode(modes, parameters, space, rng):
    absent = [m for m in space.task.modes if m not in modes]
    if not absent:
        return False
    new = _pick(rng, absent)
    mode, index = _any_rule(modes, rng)
    modes[mode][index] = dataclasses.replace(modes[mode][index], go=new)
    modes[new] = [random_rule(space, rng)]
    return True


def _remove_mode(modes, parameters, space, rng):
    mode = _pick(rng, [m for m in modes if m not in space.start] or [None])
    if mode is None:
        return False
    del modes[mode]
    return True


MUTATIONS = {
    "add rule": _add_rule,
    "remove rule": _remove_rule,
    "replace rule": _replace_rule,
    "swap rules": _swap_rules,
    "add condition": _add_condition,
    "remove condition": _remove_condition,
    "replace condition": _replace_condition,
    "negate condition": _negate_condition,
    "add action": _add_action,
    "remove action": _remove_action,
    "replace action": _replace_action,
    "change go": _change_go,
    "change set": _change_set,
    "perturb number": _perturb_number,
    "add mode": _add_mode,
    "remove mode": _remove_mode,
}
"""The mutations by name: ``fn(modes, parameters, space, rng)`` edits the mutable copies in
place and returns False when it does not apply to the program."""


def mutate(program: Program, space: ProgramSpace, rng: np.random.Generator) -> Program:
    """``program`` with one random mutation of :data:`MUTATIONS` (valid; see the module docstring)."""
    for _ in range(ATTEMPTS):
        modes, parameters = _parts(program)
        if not MUTATIONS[_pick(rng, tuple(MUTATIONS))](modes, parameters, space, rng):
            continue
        try:
            return _finish(program, modes, parameters, space)
        except ConfigError:
            continue
    return program


def crossover(first: Program, second: Program, space: ProgramSpace, rng: np.random.Generator) -> Program:
    """A child of two programs of one task: ``first`` with one mode's rules taken from
    ``second`` (or dropped, when ``second`` has none), or with one mode's rules from a cut
    point on replaced by ``second``'s from another cut point; parameters of both (``first``'s
    value where both name one). Valid; ``first`` when no draw gives a valid child."""
    theirs = dict(second.modes)
    for _ in range(ATTEMPTS):
        modes, parameters = _parts(first)
        parameters = {**dict(second.parameters), **parameters}
        shared = [m for m in modes if m in theirs]
        if shared and rng.random() < 0.5:
            mode = _pick(rng, shared)
            cut, their_cut = int(rng.integers(len(modes[mode]) + 1)), int(rng.integers(len(theirs[mode])))
            modes[mode] = (modes[mode][:cut] + list(theirs[mode][their_cut:]))[: space.max_rules]
        else:
            mode = _pick(rng, sorted(set(modes) | set(theirs)))
            if mode in theirs:
                modes[mode] = list(theirs[mode])
            else:
                del modes[mode]
        try:
            return _finish(first, modes, parameters, space)
        except ConfigError:
            continue
    return first

"""A small language for module controllers built from the paper's primitives.

A program is a finite-state machine that every module runs on its own observation. It has
the task's modes; for each mode an ordered list of rules; the first rule whose conditions all
hold fires: its actions give the module's action this cycle, ``go`` its next mode and ``set``
a mode message to neighbours. A module whose mode has no rule that fires stays, keeps its
mode, relays every scent channel and sends nothing. Programs are YAML text::

    task: chain                  # the task (name) the program is written for
    channels: [scent]            # names of the task's scent channels, in channel order
    start: [SLEEP, SEED]         # the modes modules start in (default: the task's first)
    parameters: {p_random: 0.05} # named numbers a condition may use instead of a literal
    modes:
      SEED:
        - if: [waited 1, neighbour SEARCH at growth]
          do: [emit scent]
          set: SEARCH at growth to SEED
          go: FINAL
        - do: [emit scent, pick growth, tell growth]

Conditions and actions are phrases of :data:`CONDITIONS` and :data:`ACTIONS` (a condition
may start with ``not``); placeholders are filled with a channel name, a mode name, a
direction class of :data:`DIRECTION_CLASSES`, or a number (a literal or a parameter name).
:func:`load_program` reads and checks a program against a task, :func:`format_program`
prints it back (``load_program(format_program(p), task) == p``).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

from proteo_env.config import ConfigError, parse_yaml, read_text
from proteo_env.registry import task_class, task_name

PROGRAMS_DIR = Path(__file__).parent / "programs"
"""Where the paper's behaviours are kept as programs (``chain.yaml`` ...): a program's name is its file's stem."""

CONDITIONS = {
    "detects {channel}": "the module or a face neighbour carries the channel's scent",
    "scent {channel} above {count}": "the module's own scent value is above the count (the scent is weak)",
    "scent {channel} below {count}": "the module's own scent value is below the count (the scent is strong)",
    "neighbour {mode}": "a face neighbour is in the mode",
    "neighbour {mode} at {class}": "a face neighbour in a direction of the class is in the mode",
    "at spot {mode}": "the module is at the growth spot a face neighbour in the mode told (its growth points here)",
    "touching ground": "the module touches the ground (or any solid site)",
    "touching object": "the module touches the object",
    "load above {number}": "the weight the module carries is above the number",
    "load below {number}": "the weight the module carries is below the number",
    "can move": "the module has a legal roll",
    "waited {count}": "the module has been in its mode for at least the count of cycles",
    "sent {count}": "the module has sent at least the count of mode sets (``set``) since it entered its mode",
    "chance {probability}": "true with the probability (one draw)",
}
"""Condition phrases and what each senses (the module's own observation and memory only)."""

ACTIONS = {
    "emit {channel}": "emit the channel's scent (value 0 here)",
    "relay {channel}": "relay the channel's scent (one more than the lowest neighbour)",
    "block {channel}": "neither emit nor relay the channel's scent",
    "move {class}": "a uniformly random legal roll towards a direction of the class (stay if none)",
    "move gradient {channel}": "roll over the faces of the neighbour with the lowest scent (stay when every roll loses it)",
    "move spot {mode}": "roll towards the growth spot of the neighbour in the mode (as it told; stay there)",
    "move around {mode}": "a uniformly random legal roll over the faces of a neighbour in the mode (it stays a neighbour; stay if none)",
    "stay": "no roll",
    "pick growth": "choose the growth direction, an empty face site, unless the module has one",
    "pick level growth": "the same, among the 4 horizontal directions only",
    "pick hint growth": "the same, among the directions at less than 90 degrees to the hint",
    "drop growth": "forget the growth direction (the next pick chooses again)",
    "tell growth": "send the growth direction to every neighbour",
}
"""Action phrases and what each does (one roll, scent roles, one message per cycle)."""

DIRECTION_CLASSES = {
    "any": "all 12 face directions",
    "growth": "the module's growth direction (picked, or the one a mode message came along)",
    "hint": "the directions at less than 90 degrees to the task's hint",
    "down": "the 4 directions pointing down (towards the ground)",
    "up": "the 4 directions pointing up",
    "level": "the 4 horizontal directions",
}
"""Direction classes, relative to the module's growth, the hint and the ground."""

SET_TARGETS = ("growth", "any", "one")
"""Where a rule's ``set`` may send its mode message: the growth direction's neighbour, all
neighbours, or one neighbour in the set's mode (the first the module sees)."""

MOVES = ("move {class}", "move gradient {channel}", "move spot {mode}", "move around {mode}", "stay")
MESSAGES = ("tell growth",)
ROLES = ("emit {channel}", "relay {channel}", "block {channel}")
PROGRAM_KEYS = ("task", "channels", "start", "parameters", "modes")
RULE_KEYS = ("if", "do", "go", "set")
NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
DIRECTION_MESSAGES = 12
"""Message values ``1..12`` carry a direction (``d + 1``); the program's mode sets follow."""


@dataclass(frozen=True)
class Condition:
    """A condition phrase: ``pattern`` (a key of :data:`CONDITIONS`), the values of its
    placeholders in order (``str`` names, ``int``/``float`` literals), and ``negated`` (``not``)."""

    pattern: str
    arguments: tuple = ()
    negated: bool = False

    def __str__(self) -> str:
        return ("not " if self.negated else "") + _fill(self.pattern, self.arguments)


@dataclass(frozen=True)
class Action:
    """An action phrase: ``pattern`` (a key of :data:`ACTIONS`) and the values of its placeholders."""

    pattern: str
    arguments: tuple = ()

    def __str__(self) -> str:
        return _fill(self.pattern, self.arguments)


@dataclass(frozen=True)
class ModeSet:
    """``set: <neighbour_mode> [at growth] to <to>``: a message that sets the neighbours in
    ``neighbour_mode`` (at ``at``, one of :data:`SET_TARGETS`) to mode ``to``."""

    neighbour_mode: str
    at: str
    to: str

    def __str__(self) -> str:
        where = "" if self.at == "any" else f" at {self.at}"
        return f"{self.neighbour_mode}{where} to {self.to}"


@dataclass(frozen=True)
class Rule:
    """``if <conditions> then <actions> [go to mode] [set neighbours' mode]`` (empty conditions: always)."""

    conditions: tuple[Condition, ...] = ()
    actions: tuple[Action, ...] = ()
    go: str | None = None
    set: ModeSet | None = None


@dataclass(frozen=True)
class Program:
    """A module controller for one task.

    Attributes:
        task: the task's name (``"chain"``) or id (``"chain-v1"``).
        channels: names of the task's scent channels used, channel ``c`` is ``channels[c]``.
        start: the modes modules may start in.
        parameters: ``(name, value)`` pairs of named numbers.
        modes: ``(mode name, rules)`` pairs, in the program's order.
    """

    task: str
    channels: tuple[str, ...]
    start: tuple[str, ...]
    parameters: tuple[tuple[str, float], ...]
    modes: tuple[tuple[str, tuple[Rule, ...]], ...]

    def value(self, argument):
        """A number argument's value: the literal, or the named parameter's value."""
        return dict(self.parameters)[argument] if isinstance(argument, str) else argument

    def __deepcopy__(self, memo) -> Program:
        """The program itself: every part of it is frozen (a policy copied per episode shares it)."""
        return self

    @property
    def mode_sets(self) -> tuple[tuple[str, str], ...]:
        """The distinct ``(neighbour_mode, to)`` pairs of the rules' ``set``, in order: pair
        ``j`` travels as message value ``13 + j``."""
        pairs = []
        for _, rules in self.modes:
            for rule in rules:
                if rule.set is not None and (rule.set.neighbour_mode, rule.set.to) not in pairs:
                    pairs.append((rule.set.neighbour_mode, rule.set.to))
        return tuple(pairs)


def _fill(pattern: str, arguments) -> str:
    words = iter(arguments)
    return " ".join(_number_text(next(words)) if w.startswith("{") else w for w in pattern.split())


def _number_text(value) -> str:
    return repr(value) if isinstance(value, float) else str(value)


def format_program(program: Program) -> str:
    """``program`` as YAML text (the form :func:`load_program` reads; comments are not kept)."""
    lines = [f"task: {program.task}", f"channels: [{', '.join(program.channels)}]"]
    lines.append(f"start: [{', '.join(program.start)}]")
    if program.parameters:
        lines.append("parameters:")
        lines += [f"  {name}: {_number_text(value)}" for name, value in program.parameters]
    lines.append("modes:")
    for mode, rules in program.modes:
        lines.append(f"  {mode}:")
        for rule in rules:
            fields = []
            if rule.conditions:
                fields.append(f"if: [{', '.join(map(str, rule.conditions))}]")
            fields.append(f"do: [{', '.join(map(str, rule.actions))}]")
            if rule.set is not None:
                fields.append(f"set: {rule.set}")
            if rule.go is not None:
                fields.append(f"go: {rule.go}")
            lines.append(f"    - {fields[0]}")
            lines += [f"      {f}" for f in fields[1:]]
    return "\n".join(lines) + "\n"


def load_program(source, env_or_task) -> Program:
    """The program in ``source``, checked against a task.

    Args:
        source: YAML text (several lines), a path to a YAML file, or the name of a program in
            ``baselines/programs/`` (``"chain"``).
        env_or_task: an environment (``env.task`` is used), a task instance or class, or a task id.

    Raises:
        ConfigError: one error naming the line and field, the value and what is allowed: an
            unknown key, primitive (phrase), mode, channel, direction class or parameter; a
            mode that no rule reaches from ``start``; more channels than the task has; a
            program for another task; a probability outside [0, 1]; two rolls, two messages
            or two roles of one channel in one rule; more mode sets than message values.
    """
    task = getattr(env_or_task, "task", env_or_task)
    task = task_class(task) if isinstance(task, str) else task
    text, where = _read(source)
    return _Loader(text, where, task).program()


def _read(source) -> tuple[str, str]:
    """``(text, where)`` of ``source``: program text, a file path, or a program name."""
    if isinstance(source, str) and "\n" in source:
        return source, "program text"
    path = Path(source)
    if not path.suffix and not path.is_file():
        path = PROGRAMS_DIR / f"{source}.yaml"
    if not path.is_file():
        names = ", ".join(sorted(p.stem for p in PROGRAMS_DIR.glob("*.yaml")))
        raise ConfigError(
            f"program {str(source)!r} does not exist; allowed: program text, a path to a YAML file, "
            f"or a program name ({names})"
        )
    return read_text(path, "program"), f"program {str(path)!r}"


def _line_numbers(text: str) -> dict[tuple, int]:
    """The 1-based line of every node of the YAML ``text``, by its path of keys and indices."""
    import yaml

    lines: dict[tuple, int] = {}

    def walk(node, path):
        lines[path] = node.start_mark.line + 1
        if isinstance(node, yaml.MappingNode):
            for key, value in node.value:
                walk(value, path + (key.value,))
        elif isinstance(node, yaml.SequenceNode):
            for index, item in enumerate(node.value):
                walk(item, path + (index,))

    try:  # the parser that read the program (libyaml where PyYAML has it: its own parser refuses some texts libyaml reads)
        root = yaml.compose(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except yaml.YAMLError:
        return lines  # no line numbers, the error all the same
    if root is not None:
        walk(root, ())
    return lines


class _Loader:
    """Reads one program's YAML data into a :class:`Program`, checking every field against ``task``."""

    def __init__(self, text: str, where: str, task):
        self.data = parse_yaml(text, where)
        self.text = text
        self.where = where
        self.task = task
        self.channels: tuple[str, ...] = ()
        self.parameters: dict[str, float] = {}

    def fail(self, path: tuple, value, allowed: str, why: str = ""):
        lines = _line_numbers(self.text)  # read again only to name the line of an error
        line = next((lines[path[:n]] for n in range(len(path), -1, -1) if path[:n] in lines), None)
        field = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path).lstrip(".") or "the program"
        at = f", line {line}" if line is not None else ""
        because = f" ({why})" if why else ""
        raise ConfigError(f"{self.where}{at}, {field}: {value!r} is not allowed{because}; allowed: {allowed}")

    def program(self) -> Program:
        data = self.data
        if not isinstance(data, dict):
            self.fail((), data, f"a mapping with the keys {', '.join(PROGRAM_KEYS)}")
        for key in data:
            if key not in PROGRAM_KEYS:
                self.fail((key,), key, f"the keys {', '.join(PROGRAM_KEYS)}", "unknown key")
        task = data.get("task")
        if not isinstance(task, str) or task_name(task) != self.task.name:
            self.fail(
                ("task",), task, f"{self.task.name!r}, the task the program runs on", "a program for another task"
            )
        self.channels = tuple(self.names(("channels",), data.get("channels", [])))
        if len(self.channels) > self.task.n_channels:
            self.fail(
                ("channels",),
                list(self.channels),
                f"at most {self.task.n_channels} channel names",
                "the task has fewer",
            )
        self.parameters = self.read_parameters(data.get("parameters", {}))
        start = tuple(self.mode(("start", n), m) for n, m in enumerate(self.names(("start",), data.get("start", []))))
        modes_data = data.get("modes")
        if not isinstance(modes_data, dict) or not modes_data:
            self.fail(("modes",), modes_data, "a mapping from mode names to lists of rules")
        modes = tuple(
            (self.mode(("modes", name), name), self.rules(("modes", name), rules)) for name, rules in modes_data.items()
        )
        program = Program(task, self.channels, start or (self.task.modes[0],), tuple(self.parameters.items()), modes)
        self.check_reachable(program)
        self.check_messages(program)
        return program

    def names(self, path, value) -> list[str]:
        if not isinstance(value, list) or not all(isinstance(v, str) and NAME.match(v) for v in value):
            self.fail(path, value, "a list of names such as [scent]")
        return value

    def read_parameters(self, value) -> dict[str, float]:
        path = ("parameters",)
        if not isinstance(value, dict):
            self.fail(path, value, "a mapping from names to numbers such as {p_random: 0.05}")
        for name, number in value.items():
            if not (isinstance(name, str) and NAME.match(name)):
                self.fail(path + (name,), name, "a name (letters, digits, _)")
            if isinstance(number, bool) or not isinstance(number, (int, float)) or not math.isfinite(number):
                self.fail(path + (name,), number, "a finite number")
        return dict(value)

    def mode(self, path, name):
        if name not in self.task.modes:
            self.fail(path, name, f"the modes of {self.task.name}: {', '.join(self.task.modes)}", "unknown mode")
        return name

    def rules(self, path, value) -> tuple[Rule, ...]:
        if not isinstance(value, list) or not value:
            self.fail(path, value, "a list of rules, each a mapping with the keys if, do, go, set")
        return tuple(self.rule(path + (n,), item) for n, item in enumerate(value))

    def rule(self, path, value) -> Rule:
        if not isinstance(value, dict):
            self.fail(path, value, f"a mapping with the keys {', '.join(RULE_KEYS)}")
        for key in value:
            if key not in RULE_KEYS:
                self.fail(path + (key,), key, f"the keys {', '.join(RULE_KEYS)}", "unknown key")
        conditions = tuple(
            self.phrase(path + ("if", n), text, CONDITIONS, Condition)
            for n, text in enumerate(self.phrases(path + ("if",), value.get("if", [])))
        )
        actions = tuple(
            self.phrase(path + ("do", n), text, ACTIONS, Action)
            for n, text in enumerate(self.phrases(path + ("do",), value.get("do", [])))
        )
        go = self.mode(path + ("go",), value["go"]) if "go" in value else None
        mode_set = self.mode_set(path + ("set",), value["set"]) if "set" in value else None
        self.check_rule(path, actions, mode_set)
        return Rule(conditions, actions, go, mode_set)

    def phrases(self, path, value) -> list[str]:
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            self.fail(path, value, "a list of phrases such as [detects scent, chance 0.5]")
        return value

    def phrase(self, path, text: str, table: dict, cls):
        words = text.split()
        negated = cls is Condition and words[:1] == ["not"]
        words = words[1:] if negated else words
        for pattern in table:
            shape = pattern.split()
            if len(shape) == len(words) and all(s.startswith("{") or s == w for s, w in zip(shape, words)):
                arguments = tuple(
                    self.argument(path, text, s[1:-1], w) for s, w in zip(shape, words) if s.startswith("{")
                )
                return cls(pattern, arguments, negated) if cls is Condition else cls(pattern, arguments)
        kind = "condition" if cls is Condition else "action"
        self.fail(path, text, " | ".join(table), f"unknown {kind}")

    def argument(self, path, text, kind: str, word: str):
        if kind == "channel":
            if word not in self.channels:
                self.fail(
                    path, text, f"the program's channels: {', '.join(self.channels) or 'none'}", "unknown channel"
                )
            return word
        if kind == "mode":
            return self.mode(path, word)
        if kind == "class":
            if word not in DIRECTION_CLASSES:
                self.fail(path, text, f"the direction classes {', '.join(DIRECTION_CLASSES)}", "unknown class")
            return word
        value = _number(word)
        if value is None and word not in self.parameters:
            self.fail(path, text, f"a number or a parameter: {', '.join(self.parameters) or 'none'}", "unknown number")
        number = self.parameters.get(word, value)
        if kind == "probability" and not 0.0 <= number <= 1.0:
            self.fail(path, text, "a probability in [0, 1]", f"{word} = {number}")
        if kind == "count" and not (float(number).is_integer() and number >= 0):
            self.fail(path, text, "a whole number >= 0", f"{word} = {number}")
        return word if value is None else value

    def mode_set(self, path, text) -> ModeSet:
        words = str(text).split()
        shapes = {3: "{mode} to {mode}", 5: "{mode} at {target} to {mode}"}
        if len(words) not in shapes or words[-2] != "to" or (len(words) == 5 and words[1] != "at"):
            self.fail(path, text, " | ".join(shapes.values()))
        at = words[2] if len(words) == 5 else "any"
        if at not in SET_TARGETS:
            self.fail(path, text, f"the targets {', '.join(SET_TARGETS)}", "unknown target")
        return ModeSet(self.mode(path, words[0]), at, self.mode(path, words[-1]))

    def check_rule(self, path, actions, mode_set) -> None:
        """At most one roll, one message and one role per channel in a rule."""
        moves = [str(a) for a in actions if a.pattern in MOVES]
        messages = [str(a) for a in actions if a.pattern in MESSAGES] + ([f"set {mode_set}"] if mode_set else [])
        roles = [a.arguments[0] for a in actions if a.pattern in ROLES]
        for what, found in (("roll", moves), ("message", messages)):
            if len(found) > 1:
                self.fail(path, found, f"one {what} a cycle per rule")
        twice = sorted({c for c in roles if roles.count(c) > 1})
        if twice:
            self.fail(path + ("do",), twice, "one role (emit, relay, block) per channel per rule")

    def check_reachable(self, program: Program) -> None:
        """Every mode with rules is a start mode or the ``go`` or ``set`` target of a reachable mode's rule."""
        rules = dict(program.modes)
        reached, todo = set(program.start), list(program.start)
        while todo:
            for rule in rules.get(todo.pop(), ()):
                for mode in (rule.go, rule.set and rule.set.to):
                    if mode and mode not in reached:
                        reached.add(mode)
                        todo.append(mode)
        for mode in rules:
            if mode not in reached:
                self.fail(
                    ("modes", mode),
                    mode,
                    f"the modes reached from start: {', '.join(sorted(reached))}",
                    "no rule reaches it",
                )

    def check_messages(self, program: Program) -> None:
        """Direction messages and one value per mode set fit the task's message values."""
        need = DIRECTION_MESSAGES + len(program.mode_sets)
        if need > self.task.n_message_values:
            pairs = [f"{a} to {b}" for a, b in program.mode_sets]
            self.fail(
                ("modes",),
                pairs,
                f"at most {self.task.n_message_values - DIRECTION_MESSAGES} distinct mode sets",
                f"the task's messages carry {self.task.n_message_values} values, 12 go to directions",
            )


def _number(word: str):
    """``word`` as an int or a finite float, or None when it is no number (``nan`` and ``inf`` are not)."""
    for kind in (int, float):
        try:
            value = kind(word)
        except ValueError:
            continue
        return value if math.isfinite(value) else None
    return None

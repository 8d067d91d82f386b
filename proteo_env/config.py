"""Typed, frozen configs; YAML only at the edge.

:func:`build` turns a plain mapping into a frozen dataclass, rejecting unknown keys and values
of the wrong type with one message that names the field, the value and what is allowed.
A run config file is flat YAML: ``task: chain-v0`` plus any overrides that
:func:`proteo_env.make` accepts, for example::

    task: chain-v0
    n_modules: 50
    motion_model: sphere
    max_cycles: 3000
"""

from __future__ import annotations

import dataclasses
import math
import typing
from pathlib import Path

import numpy as np

from .core.world import Physics

CONTROL_LEVELS = ("move", "move+mode", "full")
"""The control levels (:mod:`proteo_env.control`), from the easiest to learn to the hardest."""


class ConfigError(ValueError):
    """A config value or key that is not allowed (the message names field, value and allowed)."""


def check_seed(seed, name: str = "seed"):
    """``seed`` as a Python int or a :class:`numpy.random.SeedSequence` (``None`` passes
    through); a :class:`ConfigError` naming ``name`` and the value unless it is ``None``, an
    integer >= 0 (NumPy integers included, bools not) or a ``SeedSequence``."""
    if seed is None or isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(
            f"{name}={seed!r} is not allowed; allowed: None or an integer >= 0, or a numpy.random.SeedSequence"
        )
    return int(seed)


def world_seeds(seed, n_worlds: int) -> list[np.random.SeedSequence]:
    """The seed sequences of ``n_worlds`` worlds started from one ``seed`` (an integer >= 0 or a
    :class:`numpy.random.SeedSequence`): world ``b`` gets child ``b`` of ``SeedSequence(seed)``,
    as NumPy's ``spawn`` makes it. Children of different seeds, and different children of one
    seed, are independent streams; the first ``k`` children do not depend on ``n_worlds``, and
    none is the stream of a plain integer seed (``reset(seed=s)`` of a single env)."""
    root = check_seed(seed)
    if not isinstance(root, np.random.SeedSequence):
        root = np.random.SeedSequence(root)
    return [np.random.SeedSequence(root.entropy, spawn_key=(*root.spawn_key, b)) for b in range(n_worlds)]


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """Environment settings shared by every task.

    Attributes:
        max_cycles: cycle limit; reaching it sets ``truncated``.
        obs_radius: 1 (12 neighbour sites) or 2 (54 sites) in observations.
        control: the control level, ``"move"``, ``"move+mode"`` or ``"full"``: which action
            fields the agent chooses (:mod:`proteo_env.control`).
        physics: :class:`~proteo_env.core.world.Physics` (motion model, connectivity, scents).
    """

    max_cycles: int = 1000
    obs_radius: int = 1
    control: str = "full"
    physics: Physics = dataclasses.field(default_factory=Physics)

    def __post_init__(self):
        if self.max_cycles < 1:
            raise ConfigError(f"max_cycles={self.max_cycles!r} is not allowed; allowed: an integer >= 1")
        if self.obs_radius not in (1, 2):
            raise ConfigError(f"obs_radius={self.obs_radius!r} is not allowed; allowed: 1 or 2")
        if self.control not in CONTROL_LEVELS:
            raise ConfigError(
                f"control={self.control!r} is not allowed; allowed: {', '.join(map(repr, CONTROL_LEVELS))}"
            )


ENV_KEYS = tuple(f.name for f in dataclasses.fields(EnvConfig) if f.name != "physics")
PHYSICS_KEYS = tuple(f.name for f in dataclasses.fields(Physics))


def _type_ok(value, annotation) -> bool:
    origin = typing.get_origin(annotation)
    if origin is typing.Union or origin is getattr(__import__("types"), "UnionType", None):
        return any(_type_ok(value, a) for a in typing.get_args(annotation))
    if annotation is type(None):
        return value is None
    if origin is tuple:
        return isinstance(value, (tuple, list))
    if annotation is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if annotation is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if isinstance(annotation, type):
        return isinstance(value, annotation)
    return True


def build(cls, values: dict, *, where: str = ""):
    """Build dataclass ``cls`` from ``values``; unknown keys and wrong types raise :class:`ConfigError`."""
    fields = {f.name: f for f in dataclasses.fields(cls)}
    hints = typing.get_type_hints(cls)
    for key, value in values.items():
        if key not in fields:
            raise ConfigError(f"{where}unknown key {key!r}; allowed: {', '.join(sorted(fields))}")
        if not _type_ok(value, hints[key]):
            raise ConfigError(
                f"{where}{key}={value!r} is not allowed; allowed: a value of type "
                f"{getattr(hints[key], '__name__', hints[key])}"
            )
        numbers = value if isinstance(value, tuple | list) else (value,)
        if any(isinstance(v, float) and not math.isfinite(v) for v in numbers):
            raise ConfigError(f"{where}{key}={value!r} is not allowed; allowed: finite numbers (no nan or inf)")
        if typing.get_origin(hints[key]) is tuple and isinstance(value, list):
            values = {**values, key: tuple(value)}
    try:
        return cls(**values)
    except ConfigError:
        raise
    except ValueError as err:
        raise ConfigError(f"{where}{err}") from None


def split_overrides(overrides: dict, task_params_cls, *, task_name: str):
    """Split flat overrides into an :class:`EnvConfig` and the task's params dataclass."""
    task_keys = {f.name for f in dataclasses.fields(task_params_cls)}
    allowed = sorted(set(ENV_KEYS) | set(PHYSICS_KEYS) | task_keys)
    unknown = [k for k in overrides if k not in allowed]
    if unknown:
        raise ConfigError(f"unknown key {unknown[0]!r} for task {task_name!r}; allowed: {', '.join(allowed)}")
    physics = build(Physics, {k: v for k, v in overrides.items() if k in PHYSICS_KEYS})
    env = build(EnvConfig, {k: v for k, v in overrides.items() if k in ENV_KEYS})
    env = dataclasses.replace(env, physics=physics)
    params = build(
        task_params_cls, {k: v for k, v in overrides.items() if k in task_keys}, where=f"task {task_name!r}: "
    )
    return env, params


MAX_YAML_DEPTH = 32
"""The deepest nesting of mappings and lists :func:`parse_yaml` reads: four times the deepest file in
the repository (a benchmark protocol, 8), far below what would exhaust the parser's stack."""


def parse_yaml(text: str, where: str):
    """The YAML value of ``text``; a :class:`ConfigError` that starts with ``where`` (what the text
    is: a file, a flag), names the line and says what is wrong, instead of the parser's traceback:
    broken syntax, a key given twice in one mapping (the later one would silently win), an anchor
    or alias (``&name``/``*name``: what YAML bombs are made of; no file here needs one), or nesting
    deeper than :data:`MAX_YAML_DEPTH`.

    Parsed by libyaml where PyYAML has it (ten times faster: evolution parses every new
    program); text it rejects is parsed again by PyYAML's own parser, whose messages name the
    problem more plainly."""
    import yaml

    def refuse(problem: str, mark, allowed: str) -> ConfigError:
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        return ConfigError(f"{where} is not allowed{at}: {problem}; allowed: {allowed}")

    fast = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    try:
        _check_yaml_events(yaml.parse(text, Loader=fast), refuse)
        return yaml.load(text, Loader=_strict_loader(fast))
    except yaml.YAMLError:
        pass
    try:
        _check_yaml_events(yaml.parse(text, Loader=yaml.SafeLoader), refuse)
        return yaml.load(text, Loader=_strict_loader(yaml.SafeLoader))
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(err, "problem", None) or str(err)
        if problem.startswith("found duplicate key"):
            raise refuse(problem, mark, "each key once in a mapping") from None
        raise ConfigError(
            f"{where} is not valid YAML{at} ({problem}); allowed: YAML such as 'key: value' lines or {{key: value}}"
        ) from None


def _check_yaml_events(events, refuse) -> None:
    """Walk the parser's events (no recursion, whatever the depth): a :class:`ConfigError` at the
    first anchor, alias or nesting past :data:`MAX_YAML_DEPTH`."""
    import yaml

    depth = 0
    for event in events:
        if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None) is not None:
            raise refuse("an anchor or alias (&name, *name)", event.start_mark, "YAML without anchors and aliases")
        if isinstance(event, yaml.MappingStartEvent | yaml.SequenceStartEvent):
            depth += 1
            if depth > MAX_YAML_DEPTH:
                raise refuse(
                    f"mappings and lists nested {depth} deep", event.start_mark, f"at most {MAX_YAML_DEPTH} levels"
                )
        elif isinstance(event, yaml.MappingEndEvent | yaml.SequenceEndEvent):
            depth -= 1


_STRICT_LOADERS: dict = {}


def _strict_loader(base):
    """``base`` (a PyYAML safe loader class) that refuses a key given twice in one mapping."""
    if base not in _STRICT_LOADERS:
        import yaml

        class Strict(base):
            def construct_mapping(self, node, deep=False):
                seen = set()
                for key_node, _ in node.value:
                    key = self.construct_object(key_node, deep=True)
                    if not isinstance(key, str | int | float | bool):
                        continue  # an unhashable key: the base constructor names it
                    if key in seen:
                        raise yaml.constructor.ConstructorError(
                            "while reading a mapping",
                            node.start_mark,
                            f"found duplicate key {key!r}",
                            key_node.start_mark,
                        )
                    seen.add(key)
                return super().construct_mapping(node, deep=deep)

        _STRICT_LOADERS[base] = Strict
    return _STRICT_LOADERS[base]


def load_yaml(path, what: str = "config file", example: str = "a path to a YAML file"):
    """The YAML document in file ``path``: the one loader of every file the project reads (run,
    training, eval, sweep and entrant configs, protocols, programs). A :class:`ConfigError` names
    ``what`` and the path when the file is missing, is not UTF-8 text, or its YAML is malformed or
    refused (:func:`parse_yaml`; with the line and column)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{what} {str(path)!r} does not exist; allowed: {example}")
    return parse_yaml(read_text(path, what), f"{what} {str(path)!r}")


def read_text(path, what: str) -> str:
    """The UTF-8 text of file ``path``; a :class:`ConfigError` naming ``what``, the path and the
    first byte that is not UTF-8 otherwise."""
    try:
        return Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        raise ConfigError(
            f"{what} {str(path)!r} is not allowed: byte {err.start} is not UTF-8 text; allowed: a UTF-8 YAML file"
        ) from None


def load_run_config(path) -> tuple[str, dict]:
    """Read a flat YAML run config; return ``(task_id, overrides)``."""
    data = load_yaml(path)
    path = Path(path)
    if not isinstance(data, dict) or "task" not in data:
        raise ConfigError(f"config file {str(path)!r}: a mapping with a 'task' key is required")
    data = dict(data)
    return str(data.pop("task")), data

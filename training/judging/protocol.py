"""The benchmark protocol: what is judged, on which worlds (``configs/benchmark/<version>.yaml``).

A protocol is one YAML file per version, ``configs/benchmark/<version>.yaml`` (``v1.yaml`` is
the first; a published version is never changed, a new one is a new file; ``v2.yaml`` extends
v1, see :func:`load_protocol`). It fixes, for each task of the study: the task version judged
(``task``) and the versions whose checkpoints are judged on it (``trained_on``), the control
levels judged (``levels``: ``learned``, ``rules``, ``random``, and optionally ``evolved``), the training settings (``env``), the training recipes (``recipes``: a config in
``configs/train`` and a budget in agent-steps) and the evaluation splits (``splits``: each its
settings over ``env``; ``heldout``, the training size, and ``larger``, about twice the size, in
every task, then the out-of-distribution variants the task has parameters for). ``worlds``
fixes how many worlds a policy is judged on per split: the rules and random on ``reference``
worlds, a learned or evolved recipe on ``per_training_seed`` worlds for each of at least
``training_seeds`` training seeds; every policy takes the world seeds ``first_seed``,
``first_seed + 1``, ... (one judged on fewer worlds takes the first ones). :func:`load_protocol`
reads and checks a file; any bad input (a version that does not exist, an unknown key anywhere,
a value of the wrong kind, fewer worlds or training seeds than the protocol's statistics need)
is one :class:`~proteo_env.config.ConfigError` naming the field, the value and what is allowed.

The judge that runs a protocol is :mod:`training.judging.judge` (``proteo eval --benchmark``).
"""

from __future__ import annotations

import difflib
import hashlib
from dataclasses import dataclass
from pathlib import Path

from proteo_env.config import CONTROL_LEVELS, ConfigError, load_yaml, split_overrides
from proteo_env.registry import TASKS

ROOT = Path(__file__).resolve().parents[2]
"""The repository: protocol files and recipe configs are read relative to it."""
PROTOCOL_DIR = "configs/benchmark"
"""Where the protocol files are: ``<version>.yaml``."""

MIN_REFERENCE_WORLDS = 100
"""The rules and random are judged on at least this many worlds per split (a success rate then
known to about +-0.05 or better: the widest 95 % Wilson interval at 100 worlds, at 50/100, is
0.40-0.60, +-0.10 wide in all, +-0.05 ... +-0.10 from the middle; within +-0.05 from 90/100 on)."""
MIN_WORLDS_PER_TRAINING_SEED = 20
"""A learned or evolved recipe is judged on at least this many worlds per training seed and split."""
MIN_TRAINING_SEEDS = 5
"""A learned or evolved recipe is judged with at least this many training seeds."""
MIN_SPLIT_REFERENCE_WORLDS = 20
"""A split that takes fewer worlds than the protocol's (a split of large worlds, ``worlds`` in its
entry) judges the rules and random on at least this many: a success rate known to +-0.22 at
worst (the 95 % Wilson interval at 10/20 is 0.30-0.70), to +-0.09 from 18/20 on."""
MIN_SPLIT_WORLDS_PER_TRAINING_SEED = 5
"""Such a split judges a learned or evolved recipe on at least this many worlds per training seed:
with ten training seeds, 50 episodes (the pooled 95 % Wilson interval at 25/50 is 0.36-0.64)."""

PROTOCOL_KEYS = ("version", "worlds", "equivalence_margin", "tasks")
EXTENSION_KEYS = ("version", "extends", "tasks")
"""The keys of a protocol that extends another: it only adds levels and recipes to its tasks."""
WORLDS_KEYS = ("first_seed", "reference", "per_training_seed", "training_seeds")
TASK_KEYS = ("task", "trained_on", "levels", "env", "recipes", "splits")
EXTENSION_TASK_KEYS = ("levels", "recipes", "splits")
LEVEL_KEYS = ("learned", "rules", "random")
OPTIONAL_LEVEL_KEYS = ("evolved",)
"""``evolved``: the levels evolved controllers are judged at (without it: ``learned``'s)."""
RECIPE_KEYS = ("config", "agent_steps", "init")
SPLIT_KEYS = ("about", "env", "worlds")
SPLIT_WORLDS_KEYS = ("reference", "per_training_seed")
"""A split's own world counts (fewer than the protocol's, for splits of large worlds)."""
REQUIRED_SPLITS = ("heldout", "larger")
REFERENCE_POLICIES = ("rules", "random")
"""The names ``--policy`` takes: the task's hand-coded rules, and the random policy."""


@dataclass(frozen=True)
class Split:
    """One evaluation split of a task: its name and the ``proteo_env.make`` settings of its worlds."""

    name: str
    about: str
    env: dict
    worlds: dict | None = None
    """``{"reference", "per_training_seed"}``: this split's own world counts, fewer than the
    protocol's (a split of large worlds); ``None``: the protocol's."""


@dataclass(frozen=True)
class TaskProtocol:
    """What a protocol fixes for one task."""

    name: str
    task_id: str
    trained_on: tuple
    levels: dict
    """``{"learned": [...], "rules": [...], "random": [...], "evolved": [...]}``: the control levels
    judged (``evolved`` defaults to ``learned``'s)."""
    env: dict
    recipes: dict
    splits: tuple
    """The :class:`Split` s, in the file's order."""


@dataclass(frozen=True)
class Protocol:
    """A benchmark protocol version (:func:`load_protocol`)."""

    version: str
    path: Path
    sha256: str
    """Of this version's file (see ``lineage`` for the files it extends)."""
    lineage: tuple
    """``((version, sha256), ...)``: the versions this one extends, oldest first, then itself.
    A result judged under an earlier version of the lineage holds under this one: an extension
    only adds levels and recipes."""
    first_seed: int
    reference: int
    per_training_seed: int
    training_seeds: int
    tasks: dict
    """``{task name: TaskProtocol}``."""
    equivalence_margin: float | None = None
    """The margin within which a controller's success rate "matches" the rules' on the same worlds
    (two one-sided tests, :func:`training.judging.statistics.equivalence`); ``None``: no "matches" claim."""

    def world_seeds(self, n: int) -> list[int]:
        """The first ``n`` world seeds: every policy judged on ``n`` worlds gets these."""
        return list(range(self.first_seed, self.first_seed + n))

    def worlds(self, kind: str, cap: int | None = None, split: Split | None = None) -> int:
        """Worlds of ``split`` (per training seed for a learned or evolved policy) for ``kind``:
        the split's own count where it has one, else the protocol's; at most ``cap`` (quick
        checks only)."""
        counts = (split.worlds if split is not None else None) or {
            "reference": self.reference,
            "per_training_seed": self.per_training_seed,
        }
        n = counts["reference"] if kind in ("hand-coded", "random") else counts["per_training_seed"]
        return n if cap is None else min(n, cap)


def versions(root=None) -> list[str]:
    """The protocol versions present: the names of ``configs/benchmark/*.yaml``."""
    folder = Path(root or ROOT) / PROTOCOL_DIR
    return sorted(p.stem for p in folder.glob("*.yaml"))


def _unknown(where: str, keys, allowed) -> None:
    bad = [k for k in keys if k not in allowed]
    if bad:
        close = difflib.get_close_matches(str(bad[0]), [str(a) for a in allowed], n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ConfigError(
            f"{where}: unknown key {bad[0]!r}{hint} = {keys[bad[0]]!r} is not allowed; allowed keys: {', '.join(allowed)}"
        )


def _mapping(where: str, field_path: str, value, allowed) -> dict:
    value = {} if value is None else value
    if not isinstance(value, dict):
        raise ConfigError(
            f"{where}: {field_path} = {value!r} is not allowed; allowed: a mapping with keys {', '.join(allowed)}"
        )
    return value


def _integer(where: str, field_path: str, value, least: int, why: str = "") -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < least:
        raise ConfigError(
            f"{where}: {field_path} = {value!r} is not allowed; allowed: an integer >= {least}{f' ({why})' if why else ''}"
        )
    return value


def _settings(where: str, at: str, field_path: str, value, cls) -> dict:
    """``value`` checked as ``proteo_env.make`` settings of task class ``cls`` (no ``control``)."""
    value = _mapping(where, field_path, value, ["proteo_env.make settings"])
    try:
        split_overrides(value, cls.Params, task_name=cls.task_id())
    except (ValueError, TypeError) as err:
        raise ConfigError(f"{where}: {field_path} = {value!r} is not allowed: {err}") from None
    if "control" in value:
        raise ConfigError(
            f"{where}: {field_path}.control = {value['control']!r} is not allowed; allowed: the levels "
            f"under {at}.levels (settings without control)"
        )
    return dict(value)


def _split_worlds(where: str, field_path: str, value, counts: dict) -> dict | None:
    """A split's own world counts, checked: each at least its minimum
    (:data:`MIN_SPLIT_REFERENCE_WORLDS`, :data:`MIN_SPLIT_WORLDS_PER_TRAINING_SEED`) and at most the
    protocol's; ``None`` without them."""
    if value is None:
        return None
    value = _mapping(where, field_path, value, SPLIT_WORLDS_KEYS)
    _unknown(f"{where}: {field_path}", value, SPLIT_WORLDS_KEYS)
    least = {"reference": MIN_SPLIT_REFERENCE_WORLDS, "per_training_seed": MIN_SPLIT_WORLDS_PER_TRAINING_SEED}
    own = {}
    for key in SPLIT_WORLDS_KEYS:
        n = value.get(key)
        if isinstance(n, bool) or not isinstance(n, int) or not least[key] <= n <= counts[key]:
            raise ConfigError(
                f"{where}: {field_path}.{key} = {n!r} is not allowed; allowed: an integer from {least[key]} to "
                f"{counts[key]} (the protocol's worlds.{key}: a split of large worlds may take fewer, not more)"
            )
        own[key] = n
    return own


def _protocol_data(version: str, root: Path, children: tuple) -> tuple[dict, tuple]:
    """The checked top level of ``<version>.yaml`` with the protocols it extends merged in, and
    its lineage (:attr:`Protocol.lineage`). ``children``: the versions that extend it (a cycle
    is an error)."""
    present = versions(root)
    if not isinstance(version, str) or version not in present:
        field_path = f"{PROTOCOL_DIR}/{children[-1]}.yaml: extends" if children else "--benchmark"
        raise ConfigError(
            f"{field_path} {version!r} is not allowed: no protocol file {PROTOCOL_DIR}/{version}.yaml; "
            f"allowed: {', '.join(v for v in present if v not in children) or 'none present'}"
        )
    if version in children:
        raise ConfigError(
            f"benchmark {PROTOCOL_DIR}/{children[-1]}.yaml: extends = {version!r} is not allowed: a cycle "
            f"({' -> '.join([*children, version])}); allowed: an earlier version"
        )
    path = root / PROTOCOL_DIR / f"{version}.yaml"
    where = f"benchmark {PROTOCOL_DIR}/{version}.yaml"
    sha = hashlib.sha256(path.read_bytes()).hexdigest()
    data = load_yaml(path, "benchmark protocol", f"one of {', '.join(present)}")
    allowed = EXTENSION_KEYS if isinstance(data, dict) and "extends" in data else PROTOCOL_KEYS
    data = _mapping(where, "top level", data, allowed)
    _unknown(f"{where}: top level", data, allowed)
    if data.get("version") != version:
        raise ConfigError(
            f"{where}: version = {data.get('version')!r} is not allowed; allowed: {version!r} (the file's name)"
        )
    if "extends" not in data:
        return data, ((version, sha),)
    parent, lineage = _protocol_data(data["extends"], root, (*children, version))
    merged = {**parent, "version": version, "tasks": {k: dict(v) for k, v in parent["tasks"].items()}}
    tasks = _mapping(where, "tasks", data.get("tasks"), list(parent["tasks"]))
    _unknown(f"{where}: tasks", tasks, list(parent["tasks"]))
    for name, entry in tasks.items():
        at = f"tasks.{name}"
        entry = _mapping(where, at, entry, EXTENSION_TASK_KEYS)
        _unknown(f"{where}: {at} (an extension only adds levels, recipes and splits)", entry, EXTENSION_TASK_KEYS)
        into = merged["tasks"][name]
        for key in EXTENSION_TASK_KEYS:
            added = _mapping(where, f"{at}.{key}", entry.get(key), ["new names"])
            before = dict(into.get(key) or {})
            again = [k for k in added if k in before]
            if again:
                raise ConfigError(
                    f"{where}: {at}.{key}.{again[0]} = {added[again[0]]!r} is not allowed: {data['extends']} "
                    f"already fixes it; allowed: {key} that {data['extends']} does not have"
                )
            into[key] = {**before, **added}
    return merged, (*lineage, (version, sha))


def load_protocol(version: str, root=None) -> Protocol:
    """The protocol ``configs/benchmark/<version>.yaml``, checked.

    Bad input is one :class:`ConfigError` naming the field (its path in the file), the value and
    what is allowed: a version with no file (the message lists the versions present), a file
    whose ``version`` is not its name, an unknown key anywhere, a task name that is not
    registered, a task version that is not one of the name's, a control level that does not
    exist, settings a task does not have or does not allow, a recipe config that does not exist,
    a protocol without a ``heldout`` or ``larger`` split, and fewer worlds or training seeds than
    :data:`MIN_REFERENCE_WORLDS`, :data:`MIN_WORLDS_PER_TRAINING_SEED` and
    :data:`MIN_TRAINING_SEEDS`.

    A file with ``extends: <earlier version>`` holds only what it adds to that version: new
    levels (``evolved``), new recipes and new splits of its tasks; changing anything the earlier
    version fixes (worlds, settings, a level, recipe or split it has) is an error, so every result
    judged under the earlier version holds under this one (:attr:`Protocol.lineage`).

    A split may take fewer worlds than the protocol (``worlds: {reference, per_training_seed}``
    in its entry, for splits of large worlds), at least :data:`MIN_SPLIT_REFERENCE_WORLDS` and
    :data:`MIN_SPLIT_WORLDS_PER_TRAINING_SEED`.
    """
    root = Path(root or ROOT)
    data, lineage = _protocol_data(version, root, ())
    where = f"benchmark {PROTOCOL_DIR}/{version}.yaml"
    worlds = _mapping(where, "worlds", data.get("worlds"), WORLDS_KEYS)
    _unknown(f"{where}: worlds", worlds, WORLDS_KEYS)
    least = {
        "first_seed": (0, ""),
        "reference": (MIN_REFERENCE_WORLDS, "the rules and random: a success rate known to about +-0.05"),
        "per_training_seed": (MIN_WORLDS_PER_TRAINING_SEED, "worlds per training seed of a learned recipe"),
        "training_seeds": (MIN_TRAINING_SEEDS, "training seeds of a learned recipe"),
    }
    counts = {}
    for key in WORLDS_KEYS:
        if key not in worlds:
            raise ConfigError(f"{where}: worlds.{key} is missing; allowed: an integer >= {least[key][0]}")
        counts[key] = _integer(where, f"worlds.{key}", worlds[key], *least[key])

    margin = data.get("equivalence_margin")
    if margin is not None and (
        not isinstance(margin, (int, float)) or isinstance(margin, bool) or not 0.0 < margin < 1.0
    ):
        raise ConfigError(
            f"{where}: equivalence_margin = {margin!r} is not allowed; allowed: a success-rate difference "
            "between 0 and 1 (0.05: within five points), or no key (no equivalence claims)"
        )

    tasks_raw = data.get("tasks")
    names = sorted({cls.name for cls in TASKS.values()} - {"sandbox"})
    tasks_raw = _mapping(where, "tasks", tasks_raw, names)
    if not tasks_raw:
        raise ConfigError(
            f"{where}: tasks = {tasks_raw!r} is not allowed; allowed: a mapping of task names ({', '.join(names)})"
        )
    _unknown(f"{where}: tasks", tasks_raw, names)
    tasks = {}
    for name, entry in tasks_raw.items():
        at = f"tasks.{name}"
        entry = _mapping(where, at, entry, TASK_KEYS)
        _unknown(f"{where}: {at}", entry, TASK_KEYS)
        ids = sorted(tid for tid, cls in TASKS.items() if cls.name == name)
        task_id = entry.get("task")
        if task_id not in ids:
            raise ConfigError(f"{where}: {at}.task = {task_id!r} is not allowed; allowed: {', '.join(ids)}")
        trained_on = entry.get("trained_on", [task_id])
        if not isinstance(trained_on, list) or task_id not in trained_on or any(t not in ids for t in trained_on):
            raise ConfigError(
                f"{where}: {at}.trained_on = {trained_on!r} is not allowed; allowed: a list of versions of "
                f"{name} ({', '.join(ids)}) that holds {task_id!r}"
            )
        levels = _mapping(where, f"{at}.levels", entry.get("levels"), LEVEL_KEYS + OPTIONAL_LEVEL_KEYS)
        _unknown(f"{where}: {at}.levels", levels, LEVEL_KEYS + OPTIONAL_LEVEL_KEYS)
        levels.setdefault("evolved", levels.get("learned"))
        for key in LEVEL_KEYS + OPTIONAL_LEVEL_KEYS:
            value = levels.get(key)
            if not isinstance(value, list) or not value or any(v not in CONTROL_LEVELS for v in value):
                raise ConfigError(
                    f"{where}: {at}.levels.{key} = {value!r} is not allowed; allowed: a list of control levels "
                    f"({', '.join(CONTROL_LEVELS)})"
                )
        cls = TASKS[task_id]

        env = _settings(where, at, f"{at}.env", entry.get("env"), cls)
        recipes_raw = _mapping(where, f"{at}.recipes", entry.get("recipes"), RECIPE_KEYS)
        recipes = {}
        for label, recipe in recipes_raw.items():
            rat = f"{at}.recipes.{label}"
            recipe = _mapping(where, rat, recipe, RECIPE_KEYS)
            _unknown(f"{where}: {rat}", recipe, RECIPE_KEYS)
            config = recipe.get("config")
            if not isinstance(config, str) or not (root / config).is_file():
                raise ConfigError(
                    f"{where}: {rat}.config = {config!r} is not allowed; allowed: a file in configs/train"
                )
            steps = recipe.get("agent_steps")
            if steps is not None:
                _integer(where, f"{rat}.agent_steps", steps, 1, "or null: the config's own budget")
            init = recipe.get("init")
            if init is not None and init not in recipes_raw:
                raise ConfigError(
                    f"{where}: {rat}.init = {init!r} is not allowed; allowed: one of {', '.join(recipes_raw)}"
                )
            recipes[str(label)] = {"config": config, "agent_steps": steps, "init": init}
        splits_raw = _mapping(where, f"{at}.splits", entry.get("splits"), SPLIT_KEYS)
        for required in REQUIRED_SPLITS:
            if required not in splits_raw:
                raise ConfigError(
                    f"{where}: {at}.splits = {sorted(splits_raw)!r} is not allowed; allowed: splits that include "
                    f"{', '.join(REQUIRED_SPLITS)}"
                )
        splits = []
        for split, spec in splits_raw.items():
            sat = f"{at}.splits.{split}"
            spec = _mapping(where, sat, spec, SPLIT_KEYS)
            _unknown(f"{where}: {sat}", spec, SPLIT_KEYS)
            about = spec.get("about", "")
            if not isinstance(about, str):
                raise ConfigError(f"{where}: {sat}.about = {about!r} is not allowed; allowed: a string")
            merged = _settings(where, at, f"{sat}.env", {**env, **(spec.get("env") or {})}, cls)
            own = _split_worlds(where, f"{sat}.worlds", spec.get("worlds"), counts)
            splits.append(Split(name=str(split), about=about, env=merged, worlds=own))
        tasks[name] = TaskProtocol(
            name=name,
            task_id=task_id,
            trained_on=tuple(trained_on),
            levels={k: list(levels[k]) for k in LEVEL_KEYS + OPTIONAL_LEVEL_KEYS},
            env=env,
            recipes=recipes,
            splits=tuple(splits),
        )
    return Protocol(
        version=version,
        path=root / PROTOCOL_DIR / f"{version}.yaml",
        sha256=lineage[-1][1],
        lineage=lineage,
        first_seed=counts["first_seed"],
        reference=counts["reference"],
        per_training_seed=counts["per_training_seed"],
        training_seeds=counts["training_seeds"],
        tasks=tasks,
        equivalence_margin=None if margin is None else float(margin),
    )

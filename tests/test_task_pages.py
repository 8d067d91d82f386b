"""Every registered task has one contract, its page ``docs/tasks/<name>.md``: the page exists,
the task's module docstring is a short summary that points to it, and the page names every
registered version of the task, every metric the task reports and every parameter it takes."""

from __future__ import annotations

import dataclasses
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import SMALL_OVERRIDES

import proteo_env

ROOT = Path(__file__).resolve().parents[1]
MAX_DOCSTRING_LINES = 12


def task_classes() -> dict[str, list[type]]:
    """The registered task classes by task name (every version of it)."""
    by_name: dict[str, list[type]] = {}
    for cls in proteo_env.TASKS.values():
        by_name.setdefault(cls.name, []).append(cls)
    return by_name


TASK_NAMES = sorted(task_classes())


def page(name: str) -> Path:
    return ROOT / "docs" / "tasks" / f"{name}.md"


def page_text(name: str) -> str:
    return page(name).read_text()


def metric_names(task_id: str) -> set[str]:
    """The metric names of one step's info of a small env of ``task_id`` (first agent's info,
    ``metric/`` stripped), after a step in which every agent stays (move 0, always legal)."""
    cls = proteo_env.TASKS[task_id]
    env = proteo_env.make(task_id, **SMALL_OVERRIDES.get(cls.name, {}))
    env.reset(seed=0)
    actions = {agent: np.zeros(len(env.action_space(agent).nvec), dtype=np.int64) for agent in env.agents}
    _, _, _, _, infos = env.step(actions)
    info = infos[next(iter(infos))]
    return {key.removeprefix("metric/") for key in info if key.startswith("metric/")}


def named_in(text: str, name: str) -> bool:
    """``name`` appears in the page as a whole word; a metric with an index suffix
    (``restabilise_0``) also counts when its family (``restabilise_k``, ``restabilise_0 ..``)
    is named, i.e. its prefix followed by ``_``."""
    if re.search(rf"(?<![\w/]){re.escape(name)}(?!\w)", text):
        return True
    family = re.fullmatch(r"(.+)_\d+", name)
    return bool(family) and re.search(rf"(?<![\w/]){re.escape(family.group(1))}_", text) is not None


@pytest.mark.parametrize("name", TASK_NAMES)
def test_the_page_exists(name):
    assert page(name).is_file(), f"task {name!r} has no page docs/tasks/{name}.md"


@pytest.mark.parametrize("name", TASK_NAMES)
def test_the_module_docstring_is_a_summary_that_points_to_the_page(name):
    for cls in task_classes()[name]:
        doc = sys.modules[cls.__module__].__doc__ or ""
        assert f"docs/tasks/{name}.md" in doc, f"{cls.__module__}'s docstring does not name docs/tasks/{name}.md"
        lines = doc.strip().splitlines()
        assert len(lines) <= MAX_DOCSTRING_LINES, (
            f"{cls.__module__}'s docstring has {len(lines)} lines; allowed: at most {MAX_DOCSTRING_LINES}"
        )


@pytest.mark.parametrize("name", TASK_NAMES)
def test_the_page_names_every_version(name):
    text = page_text(name)
    missing = sorted(cls.task_id() for cls in task_classes()[name] if cls.task_id() not in text)
    assert not missing, f"docs/tasks/{name}.md does not name {missing}"


def unnamed(name: str, names_of) -> dict:
    """``{task id: names the page of task ``name`` does not name}`` over its versions, ``names_of(cls)``
    giving a version's names."""
    text = page_text(name)
    missing = {}
    for cls in task_classes()[name]:
        absent = sorted(n for n in names_of(cls) if not named_in(text, n))
        if absent:
            missing[cls.task_id()] = absent
    return missing


@pytest.mark.parametrize("name", TASK_NAMES)
def test_the_page_names_every_metric(name):
    missing = unnamed(name, lambda cls: metric_names(cls.task_id()))
    assert not missing, f"docs/tasks/{name}.md does not name these metrics: {missing}"


@pytest.mark.parametrize("name", TASK_NAMES)
def test_the_page_names_every_parameter(name):
    missing = unnamed(name, lambda cls: [f.name for f in dataclasses.fields(cls.Params)])
    assert not missing, f"docs/tasks/{name}.md does not name these parameters: {missing}"

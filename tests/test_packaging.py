"""pyproject.toml declares compatible ranges; constraints.txt pins the exact versions tested."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[1]


def normalise(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def requirements() -> list[str]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return list(project["dependencies"]) + [r for extra in project["optional-dependencies"].values() for r in extra]


def test_the_package_declares_ranges_and_constraints_pin_every_package_it_names():
    pins = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        if line and not line.startswith("#"):
            name, version = line.split("==")
            pins[normalise(name)] = version
    for text in requirements():
        requirement = Requirement(text)
        name = normalise(requirement.name)
        assert "==" not in text, f"{text!r} is an exact pin; pyproject.toml declares ranges"
        assert name in pins, f"{name} is not pinned in constraints.txt"
        assert requirement.specifier.contains(pins[name]), f"constraints.txt's {name}=={pins[name]} is not in {text!r}"

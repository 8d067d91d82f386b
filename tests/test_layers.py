"""Dependencies run one way: ``proteo_env/core`` <- ``proteo_env`` <- ``baselines`` <- ``training``.

Reads every import statement (module level and inside functions) of the four layers with
``ast`` and fails on one that reaches a layer above its own.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("proteo_env.core", "proteo_env", "baselines", "training")
"""From the bottom up; a module may import its own layer and the ones below."""


def layer(module: str) -> int | None:
    """The index in :data:`LAYERS` of a dotted module name of the project (None: outside it)."""
    for k in reversed(range(len(LAYERS))):
        if module == LAYERS[k] or module.startswith(LAYERS[k] + "."):
            return 0 if module.startswith("proteo_env.core") else k
    return None


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> list[tuple[int, str]]:
    """``(line, absolute module)`` of every import in ``path`` (relative imports resolved)."""
    here = module_name(path)
    package = here if path.name == "__init__.py" else here.rsplit(".", 1)[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")
                parent = parent[: len(parent) - (node.level - 1)]
                base = ".".join(parent + ([base] if base else []))
            found.append((node.lineno, base))
    return found


def project_files():
    for top in ("proteo_env", "baselines", "training"):
        yield from sorted((ROOT / top).rglob("*.py"))


def test_layer_of_a_module_and_relative_imports(tmp_path):
    assert layer("proteo_env.core.world") == 0 and layer("proteo_env.core") == 0
    assert layer("proteo_env.env") == 1 and layer("proteo_env") == 1 and layer("proteo_env_x") is None
    assert layer("baselines.chain") == 2 and layer("training.cli") == 3 and layer("numpy") is None
    found = dict((name, line) for line, name in imports(ROOT / "proteo_env" / "tasks" / "chain.py"))
    assert "proteo_env.core.structure" in found and "proteo_env.tasks.base" in found


@pytest.mark.parametrize("path", list(project_files()), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_module_imports_a_layer_above_its_own(path):
    own = layer(module_name(path))
    above = [f"{path.relative_to(ROOT)}:{line} imports {name}" for line, name in imports(path)
             if layer(name) is not None and layer(name) > own]
    assert not above, "dependencies must run core <- proteo_env <- baselines <- training: " + "; ".join(above)

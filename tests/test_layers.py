"""Dependencies run one way: ``proteo_env/core`` <- ``proteo_env`` <- ``baselines`` <- ``training``,
and no two project modules import each other, directly or through others.

Reads every import statement (module level and inside functions) of the four layers with
``ast``; fails on one that reaches a layer above its own, and on a cycle in the graph of
imports between project modules.
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


def import_statements(path: Path) -> list[tuple[ast.stmt, str]]:
    """``(statement, absolute module)`` of every ``import``/``from .. import`` in ``path``; the
    module is that of a ``from`` statement (relative ones resolved), empty for ``import``."""
    here = module_name(path)
    package = here if path.name == "__init__.py" else here.rsplit(".", 1)[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.append((node, ""))
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")
                parent = parent[: len(parent) - (node.level - 1)]
                base = ".".join(parent + ([base] if base else []))
            found.append((node, base))
    return found


def imports(path: Path) -> list[tuple[int, str]]:
    """``(line, absolute module)`` of every import in ``path`` (relative imports resolved)."""
    found = []
    for node, base in import_statements(path):
        found += (
            [(node.lineno, alias.name) for alias in node.names]
            if isinstance(node, ast.Import)
            else [(node.lineno, base)]
        )
    return found


def project_files():
    for top in ("proteo_env", "baselines", "training"):
        yield from sorted((ROOT / top).rglob("*.py"))


def import_graph() -> dict[str, set[str]]:
    """The project modules each project module imports (``from package import submodule``
    counts as importing the submodule, not the package)."""
    modules = {module_name(path): path for path in project_files()}
    graph = {}
    for name, path in modules.items():
        targets = set()
        for node, base in import_statements(path):
            if isinstance(node, ast.Import):
                targets.update(alias.name for alias in node.names if alias.name in modules)
                continue
            subs = [f"{base}.{alias.name}" for alias in node.names if f"{base}.{alias.name}" in modules]
            targets.update(subs)
            if len(subs) < len(node.names) and base in modules:
                targets.add(base)
        graph[name] = targets - {name}
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle ``[a, b, .., a]`` through each group of modules that import each other
    (Tarjan's strongly connected components of ``graph``)."""
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.add(w)
                if w == v:
                    break
            if len(group) > 1:
                cycles.append(path_within(graph, group, v))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return cycles


def path_within(graph, group, start) -> list[str]:
    """A shortest cycle from ``start`` back to it through modules of ``group``."""
    previous, frontier = {start: None}, [start]
    while frontier:
        following = []
        for v in frontier:
            for w in sorted(graph[v] & group):
                if w == start:
                    path = [v]
                    while previous[path[-1]] is not None:
                        path.append(previous[path[-1]])
                    return path[::-1] + [start]
                if w not in previous:
                    previous[w] = v
                    following.append(w)
        frontier = following
    return [start]


def test_layer_of_a_module_and_relative_imports(tmp_path):
    assert layer("proteo_env.core.world") == 0 and layer("proteo_env.core") == 0
    assert layer("proteo_env.env") == 1 and layer("proteo_env") == 1 and layer("proteo_env_x") is None
    assert layer("baselines.chain") == 2 and layer("training.cli") == 3 and layer("numpy") is None
    found = dict((name, line) for line, name in imports(ROOT / "proteo_env" / "tasks" / "chain.py"))
    assert "proteo_env.core.structure" in found and "proteo_env.tasks.base" in found


@pytest.mark.parametrize("path", list(project_files()), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_module_imports_a_layer_above_its_own(path):
    own = layer(module_name(path))
    above = [
        f"{path.relative_to(ROOT)}:{line} imports {name}"
        for line, name in imports(path)
        if layer(name) is not None and layer(name) > own
    ]
    assert not above, "dependencies must run core <- proteo_env <- baselines <- training: " + "; ".join(above)


def test_cycles_are_found_and_reported():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert import_cycles(graph) == [["a", "b", "c", "a"]]
    assert import_cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles_between_project_modules():
    cycles = import_cycles(import_graph())
    assert not cycles, "project modules must not import each other: " + "; ".join(" -> ".join(c) for c in cycles)


ROOMS = ("training.machinery", "training.judging", "training.trainers")
"""The rooms of ``training/`` from the bottom up (the command line, playback and sweeps stand above
them all): the trainers use judging and the machinery, judging uses the machinery, and the
machinery neither."""


def room(module: str) -> int:
    """The index in :data:`ROOMS` of a module of ``training/`` (``len(ROOMS)``: the command line's floor)."""
    for k, name in enumerate(ROOMS):
        if module == name or module.startswith(name + "."):
            return k
    return len(ROOMS)


@pytest.mark.parametrize("path", sorted((ROOT / "training").rglob("*.py")), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_module_of_training_imports_a_room_above_its_own(path):
    own = room(module_name(path))
    above = [
        f"{path.relative_to(ROOT)}:{line} imports {name}"
        for line, name in imports(path)
        if name.startswith("training") and name != "training" and room(name) > own
    ]
    assert not above, "training/'s rooms run machinery <- judging <- trainers <- the command line: " + "; ".join(above)


def test_rooms_of_training():
    assert room("training.machinery.checkpoints") == 0 and room("training.judging.judge") == 1
    assert room("training.trainers.ppo") == 2 and room("training.cli") == room("training.playback") == 3


LAZY_PACKAGES = (
    "benchmarl", "cma", "gymnasium", "matplotlib", "numba", "onnxruntime", "ray", "sb3_contrib", "scipy",
    "stable_baselines3", "tensordict", "torch", "torchrl", "tqdm",
)  # fmt: skip
"""The optional or heavy packages that ``training/`` imports where it uses them, not at the top of a
module: so that ``proteo --help`` and the judge of the rules start without torch, a trainer's module
loads without Ray, and a missing extra is an error only where it is needed. A module of the project
that loads one of them at import (the engine, through numba; the networks, through torch) is
imported where used by a module that would not load it otherwise."""


def top_level_imports(path: Path) -> list[str]:
    """The absolute modules ``path`` imports outside any function (``from P import m`` of a
    project package counts as importing ``P.m``)."""
    modules = {module_name(p) for p in project_files()}
    inside = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            inside.update(sub.lineno for sub in ast.walk(node) if isinstance(sub, (ast.Import, ast.ImportFrom)))
    found = []
    for node, base in import_statements(path):
        if node.lineno in inside:
            continue
        if isinstance(node, ast.Import):
            found += [alias.name for alias in node.names]
        else:
            subs = [f"{base}.{alias.name}" for alias in node.names if f"{base}.{alias.name}" in modules]
            found += subs if len(subs) == len(node.names) else [base, *subs]
    return found


def lazy_packages_loaded() -> dict[str, set[str]]:
    """For each project module, the :data:`LAZY_PACKAGES` that importing it loads (through the
    imports at the top of it and of the project modules it imports so)."""
    paths = {module_name(p): p for p in project_files()}
    direct = {name: top_level_imports(path) for name, path in paths.items()}

    def parents(module):  # importing a.b.c runs a/__init__ and a/b/__init__ first
        parts = module.split(".")
        return [".".join(parts[:k]) for k in range(1, len(parts) + 1)]

    def closure(name):  # every project module that importing ``name`` runs: its packages, itself and what they import
        reached = {module for module in parents(name) if module in paths}
        frontier = list(reached)
        while frontier:
            for target in direct[frontier.pop()]:
                for module in parents(target):
                    if module in paths and module not in reached:
                        reached.add(module)
                        frontier.append(module)
        return reached

    lazy = {
        name: {t.split(".")[0] for t in targets if t.split(".")[0] in LAZY_PACKAGES} for name, targets in direct.items()
    }
    return {name: set().union(*(lazy[m] for m in closure(name))) for name in paths}


def test_imports_stand_at_the_top_but_those_of_lazy_packages():
    loaded = lazy_packages_loaded()
    assert {"numba"} <= loaded["proteo_env.core.world"] and "torch" in loaded["training.machinery.networks"]
    assert not loaded["training.cli"] and not loaded["training.machinery.registry"]
    misplaced = []
    for path in sorted((ROOT / "training").rglob("*.py")):
        here = module_name(path)
        tree = ast.parse(path.read_text())
        guarded = {id(sub) for node in ast.walk(tree) if isinstance(node, ast.Try) for sub in ast.walk(node)}
        for node in ast.walk(tree):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for sub in ast.walk(node):
                if sub is node or not isinstance(sub, (ast.Import, ast.ImportFrom)) or id(sub) in guarded:
                    continue
                names = [a.name for a in sub.names] if isinstance(sub, ast.Import) else [sub.module or ""]
                if isinstance(sub, ast.ImportFrom) and sub.module and f"{sub.module}.{sub.names[0].name}" in loaded:
                    names = [f"{sub.module}.{a.name}" for a in sub.names]
                needs = set()
                for name in names:
                    if name.split(".")[0] in LAZY_PACKAGES:
                        needs.add(name.split(".")[0])
                    needs |= loaded.get(name, set())
                if not needs - loaded[here]:
                    misplaced.append(f"{path.relative_to(ROOT)}:{sub.lineno} {', '.join(names)}")
    assert not misplaced, "imports inside functions that could stand at the top: " + "; ".join(misplaced)

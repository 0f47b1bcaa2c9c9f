"""Imports run one way: no module of the package imports its caller.

The graph of ``fem_anim`` modules is read from every ``import`` statement, at module level
and inside functions (lazy imports count: a cycle through one is still a cycle), and must
have no cycle; the command line is imported by nobody but ``__main__``.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: package folder -> dotted package name (pyproject.toml's package-dir)
PACKAGES = {ROOT / "fem_anim": "fem_anim", ROOT / "forms": "fem_anim.forms",
            ROOT / "meshes": "fem_anim.meshes"}


def module_name(path: Path) -> str:
    for folder, package in PACKAGES.items():
        if path.is_relative_to(folder):
            parts = list(path.relative_to(folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            return ".".join([package, *parts])
    raise ValueError(path)


def imports_of(path: Path, name: str, known: set[str]) -> set[str]:
    """The package modules ``path`` (module ``name``) imports."""
    is_package = path.name == "__init__.py"
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")[: len(name.split(".")) - node.level + is_package]
                stem = ".".join(base + ([node.module] if node.module else []))
            else:
                stem = node.module or ""
            targets = [stem] + [f"{stem}.{a.name}" for a in node.names]
        else:
            continue
        out.update(t for t in targets if t in known and t != name)
    return out


def import_graph() -> dict[str, set[str]]:
    files = {module_name(p): p for folder in PACKAGES for p in folder.rglob("*.py")
             if "__pycache__" not in p.parts and "data" not in p.relative_to(folder).parts}
    known = set(files)
    return {name: imports_of(path, name, known) for name, path in files.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def test_the_package_imports_run_one_way():
    graph = import_graph()
    assert len(graph) > 40 and graph["fem_anim.simulation.loop"]  # the graph is really read
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_only_main_imports_the_command_line():
    graph = import_graph()
    callers = sorted(m for m, deps in graph.items() if "fem_anim.cli" in deps)
    assert callers == ["fem_anim.__main__"]


def test_the_check_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_every_package_folder_is_installed():
    """pyproject.toml lists every folder of the package (a folder left out is missing from a
    non-editable install, although an editable one still finds it)."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
                 ["packages"])
    folders = {module_name(init) for folder in PACKAGES for init in folder.rglob("__init__.py")
               if "__pycache__" not in init.parts}
    assert folders == listed


def test_no_two_modules_share_a_name():
    """One name, one module: a file name says which module it is anywhere in the package."""
    names = [p.name for folder in PACKAGES for p in folder.rglob("*.py")
             if "__pycache__" not in p.parts and "data" not in p.relative_to(folder).parts
             and p.name != "__init__.py"]
    assert sorted({n for n in names if names.count(n) > 1}) == []

"""The core's layout: packages follow the data flow, no import cycle, imports at the top.

The import graph is read from the source (every ``import`` statement, also those inside
functions), so a new cycle or a backward import fails here before it confuses anyone.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

CORE = Path(__file__).resolve().parents[1] / "core"

#: Layers in data-flow order: a module may import its own layer and the layers before it.
LAYERS = ["__init__", "errors", "files", "resources", "jit", "physics", "scene", "render", "output",
          "progress", "runner", "warmup", "farm", "cli"]

#: Imports allowed inside functions: optional or heavy libraries used by one code path.
LAZY_IMPORTS = {
    "distributed": "Dask, only for --scheduler/--workers (seconds to import)",
    "trimesh": "meshes from .ply/.obj/.stl files, only when a job has one",
    "colour": "colour-science, only to regenerate the embedded CIE tables",
    "numba": "core/__init__: after the BLAS thread pins, before numpy loads",
    "resource": "the Unix rlimits (the module does not exist on Windows)",
}


def module_name(path: Path) -> str:
    rel = path.relative_to(CORE).with_suffix("")
    parts = [p for p in rel.parts if p != "__init__"]
    return ".".join(parts) or "__init__"


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(CORE.rglob("*.py"))}


def resolve(importer: str, path: Path, node: ast.ImportFrom) -> list[str]:
    """Core modules named by a relative ``from`` import in ``importer`` (core-relative)."""
    if node.level == 0:
        mod = node.module or ""
        if not mod.startswith("relray.core"):
            return []
        base = mod[len("relray.core"):].lstrip(".")
    else:
        pkg = module_name(path).split(".") if path.name == "__init__.py" else \
            module_name(path).split(".")[:-1]
        if pkg == ["__init__"]:
            pkg = []
        up = node.level - 1
        if up > len(pkg):
            return []  # above the core (relray's __version__)
        base = ".".join(pkg[:len(pkg) - up] + ([node.module] if node.module else []))
    known = modules()
    out = []
    for alias in node.names:
        full = f"{base}.{alias.name}" if base else alias.name
        if full in known:
            out.append(full)
        elif base in known or base == "":
            out.append(base or "__init__")
    return out


def import_graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for name, path in modules().items():
        deps: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom):
                deps.update(d for d in resolve(name, path, node) if d != name)
        graph[name] = deps
    return graph


def layer(module: str) -> int:
    return LAYERS.index(module.split(".")[0])


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n: str) -> list[str] | None:
        state[n] = 1
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == 1:
                return stack[stack.index(m):] + [m]
            if m not in state and (c := visit(m)):
                return c
        state[n] = 2
        stack.pop()
        return None

    for n in sorted(graph):
        if n not in state and (c := visit(n)):
            return c
    return None


def test_the_graph_sees_the_known_edges():
    """The parser finds real edges (so the checks below cannot pass on an empty graph)."""
    g = import_graph()
    assert "physics.relativity" in g["render.camera"]
    assert "scene.description" in g["scene.gltf"]
    assert "__init__" in g["physics.sigmoid"]          # from .. import user_cache_dir
    assert len(g) >= 30 and sum(map(len, g.values())) >= 60


def test_no_import_cycle_in_core():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_a_cycle_is_found_when_there_is_one():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


@pytest.mark.parametrize("module", sorted(modules()))
def test_imports_follow_the_data_flow(module):
    backward = [d for d in import_graph()[module] if layer(d) > layer(module)]
    assert not backward, f"core.{module} imports later layers: {backward} (see LAYERS)"


@pytest.mark.parametrize("module", sorted(modules()))
def test_imports_are_at_the_top(module):
    """Function-level imports hide the graph; only LAZY_IMPORTS may be deferred."""
    tree = ast.parse(modules()[module].read_text())
    top = set(map(id, tree.body))
    lazy = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import | ast.ImportFrom) and id(node) not in top:
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or "."]
            if getattr(node, "level", 0) or any(n.split(".")[0] not in LAZY_IMPORTS for n in names):
                lazy.append(f"line {node.lineno}: {ast.unparse(node)}")
    assert not lazy, f"core.{module} imports inside functions: {lazy}"


def test_no_bpy_in_core():
    for name, path in modules().items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import | ast.ImportFrom):
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                    [node.module or ""]
                assert not any(n.split(".")[0] in ("bpy", "relblend") for n in names), name


def test_each_package_says_what_it_owns_and_may_import():
    for pkg in ("physics", "scene", "render", "output"):
        doc = ast.get_docstring(ast.parse((CORE / pkg / "__init__.py").read_text())) or ""
        assert "Owns" in doc and "May import" in doc, pkg

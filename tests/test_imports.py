"""No import circles: among pinsettle's modules, and among the benchmark scripts.

The graphs are read from the source with ``ast`` (nothing is imported), counting the imports
inside functions too: a circle hidden in a function is still a circle.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "python" / "pinsettle"
BENCHMARKS = ROOT / "benchmarks"

Graph = dict[str, set[str]]


def _package_target(name: str, modules: set[str]) -> str:
    """The module of the package that ``name`` (dotted, relative to the package; '' for the
    package itself) stands for: its first part if that is a module, else ``__init__``."""
    first = name.split(".")[0]
    return first if first in modules else "__init__"


def package_graph(folder: Path, package: str = "pinsettle") -> Graph:
    """Module -> the package's modules it imports: ``from . import x``, ``from .x import y``,
    ``import pinsettle.x``, ``from pinsettle.x import y``, and ``importlib.import_module``
    with a literal name; at any depth of the file."""
    modules = {p.stem for p in folder.glob("*.py")} | {p.stem for p in folder.glob("*.pyi")}
    graph: Graph = {}
    for path in sorted(folder.glob("*.py")):
        edges: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            names: list[str] = []
            if isinstance(node, ast.ImportFrom):
                if node.level > 1:
                    raise AssertionError(f"{path.name}: import from a parent package: unexpected")
                if node.level == 1:
                    base = node.module or ""
                elif node.module == package or (node.module or "").startswith(package + "."):
                    base = node.module[len(package) + 1 :] if node.module != package else ""
                else:
                    continue
                if base:
                    names.append(base)
                else:  # from . import a, b: each is a module, or a name of __init__
                    names += [alias.name for alias in node.names]
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name == package:
                        names.append("")
                    elif alias.name.startswith(package + "."):
                        names.append(alias.name[len(package) + 1 :])
            elif (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Attribute)
                and node.func.attr == "import_module"
                and node.args
                and isinstance(node.args[0], ast.Constant)
                and isinstance(node.args[0].value, str)
            ):
                name = node.args[0].value
                if name.startswith("."):
                    names.append(name.lstrip("."))
                elif name == package or name.startswith(package + "."):
                    names.append(name[len(package) + 1 :] if name != package else "")
            edges |= {_package_target(name, modules) for name in names}
        edges.discard(path.stem)
        graph[path.stem] = edges
    return graph


def scripts_graph(folder: Path) -> Graph:
    """Script -> the scripts of the same folder it imports (``import x``, ``from x import y``),
    the folder being on sys.path as the benchmarks put it."""
    scripts = {p.stem for p in folder.glob("*.py")}
    graph: Graph = {}
    for path in sorted(folder.glob("*.py")):
        edges: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Import):
                edges |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                edges.add(node.module.split(".")[0])
        graph[path.stem] = (edges & scripts) - {path.stem}
    return graph


def find_cycle(graph: Graph) -> list[str] | None:
    """A circle of the graph as a path that ends where it starts, or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt) :] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def assert_acyclic(graph: Graph, what: str) -> None:
    cycle = find_cycle(graph)
    assert cycle is None, f"import circle in {what}: {' -> '.join(cycle or [])}"


# --- the checker itself ------------------------------------------------------------------------


def test_find_cycle_names_the_circle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    with pytest.raises(AssertionError, match=r"import circle in x: a -> b -> a"):
        assert_acyclic({"a": {"b"}, "b": {"a"}}, "x")


def test_package_graph_sees_imports_inside_functions(tmp_path):
    (tmp_path / "__init__.py").write_text("from .a import f\n")
    (tmp_path / "a.py").write_text("def f():\n    from . import b\n    return b\n")
    (tmp_path / "b.py").write_text("import pinsettle.c\n")
    (tmp_path / "c.py").write_text(
        "import importlib\n\ndef g():\n    from pinsettle.a import f\n"
        "    return importlib.import_module('.b', __name__)\n"
    )
    graph = package_graph(tmp_path)
    assert graph == {"__init__": {"a"}, "a": {"b"}, "b": {"c"}, "c": {"a", "b"}}
    assert find_cycle(graph) == ["a", "b", "c", "a"]


def test_scripts_graph_sees_imports_inside_functions(tmp_path):
    (tmp_path / "report.py").write_text("import numpy\n\ndef main():\n    import writer\n")
    (tmp_path / "writer.py").write_text("import report as R\n")
    graph = scripts_graph(tmp_path)
    assert graph == {"report": {"writer"}, "writer": {"report"}}
    assert find_cycle(graph) == ["report", "writer", "report"]


# --- the project ---------------------------------------------------------------------------------


def test_pinsettle_has_no_import_circle():
    graph = package_graph(PACKAGE)
    assert {"_core", "_checks", "_settings", "_scene"} <= graph["_solve"]  # the parse sees them
    assert_acyclic(graph, "python/pinsettle")


def test_pinsettle_layers():
    """The shared helpers sit at the bottom: everything may use them, they use nothing above."""
    graph = package_graph(PACKAGE)
    assert graph["_checks"] == set()
    assert graph["_settings"] <= {"_core", "_checks"}
    # Reading a URDF's <mimic> tags is a leaf too (the standard library only): robots uses it to
    # say which tags a bare model leaves out.
    assert graph["_urdf_mimic"] == set()
    assert graph["robots"] <= {"_checks", "_urdf_mimic"} and graph["scenes"] <= {"_checks"}
    assert "_solve" not in graph["_scene"]


def test_benchmark_scripts_have_no_import_circle():
    graph = scripts_graph(BENCHMARKS)
    assert "report_writer" in graph["report"]
    assert "report" not in graph["report_writer"]
    assert_acyclic(graph, "benchmarks")

"""No import cycles inside ``robot`` and ``vision``, deferred imports included.

A cycle that "works" because one side imports lazily (as ``robot.trajectory`` and
``robot.trajectory_cartesian`` once did through a module ``__getattr__``) still ties two
modules together: neither can be understood, tested or moved alone.  Every ``import`` and
``from ... import`` is an edge, wherever it sits (module level or inside a function);
imports under ``if TYPE_CHECKING:`` are annotations only and do not count.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _modules(package: str) -> dict[str, Path]:
    mods = {}
    for path in (ROOT / package).rglob("*.py"):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        mods[".".join(parts)] = path
    return mods


def _is_type_checking(node: ast.If) -> bool:
    t = node.test
    return (isinstance(t, ast.Name) and t.id == "TYPE_CHECKING") or (
        isinstance(t, ast.Attribute) and t.attr == "TYPE_CHECKING"
    )


def _imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import | ast.ImportFrom):
            found.append(node)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return found


def _graph(mods: dict[str, Path]) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for name, path in mods.items():
        for node in _imports(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                graph[name].update(a.name for a in node.names if a.name in mods)
            elif node.level == 0 and node.module in mods:
                for a in node.names:
                    sub = f"{node.module}.{a.name}"
                    graph[name].add(sub if sub in mods else node.module)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_cycle_finder_finds_a_lazy_cycle():
    graph = {"a": {"b"}, "b": {"a"}, "c": {"a"}}
    assert _cycles(graph) == [["a", "b"]]


@pytest.mark.parametrize("package", ["robot", "vision"])
def test_no_import_cycle(package):
    assert _cycles(_graph(_modules(package))) == []


def _reaches(graph: dict[str, set[str]], start: str, prefix: str) -> list[str]:
    """The modules under ``prefix`` that ``start`` imports, directly or through others
    (a path to each, for the message)."""
    seen, todo, found = {start: [start]}, [start], []
    while todo:
        v = todo.pop()
        for w in sorted(graph.get(v, ())):
            if w in seen:
                continue
            seen[w] = [*seen[v], w]
            if w == prefix or w.startswith(prefix + "."):
                found.append(" -> ".join(seen[w]))
            todo.append(w)
    return found


def test_reaches_follows_imports_through_other_modules():
    graph = {"a": {"b"}, "b": {"p.x"}, "p.x": set(), "c": set()}
    assert _reaches(graph, "a", "p") == ["a -> b -> p.x"]
    assert _reaches(graph, "c", "p") == []


@pytest.mark.parametrize(
    ("start", "other"),
    [
        ("backend.recognition.teach", "backend.inspection"),
        ("backend.inspection.service", "backend.recognition.teach"),
    ],
)
def test_teach_and_inspect_do_not_import_each_other(start, other):
    """Both stand on the planning layer (``backend.planning``), not on each other."""
    graph = _graph(_modules("backend"))
    assert _reaches(graph, start, other) == []

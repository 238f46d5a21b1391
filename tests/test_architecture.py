"""Imports between the packages of psg_data follow the data flow (docs/ARCHITECTURE.md).

raw -> convert -> canonical -> label -> estimate -> evaluate -> report: a package may import
packages of a lower layer and of its own, never of a higher one, and the imports between packages
form no cycle (two packages of one layer may not import each other, directly or through others).
Imports only for type checking (``if TYPE_CHECKING:``) do not count.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "psg_data"

LAYERS = [
    {"errors", "_cpus", "_pool", "_executors", "_geometry", "_settings", "_fetch", "open3d_import",
     "__version__"},  # foundations
    {"schemas"},  # the format: records, table schemas, manifest, validation
    {"loaders", "writers"},  # reading and writing the format (and raw recordings)
    {"convert", "synth"},  # producers of canonical datasets
    {"labeling"},
    {"estimators", "maps"},  # the plugin interface and built-ins; occupancy grids and planners
    {"metrics", "graph"},  # pure metric functions; the PredictiveGraph
    {"evaluation", "navigation"},  # task harnesses
    {"viewer", "datasets", "cli", "__init__"},  # tools and the package's front door
]
RANK = {name: k for k, layer in enumerate(LAYERS) for name in layer}

KNOWN: dict[tuple[str, str], str] = {}
"""Imports against the flow not fixed yet, with the reason; each must still exist (no stale entries)."""


def _package_of(path: Path) -> str:
    rel = path.relative_to(PACKAGE)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def _imported(tree: ast.AST) -> set[str]:
    """Top-level psg_data packages imported anywhere in a module (also inside functions), except under
    ``if TYPE_CHECKING:``."""
    out: set[str] = set()

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.orelse:
                visit(child)
            return
        names: list[str] = []
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [f"{node.module}.{a.name}" for a in node.names] if node.module == "psg_data" else [node.module]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        out.update(n.split(".")[1] for n in names if n.startswith("psg_data."))
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return out


def _edges() -> dict[tuple[str, str], list[str]]:
    edges: dict[tuple[str, str], list[str]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        src = _package_of(path)
        for dst in _imported(ast.parse(path.read_text(encoding="utf-8"))):
            if dst != src:
                edges.setdefault((src, dst), []).append(str(path.relative_to(PACKAGE)))
    return edges


def test_every_package_has_a_layer() -> None:
    names = {_package_of(p) for p in PACKAGE.rglob("*.py")}
    assert names <= set(RANK), f"packages without a layer in this test and docs/ARCHITECTURE.md: {names - set(RANK)}"


def test_imports_follow_the_data_flow() -> None:
    edges = _edges()
    against = {e: files for e, files in edges.items() if RANK[e[1]] > RANK[e[0]]}
    new = {f"{a} -> {b} ({', '.join(files)})" for (a, b), files in against.items() if (a, b) not in KNOWN}
    assert not new, "imports against the data flow: " + "; ".join(sorted(new))
    stale = set(KNOWN) - set(against)
    assert not stale, f"fixed, remove from KNOWN: {stale}"


def _cycle(graph: dict[str, set[str]]) -> list[str]:
    """One import cycle of ``graph`` (package -> packages it imports) as [a, b, ..., a], or []."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str]:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        state[node] = 2
        stack.pop()
        return []

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return []


def test_the_cycle_finder_finds_cycles() -> None:
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": set()}) == []
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"x": {"y"}, "y": {"x"}, "z": {"x"}}) == ["x", "y", "x"]


def test_no_import_cycle_between_packages() -> None:
    edges = _edges()
    graph: dict[str, set[str]] = {}
    for a, b in edges:
        graph.setdefault(a, set()).add(b)
    cycle = _cycle(graph)
    where = "; ".join(f"{a} -> {b} ({', '.join(edges[(a, b)])})" for a, b in zip(cycle, cycle[1:]))
    assert not cycle, f"import cycle between packages: {' -> '.join(cycle)}: {where}"

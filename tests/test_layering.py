"""The filters layer imports nothing above it, and its modules no circle through ``_base``.

docs/architecture.md: data flows down the layers, nothing imports upward. Read from the sources
with ``ast`` (no import, well under a second), counting every import: at module level, inside
functions (the usual way around a circle) and under ``TYPE_CHECKING``.
"""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FILTERS = ROOT / "jaxtrack" / "filters"
# What the filters may import from jaxtrack: themselves, the layers below them, and the package's
# private top-level helpers (jaxtrack._validation, jaxtrack._export, ...).
BELOW_FILTERS = ("jaxtrack.filters", "jaxtrack.models", "jaxtrack.geometry")


def imported_modules(path: Path, package: str) -> set[str]:
    """The absolute names of the modules ``path`` imports anywhere in its body (``from X import
    y`` gives ``X`` and ``X.y``: ``y`` may be a submodule)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = importlib.util.resolve_name("." * node.level + (node.module or ""), package) if node.level \
                else node.module
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)
    return names


def filters_graph() -> dict[str, set[str]]:
    """``jaxtrack.filters`` module -> the jaxtrack modules it imports (all kinds)."""
    return {
        f"jaxtrack.filters.{p.stem}": {n for n in imported_modules(p, "jaxtrack.filters") if n.startswith("jaxtrack")}
        for p in sorted(FILTERS.glob("*.py")) if p.stem != "__init__"
    }


def reachable(graph: dict[str, set[str]], start: str) -> set[str]:
    seen, todo = set(), [start]
    while todo:
        for nxt in graph.get(todo.pop(), ()):
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return seen


def test_the_parser_sees_lazy_and_type_checking_imports(tmp_path):
    src = tmp_path / "m.py"
    src.write_text("from typing import TYPE_CHECKING\nfrom ._a import x\nif TYPE_CHECKING:\n    from ._b import y\n"
                   "def f():\n    from ..montecarlo._metrics import z\n    import jaxtrack.cli\n")
    assert {"jaxtrack.filters._a", "jaxtrack.filters._b", "jaxtrack.montecarlo._metrics",
            "jaxtrack.cli"} <= imported_modules(src, "jaxtrack.filters")
    graph = filters_graph()
    assert "jaxtrack.filters._kalman" in graph["jaxtrack.filters._parallel"]  # a function-level import


def test_filters_import_nothing_above_them():
    def allowed(name: str) -> bool:
        parts = name.split(".")
        return (len(parts) == 1 or parts[1].startswith("_")
                or any(name == layer or name.startswith(layer + ".") for layer in BELOW_FILTERS))

    upward = {(module, name) for module, names in filters_graph().items() for name in names if not allowed(name)}
    assert not upward, f"filters/ imports from a layer above it: {sorted(upward)}"


def test_base_does_not_reach_the_scan_strategies_or_run_filter():
    # _parallel (the scan= strategies) imports _base; _run (run_filter) imports both. _base
    # reaching either of them, directly or through another module, would be a circle.
    graph = filters_graph()
    circle = reachable(graph, "jaxtrack.filters._base") & {
        "jaxtrack.filters._parallel", "jaxtrack.filters._run", "jaxtrack.filters._base"}
    assert not circle, f"jaxtrack.filters._base imports (directly or not) {sorted(circle)}, which import it"
    assert "jaxtrack.filters._base" in graph["jaxtrack.filters._parallel"]
    assert {"jaxtrack.filters._base", "jaxtrack.filters._parallel"} <= graph["jaxtrack.filters._run"]


def test_fusion_imports_only_the_filters_and_below():
    # jaxtrack.fusion sits above the filters and below the multi-target layer: it may import
    # itself, the filters, the models, the geometry and the private helpers; never montecarlo
    # (runs are simulated by the caller), multitarget, applications or the CLI.
    fusion = ROOT / "jaxtrack" / "fusion"
    below = ("jaxtrack.fusion",) + BELOW_FILTERS

    def allowed(name: str) -> bool:
        parts = name.split(".")
        return (len(parts) == 1 or parts[1].startswith("_")
                or any(name == layer or name.startswith(layer + ".") for layer in below))

    graph = {p.stem: {n for n in imported_modules(p, "jaxtrack.fusion") if n.startswith("jaxtrack")}
             for p in sorted(fusion.glob("*.py"))}
    assert "jaxtrack.filters._kalman" in graph["_track"]  # the parser read the sources
    upward = {(module, name) for module, names in graph.items() for name in names if not allowed(name)}
    assert not upward, f"fusion/ imports from a layer above it: {sorted(upward)}"

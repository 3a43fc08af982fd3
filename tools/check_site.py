"""Check a built documentation site: every gallery page shows figures, the API reference is complete.

Run by ``make docs`` after ``mkdocs build``::

    python tools/check_site.py [build/site]

- Gallery: for every notebook in ``notebooks/``, its page ``gallery/<name>/index.html`` exists and
  holds at least one embedded PNG figure (``<img`` with ``data:image/png``).
- API: every name in every public ``__all__`` (``PUBLIC_MODULES``) has its anchor
  ``id="jaxtrack.<module>.<Name>"`` in the built reference.

The ``__all__`` lists are read from the source files (``ast``), so the check does not import JAX.
Exits 1 with one line per problem.
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# The public layers, one API page each (docs/api/<name>.md).
PUBLIC_MODULES = (
    "models",
    "filters",
    "montecarlo",
    "sensitivity",
    "covariance",
    "design",
    "estimation",
    "geometry",
    "learning",
    "bounds",
    "plotting",
    "association",
    "multitarget",
)
# Names of the top-level ``jaxtrack.__all__`` that are documented objects (the rest are the
# subpackages themselves and ``__version__``), with the path they are documented at:
# ``InputError`` is imported lazily (PEP 562), so griffe documents it where it is defined.
TOP_LEVEL_DOCUMENTED = {"InputError": "jaxtrack._validation.InputError"}


def module_file(module: str) -> Path:
    """The source file of ``jaxtrack.<module>`` (a package's ``__init__.py`` or a module file)."""
    package = ROOT / "jaxtrack" / module / "__init__.py"
    return package if package.exists() else ROOT / "jaxtrack" / f"{module}.py"


def read_all(path: Path) -> list[str]:
    """The literal ``__all__`` list assigned in ``path`` (every public module has one)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets):
            return [ast.literal_eval(e) for e in node.value.elts if isinstance(e, ast.Constant)]
    raise LookupError(f"{path.relative_to(ROOT)} has no __all__")


def documented_paths() -> list[str]:
    """Every object path the API reference must document: ``jaxtrack.<module>.<Name>``."""
    paths = [f"jaxtrack.{m}.{name}" for m in PUBLIC_MODULES for name in read_all(module_file(m))]
    return paths + list(TOP_LEVEL_DOCUMENTED.values())


def figures_in(html: str) -> int:
    """Number of embedded PNG images in one HTML page."""
    return len(re.findall(r"<img[^>]*data:image/png", html))


def check(site: Path) -> list[str]:
    problems = []
    notebooks = sorted((ROOT / "notebooks").glob("*.ipynb"))
    if not notebooks:
        problems.append("notebooks/ holds no notebook")
    for nb in notebooks:
        page = site / "gallery" / nb.stem / "index.html"
        if not page.exists():
            problems.append(f"gallery: no page for {nb.name} ({page.relative_to(site)})")
            continue
        n = figures_in(page.read_text(encoding="utf-8"))
        print(f"gallery/{nb.stem}: {n} figure(s)")
        if n < 1:
            problems.append(f"gallery: {nb.name} is rendered without a figure")
    anchors = set()
    for page in (site / "api").rglob("*.html"):
        anchors.update(re.findall(r'id="(jaxtrack[\w.]*)"', page.read_text(encoding="utf-8")))
    expected = documented_paths()
    missing = [p for p in expected if p not in anchors]
    problems += [f"API reference: no entry for {p}" for p in missing]
    print(f"API reference: {len(expected) - len(missing)}/{len(expected)} public names documented")
    return problems


def main(argv: list[str]) -> int:
    site = Path(argv[0]) if argv else ROOT / "build" / "site"
    if not (site / "index.html").exists():
        print(f"{site} holds no built site (run mkdocs build first)", file=sys.stderr)
        return 1
    problems = check(site)
    for p in problems:
        print(p, file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

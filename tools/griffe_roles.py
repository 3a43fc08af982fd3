"""Griffe extension for the documentation site: Sphinx markup in docstrings becomes Markdown.

The docstrings are Markdown (equinox style) but cross-reference with Sphinx roles,
``:class:`~jaxtrack.models.TrackingModel``` or ``:func:`run_filter```. Rendered as written, the
role names would show. This rewrites each role to inline code, and to a link
``[`Name`][jaxtrack.layer.Name]`` when the target is a name the API reference documents (a
``::: jaxtrack.layer.Name`` directive under docs/): a link to anything else would not resolve,
which fails the strict build. A ``.. math::`` directive (its formula on the directive's line or
in the indented block below) becomes a ``$$`` block, which ``pymdownx.arithmatex`` keeps and
``tools/mkdocs_hooks.py`` typesets; a formula of several lines (``\\``) is set in an ``aligned``
environment, as Sphinx sets it in ``split``. A paragraph ending in ``::`` (a literal block follows)
ends in ``:``.
"""

from __future__ import annotations

import re
from pathlib import Path

import griffe

DOCS = Path(__file__).resolve().parent.parent / "docs"
ROLE = re.compile(r":(?:class|func|meth|mod|attr|data|obj|exc|py:\w+):`(~?)([^`]+)`")
MATH = re.compile(r"^([ \t]*)\.\. math::[ \t]*(.*)$")
LITERAL = re.compile(r"(?<=[^\s:]):(?=:[ \t]*$)", re.M)
DIRECTIVE = re.compile(r"^::: (jaxtrack(?:\.\w+)+)\s*$", re.M)


def documented_names() -> set[str]:
    """Every object path named by a ``:::`` directive in docs/."""
    return {m.group(1) for page in DOCS.rglob("*.md") for m in DIRECTIVE.finditer(page.read_text(encoding="utf-8"))}


def _public_package(path: str) -> str:
    """``jaxtrack.filters._base.run_filter`` -> ``jaxtrack.filters`` (the public layer)."""
    parts = path.split(".")
    keep = []
    for part in parts[:-1]:
        if part.startswith("_"):
            break
        keep.append(part)
    return ".".join(keep)


def math_blocks(text: str) -> str:
    """Every ``.. math::`` directive of ``text`` as a ``$$`` block at the directive's indentation."""
    lines, out, i = text.split("\n"), [], 0
    while i < len(lines):
        m = MATH.match(lines[i])
        if not m:
            out.append(lines[i])
            i += 1
            continue
        indent, body = m.group(1), [m.group(2)] if m.group(2).strip() else []
        i += 1
        # The directive's block: the lines indented deeper than the directive, and blank lines.
        while i < len(lines) and (not lines[i].strip() or len(lines[i]) - len(lines[i].lstrip()) > len(indent)):
            body.append(lines[i])
            i += 1
        while body and not body[-1].strip():
            i -= 1  # the blank lines after the block stay in the text
            body.pop()
        body = [b.strip() for b in body if b.strip()]
        if any(b.endswith("\\\\") for b in body):
            body = ["\\begin{aligned}", *body, "\\end{aligned}"]
        out += ["", f"{indent}$$", *(f"{indent}{b}" for b in body), f"{indent}$$", ""]
    return "\n".join(out)


def rewrite(text: str, owner_path: str, documented: set[str]) -> str:
    """Replace every Sphinx role in ``text``; ``owner_path`` resolves unqualified targets."""
    layer = _public_package(owner_path)

    def repl(m: re.Match) -> str:
        tilde, target = m.group(1), m.group(2).strip()
        target = target.removesuffix("()")
        label = target.rsplit(".", 1)[-1] if tilde else target
        candidates = [target] if target.startswith("jaxtrack.") else [f"{layer}.{target.lstrip('.')}"]
        # Only documented names: a member's anchor exists only when the member is rendered.
        for c in candidates:
            if c in documented:
                return f"[`{label}`][{c}]"
        return f"`{label}`"

    return LITERAL.sub("", math_blocks(ROLE.sub(repl, text)))


class SphinxRolesToMarkdown(griffe.Extension):
    """Rewrite the roles in every docstring griffe loads."""

    def __init__(self) -> None:
        super().__init__()
        self.documented = documented_names()

    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = rewrite(obj.docstring.value, obj.path, self.documented)

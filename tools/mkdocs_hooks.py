"""mkdocs hooks: the gallery's executed notebooks are there; the README's reproduction summary;
the math typeset at build time.

**Gallery check** (``on_config``). The gallery renders the executed copies in ``docs/gallery/``
that ``make docs`` (or the notebook tests) write; a plain ``mkdocs build`` in a fresh clone has
none, and strict mode would abort on one warning per missing page without saying why. The hook
stops first with one line that names the missing copies and says to run ``make docs``.

**Reproduction summary.**

The README's ``## Reproduced studies`` section holds the reproduction summary, generated from
``jaxtrack reproduce all --json`` between ``<!-- reproduce:begin -->`` and
``<!-- reproduce:end -->``; the Studies page shows that whole section, so the site and the
README cannot disagree. Without that heading, the non-empty block between the markers is used.
The page marks the place with ``<!-- include:reproduction-summary -->``.

**Math** (``on_page_content``). TeX is typeset when the site is built, by KaTeX (the ``pykatex``
package runs it in-process), as MathML: browsers draw MathML themselves, so a page needs no
script, style sheet or font from anywhere, and the site works offline. KaTeX's HTML output would
need its style sheet and fonts, which no Python package ships. Where the TeX comes from:

- Markdown pages and docstrings (mkdocstrings renders them with the same extensions):
  ``pymdownx.arithmatex`` in generic mode marks ``$…$`` and ``$$…$$`` as
  ``<span class="arithmatex">\\(…\\)</span>`` and ``<div class="arithmatex">\\[…\\]</div>``,
  having kept them from Markdown (``_`` or ``*`` in a formula never turns into emphasis);
  ``tools/griffe_roles.py`` turns a docstring's ``.. math::`` directive into a ``$$`` block.
- Notebook pages: mkdocs-jupyter's Markdown keeps ``$…$`` and ``$$…$$`` as written (it expects
  MathJax in the browser): they are typeset in the Markdown cells of the page, and the page's
  MathJax configuration, whose script address is empty here, is removed.

A formula KaTeX cannot parse stops the build, naming the page and the formula.
"""

from __future__ import annotations

import html
import re
from pathlib import Path

from mkdocs.exceptions import PluginError

PLACEHOLDER = "<!-- include:reproduction-summary -->"
ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"


def missing_gallery(root: Path | None = None) -> list[str]:
    """Names of the notebooks in ``notebooks/`` without an executed copy in ``docs/gallery/``."""
    root = ROOT if root is None else root
    return sorted(p.name for p in (root / "notebooks").glob("*.ipynb") if not (root / "docs" / "gallery" / p.name).exists())


def on_config(config):
    missing = missing_gallery()
    if missing:
        raise PluginError(
            f"docs/gallery/ lacks the executed copies of {len(missing)} notebook(s) ({', '.join(missing[:3])}"
            f"{', …' if len(missing) > 3 else ''}): run `make docs`, which executes them and builds the site."
        )
    return config


def reproduction_summary(readme_text: str) -> str:
    """The README's "Reproduced studies" section, else its non-empty block between the markers."""
    section = re.search(r"^## Reproduced studies\n(.*?)(?=^## |\Z)", readme_text, re.S | re.M)
    if section and section.group(1).strip():
        return section.group(1).strip()
    marked = re.search(r"<!-- reproduce:begin -->\n(.*?)<!-- reproduce:end -->", readme_text, re.S)
    if marked and marked.group(1).strip():
        return marked.group(1).strip()
    raise PluginError("README.md has neither reproduce markers nor a '## Reproduced studies' section.")


def on_page_markdown(markdown: str, page, config, files) -> str:
    if PLACEHOLDER not in markdown:
        return markdown
    block = reproduction_summary(README.read_text(encoding="utf-8"))
    # The README's headings sit one level above the page's section: demote them.
    block = re.sub(r"^(#{2,5}) ", r"#\1 ", block, flags=re.M)
    return markdown.replace(PLACEHOLDER, block)


# pymdownx.arithmatex's generic output; its TeX is HTML-escaped and wrapped in \( \) or \[ \].
ARITHMATEX = re.compile(r'<(span|div) class="arithmatex">(.*?)</\1>', re.S)
# A notebook page: the MathJax loader (an empty address) and its configuration.
NOTEBOOK_MATHJAX = re.compile(r"<!-- Load mathjax -->.*?<!-- End of mathjax configuration -->", re.S)
# A notebook page: each Markdown cell's rendered text runs to the next cell.
NOTEBOOK_MARKDOWN = re.compile(r'data-mime-type="text/markdown">(.*?)(?=<div class="jp-Cell |\Z)', re.S)
# Code in a Markdown cell keeps its dollars (``$HOME``).
CODE = re.compile(r"(<(code|pre)\b.*?</\2>)", re.S)
DISPLAY_DOLLARS = re.compile(r"\$\$(.+?)\$\$", re.S)
INLINE_DOLLARS = re.compile(r"(?<![\\$])\$(?=\S)([^$<>\n]+?)(?<=\S)(?<!\\)\$")


def render_tex(tex: str, display: bool, where: str = "") -> str:
    """``tex`` (plain TeX, not HTML-escaped) typeset by KaTeX as MathML, in a ``katex`` span
    (display math: within a ``katex-display`` span)."""
    import pykatex  # the docs extra; imported here so that the other hooks work without it

    try:
        # strict="ignore": Unicode letters and symbols (τ, ∂, ≥) are written as such in the
        # docstrings; KaTeX typesets them but would warn about each one.
        mathml = pykatex.renderToString(tex.strip(), displayMode=display, output="mathml", strict="ignore")
    except Exception as e:
        raise PluginError(f"{where or 'math'}: KaTeX cannot typeset {tex.strip()!r}: {e}") from e
    # KaTeX wraps display math in this span only with its HTML output (and its style sheet): a
    # wide formula scrolls instead of widening the page. A span, as it may stand inside a <p>.
    return f'<span class="katex-display" style="display:block;overflow-x:auto">{mathml}</span>' if display else mathml


def typeset_arithmatex(content: str, where: str = "") -> str:
    """Replace every formula that pymdownx.arithmatex marked in ``content`` by its MathML."""

    def repl(m: re.Match) -> str:
        display = m.group(1) == "div"
        tex = html.unescape(m.group(2)).strip()
        # Generic mode wraps inline math in \( \), display math in \[ \] (an environment bare).
        if tex[:2] in ("\\(", "\\[") and tex[-2:] in ("\\)", "\\]"):
            tex = tex[2:-2]
        return render_tex(tex, display, where)

    return ARITHMATEX.sub(repl, content)


def typeset_notebook(content: str, where: str = "") -> str:
    """Typeset the ``$…$``/``$$…$$`` math of a notebook page's Markdown cells; drop its MathJax."""

    def dollars(text: str) -> str:
        text = DISPLAY_DOLLARS.sub(lambda m: render_tex(html.unescape(m.group(1)), True, where), text)
        return INLINE_DOLLARS.sub(lambda m: render_tex(html.unescape(m.group(1)), False, where), text)

    def cell(m: re.Match) -> str:
        parts = CODE.split(m.group(1))  # [text, code, tag name, text, code, tag name, …]
        body = "".join(dollars(p) if i % 3 == 0 else p for i, p in enumerate(parts) if i % 3 != 2)
        return 'data-mime-type="text/markdown">' + body

    return NOTEBOOK_MARKDOWN.sub(cell, NOTEBOOK_MATHJAX.sub("", content))


def on_page_content(content: str, page, config, files) -> str:
    where = page.file.src_uri
    if where.endswith(".ipynb"):
        content = typeset_notebook(content, where)
    return typeset_arithmatex(content, where)

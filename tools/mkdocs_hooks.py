"""mkdocs hooks: the gallery's executed notebooks are there; the README's reproduction summary.

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
"""

from __future__ import annotations

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

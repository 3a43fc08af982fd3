"""The documentation site's math, without building the site or opening a browser.

The same path as ``make docs``: Markdown through the extensions of ``mkdocs.yml`` (arithmatex
marks the TeX), docstrings through ``tools/griffe_roles.py`` (``.. math::`` becomes ``$$``), then
``tools/mkdocs_hooks.py`` typesets with KaTeX; a notebook page as mkdocs-jupyter renders it.
``tools/check_site.py --browser`` checks a built site in Chromium.
"""

import importlib.util
from pathlib import Path

import pytest
import yaml

markdown = pytest.importorskip("markdown")
pytest.importorskip("pykatex")
pytest.importorskip("mkdocs")

ROOT = Path(__file__).parent.parent


def _load(name: str):
    spec = importlib.util.spec_from_file_location(f"_{name}", ROOT / "tools" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


hooks = _load("mkdocs_hooks")
check_site = _load("check_site")


class _Loader(yaml.SafeLoader):
    """mkdocs.yml as data (an unknown tag, such as ``!!python/name``, becomes None)."""


_Loader.add_multi_constructor("", lambda loader, suffix, node: None)


def site_markdown(text: str) -> str:
    """``text`` as the site renders it: mkdocs.yml's Markdown extensions, then the math hook."""
    config = yaml.load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"), Loader=_Loader)
    names, options = [], {}
    for entry in config["markdown_extensions"]:
        name, opts = next(iter(entry.items())) if isinstance(entry, dict) else (entry, None)
        names.append(name)
        if opts:
            options[name] = opts
    html = markdown.markdown(text, extensions=names, extension_configs=options)
    return hooks.typeset_arithmatex(html, "test")


def test_markdown_math_is_typeset_as_mathml_and_kept_from_emphasis():
    html = site_markdown("Inline $P_{k/k-1} = Φ P_{k-1/k-1} Φᵀ + Q$ and $a_1 * b_1$.\n\n$$\n\\frac{∂J}{∂τ}\n$$\n")
    assert html.count('class="katex"') == 2 + 1
    assert 'class="katex-display"' in html  # the $$ block
    assert "<math" in html and "arithmatex" not in html and "$" not in html
    assert "<em>" not in html  # underscores and stars inside a formula stay TeX


def test_docstring_math_directive_becomes_display_math_and_no_link():
    griffe_roles = _load("griffe_roles")
    # The one-line directive of dimensionless_period_sensitivity: rendered as written, its
    # brackets and parentheses read as a Markdown link.
    doc = ":func:`f` is\n\n.. math::  \\frac{τ(a + 2τ)}{[(1 + aτ + τ^2)/r_x + 1](1 + aτ + τ^2)}\n\nInvariant."
    html = site_markdown(griffe_roles.rewrite(doc, "jaxtrack.sensitivity._one_stage.f", set()))
    assert 'class="katex-display"' in html and "<a " not in html
    multi = "Sum:\n\n.. math::\n\n    a &= b \\\\\n    c &= d\n\nafter"  # two lines: aligned
    html = site_markdown(griffe_roles.rewrite(multi, "jaxtrack.x", set()))
    assert html.count('class="katex-display"') == 1 and "after" in html


def test_a_display_formula_left_raw_is_caught():
    """A ``.. math::`` indented inside a docstring's list item came out as raw ``$$`` text (LoopyBP's
    Bethe formula did); tools/check_site.py now reports such a page. LoopyBP's docstring renders."""
    import inspect

    from jaxtrack.association import LoopyBP

    griffe_roles = _load("griffe_roles")
    nested = "- item:\n\n  .. math::\n\n      a = b\n\n  (after)\n"
    assert check_site.raw_display_math(site_markdown(griffe_roles.rewrite(nested, "jaxtrack.x", set())))
    html = site_markdown(griffe_roles.rewrite(inspect.cleandoc(LoopyBP.__doc__), "jaxtrack.association.LoopyBP", set()))
    assert not check_site.raw_display_math(html) and html.count('class="katex-display"') == 2
    assert not check_site.raw_display_math('<code>$$x$$</code><annotation encoding="x">$$</annotation>')


def test_a_formula_katex_cannot_parse_stops_the_build():
    with pytest.raises(hooks.PluginError, match="page.md"):
        hooks.typeset_arithmatex('<span class="arithmatex">\\(\\frac{\\)</span>', "page.md")


def test_notebook_page_math_is_typeset_and_mathjax_removed():
    # The shape of mkdocs-jupyter's page (nbconvert's lab template): the MathJax loader and the
    # Markdown cells with their TeX as written, HTML-escaped.
    page = (
        '<!-- Load mathjax -->\n<script src=""> </script>\n<script type="text/x-mathjax-config">init</script>\n'
        "<!-- End of mathjax configuration -->"
        '<div class="jp-Cell jp-MarkdownCell"><div data-mime-type="text/markdown">\n'
        "<p>Text $P_{k|k-1} = a_k^2 &lt; b$, costs $5 and <code>$HOME</code></p>\n"
        "<p>$$\n\\frac{\\partial P}{\\partial \\tau}\n$$</p>\n</div></div>"
        '<div class="jp-Cell jp-CodeCell"><pre>echo $PATH and $HOME</pre></div>'
    )
    html = hooks.typeset_notebook(page, "gallery/x.ipynb")
    assert html.count('class="katex"') == 2 and 'class="katex-display"' in html
    assert "MathJax" not in html and "mathjax" not in html
    assert "<code>$HOME</code>" in html and "costs $5" in html and "echo $PATH and $HOME" in html


def test_built_site_shows_no_tqdm_warning():
    """No built gallery page shows tqdm's warning, where the page is up to date.

    A page is checked when it was built from the current executed copy of its notebook (the page
    is the newer) and that copy was executed after jaxtrack/_progress.py appeared (a checkout's
    older copies and pages show the warning until ``make test`` or ``make docs`` renews them).
    """
    site = ROOT / "build" / "site"
    pages = sorted((site / "gallery").glob("*/index.html"))
    if not pages:
        pytest.skip("no built site (make docs)")
    since = (ROOT / "jaxtrack" / "_progress.py").stat().st_mtime
    checked = 0
    for page in pages:
        executed = ROOT / "docs" / "gallery" / f"{page.parent.name}.ipynb"
        if not executed.exists() or not since <= executed.stat().st_mtime <= page.stat().st_mtime:
            continue
        checked += 1
        assert check_site.TQDM_WARNING not in page.read_text(encoding="utf-8"), page.parent.name
    if not checked:
        pytest.skip("no built gallery page is up to date")

"""The documentation site's sources: complete ``__all__`` lists, an API directive for each name.

Fast checks without building the site (``make docs`` builds it strictly and runs
``tools/check_site.py`` on the result).
"""

import importlib
import importlib.util
import re
import types
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).parent.parent
DOCS = ROOT / "docs"

_spec = importlib.util.spec_from_file_location("_check_site", ROOT / "tools" / "check_site.py")
check_site = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(check_site)

DIRECTIVE = re.compile(r"^::: *(\S+)", re.M)


def public_attributes(module: types.ModuleType) -> set[str]:
    """What ``module`` offers: public names that are neither modules nor imported from elsewhere.

    A name counts when its object belongs to ``module`` or to a submodule of it (``__module__``),
    or has no ``__module__`` at all (constants: floats, tuples, slices). Names such as
    ``Sequence`` or ``KalmanFilter`` that a module file merely imports for its own use do not.
    """
    names = set()
    for name, value in vars(module).items():
        if name.startswith("_") or isinstance(value, types.ModuleType):
            continue
        owner = getattr(value, "__module__", None)
        if not isinstance(owner, str) or owner == module.__name__ or owner.startswith(module.__name__ + "."):
            names.add(name)
    return names


@pytest.mark.parametrize("name", check_site.PUBLIC_MODULES)
def test_all_lists_exactly_the_public_names(name):
    module = importlib.import_module(f"jaxtrack.{name}")
    assert len(module.__all__) == len(set(module.__all__)), "duplicates in __all__"
    assert set(module.__all__) == public_attributes(module)


def test_public_attributes_notices_a_name_missing_from_all():
    module = types.ModuleType("jaxtrack.fake")
    exec("import math\nfrom collections.abc import Sequence\nLIMIT = 3.0\ndef f(): pass\nclass C: pass\n", vars(module))
    module.__all__ = ["f", "C"]  # LIMIT dropped
    assert public_attributes(module) == {"f", "C", "LIMIT"} != set(module.__all__)


def test_top_level_all_is_subpackages_version_and_documented_names():
    import jaxtrack

    documented = set(jaxtrack.__all__) - set(jaxtrack._SUBPACKAGES) - {"__version__"}
    assert documented == set(check_site.TOP_LEVEL_DOCUMENTED)
    for name, path in check_site.TOP_LEVEL_DOCUMENTED.items():
        module, attr = path.rsplit(".", 1)
        assert getattr(jaxtrack, name) is getattr(importlib.import_module(module), attr)


def _directives() -> list[tuple[str, str]]:
    return [
        (page.relative_to(DOCS).as_posix(), m.group(1))
        for page in sorted(DOCS.rglob("*.md"))
        for m in DIRECTIVE.finditer(page.read_text(encoding="utf-8"))
    ]


def test_every_public_name_has_exactly_one_directive_and_every_directive_exists():
    # Reads __all__ from the sources (no JAX import): well under a second.
    expected = check_site.documented_paths()
    written = [target for _, target in _directives()]
    missing = sorted(set(expected) - set(written))
    unknown = sorted(set(written) - set(expected))
    repeated = sorted({t for t in written if written.count(t) > 1})
    assert not missing, f"public names without a `::: name` directive in docs/: {missing}"
    assert not unknown, f"directives naming something that is not public API: {unknown}"
    assert not repeated, f"names documented twice: {repeated}"
    assert len(expected) > 200  # the package's size: the lists were read, not empty


def test_each_layer_page_documents_its_own_module():
    for page, target in _directives():
        if page.startswith("api/") and page != "api/errors.md":
            assert target.startswith(f"jaxtrack.{Path(page).stem}."), (page, target)


def _nav_files(nav) -> list[str]:
    files = []
    for entry in nav:
        value = next(iter(entry.values())) if isinstance(entry, dict) else entry
        files += _nav_files(value) if isinstance(value, list) else [value]
    return files


def test_nav_lists_every_page_and_every_notebook():
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))
    nav = _nav_files(config["nav"])
    pages = sorted(p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md"))
    assert sorted(p for p in nav if p.endswith(".md")) == pages
    notebooks = sorted(f"gallery/{p.name}" for p in (ROOT / "notebooks").glob("*.ipynb"))
    assert sorted(p for p in nav if p.endswith(".ipynb")) == notebooks
    assert config["theme"]["font"] is False  # no web fonts: the build is offline


def _fake_site(tmp_path, *, figure: bool, anchors: list[str]) -> Path:
    site = tmp_path / "site"
    (site / "api").mkdir(parents=True)
    (site / "index.html").write_text("<html></html>")
    img = '<img alt="" src="data:image/png;base64,iVBORw0KGgo=">' if figure else "<p>no figure</p>"
    # A complete site's math pages hold typeset formulas; the other shows TeX left as written
    # and a notebook's tqdm warning.
    math = '<span class="katex"><math></math></span>' if figure else '<span class="arithmatex">\\(x\\)</span>'
    for nb in (ROOT / "notebooks").glob("*.ipynb"):
        (site / "gallery" / nb.stem).mkdir(parents=True)
        (site / "gallery" / nb.stem / "index.html").write_text(img + ("" if figure else check_site.TQDM_WARNING))
    (site / "api" / "index.html").write_text("".join(f'<h3 id="{a}">x</h3>' for a in anchors))
    for rel in check_site.MATH_PAGES:
        (site / rel).parent.mkdir(parents=True, exist_ok=True)
        (site / rel).write_text((site / rel).read_text() + math if (site / rel).exists() else math)
    return site


def test_check_site_passes_a_complete_site_and_names_each_gap(tmp_path):
    expected = check_site.documented_paths()
    assert check_site.check(_fake_site(tmp_path / "a", figure=True, anchors=expected)) == []
    problems = check_site.check(_fake_site(tmp_path / "b", figure=False, anchors=expected[1:]))
    assert f"API reference: no entry for {expected[0]}" in problems
    assert sum("rendered without a figure" in p for p in problems) == len(list((ROOT / "notebooks").glob("*.ipynb")))
    assert sum("shows no typeset formula" in p for p in problems) == len(check_site.MATH_PAGES)
    assert sum("TeX left untypeset" in p for p in problems) == len(check_site.MATH_PAGES)
    assert sum("IProgress not found" in p for p in problems) == len(list((ROOT / "notebooks").glob("*.ipynb")))


def test_reproduction_summary_comes_from_the_readme():
    spec = importlib.util.spec_from_file_location("_mkdocs_hooks", ROOT / "tools" / "mkdocs_hooks.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    readme = "## Reproduced studies\n\nintro\n<!-- reproduce:begin -->\n| a | b |\n<!-- reproduce:end -->\n\n## Next\nother\n"
    assert hooks.reproduction_summary(readme) == "intro\n<!-- reproduce:begin -->\n| a | b |\n<!-- reproduce:end -->"
    assert hooks.reproduction_summary("# x\n<!-- reproduce:begin -->\n| a | b |\n<!-- reproduce:end -->\n") == "| a | b |"
    with pytest.raises(Exception, match="Reproduced studies"):
        hooks.reproduction_summary("# x\n<!-- reproduce:begin -->\n<!-- reproduce:end -->\n")
    assert "jaxtrack reproduce" in hooks.reproduction_summary((ROOT / "README.md").read_text(encoding="utf-8"))


def test_a_build_without_the_gallery_says_to_run_make_docs(tmp_path):
    spec = importlib.util.spec_from_file_location("_mkdocs_hooks", ROOT / "tools" / "mkdocs_hooks.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    (tmp_path / "notebooks").mkdir()
    (tmp_path / "docs" / "gallery").mkdir(parents=True)
    for name in ("a.ipynb", "b.ipynb"):
        (tmp_path / "notebooks" / name).write_text("{}")
    (tmp_path / "docs" / "gallery" / "a.ipynb").write_text("{}")
    assert hooks.missing_gallery(tmp_path) == ["b.ipynb"]
    hooks.ROOT = tmp_path
    with pytest.raises(Exception, match=r"1 notebook\(s\) \(b.ipynb\): run `make docs`") as err:
        hooks.on_config({})
    assert "\n" not in str(err.value)
    (tmp_path / "docs" / "gallery" / "b.ipynb").write_text("{}")
    assert hooks.on_config({"x": 1}) == {"x": 1}


def test_sphinx_roles_become_links_to_documented_names_and_code_otherwise():
    spec = importlib.util.spec_from_file_location("_griffe_roles", ROOT / "tools" / "griffe_roles.py")
    roles = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(roles)
    documented = {"jaxtrack.filters.run_filter", "jaxtrack.models.TrackingModel"}
    text = "See :func:`run_filter`, :class:`~jaxtrack.models.TrackingModel` and :mod:`.scenario`.\n\nExample::\n"
    assert roles.rewrite(text, "jaxtrack.filters._base.run_filter", documented) == (
        "See [`run_filter`][jaxtrack.filters.run_filter], [`TrackingModel`][jaxtrack.models.TrackingModel]"
        " and `.scenario`.\n\nExample:\n"
    )
    assert "jaxtrack.filters.run_filter" in roles.documented_names()

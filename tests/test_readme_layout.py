"""The README's Layout block names every public part of the package, and nothing that is not there.

Public parts: each ``jaxtrack/<name>/`` with an ``__init__.py`` and each ``jaxtrack/<name>.py``,
``<name>`` not starting with ``_``. An entry of the block is the first word of a line that does
not start with a space; every entry, the package's and the others (``tests/``, ``docs/…``), must
exist in the repository.
"""

import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "jaxtrack"


def layout_entries(readme: str) -> list[str]:
    """The first words of the unindented lines of the first code block under ``## Layout``."""
    section = re.search(r"^## Layout\n(.*?)(?=^## |\Z)", readme, re.S | re.M)
    assert section, "README.md has no '## Layout' section"
    block = re.search(r"^```\n(.*?)^```", section.group(1), re.S | re.M)
    assert block, "the Layout section has no code block"
    return [line.split()[0] for line in block.group(1).splitlines() if line.strip() and not line[0].isspace()]


def public_parts() -> set[str]:
    packages = {f"jaxtrack/{p.name}" for p in PACKAGE.iterdir()
                if p.is_dir() and (p / "__init__.py").exists() and not p.name.startswith("_")}
    modules = {f"jaxtrack/{p.name}" for p in PACKAGE.glob("*.py") if not p.name.startswith("_")}
    return packages | modules


def check(readme: str) -> None:
    entries = layout_entries(readme)
    listed = {e.rstrip("/") for e in entries if e.startswith("jaxtrack/")}
    missing = public_parts() - listed
    assert not missing, f"the README's Layout lacks {sorted(missing)}"
    absent = [e for e in entries if not (ROOT / e).exists()]
    assert not absent, f"the README's Layout names what does not exist: {absent}"
    assert len(entries) == len(set(entries)), f"the README's Layout repeats an entry: {entries}"


def test_layout_lists_every_public_subpackage_and_module():
    check((ROOT / "README.md").read_text(encoding="utf-8"))


def test_layout_check_fails_on_a_missing_or_invented_entry():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    dropped = re.sub(r"^jaxtrack/bounds .*\n(?: .*\n)*", "", readme, count=1, flags=re.M)
    assert dropped != readme
    invented = readme.replace("jaxtrack/plotting.py ", "jaxtrack/plots.py    ", 1)
    assert invented != readme
    for broken in (dropped, invented):
        try:
            check(broken)
        except AssertionError:
            continue
        raise AssertionError("the Layout check passed on a broken README")

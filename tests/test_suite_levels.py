"""The suite's XLA levels (tests/conftest.py): most optimisations off, except in modules marked
``xla_optimized``, whose long programs run faster at the default level."""

import pytest

from conftest import FUSION_EMITTERS, LEGACY_EMITTERS_FLAG, XLA_DEFAULT, fast_compile


def test_unmarked_modules_compile_with_most_optimisations_off():
    assert fast_compile() is not XLA_DEFAULT


@pytest.mark.parametrize("module", ["test_covariance", "test_imm_fit", "test_maneuvering",
                                    "test_multitarget_learning"])
def test_marked_modules_say_so(module):
    import importlib

    marks = getattr(importlib.import_module(module), "pytestmark", None)
    assert marks is not None and marks.name == "xla_optimized"


def test_the_emitters_are_the_ones_asked_for():
    import os

    assert (LEGACY_EMITTERS_FLAG in os.environ.get("XLA_FLAGS", "")) is not FUSION_EMITTERS


def test_make_test_runs_the_fusion_emitter_modules_in_the_session_that_sets_them():
    """Modules marked ``fusion_emitters`` skip themselves under the former emitters: the Makefile
    must run each in the session that sets JAXTRACK_TEST_FUSION_EMITTERS=1."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    marked = {f"tests/{p.name}" for p in (root / "tests").glob("test_*.py")
              if re.search(r"^pytestmark = pytest\.mark\.fusion_emitters$", p.read_text(encoding="utf-8"), re.M)}
    assert {"tests/test_multitarget_contract.py", "tests/test_square_root.py"} <= marked
    text = (root / "Makefile").read_text()
    isolated = set(re.search(r"^ISOLATED\s*:=(.*)$", text, re.M).group(1).split())
    assert marked <= isolated, marked - isolated
    recipe = text[text.index("\ntest: "):].split("\n\n")[0]
    lines = [ln for ln in recipe.splitlines() if "$(ISOLATED)" in ln]
    assert lines and all("JAXTRACK_TEST_FUSION_EMITTERS=1" in ln for ln in lines), lines

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


def test_make_test_runs_the_bit_for_bit_contract_with_the_fusion_emitters():
    """test_multitarget_contract skips itself under the former emitters: the Makefile must run it
    in the session that sets JAXTRACK_TEST_FUSION_EMITTERS=1, and in no other."""
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parent.parent / "Makefile").read_text()
    isolated = re.search(r"^ISOLATED\s*:=(.*)$", text, re.M).group(1).split()
    assert "tests/test_multitarget_contract.py" in isolated
    recipe = text[text.index("\ntest: "):].split("\n\n")[0]
    lines = [ln for ln in recipe.splitlines() if "$(ISOLATED)" in ln]
    assert lines and all("JAXTRACK_TEST_FUSION_EMITTERS=1" in ln for ln in lines), lines

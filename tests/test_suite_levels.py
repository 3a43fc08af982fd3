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


def test_make_test_compiles_every_session_with_the_former_emitters_and_test_slow_checks_the_contract_bit_for_bit():
    """No make test session sets the fusion emitters (twice the compile time; tests/conftest.py);
    make test-slow holds the multi-target contract to its reference at the reference's emitters."""
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parent.parent / "Makefile").read_text()

    def recipe(target):
        return text[text.index(f"\n{target}: "):].split("\n\n")[0]

    assert "FUSION_EMITTERS" not in recipe("test")
    slow = [ln for ln in recipe("test-slow").splitlines() if "JAXTRACK_TEST_FUSION_EMITTERS=1" in ln]
    assert len(slow) == 1 and re.search(r"tests/test_multitarget_contract\.py\s*$", slow[0]), slow

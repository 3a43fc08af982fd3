"""The suite's XLA levels (tests/conftest.py): most optimisations off, except in modules marked
``xla_optimized``, whose long programs run faster at the default level."""

import pytest

from conftest import XLA_DEFAULT, fast_compile


def test_unmarked_modules_compile_with_most_optimisations_off():
    assert fast_compile() is not XLA_DEFAULT


@pytest.mark.parametrize("module", ["test_covariance", "test_imm_fit", "test_maneuvering",
                                    "test_multitarget_learning"])
def test_marked_modules_say_so(module):
    import importlib

    marks = getattr(importlib.import_module(module), "pytestmark", None)
    assert marks is not None and marks.name == "xla_optimized"

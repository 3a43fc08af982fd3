"""Test configuration: float64, loud numerics, and an opt-in flag for slow Monte Carlo sizes."""

import os

import jax
import pytest

import jaxtrack  # noqa: F401  (switches on float64)

jax.config.update("jax_enable_x64", True)
# Catch accidental rank broadcasting between e.g. (n,) and (n, 1).
jax.config.update("jax_numpy_rank_promotion", "raise")


def pytest_addoption(parser):
    parser.addoption(
        "--runslow",
        action="store_true",
        default=os.environ.get("JAXTRACK_RUNSLOW", "") == "1",
        help="run tests marked slow (large Monte Carlo sizes)",
    )


def pytest_collection_modifyitems(config, items):
    if config.getoption("--runslow"):
        return
    skip = pytest.mark.skip(reason="slow: run with --runslow or JAXTRACK_RUNSLOW=1")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)

"""float32 (issue 24): a Monte Carlo whose NEES leaves its bounds by a wide margin in float32 is
flagged, and `jaxtrack reproduce` refuses float32 studies with one line instead of crashing."""

import os
import subprocess
import sys
import warnings

import jax
import jax.numpy as jnp
import pytest

from jaxtrack.models import LinearGaussianModel
from jaxtrack.montecarlo import monte_carlo
from jaxtrack.montecarlo._result import PRECISION_MARGIN


def _long_tiny_noise_model(dtype):
    """A 1-D constant-velocity target at 300 m/s for 300 s, measured to 1 mm, almost no process
    noise: the filter's position σ falls to ~1e-4 m while positions reach 1.8e5 m, where float32
    resolves only ~0.02 m."""
    F = jnp.array([[1.0, 1.0], [0.0, 1.0]], dtype)
    Q = 1e-10 * jnp.array([[1 / 3, 1 / 2], [1 / 2, 1.0]], dtype)
    H = jnp.array([[1.0, 0.0]], dtype)
    R = jnp.array([[1e-6]], dtype)
    return LinearGaussianModel(F, Q, H, R, jnp.array([0.0, 300.0], dtype), jnp.eye(2, dtype=dtype))


def test_float32_monte_carlo_outside_its_bounds_is_flagged():
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # float64: consistent, no warning
        res64 = monte_carlo(_long_tiny_noise_model(jnp.float64), jax.random.key(0), 128, num_steps=300,
                            progress=False)
    assert res64.anees_bounds[0] < res64.anees < res64.anees_bounds[1] and not res64.precision_warning
    with pytest.warns(RuntimeWarning, match="float32"):
        res32 = monte_carlo(_long_tiny_noise_model(jnp.float32), jax.random.key(0), 128, num_steps=300,
                            progress=False)
    assert res32.nees.dtype == jnp.float32 and res32.num_failed == 0  # ok: nothing non-finite
    assert res32.anees > PRECISION_MARGIN * res32.anees_bounds[1]  # ~1e4 measured, vs 1.0 in float64
    assert res32.precision_warning


def test_float32_mismodelled_but_not_extreme_is_not_flagged():
    # The filter assumes R 4× too small: ANEES ≈ 2, above its bound but far from the 10× margin.
    F = jnp.array([[1.0, 1.0], [0.0, 1.0]], jnp.float32)
    Q = jnp.array([[1 / 3, 1 / 2], [1 / 2, 1.0]], jnp.float32)
    H = jnp.array([[1.0, 0.0]], jnp.float32)
    P0 = 100 * jnp.eye(2, dtype=jnp.float32)
    truth = LinearGaussianModel(F, Q, H, jnp.array([[4.0]], jnp.float32), jnp.zeros(2, jnp.float32), P0)
    mis = LinearGaussianModel(F, Q, H, jnp.array([[1.0]], jnp.float32), jnp.zeros(2, jnp.float32), P0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        res = monte_carlo(truth, jax.random.key(1), 256, num_steps=30, filter_model=mis, progress=False)
    assert res.anees_bounds[1] < res.anees < 3 * res.anees_bounds[1] and not res.precision_warning


def test_reproduce_refuses_float32_with_one_line(tmp_path):
    # JAX_ENABLE_X64 is dropped: importing jaxtrack (conftest) sets it for JAX, and a child that
    # inherits it runs in float64 whatever JAXTRACK_ENABLE_X64 says (jaxtrack._config._request_x64).
    env = {k: v for k, v in os.environ.items() if k != "JAX_ENABLE_X64"}
    env["JAXTRACK_ENABLE_X64"] = "0"
    proc = subprocess.run([sys.executable, "-m", "jaxtrack", "reproduce", "ho", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr
    assert lines[0].startswith("jaxtrack reproduce: error: study ho needs float64 (")
    assert lines[0].endswith("unset JAXTRACK_ENABLE_X64")
    assert list(tmp_path.iterdir()) == []  # refused before anything was computed or written

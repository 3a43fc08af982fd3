"""Precision policy: float64 by default, float32 honoured end to end when the inputs are float32."""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np

from jaxtrack.filters import KalmanFilter, UnscentedKalmanFilter, run_filter
from jaxtrack.models import constant_velocity
from jaxtrack.montecarlo import monte_carlo, simulate


def _cv(dtype):
    return constant_velocity(
        jnp.asarray(1.0, dtype), dim=2, accel_psd=jnp.asarray(0.5, dtype),
        measurement_std=jnp.asarray(10.0, dtype), initial_cov=jnp.eye(4, dtype=dtype) * 100.0,
    )


def test_import_enables_float64():
    assert jax.config.jax_enable_x64
    assert _cv(float).F.dtype == jnp.float64


def test_opt_out_leaves_x64_off():
    code = "import jax, jaxtrack; print(jax.config.jax_enable_x64)"
    env = dict(os.environ, JAXTRACK_ENABLE_X64="0", JAX_ENABLE_X64="0")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.stdout.strip() == "False", out.stderr


def test_float32_inputs_stay_float32_and_agree_with_float64():
    zs = simulate(_cv(jnp.float64), jax.random.key(0), 50).measurements
    for filt in (KalmanFilter(), UnscentedKalmanFilter()):
        r32 = run_filter(filt, _cv(jnp.float32), zs.astype(jnp.float32))
        r64 = run_filter(filt, _cv(jnp.float64), zs)
        assert r32.filtered_mean.dtype == r32.filtered_cov.dtype == r32.log_likelihood.dtype == jnp.float32
        # A well-conditioned 4-state tracker loses about 5 of float32's 7 digits at most.
        np.testing.assert_allclose(r32.filtered_mean, r64.filtered_mean, rtol=1e-4, atol=1e-3)
        np.testing.assert_allclose(r32.filtered_cov, r64.filtered_cov, rtol=1e-4, atol=1e-4)
        np.testing.assert_allclose(r32.log_likelihood, r64.log_likelihood, rtol=1e-5)
    mc = monte_carlo(_cv(jnp.float32), jax.random.key(0), 200, num_steps=20, progress=False)
    assert mc.anees.dtype == jnp.float32

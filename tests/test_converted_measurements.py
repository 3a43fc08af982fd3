"""Unbiased converted measurements (Longbin et al. 1998) against a 10⁶-sample Monte Carlo.

Bounds (stated once, used throughout). With N = 10⁶ samples (``jax.random``, fixed keys):

- **bias**: each component of the sample mean error lies within ±4 standard errors
  (SE = sample std / √N). For a normal sample mean that is a two-sided 99.994% interval
  (false alarm 6.3e-5 per component).
- **covariance**: each sample second moment ``mean(e_i e_j)`` (about the known mean) lies within
  ±4 SE of the predicted entry, SE = std(e_i e_j) / √N (the CLT bound of a sample moment; for
  Gaussian errors on the diagonal it is the χ²_N bound σ²(1 ± 4√(2/N)) — used here with the
  sample kurtosis because polar→Cartesian errors at σ_θ = 0.1 rad are not Gaussian).

The geometry is the large-cross-range-error case r = 10 km, σ_θ = 0.1 rad (cross-range σ ≈ 1 km
against σ_r = 50 m), where the plain conversion ``r_m [cos θ_m, sin θ_m]`` with the linearised
covariance is biased by ≈ (1 − e^{−σ²/2}) r ≈ 50 m (~50 SE) and its covariance misses the
second-order r²σ_θ⁴/2 range-direction term: both fail the same bounds (shown below).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.models import unbiased_polar_to_cartesian, unbiased_spherical_to_cartesian

N = 1_000_000
Z_BOUND = 4.0
R_TRUE, THETA, SIG_R, SIG_T = 10_000.0, 0.6, 50.0, 0.1
ALPHA, EPS, SIG_E = -2.2, 0.35, 0.05


def _within(stat_samples: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """|mean − predicted| in standard errors, per column of ``stat_samples`` ``(N, q)``."""
    mean = stat_samples.mean(axis=0)
    se = stat_samples.std(axis=0, ddof=1) / np.sqrt(stat_samples.shape[0])
    return np.abs(mean - predicted) / se


def _second_moments(e: np.ndarray) -> np.ndarray:
    """``e_i e_j`` for i ≤ j, shape ``(N, q)``."""
    i, j = np.triu_indices(e.shape[1])
    return e[:, i] * e[:, j]


def _upper(M: np.ndarray) -> np.ndarray:
    return M[np.triu_indices(M.shape[0])]


def _noise(key, d):
    return np.asarray(jax.random.normal(key, (N, d)))


def _plain_polar(z):
    """The classical conversion and its linearised covariance J R Jᵀ at the measurement."""
    r, t = z[..., 0], z[..., 1]
    pos = np.stack([r * np.cos(t), r * np.sin(t)], -1)
    return pos


def _plain_cov(r, t):
    J = np.array([[np.cos(t), -r * np.sin(t)], [np.sin(t), r * np.cos(t)]])
    return J @ np.diag([SIG_R**2, SIG_T**2]) @ J.T


# ------------------------------------------------------------------------------------------------
# 2-D
# ------------------------------------------------------------------------------------------------


def test_polar_given_truth_unbiased_and_covariance_within_bounds():
    n = _noise(jax.random.key(0), 2)
    z = np.stack([R_TRUE + SIG_R * n[:, 0], THETA + SIG_T * n[:, 1]], -1)
    truth = R_TRUE * np.array([np.cos(THETA), np.sin(THETA)])
    conv = unbiased_polar_to_cartesian(z, (SIG_R, SIG_T))
    e = np.asarray(conv.position) - truth
    # Bias: unbiased conversion inside ±4 SE.
    dev = _within(e, np.zeros(2))
    assert np.all(dev < Z_BOUND), dev
    # Covariance given the truth, Cov(x_u | x): inside ±4 SE entrywise.
    predicted = unbiased_polar_to_cartesian(np.array([R_TRUE, THETA]), (SIG_R, SIG_T), given="truth")
    np.testing.assert_allclose(predicted.position, truth, rtol=1e-14)
    dev_cov = _within(_second_moments(e), _upper(np.asarray(predicted.cov)))
    assert np.all(dev_cov < Z_BOUND), dev_cov
    # The plain conversion fails the same bounds: bias ~50 SE and the linearised covariance.
    e_plain = _plain_polar(z) - truth
    dev_plain = _within(e_plain, np.zeros(2))
    assert np.all(dev_plain > Z_BOUND), dev_plain  # measured: 73 and 34 SE
    centred = e_plain - e_plain.mean(axis=0)
    dev_plain_cov = _within(_second_moments(centred), _upper(_plain_cov(R_TRUE, THETA)))
    assert dev_plain_cov.max() > Z_BOUND, dev_plain_cov


def test_polar_given_measurement_mse_within_bounds():
    # Fix the measurement; the truth is r_m − ṽ_r, θ_m − ṽ_θ (Longbin et al.'s conditioning).
    z_m = np.array([R_TRUE, THETA])
    n = _noise(jax.random.key(1), 2)
    r, t = z_m[0] - SIG_R * n[:, 0], z_m[1] - SIG_T * n[:, 1]
    conv = unbiased_polar_to_cartesian(z_m, (SIG_R, SIG_T))
    e = np.asarray(conv.position)[None, :] - np.stack([r * np.cos(t), r * np.sin(t)], -1)
    # x_u is not the conditional mean: E[x_u − x | z_m] = (1/λ − λ) r_m [cos, sin].
    lam = np.exp(-0.5 * SIG_T**2)
    offset = (1 / lam - lam) * R_TRUE * np.array([np.cos(THETA), np.sin(THETA)])
    assert np.all(_within(e, offset) < Z_BOUND)
    # The MSE matrix eqs. (7a)-(7c), about zero.
    dev = _within(_second_moments(e), _upper(np.asarray(conv.cov)))
    assert np.all(dev < Z_BOUND), dev
    # Longbin eqs. (7a)-(7c) written out.
    lp, c, s = lam**4, np.cos(THETA), np.sin(THETA)
    a, b = (lam**-2 - 2) * R_TRUE**2, 0.5 * (R_TRUE**2 + SIG_R**2)
    R = np.array([[a * c * c + b * (1 + lp * np.cos(2 * THETA)), a * c * s + b * lp * np.sin(2 * THETA)],
                  [a * c * s + b * lp * np.sin(2 * THETA), a * s * s + b * (1 - lp * np.cos(2 * THETA))]])
    np.testing.assert_allclose(conv.cov, R, rtol=1e-13)


# ------------------------------------------------------------------------------------------------
# 3-D
# ------------------------------------------------------------------------------------------------


def _sph(r, a, e):
    return np.stack([r * np.cos(e) * np.cos(a), r * np.cos(e) * np.sin(a), r * np.sin(e)], -1)


def test_spherical_given_truth_unbiased_and_covariance_within_bounds():
    std = (SIG_R, SIG_T, SIG_E)
    n = _noise(jax.random.key(2), 3)
    z = np.stack([R_TRUE + SIG_R * n[:, 0], ALPHA + SIG_T * n[:, 1], EPS + SIG_E * n[:, 2]], -1)
    truth = _sph(R_TRUE, ALPHA, EPS)
    e = np.asarray(unbiased_spherical_to_cartesian(z, std).position) - truth
    dev = _within(e, np.zeros(3))
    assert np.all(dev < Z_BOUND), dev
    predicted = unbiased_spherical_to_cartesian(np.array([R_TRUE, ALPHA, EPS]), std, given="truth")
    np.testing.assert_allclose(predicted.position, truth, rtol=1e-14)
    dev_cov = _within(_second_moments(e), _upper(np.asarray(predicted.cov)))
    assert np.all(dev_cov < Z_BOUND), dev_cov
    # Plain conversion: biased by many SE.
    assert _within(_sph(z[:, 0], z[:, 1], z[:, 2]) - truth, np.zeros(3)).max() > 10 * Z_BOUND


def test_spherical_given_measurement_mse_within_bounds():
    std = (SIG_R, SIG_T, SIG_E)
    z_m = np.array([R_TRUE, ALPHA, EPS])
    n = _noise(jax.random.key(3), 3)
    truth = _sph(z_m[0] - SIG_R * n[:, 0], z_m[1] - SIG_T * n[:, 1], z_m[2] - SIG_E * n[:, 2])
    conv = unbiased_spherical_to_cartesian(z_m, std)
    e = np.asarray(conv.position)[None, :] - truth
    dev = _within(_second_moments(e), _upper(np.asarray(conv.cov)))
    assert np.all(dev < Z_BOUND), dev


# ------------------------------------------------------------------------------------------------
# Conventions, batching, errors
# ------------------------------------------------------------------------------------------------


def test_spherical_reduces_to_polar_and_compass_convention():
    for given in ("measurement", "truth"):
        s = unbiased_spherical_to_cartesian(np.array([R_TRUE, THETA, 0.0]), (SIG_R, SIG_T, 0.0), given=given)
        p = unbiased_polar_to_cartesian(np.array([R_TRUE, THETA]), (SIG_R, SIG_T), given=given)
        np.testing.assert_allclose(s.position[:2], p.position, rtol=1e-14)
        np.testing.assert_allclose(s.cov[:2, :2], p.cov, rtol=1e-12)
        np.testing.assert_allclose(s.cov[2], 0.0, atol=1e-9)
    compass = unbiased_polar_to_cartesian(np.array([R_TRUE, 0.5 * np.pi - THETA]), (SIG_R, SIG_T), azimuth="compass")
    math = unbiased_polar_to_cartesian(np.array([R_TRUE, THETA]), (SIG_R, SIG_T))
    np.testing.assert_allclose(compass.position, math.position, rtol=1e-14)
    np.testing.assert_allclose(compass.cov, math.cov, rtol=1e-12)


def test_vmap_matches_batch_and_grad_is_finite():
    z = jnp.stack([jnp.linspace(1e3, 2e4, 5), jnp.linspace(-3.0, 3.0, 5), jnp.linspace(-0.2, 0.8, 5)], -1)
    std = jnp.array([30.0, 0.02, 0.03])
    batch = unbiased_spherical_to_cartesian(z, std)
    mapped = jax.vmap(unbiased_spherical_to_cartesian, in_axes=(0, None))(z, std)
    np.testing.assert_allclose(mapped.position, batch.position, rtol=1e-14)
    np.testing.assert_allclose(mapped.cov, batch.cov, rtol=1e-14)
    assert batch.position.shape == (5, 3) and batch.cov.shape == (5, 3, 3)
    g = jax.grad(lambda s: jnp.trace(unbiased_spherical_to_cartesian(z[0], s).cov))(std)
    assert np.all(np.isfinite(np.asarray(g)))
    assert np.all(np.linalg.eigvalsh(np.asarray(batch.cov)) > 0)


def test_converted_errors():
    with pytest.raises(InputError, match="`measurement`"):
        unbiased_polar_to_cartesian(np.zeros(3), (1.0, 0.1))
    with pytest.raises(InputError, match="`noise_std`"):
        unbiased_spherical_to_cartesian(np.ones(3), (1.0, 0.1))
    with pytest.raises(InputError, match="`noise_std`"):
        unbiased_polar_to_cartesian(np.ones(2), (1.0, -0.1))
    with pytest.raises(InputError, match="`azimuth`"):
        unbiased_polar_to_cartesian(np.ones(2), (1.0, 0.1), azimuth="north")
    with pytest.raises(InputError, match="`given`"):
        unbiased_polar_to_cartesian(np.ones(2), (1.0, 0.1), given="both")

"""jaxtrack.montecarlo.circular_error_probable: closed forms, a quadrature oracle, Monte Carlo, errors."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import integrate, optimize

from jaxtrack import InputError
from jaxtrack.montecarlo import circular_error_probable, monte_carlo_map

KEY = jax.random.key(20260907)


def _cep_oracle(cov, p=0.5):
    s1, s2 = np.sqrt(np.linalg.eigvalsh(cov))

    def prob(R):
        def f(th):
            a = np.cos(th) ** 2 / s1 ** 2 + np.sin(th) ** 2 / s2 ** 2
            return (1 - np.exp(-R * R * a / 2)) / a
        return integrate.quad(f, 0, 2 * np.pi, epsabs=1e-14, epsrel=1e-13, limit=400)[0] / (2 * np.pi * s1 * s2) - p

    return optimize.brentq(prob, 1e-9, 10 * s2, xtol=1e-14)


def test_circular_closed_form():
    # P(‖x‖ ≤ R) = 1 − exp(−R²/2σ²): R = sqrt(−2 ln(1 − p)) σ, 1.1774100 σ for p = 0.5
    assert_allclose(float(circular_error_probable(jnp.eye(2))), 1.1774100225154747, rtol=1e-12)
    for sigma, p in ((0.3, 0.5), (7.0, 0.9), (2.0, 0.1)):
        got = float(circular_error_probable(sigma ** 2 * jnp.eye(2), p))
        assert_allclose(got, math.sqrt(-2.0 * math.log(1.0 - p)) * sigma, rtol=1e-12)


def test_cep_exact_against_polar_integral_and_limits():
    assert_allclose(float(circular_error_probable(4.0 * jnp.eye(2))), 2 * math.sqrt(2 * math.log(2)), rtol=1e-12)
    covs = [np.array([[9.0, 2.0], [2.0, 1.0]]), np.array([[1.0, 0.0], [0.0, 100.0]]), np.array([[4.0, -1.9], [-1.9, 1.0]])]
    got = np.asarray(circular_error_probable(jnp.asarray(np.stack(covs))))
    assert got.shape == (3,)
    assert_allclose(got, [_cep_oracle(c) for c in covs], rtol=1e-9)
    assert_allclose(float(circular_error_probable(covs[0], 0.95)), _cep_oracle(covs[0], 0.95), rtol=1e-9)
    thin = float(circular_error_probable(jnp.diag(jnp.array([1.0, 1e-10]))))
    assert_allclose(thin, 0.6744897501960817, rtol=1e-4)  # 1-D median of |x|
    # the engineering approximation 0.5887(σ1 + σ2) for a moderately elliptical Gaussian
    s = np.sqrt(np.linalg.eigvalsh(covs[0]))
    assert_allclose(float(circular_error_probable(covs[0])), 0.5887 * s.sum(), rtol=0.05)


def test_cep_is_differentiable():
    c = jnp.array([[9.0, 2.0], [2.0, 1.0]])
    g = jax.grad(lambda s: circular_error_probable(s * c))(1.0)
    assert_allclose(float(g), 0.5 * float(circular_error_probable(c)), rtol=1e-8)  # CEP ∝ √scale
    # and under jit (the positive-definiteness check is skipped for tracers)
    assert_allclose(float(jax.jit(circular_error_probable)(c)), float(circular_error_probable(c)), rtol=1e-14)


def _inside(key, args):
    chol, radius = args
    x = chol @ jax.random.normal(key, (2,), dtype=chol.dtype)
    return jnp.sum(x * x) <= radius ** 2


def test_cep_against_monte_carlo_within_binomial_bound():
    cov = jnp.array([[9.0, 2.0], [2.0, 1.0]])
    radius = circular_error_probable(cov)
    n = 20_000
    inside = int(monte_carlo_map(_inside, KEY, n, args=(jnp.linalg.cholesky(cov), radius)))
    # the count is Binomial(n, 1/2): 4.5 standard deviations is a false-alarm rate below 1e-5
    assert abs(inside / n - 0.5) <= 4.5 * math.sqrt(0.25 / n), inside / n


def test_follows_input_dtype():
    c32 = jnp.eye(2, dtype=jnp.float32)
    assert circular_error_probable(c32).dtype == jnp.float32
    assert_allclose(float(circular_error_probable(c32)), 1.1774100, rtol=1e-5)


def test_bad_inputs_raise_input_error():
    with pytest.raises(InputError, match="positive definite"):
        circular_error_probable(jnp.diag(jnp.array([1.0, 0.0])))
    with pytest.raises(InputError, match="cov"):
        circular_error_probable(jnp.eye(3))
    with pytest.raises(InputError, match="probability"):
        circular_error_probable(jnp.eye(2), 1.0)

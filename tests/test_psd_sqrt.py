"""Derivative of the noise factor ``psd_sqrt`` (``L Lᵀ = Q``) that every simulation draws with.

Before its custom JVP, ``jax.grad`` of anything simulated with respect to the truth's noise
level was NaN: every kinematic model's ``Q = Q₁ ⊗ I`` repeats its eigenvalues, and JAX's ``eigh``
derivative divides by their differences. Oracles: the identity ``d(L Lᵀ) = dQ``; central
differences where the eigenvalues are distinct (the factor is smooth there); and, for the
repeated case, the analytic derivative of an expectation (the state covariance of a constant-
velocity model is linear in q) against the Monte Carlo average of the pathwise gradients.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxtrack.models import constant_velocity
from jaxtrack.montecarlo import simulate
from jaxtrack.montecarlo._simulate import psd_sqrt

Q1 = np.array([[1 / 3, 1 / 2], [1 / 2, 1.0]])  # white-noise-acceleration block, τ = 1 s


def test_repeated_eigenvalues_give_a_finite_exact_factor_derivative():
    q = jnp.asarray(np.kron(Q1, np.eye(2)))  # eigenvalues repeated twice
    dq = jnp.asarray(np.kron([[0.2, 0.1], [0.1, 0.5]], np.eye(2)))
    _, tangent = jax.jvp(lambda c: psd_sqrt(c) @ psd_sqrt(c).T, (q,), (dq,))
    np.testing.assert_allclose(tangent, dq, rtol=0, atol=1e-14)
    g = jax.grad(lambda s: jnp.sum(psd_sqrt(s * q) ** 3))(1.3)
    assert np.isfinite(g)


def test_singular_cov_has_a_finite_derivative():
    q = jnp.diag(jnp.array([0.0, 0.0, 2.0, 2.0]))  # noise on the velocities only
    g = jax.grad(lambda s: jnp.sum(psd_sqrt(s * q) ** 2))(0.7)
    # Σ L² = tr(L Lᵀ) = tr(s Q) → derivative tr(Q) = 4
    np.testing.assert_allclose(g, 4.0, rtol=1e-12)


def test_distinct_eigenvalues_match_central_differences():
    a = jnp.array([[4.0, 1.0, 0.2], [1.0, 3.0, 0.5], [0.2, 0.5, 2.0]])
    jac = jax.jacfwd(psd_sqrt)(a)
    for i, j in [(0, 0), (0, 1), (1, 2), (2, 2)]:
        e = jnp.zeros((3, 3)).at[i, j].set(1.0).at[j, i].set(1.0)
        h = 1e-6
        fd = (psd_sqrt(a + h * e) - psd_sqrt(a - h * e)) / (2 * h)
        np.testing.assert_allclose(jnp.einsum("abkl,kl->ab", jac, e), fd, rtol=0, atol=1e-8)


def test_pathwise_gradient_of_an_expectation_is_unbiased():
    """d/dq E[|p_T|²] for 2-D constant velocity, q the acceleration PSD, from 4000 simulated
    runs' pathwise gradients, against the analytic value: E[|p_T|²] = |E p_T|² + tr P_pos(T) and
    P is affine in q, so the derivative is tr of the position block of Σ_k Φ^(T-k) Q₁⊗I Φᵀ^(T-k).
    Tolerance: 4 standard errors of the mean gradient (≈ 99.99 % for a normal mean)."""
    T, num = 10, 4000
    m0, p0 = jnp.array([0.0, 0.0, 1.0, -1.0]), jnp.eye(4)

    def build(q):
        return constant_velocity(1.0, dim=2, accel_psd=q, measurement_std=5.0, initial_mean=m0, initial_cov=p0)

    def f(q, key):
        x = simulate(build(q), key, T).states
        return jnp.sum(x[-1, :2] ** 2)

    keys = jax.vmap(lambda i: jax.random.fold_in(jax.random.key(11), i))(jnp.arange(num))
    grads = jax.jit(jax.vmap(jax.grad(f), in_axes=(None, 0)))(0.7, keys)
    assert np.all(np.isfinite(grads))
    phi = np.block([[np.eye(2), np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])
    dq = np.kron(Q1, np.eye(2))
    # under first_step="update" x_0 is the prior draw, so T-1 transitions reach x_{T-1}
    d_cov = sum(np.linalg.matrix_power(phi, j) @ dq @ np.linalg.matrix_power(phi, j).T for j in range(T - 1))
    exact = np.trace(d_cov[:2, :2])
    mean, se = float(np.mean(grads)), float(np.std(grads, ddof=1) / np.sqrt(num))
    assert abs(mean - exact) <= 4 * se, (mean, exact, se)
    assert se < 0.05 * exact  # the check has power: the standard error is small against the value

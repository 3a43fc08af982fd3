"""Batch linear estimation and observability (jaxtrack.estimation) against dense NumPy references."""

import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import estimation as est
from jaxtrack._validation import InputError


def _spd(rng, n, scale=1.0):
    a = rng.normal(size=(n, n))
    return scale * (a @ a.T + n * np.eye(n))


def _cv(dt):
    return np.array([[1.0, dt], [0.0, 1.0]])


# ------------------------------------------------------------------------------ observability


def test_observability_matches_numpy_svd_and_eigh():
    rng = np.random.default_rng(0)
    K, m, n = 6, 3, 5
    h = rng.normal(size=(K, m, n)) * np.array([1.0, 10.0, 1e3, 0.1, 1.0])
    o = est.observability(h)
    a = h.reshape(K * m, n)
    np.testing.assert_allclose(o.gramian, a.T @ a, rtol=1e-12)
    np.testing.assert_allclose(o.singular_values, np.linalg.svd(a, compute_uv=False), rtol=1e-12)
    s = np.sqrt(np.diag(a.T @ a))
    mn = (a.T @ a) / np.outer(s, s)
    ev, vec = np.linalg.eigh(mn)
    np.testing.assert_allclose(o.column_norms, s, rtol=1e-12)
    np.testing.assert_allclose(o.eigenvalues, ev, rtol=1e-10)
    np.testing.assert_allclose(np.abs(np.sum(np.asarray(o.eigenvectors) * vec, axis=0)), 1.0, rtol=1e-10)
    assert float(o.condition) == pytest.approx(ev[-1] / ev[0], rel=1e-10)
    assert float(jnp.trace(jnp.diag(o.eigenvalues))) == pytest.approx(n, rel=1e-12)  # scale-free
    assert o.rank() == n and o.num_null() == 0
    # The stacked (K·m, n) form gives the same spectrum and Gramian.
    o2 = est.observability(a)
    np.testing.assert_allclose(o2.singular_values, o.singular_values, rtol=1e-12)
    np.testing.assert_allclose(o2.gramian, o.gramian, rtol=1e-12)
    # Without normalisation the eigenvalues are those of M = AᵀA itself, σ² ascending.
    o3 = est.observability(h, normalize=False)
    sigma2 = np.sort(np.asarray(o.singular_values) ** 2)
    np.testing.assert_allclose(o3.eigenvalues, sigma2, rtol=1e-9, atol=1e-13 * sigma2[-1])  # eigh: abs error ~ε·λ_max
    np.testing.assert_array_equal(o3.column_norms, np.ones(n))


def test_observability_of_textbook_constant_velocity_cases():
    """x = [position, velocity], Φ = [[1, T], [0, 1]]: position measurements observe both states,
    velocity measurements never observe the position (null direction [1, 0])."""
    K, dt = 5, 2.0
    phis = np.stack([np.linalg.matrix_power(_cv(dt), k) for k in range(K)])
    pos = est.observability(np.tile([[[1.0, 0.0]]], (K, 1, 1)), transitions=phis)
    assert pos.rank() == 2 and pos.num_null() == 0
    vel = est.observability(np.tile([[[0.0, 1.0]]], (K, 1, 1)), transitions=phis, normalize=False)
    assert vel.rank() == 1 and vel.num_null() == 1
    np.testing.assert_allclose(np.abs(vel.physical_direction(0)), [1.0, 0.0], atol=1e-12)
    # One position measurement alone leaves the velocity unobservable.
    single = est.observability(np.array([[[1.0, 0.0]]]), transitions=phis[:1], normalize=False)
    assert single.rank() == 1
    np.testing.assert_allclose(np.abs(single.physical_direction(0)), [0.0, 1.0], atol=1e-12)


def test_observability_follows_dtype_and_rejects_bad_input():
    h = np.random.default_rng(1).normal(size=(4, 2, 3)).astype(np.float32)
    o = est.observability(h)
    assert o.eigenvalues.dtype == jnp.float32 and o.singular_values.dtype == jnp.float32
    with pytest.raises(InputError, match="measurement_matrices"):
        est.observability(np.ones(3))
    with pytest.raises(InputError, match="measurement_matrices"):
        est.observability(np.array([[np.nan, 1.0]]))
    with pytest.raises(InputError, match="transitions"):
        est.observability(np.ones((4, 2, 3)), transitions=np.ones((4, 2, 2)))


# ------------------------------------------------------------------------------ least squares


@pytest.mark.parametrize("k", [3, 9])
def test_gain_and_information_forms_match_dense_bayes(k):
    rng = np.random.default_rng(k)
    n = 4
    P, R, A = _spd(rng, n), _spd(rng, k, 0.3), rng.normal(size=(k, n))
    B = P @ A.T @ np.linalg.inv(R + A @ P @ A.T)
    C = np.linalg.inv(np.linalg.inv(P) + A.T @ np.linalg.inv(R) @ A)
    for form in ("gain", "information"):
        np.testing.assert_allclose(est.linear_estimator_matrix(P, A, R, form=form), B, rtol=1e-10, atol=1e-13)
        np.testing.assert_allclose(est.posterior_covariance(P, A, R, form=form), C, rtol=1e-10, atol=1e-12)
    with pytest.raises(InputError, match="form"):
        est.posterior_covariance(P, A, R, form="joseph")
    with pytest.raises(InputError, match="R"):
        est.linear_estimator_matrix(P, A, R[:-1, :-1])


def test_batch_estimate_is_the_bayesian_posterior():
    rng = np.random.default_rng(2)
    k, n = 7, 4
    A, Z, R = rng.normal(size=(k, n)), rng.normal(size=k), _spd(rng, k, 0.1)
    m0, P0, phi = rng.normal(size=n), _spd(rng, n), np.eye(n) + 0.3 * rng.normal(size=(n, n))
    prior_mean, prior_cov = phi @ m0, phi @ P0 @ phi.T
    Ri = np.linalg.inv(R)
    cov = np.linalg.inv(np.linalg.inv(prior_cov) + A.T @ Ri @ A)
    mean = cov @ (A.T @ Ri @ Z + np.linalg.solve(prior_cov, prior_mean))
    b = est.batch_estimate(A, Z, R, m0, P0, phi)
    np.testing.assert_allclose(b.cov, cov, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(b.mean, mean, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(b.pseudo_inverse, cov @ A.T @ Ri, rtol=1e-9, atol=1e-12)
    # The blocks form with the propagated prior gives the same posterior (diagonal R: one row per block).
    Rd = np.diag(np.diag(R))
    wb = est.batch_estimate(A, Z, Rd, m0, P0, phi)
    w = est.weighted_least_squares(A[:, None, :], Z[:, None], np.diag(R)[:, None, None], prior_cov, prior_mean=prior_mean)
    np.testing.assert_allclose(w.mean, wb.mean, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(w.cov, wb.cov, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(w.pseudo_inverse, wb.pseudo_inverse, rtol=1e-9, atol=1e-12)


def test_weighted_least_squares_matches_lstsq():
    rng = np.random.default_rng(3)
    K, m, n = 10, 3, 5
    H, Z = rng.normal(size=(K, m, n)), rng.normal(size=(K, m))
    R = np.stack([_spd(rng, m, 0.2) for _ in range(K)])
    # Whiten each block with its Cholesky factor and solve by dense least squares.
    L = np.linalg.cholesky(R)
    Hw = np.concatenate([np.linalg.solve(L[k], H[k]) for k in range(K)])
    Zw = np.concatenate([np.linalg.solve(L[k], Z[k]) for k in range(K)])
    ref = np.linalg.lstsq(Hw, Zw, rcond=None)[0]
    w = est.weighted_least_squares(H, Z, R)
    np.testing.assert_allclose(w.mean, ref, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(w.cov, np.linalg.inv(Hw.T @ Hw), rtol=1e-10)
    np.testing.assert_allclose(w.pseudo_inverse @ Z.ravel(), ref, rtol=1e-10, atol=1e-12)
    # A shared (m, m) covariance broadcasts; stacked rows take variances.
    shared = est.weighted_least_squares(H, Z, R[0])
    np.testing.assert_allclose(shared.mean, est.weighted_least_squares(H, Z, np.broadcast_to(R[0], R.shape)).mean)
    a, z = H[:, 0, :], Z[:, 0]
    np.testing.assert_allclose(est.weighted_least_squares(a, z, 0.5).mean, np.linalg.lstsq(a, z, rcond=None)[0],
                               rtol=1e-10)
    # The stacked-row pseudo-inverse form agrees with lstsq too.
    ls = est.least_squares_estimate(a, z, 0.5 * np.eye(K))
    np.testing.assert_allclose(ls.mean, np.linalg.lstsq(a, z, rcond=None)[0], rtol=1e-10)
    np.testing.assert_allclose(ls.cov, np.linalg.inv(a.T @ a / 0.5), rtol=1e-10)
    with pytest.raises(InputError, match="prior_mean"):
        est.weighted_least_squares(H, Z, R, prior_mean=np.zeros(n))
    with pytest.raises(InputError, match="Z"):
        est.weighted_least_squares(H, Z[:-1], R)


def test_minimum_norm_for_underdetermined_problem():
    rng = np.random.default_rng(4)
    A, Z = rng.normal(size=(2, 4)), rng.normal(size=2)
    np.testing.assert_allclose(est.minimum_norm_estimate(A, Z), np.linalg.lstsq(A, Z, rcond=None)[0], rtol=1e-10)
    ls = est.least_squares_estimate(A, Z, np.eye(2))  # singular AᵀA: pseudo-inverse → minimum norm (eq. 52)
    np.testing.assert_allclose(ls.mean, np.linalg.lstsq(A, Z, rcond=None)[0], rtol=1e-8, atol=1e-10)
    phi = np.eye(4) + 0.2 * rng.normal(size=(4, 4))
    x = np.asarray(est.minimum_norm_estimate(A, Z, phi))
    np.testing.assert_allclose(A @ x, Z, rtol=1e-10)  # still fits the data exactly


def test_least_squares_follows_float32():
    rng = np.random.default_rng(5)
    A, Z = rng.normal(size=(6, 3)).astype(np.float32), rng.normal(size=6).astype(np.float32)
    assert est.least_squares_estimate(A, Z, np.eye(6, dtype=np.float32)).mean.dtype == jnp.float32
    assert est.weighted_least_squares(A, Z, np.float32(1.0)).mean.dtype == jnp.float32

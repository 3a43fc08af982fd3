"""Batch linear estimation: weighted least squares, with or without a Gaussian prior.

For ``Z = A x + v``, ``v ~ N(0, R)`` and a prior ``x ~ N(x̄, P)`` the posterior (Bayesian linear
estimate) is ``x̂ = x̄ + B (Z − A x̄)`` with the estimator matrix ``B`` in the *gain* form
``P Aᵀ (R + A P Aᵀ)⁻¹`` or the equal *information* form ``(P⁻¹ + AᵀR⁻¹A)⁻¹ AᵀR⁻¹`` (matrix
inversion lemmas B-1, B-2 of Lindgren & Gong 1977). Without a prior it is weighted least squares;
when ``AᵀR⁻¹A`` is singular the pseudo-inverse gives the minimum-norm solution.
The Kalman filter started from the same prior reaches the same numbers recursively.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError, check_shape

__all__ = [
    "LinearEstimate",
    "linear_estimator_matrix",
    "posterior_covariance",
    "batch_estimate",
    "least_squares_estimate",
    "minimum_norm_estimate",
    "weighted_least_squares",
]

_FORMS = ("gain", "information")


class LinearEstimate(eqx.Module):
    """A batch linear estimate.

    - ``mean`` ``(n,)``: the estimate ``x̂``.
    - ``cov`` ``(n, n)``: its error covariance (the posterior covariance when a prior is used).
    - ``pseudo_inverse`` ``(n, k)``: the matrix ``Ã# = P AᵀR⁻¹`` that multiplies the data
      (Lindgren & Gong eq. 61); ``k`` counts all scalar measurements (``K·m`` for blocks).
    """

    mean: Float[Array, " n"]
    cov: Float[Array, "n n"]
    pseudo_inverse: Float[Array, "n k"]


def _arrays(*arrays):
    dtype = jnp.result_type(*arrays, float)
    return tuple(jnp.asarray(a, dtype) for a in arrays)


def _check_form(form: str) -> None:
    if form not in _FORMS:
        raise InputError(f"`form` must be 'gain' or 'information'; got {form!r}.")


def _check_stacked(A, R, P=None, Z=None):
    check_shape("A", A, [(None, None)])
    k, n = A.shape
    check_shape("R", R, [(k, k)])
    if P is not None:
        check_shape("prior_cov", P, [(n, n)])
    if Z is not None:
        check_shape("Z", Z, [(k,)])


def linear_estimator_matrix(prior_cov: ArrayLike, A: ArrayLike, R: ArrayLike, *, form: str = "gain") -> Array:
    """Estimator matrix ``B`` of the Bayesian linear estimate ``x̂ = x̄ + B (Z − A x̄)`` (Lindgren & Gong eq. 30).

    ``form="gain"``: ``B = P Aᵀ [R + A P Aᵀ]⁻¹``; ``form="information"``: ``B = [P⁻¹ + AᵀR⁻¹A]⁻¹ AᵀR⁻¹``.
    The two are equal by the matrix inversion lemma (B-1).

    **Arguments:** ``prior_cov`` P ``(n, n)``; ``A`` ``(k, n)``; ``R`` ``(k, k)``; ``form`` as above.

    **Returns:** ``B`` ``(n, k)``.
    """
    _check_form(form)
    P, A, R = _arrays(prior_cov, A, R)
    _check_stacked(A, R, P)
    if form == "gain":
        return jnp.linalg.solve(R + A @ P @ A.T, A @ P.T).T
    Ri_A = jnp.linalg.solve(R, A)
    return jnp.linalg.solve(jnp.linalg.inv(P) + A.T @ Ri_A, Ri_A.T)


def posterior_covariance(prior_cov: ArrayLike, A: ArrayLike, R: ArrayLike, *, form: str = "gain") -> Array:
    """Posterior covariance of the Bayesian linear estimate (Lindgren & Gong eqs. 33, 34).

    ``form="gain"``: ``P − P Aᵀ [R + A P Aᵀ]⁻¹ A P`` (eq. 33); ``form="information"``:
    ``[P⁻¹ + AᵀR⁻¹A]⁻¹`` (eq. 34). Equal by (B-2).

    **Arguments:** ``prior_cov`` P ``(n, n)``; ``A`` ``(k, n)``; ``R`` ``(k, k)``; ``form`` as above.

    **Returns:** ``(n, n)``.
    """
    _check_form(form)
    P, A, R = _arrays(prior_cov, A, R)
    _check_stacked(A, R, P)
    if form == "gain":
        return P - P @ A.T @ jnp.linalg.solve(R + A @ P @ A.T, A @ P)
    return jnp.linalg.inv(jnp.linalg.inv(P) + A.T @ jnp.linalg.solve(R, A))


def batch_estimate(
    A: ArrayLike,
    Z: ArrayLike,
    R: ArrayLike,
    initial_mean: ArrayLike,
    initial_cov: ArrayLike,
    transition: ArrayLike | None = None,
) -> LinearEstimate:
    """Batch form of the Kalman filter after ``k`` measurements (Lindgren & Gong eqs. 34/55, 61, 64).

    The prior on ``x(k)`` is the initial estimate propagated without plant noise,
    ``N(Φ x̂(0|0), Φ P(0|0) Φᵀ)`` with ``Φ = transition = Φ(k, 0)``; then
    ``P(k|k) = [(Φ P₀ Φᵀ)⁻¹ + AᵀR⁻¹A]⁻¹``, ``Ã# = P(k|k) AᵀR⁻¹`` and
    ``x̂(k|k) = Ã# Z + [I − Ã# A] Φ x̂(0|0)``.

    **Arguments:** ``A`` ``(k, n)`` with rows ``H(i) Φ(i, k)``; ``Z`` ``(k,)``; ``R`` ``(k, k)``;
    ``initial_mean`` ``(n,)``; ``initial_cov`` ``(n, n)``; ``transition`` ``(n, n)`` (identity if
    ``None``). Rows of ``A``, ``Z`` and ``R`` in any consistent order.

    **Returns:** :class:`LinearEstimate` (``mean`` ``x̂(k|k)``, ``cov`` ``P(k|k)``, ``pseudo_inverse`` ``Ã#``).
    """
    A, Z, R, m0, P0 = _arrays(A, Z, R, initial_mean, initial_cov)
    _check_stacked(A, R, P0, Z)
    n = A.shape[1]
    check_shape("initial_mean", m0, [(n,)])
    phi = jnp.eye(n, dtype=A.dtype) if transition is None else jnp.asarray(transition, A.dtype)
    check_shape("transition", phi, [(n, n)])
    prior = phi @ P0 @ phi.T
    cov = jnp.linalg.inv(jnp.linalg.inv(prior) + A.T @ jnp.linalg.solve(R, A))
    pinv = cov @ jnp.linalg.solve(R, A).T
    mean = pinv @ Z + (jnp.eye(n, dtype=A.dtype) - pinv @ A) @ (phi @ m0)
    return LinearEstimate(mean, cov, pinv)


def least_squares_estimate(A: ArrayLike, Z: ArrayLike, R: ArrayLike) -> LinearEstimate:
    """Weighted least squares ``x̂_LS = P_LS AᵀR⁻¹ Z``, ``P_LS = (AᵀR⁻¹A)#`` (Lindgren & Gong eqs. 32, 53, 54).

    The (Hermitian) pseudo-inverse makes it the minimum-norm solution (eq. 52) when ``AᵀA`` is
    singular. For badly scaled, full-rank problems prefer :func:`weighted_least_squares`, which
    solves instead of truncating small eigenvalues.

    **Arguments:** ``A`` ``(k, n)``; ``Z`` ``(k,)``; ``R`` ``(k, k)``.

    **Returns:** :class:`LinearEstimate` with ``mean`` x̂_LS, ``cov`` P_LS, ``pseudo_inverse`` ``P_LS AᵀR⁻¹``.
    """
    A, Z, R = _arrays(A, Z, R)
    _check_stacked(A, R, None, Z)
    Ri_A = jnp.linalg.solve(R, A)
    P_ls = jnp.linalg.pinv(A.T @ Ri_A, hermitian=True)
    pinv = P_ls @ Ri_A.T
    return LinearEstimate(P_ls @ (Ri_A.T @ Z), P_ls, pinv)


def minimum_norm_estimate(A: ArrayLike, Z: ArrayLike, transition: ArrayLike | None = None) -> Array:
    """Minimum-norm solution in the metric of ``x(0)``: ``Φ(k,0) [A Φ(k,0)]# Z`` (Lindgren & Gong eq. 31, A15).

    This, not ``A# Z``, is the ``σ₀ → ∞`` limit of the Kalman filter started at ``x̂(0|0) = 0``
    with ``P(0|0) = σ₀² I`` (eqs. 57, 64), because the prior on ``x(k)`` is ``σ₀² Φ Φᵀ``.

    **Arguments:** ``A`` ``(k, n)``; ``Z`` ``(k,)``; ``transition`` ``Φ(k, 0)`` ``(n, n)`` (identity if ``None``).

    **Returns:** ``(n,)``.
    """
    A, Z = _arrays(A, Z)
    check_shape("A", A, [(None, None)])
    check_shape("Z", Z, [(A.shape[0],)])
    n = A.shape[1]
    phi = jnp.eye(n, dtype=A.dtype) if transition is None else jnp.asarray(transition, A.dtype)
    check_shape("transition", phi, [(n, n)])
    return phi @ (jnp.linalg.pinv(A @ phi) @ Z)


def weighted_least_squares(
    H: ArrayLike,
    Z: ArrayLike,
    R: ArrayLike,
    prior_cov: ArrayLike | None = None,
    *,
    prior_mean: ArrayLike | None = None,
) -> LinearEstimate:
    """Batch weighted least squares over measurement blocks, with an optional Gaussian prior.

    ``x̂ = (Σ_k H_kᵀR_k⁻¹H_k + P₀⁻¹)⁻¹ (Σ_k H_kᵀR_k⁻¹Z_k + P₀⁻¹ x̄₀)`` (information form;
    Liu et al., mobile radar registration, spec §2.6 "Equivalence"). Without ``prior_cov`` it is
    plain WLS, the limit of the Kalman filter as ``P₀⁻¹ → 0``; with it, the filter's final estimate
    for a constant state started from ``x̄₀`` (default 0). The information matrix is solved, not
    pseudo-inverted, so badly scaled but full-rank problems keep every digit.

    **Arguments:**

    - ``H``: ``(K, m, n)`` measurement blocks (or ``(k, n)``, one scalar measurement per row).
    - ``Z``: ``(K, m)`` (or ``(k,)``) measurements.
    - ``R``: ``(K, m, m)`` per-block or ``(m, m)`` shared noise covariance; for stacked rows
      ``(k,)`` variances (a full ``(k, k)`` covariance belongs to :func:`least_squares_estimate`).
    - ``prior_cov``: optional ``(n, n)`` prior covariance ``P₀``.
    - ``prior_mean``: optional ``(n,)`` prior mean ``x̄₀`` (needs ``prior_cov``).

    **Returns:** :class:`LinearEstimate`; ``cov`` is the inverse information matrix,
    ``pseudo_inverse`` ``(n, K·m)`` multiplies the flattened ``Z``.
    """
    h, z, r = _arrays(H, Z, R)
    if h.ndim == 2:
        h, z = h[:, None, :], z[..., None]
        if r.ndim <= 1:
            check_shape("R", r, [(), (h.shape[0],)])
            r = jnp.broadcast_to(jnp.reshape(r, (-1, 1, 1)), (h.shape[0], 1, 1))
    check_shape("H", h, [(None, None, None)])
    K, m, n = h.shape
    check_shape("Z", z, [(K, m)])
    check_shape("R", r, [(K, m, m), (m, m)])
    if r.ndim == 2:
        r = jnp.broadcast_to(r, (K, m, m))
    rinv_h = jnp.linalg.solve(r, h)  # (K, m, n)
    info = jnp.einsum("kin,kim->nm", h, rinv_h)
    vec = jnp.einsum("kin,ki->n", rinv_h, z)
    if prior_cov is not None:
        p0 = jnp.asarray(prior_cov, h.dtype)
        check_shape("prior_cov", p0, [(n, n)])
        p0_inv = jnp.linalg.inv(p0)
        info = info + p0_inv
        if prior_mean is not None:
            x0 = jnp.asarray(prior_mean, h.dtype)
            check_shape("prior_mean", x0, [(n,)])
            vec = vec + p0_inv @ x0
    elif prior_mean is not None:
        raise InputError("`prior_mean` needs `prior_cov`.")
    mean = jnp.linalg.solve(info, vec)
    cov = jnp.linalg.inv(info)
    pinv = cov @ jnp.reshape(rinv_h, (K * m, n)).T
    return LinearEstimate(mean, cov, pinv)

"""Measurement updates: one linearised update and one moment update, with the update form as a
strategy.

Every Gaussian filter of :mod:`jaxtrack.filters` conditions through one of two functions:

- :func:`condition_linearized` — a (linearised) measurement matrix ``H``: the Kalman filter, the
  EKF, the consider filter; the covariance form is a strategy (:class:`JosephForm`, default, valid
  for any gain; :class:`StandardForm`, ``P⁺ = (I − W H) P``);
- :func:`condition_on_moments` — the predicted measurement moments ``S``, ``C``: sigma-point
  filters (UKF, cubature).

Missing measurement components never change an array shape (:func:`masked_noise`), so one
compilation serves every mask.
"""

from __future__ import annotations

import abc
import math
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ._linalg import cholesky_and_inverse, matmul, sum_rows, tril_inverse


def symmetrize(a: Array) -> Array:
    """The symmetric part ``(A + Aᵀ)/2`` of a square matrix.

    **Arguments:**

    - ``a``: the matrix, ``(..., d, d)``.

    **Returns:** the symmetric part, ``(..., d, d)``, in the units of ``a``.
    """
    return 0.5 * (a + jnp.swapaxes(a, -1, -2))


class Conditioned(NamedTuple):
    """What one measurement update produces (one step, unbatched)."""

    mean: Float[Array, " n"]
    cov: Float[Array, "n n"]
    innovation: Float[Array, " m"]  # z − ẑ, 0 in missing components
    innovation_cov: Float[Array, "m m"]  # S; identity rows/columns in missing components
    log_likelihood: Float[Array, ""]  # log N(innovation; 0, S) over the observed components
    gain: Float[Array, "n m"]  # W used; zero columns in missing components


def masked_noise(R: Array, observed: Bool[Array, " m"]) -> Array:
    """Measurement noise with missing components decoupled: ``R`` on the observed block, ``I`` else.

    With the matching rows of ``H`` zeroed, ``S = H P Hᵀ + R`` is block diagonal with the identity
    on the missing block, so the gain has zero columns there and ``log det S`` and ``yᵀS⁻¹y`` equal
    those of the observed sub-vector: the update is exactly the one with only the observed rows
    of ``H`` and ``R``, without changing any array shape (so one compilation serves every mask).

    **Arguments:**

    - ``R``: the measurement-noise covariance, ``(m, m)``, in the measurement's units squared.
    - ``observed``: boolean ``(m,)``, True where the component is observed.

    **Returns:** the masked covariance, ``(m, m)``.
    """
    both = observed[:, None] & observed[None, :]
    return jnp.where(both, R, 0.0) + jnp.diag(jnp.where(observed, 0.0, 1.0).astype(R.dtype))


def gaussian_log_likelihood(innovation, innovation_cov_chol, num_observed, chol_inv=None) -> Array:
    """``log N(y; 0, S)`` over ``num_observed`` components, given ``L = chol(S)`` (lower).

    With ``chol_inv = L⁻¹`` the innovation is whitened by a product rather than a triangular
    solve, which stays unbatched on the factor side under ``vmap`` (see ``_linalg``).

    **Arguments:**

    - ``innovation``: ``y``, ``(m,)`` (0 in missing components).
    - ``innovation_cov_chol``: ``L``, lower triangular ``(m, m)``.
    - ``num_observed``: the number of observed components (scalar).
    - ``chol_inv``: optional ``L⁻¹``, ``(m, m)`` (computed if not given).

    **Returns:** the log-likelihood, a scalar.
    """
    if chol_inv is None:
        chol_inv = tril_inverse(innovation_cov_chol)
    whitened = matmul(chol_inv, innovation)
    # Sums over m terms as adds (sum_rows): under vmap a reduction is a kernel of its own per
    # step (README radar UKF, 4,096 runs: 6% of the step), the adds fuse with their neighbours.
    log_det = 2.0 * sum_rows(jnp.log(jnp.diagonal(innovation_cov_chol)))
    return -0.5 * (sum_rows(whitened * whitened) + log_det + num_observed * math.log(2.0 * math.pi))


class AbstractUpdateForm(eqx.Module):
    """How a linearised update forms the filtered covariance from ``P``, ``H``, ``R`` and ``W``.

    A strategy object for :class:`~jaxtrack.filters.KalmanFilter` and
    :class:`~jaxtrack.filters.ExtendedKalmanFilter` (``form=``). ``PHt`` is ``P Hᵀ`` and ``H``, ``R``
    already have missing components removed (:func:`masked_noise`).
    """

    supports_any_gain: eqx.AbstractClassVar[bool]

    @abc.abstractmethod
    def covariance(self, cov: Array, PHt: Array, H: Array, R: Array, gain: Array) -> Array:
        """The filtered covariance ``P⁺`` ``(n, n)`` (symmetric)."""


class JosephForm(AbstractUpdateForm):
    """``P⁺ = (I − W H) P (I − W H)ᵀ + W R Wᵀ`` (Joseph; Ho 1968, eq. (4)): exact for any gain.

    The default. It is the actual error covariance of a filter with a suboptimal or fixed gain,
    and stays symmetric positive semi-definite under rounding.
    """

    supports_any_gain: ClassVar[bool] = True

    def covariance(self, cov, PHt, H, R, gain):
        # Joseph form evaluated through the rank-m structure of I − W H (P is symmetric, so
        # H P = (P Hᵀ)ᵀ): (I − W H) P = P − W (P Hᵀ)ᵀ, and (I − W H) P (I − W H)ᵀ = A P − (A P Hᵀ) Wᵀ
        # with A P = (I − W H) P. The same recursion as forming I − W H and two n×n×n products,
        # in about 4n²m multiply-adds instead of 2n³.
        AP = cov - matmul(gain, PHt.T)
        return AP - matmul(matmul(AP, H.T), gain.T) + matmul(matmul(gain, R), gain.T)


class StandardForm(AbstractUpdateForm):
    """``P⁺ = (I − W H) P = P − W (P Hᵀ)ᵀ`` (the textbook form; e.g. Lindgren & Gong 1978, eq. (38)).

    Valid only with the optimal gain ``W = P Hᵀ S⁻¹`` (a supplied gain raises ``InputError``).
    Cheaper than :class:`JosephForm` by about half, but rounding can make ``P⁺`` indefinite in
    ill-conditioned problems; studies use it where the paper does.
    """

    supports_any_gain: ClassVar[bool] = False

    def covariance(self, cov, PHt, H, R, gain):
        return cov - matmul(gain, PHt.T)


def condition_linearized(
    mean: Array,
    cov: Array,
    innovation: Array,
    H: Array,
    R: Array,
    observed: Array,
    gain: Array | None = None,
    form: AbstractUpdateForm = JosephForm(),
) -> Conditioned:
    """Update with a (linearised) measurement matrix; Joseph form (valid for any gain) by default.

    .. math::

        S = H P Hᵀ + R,\\quad W = P Hᵀ S^{-1}\\ (\\text{unless given}),\\quad
        x⁺ = x + W y,\\quad P⁺ = (I − W H) P (I − W H)ᵀ + W R Wᵀ

    (Ho 1968, eqs. (2)–(4)); ``form=StandardForm()`` gives ``P⁺ = (I − W H) P`` instead (see
    :class:`AbstractUpdateForm`). Missing components (``observed`` False) are removed as described
    in :func:`masked_noise`; a supplied gain has its columns for missing components zeroed.

    **Arguments:**

    - ``mean``: the predicted mean ``x``, ``(n,)``; ``cov``: the predicted covariance ``P``, ``(n, n)``.
    - ``innovation``: ``y = z − ẑ``, ``(m,)``, in the measurement's units.
    - ``H``: the (linearised) measurement matrix, ``(m, n)``; ``R``: the measurement noise, ``(m, m)``.
    - ``observed``: boolean ``(m,)``, True where the component is observed.
    - ``gain``: optional gain ``W``, ``(n, m)`` (default: the optimal gain).
    - ``form``: the covariance update form (default ``JosephForm()``).

    **Returns:** :class:`Conditioned`: the updated mean ``(n,)`` and covariance ``(n, n)``, the
    innovation ``(m,)``, ``S`` ``(m, m)``, the log-likelihood (scalar) and the gain ``(n, m)``.
    """
    obs_f = observed.astype(cov.dtype)
    # A select, not a product with the mask: a missing component's row may be NaN (a sensor's
    # Jacobian where it is undefined, e.g. linearised at the sensor's own position), and a
    # measurement that is not used must not fail the update.
    H = jnp.where(observed[:, None], H, 0.0)
    R = masked_noise(R, observed)
    innovation = jnp.where(observed, innovation, 0.0)
    # Small products go through `matmul` (element-wise loops under vmap, see `_linalg`).
    PHt = matmul(cov, H.T)
    S = symmetrize(matmul(H, PHt) + R)
    chol, chol_inv = cholesky_and_inverse(S)
    if gain is None and S.shape[-1] == 1:
        # A scalar measurement: W = P Hᵀ / S, one division, rounded once (two products with
        # 1/√S round twice, which matters in ill-conditioned recursions such as bearings-only
        # pseudo-linear filters, where P and R are scaled by 10⁸).
        gain = PHt / S[0, 0]
    elif gain is None:
        # W = P Hᵀ S⁻¹ = (P Hᵀ L⁻ᵀ) L⁻¹ with S = L Lᵀ. Products with L⁻¹ rather than a
        # triangular solve: for small m the factor is written out (no LAPACK call per run
        # under vmap), and a factor shared by a batch stays unbatched.
        gain = matmul(matmul(PHt, chol_inv.T), chol_inv)
    else:
        gain = gain * obs_f[None, :]
    new_cov = form.covariance(cov, PHt, H, R, gain)
    # The terms round differently; keep P exactly symmetric so that Cholesky factorisations
    # downstream (next S, smoother, NEES) see a symmetric matrix.
    new_cov = symmetrize(new_cov)
    new_mean = mean + matmul(gain, innovation)
    ll = gaussian_log_likelihood(innovation, chol, jnp.sum(obs_f), chol_inv)
    return Conditioned(new_mean, new_cov, innovation, S, ll, gain)


def condition_on_moments(
    mean: Array,
    cov: Array,
    innovation: Array,
    innovation_cov: Array,
    cross_cov: Array,
    observed: Array,
) -> Conditioned:
    """Update from moments (sigma-point filters): ``W = C S⁻¹``, ``P⁺ = P − W S Wᵀ``.

    ``cross_cov`` is ``C = Cov(x, z)`` (n, m) and ``innovation_cov`` is ``S = Cov(z)`` including R.
    Missing components are removed as in :func:`masked_noise`.

    **Arguments:**

    - ``mean``: the predicted mean, ``(n,)``; ``cov``: the predicted covariance, ``(n, n)``.
    - ``innovation``: ``z − ẑ``, ``(m,)``, in the measurement's units.
    - ``innovation_cov``: ``S``, ``(m, m)``; ``cross_cov``: ``C``, ``(n, m)``.
    - ``observed``: boolean ``(m,)``, True where the component is observed.

    **Returns:** :class:`Conditioned`, as for :func:`condition_linearized`.
    """
    obs_f = observed.astype(cov.dtype)
    both = observed[:, None] & observed[None, :]
    S = jnp.where(both, innovation_cov, 0.0) + jnp.diag(1.0 - obs_f)
    S = symmetrize(S)
    C = cross_cov * obs_f[None, :]
    innovation = jnp.where(observed, innovation, 0.0)
    chol, chol_inv = cholesky_and_inverse(S)
    gain = matmul(matmul(C, chol_inv.T), chol_inv)
    # Symmetric in exact arithmetic; see condition_linearized.
    new_cov = symmetrize(cov - matmul(matmul(gain, S), gain.T))
    new_mean = mean + matmul(gain, innovation)
    ll = gaussian_log_likelihood(innovation, chol, jnp.sum(obs_f), chol_inv)
    return Conditioned(new_mean, new_cov, innovation, S, ll, gain)

"""Square-root Kalman and unscented Kalman filters: Cholesky factors propagated by QR.

A square-root filter never forms a covariance inside its recursion. It carries the lower
Cholesky factor ``L`` (``P = L Lᵀ``) and obtains each new factor as the triangular factor of a
QR decomposition of a *pre-array* whose product with its transpose is the new covariance
(:func:`tria`). A factor times its transpose is positive semidefinite whatever the rounding,
and the factor's condition number is the square root of the covariance's, so the recursion
keeps about twice the significant digits of the covariance form (Kaminski, Bryson & Schmidt
1971, IEEE TAC 16(6); Bierman 1977, ch. V). In float32 this is the difference between a filter
that loses definiteness and one that does not (``tests/test_square_root.py``).

Both filters set ``square_root = True``: their :class:`~jaxtrack.filters.FilterState`,
``StepOutput`` and :class:`~jaxtrack.filters.Conditioned` hold factors (``cov``: ``L``;
``innovation_cov``: the factor of ``S``), :meth:`consistency` scores NEES and NIS by triangular
solves with the factors, and :func:`~jaxtrack.filters.run_filter` returns both the covariances
and the factors.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
from jaxtyping import Array, Float

from .._validation import InputError
from ..models import LinearGaussianModel
from ._base import AbstractFilter, FilterState
from ._linalg import cholesky, matmul
from ._unscented import sigma_points, unscented_weights
from ._updates import Conditioned, masked_noise


def tria(a: Float[Array, "r c"]) -> Float[Array, "r r"]:
    """The lower-triangular ``L`` with ``L Lᵀ = A Aᵀ`` and a non-negative diagonal.

    From the QR decomposition ``Aᵀ = Θ U`` (Householder, backward stable):
    ``A Aᵀ = Uᵀ Θᵀ Θ U = Uᵀ U``, so ``L = Uᵀ`` up to the signs of its columns, which are made
    non-negative so that ``L`` is *the* Cholesky factor when ``A Aᵀ`` is positive definite
    ("Tria" of Arasaratnam & Haykin 2009, IEEE TAC 54(6), §V).

    **Arguments:**

    - ``a``: the pre-array ``A``, ``(r, c)`` with ``c ≥ r``, in the square root of the
      covariance's units.

    **Returns:** ``L``, lower triangular ``(r, r)``.
    """
    u = jnp.linalg.qr(a.T, mode="r")
    sign = jnp.where(jnp.diagonal(u) < 0, -1.0, 1.0).astype(u.dtype)
    return (u * sign[:, None]).T


def psd_cholesky(a: Float[Array, "d d"]) -> Float[Array, "d d"]:
    """A lower-triangular square root ``L`` (``L Lᵀ = a``) of a positive *semi*definite ``a``.

    The Cholesky–Banachiewicz recursion column by column, with a zero column wherever the pivot
    is at most ``d·ε·max(diag a)``. Plant noise is often singular (``Q = 0``, or noise on a few
    states only), where the plain Cholesky factor is NaN; for a positive definite ``a`` the
    result is the Cholesky factor. Gradients are finite away from the zero pivots.

    **Arguments:**

    - ``a``: symmetric positive semidefinite ``(d, d)``.

    **Returns:** ``L``, lower triangular ``(d, d)``, in the square root of ``a``'s units.
    """
    d = a.shape[-1]
    tol = d * jnp.finfo(a.dtype).eps * jnp.max(jnp.abs(jnp.diagonal(a)))
    L = jnp.zeros_like(a)
    for j in range(d):
        s = a[j:, j] - L[j:, :j] @ L[j, :j] if j else a[j:, j]
        positive = s[0] > tol
        # Double `where`: the discarded branch must not produce NaN gradients.
        root = jnp.sqrt(jnp.where(positive, s[0], 1.0))
        L = L.at[j:, j].set(jnp.where(positive, s / root, 0.0))
    return L


def cholesky_rank_one(L: Float[Array, "d d"], v: Float[Array, " d"], sign: float) -> Float[Array, "d d"]:
    """The Cholesky factor of ``L Lᵀ + sign · v vᵀ`` (rank-one update, or downdate for ``sign = −1``).

    The classical ``cholupdate`` recursion (Golub & Van Loan 2013, §6.5.4), one column at a time.
    A downdate that would make the matrix indefinite yields NaN (which the filters report as
    ``ok = False``).

    **Arguments:**

    - ``L``: lower triangular ``(d, d)`` with a positive diagonal; ``v``: ``(d,)``.
    - ``sign``: ``+1.0`` or ``−1.0`` (static).

    **Returns:** the new lower-triangular factor ``(d, d)``.
    """
    d = L.shape[-1]
    for k in range(d):
        r = jnp.sqrt(L[k, k] ** 2 + sign * v[k] ** 2)
        c = r / L[k, k]
        s = v[k] / L[k, k]
        L = L.at[k, k].set(r)
        if k + 1 < d:
            col = (L[k + 1 :, k] + sign * s * v[k + 1 :]) / c
            v = v.at[k + 1 :].set(c * v[k + 1 :] - s * col)
            L = L.at[k + 1 :, k].set(col)
    return L


def _solve_lower(L: Array, b: Array) -> Array:
    return jsl.solve_triangular(L, b, lower=True)


def _log_likelihood(whitened: Array, chol: Array, num_observed: Array) -> Array:
    """``log N(y; 0, S)`` from ``L_S⁻¹ y`` and ``L_S``: no covariance is formed."""
    log_det = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol)))
    return -0.5 * (whitened @ whitened + log_det + num_observed * math.log(2.0 * math.pi))


def _gain(chol_S: Array, cross: Array) -> Array:
    """``W = C S⁻¹ = (C L_S⁻ᵀ) L_S⁻¹`` by two triangular solves, given ``C L_S⁻ᵀ`` (``cross``)."""
    return jsl.solve_triangular(chol_S, cross.T, lower=True, trans="T").T


def _factor_consistency(conditioned: Conditioned, error: Array, components=None) -> tuple[Array, Array]:
    """NEES and NIS from the factors: ``‖L⁻¹ e‖²`` and ``‖L_S⁻¹ y‖²``, never forming ``P``.

    For a sub-state ``c`` the marginal covariance is ``L_c L_cᵀ`` with ``L_c = L[c, :]`` (rows);
    the QR factorisation ``L_cᵀ = Q R`` gives ``L_c L_cᵀ = Rᵀ R``, so ``Rᵀ`` is a lower factor of
    the marginal, again without forming a covariance.
    """
    factor = conditioned.cov
    if components is not None:
        rows = factor[np.asarray(components), :]
        factor = jnp.linalg.qr(rows.T, mode="r").T
    whitened_error = _solve_lower(factor, error)
    whitened_innovation = _solve_lower(conditioned.innovation_cov, conditioned.innovation)
    return whitened_error @ whitened_error, whitened_innovation @ whitened_innovation


class _SquareRootFilter(AbstractFilter):
    """What both square-root filters share: the factored prior and factor-based consistency."""

    square_root = True

    def init(self, model) -> FilterState:
        """The state before the first measurement, with the prior's Cholesky factor (formed once)."""
        state = super().init(model)
        return eqx.tree_at(lambda s: s.cov, state, cholesky(model.initial_cov))

    def consistency(
        self, conditioned: Conditioned, error: Array, components: tuple[int, ...] | None = None
    ) -> tuple[Array, Array]:
        """NEES ``‖L⁻¹ e‖²`` and NIS ``‖L_S⁻¹ y‖²`` by triangular solves with the factors.

        **Arguments:** ``conditioned``: the step's :class:`Conditioned` (factors in ``cov`` and
        ``innovation_cov``); ``error``: ``x − x̂_{k/k}``, ``(n,)`` or ``(len(components),)``;
        ``components``: as in :meth:`AbstractFilter.consistency` (marginal NEES).

        **Returns:** ``(nees, nis)``, two dimensionless scalars.
        """
        return _factor_consistency(conditioned, error, components)


class SquareRootKalmanFilter(_SquareRootFilter):
    r"""Square-root Kalman filter (array form; linear models): the Kalman filter on Cholesky factors.

    Prediction: ``L_{k/k-1} = Tria([F L_{k-1/k-1},\ Q^{1/2}])`` (``Q^{1/2}`` a semidefinite
    Cholesky factor, so ``Q = 0`` is allowed). Update: the pre-array is triangularised,

    .. math::

        \begin{bmatrix} R^{1/2} & H L \\ 0 & L \end{bmatrix} Θ =
        \begin{bmatrix} S^{1/2} & 0 \\ \bar K & L⁺ \end{bmatrix},\qquad
        x⁺ = x + \bar K S^{-1/2} y,\quad W = \bar K S^{-1/2}

    (Kaminski, Bryson & Schmidt 1971, IEEE TAC 16(6), the array form of the square-root
    covariance filter; Θ orthogonal, from QR). Squaring both sides gives ``S = HPHᵀ + R``,
    ``\bar K = P Hᵀ S^{-ᵀ/2}`` and ``L⁺L⁺ᵀ = P − \bar K \bar Kᵀ``: the optimal-gain Kalman update,
    equal in exact arithmetic to :class:`~jaxtrack.filters.KalmanFilter` (Joseph form), but
    positive semidefinite by construction.

    Missing measurement components are decoupled as in
    :func:`~jaxtrack.filters.condition_linearized` (zero rows of ``H``, ``R`` replaced by
    :func:`masked_noise`), so ``S^{1/2}`` has identity rows and columns there and the gain zero
    columns. States, step outputs and :class:`Conditioned` hold factors (see the module); use
    ``run_filter(...).filtered_cov`` for covariances.

    Requires a :class:`~jaxtrack.models.LinearGaussianModel` whose prior covariance is positive
    definite (it is factored once, in :meth:`init`).
    """

    def check_model(self, model):
        if not isinstance(model, LinearGaussianModel):
            raise InputError(
                f"SquareRootKalmanFilter needs a LinearGaussianModel; got {type(model).__name__}. "
                f"Use SquareRootUnscentedKalmanFilter for nonlinear models."
            )

    def predict(self, model, mean, cov, k):
        F = model.transition_matrix(k)
        pre = jnp.concatenate([matmul(F, cov), psd_cholesky(model.process_noise_cov(k))], axis=1)
        return model.transition(mean, k), tria(pre)

    def update(self, model, mean, cov, z, observed, k) -> Conditioned:
        obs_f = observed.astype(cov.dtype)
        H = model.measurement_matrix(k) * obs_f[:, None]
        chol_R = cholesky(masked_noise(model.measurement_noise_cov(k), observed))
        innovation = jnp.where(observed, z - matmul(H, mean), 0.0)
        m, n = H.shape
        pre = jnp.block([[chol_R, matmul(H, cov)], [jnp.zeros((n, m), cov.dtype), cov]])
        post = tria(pre)
        chol_S, cross, new_chol = post[:m, :m], post[m:, :m], post[m:, m:]
        whitened = _solve_lower(chol_S, innovation)
        new_mean = mean + matmul(cross, whitened)
        ll = _log_likelihood(whitened, chol_S, jnp.sum(obs_f))
        return Conditioned(new_mean, new_chol, innovation, chol_S, ll, _gain(chol_S, cross))


def _weighted_factor(deviations: Array, wc: np.ndarray, extra: Array) -> Array:
    """Lower factor of ``Σ_i wc_i d_i d_iᵀ + E Eᵀ`` (rows ``d_i`` of ``deviations``, ``extra`` = E).

    The points ``i ≥ 1`` (positive weights) and ``E`` enter one QR pre-array; the zeroth point
    enters the pre-array too when ``wc_0 > 0``, or as a rank-one Cholesky downdate when
    ``wc_0 < 0`` (van der Merwe & Wan 2001, ICASSP, §3, the ``qr`` and ``cholupdate`` steps of
    the square-root UKF). ``wc`` is static NumPy.
    """
    dtype = deviations.dtype
    w = jnp.asarray(np.sqrt(wc[1:]), dtype)
    columns = [deviations[1:].T * w[None, :], extra]
    if wc[0] > 0:
        columns.insert(0, deviations[0][:, None] * jnp.asarray(np.sqrt(wc[0]), dtype))
    L = tria(jnp.concatenate(columns, axis=1))
    if wc[0] < 0:
        L = cholesky_rank_one(L, jnp.asarray(np.sqrt(-wc[0]), dtype) * deviations[0], -1.0)
    return L


class SquareRootUnscentedKalmanFilter(_SquareRootFilter):
    r"""Square-root unscented Kalman filter (van der Merwe & Wan 2001, ICASSP, §3).

    The sigma points come straight from the carried factor, ``χ_{±i} = x̂ ± √(n+λ) L_i``, with
    the weights of :class:`~jaxtrack.filters.UnscentedKalmanFilter` (``λ = α²(n+κ) − n``). The
    predicted factor and the factor of ``S`` are QR triangularisations of the weighted
    deviations and the noise factor,

    .. math::

        L_{k/k-1} = \mathrm{Tria}\big([\sqrt{w_i^c}(𝒳_i − x̂^-)]_{i≥1},\ Q^{1/2}\big),\qquad
        S^{1/2} = \mathrm{Tria}\big([\sqrt{w_i^c}(𝒵_i − ẑ)]_{i≥1},\ R^{1/2}\big)

    with the zeroth point added as one more column when ``w_0^c > 0`` (QR only: the default
    cubature weights have ``w_0^c = 0``) or removed by a rank-one Cholesky downdate when
    ``w_0^c < 0`` (``α < 1``; the downdate yields NaN, reported as ``ok = False``, where the
    UKF's own covariance would be indefinite). The filtered factor is the Joseph-like form

    .. math::

        L⁺ = \mathrm{Tria}\big([\sqrt{w_i^c}(𝒳_i − x̂ − W(𝒵_i − ẑ))]_{i},\ W R^{1/2}\big),
        \quad W = C S^{-1}

    (the square-root cubature filter of Arasaratnam & Haykin 2009, IEEE TAC 54(6), §V, with
    unscented weights): a sum of
    positive terms equal to ``P − W S Wᵀ`` since ``Σ w_i^c (𝒳_i − x̂)(𝒳_i − x̂)ᵀ = P``, where
    van der Merwe & Wan's ``m`` sequential downdates by ``W S^{1/2}`` can fail in low
    precision. In exact arithmetic the filter equals :class:`UnscentedKalmanFilter`; angle
    components of the measurement average through ``model.residual`` as there.

    **Arguments:** ``alpha`` (spread, ``> 0``), ``beta``, ``kappa``; dimensionless floats, as
    :class:`~jaxtrack.filters.UnscentedKalmanFilter` (defaults 1, 0, 0: cubature).
    """

    alpha: float = eqx.field(static=True, default=1.0)
    beta: float = eqx.field(static=True, default=0.0)
    kappa: float = eqx.field(static=True, default=0.0)

    def __check_init__(self):
        if not self.alpha > 0:
            raise InputError(f"`alpha` must be positive; got {self.alpha}.")

    def _sigma_points(self, mean, chol):
        wm, wc, scale = unscented_weights(mean.shape[0], self.alpha, self.beta, self.kappa)
        return sigma_points(mean, chol, scale), jnp.asarray(wm, mean.dtype), wc

    def predict(self, model, mean, cov, k):
        points, wm, wc = self._sigma_points(mean, cov)
        propagated = jax.vmap(model.transition, in_axes=(0, None))(points, k)
        pred_mean = wm @ propagated
        dev = propagated - pred_mean[None, :]
        return pred_mean, _weighted_factor(dev, wc, psd_cholesky(model.process_noise_cov(k)))

    def update(self, model, mean, cov, z, observed, k) -> Conditioned:
        points, wm, wc = self._sigma_points(mean, cov)
        obs_f = observed.astype(cov.dtype)
        z_points = jax.vmap(model.measurement, in_axes=(0, None))(points, k)
        # As the UKF: deviations about the central point through the residual (wrapped angles).
        z_dev0 = jax.vmap(model.residual, in_axes=(0, None))(z_points, z_points[0])
        z_pred_offset = wm @ z_dev0
        # Missing components: zero deviations and the identity noise factor decouple them
        # (S^{1/2} identity there, zero gain columns), as masked_noise does for the Kalman update.
        z_dev = (z_dev0 - z_pred_offset[None, :]) * obs_f[None, :]
        x_dev = points - mean[None, :]
        chol_R = cholesky(masked_noise(model.measurement_noise_cov(k), observed))
        chol_S = _weighted_factor(z_dev, wc, chol_R)
        wcj = jnp.asarray(wc, cov.dtype)
        C = matmul(x_dev.T * wcj[None, :], z_dev)
        gain = _gain(chol_S, jsl.solve_triangular(chol_S, C.T, lower=True).T)
        innovation = jnp.where(observed, model.residual(z, z_points[0]) - z_pred_offset, 0.0)
        new_mean = mean + matmul(gain, innovation)
        new_chol = _weighted_factor(x_dev - z_dev @ gain.T, wc, matmul(gain, chol_R))
        whitened = _solve_lower(chol_S, innovation)
        ll = _log_likelihood(whitened, chol_S, jnp.sum(obs_f))
        return Conditioned(new_mean, new_chol, innovation, chol_S, ll, gain)

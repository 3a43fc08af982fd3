"""Rauch–Tung–Striebel fixed-interval smoother."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
from jaxtyping import Array, ArrayLike, Bool, Float

from ..models import AbstractStateSpaceModel
from ._base import AbstractFilter, FilterResult, FirstStep, run_filter, symmetrize
from ._kalman import KalmanFilter


class SmootherResult(eqx.Module):
    """Output of :func:`rts_smoother`.

    - ``smoothed_mean`` ``(T, n)``, ``smoothed_cov`` ``(T, n, n)``: ``x̂_{k/T-1}``, ``P_{k/T-1}``.
    - ``smoother_gain`` ``(T-1, n, n)``: ``G_k = P_{k/k} Φ_{k+1}ᵀ P_{k+1/k}⁻¹``.
    - ``filtered``: the forward pass, a :class:`FilterResult`.
    - ``ok`` ``()`` bool: False if the forward pass failed (``filtered.ok``) or any smoothed mean
      or covariance is non-finite (typically a singular predicted covariance ``P_{k+1/k}``:
      ``Q = 0`` with a singular ``F``, whose Cholesky factor is NaN).
    """

    smoothed_mean: Float[Array, "T n"]
    smoothed_cov: Float[Array, "T n n"]
    smoother_gain: Float[Array, "Tm1 n n"]
    filtered: FilterResult
    ok: Bool[Array, ""]


_SMOOTHER_FAILED = (
    "jaxtrack: rts_smoother produced a non-finite smoothed mean or covariance. Likely causes: "
    "(a) a singular predicted covariance P_{k+1/k}, e.g. `process_noise_cov` Q = 0 (or singular) "
    "with a singular `transition_matrix` F, so the smoother gain P_{k/k} F^T P_{k+1/k}^-1 does "
    "not exist; (b) covariances whose units differ by many orders of magnitude, so P_{k+1/k} is "
    "numerically singular. Add a small plant noise on the affected states, or pass throw=False "
    "to get the result with ok=False instead."
)


@eqx.filter_jit
def _rts_backward(model, filtered: FilterResult, throw: bool):
    def step(carry, inputs):
        next_mean, next_cov = carry
        k, m_f, P_f, m_p_next, P_p_next = inputs
        # Φ_{k+1} linearised at the filtered estimate (exact for a linear model).
        F = model.transition_jacobian(m_f, k + 1)
        # G = P_f Fᵀ P_p⁻¹ via Cholesky of the (symmetric positive definite) prediction.
        chol = jnp.linalg.cholesky(P_p_next)
        G = jsl.cho_solve((chol, True), F @ P_f).T
        mean = m_f + G @ (next_mean - m_p_next)
        cov = symmetrize(P_f + G @ (next_cov - P_p_next) @ G.T)
        return (mean, cov), (mean, cov, G)

    T = filtered.filtered_mean.shape[0]
    last = (filtered.filtered_mean[-1], filtered.filtered_cov[-1])
    inputs = (
        jnp.arange(T - 1),
        filtered.filtered_mean[:-1],
        filtered.filtered_cov[:-1],
        filtered.predicted_mean[1:],
        filtered.predicted_cov[1:],
    )
    _, (means, covs, gains) = jax.lax.scan(step, last, inputs, reverse=True)
    means = jnp.concatenate([means, last[0][None]])
    covs = jnp.concatenate([covs, last[1][None]])
    return _with_status(SmootherResult(means, covs, gains, filtered, filtered.ok), throw)


def _with_status(result: SmootherResult, throw: bool) -> SmootherResult:
    """Set ``ok`` from the smoothed moments; with ``throw`` raise at run time if it is False."""
    finite = jnp.all(jnp.isfinite(result.smoothed_mean)) & jnp.all(jnp.isfinite(result.smoothed_cov))
    result = eqx.tree_at(lambda r: r.ok, result, result.filtered.ok & finite)
    if throw:
        result = eqx.error_if(result, ~result.ok, _SMOOTHER_FAILED)
    return result


def rts_smoother(
    model: AbstractStateSpaceModel,
    measurements: ArrayLike,
    *,
    filter: AbstractFilter | None = None,
    mask: ArrayLike | None = None,
    first_step: FirstStep = "update",
    nan_as_missing: bool = False,
    throw: bool = True,
) -> SmootherResult:
    r"""Rauch–Tung–Striebel smoother: a forward filter, then one reverse ``lax.scan``.

    .. math::

        G_k = P_{k/k} Φ_{k+1}ᵀ P_{k+1/k}^{-1},\quad
        x̂_{k/N} = x̂_{k/k} + G_k (x̂_{k+1/N} − x̂_{k+1/k}),\quad
        P_{k/N} = P_{k/k} + G_k (P_{k+1/N} − P_{k+1/k}) G_kᵀ

    (Rauch, Tung & Striebel 1965). ``filter`` defaults to :class:`KalmanFilter`; with an
    :class:`ExtendedKalmanFilter` it is the extended RTS smoother (Φ linearised at the filtered
    estimate). Arguments as :func:`run_filter`; ``throw=True`` (default) also raises at run time
    (``equinox``'s runtime error, whose message lists the likely causes) when a smoothed mean or
    covariance is non-finite; with ``throw=False`` read :attr:`SmootherResult.ok`.

    **Returns:** a :class:`SmootherResult` (``T`` steps, ``n`` states).

    **Raises:** ``InputError`` as :func:`run_filter`; with ``throw=True`` a runtime error if the
    forward or backward pass produced non-finite values (e.g. a singular predicted covariance).
    """
    filter = KalmanFilter() if filter is None else filter
    filtered = run_filter(
        filter,
        model,
        measurements,
        mask=mask,
        first_step=first_step,
        save="all",
        nan_as_missing=nan_as_missing,
        throw=throw,
    )
    if filtered.filtered_mean.shape[0] == 1:
        empty = jnp.zeros((0,) + filtered.filtered_cov.shape[1:], filtered.filtered_cov.dtype)
        return SmootherResult(filtered.filtered_mean, filtered.filtered_cov, empty, filtered, filtered.ok)
    return _rts_backward(model, filtered, throw)

"""Consistency statistics: NEES, NIS, their chi-square confidence bounds, and streaming sums;
time-averaged RMSE and paired RMSE ratios with delta-method confidence intervals."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.stats
from jaxtyping import Array, ArrayLike

from .._validation import InputError
from ..filters._linalg import normalized_squared_error as _normalized_squared_error


def normalized_squared_error(error: Array, cov: Array) -> Array:
    """``eᵀ P⁻¹ e`` for one error vector ``(d,)`` and covariance ``(d, d)`` (NEES or NIS).

    Uses the Cholesky factor ``L`` of ``cov``; missing measurement components must already be
    decoupled (identity rows/columns, zero error), as in :class:`~jaxtrack.filters.FilterResult`.
    The error is whitened by a product with ``L⁻¹``, not a triangular solve, so that under
    ``jax.vmap`` with a covariance shared by the batch only the product is batched.

    **Arguments:**

    - ``error``: ``e``, ``(d,)``; ``cov``: ``P``, ``(d, d)``, in the units of ``e`` squared.

    **Returns:** ``eᵀ P⁻¹ e``, a scalar (dimensionless).
    """
    # The formula lives in the filters layer (jaxtrack.filters._linalg), which scores its own
    # steps with it (AbstractFilter.consistency) and must not import this one. A function of
    # this module, not a bare re-export, so that it stays documented and owned here.
    return _normalized_squared_error(error, cov)


def chi2_mean_bounds(dof: ArrayLike, num_runs: int, confidence: float = 0.95) -> np.ndarray:
    r"""Two-sided bounds for the average of ``num_runs`` independent χ²(dof) variables.

    If each run's NEES (or NIS) is χ² with ``dof`` degrees of freedom, ``num_runs`` times their
    average is χ²(``num_runs·dof``), so the ``confidence`` interval of the average is

    $$
    \left[\frac{(χ^2_{Md})^{-1}(α/2)}{M},\ \frac{(χ^2_{Md})^{-1}(1 − α/2)}{M}\right],
    \qquad α = 1 − \text{confidence}
    $$

    (Bar-Shalom, Li & Kirubarajan 2001, §5.4.2). ``dof`` may be an array (e.g. NIS degrees of
    freedom per step under a mask); where it is 0 both bounds are 0.

    **Arguments:**

    - ``dof``: the degrees of freedom ``d`` per run, scalar or array ``(...)``.
    - ``num_runs``: ``M ≥ 1``; ``confidence``: in ``(0, 1)`` (default 0.95).

    **Returns:** an array of shape ``dof.shape + (2,)``: lower and upper bound.

    **Raises:** ``InputError`` for ``confidence`` outside ``(0, 1)`` or ``num_runs < 1``.
    """
    if not 0.0 < confidence < 1.0:
        raise InputError(f"`confidence` must lie in (0, 1); got {confidence}.")
    if num_runs < 1:
        raise InputError(f"`num_runs` must be at least 1; got {num_runs}.")
    dof = np.asarray(dof, dtype=np.float64)
    alpha = 1.0 - confidence
    total = dof * num_runs
    safe = np.where(total > 0, total, 1.0)
    lo = scipy.stats.chi2.ppf(alpha / 2, safe) / num_runs
    hi = scipy.stats.chi2.ppf(1 - alpha / 2, safe) / num_runs
    return np.stack([np.where(total > 0, lo, 0.0), np.where(total > 0, hi, 0.0)], axis=-1)


class Interval(NamedTuple):
    """A Monte Carlo estimate and its two-sided confidence interval (Python floats)."""

    value: float
    lower: float
    upper: float


def _time_averaged_rmse_influence(squared_error):
    """``f = (1/T) Σ_k √m_k`` (``m_k`` the run mean of ``e_ik``) and each run's influence on it.

    The delta method: ``∂f/∂m_k = 1/(2T√m_k)`` and run ``i`` moves ``m_k`` by ``(e_ik − m_k)/M``,
    so ``f − E f ≈ (1/M) Σ_i ψ_i`` with ``ψ_i = (1/T) Σ_k (e_ik − m_k) / (2√m_k)``.
    """
    e = np.asarray(squared_error, dtype=np.float64)
    if e.ndim != 2 or e.shape[0] < 2:
        raise InputError(f"squared errors must be (M, T) with M ≥ 2 runs; got shape {e.shape}.")
    if not np.all(np.isfinite(e)) or np.any(e < 0):
        raise InputError("squared errors must be finite and non-negative.")
    m = e.mean(axis=0)
    root = np.sqrt(m)
    safe = np.where(root > 0, root, 1.0)
    psi = np.mean(np.where(root > 0, (e - m) / (2.0 * safe), 0.0), axis=1)
    return float(np.mean(root)), psi


def time_averaged_rmse(squared_error: ArrayLike, confidence: float = 0.95) -> Interval:
    """Time-averaged RMSE ``(1/T) Σ_k √(mean_i e_ik)`` and its delta-method confidence interval.

    **Arguments:**

    - ``squared_error``: ``(M, T)``, run ``i``'s squared error ``e_ik`` at step ``k`` (e.g.
      ``‖p − p̂‖²`` of a position, m²), ``M ≥ 2`` independent runs.
    - ``confidence``: in ``(0, 1)`` (default 0.95).

    **Returns:** an :class:`Interval` (in the units of ``√e``): the estimate ``f`` and
    ``f ∓ z·σ̂_ψ/√M`` with ``ψ_i`` the runs' influence values (the first-order delta method;
    ``z`` the normal quantile). Valid for many runs; the steps' dependence within a run is
    accounted for (``ψ_i`` sums over a run's steps before the variance is taken).
    """
    if not 0.0 < confidence < 1.0:
        raise InputError(f"`confidence` must lie in (0, 1); got {confidence}.")
    f, psi = _time_averaged_rmse_influence(squared_error)
    half = scipy.stats.norm.ppf(0.5 + confidence / 2) * np.std(psi, ddof=1) / np.sqrt(psi.shape[0])
    return Interval(f, f - half, f + half)


def time_averaged_rmse_ratio(
    squared_error: ArrayLike, reference_squared_error: ArrayLike, confidence: float = 0.95
) -> Interval:
    """Ratio of two estimators' time-averaged RMSEs on the same runs, with a paired interval.

    ``r = f_a / f_b`` with ``f`` as :func:`time_averaged_rmse`. The runs are paired (both
    estimators saw the same truth and measurements: common random numbers), so the interval
    uses the per-run influence of the ratio, ``(ψ_a,i − r ψ_b,i) / f_b``: the shared noise
    cancels and the interval is far narrower than one from two independent estimates.

    **Arguments:** ``squared_error``, ``reference_squared_error``: ``(M, T)`` each, the same runs
    in the same order; ``confidence`` as :func:`time_averaged_rmse`.

    **Returns:** an :class:`Interval` of the dimensionless ratio (< 1: the first is better).
    """
    if not 0.0 < confidence < 1.0:
        raise InputError(f"`confidence` must lie in (0, 1); got {confidence}.")
    if np.shape(squared_error) != np.shape(reference_squared_error):
        raise InputError(
            f"`squared_error` {np.shape(squared_error)} and `reference_squared_error` "
            f"{np.shape(reference_squared_error)} must have the same (M, T) shape (paired runs)."
        )
    fa, psa = _time_averaged_rmse_influence(squared_error)
    fb, psb = _time_averaged_rmse_influence(reference_squared_error)
    if fb <= 0:
        raise InputError("`reference_squared_error` is 0 everywhere: the ratio is undefined.")
    r = fa / fb
    psi = (psa - r * psb) / fb
    half = scipy.stats.norm.ppf(0.5 + confidence / 2) * np.std(psi, ddof=1) / np.sqrt(psi.shape[0])
    return Interval(r, r - half, r + half)

"""Consistency statistics: NEES, NIS, their chi-square confidence bounds, and streaming sums."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import scipy.stats
from jaxtyping import Array, ArrayLike

from .._validation import InputError
from ..filters._linalg import cholesky_and_inverse, matmul


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
    _, chol_inv = cholesky_and_inverse(cov)
    whitened = matmul(chol_inv, error)
    return whitened @ whitened


def chi2_mean_bounds(dof: ArrayLike, num_runs: int, confidence: float = 0.95) -> np.ndarray:
    """Two-sided bounds for the average of ``num_runs`` independent χ²(dof) variables.

    If each run's NEES (or NIS) is χ² with ``dof`` degrees of freedom, ``num_runs`` times their
    average is χ²(``num_runs·dof``), so the ``confidence`` interval of the average is

    ``[χ²_{M·d}⁻¹(α/2) / M,  χ²_{M·d}⁻¹(1 − α/2) / M]``,  ``α = 1 − confidence``

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

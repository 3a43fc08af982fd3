"""The PDA/JPDA state update: one track's Gaussian mixture over its association events, collapsed.

Given a track's association probabilities ``β`` (a row of an
:class:`~jaxtrack.association.Association`) and its filter's update on every measurement of the
scan, the posterior is the mixture ``β_0 N(x̂⁻, P⁻) + Σ_j β_j N(x̂_j, P_j)``; the PDA filter
replaces it by the Gaussian with the same mean and covariance (Bar-Shalom, Daum & Huang 2009,
the PDAF state and covariance update; Bar-Shalom & Tse 1975). The filter is any
:class:`~jaxtrack.filters.AbstractFilter`: its ``update`` vmapped over the measurements gives the
batch of :class:`~jaxtrack.filters.Conditioned` this function reads, so the EKF, UKF and square-
root filters need nothing of their own. (A square-root filter's ``Conditioned`` carries Cholesky
factors: square them first.)
"""

from __future__ import annotations

from typing import Literal

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError, is_concrete
from ..filters._updates import Conditioned, symmetrize

PDAForm = Literal["mixture", "innovation"]


def pda_update(
    conditioned: Conditioned,
    association_row: Float[ArrayLike, " Mp1"],
    predicted_mean: Float[ArrayLike, " n"],
    predicted_cov: Float[ArrayLike, "n n"],
    *,
    form: PDAForm = "mixture",
) -> tuple[Float[Array, " n"], Float[Array, "n n"]]:
    r"""Collapse one track's PDA/JPDA mixture to its mean and covariance.

    **Mixture form** (``form="mixture"``, the default; any filter), with ``x̂_0 = x̂⁻``,
    ``P_0 = P⁻`` the prediction and ``x̂_j``, ``P_j`` the filter's update on measurement ``j``:

    .. math::

        x̂ = \sum_{j=0}^{M} β_j x̂_j,\qquad
        P = \sum_{j=0}^{M} β_j \big(P_j + (x̂_j − x̂)(x̂_j − x̂)ᵀ\big).

    **Innovation form** (``form="innovation"``; for filters whose gain ``W`` and updated
    covariance ``P^c`` do not depend on the measurement — the KF, and the EKF/UKF linearised at
    the predicted mean), Bar-Shalom, Daum & Huang 2009's PDAF update:

    .. math::

        x̂ = x̂⁻ + W ν̄,\quad ν̄ = \sum_{j ≥ 1} β_j ν_j,\qquad
        P = β_0 P⁻ + (1 − β_0) P^c + W \Big[\sum_{j ≥ 1} β_j ν_j ν_jᵀ − ν̄ ν̄ᵀ\Big] Wᵀ.

    Here ``(1 − β_0) P^c`` is formed as ``Σ_{j≥1} β_j P_j`` and ``W`` as the ``β``-weighted mean of
    the per-measurement gains, so that with equal gains the two forms agree to rounding (Stone
    Soup's ``PDAUpdater`` has both: ``gm_method=True`` / ``False``). With a gain that depends on
    the measurement (an iterated EKF) only the mixture form is the moment match.

    **Arguments:**

    - ``conditioned``: a :class:`~jaxtrack.filters.Conditioned` with a leading axis of ``M``
      (the filter's ``update`` vmapped over the scan's measurements): ``mean`` ``(M, n)``,
      ``cov`` ``(M, n, n)``, ``innovation`` ``(M, m)``, ``gain`` ``(M, n, m)``, in the state's
      and measurement's units. Entries for measurements with ``β_j = 0`` (padding, outside the
      gate) are never read — they may hold anything, NaN included (a select, not a product
      with 0).
    - ``association_row``: ``β``, ``(1 + M,)``: ``β_0`` the probability that the track was not
      detected, ``β_j`` that measurement ``j − 1`` is the track's: entries ``≥ 0`` summing to 1
      (to ``tol = (1 + M)·max(10⁻⁹, 16·ε)``, ``ε`` the machine epsilon of ``β``'s dtype; an entry
      down to ``−tol`` is read as rounding). A row of zeros (a padded track) returns the
      prediction.
    - ``predicted_mean``: ``x̂⁻``, ``(n,)``; ``predicted_cov``: ``P⁻``, ``(n, n)``.
    - ``form``: ``"mixture"`` (default) or ``"innovation"`` (static).

    **Returns:** ``(mean, cov)``, ``(n,)`` and ``(n, n)`` (symmetric), in the state's units. A
    traced ``β`` (under ``jit``/``vmap``) that is not a probability row (a NaN or infinite entry,
    an entry below ``−tol``, or a sum off 1 by more than ``tol``, other than the all-zero row)
    gives NaN in every entry of both: no moment match of such a mixture is right, and a NaN is
    caught by the tracker's and the filters' finiteness checks where a finite wrong moment would
    pass as an answer.

    **Raises:** ``InputError`` if the shapes disagree or ``form`` is unknown, or, naming
    ``association_row``, if a concrete ``β`` is not a probability row (as above).

    Differentiable in ``β`` and in the conditioned moments; the derivative with respect to a
    ``β_j`` that is exactly 0 is taken as 0 (its moments are not read).

    References: Y. Bar-Shalom and E. Tse, "Tracking in a cluttered environment with
    probabilistic data association", Automatica 11(5), 1975; Y. Bar-Shalom, F. Daum and J.
    Huang, "The probabilistic data association filter", IEEE Control Systems Magazine 29(6),
    2009.
    """
    if form not in ("mixture", "innovation"):
        raise InputError(f"`form` must be 'mixture' or 'innovation'; got {form!r}.")
    beta = jnp.asarray(association_row)
    x_pred = jnp.asarray(predicted_mean)
    P_pred = jnp.asarray(predicted_cov)
    dtype = jnp.result_type(beta, x_pred, P_pred, conditioned.mean, float)
    beta, x_pred, P_pred = beta.astype(dtype), x_pred.astype(dtype), P_pred.astype(dtype)
    M, n = conditioned.mean.shape
    if beta.shape != (1 + M,):
        raise InputError(
            f"`association_row` must have shape ({1 + M},) for {M} conditioned measurements; "
            f"got {beta.shape}."
        )
    if x_pred.shape != (n,) or P_pred.shape != (n, n):
        raise InputError(
            f"`predicted_mean`/`predicted_cov` must have shapes ({n},)/({n}, {n}); got "
            f"{x_pred.shape}/{P_pred.shape}."
        )
    row_dtype = jnp.asarray(association_row).dtype
    eps = float(jnp.finfo(row_dtype if jnp.issubdtype(row_dtype, jnp.floating) else dtype).eps)
    tol = (1 + M) * max(1e-9, 16.0 * eps)
    if is_concrete(beta):
        _check_row(np.asarray(beta, dtype=np.float64), tol)
    empty = jnp.all(beta == 0.0)
    not_a_row = (
        ~jnp.all(jnp.isfinite(beta))
        | jnp.any(beta < -tol)
        | (~empty & (jnp.abs(jnp.sum(beta) - 1.0) > tol))
    )
    b0, b = beta[0], beta[1:]
    used = b != 0.0
    # Selects, not products with β_j = 0: an unused measurement's moments may be NaN or huge.
    x_j = jnp.where(used[:, None], conditioned.mean.astype(dtype), 0.0)
    P_j = jnp.where(used[:, None, None], conditioned.cov.astype(dtype), 0.0)
    # Σ_j β_j P_j: the same term in both forms.
    P_detected = jnp.einsum("j,jab->ab", b, P_j)

    if form == "mixture":
        mean = b0 * x_pred + b @ x_j
        d0 = x_pred - mean
        d = jnp.where(used[:, None], x_j - mean[None, :], 0.0)
        spread = b0 * jnp.outer(d0, d0) + jnp.einsum("j,ja,jb->ab", b, d, d)
        cov = b0 * P_pred + P_detected + spread
    else:
        nu = jnp.where(used[:, None], conditioned.innovation.astype(dtype), 0.0)
        W_j = jnp.where(used[:, None, None], conditioned.gain.astype(dtype), 0.0)
        detected = jnp.sum(b)
        # The β-weighted mean gain (the gain itself when every measurement has the same one);
        # with no detection mass the gain is never used.
        W = jnp.einsum("j,jab->ab", b, W_j) / jnp.where(detected > 0, detected, 1.0)
        nu_bar = b @ nu
        mean = x_pred + W @ nu_bar
        spread_nu = jnp.einsum("j,ja,jb->ab", b, nu, nu) - jnp.outer(nu_bar, nu_bar)
        cov = b0 * P_pred + P_detected + W @ spread_nu @ W.T
    # The products W A Wᵀ (and the sums of outer products) round asymmetrically; downstream
    # Cholesky factorisations (the next S, gating) need an exactly symmetric P.
    cov = symmetrize(cov)
    # A padded track (β all zero) keeps its prediction rather than collapsing to 0; a traced row
    # that is not a probability row gives NaN (the concrete one raised above).
    mean = jnp.where(empty, x_pred, mean)
    cov = jnp.where(empty, P_pred, cov)
    return jnp.where(not_a_row, jnp.nan, mean), jnp.where(not_a_row, jnp.nan, cov)


def _check_row(beta: np.ndarray, tol: float) -> None:
    """``InputError`` naming ``association_row`` unless ``β`` is all zeros or a probability row."""
    if not np.all(np.isfinite(beta)):
        raise InputError(f"`association_row` must be finite; got {beta.tolist()}.")
    if np.any(beta < -tol):
        raise InputError(
            f"`association_row` must be probabilities (>= 0); its smallest entry is {beta.min():.3g}."
        )
    total = float(np.sum(beta))
    if np.any(beta != 0.0) and abs(total - 1.0) > tol:
        raise InputError(
            f"`association_row` must sum to 1 (or be all zeros, a padded track); it sums to "
            f"{total!r} (tolerance {tol:.3g})."
        )

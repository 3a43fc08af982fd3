"""Data-free covariance recursions: computed versus actual covariance (Ho 1968, Sec. I, II-A, App. A).

For a linear model the Kalman filter's covariances and gains do not depend on the data, so
performance analysis needs no simulation. Two different covariances matter:

- the **computed** covariance ``P*`` that a filter propagates from its *assumed* ``P*_{0/-1}``,
  ``Q*``, ``R*`` to build its gains ``W*``;
- the **actual** covariance ``P``: the true second moment of the estimation error of that filter,
  the Joseph recursion (Ho 1968, eq. (3)) with the *true* ``P_{0/-1}``, ``Q``, ``R`` and the gains
  ``W*`` the filter actually used (Sec. II-G(1)).

:func:`covariance_recursion` runs the very step function that :func:`jaxtrack.filters.run_filter`
runs (with zero data), so a covariance analysis and a filter cannot disagree.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._validation import InputError, is_concrete
from .filters import KalmanFilter, covariance_pass
from .filters._base import FirstStep, prepare_measurements
from .models import AbstractStateSpaceModel, LinearGaussianModel

__all__ = [
    "CovarianceHistory",
    "covariance_recursion",
    "actual_covariance",
    "second_order_term",
    "predicted_error_mean",
    "updated_error_mean",
]


class CovarianceHistory(eqx.Module):
    """Covariances and gains of a linear filter over ``T`` steps (no data involved).

    - ``predicted_cov`` ``(T, n, n)``: $P_{k/k-1}$ (the prior at ``k = 0`` when
      ``first_step="update"``).
    - ``filtered_cov`` ``(T, n, n)``: $P_{k/k}$.
    - ``gain`` ``(T, n, m)``: ``W_k`` (zero columns where a component is missing).
    - ``innovation_cov`` ``(T, m, m)``: $S_k = H_k P_{k/k-1} H_kᵀ + R_k$ of the model the
      recursion ran on (identity rows/columns where missing).
    """

    predicted_cov: Float[Array, "T n n"]
    filtered_cov: Float[Array, "T n n"]
    gain: Float[Array, "T n m"]
    innovation_cov: Float[Array, "T m m"]


def _resolve_steps(model, num_steps):
    if num_steps is None:
        if model.num_steps is None:
            raise InputError("`num_steps` is required for a time-invariant model.")
        return model.num_steps
    if not isinstance(num_steps, int) or num_steps < 1:
        raise InputError(f"`num_steps` must be a positive int; got {num_steps!r}.")
    return num_steps


@eqx.filter_jit
def _covariance_scan(filter, model, observed, first_step):
    return CovarianceHistory(*covariance_pass(filter, model, observed, first_step))


def covariance_recursion(
    model: LinearGaussianModel,
    num_steps: int | None = None,
    *,
    gain: ArrayLike | None = None,
    mask: ArrayLike | None = None,
    first_step: FirstStep = "update",
) -> CovarianceHistory:
    r"""The Kalman filter's covariance recursion alone (Ho 1968, eqs. (3)–(4)).

    .. math::

        P_{k/k-1} = Φ_{k-1} P_{k-1/k-1} Φ_{k-1}ᵀ + Q_{k-1},\qquad
        P_{k/k} = (I − W_k H_k) P_{k/k-1} (I − W_k H_k)ᵀ + W_k R_k W_kᵀ

    with the optimal gain $W_k = P_{k/k-1} H_kᵀ S_k^{-1}$ unless ``gain`` is given (then the
    Joseph form gives the covariance of that suboptimal filter).

    **Arguments:**

    - ``model``: a :class:`~jaxtrack.models.LinearGaussianModel` (its means are ignored).
    - ``num_steps``: ``T``; defaults to the model's per-step length.
    - ``gain``: optional fixed gains ``(n, m)`` or ``(T, n, m)``.
    - ``mask``: optional boolean ``(T,)`` or ``(T, m)``; missing measurements are skipped.
    - ``first_step``: ``"update"`` (Ho's convention: the prior is ``P_{0/-1}`` on the state at the
      first sample) or ``"predict"``, as in :func:`~jaxtrack.filters.run_filter`.

    **Returns:** a :class:`CovarianceHistory`. Differentiable with ``jax.jacfwd``/``jax.grad`` in
    every array of the model (τ, Q, R, P0) and in ``gain``.
    """
    filter = KalmanFilter(gain)
    filter.check_model(model)
    num_steps = _resolve_steps(model, num_steps)
    zeros = jnp.zeros((num_steps, model.meas_dim), model.initial_cov.dtype)
    _, observed = prepare_measurements(model, zeros, mask, False)
    if first_step not in ("update", "predict"):
        raise InputError(f"`first_step` must be 'update' or 'predict'; got {first_step!r}.")
    return _covariance_scan(filter, model, observed, first_step)


def actual_covariance(
    true_model: LinearGaussianModel,
    filter_model: LinearGaussianModel,
    num_steps: int | None = None,
    *,
    mask: ArrayLike | None = None,
    first_step: FirstStep = "update",
) -> tuple[CovarianceHistory, CovarianceHistory]:
    """Computed and actual covariance of a filter built on wrong statistics (Ho 1968, Sec. II-G(1)).

    The filter runs on ``filter_model`` (its assumed ``P*_{0/-1}``, ``Q*``, ``R*``), which fixes its
    gains ``W*``; the actual error covariance is the Joseph recursion with the truth's
    ``P_{0/-1}``, ``Q``, ``R`` and those gains. Exact for linear models.

    Both models must share ``F`` and ``H``: Ho's eq. (26) with ΔΦ describes a dynamics change the
    filter also knows; a filter whose Φ differs from the truth needs an augmented (truth, error)
    covariance, which this function does not compute.

    **Arguments:**

    - ``true_model``: the truth, a :class:`~jaxtrack.models.LinearGaussianModel` (``P_{0/-1}``, ``Q``, ``R``).
    - ``filter_model``: the filter's assumed model (``P*_{0/-1}``, ``Q*``, ``R*``), same ``F`` and ``H``.
    - ``num_steps``, ``mask``, ``first_step``: as in :func:`covariance_recursion` (``mask`` ``(T,)`` or
      ``(T, m)``).

    **Returns:** ``(computed, actual)``, two :class:`CovarianceHistory`; ``actual.gain`` equals
    ``computed.gain``.

    **Raises:** ``InputError`` if the models do not share ``F`` and ``H``.
    """
    for name in ("F", "H"):
        a, b = getattr(true_model, name), getattr(filter_model, name)
        if a.shape != b.shape or (is_concrete(a) and is_concrete(b) and not np.array_equal(np.asarray(a), np.asarray(b))):
            raise InputError(
                f"`filter_model` and `true_model` must share {name}: the actual covariance of a filter "
                f"with a wrong {'transition' if name == 'F' else 'measurement'} matrix needs an augmented "
                f"state (Ho 1968 treats model error as plant noise instead, Sec. II-G(4))."
            )
    computed = covariance_recursion(filter_model, num_steps, mask=mask, first_step=first_step)
    actual = covariance_recursion(true_model, num_steps, gain=computed.gain, mask=mask, first_step=first_step)
    return computed, actual


# --------------------------------------------------------------------------------------------
# Appendix A: second-order error means of the EKF (signs corrected, spec §2.9)


def second_order_term(fn, x: Array, B: Array) -> Array:
    """``(f_xx ∘ B)^{(i)} = Σ_{j,k} ∂²f^{(i)}/∂x_j∂x_k · B_{jk}`` (Ho 1968, eq. (A.6)), by ``jax.hessian``.

    **Arguments:**

    - ``fn``: ``f``, a function ``(n,) -> (p,)``.
    - ``x``: the point, ``(n,)``; ``B``: the matrix, ``(n, n)``.

    **Returns:** ``(f_xx ∘ B)``, shape ``(p,)``.
    """
    hess = jax.hessian(fn)(x)
    return jnp.einsum("ijk,jk->i", hess, B)


def predicted_error_mean(
    model: AbstractStateSpaceModel, error_mean: Array, cov: Array, estimate: Array, k
) -> Array:
    r"""Mean of the EKF prediction error to second order (Ho 1968, eq. (A.10), additive noise).

    .. math::

        \bar{x̃}_{k/k-1} = f_x \bar{x̃}_{k-1/k-1}
            + ½ f_{xx} ∘ [P_{k-1/k-1} + \bar{x̃}_{k-1/k-1}\bar{x̃}_{k-1/k-1}ᵀ]

    with ``f_x``, ``f_xx`` at the estimate ``x̂_{k-1/k-1}``. (The ``f_ww∘Q`` term vanishes for
    additive noise.) **Arguments:** ``error_mean`` ``(n,)``, ``cov`` ``P_{k-1/k-1}`` ``(n, n)``,
    ``estimate`` ``x̂_{k-1/k-1}`` ``(n,)``, ``k`` the step the transition leads into.
    """
    fn = lambda x: model.transition(x, k)  # noqa: E731
    phi = jax.jacfwd(fn)(estimate)
    second = cov + jnp.outer(error_mean, error_mean)
    return phi @ error_mean + 0.5 * second_order_term(fn, estimate, second)


def updated_error_mean(
    model: AbstractStateSpaceModel, error_mean: Array, cov: Array, estimate: Array, gain: Array, k
) -> Array:
    r"""Mean of the EKF update error to second order (Ho 1968, eq. (A.14), additive noise).

    .. math::

        \bar{x̃}_{k/k} = (I − W h_x) \bar{x̃}_{k/k-1}
            − ½ W h_{xx} ∘ [P_{k/k-1} + \bar{x̃}_{k/k-1}\bar{x̃}_{k/k-1}ᵀ]

    with ``h_x``, ``h_xx`` at the prediction ``x̂_{k/k-1}`` (``estimate``); ``gain`` is ``W`` ``(n, m)``.

    **Arguments:**

    - ``model``: the state-space model (its ``measurement(x, k)`` is ``h``).
    - ``error_mean``: ``x̄̃_{k/k-1}``, ``(n,)``; ``cov``: ``P_{k/k-1}``, ``(n, n)``.
    - ``estimate``: ``x̂_{k/k-1}``, ``(n,)``; ``gain``: ``W``, ``(n, m)``; ``k``: the step index.

    **Returns:** ``x̄̃_{k/k}``, shape ``(n,)``, in the state's units.
    """
    fn = lambda x: model.measurement(x, k)  # noqa: E731
    H = jax.jacfwd(fn)(estimate)
    second = cov + jnp.outer(error_mean, error_mean)
    n = error_mean.shape[0]
    return (jnp.eye(n, dtype=cov.dtype) - gain @ H) @ error_mean - 0.5 * gain @ second_order_term(fn, estimate, second)

"""Kalman filter (Joseph form, optional external gain) and extended Kalman filter."""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError, check_finite, check_shape
from ..models import LinearGaussianModel, at_step
from ._base import AbstractFilter
from ._updates import AbstractUpdateForm, JosephForm, condition_linearized
from ._linalg import matmul


def checked_gain(gain: ArrayLike, rows: int | None = None) -> Array:
    """A supplied fixed gain as a finite array of shape ``(rows, m)`` or per step ``(T, rows, m)``.

    **Arguments:** ``gain`` the gain; ``rows`` the number of gain rows if known (the state
    dimension, or the number of estimated states of a consider filter).

    **Returns:** ``gain`` as a jax array. **Raises:** ``InputError`` naming ``gain``.
    """
    gain = jnp.asarray(gain)
    check_shape("gain", gain, [(rows, None), (None, rows, None)])
    check_finite("gain", gain)
    return gain


def _predict_linearized(model, mean, cov, k, jacobian):
    Q = model.process_noise_cov(k)
    return model.transition(mean, k), matmul(matmul(jacobian, cov), jacobian.T) + Q


class KalmanFilter(AbstractFilter):
    r"""Linear Kalman filter with the Joseph-form covariance update.

    .. math::

        x̂_{k/k-1} = F_k x̂_{k-1/k-1} + b_k,\qquad P_{k/k-1} = F_k P_{k-1/k-1} F_kᵀ + Q_k

        W_k = P_{k/k-1} H_kᵀ (H_k P_{k/k-1} H_kᵀ + R_k)^{-1}

        P_{k/k} = (I − W_k H_k) P_{k/k-1} (I − W_k H_k)ᵀ + W_k R_k W_kᵀ

    (Ho 1968, eqs. (2)–(4)). The Joseph form is exact for any gain, so a suboptimal gain
    supplied through ``gain`` gives the *actual* error covariance of that filter, provided the
    model holds the true noise covariances.

    **Arguments:**

    - ``form``: the covariance update, :class:`~jaxtrack.filters.JosephForm` (default) or
      :class:`~jaxtrack.filters.StandardForm` (``P⁺ = (I − W H) P``, optimal gain only).
    - ``gain``: optional fixed gain ``W``, shape ``(n, m)`` or per step ``(T, n, m)``. When given,
      it replaces the optimal gain (columns of missing components are zeroed). It is an array leaf,
      so ``jax.grad`` with respect to it works.

    Requires a :class:`~jaxtrack.models.LinearGaussianModel`.
    """

    gain: Float[Array, "*T n m"] | None = None
    form: AbstractUpdateForm = JosephForm()

    def __init__(self, gain: ArrayLike | None = None, form: AbstractUpdateForm = JosephForm()):
        if not isinstance(form, AbstractUpdateForm):
            raise InputError(f"`form` must be JosephForm() or StandardForm(); got {form!r}.")
        if gain is not None:
            if not form.supports_any_gain:
                raise InputError(
                    f"`gain` was given with form={type(form).__name__}(), which is valid only for "
                    f"the optimal gain; use JosephForm() (the default) with a supplied gain."
                )
        self.gain = None if gain is None else checked_gain(gain)
        self.form = form

    def check_model(self, model):
        if not isinstance(model, LinearGaussianModel):
            raise InputError(
                f"KalmanFilter needs a LinearGaussianModel; got {type(model).__name__}. "
                f"Use ExtendedKalmanFilter or UnscentedKalmanFilter for nonlinear models."
            )
        if self.gain is not None:
            n, m = model.state_dim, model.meas_dim
            check_shape("gain", self.gain, [(n, m), (None, n, m)])

    def covariance_is_data_free(self, model):
        # P, W and S follow from F, H, Q, R, the prior and the schedule alone.
        return isinstance(model, LinearGaussianModel)

    def predict(self, model, mean, cov, k):
        return _predict_linearized(model, mean, cov, k, model.transition_matrix(k))

    def mean_map(self, model: LinearGaussianModel, gain: Array, k: Array, first_step="update") -> "MeanMap":
        """The update of the mean at step ``k`` as an affine map, given this step's gain ``W_k``.

        With the covariances computed once for a batch (they do not depend on the data), the
        mean recursion of :meth:`predict` + :meth:`update` is affine in the previous mean and
        the measurement: ``x⁺ = A x + W z + c``. Used, with :func:`mean_step`, by the
        shared-covariance paths of :func:`~jaxtrack.filters.run_filter_batch` and
        :func:`~jaxtrack.montecarlo.monte_carlo`; equal to :meth:`update` to rounding (tested).
        """
        n = model.state_dim
        dtype = model.initial_cov.dtype
        eye = jnp.eye(n, dtype=dtype)
        phi = model.transition_matrix(k)
        b = jnp.zeros((n,), dtype) if model.b is None else at_step(model.b, k, 1)
        if first_step == "update":
            phi = jnp.where(k == 0, eye, phi)
            b = jnp.where(k == 0, 0.0, b)
        H = model.measurement_matrix(k)
        IWH = eye - gain @ H
        return MeanMap(phi, b, IWH @ phi, IWH @ b, H @ phi, H @ b)

    def update(self, model, mean, cov, z, observed, k):
        H = model.measurement_matrix(k)
        gain = None if self.gain is None else at_step(self.gain, k, 2)
        return condition_linearized(
            mean, cov, z - matmul(H, mean), H, model.measurement_noise_cov(k), observed, gain,
            self.form,
        )


class ExtendedKalmanFilter(AbstractFilter):
    r"""Extended Kalman filter (first order), Joseph-form update.

    Linearises ``f`` at ``x̂_{k-1/k-1}`` and ``h`` at ``x̂_{k/k-1}`` (Ho 1968, eq. (2) and App. A)
    with the model's Jacobians (``jax.jacfwd`` unless the model supplies them). The innovation is
    ``model.residual(z, h(x̂))``, so angle components wrap to (−π, π]. On a linear model it is the
    Kalman filter.

    **Arguments:** ``form``: the covariance update, :class:`~jaxtrack.filters.JosephForm`
    (default) or :class:`~jaxtrack.filters.StandardForm`.
    """

    form: AbstractUpdateForm = JosephForm()

    def predict(self, model, mean, cov, k):
        return _predict_linearized(model, mean, cov, k, model.transition_jacobian(mean, k))

    def update(self, model, mean, cov, z, observed, k):
        H = model.measurement_jacobian(mean, k)
        innovation = model.residual(z, model.measurement(mean, k))
        return condition_linearized(
            mean, cov, innovation, H, model.measurement_noise_cov(k), observed, None, self.form
        )


class MeanMap(NamedTuple):
    """Per-step affine maps of the mean recursion with shared gains (one step, or with a leading ``T``).

    With ``Φ_k``, ``b_k`` the transition into step ``k`` (identity and 0 at ``k = 0`` when the
    prior sits at the first measurement) and ``W_k`` the gain:
    ``x⁻ = Φ x + b``, ``y = z − H x⁻``, ``x⁺ = x⁻ + W y = A x + W z + c`` with
    ``A = (I − W H) Φ``, ``c = (I − W H) b``; ``y = z − (H Φ) x − H b``.
    """

    transition: Array  # Φ_k (T, n, n)
    offset: Array  # b_k (T, n)
    update: Array  # A_k (T, n, n)
    update_offset: Array  # c_k (T, n)
    innovation_map: Array  # H_k Φ_k (T, m, n)
    innovation_offset: Array  # H_k b_k (T, m)


def mean_step(mp: MeanMap, gain, x, z, observed):
    """One step of the mean recursion with shared gains (the :class:`MeanMap` of step ``k``).

    ``x`` is ``(n,)`` or ``(n, B)`` (runs as the trailing axis), ``z`` ``(m,)`` or ``(m, B)``,
    ``observed`` ``(m,)``. Missing components of ``z`` are zeroed (they may hold NaN) and their
    innovations are 0. Returns ``(x⁺, y)``: ``x⁺ = A x + W z + c``, ``y = z − (HΦ) x − Hb``.

    **Arguments:**

    - ``mp``: the :class:`MeanMap` of step ``k`` (no leading ``T``); ``gain``: ``W_k``, ``(n, m)``.
    - ``x``: the previous filtered mean, ``(n,)`` or ``(n, B)``; ``z``: the measurement, ``(m,)`` or
      ``(m, B)``, in the model's units; ``observed``: boolean ``(m,)``.

    **Returns:** ``(x⁺, y)``: shapes ``(n,)`` and ``(m,)`` (``(n, B)`` and ``(m, B)`` batched).
    """
    col = (lambda v: v) if x.ndim == 1 else (lambda v: v[:, None])  # noqa: E731
    z = jnp.where(col(observed), z, 0.0)
    post = matmul(mp.update, x) + matmul(gain, z) + col(mp.update_offset)
    innovation = z - matmul(mp.innovation_map, x) - col(mp.innovation_offset)
    return post, jnp.where(col(observed), innovation, 0.0)

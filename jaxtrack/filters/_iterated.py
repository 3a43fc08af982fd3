"""Iterated extended Kalman filter: the measurement update as a fixed number of Gauss–Newton steps."""

from __future__ import annotations

import equinox as eqx
import jax
from jaxtyping import Array

from .._validation import InputError
from ._base import AbstractFilter
from ._kalman import _predict_linearized
from ._linalg import matmul
from ._updates import AbstractUpdateForm, Conditioned, JosephForm, condition_linearized


class IteratedExtendedKalmanFilter(AbstractFilter):
    r"""Iterated extended Kalman filter (IEKF): the EKF with a Gauss–Newton measurement update.

    The update relinearises ``h`` about its own latest estimate ``x^{(i)}`` (``x^{(0)} = x̂``,
    the prediction):

    .. math::

        H_i = ∂h/∂x\,(x^{(i)}),\quad
        W_i = P H_iᵀ (H_i P H_iᵀ + R)^{-1},\quad
        x^{(i+1)} = x̂ + W_i\,[z − h(x^{(i)}) − H_i (x̂ − x^{(i)})]

    (Bar-Shalom, Li & Kirubarajan 2001, §10.5.2, the iterated EKF). Each step is one
    Gauss–Newton step on the negative log-posterior
    ``½‖x − x̂‖²_{P⁻¹} + ½‖z − h(x)‖²_{R⁻¹}`` (Bell & Cathey 1993, IEEE TAC 38(2), §II), so
    the iterates approach its minimiser, the MAP estimate, when Gauss–Newton converges. The
    filtered mean is ``x^{(N)}``; the covariance comes from the last linearisation
    ``H_{N-1}`` in the update ``form`` (Joseph by default). The prediction is the EKF's.

    The number of iterations is fixed (a ``lax.fori_loop``, no data-dependent stopping), so the
    update is ``jit``-able, ``vmap``-able and differentiable, and every run of a batch does the
    same work. With ``num_iterations=1`` it is exactly the :class:`ExtendedKalmanFilter`. The
    step's reported innovation (and NIS) is that of the last linearisation,
    ``z − h(x^{(N-1)}) − H_{N-1}(x̂ − x^{(N-1)})``, whose covariance is the reported ``S``.
    The innovation goes through ``model.residual``, so angle components wrap to (−π, π].

    **Arguments:**

    - ``num_iterations``: ``N ≥ 1``, the number of linearisations of ``h`` per update
      (static int; default 5).
    - ``form``: the covariance update, :class:`~jaxtrack.filters.JosephForm` (default) or
      :class:`~jaxtrack.filters.StandardForm`.
    """

    num_iterations: int = eqx.field(static=True, default=5)
    form: AbstractUpdateForm = JosephForm()

    def __check_init__(self):
        n = self.num_iterations
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise InputError(f"`num_iterations` must be an int >= 1; got {n!r}.")
        if not isinstance(self.form, AbstractUpdateForm):
            raise InputError(f"`form` must be JosephForm() or StandardForm(); got {self.form!r}.")

    def predict(self, model, mean, cov, k):
        return _predict_linearized(model, mean, cov, k, model.transition_jacobian(mean, k))

    def update(self, model, mean, cov, z, observed, k) -> Conditioned:
        R = model.measurement_noise_cov(k)

        def linearized(x_i: Array):
            # The measurement linearised about x_i, written as an innovation of the prediction:
            # z − [h(x_i) + H_i (x̂ − x_i)]. At x_i = x̂ the correction term is exactly 0, so the
            # first iteration is the EKF's update to the last bit.
            H = model.measurement_jacobian(x_i, k)
            innovation = model.residual(z, model.measurement(x_i, k)) - matmul(H, mean - x_i)
            return innovation, H

        def gauss_newton_step(_, x_i):
            innovation, H = linearized(x_i)
            return condition_linearized(mean, cov, innovation, H, R, observed, None, self.form).mean

        # N − 1 relinearisations; the N-th linearisation also gives the covariance (and the
        # innovation, S and log-likelihood reported for the step).
        x_last = jax.lax.fori_loop(0, self.num_iterations - 1, gauss_newton_step, mean)
        innovation, H = linearized(x_last)
        return condition_linearized(mean, cov, innovation, H, R, observed, None, self.form)

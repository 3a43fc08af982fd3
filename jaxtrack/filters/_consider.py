r"""The consider (Schmidt–Kalman, reduced-state) filter: estimate some states, carry the rest.

The state is split as ``[x; c]``: ``x`` (the first ``num_estimated`` components) is estimated,
``c`` (the remaining ``p``) holds *considered* parameters — a sensor bias, a model constant —
whose uncertainty the filter accounts for without estimating them. The filter's estimate of
``c`` stays at its prior mean; the cross-covariance ``P_xc`` and the block ``P_cc`` are
propagated, so the gain and the covariance of ``x`` include the effect of the unknown ``c``.

One predict and one update, both of the library's linear Kalman filter:

.. math::

    P⁻ = F P F^T + Q,\qquad S = H P⁻ H^T + R,\qquad
    W = \begin{bmatrix} K \\ 0 \end{bmatrix},\quad K = [P⁻ H^T S^{-1}]_{x\text{ rows}}

    P⁺ = (I − W H) P⁻ (I − W H)^T + W R W^T

The optimal consider gain ``K`` is the ``x`` rows of the full Kalman gain: it minimises
``tr P⁺_xx`` over all gains with zero ``c`` rows. The Joseph update with those rows zero *is* the
consider covariance update (it leaves ``P_cc`` unchanged and gives
``P⁺_xc = (I − K H_x) P⁻_xc − K H_c P⁻_cc``), so the update is
:func:`~jaxtrack.filters.condition_linearized` with ``gain=W`` and no new covariance arithmetic.

References: S. F. Schmidt, "Application of state-space methods to navigation problems",
Advances in Control Systems 3, 1966; G. J. Bierman, *Factorization Methods for Discrete
Sequential Estimation*, 1977 (consider filtering and covariance); R. G. Brown and P. Y. C. Hwang,
*Introduction to Random Signals and Applied Kalman Filtering*, 4th ed., 2012 (the Schmidt–Kalman
filter). The radar-bias study (Serakos, Gray, Youssef, "Topics in mitigating radar bias",
eqs. (58)–(69); Mookerjee & Reifler, IEEE TAES 40(2), 2004) is the case ``c = λ``, a constant
measurement bias: ``P_xc = D Λ`` with the error sensitivity ``D = ∂ε/∂λ``, ``P_cc = Λ``,
``H = [H̃, W ∂u/∂λ]``, and (67)/(69) are the update and gain above.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .._validation import InputError, check_covariance, check_finite, check_shape
from ..models import LinearGaussianModel, at_step
from ._base import AbstractFilter
from ._kalman import KalmanFilter, _predict_linearized, checked_gain
from ._linalg import cholesky_and_inverse, matmul
from ._updates import JosephForm, condition_linearized, masked_noise, symmetrize

__all__ = ["ConsiderKalmanFilter", "consider_gain", "consider_model"]


def consider_gain(
    cov: Float[Array, "n n"],
    H: Float[Array, "m n"],
    R: Float[Array, "m m"],
    num_estimated: int,
    observed: Bool[Array, " m"] | None = None,
) -> Float[Array, "ne m"]:
    r"""The optimal consider (Schmidt–Kalman) gain: the estimated rows of ``P Hᵀ S⁻¹``.

    ``K = [P Hᵀ (H P Hᵀ + R)⁻¹]_{0:ne}``. With the rows of the considered states set to zero, it
    minimises ``tr P⁺_xx`` of the Joseph update (radar-bias paper eqs. (68)–(69), with the inverse
    on the right). Missing components (``observed`` False) get zero columns, as in
    :func:`~jaxtrack.filters.condition_linearized`.

    **Arguments:** ``cov`` the predicted covariance ``(n, n)`` of ``[x; c]``; ``H`` ``(m, n)``;
    ``R`` ``(m, m)``; ``num_estimated`` ``ne`` (static int, ``1 ≤ ne ≤ n``); ``observed``
    optional boolean ``(m,)``.

    **Returns:** ``K`` ``(ne, m)``.
    """
    if observed is None:
        observed = jnp.ones(H.shape[0], bool)
    obs_f = observed.astype(cov.dtype)
    H = H * obs_f[:, None]
    PHt = matmul(cov, H.T)
    # The same S and factorisation as condition_linearized, so that with ne = n the gain is the
    # Kalman filter's to the last bit.
    S = symmetrize(matmul(H, PHt) + masked_noise(R, observed))
    _, chol_inv = cholesky_and_inverse(S)
    return matmul(matmul(PHt, chol_inv.T), chol_inv)[:num_estimated]


class ConsiderKalmanFilter(AbstractFilter):
    r"""Consider (Schmidt–Kalman, reduced-state) Kalman filter on a linear model ``[x; c]``.

    The first ``num_estimated`` states ``x`` are estimated; the remaining ones ``c`` are
    *considered*: their estimate stays at the prior mean (zero gain rows) while their
    covariance and cross-covariance with ``x`` are propagated exactly. Per step (see the module
    docstring for the equations and references): the Kalman prediction, then
    :func:`consider_gain` padded with zero rows, then the Joseph update
    :func:`~jaxtrack.filters.condition_linearized` with that gain. ``filtered_cov`` is the
    *actual* error covariance of ``[x; c]`` (including the unestimated ``c``), valid for the
    optimal consider gain and for a supplied one.

    **Arguments:**

    - ``num_estimated``: ``ne``, the number of estimated (leading) states; static. With
      ``ne = n`` the filter is :class:`~jaxtrack.filters.KalmanFilter` (Joseph form).
    - ``gain``: optional fixed gain for the estimated states, ``(ne, m)`` or per step
      ``(T, ne, m)`` (e.g. an α-β filter); the considered rows are zero. An array leaf, so
      ``jax.grad`` with respect to it works.

    Requires a :class:`~jaxtrack.models.LinearGaussianModel` of dimension ``n = ne + p``
    (:func:`consider_model` builds one for constant considered parameters). Its covariances do
    not depend on the data, so batches share them
    (:func:`~jaxtrack.filters.covariance_pass`, :func:`~jaxtrack.filters.run_filter_batch`).

    Example — a position/velocity track with a constant, unestimated measurement bias::

        model = consider_model(F, Q, H, R, x0, P0, consider_matrix=jnp.ones((1, 1)),
                               consider_mean=jnp.zeros(1), consider_cov=25.0 * jnp.eye(1))
        result = run_filter(ConsiderKalmanFilter(2), model, zs, first_step="predict")
        x_hat = result.filtered_mean[:, :2]           # (T, 2) estimates of [p, v]
        P_xx = result.filtered_cov[:, :2, :2]         # (T, 2, 2) including the bias effect
        P_xc = result.filtered_cov[:, :2, 2:]         # (T, 2, 1) = D Λ (error sensitivity × Λ)
    """

    num_estimated: int = eqx.field(static=True)
    gain: Float[Array, "*T ne m"] | None = None

    def __init__(self, num_estimated: int, gain: ArrayLike | None = None):
        if isinstance(num_estimated, bool) or not isinstance(num_estimated, int) or num_estimated < 1:
            raise InputError(f"`num_estimated` must be a positive int; got {num_estimated!r}.")
        self.num_estimated = num_estimated
        self.gain = None if gain is None else checked_gain(gain, num_estimated)

    def check_model(self, model):
        if not isinstance(model, LinearGaussianModel):
            raise InputError(f"ConsiderKalmanFilter needs a LinearGaussianModel; got {type(model).__name__}.")
        n, m = model.state_dim, model.meas_dim
        if self.num_estimated > n:
            raise InputError(f"`num_estimated` = {self.num_estimated} exceeds the model's state dimension {n}.")
        if self.gain is not None:
            check_shape("gain", self.gain, [(self.num_estimated, m), (None, self.num_estimated, m)])

    def covariance_is_data_free(self, model):
        return isinstance(model, LinearGaussianModel)

    def mean_map(self, model, gain, k, first_step="update"):
        """The mean update as an affine map given the full (zero-padded) gain; as the Kalman filter's."""
        return KalmanFilter().mean_map(model, gain, k, first_step)

    def predict(self, model, mean, cov, k):
        return _predict_linearized(model, mean, cov, k, model.transition_matrix(k))

    def update(self, model, mean, cov, z, observed, k):
        H = model.measurement_matrix(k)
        R = model.measurement_noise_cov(k)
        ne = self.num_estimated
        if self.gain is None:
            gain = consider_gain(cov, H, R, ne, observed)
        else:
            gain = at_step(self.gain, k, 2).astype(cov.dtype)
        padded = jnp.concatenate([gain, jnp.zeros((cov.shape[0] - ne, gain.shape[1]), cov.dtype)])
        return condition_linearized(mean, cov, z - matmul(H, mean), H, R, observed, padded, JosephForm())


def _block_diag(a, b):
    """``blkdiag(a, b)`` for ``(*T, n, n)`` and ``(p, p)`` (``b`` broadcast over ``T``)."""
    lead = a.shape[:-2]
    n, p = a.shape[-1], b.shape[-1]
    top = jnp.concatenate([a, jnp.zeros(lead + (n, p), a.dtype)], axis=-1)
    bottom = jnp.concatenate([jnp.zeros(lead + (p, n), a.dtype), jnp.broadcast_to(b, lead + (p, p))], axis=-1)
    return jnp.concatenate([top, bottom], axis=-2)


def consider_model(
    transition_matrix: ArrayLike,
    process_noise_cov: ArrayLike,
    measurement_matrix: ArrayLike,
    measurement_noise_cov: ArrayLike,
    initial_mean: ArrayLike,
    initial_cov: ArrayLike,
    *,
    consider_matrix: ArrayLike,
    consider_mean: ArrayLike,
    consider_cov: ArrayLike,
) -> LinearGaussianModel:
    r"""The augmented linear model of a plant with constant considered parameters ``c``.

    .. math::

        \begin{bmatrix} x_k \\ c \end{bmatrix} =
        \begin{bmatrix} F & 0 \\ 0 & I \end{bmatrix}
        \begin{bmatrix} x_{k-1} \\ c \end{bmatrix} + \begin{bmatrix} w_k \\ 0 \end{bmatrix},\qquad
        z_k = H x_k + G c + v_k,

    with ``c ~ N(c̄, C)`` drawn once (independent of ``x``). Run :class:`ConsiderKalmanFilter`
    with ``num_estimated = n`` on it to estimate ``x`` while considering ``c``; simulate it with
    :func:`jaxtrack.montecarlo.simulate` to draw truths with a random constant ``c``.

    **Arguments** (``n`` states, ``m`` measurement components, ``p`` considered parameters; the
    plant matrices constant or per step with a leading ``T``, as in
    :class:`~jaxtrack.models.LinearGaussianModel`):

    - ``transition_matrix`` F ``(n, n)``; ``process_noise_cov`` Q ``(n, n)`` PSD;
    - ``measurement_matrix`` H ``(m, n)``; ``measurement_noise_cov`` R ``(m, m)`` PD;
    - ``initial_mean`` ``(n,)`` and ``initial_cov`` ``(n, n)``: the prior on ``x``;
    - ``consider_matrix`` G ``(m, p)``; ``consider_mean`` c̄ ``(p,)``; ``consider_cov`` C ``(p, p)``
      PSD (may be singular, e.g. 0 for a known parameter).

    **Returns:** a :class:`~jaxtrack.models.LinearGaussianModel` of dimension ``n + p`` with the
    prior ``N([x̄; c̄], blkdiag(P0, C))``.
    """
    F, Q, H, R, m0, P0, G, c0, C = (jnp.asarray(a) for a in (
        transition_matrix, process_noise_cov, measurement_matrix, measurement_noise_cov, initial_mean,
        initial_cov, consider_matrix, consider_mean, consider_cov))
    dtype = jnp.result_type(F, Q, H, R, m0, P0, G, c0, C, float)
    F, Q, H, R, m0, P0, G, c0, C = (a.astype(dtype) for a in (F, Q, H, R, m0, P0, G, c0, C))
    check_shape("initial_mean", m0, [(None,)])
    n = m0.shape[0]
    check_shape("initial_cov", P0, [(n, n)])
    check_shape("consider_mean", c0, [(None,)])
    p = c0.shape[0]
    check_shape("consider_cov", C, [(p, p)])
    check_shape("measurement_matrix", H, [(None, n), (None, None, n)])
    check_shape("consider_matrix", G, [(H.shape[-2], p), (None, H.shape[-2], p)])
    check_finite("consider_matrix", G)
    check_finite("consider_mean", c0)
    check_covariance("consider_cov", C, definite=False)
    check_covariance("initial_cov", P0)
    zeros_p = jnp.zeros((p, p), dtype)
    F_aug = _block_diag(F, jnp.eye(p, dtype=dtype))
    Q_aug = _block_diag(Q, zeros_p)
    lead = jnp.broadcast_shapes(H.shape[:-2], G.shape[:-2])
    H_aug = jnp.concatenate([jnp.broadcast_to(H, lead + H.shape[-2:]), jnp.broadcast_to(G, lead + G.shape[-2:])], axis=-1)
    mean = jnp.concatenate([m0, c0])
    cov = _block_diag(P0, C)
    # LinearGaussianModel asks for a definite prior; a considered block may be singular (a known
    # parameter, Λ = 0), which the consider filter and the simulation handle. Validate with the
    # definite plant prior and substitute the augmented one (checked PSD above).
    model = LinearGaussianModel(F_aug, Q_aug, H_aug, R, mean, _block_diag(P0, jnp.eye(p, dtype=dtype)))
    return eqx.tree_at(lambda mdl: mdl.initial_cov, model, cov)

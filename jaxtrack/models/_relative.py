"""Bearings-only relative-state models (two-dimensional target motion analysis).

State ``x_R = [r_x, r_y, V_x, V_y]``: the target's position and velocity *relative to the observer*
(x east, y north; m, m/s), constant-velocity motion without plant noise, and a compass bearing
``β = atan2(r_x, r_y)`` measured clockwise from north (:func:`jaxtrack.geometry.bearing`). The
observer's own motion enters as a known input ``u(k)`` subtracted in the prediction,
``x_R(k+1) = Φ(t_s) x_R(k) − u(k)`` with ``u(k) = x_O(k+1) − Φ(t_s) x_O(k)`` (Lindgren & Gong 1977,
eq. 67b; exact for any observer path).

Two models of the same physics:

- :func:`pseudolinear_bearing_model`: the *pseudo-linear* measurement ``0 = H(β_m) x_R + η`` with
  ``H(β_m) = [cos β_m, −sin β_m, 0, 0]`` built from the measured bearing (eqs. 11–13), a
  :class:`~jaxtrack.models.LinearGaussianModel` for :class:`~jaxtrack.filters.KalmanFilter`;
- :class:`RelativeBearingModel`: the nonlinear bearing measurement with its analytic Jacobian
  (Appendix D), for :class:`~jaxtrack.filters.ExtendedKalmanFilter` and the UKF.

Per-step arrays follow the library convention: entry ``k`` belongs to the interval that ends at
measurement ``k`` (with ``first_step="predict"`` the prior sits one sample before the first bearing).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._validation import check_finite, check_shape
from ..geometry import bearing
from ._base import AbstractStateSpaceModel, LinearGaussianModel

__all__ = [
    "constant_velocity_transition",
    "pseudolinear_measurement_row",
    "pseudolinear_bearing_model",
    "RelativeBearingModel",
]


def constant_velocity_transition(dt: ArrayLike, dtype=None, *, dim: int = 2) -> Array:
    """Constant-velocity transition ``Φ(dt) = [[I, dt I], [0, I]]`` for ``[positions…, velocities…]``.

    Lindgren & Gong eq. (1) (``Φ(i, j)`` with ``dt = (i − j) t_s``). Any sign of ``dt``:
    ``Φ(−dt) = Φ(dt)⁻¹``. The same matrix as :func:`~jaxtrack.models.constant_velocity`'s ``F``,
    without a noise model or a check that ``dt > 0``.

    **Arguments:** ``dt`` ``()`` s; ``dim`` spatial axes; ``dtype`` (default: that of ``dt``, at least float).

    **Returns:** ``(2·dim, 2·dim)``.
    """
    dt = jnp.asarray(dt, dtype=dtype)
    dt = dt.astype(jnp.result_type(dt, float))
    eye = jnp.eye(dim, dtype=dt.dtype)
    top = jnp.concatenate([eye, dt * eye], axis=1)
    bottom = jnp.concatenate([jnp.zeros((dim, dim), dt.dtype), eye], axis=1)
    return jnp.concatenate([top, bottom], axis=0)


def pseudolinear_measurement_row(measured_bearing: ArrayLike) -> Array:
    """Pseudo-linear measurement matrix ``H(β_m) = [cos β_m, −sin β_m, 0, 0]`` (Lindgren & Gong eq. 11).

    ``H(β_m) x_O = H(β_m) x_T + r_s sin(β_m − β)`` (eqs. 12–13): the bearing measured from the
    observer at ``x_O`` becomes a linear measurement of the target state, ``z = H x_O``, with the
    cross-range noise ``η = r_s sin ν`` (eq. 15); in relative state, ``H(β_m) x_R = −η``.

    **Arguments:** ``measured_bearing`` ``(...)`` rad, compass convention.

    **Returns:** ``(..., 4)``.
    """
    b = jnp.asarray(measured_bearing)
    b = b.astype(jnp.result_type(b, float))
    zero = jnp.zeros_like(b)
    return jnp.stack([jnp.cos(b), -jnp.sin(b), zero, zero], axis=-1)


def pseudolinear_bearing_model(
    measured_bearings: ArrayLike,
    noise_var: ArrayLike,
    sample_period: ArrayLike,
    initial_mean: ArrayLike,
    initial_cov: ArrayLike,
    *,
    observer_input: ArrayLike | None = None,
) -> LinearGaussianModel:
    """The pseudo-linear bearings-only model as a linear-Gaussian model (Lindgren & Gong eqs. 11–13, 67).

    ``x(k) = Φ(t_s) x(k−1) − u(k)``, no plant noise; ``z(k) = H(β_m(k)) x(k) + η(k)`` with the
    per-step row of :func:`pseudolinear_measurement_row` and ``Var η(k) = noise_var[k]``. For the
    relative state the measurement is ``z = 0``; for the target state (``observer_input`` None) it
    is ``z(k) = H(β_m(k)) x_O(k)`` (eq. 12). With ``noise_var = σ_ν²`` and ``initial_cov = P_N(0|0)``
    the covariance is the range-normalised ``P_N`` of Table 2 (eq. 69); with ``r_s²(k) σ_ν²`` and
    ``σ_0² I`` it is Table 1's.

    **Arguments:**

    - ``measured_bearings``: ``(T,)`` rad, the bearings the ``T`` updates use.
    - ``noise_var``: ``()`` or ``(T,)``, variance of the pseudo-measurement noise (rad², or m²).
    - ``sample_period``: ``t_s`` ``()``, s.
    - ``initial_mean`` ``(4,)``, ``initial_cov`` ``(4, 4)``: the prior, one sample before the first
      bearing when run with ``first_step="predict"``.
    - ``observer_input``: optional ``(T, 4)`` ``u``; entry ``k`` is subtracted in the prediction
      into measurement ``k`` (m, m/s).

    **Returns:** a :class:`~jaxtrack.models.LinearGaussianModel` with per-step ``H`` ``(T, 1, 4)``,
    ``R`` ``(T, 1, 1)`` and offset ``b = −u``.
    """
    b = jnp.asarray(measured_bearings)
    m0 = jnp.asarray(initial_mean)
    dtype = jnp.result_type(b, m0, float)
    b = b.astype(dtype)
    check_shape("measured_bearings", b, [(None,)])
    check_finite("measured_bearings", b)
    num = b.shape[0]
    var = jnp.asarray(noise_var, dtype)
    check_shape("noise_var", var, [(), (num,)])
    R = jnp.broadcast_to(var, (num,))[:, None, None]
    offset = None
    if observer_input is not None:
        u = jnp.asarray(observer_input, dtype)
        check_shape("observer_input", u, [(num, 4)])
        offset = -u
    return LinearGaussianModel(
        constant_velocity_transition(sample_period, dtype=dtype),
        jnp.zeros((4, 4), dtype),
        pseudolinear_measurement_row(b)[:, None, :],
        R,
        m0.astype(dtype),
        jnp.asarray(initial_cov, dtype),
        transition_offset=offset,
    )


class RelativeBearingModel(AbstractStateSpaceModel):
    r"""Relative-state bearings-only model with the nonlinear bearing measurement (Lindgren & Gong, Appendix D).

    State ``x = [r_x, r_y, V_x, V_y]`` (D-1), no plant noise (Q = 0).

    - Transition into measurement ``k``: ``x ↦ Φ(t_s) x − u(k)`` (D-4 with the observer input).
    - Measurement ``β = atan2(r_x, r_y)`` (D-6, compass convention) with the analytic Jacobian
      ``[r_y / r_s², −r_x / r_s², 0, 0] = [cos β̂ / r̂_s, −sin β̂ / r̂_s, 0, 0]`` (D-8…D-12), i.e. the
      pseudo-linear row at the predicted bearing divided by the range; residuals wrap to (−π, π]
      (D-14). The Jacobian is undefined at zero range.

    **Fields** (array leaves, differentiable): ``observer_input`` ``(T, 4)`` m, m/s;
    ``sample_period`` ``()`` s; ``bearing_var`` ``()`` rad²; ``initial_mean`` ``(4,)``;
    ``initial_cov`` ``(4, 4)``.
    """

    observer_input: Float[Array, "T 4"]
    sample_period: Float[Array, ""]
    bearing_var: Float[Array, ""]
    initial_mean: Float[Array, " 4"]
    initial_cov: Float[Array, "4 4"]
    angle_components: tuple[int, ...] = eqx.field(static=True)

    def __init__(self, observer_input, sample_period, bearing_var, initial_mean, initial_cov):
        m0 = jnp.asarray(initial_mean)
        dtype = jnp.result_type(m0, float)
        self.observer_input = jnp.asarray(observer_input, dtype)
        self.sample_period = jnp.asarray(sample_period, dtype)
        self.bearing_var = jnp.asarray(bearing_var, dtype)
        self.initial_mean = m0.astype(dtype)
        self.initial_cov = jnp.asarray(initial_cov, dtype)
        self.angle_components = (0,)
        check_shape("observer_input", self.observer_input, [(None, 4)])
        check_shape("initial_mean", self.initial_mean, [(4,)])
        check_shape("initial_cov", self.initial_cov, [(4, 4)])
        check_shape("bearing_var", self.bearing_var, [()])

    def transition(self, x, k):
        return constant_velocity_transition(self.sample_period, dtype=x.dtype) @ x - self.observer_input[k]

    def transition_jacobian(self, x, k):
        return constant_velocity_transition(self.sample_period, dtype=x.dtype)

    def measurement(self, x, k):
        return bearing(x)[None]

    def measurement_jacobian(self, x, k):
        # (D-9), (D-10): ∂β/∂r_x = cos β̂ / r̂ = r_y / r², ∂β/∂r_y = −sin β̂ / r̂ = −r_x / r².
        r2 = x[0] ** 2 + x[1] ** 2
        zero = jnp.zeros_like(r2)
        return jnp.stack([x[1] / r2, -x[0] / r2, zero, zero])[None, :]

    def process_noise_cov(self, k):
        return jnp.zeros((4, 4), self.initial_cov.dtype)

    def measurement_noise_cov(self, k):
        return self.bearing_var * jnp.ones((1, 1), self.initial_cov.dtype)

    @property
    def num_steps(self) -> int:
        return self.observer_input.shape[0]

"""Bearings-only TMA estimators: the pseudo-linear filters of Tables 1 and 2 and eq. (66), and the
Appendix D EKF — every one a call of :func:`jaxtrack.filters.run_filter` on a library model.

- The pseudo-linear filters are :class:`~jaxtrack.filters.KalmanFilter` with the report's standard
  covariance update (eq. 38, :class:`~jaxtrack.filters.StandardForm`; Joseph form on request, A24)
  on :func:`jaxtrack.models.pseudolinear_bearing_model`: per-step measurement row ``H(β_m(k))``,
  observer input ``u(k)`` as the per-step offset ``b = −u``, no plant noise, the prior one sample
  before the first bearing (``first_step="predict"``). The gains reported are the filter's own
  (:func:`jaxtrack.filters.covariance_pass`, the same step function).
- The EKF is :class:`~jaxtrack.filters.ExtendedKalmanFilter` on
  :class:`jaxtrack.models.RelativeBearingModel`.

``β_m(0)`` only initialises the filter (A12); the first update uses ``β_m(1)``. float64 is required
(spec §3.5 item 6); every function follows the dtype of its inputs.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from ..._validation import InputError, check_finite, check_shape
from ...filters import ExtendedKalmanFilter, JosephForm, KalmanFilter, StandardForm, covariance_pass, run_filter
from ...geometry import bearing, course
from ...models import (
    LinearGaussianModel,
    RelativeBearingModel,
    constant_velocity_transition,
    pseudolinear_bearing_model,
    pseudolinear_measurement_row,
)
from .scenario import EKF_VELOCITY_STD


class PseudoLinearEstimate(eqx.Module):
    """Output of the pseudo-linear filters over samples ``k = 0, …, K``.

    - ``mean``: ``(K+1, 4)`` ``x̂(k|k)``; row 0 is the initialisation ``x̂(0|0)`` (eq. 73).
    - ``cov``: ``(K+1, 4, 4)`` ``P(k|k)``; for Table 2 the normalized ``P_N(k|k) = P/r_s²``
      (eq. 69: m²/m² in position, 1/s² in velocity); row 0 is ``P(0|0)``.
    - ``gain``: ``(K, 4)`` ``K(k)`` for ``k = 1..K`` (eq. 44 / 71), row ``j`` is ``K(j+1)``
      (``None`` where not requested).
    """

    mean: Float[Array, "K1 4"]
    cov: Float[Array, "K1 4 4"]
    gain: Float[Array, "K 4"] | None


def _kalman_filter(joseph: bool) -> KalmanFilter:
    return KalmanFilter(form=JosephForm() if joseph else StandardForm())


@eqx.filter_jit
def _run_pseudolinear(model: LinearGaussianModel, z, joseph: bool, with_gain: bool, throw: bool):
    kf = _kalman_filter(joseph)
    res = run_filter(kf, model, z[:, None], first_step="predict", throw=throw)
    m0, P0 = model.initial_mean, model.initial_cov
    gain = None
    if with_gain:
        observed = jnp.ones((z.shape[0], 1), bool)
        gain = covariance_pass(kf, model, observed, "predict")[2][:, :, 0]
    return PseudoLinearEstimate(
        jnp.concatenate([m0[None], res.filtered_mean], axis=0),
        jnp.concatenate([P0[None], res.filtered_cov], axis=0),
        gain,
    )


def kalman_recursion(
    initial_mean: ArrayLike,
    initial_cov: ArrayLike,
    measurement_rows: ArrayLike,
    measurements: ArrayLike,
    inputs: ArrayLike,
    noise_var: ArrayLike,
    sample_period: ArrayLike,
    *,
    joseph: bool = False,
    throw: bool = False,
) -> PseudoLinearEstimate:
    r"""The scalar-measurement Kalman recursion of eqs. (38), (39), (42)–(44), no plant noise.

    For ``k = 0..K−1``: ``x̂(k+1|k) = Φ x̂(k|k) − u(k)``, ``P(k+1|k) = Φ P Φ'`` (43, 39, 67b);
    ``K = P(k+1|k) H' / [H P(k+1|k) H' + σ²(k+1)]`` (44); ``x̂(k+1|k+1) = x̂(k+1|k) + K [z − H x̂]``
    (42); ``P(k+1|k+1) = [I − K H] P(k+1|k)`` (38), or the Joseph form with ``joseph=True`` (A24).
    It is :class:`~jaxtrack.filters.KalmanFilter` (``StandardForm()`` / ``JosephForm()``) run by
    :func:`~jaxtrack.filters.run_filter` on a linear-Gaussian model with per-step ``H`` and ``R``
    and offset ``b = −u`` (the library symmetrises ``P`` after every update).

    This serves Table 1, Table 2, the target-state filter (66) and the generic checks of §2.2 and
    Appendix C.

    **Arguments** (``K`` updates):

    - ``initial_mean`` ``(4,)``, ``initial_cov`` ``(4, 4)``: ``x̂(0|0)``, ``P(0|0)``.
    - ``measurement_rows``: ``(K, 4)``, row ``j`` is ``H(j+1)``.
    - ``measurements``: ``(K,)`` ``z(j+1)``.
    - ``inputs``: ``(K, 4)`` ``u(j)``, subtracted in the prediction into sample ``j+1``.
    - ``noise_var``: ``()`` or ``(K,)`` ``σ²(j+1)``.
    - ``sample_period``: ``t_s`` (s).
    - ``throw``: raise if the recursion becomes non-finite (off by default, as the report's
      recursion: an indefinite float32 ``P`` is a documented outcome, spec §3.5 item 6).

    **Returns:** :class:`PseudoLinearEstimate`.
    """
    x0 = jnp.asarray(initial_mean)
    x0 = x0.astype(jnp.result_type(x0, float))
    dtype = x0.dtype
    P0 = jnp.asarray(initial_cov, dtype)
    H = jnp.asarray(measurement_rows, dtype)
    z = jnp.asarray(measurements, dtype)
    u = jnp.asarray(inputs, dtype)
    check_shape("initial_mean", x0, [(4,)])
    check_shape("initial_cov", P0, [(4, 4)])
    check_shape("measurement_rows", H, [(None, 4)])
    check_shape("measurements", z, [(H.shape[0],)])
    check_shape("inputs", u, [(H.shape[0], 4)])
    r = jnp.broadcast_to(jnp.asarray(noise_var, dtype), z.shape)
    model = LinearGaussianModel(
        constant_velocity_transition(sample_period, dtype=dtype), jnp.zeros((4, 4), dtype), H[:, None, :],
        r[:, None, None], x0, P0, transition_offset=-u,
    )
    return _run_pseudolinear(model, z, joseph, True, throw)


def initial_relative_state(measured_bearing0: ArrayLike, initial_range: ArrayLike) -> Array:
    """``x̂_R(0|0) = [r̂ sin β_m(0), r̂ cos β_m(0), 0, 0]'`` (eq. 73, Table 2 item 2-2).

    **Arguments:** ``measured_bearing0`` ``()`` rad; ``initial_range`` ``()`` m. **Returns:** ``(4,)``.
    """
    b = jnp.asarray(measured_bearing0)
    b = b.astype(jnp.result_type(b, float))
    r = jnp.asarray(initial_range, b.dtype)
    zero = jnp.zeros_like(b)
    return jnp.stack([r * jnp.sin(b), r * jnp.cos(b), zero, zero])


def _check_bearings(bearings, inputs):
    check_shape("bearings", bearings, [(None,)])
    k1 = bearings.shape[0]
    if k1 < 2:
        raise InputError(f"`bearings` needs β_m(0) and at least one more sample; got {k1}.")
    check_shape("observer_input", inputs, [(k1 - 1, 4)])
    check_finite("bearings", bearings)
    check_finite("observer_input", inputs)


def _float_bearings(bearings):
    b = jnp.asarray(bearings)
    return b.astype(jnp.result_type(b, float))


def _relative_filter(b, observer_input, sample_period, var, initial_range, P0, joseph, with_gain):
    """Relative-state pseudo-linear filter from ``β_m(0..K)``: start (eq. 73), model, run."""
    u = jnp.asarray(observer_input, b.dtype)
    _check_bearings(b, u)
    x0 = initial_relative_state(b[0], initial_range)
    model = pseudolinear_bearing_model(b[1:], var, sample_period, x0, P0, observer_input=u)
    return _run_pseudolinear(model, jnp.zeros_like(b[1:]), joseph, with_gain, False)


def normalized_pseudolinear_filter(
    bearings: ArrayLike,
    observer_input: ArrayLike,
    sample_period: ArrayLike,
    bearing_std: ArrayLike,
    initial_range: ArrayLike,
    *,
    initial_cov: ArrayLike | None = None,
    joseph: bool = False,
    with_gain: bool = True,
) -> PseudoLinearEstimate:
    r"""The normalized recursive algorithm of Table 2 (eqs. 69–75), relative state ``x_R``.

    ``x̂_R(0|0) = r̂_s(0)[sin β_m(0), cos β_m(0), 0, 0]'``, ``P_N(0|0) = I`` (2-2, 2-3); then the
    Kalman filter of :func:`kalman_recursion` with ``H = [cos β_m(k+1), −sin β_m(k+1), 0, 0]``
    (2-6), ``z = 0``, noise σ_ν² (2-7) and the general observer input ``u(k)`` of spec §3.5 (for
    point maneuvers ``[0; ΔV_O(k)]``, item 2-4). ``K`` and ``P_N`` depend only on the measured
    bearings, σ_ν, ``t_s`` and ``P_N(0|0)`` (not on ``r̂_s(0)`` nor on ``u``), so the estimate is
    affine in ``r̂_s(0)`` (:func:`~jaxtrack.applications.bearings_tma.initial_range_sensitivity`).
    ``r̂_s(0) = 0`` gives the minimum-norm solution: exactly zero before the first maneuver
    (eq. 52, Appendix C).

    **Arguments:**

    - ``bearings``: ``(K+1,)`` measured bearings ``β_m(0..K)``, rad; ``β_m(0)`` only initialises.
    - ``observer_input``: ``(K, 4)`` ``u(k)`` (:attr:`Scenario.observer_input`), m and m/s.
    - ``sample_period``: ``t_s``, s. ``bearing_std``: filter σ_ν, rad, ``()`` or ``(K,)``.
    - ``initial_range``: ``r̂_s(0)``, m (may be 0; differentiable).
    - ``initial_cov``: ``P_N(0|0)``, default ``I`` in SI units (eq. 75, A13).
    - ``joseph``: Joseph-form covariance update (A24). ``with_gain``: also return the gains.

    **Returns:** :class:`PseudoLinearEstimate` with ``cov = P_N``.
    """
    b = _float_bearings(bearings)
    P0 = jnp.eye(4, dtype=b.dtype) if initial_cov is None else jnp.asarray(initial_cov, b.dtype)
    return _relative_filter(b, observer_input, sample_period, jnp.asarray(bearing_std, b.dtype) ** 2,
                            initial_range, P0, joseph, with_gain)


def relative_state_filter(
    bearings: ArrayLike,
    observer_input: ArrayLike,
    sample_period: ArrayLike,
    bearing_std: ArrayLike,
    initial_range: ArrayLike,
    slant_range: ArrayLike,
    initial_var: ArrayLike,
) -> PseudoLinearEstimate:
    """The relative-state pseudo-linear filter of Table 1 (eqs. 67a/b, 44, 38).

    Like Table 2 but with the unnormalized covariance: ``P(0|0) = σ_0² I`` (item 1-3,
    ``initial_var = σ_0²``, m²) and measurement-noise variance ``r_s²(k+1) σ_ν²`` (item 1-7), which
    needs a range ``slant_range`` ``(K+1,)`` (m) that the report's Table 2 removes by
    normalization. With ``slant_range`` frozen at ``r_s(0)`` and ``σ_0² = r_s²(0)`` it is Table 2
    with ``P = r_s²(0) P_N`` (V15). Other arguments as :func:`normalized_pseudolinear_filter`.

    **Returns:** :class:`PseudoLinearEstimate` (``cov`` in m², m²/s, m²/s²).
    """
    b = _float_bearings(bearings)
    rs = jnp.asarray(slant_range, b.dtype)
    check_shape("slant_range", rs, [b.shape])
    P0 = jnp.asarray(initial_var, b.dtype) * jnp.eye(4, dtype=b.dtype)
    var = rs[1:] ** 2 * jnp.asarray(bearing_std, b.dtype) ** 2
    return _relative_filter(b, observer_input, sample_period, var, initial_range, P0, False, True)


def target_state_filter(
    bearings: ArrayLike,
    observer_states: ArrayLike,
    sample_period: ArrayLike,
    bearing_std: ArrayLike,
    initial_range: ArrayLike,
    *,
    initial_cov: ArrayLike | None = None,
) -> PseudoLinearEstimate:
    """The target-state pseudo-linear filter (eq. 66, Fig. 3a), normalized as Table 2.

    Measurement ``z(k) = H(β_m(k)) x_O(k)`` (eq. 12), prediction ``Φ x̂_T`` with no input, start
    ``x̂_T(0|0) = x̂_R(0|0) + x_O(0)``. It needs only observer *states*, so it also serves bearings
    from several platforms (one row of ``observer_states`` per bearing). For one observer it
    equals Table 2 shifted by the observer: ``x̂_T − x_O ≡ x̂_R`` (Fig. 3 equivalence, V15).

    **Arguments:** ``observer_states`` ``(K+1, 4)`` ``x_O(k)`` (m, m/s); others as
    :func:`normalized_pseudolinear_filter`. **Returns:** the *target* state estimate.
    """
    b = _float_bearings(bearings)
    xo = jnp.asarray(observer_states, b.dtype)
    check_shape("observer_states", xo, [(b.shape[0], 4)])
    _check_bearings(b, jnp.zeros((b.shape[0] - 1, 4), b.dtype))
    x0 = initial_relative_state(b[0], initial_range) + xo[0]
    P0 = jnp.eye(4, dtype=b.dtype) if initial_cov is None else jnp.asarray(initial_cov, b.dtype)
    model = pseudolinear_bearing_model(b[1:], jnp.asarray(bearing_std, b.dtype) ** 2, sample_period, x0, P0)
    z = jnp.sum(pseudolinear_measurement_row(b[1:]) * xo[1:], axis=1)
    return _run_pseudolinear(model, z, False, True, False)


class TrackSolution(eqx.Module):
    """Table 1 outputs (items 1-10 … 1-13) per sample: ``range`` r̂_s (m), ``bearing`` β̂ (rad),
    ``course`` Ĉ_T (rad in [0, 2π)), ``speed`` Ŝ_T (m/s); shapes follow the estimates ``(...)``."""

    range: Float[Array, "..."]
    bearing: Float[Array, "..."]
    course: Float[Array, "..."]
    speed: Float[Array, "..."]


def track_solution(relative_state: ArrayLike, observer_velocity: ArrayLike) -> TrackSolution:
    """Range, bearing, target course and speed from ``x̂_R`` (Table 1 items 1-10…1-13).

    **Arguments:** ``relative_state`` ``(..., 4)``; ``observer_velocity`` ``(..., 2)`` ``V_O(k)`` at the
    same samples (broadcast). The target velocity is ``V̂_T = V̂_R + V_O`` (eq. 68).

    **Returns:** :class:`TrackSolution`.
    """
    x = jnp.asarray(relative_state)
    x = x.astype(jnp.result_type(x, float))
    # Explicit broadcast: estimates often carry leading (run, initial-range) axes.
    vt = x[..., 2:] + jnp.broadcast_to(jnp.asarray(observer_velocity, x.dtype), x[..., 2:].shape)
    return TrackSolution(jnp.hypot(x[..., 0], x[..., 1]), bearing(x), course(vt), jnp.hypot(vt[..., 0], vt[..., 1]))


# --------------------------------------------------------------------------------------------
# Appendix D: the extended Kalman filter used for comparison


class EkfEstimate(eqx.Module):
    """Appendix D EKF over samples ``k = 0..K``: ``mean`` ``(K+1, 4)``, ``cov`` ``(K+1, 4, 4)``,
    ``ok`` ``()`` (False if the filter went non-finite)."""

    mean: Float[Array, "K1 4"]
    cov: Float[Array, "K1 4 4"]
    ok: Bool[Array, ""]


class EkfPrior(eqx.Module):
    """Appendix D prior: ``mean`` ``(4,)`` (m, m/s) and ``cov`` ``(4, 4)``."""

    mean: Float[Array, " 4"]
    cov: Float[Array, "4 4"]

    def __iter__(self):  # ``m0, P0 = ekf_prior(...)``
        return iter((self.mean, self.cov))


def ekf_prior(
    measured_bearing0: ArrayLike,
    initial_range: ArrayLike,
    observer_velocity0: ArrayLike,
    *,
    position_std: ArrayLike | None = None,
    velocity_std: ArrayLike = EKF_VELOCITY_STD,
) -> EkfPrior:
    """Appendix D initialisation (D-2, D-3) with the spec's resolutions (A8).

    ``x̂(0|0) = [r̂ sin β_m(0), r̂ cos β_m(0), −V_Ox(0), −V_Oy(0)]`` (target assumed stationary),
    ``P(0|0) = diag(σ_r², σ_r², σ_V², σ_V²)`` with ``σ_r = r̂_s(0)/2`` unless ``position_std``
    is given, and ``σ_V = 10`` m/s.

    **Arguments:** ``measured_bearing0`` ``()`` rad; ``initial_range`` ``()`` m;
    ``observer_velocity0`` ``(2,)`` m/s; ``position_std`` m; ``velocity_std`` m/s.

    **Returns:** :class:`EkfPrior` (unpacks as ``mean, cov``).
    """
    b = _float_bearings(measured_bearing0)
    r = jnp.asarray(initial_range, b.dtype)
    vo = jnp.asarray(observer_velocity0, b.dtype)
    check_shape("observer_velocity0", vo, [(2,)])
    mean = jnp.stack([r * jnp.sin(b), r * jnp.cos(b), -vo[0], -vo[1]])
    sr = 0.5 * r if position_std is None else jnp.asarray(position_std, b.dtype)
    sv = jnp.asarray(velocity_std, b.dtype)
    return EkfPrior(mean, jnp.diag(jnp.stack([sr, sr, sv, sv]) ** 2))


def bearing_ekf(
    bearings: ArrayLike,
    observer_input: ArrayLike,
    sample_period: ArrayLike,
    bearing_std: ArrayLike,
    initial_mean: ArrayLike,
    initial_cov: ArrayLike,
    *,
    throw: bool = True,
) -> EkfEstimate:
    """Run the Appendix D EKF (D-4 … D-15) on ``β_m(1..K)`` from the prior at sample 0.

    :class:`~jaxtrack.filters.ExtendedKalmanFilter` (Joseph form, which equals D-15 at the optimal
    gain up to round-off) on :class:`~jaxtrack.models.RelativeBearingModel`. The EKF cannot start
    at ``r̂_s(0) = 0`` (D-9 divides by the range, A9): such a prior raises when concrete.
    ``throw=False`` is for ``vmap``: read ``ok`` per run instead.

    **Arguments:** ``bearings`` ``(K+1,)`` rad; ``observer_input`` ``(K, 4)``; ``sample_period`` s;
    ``bearing_std`` rad; ``initial_mean`` ``(4,)``, ``initial_cov`` ``(4, 4)`` (:func:`ekf_prior`).

    **Returns:** :class:`EkfEstimate`.
    """
    b = _float_bearings(bearings)
    u = jnp.asarray(observer_input, b.dtype)
    _check_bearings(b, u)
    m0 = jnp.asarray(initial_mean, b.dtype)
    P0 = jnp.asarray(initial_cov, b.dtype)
    check_shape("initial_mean", m0, [(4,)])
    check_shape("initial_cov", P0, [(4, 4)])
    if not isinstance(m0, jax.core.Tracer) and float(jnp.hypot(m0[0], m0[1])) == 0.0:
        raise InputError("the EKF needs a nonzero initial range r̂_s(0) (Appendix D divides by it, A9).")
    model = RelativeBearingModel(u, jnp.asarray(sample_period, b.dtype), jnp.asarray(bearing_std, b.dtype) ** 2, m0, P0)
    res = run_filter(ExtendedKalmanFilter(), model, b[1:, None], first_step="predict", throw=throw)
    return EkfEstimate(
        jnp.concatenate([m0[None], res.filtered_mean], axis=0),
        jnp.concatenate([P0[None], res.filtered_cov], axis=0),
        res.ok,
    )

"""Covariance analysis of RS-1: the single-look least-squares, consider and closed-form covariances
and CEP (spec §3.5, V-24), and the 33-state filter's covariance over time (spec §2.9–2.10 [EXT])
through :func:`jaxtrack.covariance.covariance_recursion` with Van Loan discretisation."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ...covariance import CovarianceHistory, covariance_recursion
from ...models import (
    ErrorModelOptions,
    INSErrorBudget,
    LinearGaussianModel,
    NavigationRates,
    navigation_rates,
    van_loan,
)
from ...montecarlo import circular_error_probable
from .budgets import (
    MonopulseErrorBudget,
    SARErrorBudget,
    bias_covariance,
    h423_budget,
    measurement_noise_cov,
    prior_std,
    table6_budget,
    table7_budget,
)
from .error_model import error_dynamics, first_look_prior, gps_measurement_matrix, measurement_matrix, process_noise_density
from .geometry import LookGeometry, los_rotation_rate, radar_measurements
from .scenario import CASES, RS1_HEIGHT, Case, CovarianceScenario, rs1_trajectory
from .states import MISALIGNMENT, NUM_STATES, POSITION, RANGE_CLOCK, TARGET, TEMP_ELEVATION, _choice, _vec3
from .targeting import single_look_target

class SingleLookAnalysis(eqx.Module):
    """Single-look target-location accuracy of one look (spec §3.5, V-24). Covariances in nav axes (m²).

    - ``measurements`` ``[r, ṙ, A, E]``; ``cos_cone`` cos β = −ṙ/|v|; ``los_rate`` ω_t (E72);
      ``range_accel`` r̈ = (|v|² − ṙ²)/r; ``noise_std`` ``[σ_r, σ_ṙ, σ_A, σ_E]``.
    - ``target_jacobian`` ``H_t = ∂[r, ṙ, A, E]/∂r_tⁿ`` (4×3).
    - ``least_squares_cov`` ``(H_tᵀR⁻¹H_t)⁻¹`` (white noise only).
    - ``consider_cov``: the same estimator with the radar biases (Tables 6–7) and β as consider
      parameters.
    - ``closed_form_jacobian`` ``J = ∂r_t/∂[r, ṙ, A, E]`` of §1.7 (3×4) and ``closed_form_cov`` ``J R Jᵀ``.
    - ``cep_least_squares``, ``cep_consider``, ``cep_closed_form``: exact horizontal CEP (m).
    """

    measurements: Array
    cos_cone: Array
    los_rate: Array
    range_accel: Array
    noise_std: Array
    target_jacobian: Array
    least_squares_cov: Array
    consider_cov: Array
    closed_form_jacobian: Array
    closed_form_cov: Array
    cep_least_squares: Array
    cep_consider: Array
    cep_closed_form: Array


_BIAS_COLUMNS = np.r_[RANGE_CLOCK:TEMP_ELEVATION + 1, MISALIGNMENT.start:MISALIGNMENT.stop]


def single_look_analysis(look: LookGeometry, sar: SARErrorBudget | None = None,
                         monopulse: MonopulseErrorBudget | None = None) -> SingleLookAnalysis:
    """Least-squares, consider and closed-form covariance of one look (spec §3.5, V-24).

    **Arguments:** ``look``: one :class:`LookGeometry`; ``sar``, ``monopulse``: the budgets
    (default Tables 6 and 7).

    **Returns:** a :class:`SingleLookAnalysis` (covariances in NED, m²; CEPs in m).
    """
    sar = table6_budget() if sar is None else sar
    monopulse = table7_budget() if monopulse is None else monopulse
    return _single_look_analysis(look, sar, monopulse)


@eqx.filter_jit
def _single_look_analysis(look, sar, monopulse):
    m = radar_measurements(look)
    speed = jnp.linalg.norm(look.velocity)
    R = measurement_noise_cov(look, sar, monopulse)
    H = measurement_matrix(look)
    H_t = H[:, TARGET] @ look.nav_to_ecef()  # δr_t^e = C_n^e δr_tⁿ
    R_inv = jnp.linalg.inv(R)
    P_ls = jnp.linalg.inv(H_t.T @ R_inv @ H_t)
    K = P_ls @ H_t.T @ R_inv
    H_b = H[:, _BIAS_COLUMNS]
    P_consider = P_ls + K @ H_b @ bias_covariance(sar, monopulse) @ H_b.T @ K.T
    J = jax.jacfwd(single_look_target)(m, look.aircraft_position, look.velocity, look.body_to_nav(), look.antenna_to_body())
    P_cf = J @ R @ J.T
    ceps = circular_error_probable(jnp.stack([P_ls[:2, :2], P_consider[:2, :2], P_cf[:2, :2]]))
    return SingleLookAnalysis(m, -m[1] / speed, los_rotation_rate(m[0], m[1], speed), (speed ** 2 - m[1] ** 2) / m[0],
                              jnp.sqrt(jnp.diagonal(R)), H_t, P_ls, P_consider, J, P_cf, ceps[0], ceps[1], ceps[2])


class CovarianceAnalysis(eqx.Module):
    """Covariance history of the 33-state filter on RS-1 and the derived target errors.

    - ``times`` ``(T,)`` s; ``radar_observed`` ``(T,)`` bool (a look at that step).
    - ``history``: the :class:`~jaxtrack.covariance.CovarianceHistory` (P in the state's units).
    - ``target_cov`` ``(T, 3, 3)``: ``P_tⁿ = C_e^n P_t^e C_n^e`` after each step's update (m²).
    - ``relative_cov`` ``(T, 3, 3)``: ``cov(δr_tⁿ − δr_aⁿ)``, the relative targeting error (m²).
    - ``aircraft_cov`` ``(T, 3, 3)``: ``cov(δr_aⁿ)`` (m²).
    - ``target_cep``, ``relative_cep``, ``aircraft_cep`` ``(T,)``: exact horizontal CEPs (m).
    - ``common_mode_correlation`` ``(T,)``: correlation of the North errors of target and aircraft.
    """

    times: Array
    radar_observed: Array
    history: CovarianceHistory
    target_cov: Array
    relative_cov: Array
    aircraft_cov: Array
    target_cep: Array
    relative_cep: Array
    aircraft_cep: Array
    common_mode_correlation: Array


class RS1Model(eqx.Module):
    """The per-step model of :func:`rs1_model` and what is needed to read its covariances.

    - ``model``: the 33-state :class:`~jaxtrack.models.LinearGaussianModel` in scaled units
      (``x_s = x / scale``), per-step F, Q, H, R (leading axis T).
    - ``mask`` ``(T, 7)`` bool: the measurements ``[r, ṙ, A, E, GPS_N, GPS_E, GPS_D]`` used per step.
    - ``looks``: the batched :class:`LookGeometry` of the steps.
    - ``scale`` ``(33,)``: each state's prior σ (SI units); ``P = scale scaleᵀ ∘ P_s``.
    """

    model: LinearGaussianModel
    mask: Bool[Array, "T 7"]
    looks: LookGeometry
    scale: Float[Array, "33"]


def _float(x) -> Array:
    return jnp.asarray(x, jnp.result_type(x, float))


@eqx.filter_jit
def _rs1_arrays(looks, rates, ins, sar, monopulse, options, gps_std, step, std, noise_on):
    """Per-step F, Q (Van Loan), H, R and the first-look prior, in SI units; ``rates`` per step."""
    Qc = process_noise_density(ins, monopulse) * noise_on

    def dynamics(r):
        return van_loan(error_dynamics(r, monopulse, options), Qc, step)

    def measurement(look):
        H = jnp.concatenate([measurement_matrix(look), gps_measurement_matrix()])
        R = jax.scipy.linalg.block_diag(measurement_noise_cov(look, sar, monopulse), gps_std ** 2 * jnp.eye(3))
        return H, R

    F, Q = jax.vmap(dynamics)(rates)
    H, R = jax.vmap(measurement)(looks)
    P0 = first_look_prior(jax.tree.map(lambda a: a[0], looks), std, R[0, :4, :4])
    return F, Q, H, R, P0


@eqx.filter_jit
def _trajectory_rates(lat, velocity, attitude, options):
    return jax.vmap(lambda la, v, a: navigation_rates(la, RS1_HEIGHT, v, a, options=options))(lat, velocity, attitude)


def rs1_model(case: Case = "radar", scenario: CovarianceScenario = CovarianceScenario(), *,
              ins: INSErrorBudget | None = None, sar: SARErrorBudget | None = None,
              monopulse: MonopulseErrorBudget | None = None, options: ErrorModelOptions = ErrorModelOptions(),
              rates: NavigationRates | None = None, process_noise: bool = True) -> RS1Model:
    """The per-step 33-state :class:`~jaxtrack.models.LinearGaussianModel` of RS-1 and its mask, in scaled units.

    Measurements per step are ``[r, ṙ, A, E, GPS_N, GPS_E, GPS_D]`` (7 components); the mask
    selects those of ``case`` (:data:`CASES`). ``F``, ``Q`` per step come from
    :func:`jaxtrack.models.van_loan` of the continuous model at the interval's midpoint. ``rates``
    overrides the trajectory's :func:`navigation_rates` (V-21 freezes them); ``process_noise=False``
    sets Q = 0. Returns an :class:`RS1Model` ``(model, mask (T, 7), looks, scale (33,))``: the model's state is
    ``x_s = x / scale`` (each state in units of its prior σ; see the comment in the code), so
    a covariance ``P_s`` of the model is ``scale scaleᵀ ∘ P_s`` in SI units.

    **Arguments:** ``case``: one of :data:`CASES`; ``scenario``: :class:`CovarianceScenario`;
    ``ins``, ``sar``, ``monopulse``: budgets (default Tables 5–7); ``options``:
    :class:`~jaxtrack.models.ErrorModelOptions`; ``rates``: optional unbatched
    :class:`~jaxtrack.models.NavigationRates` held for every step; ``process_noise``: bool.

    **Returns:** :class:`RS1Model`.
    """
    _choice("case", case, tuple(CASES))
    ins = h423_budget() if ins is None else ins
    sar = table6_budget() if sar is None else sar
    monopulse = table7_budget() if monopulse is None else monopulse
    times = scenario.times
    looks = rs1_trajectory(times, flat_earth=scenario.flat_earth)
    if rates is None:  # the trajectory's rates at each interval's midpoint
        mid = rs1_trajectory(times - 0.5 * scenario.step, flat_earth=scenario.flat_earth)
        rates = _trajectory_rates(mid.lat, mid.velocity, mid.attitude, options)
    else:
        rates = jax.tree.map(lambda a: jnp.broadcast_to(a, (scenario.num_steps, *jnp.shape(a))), rates)
    F, Q, H, R, P0 = _rs1_arrays(looks, rates, ins, sar, monopulse, options, _float(scenario.gps_std),
                                 _float(scenario.step), prior_std(ins, sar, monopulse, scenario.nav),
                                 jnp.asarray(1.0 if process_noise else 0.0))
    k = np.arange(scenario.num_steps)
    look_steps = (k % scenario.look_every == 0) & (k > 0)  # the first look initialised the target
    gps_steps = k % scenario.gps_every == 0
    radar_cols = {"radar": [0, 1, 2, 3], "sar_only": [0, 1], "radar_gps": [0, 1, 2, 3]}[case]
    mask = np.zeros((scenario.num_steps, 7), bool)
    mask[np.ix_(look_steps, radar_cols)] = True
    if case == "radar_gps":
        mask[gps_steps, 4:] = True
    # The states' variances span ~20 orders of magnitude (ε² ≈ 4e-16 rad²/s² beside 1e3 m²), below
    # what an eigenvalue or Cholesky test of P resolves in float64 (eps·‖P‖ ≈ 4e-13). The filter
    # therefore runs in units of each state's prior σ: x = S x_s with S = diag(σ_0), F_s = S⁻¹FS,
    # Q_s = S⁻¹QS⁻¹, H_s = HS, P_s = S⁻¹PS⁻¹. Covariances are identical after unscaling (S P_s S).
    scale = jnp.sqrt(jnp.diagonal(P0))
    model = LinearGaussianModel(F * scale[None, None, :] / scale[None, :, None], Q / jnp.outer(scale, scale)[None],
                                H * scale[None, None, :], R, jnp.zeros(NUM_STATES), P0 / jnp.outer(scale, scale))
    return RS1Model(model, jnp.asarray(mask), looks, scale)


def rs1_covariance_analysis(case: Case = "radar", scenario: CovarianceScenario = CovarianceScenario(), **kwargs) -> CovarianceAnalysis:
    """Target-location error and CEP over time on RS-1 for one ``case`` (spec §2.9–2.10 [EXT]).

    Runs :func:`jaxtrack.covariance.covariance_recursion` (the Kalman filter's own Joseph-form
    step, data-free) on :func:`rs1_model`. Without GPS the shared (common-mode) position error
    of aircraft and target is unobservable (V-21): the looks bound the relative error
    δr_t − δr_a, while the absolute target error stays at the INS position error.

    **Arguments:** ``case``, ``scenario`` and the keywords of :func:`rs1_model`.

    **Returns:** a :class:`CovarianceAnalysis` over the scenario's ``T`` steps.
    """
    m = rs1_model(case, scenario, **kwargs)
    hist = unscale_history(covariance_recursion(m.model, mask=m.mask), m.scale)
    return _target_errors(hist, m.looks, scenario.times, m.mask[:, 0])


def unscale_history(hist: CovarianceHistory, scale: ArrayLike) -> CovarianceHistory:
    """A :class:`~jaxtrack.covariance.CovarianceHistory` of :func:`rs1_model` back in SI units.

    **Arguments:** ``hist``: the history of the scaled model; ``scale``: :attr:`RS1Model.scale`, ``(33,)``.

    **Returns:** the :class:`~jaxtrack.covariance.CovarianceHistory` in SI units.
    """
    s = jnp.asarray(scale)
    S = jnp.outer(s, s)[None]
    return CovarianceHistory(hist.predicted_cov * S, hist.filtered_cov * S, hist.gain * s[None, :, None], hist.innovation_cov)


@jax.jit
def _target_errors_jit(P, C_ne):
    C_en = jnp.swapaxes(C_ne, -1, -2)
    T_target = jnp.zeros((P.shape[0], 3, NUM_STATES), P.dtype).at[:, :, TARGET].set(C_en)
    T_relative = T_target.at[:, :, POSITION].set(jnp.broadcast_to(-jnp.eye(3), (P.shape[0], 3, 3)))
    sandwich = lambda T: T @ P @ jnp.swapaxes(T, -1, -2)  # noqa: E731
    target, relative = sandwich(T_target), sandwich(T_relative)
    aircraft = P[:, POSITION, POSITION]
    cross = jnp.einsum("tij,tjk->tik", T_target, P[:, :, POSITION])[:, 0, 0]
    corr = cross / jnp.sqrt(target[:, 0, 0] * aircraft[:, 0, 0])
    return target, relative, aircraft, corr


def _target_errors(hist, looks, times, observed) -> CovarianceAnalysis:
    target, relative, aircraft, corr = _target_errors_jit(hist.filtered_cov, looks.nav_to_ecef())
    ceps = circular_error_probable(jnp.stack([target, relative, aircraft])[..., :2, :2])
    return CovarianceAnalysis(times, observed, hist, target, relative, aircraft, ceps[0], ceps[1], ceps[2], corr)


def common_mode_information(cov: ArrayLike, direction: ArrayLike, nav_to_ecef_dcm: ArrayLike) -> Array:
    """``nᵀP⁻¹n`` for the unobservable direction ``n = [δr_a = c, δr_t^e = C_n^e c, 0 …]`` (V-21).

    ``direction`` is ``c`` (m, NED, shape ``(3,)``). The solve runs on the correlation matrix
    (``P`` scaled to unit diagonal), because the states' variances span ~20 orders of magnitude.

    **Arguments:** ``cov``: a 33-state covariance ``(33, 33)`` (SI); ``direction`` ``c`` ``(3,)``;
    ``nav_to_ecef_dcm``: ``C_n^e`` ``(3, 3)``.

    **Returns:** the information ``nᵀP⁻¹n``, shape ``()``.
    """
    P, c, C_ne = jnp.asarray(cov), _vec3("direction", direction), jnp.asarray(nav_to_ecef_dcm)
    n = jnp.zeros(P.shape[-1], P.dtype).at[POSITION].set(c).at[TARGET].set(C_ne @ c)
    d = jnp.sqrt(jnp.diagonal(P))
    corr = P / jnp.outer(d, d)
    y = n / d  # P = D C D with D = diag(σ): nᵀP⁻¹n = (D⁻¹n)ᵀ C⁻¹ (D⁻¹n)
    chol = jnp.linalg.cholesky(corr)
    return y @ jax.scipy.linalg.cho_solve((chol, True), y)

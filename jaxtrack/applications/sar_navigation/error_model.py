"""The 33-state linearised error model of SAR + INS targeting (Sec. 10–11, Tables 1–4).

``F = blockdiag(F_Ind, F_Radar)`` (E177): the 21 ψ-angle INS error states of
:func:`jaxtrack.models.ins_error_dynamics`, the target position error and the antenna
misalignment (random constants), and six radar biases. The measurement side holds the analytic
``H`` (Tables 3–4 corrected) and the exact nonlinear measurement error whose Jacobian at zero is
``H`` (V-10), and the closed-form first-look prior of the target (spec §2.8).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._validation import check_shape
from ...geometry import rotation_vector_to_dcm, skew
from ...models import (
    INS_STATE_DIM,
    ErrorModelOptions,
    INSErrorBudget,
    NavigationRates,
    discretize,
    ins_error_dynamics,
    ins_process_noise_density,
)
from .budgets import MonopulseErrorBudget, table7_budget
from .geometry import LookGeometry, _radar, radar_measurements
from .states import (
    ATTITUDE,
    DOPPLER_BIAS,
    FREQUENCY,
    MISALIGNMENT,
    NUM_STATES,
    POSITION,
    PROPAGATION_SPEED,
    RANGE_CLOCK,
    TARGET,
    TEMP_AZIMUTH,
    TEMP_ELEVATION,
    VELOCITY,
)
from .targeting import single_look_target


def error_dynamics(rates: NavigationRates, monopulse: MonopulseErrorBudget,
                   options: ErrorModelOptions = ErrorModelOptions()) -> Float[Array, "33 33"]:
    """``F = blockdiag(F_Ind, F_Radar)`` (E177), with ``F_Radar = diag(0, 0, 0, 0, −β_ATEMP, −β_ETEMP)`` (Table 2).

    **Arguments:** ``rates``: unbatched :class:`~jaxtrack.models.NavigationRates`; ``monopulse``:
    the Table 7 budget (its TEMP correlation time); ``options``: :class:`~jaxtrack.models.ErrorModelOptions`.

    **Returns:** ``F``, shape ``(33, 33)``; the target and β rows are zero (random constants).
    """
    F_ins = ins_error_dynamics(rates, options)
    F = jnp.zeros((NUM_STATES, NUM_STATES), F_ins.dtype).at[:INS_STATE_DIM, :INS_STATE_DIM].set(F_ins)
    beta = monopulse.temperature_inverse_correlation_time
    return F.at[TEMP_AZIMUTH, TEMP_AZIMUTH].set(-beta).at[TEMP_ELEVATION, TEMP_ELEVATION].set(-beta)


def process_noise_density(ins: INSErrorBudget, monopulse: MonopulseErrorBudget) -> Float[Array, "33 33"]:
    """State-space PSD of ``w = [w_Ind; w_Radar]`` (E183–E184, spec §2.8).

    ``q_v I`` on δv, ``q_ψ I`` on ψ (:func:`jaxtrack.models.ins_process_noise_density`), and
    ``2 β_TEMP σ_TEMP²`` on the TEMP states (zero for the default random bias; FIX-26).

    **Arguments:** ``ins``: :class:`~jaxtrack.models.INSErrorBudget`; ``monopulse``: Table 7 budget.

    **Returns:** ``Q_c``, shape ``(33, 33)``.
    """
    dtype = jnp.result_type(ins.accel_noise_psd, float)
    Qc = jnp.zeros((NUM_STATES, NUM_STATES), dtype).at[:INS_STATE_DIM, :INS_STATE_DIM].set(ins_process_noise_density(ins))
    q_temp = 2.0 * monopulse.temperature_inverse_correlation_time * monopulse.temperature ** 2
    return Qc.at[TEMP_AZIMUTH, TEMP_AZIMUTH].set(q_temp).at[TEMP_ELEVATION, TEMP_ELEVATION].set(q_temp)


def _look_frame(look: LookGeometry):
    p = look.line_of_sight
    r = jnp.linalg.norm(p)
    u = p / r
    C_bn = look.body_to_nav()
    C_an = C_bn @ look.antenna_to_body()
    return p, r, u, C_bn, C_an


@functools.partial(jax.jit, static_argnames=("printed_e133", "printed_e163"))
def measurement_matrix(look: LookGeometry, *, printed_e133: bool = False, printed_e163: bool = False) -> Float[Array, "4 33"]:
    r"""Analytic ``H = [H_Ind  H_Radar]`` of one look (Tables 3–4 corrected; E170–E173), rows
    ``[z_r, z_ṙ, z_A, z_E]``.

    Footnote quantities ``L = −(1/r)[I − u_p u_pᵀ]`` (FIX-22),
    ``(∇Aⁿ)ᵀ = −u_pyᵀ[I − u_p u_pᵀ]/(r sin A)``, ``(∇Eⁿ)ᵀ = −u_pzᵀ[I − u_p u_pᵀ]/(r sin E)`` (E150,
    E163 with FIX-31); ``C_e^n`` at the look's latitude and longitude (FIX-23).

    ``printed_e133=True`` uses the printed ``L = +(1/r)[I − uuᵀ]`` and ``printed_e163=True`` the
    printed ∇E without its minus sign: both are wrong and exist for the regression test V-13.

    **Arguments:** ``look``: one :class:`LookGeometry`; ``printed_e133``, ``printed_e163``: bools.

    **Returns:** ``H``, shape ``(4, 33)``.
    """
    p, r, u, C_bn, C_an = _look_frame(look)
    v = look.velocity
    C_en = look.nav_to_ecef().T
    u_py, u_pz = C_an[:, 1], C_an[:, 2]
    P = jnp.eye(3, dtype=u.dtype) - jnp.outer(u, u)
    L = (1.0 if printed_e133 else -1.0) / r * P
    sin_a = jnp.sqrt(1.0 - (u @ u_py) ** 2)
    sin_e = jnp.sqrt(1.0 - (u @ u_pz) ** 2)
    grad_a = -(u_py @ P) / (r * sin_a)
    grad_e = (1.0 if printed_e163 else -1.0) * (u_pz @ P) / (r * sin_e)
    rdot = -(u @ v)
    U = skew(u)
    H = jnp.zeros((4, NUM_STATES), u.dtype)
    H = H.at[0, POSITION].set(-u).at[0, TARGET].set(u @ C_en)
    H = H.at[1, POSITION].set(-(v @ L)).at[1, VELOCITY].set(-u).at[1, TARGET].set(v @ L @ C_en)
    for row, grad in ((2, grad_a), (3, grad_e)):
        H = H.at[row, POSITION].set(-grad).at[row, TARGET].set(grad @ C_en)
        H = H.at[row, ATTITUDE].set(-r * grad @ U).at[row, MISALIGNMENT].set(-r * grad @ U @ C_bn)
    H = H.at[0, RANGE_CLOCK].set(-1.0).at[0, PROPAGATION_SPEED].set(-r)  # Table 4 (FIX-33)
    H = H.at[1, DOPPLER_BIAS].set(-1.0).at[1, PROPAGATION_SPEED].set(-rdot).at[1, FREQUENCY].set(-rdot)
    return H.at[2, TEMP_AZIMUTH].set(-1.0).at[3, TEMP_ELEVATION].set(-1.0)


def _indicated(x: Array, look: LookGeometry):
    """INS-indicated aircraft/target state and DCMs for the error state ``x`` (E86–E97, E116–E117).

    The attitude errors act as exact rotations, ``C̄_b^n = exp(−[ψ×]) C_b^n`` and
    ``C̄_a^b = exp(−[β×]) C_a^b`` (first order: E109, E114). δv is added to the true velocity
    (FIX-39) and the nav frame is not perturbed (FIX-40).
    """
    C_en = look.nav_to_ecef().T
    r_a = look.aircraft_position + x[POSITION]
    r_t = look.target_position + C_en @ x[TARGET]
    v = look.velocity + x[VELOCITY]
    C_bn = rotation_vector_to_dcm(-x[ATTITUDE]) @ look.body_to_nav()
    C_ab = rotation_vector_to_dcm(-x[MISALIGNMENT]) @ look.antenna_to_body()
    return r_a, v, r_t, C_bn, C_ab


def _measured(x: Array, truth: Array, white: Array) -> Array:
    """Radar truth models (E56, E57, E82, E83): true values plus bias states minus white noise."""
    r, rdot = truth[0], truth[1]
    bias = jnp.stack([
        x[RANGE_CLOCK] + r * x[PROPAGATION_SPEED],
        x[DOPPLER_BIAS] + rdot * x[PROPAGATION_SPEED] + rdot * x[FREQUENCY],  # + ṙδF as printed (FIX-37)
        x[TEMP_AZIMUTH],
        x[TEMP_ELEVATION],
    ])
    return truth + bias - white


@jax.jit
def measurement_error(x: ArrayLike, look: LookGeometry) -> Float[Array, "4"]:
    """Exact nonlinear ``z(x) = indicated − measured`` (E166–E169; spec §2.7 [EXT]), white noise 0.

    ``jax.jacfwd(measurement_error)(zeros(33), look)`` equals :func:`measurement_matrix` (V-10);
    ``z(0) = 0`` (V-9). ``x`` is the 33-state error vector (index map in the module constants).

    **Arguments:** ``x``: the error state, shape ``(33,)``; ``look``: one :class:`LookGeometry`.

    **Returns:** ``z`` ``[r, ṙ, A, E]`` residuals (m, m/s, rad, rad), shape ``(4,)``.
    """
    x = jnp.asarray(x)
    check_shape("x", x, [(NUM_STATES,)])
    truth = radar_measurements(look)
    indicated = _radar(*_indicated(x, look))
    return indicated - _measured(x, truth, jnp.zeros((4,), x.dtype))


@jax.jit
def autodiff_measurement_matrix(look: LookGeometry) -> Float[Array, "4 33"]:
    """``∂z/∂x`` at ``x = 0`` of :func:`measurement_error` by ``jax.jacfwd``: the cross-check of
    :func:`measurement_matrix` (V-10).

    **Arguments:** ``look``: one :class:`LookGeometry`. **Returns:** shape ``(4, 33)``.
    """
    return jax.jacfwd(measurement_error)(jnp.zeros(NUM_STATES), look)


def gps_measurement_matrix() -> Float[Array, "3 33"]:
    """Loosely coupled GPS position ``z = r̄_aⁿ − r̃_GPS = δr_aⁿ + v`` (spec §2.10, [EXT], not in the report).

    **Returns:** ``H_GPS``, shape ``(3, 33)``.
    """
    return jnp.zeros((3, NUM_STATES)).at[:, POSITION].set(jnp.eye(3))


def first_look_target_error(x: ArrayLike, white: ArrayLike, look: LookGeometry) -> Float[Array, "3"]:
    """``δr_t^e`` of the closed-form first-look solution (§1.7) for error state ``x`` and white noise.

    The solution uses the measured ``[r, ṙ, A, E]`` (truth models E56–E83, with the white noise
    ``white`` of shape ``(4,)``) and the INS-indicated position, velocity and attitude with the
    nominal antenna DCM; the result is ``C_n^e (r̂_tⁿ − r_tⁿ)``. Its Jacobians in ``x`` and
    ``white`` give the correlated first-look prior of spec §2.8.

    **Arguments:** ``x`` ``(33,)``; ``white`` ``(4,)`` (m, m/s, rad, rad); ``look``: one :class:`LookGeometry`.

    **Returns:** ``δr_t^e`` (m, ECEF axes), shape ``(3,)``.
    """
    x, white = jnp.asarray(x), jnp.asarray(white)
    r_a, v, _, C_bn, C_ab = _indicated(x, look)
    measured = _measured(x, radar_measurements(look), white)
    estimate = single_look_target(measured, r_a, v, C_bn, C_ab)
    return look.nav_to_ecef() @ (estimate - look.target_position)


def error_response(rates: NavigationRates, initial_error: ArrayLike, times: ArrayLike,
                   monopulse: MonopulseErrorBudget | None = None, options: ErrorModelOptions = ErrorModelOptions()) -> Float[Array, "T 33"]:
    """Mean error-state response ``x(t) = Φ(t) x(0)`` of the 33-state model with constant rates.

    ``Φ(t)`` comes from :func:`jaxtrack.models.discretize` (Van Loan, as in the covariance
    analysis); ``times`` in s, shape ``(T,)``, each > 0.

    **Arguments:** ``rates``: unbatched :class:`~jaxtrack.models.NavigationRates`;
    ``initial_error``: ``x(0)``, shape ``(33,)``; ``times`` ``(T,)`` s; ``monopulse`` (default
    Table 7); ``options``: :class:`~jaxtrack.models.ErrorModelOptions`.

    **Returns:** ``x(t)``, shape ``(T, 33)``.
    """
    monopulse = table7_budget() if monopulse is None else monopulse
    F = error_dynamics(rates, monopulse, options)
    x0 = jnp.asarray(initial_error)
    check_shape("initial_error", x0, [(NUM_STATES,)])
    times = jnp.asarray(times)
    phis, _ = discretize(F, jnp.zeros_like(F), times.astype(jnp.result_type(times, F.dtype)))
    return phis @ x0


@jax.jit
def first_look_prior(look: LookGeometry, std: ArrayLike, R: ArrayLike) -> Float[Array, "33 33"]:
    """Prior covariance with the target initialised by the closed-form first look (spec §2.8).

    ``δr_t^e = G x + J_w w`` with ``G``, ``J_w`` the Jacobians of
    :func:`first_look_target_error`; the target block is ``G P Gᵀ + J_w R J_wᵀ`` and its
    cross-covariance with the other states ``G P`` (the first-look error is correlated with
    δr_a, δv_a, ψ, β and the radar biases; treating it as independent would be optimistic).
    ``std`` is :func:`prior_std` (its target entries are ignored); ``R`` the first look's noise.

    **Arguments:** ``look``: the first :class:`LookGeometry`; ``std`` ``(33,)``; ``R`` ``(4, 4)``.

    **Returns:** ``P0``, shape ``(33, 33)`` (SI units).
    """
    std = jnp.asarray(std).at[TARGET].set(0.0)
    P = jnp.diag(std ** 2)
    x0, w0 = jnp.zeros(NUM_STATES), jnp.zeros(4)
    G = jax.jacfwd(first_look_target_error, argnums=0)(x0, w0, look)
    J_w = jax.jacfwd(first_look_target_error, argnums=1)(x0, w0, look)
    A = jnp.eye(NUM_STATES).at[TARGET, :].set(G)
    B = jnp.zeros((NUM_STATES, 4)).at[TARGET, :].set(J_w)
    P0 = A @ P @ A.T + B @ jnp.asarray(R) @ B.T
    return 0.5 * (P0 + P0.T)  # the two products round differently

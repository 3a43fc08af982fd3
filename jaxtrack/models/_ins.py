r"""The ψ-angle (perturbation) error model of a local-level inertial navigation system.

The linearised dynamics of the navigation errors of an INS mechanised in the local-level NED frame,
in the ψ-angle form (Benson 1975; Layne & Blasch 1997, "Integrated SAR and navigation systems for
targeting applications", Sec. 10, Table 1, E178–E182, corrected as in ``specs/sar-navigation.md``,
FIX-24, FIX-25, FIX-32). On a spherical, rotating Earth:

.. code-block:: text

    d/dt δr = δv
    d/dt δv = F_vr δr − 2[ω×] δv + s[A×] ψ + ∇ + diag(A) k_∇ + w_v
    d/dt ψ  = −[ω×] ψ − s(ε + diag(ω) k_ε) + w_ψ
    d/dt (∇, k_∇, ε, k_ε) = 0

with ``ω = Ω + ρ`` (Earth rate plus transport rate, nav axes), ``A`` the specific force,
``F_vr = −[ω̇×] − [ω×]² + [Ω×]² + Γ`` (E178), ``Γ`` the gravity gradient and ``s = +1`` for the
convention ``C̄_b^n = (I − [ψ×]) C_b^n`` (see :class:`ErrorModelOptions`).

**State ordering** (:data:`INS_STATE_DIM` = 21; slices :data:`INS_POSITION` …):

=====  ==========  =====================================  =========
index  slice       state                                  unit
=====  ==========  =====================================  =========
0–2    position    δr, NED position error                 m
3–5    velocity    δv, NED velocity error                 m/s
6–8    attitude    ψ, attitude error angles (nav axes)    rad
9–11   accel bias  ∇, accelerometer biases                m/s²
12–14  accel SF    k_∇, accelerometer scale factors       –
15–17  gyro bias   ε, gyro drift                          rad/s
18–20  gyro SF     k_ε, gyro scale factors                –
=====  ==========  =====================================  =========

The sensor errors are random constants (zero dynamics); the white noises ``w_v``, ``w_ψ`` have
PSDs ``q_v`` (m²/s³) and ``q_ψ`` (rad²/s) per axis (:class:`INSErrorBudget`). Studies augment the
21 states with their own (target, misalignment, radar biases) by embedding :func:`ins_error_dynamics`
in a larger matrix. Discretise with :func:`jaxtrack.models.van_loan`.

Units are SI and radians; vectors in nav axes are NED.
"""

from __future__ import annotations

import math
from typing import Callable, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, PyTree

from .._validation import InputError
from ..geometry._navigation import _vec3, body_to_ned_rotation
from ..geometry._rotations import _stack_matrix, skew

EARTH_RATE = 7.292115e-5
"""Ω_e, Earth's rotation rate, rad/s (WGS-84)."""
EARTH_RADIUS = 6378137.0
"""R, radius of the spherical Earth of the ψ-angle model, m (WGS-84 equatorial radius)."""
GRAVITY = 9.80665
"""g, standard gravity, m/s²."""
EARTH_MU = 3.986004418e14
"""μ, Earth's gravitational parameter, m³/s² (WGS-84)."""

INS_POSITION = slice(0, 3)
INS_VELOCITY = slice(3, 6)
INS_ATTITUDE = slice(6, 9)
INS_ACCEL_BIAS = slice(9, 12)
INS_ACCEL_SCALE = slice(12, 15)
INS_GYRO_BIAS = slice(15, 18)
INS_GYRO_SCALE = slice(18, 21)
INS_STATE_DIM = 21
INS_STATE_NAMES = tuple(
    [f"dr_{c}" for c in "NED"] + [f"dv_{c}" for c in "NED"] + [f"psi_{c}" for c in "xyz"]
    + [f"accel_bias_{c}" for c in "xyz"] + [f"accel_sf_{c}" for c in "xyz"]
    + [f"gyro_bias_{c}" for c in "xyz"] + [f"gyro_sf_{c}" for c in "xyz"]
)

PsiConvention = Literal["consistent", "report_literal"]
GravityGradient = Literal["physical", "report"]
SensorFrame = Literal["nav", "body"]


def _choice(name: str, value, allowed) -> None:
    if value not in allowed:
        raise InputError(f"`{name}` must be one of {', '.join(map(repr, allowed))}; got {value!r}.")


class ErrorModelOptions(eqx.Module):
    """Conventions of the ψ-angle error dynamics (all static).

    - ``psi_sign_convention``: ``"consistent"`` (``F_vψ = +[A×]``, ``ψ̇ = −[ω×]ψ − ε − diag(ω)k_ε``,
      matching ``C̄_b^n = (I − [ψ×]) C_b^n``) or ``"report_literal"`` (Layne & Blasch Table 1 as
      printed: ``−[A×]``, ``+ε``) (FIX-24).
    - ``vertical_gravity_gradient``: ``"physical"`` ``Γ = ω_s² diag(−1, −1, +2)`` (unstable
      vertical channel) or ``"report"`` ``Γ = −ω_s² I`` as printed (FIX-25).
    - ``sensor_frame``: ``"nav"`` (local-level platform: sensor errors act in nav axes, Table 1) or
      ``"body"`` (strapdown: ``∇ → C_b^n ∇``, ``k_∇ → C_b^n diag(f^b)``, ``ε → C_b^n ε``,
      ``k_ε → C_b^n diag(ω_ib^b)``) (FIX-32).
    """

    psi_sign_convention: PsiConvention = eqx.field(static=True, default="consistent")
    vertical_gravity_gradient: GravityGradient = eqx.field(static=True, default="physical")
    sensor_frame: SensorFrame = eqx.field(static=True, default="nav")

    def __check_init__(self):
        _choice("psi_sign_convention", self.psi_sign_convention, ("consistent", "report_literal"))
        _choice("vertical_gravity_gradient", self.vertical_gravity_gradient, ("physical", "report"))
        _choice("sensor_frame", self.sensor_frame, ("nav", "body"))


class NavigationRates(eqx.Module):
    """The reference-trajectory quantities that enter the error dynamics, in nav axes (NED).

    A batch of flight conditions has a leading axis on every field.

    - ``earth_rate`` Ωⁿ (rad/s), ``transport_rate`` ρⁿ (rad/s), ``transport_rate_dot`` ρ̇ⁿ (rad/s²).
    - ``specific_force`` A = f = a − g (m/s²; ≈ ``[0, 0, −g]`` in level flight) (FIX-24).
    - ``gravity_gradient`` Γ (1/s², ``(3, 3)``).
    - ``body_to_nav`` C_b^n and ``body_rate`` ω_ib^b (rad/s): used by ``sensor_frame="body"``.
    """

    earth_rate: Float[Array, "*B 3"]
    transport_rate: Float[Array, "*B 3"]
    transport_rate_dot: Float[Array, "*B 3"]
    specific_force: Float[Array, "*B 3"]
    gravity_gradient: Float[Array, "*B 3 3"]
    body_to_nav: Float[Array, "*B 3 3"]
    body_rate: Float[Array, "*B 3"]


class INSErrorBudget(eqx.Module):
    """RMS of the INS sensors' random constants and the PSDs of their white noises (one axis).

    - ``accel_bias``: ∇ RMS, m/s².   ``accel_scale_factor``: k_∇ RMS, –.
    - ``accel_noise_psd``: q_v, m²/s³ (velocity random walk).
    - ``gyro_bias``: ε RMS, rad/s.   ``gyro_scale_factor``: k_ε RMS, –.
    - ``gyro_noise_psd``: q_ψ, rad²/s (angle random walk).
    """

    accel_bias: Float[Array, ""]
    accel_scale_factor: Float[Array, ""]
    accel_noise_psd: Float[Array, ""]
    gyro_bias: Float[Array, ""]
    gyro_scale_factor: Float[Array, ""]
    gyro_noise_psd: Float[Array, ""]


def earth_rate_nav(lat: ArrayLike) -> Float[Array, "... 3"]:
    """``Ωⁿ = Ω_e [cos φ, 0, −sin φ]``: Earth's rate in NED axes (Layne & Blasch spec §2.6).

    **Arguments:** ``lat`` φ (rad), shape ``(...)``.

    **Returns:** ``(..., 3)``, rad/s.
    """
    lat = jnp.asarray(lat)
    return EARTH_RATE * jnp.stack([jnp.cos(lat), jnp.zeros_like(lat), -jnp.sin(lat)], axis=-1)


def transport_rate(lat: ArrayLike, height: ArrayLike, velocity: ArrayLike, radius: float = EARTH_RADIUS) -> Float[Array, "3"]:
    """``ρⁿ = [v_E, −v_N, −v_E tan φ]/(R + h)``: the NED frame's rate over a spherical Earth (spec §2.6).

    **Arguments:** ``lat`` φ (rad) and ``height`` h (m), shape ``()``; ``velocity`` ``[v_N, v_E, v_D]``
    (m/s), shape ``(3,)``; ``radius`` R (m).

    **Returns:** ρⁿ, shape ``(3,)``, rad/s.
    """
    v = jnp.asarray(velocity)
    rh = radius + jnp.asarray(height)
    return jnp.stack([v[1], -v[0], -v[1] * jnp.tan(jnp.asarray(lat))]) / rh


def gravity_gradient(convention: GravityGradient = "physical", *, gravity: float = GRAVITY,
                     radius: float = EARTH_RADIUS) -> Float[Array, "3 3"]:
    """The gravity gradient Γ in NED axes with ``ω_s² = g/R`` (FIX-25).

    **Arguments:** ``convention``: ``"physical"`` ``ω_s² diag(−1, −1, +2)`` or ``"report"`` the
    printed ``−ω_s² I``; ``gravity`` g (m/s²), ``radius`` R (m).

    **Returns:** Γ, shape ``(3, 3)``, 1/s².
    """
    _choice("vertical_gravity_gradient", convention, ("physical", "report"))
    ws2 = gravity / radius
    return ws2 * jnp.diag(jnp.array([-1.0, -1.0, 2.0 if convention == "physical" else -1.0]))


def navigation_rates(lat, height, velocity, attitude, *, acceleration=(0.0, 0.0, 0.0),
                     options: ErrorModelOptions = ErrorModelOptions(), radius: float = EARTH_RADIUS,
                     gravity: float = GRAVITY) -> NavigationRates:
    """:class:`NavigationRates` of a flight condition over a spherical, rotating Earth.

    ρ̇ is the derivative of ρⁿ along the trajectory (``φ̇ = v_N/(R + h)``, ``ḣ = −v_D``), by
    ``jax.jvp``. The specific force is ``f = v̇ + (2Ω + ρ) × v − [0, 0, g]`` (the navigation
    equation) and the body rate ``ω_ib^b = C_n^b (Ω + ρ)`` (attitude held fixed in the nav frame).

    **Arguments:**

    - ``lat`` φ (rad), ``height`` h (m): shape ``()``.
    - ``velocity`` v_aⁿ (m/s), ``attitude`` ``[roll, pitch, yaw]`` (rad): shape ``(3,)``.
    - ``acceleration``: nav-frame derivative of v_aⁿ (m/s²), shape ``(3,)``.
    - ``options``: :class:`ErrorModelOptions` (its gravity-gradient convention is used).
    - ``radius`` R (m), ``gravity`` g (m/s²).

    **Returns:** :class:`NavigationRates` (unbatched; use ``jax.vmap`` along a trajectory).
    """
    dtype = jnp.result_type(lat, height, velocity, float)
    lat, height = jnp.asarray(lat, dtype), jnp.asarray(height, dtype)
    v, vdot = _vec3("velocity", velocity, dtype), _vec3("acceleration", acceleration, dtype)
    rh = radius + height
    rho, rho_dot = jax.jvp(lambda la, h, vel: transport_rate(la, h, vel, radius), (lat, height, v),
                           (v[0] / rh, -v[2], vdot))
    Omega = earth_rate_nav(lat)
    f = vdot + jnp.cross(2.0 * Omega + rho, v) - jnp.array([0.0, 0.0, gravity], dtype)
    C_bn = body_to_ned_rotation(_vec3("attitude", attitude, dtype))
    Gamma = gravity_gradient(options.vertical_gravity_gradient, gravity=gravity, radius=radius).astype(dtype)
    return NavigationRates(Omega, rho, rho_dot, f, Gamma, C_bn, C_bn.T @ (Omega + rho))


def velocity_error_position_gain(rho: ArrayLike, rho_dot: ArrayLike, earth_rate: ArrayLike,
                                 gamma: ArrayLike) -> Float[Array, "3 3"]:
    """``F_vr`` = ∂(δv̇)/∂(δr) written out element by element (Layne & Blasch E178, corrected: FIX-25).

    With ``ω = Ω + ρ``: diagonal ``|ω|² − |Ω|² − (ω_i + Ω_i)ρ_i + Γ_ii``, the ρ̇ terms off it.
    Equals :func:`velocity_error_position_gain_compact` (tested).

    **Arguments:** ``rho`` ρⁿ (rad/s), ``rho_dot`` ρ̇ⁿ (rad/s²), ``earth_rate`` Ωⁿ (rad/s), shape
    ``(3,)``; ``gamma`` Γ (1/s²), shape ``(3, 3)``.

    **Returns:** ``F_vr``, shape ``(3, 3)``, 1/s².
    """
    r, rd, W, G = (jnp.asarray(a) for a in (rho, rho_dot, earth_rate, gamma))
    w = W + r
    s = w + W
    d = w @ w - W @ W
    return G + _stack_matrix([
        [d - s[0] * r[0], rd[2] - s[1] * r[0], -rd[1] - s[2] * r[0]],
        [-rd[2] - s[0] * r[1], d - s[1] * r[1], rd[0] - s[2] * r[1]],
        [rd[1] - s[0] * r[2], -rd[0] - s[1] * r[2], d - s[2] * r[2]],
    ])


def velocity_error_position_gain_compact(rho: ArrayLike, rho_dot: ArrayLike, earth_rate: ArrayLike,
                                         gamma: ArrayLike) -> Float[Array, "3 3"]:
    """``F_vr = −[ω̇×] − [ω×]² + [Ω×]² + Γ`` with ``ω = Ω + ρ``, ``ω̇ = ρ̇ + Ω × ρ`` (compact E178).

    **Arguments** and **Returns:** as :func:`velocity_error_position_gain`.
    """
    r, rd, W, G = (jnp.asarray(a) for a in (rho, rho_dot, earth_rate, gamma))
    w = skew(W + r)
    return -skew(rd + jnp.cross(W, r)) - w @ w + skew(W) @ skew(W) + G


def ins_error_dynamics(rates: NavigationRates, options: ErrorModelOptions = ErrorModelOptions()) -> Float[Array, "21 21"]:
    """The continuous-time system matrix ``F`` of the 21 ψ-angle INS error states (Table 1, E178–E182).

    See the module docstring for the equations and the state ordering; ``sensor_frame="body"``
    gives the strapdown coupling of the sensor errors.

    **Arguments:** ``rates``: unbatched :class:`NavigationRates`; ``options``: :class:`ErrorModelOptions`.

    **Returns:** ``F``, shape ``(21, 21)`` (``ẋ = F x + w``).
    """
    Omega, rho = rates.earth_rate, rates.transport_rate
    omega = Omega + rho
    f = rates.specific_force
    dtype = jnp.result_type(omega, f, rates.gravity_gradient)
    I3 = jnp.eye(3, dtype=dtype)
    sign = 1.0 if options.psi_sign_convention == "consistent" else -1.0
    if options.sensor_frame == "nav":
        accel_bias, accel_scale = I3, jnp.diag(f)
        gyro_bias, gyro_scale = I3, jnp.diag(omega)
    else:
        C = rates.body_to_nav
        accel_bias, accel_scale = C, C @ jnp.diag(C.T @ f)
        gyro_bias, gyro_scale = C, C @ jnp.diag(rates.body_rate)
    F = jnp.zeros((INS_STATE_DIM, INS_STATE_DIM), dtype)
    F = F.at[INS_POSITION, INS_VELOCITY].set(I3)
    F = F.at[INS_VELOCITY, INS_POSITION].set(
        velocity_error_position_gain(rho, rates.transport_rate_dot, Omega, rates.gravity_gradient))
    F = F.at[INS_VELOCITY, INS_VELOCITY].set(-2.0 * skew(omega))  # E179
    F = F.at[INS_VELOCITY, INS_ATTITUDE].set(sign * skew(f))  # E180 with FIX-24
    F = F.at[INS_VELOCITY, INS_ACCEL_BIAS].set(accel_bias)
    F = F.at[INS_VELOCITY, INS_ACCEL_SCALE].set(accel_scale)  # E182
    F = F.at[INS_ATTITUDE, INS_ATTITUDE].set(-skew(omega))  # E181
    F = F.at[INS_ATTITUDE, INS_GYRO_BIAS].set(-sign * gyro_bias)
    return F.at[INS_ATTITUDE, INS_GYRO_SCALE].set(-sign * gyro_scale)


def ins_process_noise_density(budget: INSErrorBudget) -> Float[Array, "21 21"]:
    """PSD of the white noise ``w`` of the 21 INS error states (E183–E184): ``q_v I`` on δv, ``q_ψ I`` on ψ.

    The same in nav or body axes, since ``C (q I) Cᵀ = q I``.

    **Arguments:** ``budget``: :class:`INSErrorBudget`.

    **Returns:** ``Q_c``, shape ``(21, 21)`` (m²/s³ on δv, rad²/s on ψ, zero elsewhere).
    """
    diag = jnp.zeros((INS_STATE_DIM,), jnp.result_type(budget.accel_noise_psd, float))
    return jnp.diag(diag.at[INS_VELOCITY].set(budget.accel_noise_psd).at[INS_ATTITUDE].set(budget.gyro_noise_psd))


# --------------------------------------------------------------------------------------------
# Schuler closed forms (Ω = ρ = 0, level platform): checks of the error dynamics


def schuler_frequency(gravity: float = GRAVITY, radius: float = EARTH_RADIUS) -> float:
    """The Schuler frequency ``ω_s = sqrt(g/R)`` (1.2399764e-3 rad/s for the defaults; period 84.4530 min).

    **Arguments:** ``gravity`` g (m/s²), ``radius`` R (m), Python floats.

    **Returns:** ω_s (rad/s), a Python float.
    """
    return math.sqrt(gravity / radius)


def schuler_rates(gravity: float = GRAVITY, radius: float = EARTH_RADIUS) -> NavigationRates:
    """:class:`NavigationRates` of the classical closed forms: a stationary, level platform on a
    non-rotating Earth (Ω = ρ = ρ̇ = 0, ``A = [0, 0, −g]``, ``Γ = ω_s² diag(−1, −1, 2)``, C_b^n = I).

    **Arguments:** ``gravity`` g (m/s²), ``radius`` R (m).

    **Returns:** unbatched :class:`NavigationRates`; with :func:`ins_error_dynamics` it gives the
    Schuler responses :func:`horizontal_accel_bias_response`, :func:`vertical_accel_bias_response`
    and :func:`gyro_bias_position_response`.
    """
    z = jnp.zeros(3)
    return NavigationRates(z, z, z, jnp.array([0.0, 0.0, -gravity]),
                           gravity_gradient("physical", gravity=gravity, radius=radius), jnp.eye(3), z)


def _omega_s(omega_s):
    return schuler_frequency() if omega_s is None else omega_s


def horizontal_accel_bias_response(bias: ArrayLike, t: ArrayLike, omega_s: float | None = None) -> Array:
    """Horizontal position error of a constant accelerometer bias: ``δr = b(1 − cos ω_s t)/ω_s²`` (m).

    The Schuler oscillation of :func:`ins_error_dynamics` with :func:`schuler_rates`.
    **Arguments:** ``bias`` b (m/s²), ``t`` (s), broadcast-compatible; ``omega_s`` (rad/s, default
    :func:`schuler_frequency`). **Returns:** δr (m), the broadcast shape.
    """
    ws = _omega_s(omega_s)
    return jnp.asarray(bias) * (1.0 - jnp.cos(ws * jnp.asarray(t))) / ws ** 2


def vertical_accel_bias_response(bias: ArrayLike, t: ArrayLike, omega_s: float | None = None) -> Array:
    """Vertical (Down) position error of a constant vertical accelerometer bias with
    ``Γ_33 = +2ω_s²``: ``δr_D = b(cosh(√2 ω_s t) − 1)/(2ω_s²)`` (m; the unstable vertical channel).

    **Arguments** and **Returns:** as :func:`horizontal_accel_bias_response`.
    """
    ws = _omega_s(omega_s)
    return jnp.asarray(bias) * (jnp.cosh(math.sqrt(2.0) * ws * jnp.asarray(t)) - 1.0) / (2.0 * ws ** 2)


def gyro_bias_position_response(gyro_bias: ArrayLike, t: ArrayLike, omega_s: float | None = None,
                                gravity: float = GRAVITY) -> Array:
    """Horizontal position error of a constant horizontal gyro drift ε: ``R ε (t − sin(ω_s t)/ω_s)``
    with ``R = g/ω_s²`` (m). The attitude error grows as ``ψ = −ε t`` (consistent convention).

    **Arguments:** ``gyro_bias`` ε (rad/s), ``t`` (s); ``omega_s`` (rad/s); ``gravity`` g (m/s²).
    **Returns:** the error magnitude (m); its sign per axis is ``δr_N = −R ε_E(…)``, ``δr_E = +R ε_N(…)``.
    """
    ws = _omega_s(omega_s)
    t = jnp.asarray(t)
    return gravity / ws ** 2 * jnp.asarray(gyro_bias) * (t - jnp.sin(ws * t) / ws)


# --------------------------------------------------------------------------------------------
# A fixed-step ODE integrator for verification simulations


def rk4(rhs: Callable[[Array, PyTree], PyTree], y0: PyTree, t0: ArrayLike, dt: ArrayLike,
        num_steps: int) -> PyTree:
    """Classical fourth-order Runge–Kutta with a fixed step, as one ``lax.scan``.

    Used to integrate truth models (nonlinear navigation equations, DCM kinematics) against the
    linear error model; not a filter. Jit-able and differentiable.

    **Arguments:**

    - ``rhs``: ``(t, y) -> dy/dt`` with ``y`` any pytree of arrays.
    - ``y0``: the state at ``t0``; ``t0``, ``dt``: start time and step (s).
    - ``num_steps``: a positive int (static).

    **Returns:** the pytree of states at ``t0 + dt·k`` for ``k = 1 … num_steps``, each leaf with a
    leading axis ``num_steps``.
    """
    if not isinstance(num_steps, int) or num_steps < 1:
        raise InputError(f"`num_steps` must be a positive int; got {num_steps!r}.")

    def axpy(y, a, k):
        return jax.tree.map(lambda yi, ki: yi + a * ki, y, k)

    def step(y, k):
        t = t0 + k * dt
        k1 = rhs(t, y)
        k2 = rhs(t + 0.5 * dt, axpy(y, 0.5 * dt, k1))
        k3 = rhs(t + 0.5 * dt, axpy(y, 0.5 * dt, k2))
        k4 = rhs(t + dt, axpy(y, dt, k3))
        y = jax.tree.map(lambda a, b1, b2, b3, b4: a + dt / 6.0 * (b1 + 2 * b2 + 2 * b3 + b4), y, k1, k2, k3, k4)
        return y, y

    _, ys = jax.lax.scan(step, y0, jnp.arange(num_steps))
    return ys

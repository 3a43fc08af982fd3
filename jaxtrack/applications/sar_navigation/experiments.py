"""Verification experiments of the error dynamics (V-16, V-19): the linear ψ-angle model against
nonlinear truth simulations, integrated with :func:`jaxtrack.models.rk4`."""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ...geometry import body_to_ned_rotation, ned_to_ecef_rotation, skew, vee
from ...models import EARTH_MU, EARTH_RADIUS, EARTH_RATE, earth_rate_nav, rk4, transport_rate
from ...models._ins import GravityGradient
from .states import _choice, _vec3

RESPONSE_TIMES = np.linspace(10.0, 600.0, 60)  # s: the grid of V-17/V-18 rows and their figure


class InertialErrorExperiment(eqx.Module):
    """Result of :func:`accelerometer_bias_experiment`.

    - ``times`` ``(T,)`` s; ``nonlinear`` ``(T, 3)`` δrⁿ of the rotating-Earth truth (m, NED);
      ``linear`` ``(T, 3)`` δrⁿ of the Pinson model (m, NED).
    """

    times: Float[Array, " T"]
    nonlinear: Float[Array, "T 3"]
    linear: Float[Array, "T 3"]


def accelerometer_bias_experiment(
    bias_nav=(1e-3, -2e-3, 5e-4), duration: float = 1500.0, *, dt: float = 1.0, lat0: float = 0.6, lon0: float = 0.3,
    height: float = 7620.0, velocity_ne=(150.0, 130.0), gamma: GravityGradient = "physical",
) -> InertialErrorExperiment:
    """V-16: the Pinson model against a nonlinear rotating-Earth inertial simulation.

    Truth: a constant-altitude flight with constant ``v_N``, ``v_E`` over a spherical Earth with
    Newtonian gravitation ``G = −μ r/|r|³`` rotating at Ω_e. The error caused by a constant
    nav-axis accelerometer bias obeys, in ECEF, the exact equation
    ``δr̈ = C_n^e b + G(r + δr) − G(r) − 2Ω × δṙ − Ω × (Ω × δr)`` (the specific forces of the true
    and erroneous trajectories cancel). The linear model propagates ``[δrⁿ, δvⁿ]`` with
    ``F_vr = −[ω̇×] − [ω×]² + Γ`` and ``F_vv = −2[ω×]`` along the same trajectory, with
    ``Γ = (μ/r³) diag(−1, −1, 2)`` (``gamma="physical"``) or the printed ``−(μ/r³) I``; there is
    no ``[Ω×]²`` term, because G is Newtonian (not plumb-bob) gravity. Both are integrated with
    RK4 at ``dt``.

    **Arguments:** ``bias_nav``: the NED accelerometer bias ``b`` (m/s²), shape ``(3,)``;
    ``duration``, ``dt`` (s); ``lat0``, ``lon0`` (rad); ``height`` (m); ``velocity_ne``
    ``(v_N, v_E)`` (m/s); ``gamma``: ``"physical"`` or ``"report"``.

    **Returns:** an :class:`InertialErrorExperiment` with ``T = duration/dt`` steps.
    """
    _choice("gamma", gamma, ("physical", "report"))
    b = _vec3("bias_nav", bias_nav)
    rh = EARTH_RADIUS + height
    Gamma = EARTH_MU / rh ** 3 * jnp.diag(jnp.array([-1.0, -1.0, 2.0 if gamma == "physical" else -1.0]))
    n = int(round(duration / dt))
    params = jnp.array([dt, lat0, lon0, height, velocity_ne[0], velocity_ne[1]], b.dtype)
    return InertialErrorExperiment(*_accelerometer_bias_core(b, Gamma, params, n))


@functools.partial(jax.jit, static_argnums=3)
def _accelerometer_bias_core(b, Gamma, params, n):
    dt, lat0, lon0, height, vn, ve = (params[i] for i in range(6))
    rh = EARTH_RADIUS + height
    Omega_e = jnp.array([0.0, 0.0, EARTH_RATE])

    def lat_lon(t):
        lat = lat0 + vn * t / rh
        # constant v_E: dλ/dφ = (v_E/v_N) sec φ, integrated in closed form (inverse Gudermannian)
        lon = lon0 + ve / vn * (jnp.arctanh(jnp.sin(lat)) - jnp.arctanh(jnp.sin(lat0)))
        return lat, lon

    def position(t):
        lat, lon = lat_lon(t)
        return rh * jnp.stack([jnp.cos(lat) * jnp.cos(lon), jnp.cos(lat) * jnp.sin(lon), jnp.sin(lat)])

    def gravitation(r):
        return -EARTH_MU * r / jnp.linalg.norm(r) ** 3

    def nonlinear_rhs(t, y):
        dr, dv = y
        lat, lon = lat_lon(t)
        r = position(t)
        acc = (ned_to_ecef_rotation(lat, lon) @ b + gravitation(r + dr) - gravitation(r)
               - 2.0 * jnp.cross(Omega_e, dv) - jnp.cross(Omega_e, jnp.cross(Omega_e, dr)))
        return (dv, acc)

    def omega_nav(t):
        lat, _ = lat_lon(t)
        return earth_rate_nav(lat) + transport_rate(lat, height, jnp.stack([vn, ve, 0.0 * vn]))

    def linear_rhs(t, y):
        dr, dv = y
        w = omega_nav(t)
        w_dot = jax.jacfwd(omega_nav)(t)
        W = skew(w)
        F_vr = -skew(w_dot) - W @ W + Gamma
        return (dv, F_vr @ dr - 2.0 * W @ dv + b)

    zeros = (jnp.zeros(3, b.dtype), jnp.zeros(3, b.dtype))
    dr_e, _ = rk4(nonlinear_rhs, zeros, 0.0, dt, n)
    dr_n, _ = rk4(linear_rhs, zeros, 0.0, dt, n)
    times = dt * jnp.arange(1, n + 1)
    lat, lon = lat_lon(times)
    nonlinear = jnp.einsum("tji,tj->ti", ned_to_ecef_rotation(lat, lon), dr_e)
    return times, nonlinear, dr_n

class AttitudeErrorExperiment(eqx.Module):
    """Result of :func:`gyro_bias_attitude_experiment`: ``times`` ``(T,)`` s, ``psi_simulated``
    ``(T, 3)`` ψ read from the true and indicated DCMs and ``psi_model`` ``(T, 3)`` ψ of the
    linear model (rad)."""

    times: Float[Array, " T"]
    psi_simulated: Float[Array, "T 3"]
    psi_model: Float[Array, "T 3"]


def gyro_bias_attitude_experiment(
    gyro_bias_body=(4e-5, -6e-5, 3e-5), body_rate=(0.02, -0.01, 0.015), nav_rate=(5e-5, -3e-5, 8e-5),
    duration: float = 100.0, *, dt: float = 0.05,
) -> AttitudeErrorExperiment:
    """V-19: the ψ dynamics against a simulation of the true and the indicated DCM.

    ``Ċ = C[ω_ib^b×] − [ω_inⁿ×]C`` for the truth and the same with ``ω_ib^b + ε^b`` for the
    indicated ``C̄``; ψ is read from ``C̄Cᵀ = I − [ψ×]`` (skew part). The model integrates the
    consistent ``ψ̇ = −ω_in × ψ − C_b^n ε^b`` (FIX-24). Rates are constant, rad/s.

    **Arguments:** ``gyro_bias_body`` ε^b, ``body_rate`` ω_ib^b, ``nav_rate`` ω_inⁿ (rad/s), shape
    ``(3,)`` each; ``duration``, ``dt`` (s).

    **Returns:** an :class:`AttitudeErrorExperiment` with ``T = duration/dt`` steps.
    """
    eps, wb, wn = _vec3("gyro_bias_body", gyro_bias_body), _vec3("body_rate", body_rate), _vec3("nav_rate", nav_rate)
    C0 = body_to_ned_rotation(jnp.array([0.1, -0.2, 0.7], eps.dtype))

    def rhs(t, y):
        C, C_bar, psi = y
        return (C @ skew(wb) - skew(wn) @ C, C_bar @ skew(wb + eps) - skew(wn) @ C_bar, -jnp.cross(wn, psi) - C @ eps)

    n = int(round(duration / dt))
    C, C_bar, psi = jax.jit(lambda: rk4(rhs, (C0, C0, jnp.zeros(3, eps.dtype)), 0.0, dt, n))()
    psi_sim = -vee(C_bar @ jnp.swapaxes(C, -1, -2))
    return AttitudeErrorExperiment(dt * jnp.arange(1, n + 1), psi_sim, psi)

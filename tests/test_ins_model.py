"""The ψ-angle INS error model of jaxtrack.models (Layne & Blasch 1997, Table 1, E178–E184)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpy.testing import assert_allclose

import jaxtrack.models as m
from jaxtrack import InputError
from jaxtrack.geometry import skew

KEY = jax.random.key(11)
T = np.linspace(10.0, 600.0, 60)


def _response(x0, rates=None, options=m.ErrorModelOptions()):
    F = m.ins_error_dynamics(m.schuler_rates() if rates is None else rates, options)
    phis, _ = m.discretize(F, jnp.zeros_like(F), jnp.asarray(T))
    return np.asarray(phis @ x0)


def test_schuler_frequency():
    ws = m.schuler_frequency()
    assert_allclose(ws, 1.2399764e-3, rtol=1e-7)
    assert_allclose(2 * math.pi / ws / 60, 84.4530, atol=1e-4)
    # the stationary platform's F has the Schuler pair ±iω_s on each horizontal channel and the
    # unstable vertical pair ±√2 ω_s
    F = np.asarray(m.ins_error_dynamics(m.schuler_rates()))
    pos_vel = np.r_[0:6]
    ev = np.linalg.eigvals(F[np.ix_(pos_vel, pos_vel)])
    assert_allclose(np.sort(np.abs(ev.imag))[-4:], [ws] * 4, rtol=1e-12)
    assert_allclose(np.sort(ev.real)[[0, -1]], [-math.sqrt(2) * ws, math.sqrt(2) * ws], rtol=1e-12)


def test_stationary_platform_accelerometer_bias_response():
    b = 30e-6 * m.GRAVITY
    north = _response(jnp.zeros(21).at[m.INS_ACCEL_BIAS.start].set(b))
    east = _response(jnp.zeros(21).at[m.INS_ACCEL_BIAS.start + 1].set(b))
    down = _response(jnp.zeros(21).at[m.INS_ACCEL_BIAS.start + 2].set(b))
    assert_allclose(north[:, 0], np.asarray(m.horizontal_accel_bias_response(b, T)), rtol=2e-8)
    assert_allclose(east[:, 1], north[:, 0], rtol=1e-9)  # expm rounds each axis differently
    assert_allclose(down[:, 2], np.asarray(m.vertical_accel_bias_response(b, T)), rtol=2e-8)
    assert_allclose(north[-1, 0], 50.5579, atol=5e-5)
    # the velocity error is the derivative of the position error
    ws = m.schuler_frequency()
    assert_allclose(north[:, 3], b * np.sin(ws * T) / ws, rtol=2e-8)
    # the printed Γ33 = −ω_s² makes the vertical channel oscillate like the horizontal ones
    import equinox as eqx
    literal = eqx.tree_at(lambda r: r.gravity_gradient, m.schuler_rates(), m.gravity_gradient("report"))
    down_lit = _response(jnp.zeros(21).at[m.INS_ACCEL_BIAS.start + 2].set(b), literal)
    assert_allclose(down_lit[:, 2], np.asarray(m.horizontal_accel_bias_response(b, T)), rtol=2e-8)


def test_stationary_platform_gyro_bias_response():
    eps = 0.004 * math.pi / 180 / 3600
    x = _response(jnp.zeros(21).at[m.INS_GYRO_BIAS.start + 1].set(eps))  # East gyro drift
    assert_allclose(x[:, m.INS_ATTITUDE.start + 1], -eps * T, rtol=2e-8)  # ψ̇ = −ε (consistent)
    assert_allclose(x[:, 0], -np.asarray(m.gyro_bias_position_response(eps, T)), rtol=2e-8)
    lit = _response(jnp.zeros(21).at[m.INS_GYRO_BIAS.start + 1].set(eps),
                    options=m.ErrorModelOptions(psi_sign_convention="report_literal"))
    assert_allclose(lit[:, m.INS_ATTITUDE.start + 1], eps * T, rtol=2e-8)
    assert_allclose(lit[:, 0], x[:, 0], rtol=1e-12)  # both signs flip: the position error is the same


def test_velocity_error_gain_forms_agree():
    for i in range(3):
        W, rho, rho_dot = (1e-4 * jax.random.normal(jax.random.fold_in(KEY, 3 * i + j), (3,)) for j in range(3))
        G = jax.random.normal(jax.random.fold_in(KEY, 100 + i), (3, 3)) * 1e-6
        assert_allclose(np.asarray(m.velocity_error_position_gain(rho, rho_dot, W, G)),
                        np.asarray(m.velocity_error_position_gain_compact(rho, rho_dot, W, G)), atol=1e-20)


def test_navigation_rates_of_a_flight_condition():
    lat, h, v = 0.7, 7620.0, jnp.array([180.0, 40.0, -5.0])
    r = m.navigation_rates(lat, h, v, jnp.array([0.05, 0.03, 0.25]))
    assert_allclose(float(jnp.linalg.norm(r.earth_rate)), m.EARTH_RATE, rtol=1e-15)
    assert_allclose(np.asarray(r.transport_rate), np.asarray(m.transport_rate(lat, h, v)), rtol=1e-15)
    # ρ̇ is the derivative of ρ along the trajectory: φ̇ = v_N/(R + h), ḣ = −v_D
    dt = 1e-3
    rh = m.EARTH_RADIUS + h
    ahead = m.transport_rate(lat + v[0] / rh * dt, h - v[2] * dt, v)
    behind = m.transport_rate(lat - v[0] / rh * dt, h + v[2] * dt, v)
    assert_allclose(np.asarray(r.transport_rate_dot), np.asarray((ahead - behind) / (2 * dt)), rtol=1e-6)
    # at rest: f = −g (Down) and ω_ib^b = C_n^b Ω
    rest = m.navigation_rates(lat, 0.0, jnp.zeros(3), jnp.zeros(3))
    assert_allclose(np.asarray(rest.specific_force), [0.0, 0.0, -m.GRAVITY], atol=1e-15)
    assert_allclose(np.asarray(rest.body_rate), np.asarray(m.earth_rate_nav(lat)), atol=1e-20)
    # batched along a trajectory with vmap: a Module with a leading axis
    batch = jax.vmap(lambda la: m.navigation_rates(la, h, v, jnp.zeros(3)))(jnp.array([0.1, 0.2]))
    assert batch.gravity_gradient.shape == (2, 3, 3)


def test_dynamics_structure_and_strapdown_option():
    rates = m.navigation_rates(0.7, 7620.0, jnp.array([180.0, 40.0, -5.0]), jnp.zeros(3))
    F = np.asarray(m.ins_error_dynamics(rates))
    assert F.shape == (m.INS_STATE_DIM, m.INS_STATE_DIM) == (21, 21)
    omega = np.asarray(rates.earth_rate + rates.transport_rate)
    assert_allclose(F[m.INS_POSITION, m.INS_VELOCITY], np.eye(3))
    assert_allclose(F[m.INS_VELOCITY, m.INS_VELOCITY], -2 * np.asarray(skew(omega)))
    assert_allclose(F[m.INS_VELOCITY, m.INS_ATTITUDE], np.asarray(skew(rates.specific_force)))
    assert_allclose(F[m.INS_ATTITUDE, m.INS_GYRO_BIAS], -np.eye(3))
    assert np.all(F[9:] == 0)  # the sensor errors are random constants
    # with a level, north-pointing body the strapdown coupling equals the local-level one
    F_body = np.asarray(m.ins_error_dynamics(rates, m.ErrorModelOptions(sensor_frame="body")))
    assert_allclose(F_body, F, rtol=1e-12, atol=1e-20)
    tilted = m.navigation_rates(0.7, 7620.0, jnp.array([180.0, 40.0, -5.0]), jnp.array([0.05, 0.03, 0.25]))
    F_t = np.asarray(m.ins_error_dynamics(tilted, m.ErrorModelOptions(sensor_frame="body")))
    assert_allclose(F_t[m.INS_VELOCITY, m.INS_ACCEL_BIAS], np.asarray(tilted.body_to_nav))
    assert_allclose(F_t[m.INS_VELOCITY, m.INS_ACCEL_SCALE] @ np.ones(3), np.asarray(tilted.specific_force), rtol=1e-12)


def test_process_noise_density():
    budget = m.INSErrorBudget(*(jnp.asarray(x) for x in (3e-4, 1e-4, 5.8e-7, 2e-8, 2e-6, 9.4e-17)))
    Qc = np.asarray(m.ins_process_noise_density(budget))
    assert_allclose(np.diag(Qc)[m.INS_VELOCITY], 5.8e-7)
    assert_allclose(np.diag(Qc)[m.INS_ATTITUDE], 9.4e-17)
    assert np.count_nonzero(Qc) == 6


def test_rk4_is_fourth_order_on_pytrees():
    def rhs(t, y):
        x, v = y
        return (v, -x)  # harmonic oscillator: x = cos t

    errors = []
    for n in (20, 40):
        dt = 2.0 / n
        xs, vs = m.rk4(rhs, (jnp.array(1.0), jnp.array(0.0)), 0.0, dt, n)
        assert xs.shape == (n,)
        errors.append(abs(float(xs[-1]) - math.cos(2.0)))
    assert 14.0 < errors[0] / errors[1] < 18.0
    # the time argument is passed: dy/dt = t integrates exactly
    ys = m.rk4(lambda t, y: t, jnp.array(0.0), 1.0, 0.1, 10)
    assert_allclose(float(ys[-1]), 0.5 * (2.0 ** 2 - 1.0), rtol=1e-13)


def test_follows_float32():
    v = jnp.array([100.0, 0.0, 0.0], jnp.float32)
    r = m.navigation_rates(jnp.float32(0.5), jnp.float32(1000.0), v, jnp.zeros(3, jnp.float32))
    assert r.transport_rate.dtype == jnp.float32 and r.specific_force.dtype == jnp.float32
    assert m.ins_error_dynamics(r).dtype == jnp.float32


def test_bad_inputs_raise_input_error():
    with pytest.raises(InputError, match="psi_sign_convention"):
        m.ErrorModelOptions(psi_sign_convention="printed")
    with pytest.raises(InputError, match="sensor_frame"):
        m.ErrorModelOptions(sensor_frame="ecef")
    with pytest.raises(InputError, match="vertical_gravity_gradient"):
        m.gravity_gradient("flat")
    with pytest.raises(InputError, match="velocity"):
        m.navigation_rates(0.1, 0.0, jnp.zeros(2), jnp.zeros(3))
    with pytest.raises(InputError, match="num_steps"):
        m.rk4(lambda t, y: y, jnp.ones(2), 0.0, 0.1, 0)

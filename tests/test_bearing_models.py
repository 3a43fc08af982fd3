"""Compass bearing/course (jaxtrack.geometry) and the bearings-only relative models (jaxtrack.models)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.filters import ExtendedKalmanFilter, KalmanFilter, StandardForm, run_filter
from jaxtrack.geometry import bearing, course
from jaxtrack.models import (
    LinearGaussianModel,
    RelativeBearingModel,
    constant_velocity,
    constant_velocity_transition,
    pseudolinear_bearing_model,
    pseudolinear_measurement_row,
)


def test_compass_bearing_and_course_convention():
    assert float(bearing(jnp.array([0.0, 1.0]))) == 0.0  # north
    assert float(bearing(jnp.array([1.0, 0.0]))) == pytest.approx(math.pi / 2, abs=1e-15)  # east
    assert float(bearing(jnp.array([-1.0, 0.0]))) == pytest.approx(-math.pi / 2)  # west
    assert float(bearing(jnp.array([0.0, -1.0, 5.0, 7.0]))) == pytest.approx(math.pi)  # south; extra components ignored
    assert float(course(jnp.array([-1.0, 0.0]))) == pytest.approx(1.5 * math.pi)  # heading west, in [0, 2π)
    rng = np.random.default_rng(0)
    r = rng.normal(0.0, 5e3, (40, 2))
    beta = np.asarray(bearing(r))
    # The compass angle is the mathematical angle mirrored about 45°: β = π/2 − atan2(y, x) (mod 2π).
    np.testing.assert_allclose(np.exp(1j * beta), np.exp(1j * (np.pi / 2 - np.arctan2(r[:, 1], r[:, 0]))), atol=1e-12)
    c = np.asarray(course(r))
    assert np.all((c >= 0) & (c < 2 * np.pi))
    np.testing.assert_allclose(np.exp(1j * c), np.exp(1j * beta), atol=1e-12)
    assert bearing(np.array([1, 1])).dtype == jnp.result_type(float)  # integers promote
    assert bearing(np.array([1.0, 1.0], np.float32)).dtype == jnp.float32


def test_constant_velocity_transition():
    phi = np.asarray(constant_velocity_transition(20.0))
    np.testing.assert_array_equal(phi, [[1, 0, 20, 0], [0, 1, 0, 20], [0, 0, 1, 0], [0, 0, 0, 1]])
    ref = constant_velocity(20.0, dim=2, accel_psd=0.0, measurement_std=1.0, initial_cov=np.eye(4)).F
    np.testing.assert_array_equal(phi, ref)  # the library CV model's F
    np.testing.assert_allclose(np.asarray(constant_velocity_transition(-20.0)) @ phi, np.eye(4), atol=1e-15)
    assert constant_velocity_transition(np.float32(2.0)).dtype == jnp.float32
    assert constant_velocity_transition(1.0, dim=3).shape == (6, 6)


def test_pseudolinear_row_gives_cross_range_noise():
    """H(β_m) x_O − H(β_m) x_T = r_s sin(β_m − β) (Lindgren & Gong eqs. 11–13)."""
    rng = np.random.default_rng(1)
    for _ in range(20):
        xt, xo, nu = rng.normal(0, 1e4, 4), rng.normal(0, 1e4, 4), rng.normal(0, 0.3)
        xr = xt - xo
        beta = float(bearing(xr))
        h = np.asarray(pseudolinear_measurement_row(beta + nu))
        rs = math.hypot(xr[0], xr[1])
        np.testing.assert_allclose(h @ xo - h @ xt, rs * math.sin(nu), atol=1e-11 * rs)
    assert pseudolinear_measurement_row(np.zeros((3, 5))).shape == (3, 5, 4)


def _engagement(num=30, dt=10.0, seed=2):
    """A target in constant velocity, an observer that turns once halfway: relative states and inputs."""
    phi = np.asarray(constant_velocity_transition(dt))
    xt = [np.array([8000.0, 6000.0, -3.0, 1.0])]
    xo = [np.array([0.0, 0.0, 5.0, 0.0])]
    for k in range(num):
        xt.append(phi @ xt[-1])
        nxt = phi @ xo[-1]
        if k == num // 2:
            nxt[2:] = [0.0, 5.0]
        xo.append(nxt)
    xt, xo = np.array(xt), np.array(xo)
    u = xo[1:] - xo[:-1] @ phi.T
    rng = np.random.default_rng(seed)
    bm = np.arctan2(xt[:, 0] - xo[:, 0], xt[:, 1] - xo[:, 1]) + 1e-3 * rng.normal(size=num + 1)
    return xt - xo, xo, u, bm


def test_pseudolinear_model_is_the_scalar_kalman_recursion():
    xr, xo, u, bm = _engagement()
    var, dt = 1e-4, 10.0  # a short, well-conditioned run: the recursion's rounding stays near 1e-12
    m0, P0 = np.array([9000.0, 7000.0, 0.0, 0.0]), np.diag([1e2, 1e2, 1e-2, 1e-2])
    model = pseudolinear_bearing_model(bm[1:], var, dt, m0, P0, observer_input=u)
    assert isinstance(model, LinearGaussianModel) and model.H.shape == (30, 1, 4) and model.R.shape == (30, 1, 1)
    res = run_filter(KalmanFilter(form=StandardForm()), model, np.zeros((30, 1)), first_step="predict")
    # Reference: the textbook recursion (eqs. 38, 39, 42–44) in NumPy.
    phi = np.asarray(constant_velocity_transition(dt))
    x, P = m0, P0
    for k in range(30):
        h = np.array([np.cos(bm[k + 1]), -np.sin(bm[k + 1]), 0.0, 0.0])
        x, P = phi @ x - u[k], phi @ P @ phi.T
        g = P @ h / (h @ P @ h + var)
        x, P = x - g * (h @ x), P - np.outer(g, P @ h)
        P = 0.5 * (P + P.T)
        np.testing.assert_allclose(res.filtered_mean[k], x, rtol=1e-8)
        np.testing.assert_allclose(res.filtered_cov[k], P, rtol=1e-8, atol=1e-10 * np.abs(P).max())
    # Target-state form (eq. 66): z = H(β_m) x_O, no input, prior shifted by x_O(0).
    H = np.asarray(pseudolinear_measurement_row(bm[1:]))
    target = pseudolinear_bearing_model(bm[1:], var, dt, m0 + xo[0], P0)
    tt = run_filter(KalmanFilter(form=StandardForm()), target, np.sum(H * xo[1:], axis=1)[:, None], first_step="predict")
    np.testing.assert_allclose(np.asarray(tt.filtered_mean) - xo[1:], res.filtered_mean, rtol=0, atol=1e-5)


def test_pseudolinear_model_rejects_bad_input():
    with pytest.raises(InputError, match="observer_input"):
        pseudolinear_bearing_model(np.zeros(5), 1e-6, 1.0, np.zeros(4), np.eye(4), observer_input=np.zeros((4, 4)))
    with pytest.raises(InputError, match="noise_var"):
        pseudolinear_bearing_model(np.zeros(5), np.ones(3), 1.0, np.zeros(4), np.eye(4))
    with pytest.raises(InputError, match="measured_bearings"):
        pseudolinear_bearing_model(np.array([0.0, np.nan]), 1e-6, 1.0, np.zeros(4), np.eye(4))


def test_relative_bearing_model_jacobian_and_ekf():
    xr, _, u, bm = _engagement(seed=3)
    m0 = np.array([9000.0, 7000.0, 0.0, 0.0])
    P0 = np.diag([4e6, 4e6, 25.0, 25.0])
    model = RelativeBearingModel(u, 10.0, 1e-6, m0, P0)
    assert model.num_steps == 30 and model.angle_components == (0,)
    rng = np.random.default_rng(4)
    for x in rng.normal(0, 5e3, (10, 4)):
        x = jnp.asarray(x)
        np.testing.assert_allclose(model.measurement_jacobian(x, 0), jax.jacfwd(model.measurement)(x, 0),
                                   rtol=1e-13, atol=1e-18)
        r = float(jnp.hypot(x[0], x[1]))  # the pseudo-linear row at the predicted bearing over the range
        np.testing.assert_allclose(model.measurement_jacobian(x, 0)[0], pseudolinear_measurement_row(bearing(x)) / r,
                                   rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(model.transition(jnp.asarray(xr[0]), 0), xr[1], atol=1e-9)  # x_R(1) = Φ x_R(0) − u(0)
    res = run_filter(ExtendedKalmanFilter(), model, bm[1:, None], first_step="predict")
    assert bool(res.ok)
    assert np.linalg.norm(res.filtered_mean[-1, :2] - xr[-1, :2]) < 0.05 * np.linalg.norm(xr[-1, :2])
    # The residual wraps: a bearing just across ±π from the prediction is a small innovation.
    assert float(model.residual(jnp.array([math.pi - 0.01]), jnp.array([-math.pi + 0.01]))[0]) == pytest.approx(-0.02)
    with pytest.raises(InputError, match="observer_input"):
        RelativeBearingModel(np.zeros((3, 2)), 10.0, 1e-6, m0, P0)

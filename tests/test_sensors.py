"""Sensor measurement models (issue 19) against Stone Soup, values and Jacobians.

Oracles: ``stonesoup.models.measurement.nonlinear`` (``function(state, noise=False)`` and
``jacobian(state)``). Stone Soup orders states ``[x, vx, y, vy(, z, vz)]``; jaxtrack's kinematic
layout is ``[x, y(, z), vx, vy(, vz)]``: states and Jacobian columns are mapped with ``PERM``.

Stone Soup's ``jacobian`` is a forward finite difference (``stonesoup.functions.jacobian``, step
~1e-8 relative) for every model except ``CartesianToElevationBearingRangeRate``, which has an
analytic Jacobian. The 1e-12 Jacobian comparisons are therefore made against that analytic one
(its rows contain the range, bearing and elevation rows of the other models: in 2-D with z = 0 and
a rotation about z only). Stone Soup's forward differences agree with its own analytic Jacobian
only to ~6e-4 of a row's largest entry (measured on these states), so they are checked at
``FD_TOL`` = 2e-3 row-relative: a sign or frame error is O(1).

Orientation: Stone Soup rotates the relative position by
``build_rotation_matrix([θx, θy, θz]) = rotx(−θx) @ roty(θy) @ rotz(−θz)`` (rotx etc. are the same
matrices as :func:`jaxtrack.geometry.rotation_x` etc.), i.e. world→sensor. That is exactly
:func:`jaxtrack.models.sensor_rotation` (yaw=θz, pitch=θy, roll=θx): ``rotation_offset =
[roll, pitch, yaw]``; in 2-D ``rotation_offset = [0, 0, sensor_yaw]``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.filters import ExtendedKalmanFilter, UnscentedKalmanFilter, run_filter
from jaxtrack.geometry import cartesian_to_compass_spherical, math_to_compass_azimuth
from jaxtrack.models import (
    AbstractTransitionModel,
    Bearing,
    RangeAzimuthElevation,
    RangeBearing,
    TrackingModel,
    sensor_rotation,
    wrap_angle,
)

ss_nl = pytest.importorskip("stonesoup.models.measurement.nonlinear")
from stonesoup.types.array import StateVector  # noqa: E402
from stonesoup.types.state import State  # noqa: E402

# jaxtrack [x, y, z, vx, vy, vz] index -> Stone Soup [x, vx, y, vy, z, vz] index.
PERM3 = np.array([0, 2, 4, 1, 3, 5])
PERM2 = np.array([0, 2, 1, 3])

FD_TOL = 2e-3
RNG = np.random.default_rng(19)
STATES3 = [RNG.uniform(-5e3, 5e3, 3).tolist() + RNG.uniform(-50, 50, 3).tolist() for _ in range(6)]
STATES2 = [s[:2] + s[3:5] for s in STATES3]
SENSOR3 = np.array([120.0, -340.0, 25.0])
SENSOR_VEL3 = np.array([3.0, -7.0, 1.5])
OFFSET = [0.1, -0.25, 0.7]  # Stone Soup rotation_offset = [roll, pitch, yaw]


def ss_state(x_jax, perm):
    sv = np.zeros(len(perm))
    sv[perm] = x_jax
    return State(StateVector(sv))


def ss_value(model, x_jax, perm):
    return np.asarray(model.function(ss_state(x_jax, perm), noise=False), dtype=float).ravel()


def ss_jacobian(model, x_jax, perm):
    return np.asarray(model.jacobian(ss_state(x_jax, perm)), dtype=float)[:, perm]


def assert_rows_close(actual, expected, rtol):
    """``|actual − expected| ≤ rtol · max|row of expected|`` elementwise (Jacobian rows mix units)."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    scale = np.abs(expected).max(axis=1, keepdims=True)
    err = np.abs(actual - expected) / scale
    assert err.max() <= rtol, f"max row-relative error {err.max():.3g} > {rtol:.1g}"


def ss_radar(range_rate: bool, offset=OFFSET):
    kw = dict(ndim_state=6, mapping=(0, 2, 4), noise_covar=np.eye(4 if range_rate else 3),
              translation_offset=StateVector(SENSOR3), rotation_offset=StateVector(offset))
    if range_rate:
        return ss_nl.CartesianToElevationBearingRangeRate(
            velocity_mapping=(1, 3, 5), velocity=StateVector(SENSOR_VEL3), **kw)
    return ss_nl.CartesianToElevationBearingRange(**kw)


def radar(range_rate: bool, azimuth="math", offset=OFFSET, **kw):
    m = 4 if range_rate else 3
    return RangeAzimuthElevation(
        noise_std=np.ones(m), sensor_position=SENSOR3, sensor_velocity=SENSOR_VEL3,
        world_to_sensor_rotation=sensor_rotation(yaw=offset[2], pitch=offset[1], roll=offset[0]),
        range_rate=range_rate, azimuth=azimuth, **kw)


# ------------------------------------------------------------------------------------------------
# 3-D radar
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("x", STATES3)
def test_radar_value_and_jacobian_match_stonesoup(x):
    # Stone Soup [el, az, r, rr] -> jaxtrack [r, az, el, rr].
    order = [2, 1, 0, 3]
    ours = radar(True)
    ss = ss_radar(True)
    z = np.asarray(ours.mean(jnp.asarray(x), 0))
    np.testing.assert_allclose(z, ss_value(ss, x, PERM3)[order], rtol=1e-12, atol=1e-12)
    # Analytic Stone Soup Jacobian: 1e-12 (relative to the row scale).
    H, H_ss = np.asarray(ours.jacobian(jnp.asarray(x), 0)), ss_jacobian(ss, x, PERM3)[order]
    assert_rows_close(H, H_ss, 1e-12)
    # Without range rate: CartesianToElevationBearingRange (value exact, FD Jacobian).
    ss3 = ss_radar(False)
    ours3 = radar(False)
    np.testing.assert_allclose(np.asarray(ours3.mean(jnp.asarray(x), 0)), ss_value(ss3, x, PERM3)[[2, 1, 0]],
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(ours3.jacobian(jnp.asarray(x), 0)), H_ss[:3], rtol=1e-12, atol=1e-15)
    H_fd = ss_jacobian(ss3, x, PERM3)[[2, 1, 0]]
    assert_rows_close(H[:3], H_fd, FD_TOL)


def test_radar_jacobian_equals_autodiff_on_custom_layout():
    # A state [vx, x, vy, y, vz, z, extra] (any layout): analytic = jax.jacfwd of the mean.
    pos, vel = (1, 3, 5), (0, 2, 4)
    ours = radar(True, azimuth="compass", position_indices=pos, velocity_indices=vel)
    plain = radar(True, azimuth="compass")
    jac = jax.jit(lambda x: ours.jacobian(x, 0))
    auto = jax.jit(jax.jacfwd(lambda x: ours.mean(x, 0)))
    for x in STATES3:
        xs = np.zeros(7)
        xs[list(pos)], xs[list(vel)], xs[6] = x[:3], x[3:], 9.0
        xs = jnp.asarray(xs)
        np.testing.assert_allclose(jac(xs), auto(xs), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(ours.mean(xs, 0), plain.mean(jnp.asarray(x), 0),
                                   rtol=0, atol=1e-12)


def test_compass_azimuth_is_rotated_math_azimuth_and_matches_geometry():
    math, compass = radar(True), radar(True, azimuth="compass")
    C = np.asarray(sensor_rotation(yaw=OFFSET[2], pitch=OFFSET[1], roll=OFFSET[0]))
    for x in STATES3:
        zm, zc = np.asarray(math.mean(jnp.asarray(x), 0)), np.asarray(compass.mean(jnp.asarray(x), 0))
        np.testing.assert_allclose(zc[1], np.asarray(math_to_compass_azimuth(zm[1])), atol=1e-12)
        np.testing.assert_allclose(zc[[0, 2, 3]], zm[[0, 2, 3]], atol=1e-12)
        # Against jaxtrack.geometry's compass spherical coordinates of the sensor-frame vector.
        ds = C @ (np.asarray(x[:3]) - SENSOR3)
        np.testing.assert_allclose(zc[:3], np.asarray(cartesian_to_compass_spherical(ds)), rtol=1e-12, atol=1e-12)
        # Jacobian: the compass row is minus the math row.
        np.testing.assert_allclose(compass.jacobian(jnp.asarray(x), 0)[1], -math.jacobian(jnp.asarray(x), 0)[1],
                                   rtol=1e-12, atol=1e-18)
    # Unrotated: a target due North-East is at compass 45 deg, math 45 deg; due North-West at
    # compass -45 deg (315), math 135 deg.
    unrot = RangeAzimuthElevation(np.ones(3), azimuth="compass")
    np.testing.assert_allclose(unrot.mean(jnp.array([-1.0, 1.0, 0.0]), 0)[1], -np.pi / 4, atol=1e-15)
    np.testing.assert_allclose(RangeAzimuthElevation(np.ones(3)).mean(jnp.array([-1.0, 1.0, 0.0]), 0)[1],
                               3 * np.pi / 4, atol=1e-15)


# ------------------------------------------------------------------------------------------------
# 2-D range-bearing and bearings-only
# ------------------------------------------------------------------------------------------------

SENSOR2, SENSOR_VEL2, YAW = SENSOR3[:2], SENSOR_VEL3[:2], 0.7


@pytest.mark.parametrize("x", STATES2)
def test_range_bearing_matches_stonesoup(x):
    ours = RangeBearing(noise_std=(1.0, 0.01), sensor_position=SENSOR2, sensor_yaw=YAW)
    ss = ss_nl.CartesianToBearingRange(ndim_state=4, mapping=(0, 2), noise_covar=np.eye(2),
                                       translation_offset=StateVector(SENSOR2),
                                       rotation_offset=StateVector([0.0, 0.0, YAW]))
    xj = jnp.asarray(x)
    np.testing.assert_allclose(np.asarray(ours.mean(xj, 0)), ss_value(ss, x, PERM2)[[1, 0]], rtol=1e-12, atol=1e-12)
    H = np.asarray(ours.jacobian(xj, 0))
    H_fd = ss_jacobian(ss, x, PERM2)[[1, 0]]
    assert_rows_close(H, H_fd, FD_TOL)
    # 1e-12 against Stone Soup's analytic 3-D Jacobian with z = vz = 0 and a yaw-only rotation.
    ss3 = ss_radar(True, offset=[0.0, 0.0, YAW])
    ss3.translation_offset = StateVector([*SENSOR2, 0.0])
    ss3.velocity = StateVector([*SENSOR_VEL2, 0.0])
    x3 = [x[0], x[1], 0.0, x[2], x[3], 0.0]
    H3 = ss_jacobian(ss3, x3, PERM3)[:, [0, 1, 3, 4]]  # columns x, y, vx, vy
    assert_rows_close(H, H3[[2, 1]], 1e-12)
    # With range rate: CartesianToBearingRangeRate2D (values) and the analytic 3-D rows.
    ours_rr = RangeBearing(noise_std=(1.0, 0.01, 0.1), sensor_position=SENSOR2, sensor_velocity=SENSOR_VEL2,
                           sensor_yaw=YAW, range_rate=True)
    ss_rr = ss_nl.CartesianToBearingRangeRate2D(
        ndim_state=4, mapping=(0, 2), velocity_mapping=(1, 3), noise_covar=np.eye(3),
        translation_offset=StateVector(SENSOR2), velocity=StateVector(SENSOR_VEL2),
        rotation_offset=StateVector([0.0, 0.0, YAW]))
    np.testing.assert_allclose(np.asarray(ours_rr.mean(xj, 0)), ss_value(ss_rr, x, PERM2)[[1, 0, 2]],
                               rtol=1e-12, atol=1e-12)
    H_rr = np.asarray(ours_rr.jacobian(xj, 0))
    assert_rows_close(H_rr, H3[[2, 1, 3]], 1e-12)


@pytest.mark.parametrize("x", STATES2[:3])
def test_bearing_matches_stonesoup(x):
    ours = Bearing(noise_std=(0.01,), sensor_position=SENSOR2, sensor_yaw=YAW)
    ss = ss_nl.Cartesian2DToBearing(ndim_state=4, mapping=(0, 2), noise_covar=np.eye(1),
                                    translation_offset=StateVector(SENSOR2),
                                    rotation_offset=StateVector([0.0, 0.0, YAW]))
    xj = jnp.asarray(x)
    np.testing.assert_allclose(np.asarray(ours.mean(xj, 0)), ss_value(ss, x, PERM2), rtol=1e-12, atol=1e-12)
    H = np.asarray(ours.jacobian(xj, 0))
    assert_rows_close(H, ss_jacobian(ss, x, PERM2), FD_TOL)
    rb = RangeBearing(noise_std=(1.0, 0.01), sensor_position=SENSOR2, sensor_yaw=YAW)
    np.testing.assert_allclose(H[0], np.asarray(rb.jacobian(xj, 0))[1], rtol=1e-14, atol=0)
    # Bearing + range rate (bearing-Doppler): the rows of RangeBearing(range_rate=True).
    bd = Bearing(noise_std=(0.01, 0.1), sensor_position=SENSOR2, sensor_velocity=SENSOR_VEL2, sensor_yaw=YAW,
                 range_rate=True, azimuth="compass")
    rbr = RangeBearing(noise_std=(1.0, 0.01, 0.1), sensor_position=SENSOR2, sensor_velocity=SENSOR_VEL2,
                       sensor_yaw=YAW, range_rate=True, azimuth="compass")
    np.testing.assert_allclose(bd.mean(xj, 0), rbr.mean(xj, 0)[1:], rtol=1e-14)
    np.testing.assert_allclose(bd.jacobian(xj, 0), rbr.jacobian(xj, 0)[1:], rtol=1e-14)


def test_nearly_constant_turn_layout():
    # A 5-state [x, y, speed, heading, ω]: range-bearing of positions (0, 1) only.
    rb = RangeBearing(noise_std=(1.0, 0.01), position_indices=(0, 1), sensor_position=(10.0, -20.0))
    x = jnp.array([300.0, 400.0, 12.0, 0.3, 0.01])
    np.testing.assert_allclose(rb.mean(x, 0), [np.hypot(290.0, 420.0), np.arctan2(420.0, 290.0)], rtol=1e-14)
    H = rb.jacobian(x, 0)
    assert H.shape == (2, 5)
    np.testing.assert_allclose(H, jax.jacfwd(rb.mean)(x, 0), rtol=1e-12, atol=1e-18)
    np.testing.assert_array_equal(H[:, 2:], 0.0)


# ------------------------------------------------------------------------------------------------
# Moving sensor, wrapping, degenerate geometry, errors
# ------------------------------------------------------------------------------------------------


def test_moving_sensor_per_step_pose():
    T = 4
    positions = np.stack([SENSOR3 + 10.0 * k for k in range(T)])
    yaws = np.linspace(0.0, 1.0, T)
    moving = RangeAzimuthElevation(np.ones(4), sensor_position=positions, sensor_velocity=np.tile(SENSOR_VEL3, (T, 1)),
                                   world_to_sensor_rotation=sensor_rotation(yaw=yaws), range_rate=True)
    assert moving.num_steps == T
    x = jnp.asarray(STATES3[0])
    for k in range(T):
        fixed = RangeAzimuthElevation(np.ones(4), sensor_position=positions[k], sensor_velocity=SENSOR_VEL3,
                                      world_to_sensor_rotation=sensor_rotation(yaw=yaws[k]), range_rate=True)
        np.testing.assert_allclose(moving.mean(x, jnp.asarray(k)), fixed.mean(x, 0), rtol=1e-14)
        np.testing.assert_allclose(moving.jacobian(x, jnp.asarray(k)), fixed.jacobian(x, 0), rtol=1e-14)
    with pytest.raises(InputError, match="disagree"):
        RangeBearing(np.ones((3, 2)), sensor_position=np.zeros((4, 2))).num_steps  # noqa: B018


def test_bearing_residual_wraps_across_pi():
    rb = RangeBearing(noise_std=(1.0, 0.01), bias=(0.0, 0.02))
    # Target just above the -x axis: bearing ≈ π − 0.001; + bias 0.02 wraps to ≈ −π + 0.019.
    x = jnp.array([-1000.0, 1.0, 0.0, 0.0])
    z_pred = rb.mean(x, 0)
    assert -np.pi < float(z_pred[1]) < -np.pi + 0.05
    np.testing.assert_allclose(z_pred[1], wrap_angle(np.arctan2(1.0, -1000.0) + 0.02), atol=1e-15)
    model = TrackingModel(_CV(2, 1.0, 0.1), rb, jnp.zeros(4), jnp.eye(4))
    z = jnp.array([1000.0, np.pi - 0.01])  # on the other side of ±π
    res = model.residual(z, z_pred)
    np.testing.assert_allclose(res[1], (np.pi - 0.01) - (np.arctan2(1.0, -1000.0) + 0.02 - 2 * np.pi) - 2 * np.pi,
                               atol=1e-12)
    assert abs(float(res[1])) < 0.05


def test_polynomial_atan2_is_within_2_ulp_of_numpy():
    """The sensors' atan2 (models/_atan2.py) against NumPy's arctan2: every octant, magnitudes
    from 1e-250 to 1e250 and ratios from 1e-12 to 1e12 (subnormals are flushed to zero by XLA's
    CPU, as for jnp.arctan2); IEEE special values; the derivative; float32."""
    from jaxtrack.models._atan2 import atan2

    rng = np.random.default_rng(3)
    n = 200_000
    scale = 10.0 ** rng.uniform(-250, 250, n)
    x = rng.standard_normal(n) * scale
    y = rng.standard_normal(n) * scale * 10.0 ** rng.uniform(-12, 12, n)
    got = np.asarray(jax.jit(atan2)(jnp.asarray(y), jnp.asarray(x)))
    want = np.arctan2(y, x)
    ulp = np.abs(got - want) / np.spacing(np.abs(want))
    assert ulp.max() <= 2.0 and ulp.mean() < 0.3, (ulp.max(), ulp.mean())
    special = np.array([0.0, -0.0, 1.0, -1.0, np.inf, -np.inf, np.nan])
    Y, X = (a.ravel() for a in np.meshgrid(special, special))
    got, want = np.asarray(atan2(jnp.asarray(Y), jnp.asarray(X))), np.arctan2(Y, X)
    np.testing.assert_array_equal(got, want)
    number = ~np.isnan(want)  # (a NaN's sign is not specified)
    np.testing.assert_array_equal(np.signbit(got[number]), np.signbit(want[number]))
    for yx in [(0.3, -1.2), (-2.0, 0.1), (1e-3, 5.0), (-7.0, -7.0)]:
        np.testing.assert_allclose(jax.grad(atan2, argnums=(0, 1))(*yx),
                                   jax.grad(jnp.arctan2, argnums=(0, 1))(*yx), rtol=1e-15)
    y32 = jnp.asarray(y[:1000] / scale[:1000], jnp.float32)
    x32 = jnp.asarray(x[:1000] / scale[:1000], jnp.float32)
    got32 = atan2(y32, x32)
    assert got32.dtype == jnp.float32
    want32 = np.arctan2(np.asarray(y32, np.float64), np.asarray(x32, np.float64))
    assert np.max(np.abs(np.asarray(got32, np.float64) - want32) / np.spacing(np.float32(np.abs(want32)))) <= 2.0


def test_zero_range_is_finite():
    for model, n in [(radar(True), 6), (RangeBearing((1.0, 0.1, 0.1), range_rate=True), 4),
                     (Bearing((0.1,)), 4)]:
        x = jnp.zeros(n)
        if n == 6:
            x = x.at[:3].set(SENSOR3)

        @jax.jit
        def values(x, model=model):
            return model.mean(x, 0), model.jacobian(x, 0), jax.grad(lambda x: model.mean(x, 0).sum())(x)

        mean, jac, grad = values(x)
        assert np.all(np.isfinite(np.asarray(mean))) and np.all(np.isfinite(np.asarray(grad)))
        # The Jacobian is undefined there: NaN, so that a filter linearised there fails loudly
        # (issue 37; it used to be 0, which made the EKF ignore every measurement, ok=True).
        assert np.all(np.isnan(np.asarray(jac)))
        # ... and defined (finite) a metre away.
        assert np.all(np.isfinite(np.asarray(values(x.at[0].add(1.0))[1])))


def _cv_on(sensor, dim):
    """A constant-velocity target seen by ``sensor`` at the origin: the truth 8-12 km out, and a
    filter model whose prior mean is 0 (on the sensor, the "uninformed" prior of issue 37)."""
    from jaxtrack.models import ConstantVelocity

    n = 2 * dim
    cov = jnp.diag(jnp.concatenate([jnp.full(dim, 1e4), jnp.full(dim, 50.0)]) ** 2)
    x0 = jnp.array([8e3, 12e3, 3e3][:dim] + [-100.0, 20.0, 0.0][:dim])
    truth = TrackingModel(ConstantVelocity(1.0, noise_intensity=0.1, dim=dim), sensor, x0, cov)
    return truth, TrackingModel(ConstantVelocity(1.0, noise_intensity=0.1, dim=dim), sensor, jnp.zeros(n), cov)


SENSORS_AT_ORIGIN = {
    "range_bearing": (RangeBearing((10.0, 1e-3)), 2),
    "bearing": (Bearing((1e-3,)), 2),
    "range_azimuth_elevation": (RangeAzimuthElevation(noise_std=(10.0, 1e-3, 1e-3)), 3),
}


@pytest.mark.parametrize("name", SENSORS_AT_ORIGIN)
def test_a_filter_linearised_on_the_sensor_fails_loudly(name):
    """Issue 37, cause 1: the EKF and iterated EKF with the prior mean on the sensor returned
    ok=True while ignoring every measurement (zero Jacobian rows); now ok=False, and with
    throw=True the error names the cause. A step whose measurement is missing does not fail."""
    from jaxtrack.filters import IteratedExtendedKalmanFilter
    from jaxtrack.montecarlo import simulate

    sensor, dim = SENSORS_AT_ORIGIN[name]
    truth, model = _cv_on(sensor, dim)
    z = simulate(truth, jax.random.key(0), 20).measurements
    for filt in (ExtendedKalmanFilter(), IteratedExtendedKalmanFilter(num_iterations=2)):
        assert not bool(run_filter(filt, model, z, throw=False).ok), type(filt).__name__
    with pytest.raises(Exception, match="linearised a sensor model where its Jacobian is undefined"):
        jax.block_until_ready(run_filter(ExtendedKalmanFilter(), model, z))
    # Every measurement missing: the NaN Jacobian is never used, the filter only predicts.
    none = run_filter(ExtendedKalmanFilter(), model, z, mask=jnp.zeros(20, bool), throw=False)
    assert bool(none.ok) and np.all(np.isfinite(np.asarray(none.filtered_cov)))
    # The same prior mean a metre off the sensor: defined, and the measurements are used.
    moved = eqx.tree_at(lambda m: m.initial_mean, model, model.initial_mean.at[0].set(1.0))
    res = run_filter(ExtendedKalmanFilter(), moved, z, throw=False)
    assert bool(res.ok) and float(res.filtered_cov[-1, 0, 0]) < 0.5 * float(model.initial_cov[0, 0])


def test_radar_straight_above_its_vertical_axis_is_undefined():
    """RangeAzimuthElevation's azimuth is undefined on the sensor's vertical axis (any height)."""
    sensor = RangeAzimuthElevation(noise_std=(10.0, 1e-3, 1e-3), sensor_position=(5.0, -3.0, 0.0),
                                   world_to_sensor_rotation=sensor_rotation(yaw=0.3))
    above = jnp.array([5.0, -3.0, 2e3, 0.0, 0.0, 0.0])
    assert np.all(np.isnan(np.asarray(sensor.jacobian(above, 0))))
    assert np.all(np.isfinite(np.asarray(sensor.jacobian(above.at[0].add(1.0), 0))))


def test_input_errors_name_the_argument():
    with pytest.raises(InputError, match="`noise_std`"):
        RangeBearing(noise_std=(1.0, 0.1, 0.2))
    with pytest.raises(InputError, match="`noise_std`.*non-negative"):
        RangeBearing(noise_std=(-1.0, 0.1))
    with pytest.raises(InputError, match="`noise_cov`"):
        RangeAzimuthElevation(noise_cov=np.eye(2))
    with pytest.raises(InputError, match="exactly one"):
        Bearing()
    with pytest.raises(InputError, match="`azimuth`"):
        Bearing((0.1,), azimuth="north")
    with pytest.raises(InputError, match="`sensor_position`"):
        RangeBearing((1.0, 0.1), sensor_position=(0.0, 0.0, 0.0))
    with pytest.raises(InputError, match="`world_to_sensor_rotation`"):
        RangeAzimuthElevation(np.ones(3), world_to_sensor_rotation=np.eye(2))
    with pytest.raises(InputError, match="`bias`"):
        RangeBearing((1.0, 0.1), bias=(0.0,))
    with pytest.raises(InputError, match="`position_indices`"):
        RangeBearing((1.0, 0.1), position_indices=(0, 0))
    with pytest.raises(InputError, match="position_indices"):
        RangeBearing((1.0, 0.1), position_indices=(0, 7)).mean(jnp.zeros(4), 0)


def test_follows_input_dtype():
    rb = RangeBearing(noise_std=np.array([1.0, 0.1], np.float32), sensor_position=np.zeros(2, np.float32))
    assert rb.noise_std.dtype == jnp.float32 and rb.sensor_position.dtype == jnp.float32
    assert rb.mean(jnp.ones(4, jnp.float32), 0).dtype == jnp.float32


# ------------------------------------------------------------------------------------------------
# Differentiable parameters through a filter
# ------------------------------------------------------------------------------------------------


class _CV(AbstractTransitionModel):
    """A linear nearly-constant-velocity transition in the [x, y, vx, vy] layout (test only)."""

    dim: int = eqx.field(static=True)
    dt: float = eqx.field(static=True)
    q: float = eqx.field(static=True)

    @property
    def state_dim(self):
        return 2 * self.dim

    def _F(self):
        d = self.dim
        return jnp.block([[jnp.eye(d), self.dt * jnp.eye(d)], [jnp.zeros((d, d)), jnp.eye(d)]])

    def mean(self, x, k):
        return self._F() @ x

    def jacobian(self, x, k):
        return self._F()

    def noise_cov(self, k):
        d, t = self.dim, self.dt
        blk = self.q * jnp.array([[t**3 / 3, t**2 / 2], [t**2 / 2, t]])
        return jnp.kron(blk, jnp.eye(d))


def _track(T=25):
    rng = np.random.default_rng(7)
    x = np.array([2000.0, 1500.0, -20.0, 15.0])
    F = np.asarray(_CV(2, 1.0, 0.5)._F())
    zs = []
    for _ in range(T):
        x = F @ x
        d = x[:2] - np.array([100.0, -50.0])
        zs.append([np.hypot(*d) + 5.0 * rng.standard_normal() + 3.0,
                   np.arctan2(d[1], d[0]) + 0.01 * rng.standard_normal() - 0.004,
                   d @ (x[2:] - np.array([1.0, 2.0])) / np.hypot(*d) + 0.5 * rng.standard_normal()])
    return jnp.asarray(zs)


@pytest.mark.parametrize("filt", [ExtendedKalmanFilter(), UnscentedKalmanFilter()], ids=["ekf", "ukf"])
def test_log_likelihood_gradient_wrt_bias_and_noise_std(filt):
    zs = _track()

    def loglik(params):
        bias, std = params
        rb = RangeBearing(noise_std=std, bias=bias, sensor_position=(100.0, -50.0), sensor_velocity=(1.0, 2.0),
                          range_rate=True)
        model = TrackingModel(_CV(2, 1.0, 0.5), rb, jnp.array([2000.0, 1500.0, -20.0, 15.0]),
                              jnp.diag(jnp.array([100.0, 100.0, 25.0, 25.0])))
        return run_filter(filt, model, zs, throw=False, save="final").log_likelihood

    params = (jnp.array([1.0, 0.001, 0.1]), jnp.array([6.0, 0.012, 0.6]))
    grads = jax.jit(jax.grad(loglik))(params)
    loglik = jax.jit(loglik)  # one compilation for the 12 finite-difference evaluations
    for which in range(2):
        g = np.asarray(grads[which])
        assert np.all(np.isfinite(g)) and np.all(g != 0)
        for i in range(3):
            h = 1e-5 * max(abs(float(params[which][i])), 1e-3)
            plus = [p for p in params]
            minus = [p for p in params]
            plus[which] = params[which].at[i].add(h)
            minus[which] = params[which].at[i].add(-h)
            fd = (float(loglik(tuple(plus))) - float(loglik(tuple(minus)))) / (2 * h)
            np.testing.assert_allclose(g[i], fd, rtol=1e-6)


def test_monte_carlo_with_the_prior_on_the_sensor_says_so():
    """Issue 37: through monte_carlo the same model gave a 7.5 km RMSE with no warning."""
    from jaxtrack.montecarlo import monte_carlo

    truth, model = _cv_on(*SENSORS_AT_ORIGIN["range_bearing"])
    with pytest.raises(FloatingPointError, match="prior mean sits on a sensor"), \
            pytest.warns(RuntimeWarning, match="20 of 20 runs produced a non-finite estimate"):
        monte_carlo(truth, jax.random.key(0), 20, num_steps=10, filter=ExtendedKalmanFilter(), filter_model=model,
                    progress=False)

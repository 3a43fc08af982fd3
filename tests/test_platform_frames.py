"""Compass-azimuth radar coordinates and small platform attitude errors (jaxtrack.geometry._platform).

Oracles: the closed forms of Wang, Chen, Jia, Progri (2012) eqs 1 and 8 written out in NumPy,
``jax.jacfwd`` of the exact platform rotation, and the cross product.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import geometry

DEG = np.pi / 180


def test_compass_spherical_to_cartesian_closed_form():
    rng = np.random.default_rng(0)
    polar = np.stack([rng.uniform(1.0, 1e5, 20), rng.uniform(-np.pi, np.pi, 20), rng.uniform(-1.0, 1.0, 20)], -1)
    r, th, el = polar.T
    expected = np.stack([r * np.sin(th) * np.cos(el), r * np.cos(th) * np.cos(el), r * np.sin(el)], -1)
    np.testing.assert_allclose(geometry.compass_spherical_to_cartesian(polar), expected, rtol=1e-12, atol=1e-9)
    # North is θ = 0, East is θ = 90°.
    np.testing.assert_allclose(geometry.compass_spherical_to_cartesian(np.array([2.0, 0.0, 0.0])), [0.0, 2.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(geometry.compass_spherical_to_cartesian(np.array([2.0, 90 * DEG, 0.0])), [2.0, 0.0, 0.0], atol=1e-15)


def test_cartesian_to_compass_spherical_round_trip_and_range():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(50, 3)) * 1e4
    s = np.asarray(geometry.cartesian_to_compass_spherical(x))
    assert np.all(s[:, 1] <= np.pi) and np.all(s[:, 1] > -np.pi)
    np.testing.assert_allclose(s[:, 1], np.arctan2(x[:, 0], x[:, 1]), atol=1e-14)
    np.testing.assert_allclose(geometry.compass_spherical_to_cartesian(s), x, rtol=1e-12, atol=1e-8)
    assert float(geometry.cartesian_to_compass_spherical(jnp.array([-1.0, -1.0, 0.0]))[1]) == pytest.approx(-135 * DEG)
    # South is +π, never −π.
    assert float(geometry.cartesian_to_compass_spherical(jnp.array([0.0, -1.0, 0.0]))[1]) == pytest.approx(np.pi)


def test_azimuth_conversions():
    th = jnp.array([-np.pi + 1e-3, -0.5, 0.0, 1.0, np.pi])
    psi = geometry.compass_to_math_azimuth(th)
    np.testing.assert_allclose(psi, np.pi / 2 - np.asarray(th), atol=0)
    np.testing.assert_allclose(geometry.math_to_compass_azimuth(psi), th, atol=1e-15)
    # The mathematical azimuth of North-East is 45°, its compass azimuth 45° too; West is 180° / −90°.
    assert float(geometry.math_to_compass_azimuth(np.pi)) == pytest.approx(-np.pi / 2)
    assert geometry.compass_to_math_azimuth(np.float32(0.3)).dtype == jnp.float32


def test_attitude_generators_are_the_derivative_of_the_platform_rotation():
    gens = jax.jacfwd(lambda a: geometry.platform_to_enu_rotation(a[0], a[1], a[2]))(jnp.zeros(3))
    np.testing.assert_allclose(np.moveaxis(np.asarray(gens), -1, 0), geometry.platform_attitude_generators(), atol=1e-15)
    expected = np.array([[[0, 1, 0], [-1, 0, 0], [0, 0, 0]], [[0, 0, 0], [0, 0, -1], [0, 1, 0]],
                         [[0, 0, -1], [0, 0, 0], [1, 0, 0]]], dtype=float)
    np.testing.assert_allclose(geometry.platform_attitude_generators(), expected, atol=0)
    assert geometry.platform_attitude_generators(jnp.float32).dtype == jnp.float32


def test_attitude_error_matrix_first_order_and_cross_product():
    alpha = np.array([2.0, 1.0, 1.0]) * DEG
    delta = np.asarray(geometry.platform_attitude_error_matrix(*alpha))
    np.testing.assert_allclose(delta, -delta.T, atol=0)
    np.testing.assert_allclose(delta, np.einsum("i,ijk->jk", alpha, geometry.platform_attitude_generators()), atol=1e-18)
    omega = np.asarray(geometry.platform_rotation_vector(*alpha))
    np.testing.assert_allclose(omega, [alpha[1], -alpha[2], -alpha[0]], atol=0)
    v = np.array([3.0, -1.0, 2.0])
    np.testing.assert_allclose(delta @ v, np.cross(omega, v), atol=1e-15)

    def err(a):
        t = np.asarray(geometry.platform_to_enu_rotation(*a))
        return np.linalg.norm(t - np.eye(3) - np.asarray(geometry.platform_attitude_error_matrix(*a)))

    assert 3.8 <= err(alpha) / err(0.5 * alpha) <= 4.2  # second order in α


def test_attitude_error_matrix_batches():
    yaw = jnp.array([0.1, -0.2])
    d = geometry.platform_attitude_error_matrix(yaw, 0.05, jnp.array([0.02, 0.03]))
    assert d.shape == (2, 3, 3)
    np.testing.assert_allclose(d[1], geometry.platform_attitude_error_matrix(-0.2, 0.05, 0.03), atol=0)

"""Navigation frames and attitude-error utilities of jaxtrack.geometry (Layne & Blasch 1997, E9–E13, E106–E113)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpy.testing import assert_allclose

import jaxtrack.geometry as geo
from jaxtrack import InputError

KEY = jax.random.key(7)
ENU_TO_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def _orthonormal(C, atol=1e-12):
    C = np.asarray(C)
    assert_allclose(C @ np.swapaxes(C, -1, -2), np.broadcast_to(np.eye(3), C.shape), atol=atol)
    assert_allclose(np.linalg.det(C), 1.0, atol=atol)


def test_ned_to_ecef_is_the_transposed_ecef_to_enu_with_the_axis_swap():
    lat = jax.random.uniform(KEY, (50,), minval=-1.5, maxval=1.5)
    lon = jax.random.uniform(jax.random.fold_in(KEY, 1), (50,), minval=-math.pi, maxval=math.pi)
    C_ne = np.asarray(geo.ned_to_ecef_rotation(lat, lon))
    C_en_enu = np.asarray(geo.ecef_to_enu_rotation(lat, lon))
    assert_allclose(C_ne, np.swapaxes(np.einsum("ij,bjk->bik", ENU_TO_NED, C_en_enu), -1, -2), atol=1e-15)
    _orthonormal(C_ne)
    # columns: North, East, Down; at the origin North = +z, East = +y, Down = −x
    assert_allclose(np.asarray(geo.ned_to_ecef_rotation(0.0, 0.0)), [[0, 0, -1], [0, 1, 0], [1, 0, 0]], atol=1e-15)
    # a scalar longitude broadcasts against a batch of latitudes
    assert geo.ned_to_ecef_rotation(lat, 0.3).shape == (50, 3, 3)


def test_down_is_the_inward_ellipsoid_normal():
    lat, lon = jnp.array([0.7, -1.1]), jnp.array([-1.4, 2.9])
    up = jax.vmap(jax.jacfwd(geo.geodetic_to_ecef, argnums=2))(lat, lon, jnp.full(2, 100.0))
    assert_allclose(np.asarray(-geo.ned_to_ecef_rotation(lat, lon)[:, :, 2]), np.asarray(up), atol=1e-15)


def test_body_and_antenna_frames_are_the_321_sequence():
    a = jax.random.uniform(KEY, (20, 3), minval=-math.pi, maxval=math.pi)
    expected = geo.rotation_z(a[:, 2]) @ geo.rotation_y(a[:, 1]) @ geo.rotation_x(a[:, 0])
    for fn in (geo.body_to_ned_rotation, geo.antenna_to_body_rotation):
        C = fn(a)
        assert_allclose(np.asarray(C), np.asarray(expected), atol=1e-15)
        _orthonormal(C)
    # a body x axis pitched up by θ points North and up (−Down)
    assert_allclose(np.asarray(geo.body_to_ned_rotation(jnp.array([0.0, 0.2, 0.0]))[:, 0]),
                    [math.cos(0.2), 0.0, -math.sin(0.2)], atol=1e-15)


def test_heading_and_path_axes():
    assert_allclose(np.asarray(geo.heading_to_ned_rotation(1.1)[:, 0]), [math.cos(1.1), math.sin(1.1), 0], atol=1e-15)
    assert_allclose(np.asarray(geo.path_to_heading_rotation(0.2)[:, 0]), [math.cos(0.2), 0, -math.sin(0.2)], atol=1e-15)
    _orthonormal(geo.heading_to_ned_rotation(jnp.linspace(-3, 3, 7)))


def test_euler_perturbation_is_the_differential():
    a = jnp.array([0.3, -0.4, 1.1])
    da = jnp.array([1.0, 2.0, -1.5])
    dC = geo.euler_321_perturbation(a, da)
    assert_allclose(np.asarray(dC), np.asarray(jax.jvp(geo.euler_321_to_dcm, (a,), (da,))[1]), atol=1e-14)


def test_psi_angles_from_dcm_error():
    a = jnp.array([0.3, -0.4, 1.1])
    da = 1e-6 * jnp.array([1.0, 2.0, -1.5])
    C = geo.euler_321_to_dcm(a)
    dC = geo.euler_321_perturbation(a, da)
    psi = geo.psi_from_dcm_error(C, dC)
    assert_allclose(np.asarray(psi), np.asarray(geo.vee(0.5 * (C @ dC.T - dC @ C.T))), atol=1e-20)
    # δC = −[ψ×] C to first order (E109), and ψ = −M δα
    assert_allclose(np.asarray(-geo.skew(psi) @ C), np.asarray(dC), atol=1e-18)
    assert_allclose(np.asarray(psi), np.asarray(-geo.euler_error_matrix(a) @ da), rtol=1e-9)
    assert_allclose(np.asarray(geo.psi_to_euler_error(a, psi)), np.asarray(da), rtol=1e-9)
    # the misprinted E112 changes ψ_y only
    lit = geo.psi_from_dcm_error(C, dC, printed_e112=True)
    assert_allclose(np.asarray(lit)[[0, 2]], np.asarray(psi)[[0, 2]], rtol=1e-15)
    assert abs(float(lit[1] - psi[1])) > 1e-2 * abs(float(psi[1]))


def test_orthonormalize_nearest_rotation_and_first_order():
    C = geo.euler_321_to_dcm(jnp.array([0.2, 0.5, -2.0]))
    assert_allclose(np.asarray(geo.orthonormalize(C)), np.asarray(C), atol=1e-15)  # idempotent on rotations
    dC = 1e-4 * jax.random.normal(KEY, (3, 3))
    exact = geo.orthonormalize(C + dC)
    _orthonormal(exact)
    # the nearest rotation: closer to C + δC than C itself
    assert np.linalg.norm(np.asarray(exact - (C + dC))) <= np.linalg.norm(np.asarray(dC))
    res = [np.linalg.norm(np.asarray(geo.orthonormalize(C + s * dC) - geo.orthonormalize_first_order(C, s * dC)))
           for s in (1.0, 0.5)]
    assert 3.6 < res[0] / res[1] < 4.4  # the residual of E108 is second order
    batch = jnp.stack([C + dC, C - dC])
    assert_allclose(np.asarray(geo.orthonormalize(batch)[1]), np.asarray(geo.orthonormalize(C - dC)), atol=1e-15)
    assert geo.orthonormalize_first_order(batch, jnp.stack([dC, dC])).shape == (2, 3, 3)


def test_follows_float32():
    a = jnp.array([0.1, 0.2, 0.3], jnp.float32)
    assert geo.body_to_ned_rotation(a).dtype == jnp.float32
    assert geo.ned_to_ecef_rotation(jnp.float32(0.5), jnp.float32(0.1)).dtype == jnp.float32
    assert geo.euler_error_matrix(a).dtype == jnp.float32


def test_bad_inputs_raise_input_error():
    with pytest.raises(InputError, match="attitude"):
        geo.body_to_ned_rotation(jnp.zeros(2))
    with pytest.raises(InputError, match="antenna_angles"):
        geo.antenna_to_body_rotation(jnp.zeros((2, 4)))
    with pytest.raises(InputError, match="attitude_error"):
        geo.euler_321_perturbation(jnp.zeros(3), jnp.zeros(4))
    with pytest.raises(InputError, match="dcm"):
        geo.orthonormalize(jnp.eye(2))
    with pytest.raises(InputError, match="psi"):
        geo.psi_to_euler_error(jnp.zeros(3), jnp.zeros(2))

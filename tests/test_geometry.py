"""jaxtrack.geometry: spherical/Cartesian, ENU/FACE, WGS-84 ECEF and ENU→ENU (radar-bias spec V1–V6).

References are written independently here in NumPy: elementary rotations multiplied out, and the
Appendix's factored products R1(L2)·R2(Ω2−Ω1)·R1(L1)'.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import geometry as g

RTOL = 1e-10


def np_R1(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def np_R2(a):  # the Appendix's R2(Ω)
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])


def np_Ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def np_Rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])


PERM = np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0]])


@pytest.fixture
def rng():
    return np.random.default_rng(20240601)


def test_V1_enu_to_face_is_RyRz_and_orthonormal(rng):
    psi = rng.uniform(-np.pi, np.pi, 50)
    theta = rng.uniform(-np.pi / 2, np.pi / 2, 50)
    T = np.asarray(g.enu_to_face_rotation(psi, theta))
    ref = np.stack([np_Ry(t) @ np_Rz(p) for p, t in zip(psi, theta)])
    np.testing.assert_allclose(T, ref, rtol=RTOL, atol=1e-15)
    np.testing.assert_allclose(np.asarray(g.rotation_y(theta) @ g.rotation_z(-psi)), ref, atol=1e-15)
    np.testing.assert_allclose(T @ np.swapaxes(T, -1, -2), np.broadcast_to(np.eye(3), T.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(T), 1.0, rtol=1e-13)
    np.testing.assert_array_equal(np.asarray(g.face_to_enu_rotation(psi, theta)), np.swapaxes(T, -1, -2))


def test_V2_boresight_and_spherical_round_trip(rng):
    psi = rng.uniform(-np.pi, np.pi, 100)
    theta = rng.uniform(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3, 100)
    r = rng.uniform(1.0, 1e5, 100)
    T = np.asarray(g.enu_to_face_rotation(psi, theta))
    ones = np.stack([np.ones_like(psi), psi, theta], axis=-1)
    np.testing.assert_allclose(T[:, 0, :], np.asarray(g.spherical_to_cartesian(ones)), atol=1e-15)
    sph = np.stack([r, psi, theta], axis=-1)
    back = np.asarray(g.cartesian_to_spherical(g.spherical_to_cartesian(sph)))
    np.testing.assert_allclose(back, sph, rtol=1e-12, atol=1e-12)
    # atan2 keeps the quadrant that the paper's arctan(y/x) loses: a West-looking target.
    west = np.asarray(g.cartesian_to_spherical(jnp.array([-1.0, -1.0, 0.0])))
    np.testing.assert_allclose(west[1], -3 * np.pi / 4, rtol=RTOL)


def test_cartesian_to_spherical_is_nan_free_at_the_origin_and_pole():
    for p in (jnp.zeros(3), jnp.array([0.0, 0.0, 5.0])):
        jac = jax.jacfwd(g.cartesian_to_spherical)(p)
        assert np.all(np.isfinite(np.asarray(jac)))
    assert np.all(np.asarray(jax.grad(lambda p: g.cartesian_to_spherical(p).sum())(jnp.zeros(3))) == 0.0)


def test_V3_face_bias_matrix_and_jacobian_convention(rng):
    for _ in range(10):
        p, psi, theta = rng.uniform(10, 1e5), rng.uniform(-np.pi, np.pi), rng.uniform(-1.4, 1.4)
        A = np.asarray(g.face_bias_matrix(p, psi, theta))
        np.testing.assert_allclose(A, np.asarray(g.face_to_enu_rotation(psi, theta)) @ np.diag([1, p, p]), rtol=RTOL)
        np.testing.assert_allclose(np.linalg.det(A), p**2, rtol=1e-10)
        jac = np.asarray(jax.jacfwd(g.spherical_to_cartesian)(jnp.array([p, psi, theta])))
        np.testing.assert_allclose(jac, A @ np.diag([1, np.cos(theta), 1]), rtol=1e-10, atol=1e-9)
        # and the cross-range convention really differs from the Jacobian (not a test that can't fail)
        assert np.abs(jac[:, 1] - A[:, 1]).max() > 1e-3 * p * (1 - np.cos(theta))


def test_face_bias_matrix_is_vectorised():
    p = jnp.array([1.0, 2.0, 3.0])
    A = g.face_bias_matrix(p[:, None], jnp.array([0.1, 0.2]), 0.3)
    assert A.shape == (3, 2, 3, 3)
    np.testing.assert_allclose(np.asarray(A[2, 1]), np.asarray(g.face_bias_matrix(3.0, 0.2, 0.3)), rtol=RTOL)


def test_V4_appendix_closed_forms_equal_factored_products(rng):
    for _ in range(20):
        L1, L2 = rng.uniform(-1.5, 1.5, 2)
        O1, O2 = rng.uniform(-np.pi, np.pi, 2)
        T1 = np.asarray(g.ecef_to_enu_rotation(L1, O1))
        np.testing.assert_allclose(T1, np_R1(L1) @ np_R2(O1) @ PERM, atol=1e-15)
        T2 = np.asarray(g.ecef_to_enu_rotation(L2, O2))
        T12 = np.asarray(g.enu_to_enu_rotation(L1, O1, L2, O2))
        np.testing.assert_allclose(T12, np_R1(L2) @ np_R2(O2 - O1) @ np_R1(L1).T, atol=1e-15)
        np.testing.assert_allclose(T12, T2 @ T1.T, atol=1e-15)
        np.testing.assert_allclose(np_R2(O2 - O1), np_R2(O2) @ np_R2(O1).T, atol=1e-15)
        np.testing.assert_allclose(np.asarray(g.rotation_y(-O1)), np_R2(O1), atol=1e-15)
        np.testing.assert_allclose(np.asarray(g.rotation_x(L1)), np_R1(L1), atol=1e-15)
    np.testing.assert_array_equal(np.asarray(g.ecef_to_enu_rotation(0.0, 0.0)) + 0.0, PERM)


def test_geodetic_to_ecef_wgs84_reference_values():
    # Equator/prime meridian, the North pole (b = a sqrt(1 − e²)), and the paper's zero-height site form.
    np.testing.assert_allclose(np.asarray(g.geodetic_to_ecef(0.0, 0.0, 0.0)), [6378137.0, 0, 0], atol=1e-9)
    b = 6378137.0 * np.sqrt(1 - 6.69437999014e-3)
    np.testing.assert_allclose(np.asarray(g.geodetic_to_ecef(np.pi / 2, 0.0, 100.0)), [0, 0, b + 100.0], atol=1e-6)
    np.testing.assert_allclose(b, 6356752.314245, rtol=1e-12)  # WGS-84 semi-minor axis
    L, O = 0.7, -1.3
    n = 6378137.0 / np.sqrt(1 - 6.69437999014e-3 * np.sin(L) ** 2)
    paper = n * np.array([np.cos(L) * np.cos(O), np.cos(L) * np.sin(O), (1 - 6.69437999014e-3) * np.sin(L)])
    np.testing.assert_allclose(np.asarray(g.geodetic_to_ecef(L, O)), paper, rtol=1e-14)


def test_up_axis_is_ellipsoid_normal():
    # Up = ∂P/∂h / |∂P/∂h|, North ∝ ∂P/∂L: the rotation's rows are the geodetic frame.
    L, O = 0.4, 2.2
    jac = np.asarray(jax.jacfwd(lambda v: g.geodetic_to_ecef(v[0], v[1], v[2]))(jnp.array([L, O, 50.0])))
    T = np.asarray(g.ecef_to_enu_rotation(L, O))
    np.testing.assert_allclose(T[2], jac[:, 2], rtol=1e-12)
    np.testing.assert_allclose(T[1], jac[:, 0] / np.linalg.norm(jac[:, 0]), rtol=1e-12)
    np.testing.assert_allclose(T[0], jac[:, 1] / np.linalg.norm(jac[:, 1]), rtol=1e-12)


def test_V5_analytic_quarter_turn_and_round_trips(rng):
    T = np.asarray(g.enu_to_enu_rotation(0.0, 0.0, 0.0, np.pi / 2))
    np.testing.assert_allclose(T, [[0, 0, -1], [0, 1, 0], [1, 0, 0]], atol=1e-15)
    np.testing.assert_allclose(np.asarray(g.enu_site_offset(0.0, 0.0, 0.0, np.pi / 2)),
                               6378137.0 * np.array([1.0, 0.0, -1.0]), rtol=1e-14, atol=1e-8)
    # Identical sites: identity and zero offset.
    np.testing.assert_allclose(np.asarray(g.enu_to_enu_rotation(0.3, 1.1, 0.3, 1.1)), np.eye(3), atol=1e-15)
    np.testing.assert_allclose(np.asarray(g.enu_site_offset(0.3, 1.1, 0.3, 1.1)), np.zeros(3), atol=1e-9)
    for _ in range(10):
        L1, L2 = rng.uniform(-1.4, 1.4, 2)
        O1, O2 = rng.uniform(-np.pi, np.pi, 2)
        h1, h2 = rng.uniform(0, 3000, 2)
        pts = rng.normal(scale=1e5, size=(7, 3))
        there = g.enu_to_enu(pts, L1, O1, L2, O2, h1, h2)
        back = np.asarray(g.enu_to_enu(there, L2, O2, L1, O1, h2, h1))
        np.testing.assert_allclose(back, pts, atol=1e-6)
        # Same point through ECEF directly.
        ecef = g.enu_to_ecef(pts, L1, O1, h1)
        np.testing.assert_allclose(np.asarray(there), np.asarray(g.ecef_to_enu(ecef, L2, O2, h2)), atol=1e-6)
        # Inverse form of the Appendix: P_ENU(1) = T_ENU(2)2ENU(1) P_ENU(2) + P_1TO2,ENU(1).
        T12 = np.asarray(g.enu_to_enu_rotation(L1, O1, L2, O2))
        off1 = np.asarray(g.enu_site_offset(L1, O1, L2, O2, h1, h2, frame=1))
        np.testing.assert_allclose(np.asarray(there) @ T12 + off1, pts, atol=1e-6)
        # The offset in frame 2 is the frame-1 offset rotated.
        np.testing.assert_allclose(np.asarray(g.enu_site_offset(L1, O1, L2, O2, h1, h2, frame=2)), T12 @ off1, atol=1e-6)


def test_geometry_is_vectorised_over_sites():
    lat = jnp.array([0.1, 0.2, 0.3])
    lon = jnp.array([[1.0], [2.0]])
    assert g.geodetic_to_ecef(lat, lon, 0.0).shape == (2, 3, 3)
    assert g.ecef_to_enu_rotation(lat, lon).shape == (2, 3, 3, 3)
    assert g.enu_to_enu_rotation(lat, lon, 0.5, 0.5).shape == (2, 3, 3, 3)
    np.testing.assert_allclose(np.asarray(g.ecef_to_enu_rotation(lat, lon)[1, 2]),
                               np.asarray(g.ecef_to_enu_rotation(0.3, 2.0)), rtol=RTOL)


def test_enu_to_enu_is_differentiable_in_site_coordinates():
    # d/dΩ2 of the mapped point: autodiff against central differences.
    p = jnp.array([1e4, -2e4, 3e3])

    def f(o2):
        return g.enu_to_enu(p, 0.5, 0.1, 0.52, o2)

    jac = np.asarray(jax.jacfwd(f)(0.13))
    h = 1e-6
    fd = (np.asarray(f(0.13 + h)) - np.asarray(f(0.13 - h))) / (2 * h)
    np.testing.assert_allclose(jac, fd, rtol=1e-6)


def test_enu_site_offset_rejects_bad_frame():
    from jaxtrack import InputError

    with pytest.raises(InputError, match="frame"):
        g.enu_site_offset(0.0, 0.0, 0.0, 1.0, frame=3)

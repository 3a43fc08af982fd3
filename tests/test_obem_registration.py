"""Mobile-radar registration study, AAM versus OBEM (specs/obem-registration.md): targets V1–V14, S1–S7.

Oracles are independent of the code under test where possible: NumPy transcriptions of the
paper's printed matrices (eqs 7, 11, 19 as corrected, §1.7's A), the spec's check values,
``jax.jacfwd`` of the exact nonlinear chain, batch weighted least squares, jaxtrack's own
``run_filter``/``KalmanFilter``, central finite differences, and Monte Carlo statistics with the
spec's margins. Monte Carlo in CI: 100 runs (the paper's and the spec's size), key 2024 (the
spec's curves seed); ``--runslow`` repeats S1–S5, S7 with 1000 runs on another key.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError, geometry
from jaxtrack.applications import obem_registration as ob
from jaxtrack.estimation import observability, weighted_least_squares
from jaxtrack.filters import KalmanFilter, condition_linearized, run_filter
from jaxtrack.models import LinearGaussianModel
from rows_baseline import assert_rows_match_c1ffaca

DEG = np.pi / 180
ALPHA = np.array([2.0, 1.0, 1.0]) * DEG  # the paper's (Δφ, Δη, Δψ)
MC_RUNS = 100
MC_SEED = 2024


# ---------------------------------------------------------------------------------------------
# Independent NumPy transcriptions of the paper's matrices


def t_p2enu_eq7(phi, eta, psi):
    """Eq. (7) entry by entry, with t31 = sψ cη and t32 = sη (spec §6 items 1–2)."""
    cf, sf, ce, se, cp, sp = np.cos(phi), np.sin(phi), np.cos(eta), np.sin(eta), np.cos(psi), np.sin(psi)
    return np.array([
        [cp * cf - sp * se * sf, ce * sf, -sp * cf - cp * se * sf],
        [-cp * sf - sp * se * cf, ce * cf, sp * sf - cp * se * cf],
        [sp * ce, se, cp * ce],
    ])


def t_enu2ecef_eq11(lat, lon):
    a, b, c, d = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    return np.array([[-c, -a * d, b * d], [d, -a * c, b * c], [0.0, b, a]])


def a_matrix_17(r, th, el):
    st, ct, se, ce = np.sin(th), np.cos(th), np.sin(el), np.cos(el)
    return np.array([
        [-st * ce, -r * st * ce, -r * ct * ce, r * st * se],
        [-ct * ce, -r * ct * ce, r * st * ce, r * ct * se],
        [-se, -r * se, 0.0, -r * ce],
    ])


def d_matrix_19(xyz, lat, lon, *, ocr=False):
    x, y, z = xyz
    a, b, c, d = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    d21 = x * a * c + y * c * d if ocr else x * a * c + y * d  # the OCR prints "x a c + y c d"
    return np.array([
        [x * a * d - y * c, y * b * d + z * a * d, x * b * d + z * c],
        [d21, y * b * c + z * a * c, x * b * c - z * d],
        [-x * b, y * a - z * b, x * a],
    ])


def random_geometry(rng):
    """A random radar measurement [r, θ, ε] and site [L, λ, h]."""
    raw = np.array([rng.uniform(20e3, 150e3), rng.uniform(-np.pi, np.pi), rng.uniform(0.0, 10 * DEG)])
    site = np.array([rng.uniform(-1.3, 1.3), rng.uniform(-np.pi, np.pi), rng.uniform(0.0, 100.0)])
    return raw, site


def rel(a, b):
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(np.asarray(b))))


@pytest.fixture
def rng():
    return np.random.default_rng(8)


@pytest.fixture(scope="module")
def scenario():
    return ob.paper_scenario()


@pytest.fixture(scope="module")
def free_track(scenario):
    """The bias-free, noise-free §4 track and its registration inputs."""
    scans = ob.simulate_scans(ob.bias_free(scenario), jax.random.key(0), measurement_noise=False, process_noise=False)
    return scans, ob.registration_inputs(scans, scenario.noise_std)


@pytest.fixture(scope="module")
def biased_track(scenario):
    """The biased, noise-free §4 track and its registration inputs."""
    scans = ob.simulate_scans(scenario, jax.random.key(0), measurement_noise=False, process_noise=False)
    return scans, ob.registration_inputs(scans, scenario.noise_std)


@pytest.fixture(scope="module")
def noisy_run(scenario):
    scans = ob.simulate_scans(scenario, jax.random.key(3))
    return scans, ob.registration_inputs(scans, scenario.noise_std)


# ---------------------------------------------------------------------------------------------
# V1–V3: frames


def test_v1_attitude_rotation(rng):
    for _ in range(5):
        a = rng.uniform(-0.3, 0.3, 3)
        t = np.asarray(ob.attitude_matrix(a))
        np.testing.assert_allclose(t, t_p2enu_eq7(*a), rtol=0, atol=1e-14)
        np.testing.assert_allclose(t @ t.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(t) == pytest.approx(1.0, abs=1e-14)
    check = np.array([[0.99922799, 0.03489418, -0.01805076],
                      [-0.03519858, 0.99923861, -0.01683004],
                      [0.01744975, 0.01745241, 0.99969541]])
    t = np.asarray(ob.attitude_matrix(ALPHA))
    np.testing.assert_allclose(t, check, rtol=0, atol=1e-8)
    # Eq. (6): T_ENU2p = T_p2ENUᵀ undoes the rotation.
    x = rng.normal(size=3)
    np.testing.assert_allclose(t.T @ (t @ x), x, atol=1e-14)
    # The OCR's t31 (a copy of t21) is not the rotation's entry.
    assert abs(t[2, 0] - t[1, 0]) > 0.05


def test_platform_rotation_geometry_function_batches():
    yaw = jnp.array([0.1, -0.2])
    t = geometry.platform_to_enu_rotation(yaw, 0.05, jnp.array([0.02, 0.03]))
    assert t.shape == (2, 3, 3)
    np.testing.assert_allclose(t[1], t_p2enu_eq7(-0.2, 0.05, 0.03), atol=1e-14)


def test_v2_first_order():
    def err(a):
        return float(np.linalg.norm(np.asarray(ob.attitude_matrix(a)) - np.asarray(jnp.eye(3) + geometry.platform_attitude_error_matrix(*a))))

    for scale in (1.0, 0.5, 0.1):
        ratio = err(scale * ALPHA) / err(0.5 * scale * ALPHA)
        assert 3.8 <= ratio <= 4.2
    gens = jax.jacfwd(ob.attitude_matrix)(jnp.zeros(3))  # (3, 3, 3): [i, j, angle]
    expected = np.array([[[0, 1, 0], [-1, 0, 0], [0, 0, 0]], [[0, 0, 0], [0, 0, -1], [0, 1, 0]],
                         [[0, 0, -1], [0, 0, 0], [1, 0, 0]]], dtype=float)
    np.testing.assert_allclose(np.moveaxis(np.asarray(gens), -1, 0), expected, atol=1e-15)
    np.testing.assert_allclose(geometry.platform_attitude_generators(), expected, atol=0)
    delta = np.asarray(geometry.platform_attitude_error_matrix(*ALPHA))
    np.testing.assert_allclose(delta, -delta.T, atol=0)
    omega = np.array([ALPHA[1], -ALPHA[2], -ALPHA[0]])
    v = np.array([3.0, -1.0, 2.0])
    np.testing.assert_allclose(delta @ v, np.cross(omega, v), atol=1e-15)


def test_v3_enu_to_ecef(rng, scenario):
    for _ in range(5):
        lat, lon = rng.uniform(-1.4, 1.4), rng.uniform(-np.pi, np.pi)
        t = np.asarray(geometry.ecef_to_enu_rotation(lat, lon)).T
        np.testing.assert_allclose(t, t_enu2ecef_eq11(lat, lon), atol=1e-15)
        np.testing.assert_allclose(t.T @ t, np.eye(3), atol=1e-15)
    x1 = np.asarray(geometry.geodetic_to_ecef(*scenario.ship_sites[0]))
    x2 = np.asarray(geometry.geodetic_to_ecef(*scenario.ship_sites[1]))
    np.testing.assert_allclose(x1, [-2_144_825.200, 4_397_543.346, 4_077_992.000], rtol=0, atol=1e-3)
    np.testing.assert_allclose(x2, [-2_070_938.660, 4_373_199.999, 4_141_437.152], rtol=0, atol=1e-3)
    assert np.linalg.norm(x2 - x1) / 1e3 == pytest.approx(100.385, abs=5e-4)
    lat, lon, h = scenario.ship_sites[0]
    above = geometry.geodetic_to_ecef(lat, lon, h + 100.0)
    np.testing.assert_allclose(geometry.ecef_to_enu(above, lat, lon, h), [0.0, 0.0, 100.0], atol=1e-6)


def test_v3_ecef_geodetic_round_trip(rng):
    lat = rng.uniform(-1.5, 1.5, 50)
    lon = rng.uniform(-np.pi, np.pi, 50)
    h = rng.uniform(-500.0, 2e4, 50)
    p = geometry.geodetic_to_ecef(lat, lon, h)
    lat2, lon2, h2 = geometry.ecef_to_geodetic(p)
    assert float(jnp.max(jnp.linalg.norm(geometry.geodetic_to_ecef(lat2, lon2, h2) - p, axis=-1))) < 1e-6
    np.testing.assert_allclose(lat2, lat, atol=1e-12)
    np.testing.assert_allclose(h2, h, atol=1e-6)
    # Differentiable and jit-able (fixed iteration count).
    g = jax.jit(jax.grad(lambda q: geometry.ecef_to_geodetic(q)[2]))(p[0])
    np.testing.assert_allclose(g, geometry.ecef_to_enu_rotation(lat[0], lon[0])[2], atol=1e-9)


def test_radar_spherical_convention():
    x = geometry.compass_spherical_to_cartesian(jnp.array([1000.0, 30 * DEG, 10 * DEG]))
    np.testing.assert_allclose(x, 1000 * np.array([np.sin(30 * DEG) * np.cos(10 * DEG),
                                                   np.cos(30 * DEG) * np.cos(10 * DEG), np.sin(10 * DEG)]), atol=1e-9)
    back = geometry.cartesian_to_compass_spherical(jnp.array([-1.0, -1.0, 0.0]))
    assert float(back[1]) == pytest.approx(-135 * DEG)


# ---------------------------------------------------------------------------------------------
# V4–V7: A, C, D and the azimuth/yaw identity


def test_v4_offset_jacobians(rng):
    for _ in range(5):
        raw, _ = random_geometry(rng)
        jac = jax.jacfwd(lambda b: ob.offset_corrected_position(raw, b))(jnp.zeros(4))
        a = np.asarray(ob.offset_jacobian(raw))
        np.testing.assert_allclose(jac, a_matrix_17(*raw), rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(a, a_matrix_17(*raw), rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(ob.noise_jacobian(raw), a[:, [0, 2, 3]], atol=0)
        jac_w = jax.jacfwd(lambda w: ob.offset_corrected_position(raw, jnp.zeros(4), w))(jnp.zeros(3))
        np.testing.assert_allclose(jac_w, a[:, [0, 2, 3]], rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(a[:, 1], raw[0] * a[:, 0], rtol=1e-12)  # collinear Δr, k_r columns


def test_v5_attitude_jacobian_and_ocr_row(rng):
    for _ in range(5):
        raw, site = random_geometry(rng)
        x = np.asarray(ob.offset_corrected_position(raw, jnp.zeros(4)))
        t = geometry.ecef_to_enu_rotation(site[0], site[1]).T
        jac = np.asarray(jax.jacfwd(lambda a: t @ ob.attitude_matrix(a) @ x)(jnp.zeros(3)))
        d = np.asarray(ob.attitude_jacobian(x, site[0], site[1]))
        np.testing.assert_allclose(jac, d_matrix_19(x, site[0], site[1]), rtol=1e-12, atol=1e-8)
        np.testing.assert_allclose(d, jac, rtol=1e-12, atol=1e-8)
        # The OCR's row 2, column 1 ("x a c + y c d") is caught.
        ocr = d_matrix_19(x, site[0], site[1], ocr=True)
        assert abs(ocr[1, 0] - jac[1, 0]) > 1e-3 * np.max(np.abs(jac))


def test_v6_azimuth_yaw_identity(rng):
    for _ in range(20):
        raw, site = random_geometry(rng)
        x = ob.offset_corrected_position(raw, jnp.zeros(4))
        ta3 = np.asarray(geometry.ecef_to_enu_rotation(site[0], site[1]).T @ ob.offset_jacobian(raw))[:, 2]
        d1 = np.asarray(ob.attitude_jacobian(x, site[0], site[1]))[:, 0]
        assert np.linalg.norm(ta3 + d1) / np.linalg.norm(d1) < 1e-12


def test_v7_aam_null_vectors(rng):
    for _ in range(10):
        (raw1, site1), (raw2, site2) = random_geometry(rng), random_geometry(rng)
        h = np.asarray(ob.registration_terms(raw1, site1, raw2, site2).measurement_matrix)
        for i, j in ((2, 8), (6, 11)):
            v = np.zeros(14)
            v[i] = v[j] = 1.0
            assert np.linalg.norm(h @ v) / np.linalg.norm(h[:, i]) < 1e-12
        np.testing.assert_allclose(ob.merged_columns(h), np.delete(h, [8, 11], axis=1), atol=0)
        np.testing.assert_allclose(ob.obem_columns(h), h[:, :8], atol=0)


# ---------------------------------------------------------------------------------------------
# V8–V9: the registration equation


def test_v8_registration_identity(scenario, free_track, biased_track):
    _, free_in = free_track
    assert float(jnp.max(jnp.abs(free_in.Z))) < 1e-6
    _, inp = biased_track
    res_aam = np.linalg.norm(inp.Z - jnp.einsum("kij,j->ki", inp.H, ob.aam_truth(scenario.offset_bias, scenario.attitude_bias)), axis=1)
    res_obem = np.linalg.norm(inp.Z - jnp.einsum("kij,j->ki", ob.obem_columns(inp.H),
                                                  ob.obem_truth(scenario.offset_bias, scenario.attitude_bias)), axis=1)
    assert res_aam.max() < 200.0 and res_aam.min() > 50.0  # spec: 100–135 m of linearisation error
    assert res_obem.max() < 600.0 and res_obem.min() > 300.0  # spec: 370–430 m (pitch/roll left out)
    z = np.linalg.norm(inp.Z, axis=1)
    assert 1.0e3 < z.min() and z.max() < 2.8e3  # spec: |Z| ≈ 1.2–2.7 km
    r_scale = np.sqrt(np.trace(np.asarray(inp.R), axis1=1, axis2=2))
    assert 0.8e3 < r_scale.min() and r_scale.max() < 1.9e3  # spec: √tr R ≈ 0.9–1.8 km


def test_v9_nonlinear_consistency(scenario, biased_track):
    scans, inp = biased_track
    truth = ob.aam_truth(scenario.offset_bias, scenario.attitude_bias)
    for k in (0, 77, 199):
        args = (scans.raw[0, k], scans.sites[0, k], scans.raw[1, k], scans.sites[1, k])
        jac = jax.jacfwd(ob.nonlinear_pseudo_measurement)(jnp.zeros(14), *args)
        np.testing.assert_allclose(jac, inp.H[k], rtol=1e-9, atol=1e-9 * float(jnp.max(jnp.abs(inp.H[k]))))
        g = [ob.ecef_position(scans.raw[i, k], scans.sites[i, k], jnp.zeros(4), jnp.zeros(3)) for i in (0, 1)]
        np.testing.assert_allclose(g[1] - g[0], inp.Z[k], atol=1e-6)
        # The exact chain explains Z up to the range-gain convention (k_r·r_m vs k_r·r_t, ≈ 13 m per radar).
        assert float(jnp.linalg.norm(ob.nonlinear_pseudo_measurement(truth, *args) - inp.Z[k])) < 30.0


# ---------------------------------------------------------------------------------------------
# V10: Proposition 2


def test_v10_proposition2_check_values():
    x = jnp.array([60e3, 30e3, 5e3])
    exact = np.asarray(ob.equivalent_errors_exact(ALPHA, x))
    first = np.asarray(ob.equivalent_errors_first_order(ALPHA, x))
    assert exact[1] / DEG == pytest.approx(-2.0338, abs=5e-4)
    assert first[1] / DEG == pytest.approx(-2.0333, abs=5e-5)
    assert exact[2] / DEG == pytest.approx(-1.3565, abs=5e-4)
    assert first[2] / DEG == pytest.approx(-1.3416, abs=5e-5)
    assert abs(exact[0]) < 1e-9
    # The [X] closed forms in θ, ε.
    th, el = np.arctan2(60.0, 30.0), np.arctan2(5.0, np.hypot(60.0, 30.0))
    assert first[1] == pytest.approx(-ALPHA[0] + np.tan(el) * (np.cos(th) * ALPHA[2] - np.sin(th) * ALPHA[1]), rel=1e-12)
    assert first[2] == pytest.approx(-(ALPHA[2] * np.sin(th) + ALPHA[1] * np.cos(th)), rel=1e-12)


def test_v10_proposition2_random_geometry(rng):
    gap_az, gap_el = ob.rows._random_prop2_gap(jax.random.key(10))
    assert gap_az < 0.03 and gap_el < 0.06
    assert gap_el > 0.02  # not trivially zero: the residual is second order, ≈ 0.05°
    raw = np.stack([rng.uniform(20e3, 150e3, 200), rng.uniform(-np.pi, np.pi, 200), rng.uniform(0, 10 * DEG, 200)], -1)
    x = geometry.compass_spherical_to_cartesian(raw)
    assert float(jnp.max(jnp.abs(ob.equivalent_errors_exact(ALPHA, x)[:, 0]))) < 1e-9

    def residual(a):
        return np.abs(np.asarray(ob.equivalent_errors_exact(a, x) - ob.equivalent_errors_first_order(a, x)))

    full, half = residual(ALPHA), residual(0.5 * ALPHA)
    ratio = full[:, 2].max() / half[:, 2].max()
    assert 3.6 < ratio < 4.4  # second order in α


def test_v10_east_axis_special_case():
    att = jnp.asarray(ALPHA)
    for x, z in ((50e3, 3e3), (120e3, 8e3)):
        eq40 = float(ob.east_axis_azimuth_error(att, x, z))
        eq36 = float(ob.equivalent_errors_first_order(att, jnp.array([x, 0.0, z]))[1])
        assert eq40 == pytest.approx(eq36, rel=1e-14)
        exact = float(ob.equivalent_errors_exact(att, jnp.array([x, 0.0, z]))[1])
        assert abs(exact - eq40) < 0.01 * DEG


# ---------------------------------------------------------------------------------------------
# V11: observability


def test_v11_observability(free_track, biased_track):
    _, inp = free_track
    o14 = observability(inp.H)
    o12 = observability(ob.merged_columns(inp.H))
    o8 = observability(ob.obem_columns(inp.H))
    assert o14.num_null() == 3
    assert o12.num_null() == 1
    assert float(o8.condition) < 1e3
    assert float(o8.condition) == pytest.approx(140, rel=0.1)
    assert float(o14.eigenvalues[-1]) == pytest.approx(4.17, abs=0.01)
    # The remaining null direction: pitch and roll of both platforms, equal signs, ≈ (0.67, 1, 0.67, 0.99).
    v = o12.physical_direction(0)
    idx = [ob.MERGED_STATES.index(s) for s in ("Δη1", "Δψ1", "Δη2", "Δψ2")]
    angles = [i for i, s in enumerate(ob.MERGED_STATES) if s[1] in "θεηψ"]
    tilt = v[idx]
    assert np.all(np.sign(tilt) == np.sign(tilt[0]))
    np.testing.assert_allclose(np.abs(tilt) / np.abs(tilt).max(), [0.67, 1.0, 0.67, 0.99], atol=0.01)
    others = [i for i in angles if i not in idx]
    assert np.linalg.norm(v[others]) < 0.02 * np.linalg.norm(tilt)
    # With H from biased raw data the direction is only weakly observable (spec: 1.9e-6, cond ≈ 2e6).
    o12b = observability(ob.merged_columns(biased_track[1].H))
    assert float(o12b.eigenvalues[0]) == pytest.approx(1.9e-6, rel=0.1)


def test_v11_baseline_rotation_is_a_null_direction(scenario, free_track):
    scans, inp = free_track
    att = np.asarray(ob.baseline_rotation_attitudes(scans.sites[0, 0], scans.sites[1, 0]))
    att = att * np.sign(att[0, 0])
    np.testing.assert_allclose(att, [[0.0079, -0.555, -0.832], [-0.0079, -0.561, -0.828]], atol=6e-4)
    # As a 14-state vector (offsets 0) it leaves Z unchanged at the scan where the sites were taken;
    # the ships' motion tilts the baseline slowly, so later scans see a small residual that the
    # merged model's offsets absorb (its null vector below).
    v = np.concatenate([np.zeros(8), att[0], att[1]])
    hv = np.abs(np.einsum("kij,j->ki", np.asarray(inp.H), v))
    scale = np.linalg.norm(np.asarray(inp.H)[:, :, 8:], axis=1).max()
    assert hv[0].max() < 1e-12 * scale
    assert hv.max() < 2e-3 * scale
    null = observability(ob.merged_columns(inp.H)).physical_direction(0)
    tilt = null[[ob.MERGED_STATES.index(s) for s in ("Δη1", "Δψ1", "Δη2", "Δψ2")]]
    ref = att[:, 1:].ravel()
    assert abs(tilt @ ref) / (np.linalg.norm(tilt) * np.linalg.norm(ref)) > 0.9999
    # A generic rotation (about the vertical) is plainly visible.
    w = np.concatenate([np.zeros(8), [1.0, 0, 0], [1.0, 0, 0]])
    assert np.abs(np.einsum("kij,j->ki", np.asarray(inp.H), w)).max() > 0.1 * scale


@pytest.mark.xfail(strict=True, reason="Proposition 1 as stated ('the 12-state model is observable') is false: "
                   "a common rotation about the baseline stays unobservable (spec §2.4 [X], §6 item 25)")
def test_v11_proposition1_as_stated(free_track):
    o12 = observability(ob.merged_columns(free_track[1].H))
    assert o12.num_null() == 0


# ---------------------------------------------------------------------------------------------
# V12: Kalman filter algebra


def test_v12_kf_equals_batch_wls(noisy_run):
    _, inp = noisy_run
    h8 = ob.obem_columns(inp.H)
    sigma0 = jnp.sqrt(jnp.diagonal(ob.prior_cov("obem")))

    def scaled_rel(a, b):
        return float(jnp.linalg.norm((a - b) / sigma0) / jnp.linalg.norm(b / sigma0))

    # The covariance-form KF cannot take P0 = 1e12·σ0² (first updates cancel all digits); 1e6·σ0²
    # is diffuse enough for the prior to be invisible at 1e-6 and still well inside float64.
    diffuse = 1e6 * ob.prior_cov("obem")
    est = ob.registration_filter(inp.Z, h8, inp.R, diffuse)
    assert scaled_rel(est.mean[-1], weighted_least_squares(h8, inp.Z, inp.R).mean) < 1e-6
    # With a proper prior the KF is exactly the regularised batch solution.
    p0 = ob.prior_cov("obem")
    est = ob.registration_filter(inp.Z, h8, inp.R, p0)
    assert scaled_rel(est.mean[-1], weighted_least_squares(h8, inp.Z, inp.R, p0).mean) < 1e-10
    # Joseph and standard forms agree.
    std = ob.registration_filter(inp.Z, h8, inp.R, p0, form="standard")
    assert scaled_rel(std.mean[-1], est.mean[-1]) < 1e-8
    aam_j = ob.registration_filter(inp.Z, inp.H, inp.R, ob.prior_cov("aam"))
    aam_s = ob.registration_filter(inp.Z, inp.H, inp.R, ob.prior_cov("aam"), form="standard")
    s14 = jnp.sqrt(jnp.diagonal(ob.prior_cov("aam")))
    assert float(jnp.max(jnp.abs(aam_j.mean[-1] - aam_s.mean[-1]) / s14)) < 1e-8


def test_v12_matches_jaxtrack_kalman_filter(noisy_run):
    _, inp = noisy_run
    p0 = ob.prior_cov("aam")
    model = LinearGaussianModel(jnp.eye(14), jnp.zeros((14, 14)), inp.H, inp.R, jnp.zeros(14), p0)
    lib = run_filter(KalmanFilter(), model, inp.Z)
    ours = ob.registration_filter(inp.Z, inp.H, inp.R, p0, save_cov=True)
    np.testing.assert_allclose(ours.mean, lib.filtered_mean, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(ours.cov[-1], lib.final_cov, rtol=1e-9, atol=1e-20)


def test_v12_scan_vmap_and_loops(scenario):
    keys = jax.random.split(jax.random.key(5), 3)
    inputs = [ob.registration_inputs(ob.simulate_scans(scenario, k), scenario.noise_std)
              for k in keys]
    p0 = ob.prior_cov("obem")
    batched = jax.vmap(lambda z, h, r: ob.registration_filter(z, h, r, p0).mean)(
        jnp.stack([i.Z for i in inputs]), jnp.stack([ob.obem_columns(i.H) for i in inputs]), jnp.stack([i.R for i in inputs]))
    sigma0 = np.sqrt(np.diagonal(np.asarray(p0)))
    for b, inp in zip(batched, inputs):
        single = ob.registration_filter(inp.Z, ob.obem_columns(inp.H), inp.R, p0).mean
        # Batched and single kernels round differently; compare in units of each state's prior σ0.
        assert np.max(np.abs(np.asarray(b - single)) / sigma0) < 1e-10
    # lax.scan against an unrolled Python loop of the same update.
    inp = inputs[0]
    mean, cov = jnp.zeros(8), p0
    h8 = ob.obem_columns(inp.H)
    for k in range(scenario.num_scans):
        post = condition_linearized(mean, cov, inp.Z[k] - h8[k] @ mean, h8[k], inp.R[k], jnp.ones(3, bool))
        mean, cov = post.mean, post.cov
    assert np.max(np.abs(np.asarray(batched[0][-1] - mean)) / sigma0) < 1e-10


def test_v12_autodiff_sensitivities_match_finite_differences(noisy_run, scenario):
    scans, _ = noisy_run
    terms = jax.vmap(ob.registration_terms)(scans.raw[0], scans.sites[0], scans.raw[1], scans.sites[1])
    h8 = ob.obem_columns(terms.measurement_matrix)
    p0 = ob.prior_cov("obem")

    def final_estimate(sigma_r):
        std = scenario.noise_std.at[:, 0].set(sigma_r)
        r = ob.pseudo_measurement_noise_cov(terms.noise_matrix, std)
        return ob.registration_filter(terms.pseudo_measurement, h8, r, p0).mean[-1]

    sr, step = 50.0, 1e-2
    ad = jax.jacfwd(final_estimate)(sr)
    fd = (final_estimate(sr + step) - final_estimate(sr - step)) / (2 * step)
    assert float(jnp.linalg.norm(ad - fd) / jnp.linalg.norm(ad)) < 1e-5

    truth = ob.obem_truth(scenario.offset_bias, scenario.attitude_bias)
    s0 = jnp.sqrt(jnp.diagonal(p0))

    def loss(log_scale):
        r = ob.pseudo_measurement_noise_cov(terms.noise_matrix, scenario.noise_std)
        est = ob.registration_filter(terms.pseudo_measurement, h8, r, jnp.exp(log_scale) * p0).mean[-1]
        return jnp.sum(((est - truth) / s0) ** 2)

    g = jax.grad(loss)(0.0)
    fd = (loss(1e-4) - loss(-1e-4)) / 2e-4
    assert float(abs(g - fd) / abs(g)) < 1e-5


# ---------------------------------------------------------------------------------------------
# V13–V14


def test_v13_geometry_table(free_track):
    scans, _ = free_track
    for k, r1, r2 in ob.GEOMETRY_TABLE:
        for i, ref in ((0, r1), (1, r2)):
            r, az, el = np.asarray(scans.raw[i, k - 1])
            assert r / 1e3 == pytest.approx(ref[0], abs=0.05)
            assert az / DEG == pytest.approx(ref[1], abs=0.05)
            assert el / DEG == pytest.approx(ref[2], abs=0.05)
    # Radar 1's target passes through North, radar 2's through South (azimuth wraps to (−π, π]).
    assert np.all(np.abs(np.asarray(scans.raw[:, :, 1])) <= np.pi)


def test_v14_cost_model(noisy_run, capsys):
    ratio = ob.cubic_cost_ratio()
    assert ratio == pytest.approx((8 / 14) ** 3, rel=1e-15)
    assert 0.75 <= 1 - ratio <= 0.85
    assert (ob.update_multiply_adds(14), ob.update_multiply_adds(8)) == (1428, 528)
    assert (ob.update_multiply_adds(14, joseph=True), ob.update_multiply_adds(8, joseph=True)) == (6916, 1552)
    flops8, flops14 = ob.update_flops(8), ob.update_flops(14)
    # The library's update is O(n²m) (rank-m Joseph form): the compiled FLOPs fall by ≈ 59%, less
    # than the dense O(n³) model's 81% and the spec's optional 60% (see the V14 row).
    assert 0.50 <= 1 - flops8 / flops14 <= 0.70
    t_aam, t_obem = ob.measure_filter_times(noisy_run[1], num_runs=20, repeats=3)
    assert t_aam > 0 and t_obem > 0  # wall-clock is reported, never asserted (spec §5.1 V14)
    with capsys.disabled():
        print(f"\n[V14] OBEM/AAM: O(n³) {ratio:.3f}, XLA FLOPs {flops8 / flops14:.3f}, measured time "
              f"{t_obem / t_aam:.2f} (paper: 'about 80%' reduction)")


# ---------------------------------------------------------------------------------------------
# Filters, rectification, inputs


def test_rectify_with_true_biases(scenario, biased_track):
    scans, _ = biased_track
    raw1, truth = scans.raw[0], scans.target_enu[0]
    off = ob.obem_truth(scenario.offset_bias, scenario.attitude_bias)[:4]
    ident = jnp.broadcast_to(off, (raw1.shape[0], 4))
    pr = jnp.broadcast_to(scenario.attitude_bias[0, 1:], (raw1.shape[0], 2))
    raw_err = np.linalg.norm(np.asarray(ob.rectify(raw1, jnp.zeros_like(ident), jnp.zeros_like(pr)) - truth), axis=1)
    fixed = np.linalg.norm(np.asarray(ob.rectify(raw1, ident, pr) - truth), axis=1)
    assert raw_err.min() > 500.0 and raw_err.mean() > 2e3
    assert fixed.max() < 150.0  # second-order terms (yaw merged into azimuth) and the gain convention
    one = ob.rectify(raw1[0], off, scenario.attitude_bias[0, 1:])
    np.testing.assert_allclose(one, ob.rectify(raw1, ident, pr)[0], atol=1e-9)


def test_input_errors(noisy_run):
    _, inp = noisy_run
    with pytest.raises(InputError, match="form"):
        ob.registration_filter(inp.Z, inp.H, inp.R, ob.prior_cov("aam"), form="information")
    with pytest.raises(InputError, match="prior_cov"):
        ob.registration_filter(inp.Z, inp.H, inp.R, ob.prior_cov("obem"))
    with pytest.raises(InputError, match="R"):
        ob.registration_filter(inp.Z, inp.H, inp.R[:-1], ob.prior_cov("aam"))
    with pytest.raises(InputError, match="positive definite"):
        ob.registration_filter(inp.Z, inp.H, inp.R, -ob.prior_cov("aam"))
    with pytest.raises(InputError, match="prior"):
        ob.prior_cov("obem", "huge")
    with pytest.raises(InputError, match="model"):
        ob.prior_cov("ekf")
    with pytest.raises(InputError, match="offset_bias"):
        ob.Scenario(**{**{f: getattr(ob.paper_scenario(), f) for f in ob.Scenario.__dataclass_fields__},
                       "offset_bias": jnp.zeros(4)})
    with pytest.raises(InputError, match="noise_std"):
        eqx.tree_at(lambda sc: sc.noise_std, ob.paper_scenario(), jnp.zeros((2, 3))).__check_init__()
    with pytest.raises(InputError, match="num_runs"):
        ob.monte_carlo(ob.paper_scenario(), jax.random.key(0), 0)
    with pytest.raises(InputError, match="scenario"):
        ob.simulate_scans("paper", jax.random.key(0))


# ---------------------------------------------------------------------------------------------
# S1–S7: Monte Carlo


@pytest.fixture(scope="module")
def mc_big(scenario):
    return ob.monte_carlo(scenario, jax.random.key(MC_SEED), MC_RUNS, prior="big")


@pytest.fixture(scope="module")
def mc_twice(scenario):
    return ob.monte_carlo(scenario, jax.random.key(MC_SEED), MC_RUNS, prior="twice_truth")


def check_s1_to_s5(big, twice):
    az, el = np.asarray(big.azimuth_minus_yaw) / DEG, np.asarray(big.elevation) / DEG
    az2 = np.asarray(twice.azimuth_minus_yaw) / DEG
    gr, pr = np.asarray(big.gross_range), np.asarray(big.pitch_roll) / DEG
    for i in (0, 1):
        # S1 (Fig. 8c): OBEM < 0.5° at every k ≥ 100; AAM at k = 200, and every k ≥ 100 with P0 2× truth.
        assert az[1, i, 99:].max() < 0.5
        assert az[0, i, -1] < 0.5
        assert az2[0, i, 99:].max() < 0.5
        assert az2[1, i, 99:].max() < 0.5
        # S2 (Fig. 8b): OBEM's elevation beats AAM's.
        assert el[1, i, 149:].mean() / el[0, i, 149:].mean() < 0.8
        assert el[1, i, -1] < 0.4
        assert np.asarray(twice.elevation)[1, i, 149:].mean() < 0.8 * np.asarray(twice.elevation)[0, i, 149:].mean()
        # S3 (Fig. 8a): gross range.
        assert gr[1, i, -1] < gr[0, i, -1]
        assert gr[1, i, -1] < 300.0
        # S4 (Fig. 9): AAM pitch and roll do not converge.
        assert np.all(pr[i, :, -1] > 0.5)
    # S5 (Fig. 10): rectified radar-1 position, time-averaged over k ≥ 100.
    pos = np.asarray(big.position)[:, 99:, :].mean(axis=1)
    raw, obem, aam_all = pos[0], pos[1], pos[2]
    assert np.all(obem < aam_all)
    assert np.all(obem < raw)
    assert obem[2] < 0.5 * raw[2]


def test_s1_to_s5_monte_carlo(mc_big, mc_twice):
    assert mc_big.num_runs == MC_RUNS
    check_s1_to_s5(mc_big, mc_twice)
    # Regression reference (spec §4.6 [X], 100 runs, big P0): same regime, not paper numbers.
    el = np.asarray(mc_big.elevation)[:, :, -1] / DEG
    assert 0.5 < el[0, 0] < 2.0 and 0.1 < el[1, 0] < 0.4
    assert 800 < float(mc_big.gross_range[0, 0, -1]) < 1600


def test_s1_transients_not_asserted_before_k50(mc_big):
    # The spec warns the transients exceed 0.5° early: confirm the curves really do rise first.
    az = np.asarray(mc_big.azimuth_minus_yaw) / DEG
    assert az[:, :, :50].max() > 0.5


def test_s6_nees_on_linear_model_data(biased_track):
    _, inp = biased_track
    for model, n in (("obem", 8), ("aam", 14)):
        res = ob.linear_model_consistency(inp, jax.random.key(MC_SEED + 1), model, MC_RUNS)
        lo, hi = np.asarray(res.nees_bounds[-1])
        assert lo <= float(res.nees[-1]) <= hi
        lo, hi = np.asarray(res.anees_bounds)
        assert lo <= float(res.anees) <= hi
        assert float(res.fraction_nees_inside()) > 0.8


def test_s7_unequal_tilt_limits_obem(mc_big):
    tilt = ob.monte_carlo(ob.unequal_tilt_scenario(), jax.random.key(MC_SEED), MC_RUNS)
    el_tilt = np.asarray(tilt.elevation)[:, :, -1] / DEG
    assert np.all(el_tilt[1] > 1.0)
    # OBEM loses its elevation advantage: no better than AAM on either radar.
    assert np.all(el_tilt[1] > el_tilt[0])
    assert np.all(np.asarray(mc_big.elevation)[1, :, -1] / DEG < 0.4)


@pytest.mark.slow
def test_s1_to_s5_and_s7_monte_carlo_1000_runs(scenario):
    key = jax.random.key(12345)
    big = ob.monte_carlo(scenario, key, 1000, prior="big", chunk_size=250)
    twice = ob.monte_carlo(scenario, key, 1000, prior="twice_truth", chunk_size=250)
    check_s1_to_s5(big, twice)
    tilt = ob.monte_carlo(ob.unequal_tilt_scenario(), key, 1000, chunk_size=250)
    assert np.all(np.asarray(tilt.elevation)[1, :, -1] / DEG > 1.0)


def test_monte_carlo_runs_replay_and_padding(scenario, mc_big):
    # Run i is fold_in(key, i) alone; runs past num_runs in the padded block do not count.
    key = jax.random.key(MC_SEED)
    args = ob.RunArgs(scenario, ob.prior_cov("aam"), ob.prior_cov("obem"))
    runs = [ob.run_squared_errors(jax.random.fold_in(key, i), args) for i in range(3)]
    three = ob.monte_carlo(scenario, key, 3)  # one block of 4 runs, one padded
    for name in ("gross_range", "elevation", "azimuth_minus_yaw", "pitch_roll", "position"):
        total = sum(np.asarray(getattr(r, name)) for r in runs)
        np.testing.assert_allclose(np.asarray(getattr(three, name)) ** 2 * 3, total, rtol=1e-10)
    # The first 100 runs' sums are what mc_big's RMSE curves are made of.
    sums = jax.jit(jax.vmap(ob.run_squared_errors, in_axes=(0, None)))(
        jax.vmap(lambda i: jax.random.fold_in(key, i))(jnp.arange(MC_RUNS)), args)
    np.testing.assert_allclose(jnp.sqrt(jnp.sum(sums.elevation, axis=0) / MC_RUNS), mc_big.elevation, rtol=1e-12)


# ---------------------------------------------------------------------------------------------
# The reproduction table


def test_reproduce_rows_pass_and_figures_written(tmp_path):
    rows, figures = ob.reproduce(tmp_path)
    failed = [r for r in rows if not r.ok]
    assert not failed, failed
    assert_rows_match_c1ffaca("registration", rows)
    ids = {r.id for r in rows}
    assert {"V1", "V3", "V8", "V10", "V11", "V13", "V14", "S1", "S2", "S3", "S4", "S5", "S6", "S7"} <= ids
    assert len(figures) == 6
    for path in figures:
        assert path.endswith(".png")
        with open(path, "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"

"""Bearings-only TMA (Lindgren & Gong 1977): verification targets V1–V31 of specs/bearings-tma.md.

Exact identities (X) run on random or well-conditioned data with tight tolerances; golden values
(G) use the spec's reconstructed geometry R1/R2 at the spec's tolerance; Monte Carlo checks (M)
run N = 2000 vmapped runs with fixed keys and assert within the spec's stated bands (≈ 3 standard
errors of the spec's own estimate) or within bounds derived from the runs' standard error.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.applications import bearings_tma as bt
from jaxtrack.filters import KalmanFilter, run_filter
from jaxtrack.models import LinearGaussianModel
from jaxtrack.montecarlo import chi2_mean_bounds
from rows_baseline import assert_rows_match_c1ffaca

SIG = bt.AVERAGED_BEARING_STD


@pytest.fixture(scope="module")
def r1():
    return bt.geometry("R1")


@pytest.fixture(scope="module")
def r2():
    return bt.geometry("R2")


@pytest.fixture(scope="module")
def studies():
    """The Monte Carlo behind the table: R1 (configs A, B, C), R2, R3; 2000 runs each."""
    return bt.run_studies(2000, seed=0)


def table2(scenario, bearings, r0, sigma=SIG, inputs=None):
    inputs = scenario.observer_input if inputs is None else inputs
    return bt.normalized_pseudolinear_filter(bearings, inputs, scenario.sample_period, sigma, r0)


def ranges_of(scenario, est):
    return np.asarray(bt.track_solution(est.mean, scenario.observer[:, 2:]).range)


def golden_bearings(scenario):
    return scenario.bearings + bt.golden_bearing_noise(scenario.times.shape[0], SIG)


def phi(dt):
    return np.asarray(bt.transition_matrix(float(dt)))


# ---------------------------------------------------------------- model and measurement (V1–V4)


def test_v1_pseudolinear_measurement_identity():
    rng = np.random.default_rng(1)
    for _ in range(20):
        xt = rng.normal(0, 1e4, 4)
        xo = rng.normal(0, 1e4, 4)
        nu = rng.normal(0, 0.3)
        xr = xt - xo
        beta = math.atan2(xr[0], xr[1])
        rs = math.hypot(xr[0], xr[1])
        H = np.asarray(bt.measurement_row(beta + nu))
        z = H @ xo  # eq. (12)
        np.testing.assert_allclose(z - H @ xt, rs * math.sin(nu), atol=1e-12 * rs)  # eqs. (8), (10), (13)
        np.testing.assert_allclose(-H @ xr, rs * math.sin(nu), atol=1e-12 * rs)
        np.testing.assert_allclose(float(bt.cross_range_noise(rs, nu)), rs * math.sin(nu), rtol=1e-15)


def test_v2_bearing_convention_and_slant_range():
    assert float(bt.bearing(jnp.array([1.0, 0.0]))) == pytest.approx(math.pi / 2, abs=1e-15)  # due east
    assert float(bt.bearing(jnp.array([0.0, 1.0]))) == 0.0  # due north
    assert float(bt.bearing(jnp.array([-1.0, 0.0]))) == pytest.approx(-math.pi / 2)  # west (≡ 270°)
    rng = np.random.default_rng(2)
    r = rng.normal(0, 5e3, (50, 2))
    beta = np.asarray(bt.bearing(jnp.asarray(r)))
    # eq. (9): r_s = r_x sin β + r_y cos β = √(r_x² + r_y²)
    np.testing.assert_allclose(r[:, 0] * np.sin(beta) + r[:, 1] * np.cos(beta), np.hypot(r[:, 0], r[:, 1]), rtol=1e-13)
    assert float(bt.course(jnp.array([-1.0, 0.0]))) == pytest.approx(1.5 * math.pi)  # courses in [0, 2π)


def test_v3_cross_range_noise_moments():
    """E[η] = 0 and Var[η] = ½ r_s²(1 − e^{−2σ²}) (16a/b); at σ = 0.3 rad the approximation r_s²σ² is rejected."""
    n = 400_000
    nu = 0.3 * jax.random.normal(jax.random.key(3), (n,))
    eta = np.asarray(bt.cross_range_noise(1.0, nu))
    mean_se = eta.std() / math.sqrt(n)
    var_se = math.sqrt(np.var(eta**2) / n)
    exact = float(bt.cross_range_noise_variance(1.0, 0.3))
    assert exact == pytest.approx(0.5 * (1 - math.exp(-0.18)), rel=1e-14)
    assert exact == pytest.approx(0.0824, abs=5e-5)
    assert abs(eta.mean()) < 4 * mean_se
    assert abs(eta.var() - exact) < 4 * var_se
    assert abs(eta.var() - 0.09) > 20 * var_se  # the small-noise approximation of (16b) is measurably off


def test_v4_transition_semigroup_and_observer_propagation(r1):
    ts = 20.0
    for i, j, l in ((5, 2, 0), (3, 7, 1), (0, 4, 9)):
        np.testing.assert_allclose(phi((i - j) * ts) @ phi((j - l) * ts), phi((i - l) * ts), atol=1e-12)
        np.testing.assert_allclose(np.linalg.inv(phi((i - j) * ts)), phi((j - i) * ts), atol=1e-12)
    # eq. (3): x_O(k+1) = Φ x_O(k) + [0; I] ΔV_O(k) for point maneuvers at sample instants.
    xo = np.asarray(r1.observer)
    dv = np.concatenate([np.zeros((48, 2)), np.diff(xo[:, 2:], axis=0)], axis=1)
    np.testing.assert_allclose(xo[1:], xo[:-1] @ phi(ts).T + dv, atol=1e-9)
    np.testing.assert_allclose(xo[[0, 12, 24, 36, 48], :2],
                               [[0, 0], [1350.24, 0], [1350.24, 1350.24], [2700.48, 1350.24], [2700.48, 2700.48]], atol=1e-9)


# ------------------------------------------------------------ linear estimation theory (V5–V9)


def _spd(rng, n, scale=1.0):
    a = rng.normal(size=(n, n))
    return scale * (a @ a.T + n * np.eye(n))


@pytest.mark.parametrize("m", [2, 7])
def test_v5_matrix_inversion_lemmas(m):
    rng = np.random.default_rng(m)
    n = 4
    P, R, A = _spd(rng, n), _spd(rng, m, 0.3), rng.normal(size=(m, n))
    B_gain = bt.linear_estimator_matrix(P, A, R, form="gain")
    B_info = bt.linear_estimator_matrix(P, A, R, form="information")
    np.testing.assert_allclose(B_gain, B_info, rtol=1e-10, atol=1e-13)  # (B-1), eq. (30)
    np.testing.assert_allclose(B_gain, P @ A.T @ np.linalg.inv(R + A @ P @ A.T), rtol=1e-10)
    C_gain = bt.posterior_covariance(P, A, R, form="gain")
    C_info = bt.posterior_covariance(P, A, R, form="information")
    np.testing.assert_allclose(C_gain, C_info, rtol=1e-10, atol=1e-12)  # (B-2), eqs. (33), (34)
    with pytest.raises(InputError, match="form"):
        bt.linear_estimator_matrix(P, A, R, form="other")


def _synthetic(k=8, seed=0, sigma=0.1):
    """Well-conditioned unit-scale data: t_s = 1, σ = 0.1 (spec V6)."""
    rng = np.random.default_rng(seed)
    H = np.concatenate([rng.normal(size=(k, 2)), np.zeros((k, 2))], axis=1)
    H[:, 2:] = rng.normal(size=(k, 2)) * 0.5  # full rows so that k ≥ 4 is observable
    return rng.normal(size=4), H, rng.normal(size=k), sigma


def _stack(H, z, ts, k):
    """A(k) with rows H(i)Φ(i,k), i = k..1, and Z newest first (eqs. 17, 22) for general H rows."""
    A = np.stack([H[i - 1] @ phi((i - k) * ts) for i in range(k, 0, -1)])
    return A, z[:k][::-1]


def test_v6_kalman_recursion_equals_batch():
    m0, H, z, sigma = _synthetic()
    P0 = 1.0 * np.eye(4)
    est = bt.kalman_recursion(m0, P0, H, z, np.zeros((8, 4)), sigma**2, 1.0)
    for k in (1, 3, 8):
        A, Z = _stack(H, z, 1.0, k)
        batch = bt.batch_estimate(A, Z, sigma**2 * np.eye(k), m0, P0, phi(k))
        np.testing.assert_allclose(est.cov[k], batch.cov, rtol=1e-12, atol=1e-14)  # (34)/(55)
        np.testing.assert_allclose(est.mean[k], batch.mean, rtol=1e-12, atol=1e-13)  # (64)


def test_v6_batch_at_tma_scale(r1):
    """Target-state filter (66) on the golden R1 bearings vs the batch formulas: rtol 1e-4 (spec §3.5 item 6)."""
    bm = golden_bearings(r1)
    est = bt.target_state_filter(bm, r1.observer, r1.sample_period, SIG, 10_000.0)
    H = np.asarray(bt.measurement_row(bm[1:]))
    z = np.sum(H * np.asarray(r1.observer[1:]), axis=1)
    for k in (6, 20, 48):
        A, Z = _stack(H, z, 20.0, k)
        np.testing.assert_allclose(A, bt.stacked_measurement_matrix(H, 20.0, k), rtol=1e-14)
        batch = bt.batch_estimate(A, Z, SIG**2 * np.eye(k), est.mean[0], np.eye(4), phi(20.0 * k))
        np.testing.assert_allclose(est.mean[k], batch.mean, rtol=1e-4, atol=1e-4 * 1e4)


def test_v7_appendix_c_identities():
    m0, H, z, sigma = _synthetic(seed=4)
    P0 = 2.0 * np.eye(4)
    est = bt.kalman_recursion(m0, P0, H, z, np.zeros((8, 4)), sigma**2, 1.0)
    phis = np.asarray(bt.error_transition(est.gain, H, 1.0))
    P = np.asarray(est.cov)
    for k in (2, 5, 8):
        A, Z = _stack(H, z, 1.0, k)
        batch = bt.batch_estimate(A, Z, sigma**2 * np.eye(k), m0, P0, phi(k))
        pinv = np.asarray(batch.pseudo_inverse)
        # (C-2)/(C-14): φ(k,0) = [I − Ã#A] Φ(k,0)
        np.testing.assert_allclose(phis[k], (np.eye(4) - pinv @ A) @ phi(k), rtol=1e-11, atol=1e-12)
        total = np.zeros(4)
        for j in range(1, k + 1):
            phi_kj = phis[k] @ np.linalg.inv(phis[j])
            # (C-8): φ(k,j) = P(k|k) Φ'(j,k) P⁻¹(j|j);  (C-9): K(j) = P(j|j) H'(j)/σ²
            np.testing.assert_allclose(phi_kj, P[k] @ phi(j - k).T @ np.linalg.inv(P[j]), rtol=1e-9, atol=1e-11)
            np.testing.assert_allclose(est.gain[j - 1], P[j] @ H[j - 1] / sigma**2, rtol=1e-10, atol=1e-12)
            total += phi_kj @ np.asarray(est.gain[j - 1]) * z[j - 1]
        np.testing.assert_allclose(total, pinv @ Z, rtol=1e-10, atol=1e-12)  # (C-11)
        # (63a): x̂(k|k) = φ(k,0) x̂(0|0) + Σ φ(k,j) K(j) z(j)
        np.testing.assert_allclose(est.mean[k], phis[k] @ m0 + total, rtol=1e-10, atol=1e-12)


def test_v8_observable_case_and_least_squares_limit():
    m0, H, z, sigma = _synthetic(seed=5)
    k = 8
    A, Z = _stack(H, z, 1.0, k)
    R = sigma**2 * np.eye(k)
    ls = bt.least_squares_estimate(A, Z, R)
    x_ls, P_ls = np.asarray(ls.mean), np.asarray(ls.cov)
    np.testing.assert_allclose(P_ls, np.linalg.inv(A.T @ A / sigma**2), rtol=1e-10)
    a_sharp = P_ls @ A.T / sigma**2
    Pk = phi(k) @ phi(k).T
    gaps = []
    for s0sq in (0.5, 4.0, 1e2, 1e4):
        batch = bt.batch_estimate(A, Z, R, m0, s0sq * np.eye(4), phi(k))
        corr = P_ls @ np.linalg.inv(Pk + P_ls / s0sq) / s0sq
        np.testing.assert_allclose(batch.pseudo_inverse, a_sharp - corr @ a_sharp, rtol=1e-9, atol=1e-11)  # (61)
        np.testing.assert_allclose(batch.mean, x_ls - corr @ (x_ls - phi(k) @ m0), rtol=1e-9, atol=1e-11)  # (65)
        gaps.append(np.linalg.norm(np.asarray(batch.mean) - x_ls))
    assert gaps[-1] < 1e-3 * gaps[0] and gaps[-1] < 1e-5  # σ₀ → ∞: the estimate tends to x̂_LS


def test_v9_minimum_norm_limit_is_in_x0_metric():
    """Underdetermined (k = 3 < 4): x̂(k|k) from x̂(0|0) = 0 tends to Φ(k,0)[AΦ(k,0)]#Z, not A#Z (A15)."""
    _, H, z, sigma = _synthetic(k=3, seed=6)
    k = 3
    A, Z = _stack(H, z, 1.0, k)
    target = np.asarray(bt.minimum_norm_estimate(A, Z, phi(k)))
    gaps = []
    for s0sq in (1e2, 1e4, 1e6):
        est = bt.kalman_recursion(np.zeros(4), s0sq * np.eye(4), H, z, np.zeros((k, 4)), sigma**2, 1.0)
        gaps.append(np.linalg.norm(np.asarray(est.mean[k]) - target))
    assert gaps[1] < 0.02 * gaps[0] and gaps[2] < 0.02 * gaps[1]  # O(1/σ₀²) convergence
    assert gaps[2] < 1e-6 * np.linalg.norm(target)
    assert np.linalg.norm(np.linalg.pinv(A) @ Z - target) > 0.1 * np.linalg.norm(target)


# ----------------------------------------------------------------- observability (V10, V11)


def test_v10_observability_rank_and_null_vector(r1):
    H = bt.measurement_row(r1.bearings[1:])
    xr = np.asarray(r1.relative)
    for k in range(3, 13):
        A = bt.stacked_measurement_matrix(H, r1.sample_period, k)
        assert bt.observability(A).rank() == 3
        if k <= 11:  # the true relative state spans the null space on leg 1
            assert np.linalg.norm(np.asarray(A) @ xr[k]) < 1e-9 * np.linalg.norm(xr[k])
    A12 = np.asarray(bt.stacked_measurement_matrix(H, r1.sample_period, 12))
    null12 = np.concatenate([xr[12, :2], xr[11, 2:]])  # x_R(12) already has the post-maneuver velocity
    assert np.linalg.norm(A12 @ null12) < 1e-9 * np.linalg.norm(null12)
    assert np.linalg.norm(A12 @ xr[12]) > 0.1 * np.linalg.norm(xr[12])
    sv = np.asarray(bt.observability(A12).singular_values)
    assert np.all(np.abs(sv[:3] - [449.73, 12.43, 1.327]) <= [0.005, 0.005, 0.0005])
    assert sv[3] < 1e-12 * sv[0]
    for k in (13, 18, 24, 30, 36, 48):
        assert bt.observability(bt.stacked_measurement_matrix(H, r1.sample_period, k)).rank() == 4
    for k, smallest in ((13, 0.0101), (24, 0.0253)):
        sv = np.asarray(bt.observability(bt.stacked_measurement_matrix(H, r1.sample_period, k)).singular_values)
        assert sv[-1] == pytest.approx(smallest, abs=5e-5)
    # Zero bearing rate: R3's first leg runs down the line of sight, rank 2.
    r3 = bt.geometry("R3")
    A = bt.stacked_measurement_matrix(bt.measurement_row(r3.bearings[1:]), r3.sample_period, 12)
    assert bt.observability(A).rank(rtol=1e-6) == 2


def test_v11_scale_invariance_of_bearings():
    """(A-9): for a constant-velocity observer the bearings of c·x_R(0) do not depend on c > 0."""
    path = bt.ObserverPath((math.radians(90.0),), leg_duration=960.0)
    vo = np.array([bt.SPEED, 0.0])
    xr0 = np.array([10_000.0, 0.0, -5.626, 5.626])
    sequences = []
    for c in (0.3, 1.0, 2.5, 7.0):
        vt = vo + c * xr0[2:]
        s = bt.make_scenario(path, c * xr0[:2], math.atan2(vt[0], vt[1]), float(np.hypot(*vt)))
        sequences.append(np.asarray(s.bearings))
    for seq in sequences[1:]:
        np.testing.assert_allclose(seq, sequences[0], rtol=0, atol=1e-13)
    assert np.ptp(sequences[0]) > 0.1  # nonzero bearing rate


# ------------------------------------------------------- Table 2 structure (V12–V18)


def test_v12_gain_and_covariance_independent_of_range_and_input(r1):
    bm = bt.noisy_bearings(r1, jax.random.key(12), SIG)
    runs = [
        table2(r1, bm, r0, inputs=u)
        for r0 in (0.0, 5000.0, 20_000.0)
        for u in (r1.observer_input, r1.naive_observer_input, jnp.zeros((48, 4)))
    ]
    for est in runs[1:]:
        np.testing.assert_allclose(est.gain, runs[0].gain, rtol=1e-15, atol=0)
        np.testing.assert_allclose(est.cov, runs[0].cov, rtol=1e-15, atol=0)


def test_v13_leg1_estimate_is_exactly_proportional_to_initial_range(r1):
    """Spec §3.5 item 2: for any noise, x̂_R(k|k; a r̂) = a x̂_R(k|k; r̂) before the first maneuver."""
    km = bt.first_maneuver_index(r1)
    assert km == 12
    for seed in range(3):
        bm = bt.noisy_bearings(r1, jax.random.key(seed), SIG)
        base = np.asarray(table2(r1, bm, 5000.0).mean)
        for a in (0.5, 3.0):
            scaled = np.asarray(table2(r1, bm, a * 5000.0).mean)
            np.testing.assert_allclose(scaled[:km], a * base[:km], rtol=1e-12, atol=1e-9)
            np.testing.assert_allclose(scaled[km, :2], a * base[km, :2], rtol=1e-12)  # position still scales at k_m
        zero = np.asarray(table2(r1, bm, 0.0).mean)
        np.testing.assert_array_equal(zero[:km], 0.0)  # the minimum-norm solution, exactly
        np.testing.assert_array_equal(zero[km, :2], 0.0)
        np.testing.assert_allclose(zero[km, 2:], -np.asarray(r1.observer_input[km - 1, 2:]), rtol=1e-15)  # −ΔV_O(11)


def test_v14_initial_range_derivative_autodiff_vs_analytic(r1):
    bm = golden_bearings(r1)
    r0 = 10_000.0
    est = table2(r1, bm, r0)
    b = np.asarray(bt.initial_range_sensitivity(bm, est.gain, r1.sample_period))
    jac = np.asarray(jax.jacfwd(lambda r: table2(r1, bm, r).mean)(jnp.asarray(r0)))
    np.testing.assert_allclose(jac, b, rtol=1e-10, atol=1e-14)
    rev = np.asarray(jax.jacrev(lambda r: table2(r1, bm, r).mean[48])(jnp.asarray(r0)))
    np.testing.assert_allclose(rev, b[48], rtol=1e-10, atol=1e-14)
    # Affine: the finite difference over the whole interval [0, r̂] is the same slope.
    fd = (np.asarray(est.mean) - np.asarray(table2(r1, bm, 0.0).mean)) / r0
    np.testing.assert_allclose(fd, b, rtol=1e-8, atol=1e-12)
    # Noise-free leg 1: b_k is the range-normalised true state x_R(k)/r_s(0) to ~1e-4.
    b_nf = np.asarray(bt.initial_range_sensitivity(r1.bearings, table2(r1, r1.bearings, r0).gain, r1.sample_period))
    xr = np.asarray(r1.relative)
    np.testing.assert_allclose(b_nf[3:12, :2], xr[3:12, :2] / 10_000.0, rtol=2e-4)


def test_v15_table1_target_state_and_library_kalman_filter(r1):
    bm = bt.noisy_bearings(r1, jax.random.key(15), SIG)
    rs0 = float(r1.slant_range[0])
    t2 = table2(r1, bm, rs0)
    t1 = bt.relative_state_filter(bm, r1.observer_input, r1.sample_period, SIG, rs0, jnp.full(49, rs0), rs0**2)
    # Equal in exact arithmetic; Table 1 scales P and R by r_s(0)² = 1e8 in a recursion whose
    # condition number is about 1e7, so the two differ by rounding: 3.9e-6 m on positions of
    # 2.6 km (2.2e-9 relative) with the library update, 1.7e-6 m with the study's former private
    # recursion. The tolerance bounds that rounding, not a modelling difference.
    np.testing.assert_allclose(t1.mean, t2.mean, rtol=1e-9, atol=1e-5)
    np.testing.assert_allclose(t1.cov, rs0**2 * np.asarray(t2.cov), rtol=1e-8, atol=1e-11 * rs0**2)  # 1.4e-4 of 1e8
    tt = bt.target_state_filter(bm, r1.observer, r1.sample_period, SIG, rs0)
    np.testing.assert_allclose(np.asarray(tt.mean) - np.asarray(r1.observer), t2.mean, rtol=0, atol=1e-6)  # Fig. 3
    np.testing.assert_allclose(tt.cov, t2.cov, rtol=1e-9, atol=1e-18)
    # Table 1 with the true range against the library's Kalman filter (independent code path).
    rs = r1.slant_range
    t1_true = bt.relative_state_filter(bm, r1.observer_input, r1.sample_period, SIG, rs0, rs, rs0**2)
    H = bt.measurement_row(bm[1:])[:, None, :]
    model = LinearGaussianModel(
        bt.transition_matrix(20.0), jnp.zeros((4, 4)), H, (rs[1:] ** 2 * SIG**2)[:, None, None],
        t1_true.mean[0], rs0**2 * jnp.eye(4), transition_offset=-r1.observer_input,
    )
    kf = run_filter(KalmanFilter(), model, jnp.zeros((48, 1)), first_step="predict")
    np.testing.assert_allclose(kf.filtered_mean, t1_true.mean[1:], rtol=1e-7, atol=1e-5)


def test_v16_cross_range_residual():
    rng = np.random.default_rng(16)
    x = rng.normal(0, 5e3, (30, 4))
    bm = rng.uniform(-math.pi, math.pi, 30)
    H = np.asarray(bt.measurement_row(bm))
    r_hat = np.hypot(x[:, 0], x[:, 1])
    beta_hat = np.arctan2(x[:, 0], x[:, 1])
    np.testing.assert_allclose(np.sum(H * x, axis=1), -r_hat * np.sin(bm - beta_hat), rtol=1e-12, atol=1e-9)  # (72)


def test_v17_ekf_jacobian_equals_autodiff():
    model = bt.RelativeBearingModel(jnp.zeros((3, 4)), jnp.asarray(20.0), jnp.asarray(SIG**2), jnp.ones(4), jnp.eye(4))
    rng = np.random.default_rng(17)
    for x in rng.normal(0, 5e3, (10, 4)):
        x = jnp.asarray(x)
        analytic = model.measurement_jacobian(x, 0)  # (D-9)–(D-12)
        auto = jax.jacfwd(model.measurement)(x, 0)
        np.testing.assert_allclose(analytic, auto, rtol=1e-13, atol=1e-18)
        # [EXT]: the EKF H is the pseudo-linear H at the predicted bearing divided by r̂.
        r = float(jnp.hypot(x[0], x[1]))
        np.testing.assert_allclose(analytic[0], bt.measurement_row(bt.bearing(x)) / r, rtol=1e-13, atol=1e-18)


def test_v18_general_observer_input(r1, r2):
    xr = np.asarray(r2.relative)
    f = phi(20.0)
    np.testing.assert_allclose(xr[1:], xr[:-1] @ f.T - np.asarray(r2.observer_input), rtol=0, atol=1e-9)
    naive_gap = np.abs(xr[1:] - (xr[:-1] @ f.T - np.asarray(r2.naive_observer_input))).max(axis=1)
    assert naive_gap.max() > 10.0  # a 3°/s turn moves the observer tens of metres off the naive prediction
    assert np.flatnonzero(naive_gap > 1e-6).tolist() == [12, 13, 24, 25, 36, 37]  # the 30-s turns only
    np.testing.assert_array_equal(r1.observer_input, r1.naive_observer_input)  # point maneuvers: [0; ΔV_O]
    # The generic form from sampled states agrees to round-off.
    np.testing.assert_allclose(bt.observer_input(r2.observer, r2.sample_period), r2.observer_input, atol=1e-9)
    np.testing.assert_allclose(r1.relative[1:], r1.relative[:-1] @ f.T - r1.observer_input, atol=1e-9)


# ------------------------------------------------------------ noise-free and golden (V19–V23)


def test_v19_noise_free_leg1_scaled_solution(r1):
    est5 = table2(r1, r1.bearings, 5000.0)
    ratio = np.asarray(est5.mean[:, :2] / r1.relative[:, :2])
    np.testing.assert_allclose(ratio[[6, 12]], 0.5, atol=1e-6)
    rng5 = ranges_of(r1, est5)
    rng20 = ranges_of(r1, table2(r1, r1.bearings, 20_000.0))
    np.testing.assert_allclose(rng5[[6, 12]], [4674.6, 4377.3], atol=0.2)
    np.testing.assert_allclose(rng20[[6, 12]], [18698.6, 17509.0], atol=0.2)


def test_v20_correct_initial_range_recovers_truth(r1, r2):
    """r̂_s(0) = r_s(0): the estimate equals the truth within 0.5 m — from k = 3 on.

    The spec says "at all k"; at k = 1 and 2 the error is 111 m and 178 m, because fewer than three
    bearings cannot yet correct the zero-relative-velocity start (rank A(k) = k < 3).
    """
    for scenario, tol in ((r1, 0.5), (r2, 0.05)):
        err = np.abs(np.asarray(table2(scenario, scenario.bearings, 10_000.0).mean - scenario.relative))
        assert err[3:, :2].max() < tol
        rng_err = np.abs(ranges_of(scenario, table2(scenario, scenario.bearings, 10_000.0)) - np.asarray(scenario.slant_range))
        assert rng_err[3:].max() < tol
    early = np.abs(np.asarray(table2(r1, r1.bearings, 10_000.0).mean - r1.relative))[1:3, 0]
    np.testing.assert_allclose(early, [111.2, 178.3], atol=0.1)


def test_v21_noise_free_convergence_after_maneuver(r1):
    k = [13, 14, 15, 18, 24, 48]
    for r0, expected in ((0.0, [8406.4, 8652.4, 8706.3, 8742.1, 8753.7, 7782.2]),
                         (20_000.0, [9102.6, 8856.7, 8802.7, 8767.0, 8755.3, 7783.9])):
        np.testing.assert_allclose(ranges_of(r1, table2(r1, r1.bearings, r0))[k], expected, atol=0.2)
    np.testing.assert_allclose(np.asarray(r1.slant_range)[k], [8754.5] * 5 + [7783.0], atol=0.05)
    wide = ranges_of(r1, table2(r1, r1.bearings, 0.0, sigma=bt.RAW_BEARING_STD))
    np.testing.assert_allclose(wide[[13, 15, 24, 48]], [4622.6, 7861.2, 8738.4, 7766.0], atol=0.2)


def test_v22_turning_observer_with_general_input(r2):
    truth = np.asarray(r2.slant_range)
    err = {r0: ranges_of(r2, table2(r2, r2.bearings, r0)) - truth for r0 in (0.0, 10_000.0, 20_000.0)}
    assert np.abs(err[10_000.0][3:]).max() < 0.05
    # Affine in r̂0 and exact for r̂0 = r_s(0) (k ≥ 3, see V20) → antisymmetric range errors.
    np.testing.assert_allclose(err[0.0][3:], -err[20_000.0][3:], rtol=0, atol=0.1)
    k = [12, 24, 36, 48]
    assert np.all(np.abs(err[0.0][k] - [-8754.5, -2.0, -1.25, -0.89]) <= [0.05, 0.05, 0.005, 0.005])
    # k = 13 (mid-turn) and 15: 1697.8 / 78.9 in the spec, from a numerically integrated turn; the
    # value at k = 13 moves 1.5 m per 3 cm of observer position (see the next lines), and
    # jaxtrack integrates the arcs exactly, so the tolerance is 0.1%.
    np.testing.assert_allclose(err[0.0][[13, 15]], [-1697.8, -78.9], rtol=1e-3)
    shifted_states = np.asarray(r2.observer).copy()
    shifted_states[13, 1] += 0.03  # 3 cm across the line of sight
    shifted = eqx.tree_at(lambda s: s.observer, r2, jnp.asarray(shifted_states))
    u = bt.observer_input(shifted.observer, shifted.sample_period)
    moved = ranges_of(shifted, table2(shifted, shifted.bearings, 0.0, inputs=u))[13] - float(shifted.slant_range[13])
    assert abs(moved - err[0.0][13]) > 1.0  # measured 1.5 m
    # The naive input [0; ΔV_O] ignores the turn displacement: +1878.7 m at 480 s, ~7 km worst.
    naive = ranges_of(r2, table2(r2, r2.bearings, 10_000.0, inputs=r2.naive_observer_input)) - truth
    assert naive[24] == pytest.approx(1878.7, rel=1e-3)
    assert 6000 < np.abs(naive).max() < 8000


GOLDEN_10K = {12: [806.662, 125.9305, 5.0596, -5.1034], 13: [6353.0937, 979.5095, -0.4090, -1.4632],
              24: [8061.9452, 1257.8981, -6.8607, 5.4109], 36: [7291.1819, 2694.9840, 0.0499, -0.0052],
              48: [7267.8916, 2688.7787, -0.0121, -0.0126]}
GOLDEN_0 = {12: [0.0, 0.0, 5.626, -5.626], 13: [6039.5284, 927.6770, -0.3264, -1.6638],
            24: [8061.0539, 1257.6529, -6.8558, 5.4107], 48: [7267.1163, 2688.4194, -0.0114, -0.0129]}
GOLDEN_EKF = {12: [10966.1505, 1702.0765, 1.1308, 1.5770], 24: [9185.5453, 1440.2903, -4.7246, 5.8231],
              48: [7330.6317, 2715.5135, -0.0281, 0.0132]}


def test_v23_golden_noisy_run(r1):
    """Tolerance 1e-3 m / 1e-6 m/s (spec), or half the last printed digit where that is coarser."""
    bm = golden_bearings(r1)
    atol = np.array([1e-3, 1e-3, 5e-5, 5e-5])
    for r0, golden in ((10_000.0, GOLDEN_10K), (0.0, GOLDEN_0)):
        est = table2(r1, bm, r0)
        for k, expected in golden.items():
            assert np.all(np.abs(np.asarray(est.mean[k]) - expected) <= atol), (r0, k, est.mean[k])
    est = table2(r1, bm, 10_000.0)
    sol = bt.track_solution(est.mean, r1.observer[:, 2:])
    np.testing.assert_allclose(np.asarray(sol.range)[[12, 13, 24, 36, 48]],
                               [816.4325, 6428.1598, 8159.4895, 7773.3051, 7749.3083], atol=1e-3)
    np.testing.assert_allclose(np.degrees(np.asarray(sol.course)[[24, 48]]), [347.1459, 359.8764], atol=5e-5)
    np.testing.assert_allclose(np.asarray(sol.speed)[[24, 48]], [5.54999, 5.61339], atol=5e-6)
    diag = np.diag(np.asarray(est.cov[48]))
    np.testing.assert_allclose(diag[:2], [1.14e-4, 1.8e-5], rtol=0.005 / 1.14 + 1e-9, atol=0.05e-5)
    assert diag[2:].max() < 1e-9  # "~0"
    m0, P0 = bt.ekf_prior(bm[0], 10_000.0, r1.observer[0, 2:])
    np.testing.assert_allclose(P0, np.diag([5000.0**2, 5000.0**2, 100.0, 100.0]), rtol=1e-15)
    ekf = bt.bearing_ekf(bm, r1.observer_input, r1.sample_period, SIG, m0, P0)
    for k, expected in GOLDEN_EKF.items():
        assert np.all(np.abs(np.asarray(ekf.mean[k]) - expected) <= atol), (k, ekf.mean[k])


# ------------------------------------------------------ Monte Carlo and the report's findings


def test_v24_leg1_collapse_factor(studies, r1):
    for cfg, expected in (("A", 0.122), ("B", 0.639), ("C", 0.110)):
        assert bt.leg1_collapse_factor(studies[f"R1-{cfg}"]) == pytest.approx(expected, abs=0.01)
    nf = ranges_of(r1, table2(r1, r1.bearings, 10_000.0))[12] / 10_000.0
    assert nf == pytest.approx(0.8755, abs=5e-5)


def test_finding_initial_range_stops_mattering_after_first_maneuver(studies):
    """Fig. 5c / V25 / spec §3.5 item 4: same noise, r̂0 = 10 km vs 0; and the analytic slope ‖b_k‖."""
    a = studies["R1-A"]
    diff = {t: bt.initial_range_difference(a, t) for t in (240, 260, 300, 360, 480)}
    assert diff[240] >= 500 and diff[300] <= 100 and diff[480] <= 5  # V25 bounds
    for t, spec in ((240, 1079), (260, 264), (300, 46), (360, 12), (480, 0.7)):
        assert diff[t] == pytest.approx(spec, rel=0.1)  # the spec's 500-run medians
    x = np.asarray(a.mc.plkf_mean)
    ranges = list(np.asarray(a.mc.initial_ranges))
    slope = (x[:, ranges.index(10_000.0)] - x[:, ranges.index(0.0)]) / 10_000.0  # b_k, exact by V14
    med = {t: float(np.median(np.hypot(slope[:, t // 20, 0], slope[:, t // 20, 1]))) for t in (240, 260, 300, 360, 480)}
    for t, spec in ((240, 0.108), (260, 0.026), (300, 0.0046), (360, 0.0012)):
        assert med[t] == pytest.approx(spec, rel=0.1)
    assert med[480] < 1.5e-4
    # After convergence the initialisation is irrelevant: rms range at 960 s within 2 m (V27).
    k = bt.sample_index(a.scenario, 960.0)
    assert abs(a.plkf.rms_range[ranges.index(10_000.0), k] - a.plkf.rms_range[ranges.index(0.0), k]) < 2.0


def test_finding_first_leg_scales_with_range_guess(studies, r1):
    """Fig. 5b: noise-free the leg-1 solution is the true track scaled by r̂0/r_s(0); with noise it
    is still proportional to r̂0 (V13) but collapses toward the minimum-norm solution unless the
    filter σ is conservative (config B) — A20."""
    for r0 in (5000.0, 20_000.0):
        est = table2(r1, r1.bearings, r0)
        np.testing.assert_allclose(est.mean[3:12, :2], r0 / 10_000.0 * r1.relative[3:12, :2], rtol=2e-4)
    a, b = bt.leg1_collapse_factor(studies["R1-A"]), bt.leg1_collapse_factor(studies["R1-B"])
    assert a < 0.2 < 0.5 < b


def test_v26_line_of_sight_velocity_variance(r1):
    est = table2(r1, r1.bearings, 10_000.0)
    along, across = bt.los_velocity_variances(r1, est.cov)
    np.testing.assert_allclose(along[[13, 24, 25, 36]], [3.15e-8, 2.67e-8, 2.26e-8, 3.07e-10], rtol=0.005)
    np.testing.assert_allclose(across[[13, 24]], [1.43e-8, 4.6e-11], rtol=0.01)
    assert 0.8 < along[24] / along[13] < 0.9  # −15%: no improvement along the LOS on the parallel leg 2
    assert 250 < across[13] / across[24] < 350  # cross-LOS variance falls ~300×
    assert 60 < along[25] / along[36] < 90  # LOS variance falls ~75× during leg 3


def test_v27_v28_convergence_and_bias(studies):
    a, c = studies["R1-A"], studies["R1-C"]
    k = bt.sample_index(a.scenario, 960.0)
    rms_range, rms_course, rms_speed = a.plkf.rms_range[0, k], a.plkf.rms_course[0, k], a.plkf.rms_speed[0, k]
    assert rms_range == pytest.approx(106.0, rel=0.1)
    assert rms_course == pytest.approx(1.0, abs=0.15)
    assert rms_speed == pytest.approx(0.042, rel=0.1)
    assert rms_range / float(a.scenario.slant_range[k]) == pytest.approx(0.014, abs=0.002)
    # V28: a biased (range-underestimating) estimator; bias grows roughly with σ².
    mean_a, sem_a = a.plkf.mean_range[0, k], a.plkf.range_sem[0, k]
    mean_c, sem_c = c.plkf.mean_range[0, k], c.plkf.range_sem[0, k]
    assert mean_a == pytest.approx(-44.0, abs=8.0) and mean_a < -3 * sem_a
    assert mean_c == pytest.approx(-732.0, abs=55.0) and mean_c < -3 * sem_c
    # Consistency (2-dof position NEES with P = r̂² P_N): near 2 but above the 95% bound (the bias).
    lo, hi = chi2_mean_bounds(2, a.mc.num_runs)
    anees = float(np.mean(np.asarray(a.mc.plkf_position_nees[:, 0, k])))
    assert hi < anees < 3.5


def test_v29_and_finding_ekf_course_error_and_partial_divergence_on_leg2(studies):
    """Fig. 6: the EKF shows substantial course error and partial divergence of the range solution on
    leg 2 of geometry 1 (parallel run), corrected after the leg-3 maneuver."""
    a = studies["R1-A"]
    ekf, plkf = a.ekf, a.plkf
    ie = list(np.asarray(a.mc.ekf_initial_ranges)).index(5000.0)
    ip = list(np.asarray(a.mc.initial_ranges)).index(5000.0)
    k = {t: bt.sample_index(a.scenario, t) for t in (360, 480, 600, 960)}
    assert ekf.rms_course[ie, k[480]] == pytest.approx(34.0, rel=0.15)
    assert plkf.rms_course[ip, k[480]] == pytest.approx(18.0, rel=0.15)
    assert ekf.rms_course[ie, k[480]] > 1.5 * plkf.rms_course[ip, k[480]]
    assert ekf.rms_course[ie, k[600]] < 10.0 and plkf.rms_course[ip, k[600]] < 10.0
    # Partial divergence: during leg 2 the EKF's range overshoots and drifts away (+ ~900 m from
    # 360 s to 480 s, mean error ~ +1475 m), the PLKF's does not.
    assert ekf.mean_range[ie, k[480]] == pytest.approx(1475.0, rel=0.15)
    assert ekf.mean_range[ie, k[480]] - ekf.mean_range[ie, k[360]] > 500.0
    assert abs(plkf.mean_range[ip, k[480]] - plkf.mean_range[ip, k[360]]) < 250.0
    assert ekf.rms_range[ie, k[480]] > 1.3 * ekf.rms_range[ie, k[360]]
    assert ekf.rms_range[ie, k[480]] > 2 * plkf.rms_range[ip, k[480]]
    # Corrected after the leg-3 maneuver.
    assert abs(ekf.mean_range[ie, k[600]]) < 300.0 and ekf.rms_course[ie, k[960]] < 5.0


def test_finding_ekf_covariance_collapse_on_geometry2(studies):
    """Fig. 7: on geometry 2 the EKF's covariance collapses prematurely (its σ is far below its
    actual error) and runs diverge; the pseudo-linear filter has neither."""
    g2 = studies["R2-A"]
    ie = list(np.asarray(g2.mc.ekf_initial_ranges)).index(5000.0)
    k = bt.sample_index(g2.scenario, 960.0)
    ekf_over = bt.overconfident_fraction(g2, "ekf")  # |range error| > 5 own σ at 960 s
    plkf_over = bt.overconfident_fraction(g2, "plkf")
    assert np.all(plkf_over == 0.0)
    assert ekf_over[ie] > 0.02  # measured 5.5% (a consistent filter: 6e-7)
    assert np.all(ekf_over > 0.0)
    own_sigma = np.median(np.asarray(g2.mc.ekf_range_std[:, ie, k]))
    assert g2.ekf.rms_range[ie, k] > 2.5 * own_sigma  # actual error ≫ the EKF's own σ
    plkf_sigma = np.median(np.asarray(g2.mc.plkf_range_std[:, 0, k]))
    assert g2.plkf.rms_range[0, k] < 1.3 * plkf_sigma
    lo, hi = chi2_mean_bounds(2, g2.mc.num_runs)
    assert float(np.mean(np.asarray(g2.mc.ekf_position_nees[:, ie, k]))) > 20 * hi
    assert np.all(bt.divergence_fraction(g2, "plkf") == 0.0)  # spec: 0 of 1000 runs on R2/R3
    assert np.all(bt.divergence_fraction(studies["R3-A"], "plkf") == 0.0)
    assert bt.divergence_fraction(g2, "ekf").max() > 0.0


def test_v30_float64_default_and_float32_failure(r1):
    keys = jax.random.split(jax.random.key(30), 100)
    bms = jax.vmap(lambda key: bt.noisy_bearings(r1, key, SIG))(keys)
    run = jax.vmap(lambda bm: table2(r1, bm, 10_000.0))
    est64 = run(bms)
    assert est64.mean.dtype == jnp.float64 and est64.cov.dtype == jnp.float64
    assert np.linalg.eigvalsh(np.asarray(est64.cov)).min() > -1e-12  # P_N stays PSD over 100 seeds
    # Spec §3.5 item 6: the same recursion in float32 (first 50 seeds) loses P_N's definiteness and
    # errs by hundreds of km.
    f32 = jnp.float32
    est32 = jax.vmap(lambda bm: bt.normalized_pseudolinear_filter(
        bm, r1.observer_input.astype(f32), r1.sample_period.astype(f32), jnp.asarray(SIG, f32), jnp.asarray(10_000.0, f32)
    ))(bms[:50].astype(f32))
    assert est32.mean.dtype == f32
    # The library update factors S = H P H' + σ² (Cholesky): a run whose P_N turned so indefinite
    # that S < 0 continues as NaN (the filter's ok = False) rather than with a finite, meaningless
    # P_N. Definiteness and errors are therefore judged on each run's finite samples only.
    cov32 = np.asarray(est32.cov, np.float64)
    finite = np.isfinite(cov32).all(axis=(-2, -1))
    eig_min = np.linalg.eigvalsh(np.where(finite[..., None, None], cov32, 0.0))[..., 0]
    indefinite = (finite & (eig_min < 0)).any(axis=1)
    err = np.nanmax(np.abs(np.asarray(est32.mean, np.float64)[..., :2] - np.asarray(est64.mean[:50, :, :2])), axis=(1, 2))
    # Measured with this key: 15 of 50 indefinite, all of which then turn NaN (spec: 20; the
    # report's own recursion, dividing by S, gave 30), 19 runs off by > 1 km, worst 32 km
    # (spec: 850 km; over other keys 34 km … 3700 km, the tail is heavy).
    assert indefinite.sum() >= 15
    assert (err > 1e3).sum() >= 15 and err.max() > 1e4


def test_v31_report_constants(r1, r2):
    assert bt.SPEED == 5.626 and bt.LEG_DURATION == 240.0 and bt.NUM_LEGS == 4
    assert math.degrees(bt.RAW_BEARING_STD) == pytest.approx(0.5) and bt.NUM_AVERAGED == 20
    assert math.degrees(bt.TURN_RATE) == pytest.approx(3.0)
    assert r1.times.shape == (49,) and float(r1.times[-1]) == 960.0
    speed = np.hypot(np.asarray(r2.observer[:, 2]), np.asarray(r2.observer[:, 3]))
    np.testing.assert_allclose(speed, bt.SPEED, rtol=1e-14)
    courses = np.degrees(np.asarray(bt.course(r1.observer[[0, 12, 24, 36], 2:])))
    np.testing.assert_allclose(courses, [90.0, 0.0, 90.0, 0.0], atol=1e-12)
    fine = bt.geometry_spec("R2").path.state_at(np.arange(230.0, 280.0, 0.5))
    c = np.degrees(np.arctan2(fine[:, 2], fine[:, 3]))
    assert np.flatnonzero(np.abs(np.diff(c)) > 1e-9)[[0, -1]].tolist() == [20, 79]  # turning 240–270 s
    # A3: pre-averaging twenty 1-s bearings of σ 0.5° gives σ ≈ 0.5°/√20 around the true bearing.
    bm = jax.vmap(lambda key: bt.noisy_bearings(r1, key, bt.RAW_BEARING_STD, preaverage=True))(
        jax.random.split(jax.random.key(31), 4000))
    # The window mean of the true bearings is what the average estimates (a 20-s window smears a
    # moving bearing: ~1σ at the maneuver samples, where the bearing rate jumps).
    smear = np.asarray(r1.window_bearings).mean(axis=1) - np.asarray(r1.bearings)
    assert abs(smear[12]) > 0.5 * SIG and np.abs(np.delete(smear, [12, 24, 36])).max() < 0.01 * SIG
    resid = np.asarray(bm - r1.bearings[None, :]) - smear[None, :]
    assert resid.std() == pytest.approx(SIG, rel=0.02)  # 4000 × 49 draws: SE of the std ≈ 0.16%
    assert abs(resid.mean()) < 4 * SIG / math.sqrt(resid.size)


# ------------------------------------------------------------------- errors, CLI, slow sizes


def test_bad_input_raises(r1):
    with pytest.raises(InputError, match="R1"):
        bt.geometry("G7")
    with pytest.raises(InputError, match="observer_input"):
        bt.normalized_pseudolinear_filter(r1.bearings, r1.observer_input[:-1], 20.0, SIG, 1e4)
    with pytest.raises(InputError, match="finite"):
        bt.normalized_pseudolinear_filter(r1.bearings.at[3].set(jnp.nan), r1.observer_input, 20.0, SIG, 1e4)
    with pytest.raises(InputError, match="nonzero initial range"):
        m0, P0 = bt.ekf_prior(r1.bearings[0], 0.0, r1.observer[0, 2:], position_std=1.0)
        bt.bearing_ekf(r1.bearings, r1.observer_input, 20.0, SIG, m0, P0)
    with pytest.raises(InputError, match="positive"):
        bt.monte_carlo(r1, jax.random.key(0), 10, true_std=SIG, filter_std=SIG, ekf_initial_ranges=(0.0,))
    with pytest.raises(InputError, match="does not fit"):
        bt.ObserverPath((0.0, math.pi / 2), leg_duration=10.0, turn_rate=bt.TURN_RATE).state_at([0.0])
    with pytest.raises(InputError, match="k"):
        bt.stacked_measurement_matrix(jnp.zeros((5, 4)), 20.0, 6)


def test_reproduce_rows_all_pass_and_figures(tmp_path, capsys):
    # Without the extra table's particle filter (30 s at 2000 runs; test_tma_bounds.py tests it).
    rows, figures = bt.reproduce(tmp_path, extra_particles=None)
    # the extra (not in the paper) PCRLB output: a figure and a table file, the table on stderr only
    # (stdout carries `jaxtrack reproduce tma --json`'s document)
    out, err = capsys.readouterr()
    assert "PCRLB" not in out and "PCRLB" in err
    assert (tmp_path / "extra_pcrlb_vs_rmse.png").stat().st_size > 10_000
    assert "PCRLB" in (tmp_path / "extra_pcrlb_vs_rmse.txt").read_text()
    ids = {r.id for r in rows}
    assert {"V2", "V3", "V10", "V19", "V21", "V22", "V23", "V24", "V25", "V26", "V27", "V28", "V29", "V31"} <= ids
    failed = [r for r in rows if not r.ok]
    assert not failed, failed
    assert_rows_match_c1ffaca("tma", rows)
    assert len(figures) == 8
    for path in figures:
        with open(path, "rb") as fh:
            assert fh.read(8) == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_monte_carlo_large_sample_statistics(r1):
    """20 000 runs: the spec's 2000-run statistics hold at 10× the sample (tighter, ±3 SE)."""
    s = bt.geometry_study("R1", 20_000, jax.random.key(99), initial_ranges=(10_000.0, 0.0), ekf_initial_ranges=(5000.0,))
    k = bt.sample_index(s.scenario, 960.0)
    assert s.plkf.mean_range[0, k] == pytest.approx(-44.0, abs=3 * s.plkf.range_sem[0, k] + 3 * 106 / math.sqrt(2000))
    assert s.plkf.rms_range[0, k] == pytest.approx(106.0, rel=0.05)
    assert bt.leg1_collapse_factor(s) == pytest.approx(0.122, abs=0.005)
    assert s.ekf.rms_course[0, bt.sample_index(s.scenario, 480.0)] == pytest.approx(34.0, rel=0.1)

"""Fixed-interval IMM smoother (jaxtrack.filters._imm_smoother, Kim 1994 backward recursion).

Oracles: the RTS smoother (one member; two identical members), and a Monte Carlo study on a
maneuvering target (the smoother must beat the IMM filter by a paired-SE margin).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.filters import (
    ExtendedKalmanFilter,
    InteractingMultipleModel,
    KalmanFilter,
    imm_smoother,
    rts_smoother,
)
from jaxtrack.models import (
    ConstantVelocity,
    CoordinatedTurn,
    LinearGaussianModel,
    NearlyConstantTurn,
    RangeBearing,
    TrackingModel,
)
from jaxtrack.montecarlo import simulate

TAU = 1.0
X0 = np.array([0.0, 0.0, 10.0, 0.0])
P0 = np.diag([100.0, 100.0, 25.0, 25.0])
R2 = np.diag([25.0, 25.0])
H2 = np.hstack([np.eye(2), np.zeros((2, 2))])
OMEGA = 0.1  # rad/s, the truth's (and the CT member's) turn rate
Q_INT = 0.05  # m²/s³


def _linear(F, q=Q_INT, x0=X0, p0=P0):
    Q = np.asarray(ConstantVelocity(TAU, noise_intensity=q).noise_cov(0))
    return LinearGaussianModel(F, Q, H2, R2, x0, p0)


def _cv_F():
    return np.asarray(ConstantVelocity(TAU, noise_intensity=0.0).transition_matrix(0))


def _ct_F(w=OMEGA):
    return np.asarray(CoordinatedTurn(TAU, turn_rate=w, noise_intensity=0.0).transition_matrix(0))


def _assert_equal_to_rts(sm, rts, tol=1e-10):
    np.testing.assert_allclose(sm.smoothed_mean, rts.smoothed_mean, rtol=0, atol=tol)
    np.testing.assert_allclose(sm.smoothed_cov, rts.smoothed_cov, rtol=0, atol=tol)


@pytest.mark.parametrize("first_step", ["update", "predict"])
def test_one_linear_member_equals_rts(first_step):
    """One KF member on a linear model whose F switches CV → CT per step (so a wrong step index
    in the backward pass shows): the RTS smoother to 1e-10 (means and covariances)."""
    model, _ = _truth_model()
    zs = simulate(model, jax.random.PRNGKey(1), T_MC, first_step=first_step).measurements
    imm = InteractingMultipleModel([(KalmanFilter(), model)], np.ones((1, 1)))
    sm = imm_smoother(imm, zs, first_step=first_step)
    rts = rts_smoother(model, zs, filter=KalmanFilter(), first_step=first_step)
    # The smoother must actually move the estimates (else the comparison is vacuous).
    assert np.max(np.abs(rts.smoothed_mean - rts.filtered.filtered_mean)) > 1.0
    _assert_equal_to_rts(sm, rts)
    np.testing.assert_allclose(sm.member_means[0], rts.smoothed_mean, rtol=0, atol=1e-10)
    np.testing.assert_allclose(sm.smoothed_mode_probs, 1.0, rtol=0, atol=1e-14)
    assert bool(sm.ok)


def test_one_ekf_member_equals_extended_rts():
    """One EKF member, nearly-constant-turn (nonlinear transition) + range–bearing: 1e-10."""
    sensor = RangeBearing(np.array([5.0, 0.01]), sensor_position=np.array([-200.0, 300.0]))
    x0 = np.array([0.0, 0.0, 10.0, 0.0, 0.05])
    p0 = np.diag([100.0, 100.0, 4.0, 4.0, 1e-3])
    model = TrackingModel(NearlyConstantTurn(TAU, noise_intensity=0.05, turn_rate_intensity=1e-4), sensor, x0, p0)
    zs = simulate(model, jax.random.PRNGKey(2), 60).measurements
    imm = InteractingMultipleModel([(ExtendedKalmanFilter(), model)], np.ones((1, 1)))
    sm = imm_smoother(imm, zs)
    rts = rts_smoother(model, zs, filter=ExtendedKalmanFilter())
    assert np.max(np.abs(rts.smoothed_mean - rts.filtered.filtered_mean)) > 1.0
    _assert_equal_to_rts(sm, rts)


def test_two_identical_members_equal_rts_and_keep_mode_probs():
    """The same CV model twice, p = [[0.9, 0.1], [0.3, 0.7]] from its stationary law [0.75, 0.25]:
    the RTS smoother to 1e-10, and the smoothed mode probabilities stay [0.75, 0.25]."""
    model = _linear(_cv_F())
    zs = simulate(model, jax.random.PRNGKey(3), 80).measurements
    p = np.array([[0.9, 0.1], [0.3, 0.7]])
    pi = np.array([0.75, 0.25])
    np.testing.assert_allclose(pi @ p, pi, rtol=0, atol=1e-15)
    imm = InteractingMultipleModel([(KalmanFilter(), model)] * 2, p, pi)
    sm = imm_smoother(imm, zs)
    rts = rts_smoother(model, zs)
    _assert_equal_to_rts(sm, rts)
    for i in range(2):
        np.testing.assert_allclose(sm.member_means[i], rts.smoothed_mean, rtol=0, atol=1e-10)
    np.testing.assert_allclose(sm.smoothed_mode_probs, np.broadcast_to(pi, (80, 2)), rtol=0, atol=1e-12)


def test_two_identical_members_from_nonstationary_start():
    """Identical members from μ_0 = [0.5, 0.5] (not stationary): the smoothed mode probabilities
    are the Markov chain's marginals μ_0 pᵏ (the measurements carry no mode information)."""
    model = _linear(_cv_F())
    zs = simulate(model, jax.random.PRNGKey(4), 80).measurements
    p = np.array([[0.9, 0.1], [0.3, 0.7]])
    imm = InteractingMultipleModel([(KalmanFilter(), model)] * 2, p, np.array([0.5, 0.5]))
    sm = imm_smoother(imm, zs)
    marg = np.array([np.array([0.5, 0.5]) @ np.linalg.matrix_power(p, k) for k in range(80)])
    np.testing.assert_allclose(sm.smoothed_mode_probs, marg, rtol=0, atol=1e-12)
    _assert_equal_to_rts(sm, rts_smoother(model, zs))


def _numpy_kim(Fs, Qs, p, mu_f, xf, Pf):
    """Kim (1994) backward recursion in NumPy, from the IMM's filtered per-mode moments."""
    T, M = mu_f.shape
    xs, Ps, mus = xf[:, -1].copy(), Pf[:, -1].copy(), mu_f[-1].copy()
    out_x, out_P, out_mu = [None] * T, [None] * T, [None] * T
    out_x[-1] = (mus[:, None] * xs).sum(0)
    out_mu[-1] = mus
    for k in range(T - 2, -1, -1):
        cbar = mu_f[k] @ p
        joint = mu_f[k][:, None] * p * (mus / cbar)[None, :]
        mu_k = joint.sum(1)
        nx, nP = np.zeros_like(xs), np.zeros_like(Ps)
        for i in range(M):
            pair_x, pair_P = [], []
            for j in range(M):
                xp = Fs[j] @ xf[i, k]
                Pp = Fs[j] @ Pf[i, k] @ Fs[j].T + Qs[j]
                G = Pf[i, k] @ Fs[j].T @ np.linalg.inv(Pp)
                pair_x.append(xf[i, k] + G @ (xs[j] - xp))
                pair_P.append(Pf[i, k] + G @ (Ps[j] - Pp) @ G.T)
            w = joint[i] / mu_k[i]
            nx[i] = sum(w[j] * pair_x[j] for j in range(M))
            nP[i] = sum(w[j] * (pair_P[j] + np.outer(pair_x[j] - nx[i], pair_x[j] - nx[i])) for j in range(M))
        xs, Ps, mus = nx, nP, mu_k
        out_x[k] = (mus[:, None] * xs).sum(0)
        out_mu[k] = mus
        d = xs - out_x[k]
        out_P[k] = sum(mus[i] * (Ps[i] + np.outer(d[i], d[i])) for i in range(M))
    return np.array(out_x), np.array(out_P[:-1]), np.array(out_mu), xs, Ps


def test_two_distinct_members_match_numpy_kim():
    """CV + CT(ω = 0.1) KF members on the maneuvering truth, 60 steps: an independent NumPy
    transcription of (K1)–(K6) from the same filtered per-mode moments, to 1e-9."""
    truth, _ = _truth_model()
    zs = simulate(truth, jax.random.PRNGKey(7), T_MC).measurements[20:80]
    imm = _members_imm()
    sm = imm_smoother(imm, zs)
    f = sm.filtered
    Q = np.asarray(ConstantVelocity(TAU, noise_intensity=Q_INT).noise_cov(0))
    x, P, mu, x0, P0_ = _numpy_kim(
        [_cv_F(), _ct_F()], [Q, Q], np.asarray(imm.transition_probs), np.asarray(f.mode_probs),
        np.stack([np.asarray(m) for m in f.member_means]), np.stack([np.asarray(c) for c in f.member_covs]),
    )
    assert np.ptp(mu[:, 1]) > 0.5  # the modes actually switch in this window
    np.testing.assert_allclose(sm.smoothed_mode_probs, mu, rtol=0, atol=1e-9)
    np.testing.assert_allclose(sm.smoothed_mean, x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(sm.smoothed_cov[:-1], P, rtol=0, atol=1e-9)
    for i in range(2):
        np.testing.assert_allclose(sm.member_means[i][0], x0[i], rtol=0, atol=1e-9)
        np.testing.assert_allclose(sm.member_covs[i][0], P0_[i], rtol=0, atol=1e-9)


# ---- maneuvering Monte Carlo --------------------------------------------------------------
T_MC = 100
TURNS = [(30, 50), (70, 85)]  # steps [a, b) where the truth turns at OMEGA
N_RUNS = 200


def _truth_model():
    turning = np.zeros(T_MC, bool)
    for a, b in TURNS:
        turning[a:b] = True
    Fs = np.where(turning[:, None, None], _ct_F()[None], _cv_F()[None])
    return _linear(Fs), turning


def _members_imm():
    members = [(KalmanFilter(), _linear(_cv_F())), (KalmanFilter(), _linear(_ct_F()))]
    return InteractingMultipleModel(members, np.array([[0.95, 0.05], [0.05, 0.95]]), np.array([0.5, 0.5]))


@pytest.fixture(scope="module")
def mc():
    truth, turning = _truth_model()
    keys = jax.random.split(jax.random.PRNGKey(20), N_RUNS)
    traj = jax.jit(jax.vmap(lambda key: simulate(truth, key, T_MC)))(keys)
    imm = _members_imm()
    sm = jax.jit(jax.vmap(lambda z: imm_smoother(imm, z, throw=False)))(traj.measurements)
    return traj, sm, turning


def test_monte_carlo_smoother_beats_filter(mc):
    """CV legs + two ω = 0.1 rad/s turns, CV + CT(ω known) KF members, 200 runs, 100 steps.

    Per run the time-averaged position RMSE of the filter and the smoother; the paired
    difference must exceed 3 paired standard errors and the smoother be ≥ 15% better.
    Measured: filter 4.247 m, smoother 3.168 m, difference 1.079 m ± 0.049 m (paired SE, 22 SEs),
    ratio 0.746.
    """
    traj, sm, _ = mc
    assert bool(jnp.all(sm.ok))
    pos = traj.states[..., :2]
    rmse = lambda est: np.sqrt(np.mean(np.sum((np.asarray(est[..., :2]) - pos) ** 2, -1), -1))  # noqa: E731
    r_f, r_s = rmse(sm.filtered.filtered_mean), rmse(sm.smoothed_mean)
    d = r_f - r_s
    se = d.std(ddof=1) / np.sqrt(N_RUNS)
    print(f"filter {r_f.mean():.3f} m, smoother {r_s.mean():.3f} m, diff {d.mean():.3f} ± {se:.4f} m")
    assert d.mean() > 3 * se
    assert r_s.mean() < 0.85 * r_f.mean()
    # Consistency is reported, not claimed (module docstring, "Known behaviour"): the smoothed
    # covariances are conservative. Measured ANEES (4 states): filter 4.04, smoother 2.61.
    def anees(mean, cov):
        e = np.asarray(traj.states - mean)
        return np.mean(np.einsum("rki,rkij,rkj->rk", e, np.linalg.inv(np.asarray(cov)), e))

    a_f, a_s = anees(sm.filtered.filtered_mean, sm.filtered.filtered_cov), anees(sm.smoothed_mean, sm.smoothed_cov)
    print(f"ANEES filter {a_f:.2f}, smoother {a_s:.2f}")
    assert 3.5 < a_f < 4.5 and 1.5 < a_s < 4.5


def test_monte_carlo_mode_probabilities(mc):
    """Smoothed μ sum to 1 and lie in [0, 1]; on the turn segments the smoothed CT probability
    is higher than the filtered one on average (measured: 0.789 vs 0.664), on the CV legs the
    smoothed CV probability too (measured: 0.832 vs 0.701)."""
    _, sm, turning = mc
    mu_s, mu_f = np.asarray(sm.smoothed_mode_probs), np.asarray(sm.filtered.mode_probs)
    np.testing.assert_allclose(mu_s.sum(-1), 1.0, rtol=0, atol=1e-12)
    assert mu_s.min() >= 0.0 and mu_s.max() <= 1.0
    ct_s, ct_f = mu_s[:, turning, 1].mean(), mu_f[:, turning, 1].mean()
    cv_s, cv_f = mu_s[:, ~turning, 0].mean(), mu_f[:, ~turning, 0].mean()
    print(f"turns: CT smoothed {ct_s:.3f} filtered {ct_f:.3f}; "
          f"legs: CV smoothed {cv_s:.3f} filtered {cv_f:.3f}")
    assert ct_s > ct_f + 0.05
    assert cv_s > cv_f + 0.05


def test_mixed_dimensions_and_errors():
    """CV (4) + NCT (5) EKF members: shapes, finiteness, μ rows sum to 1; wrong `imm` raises."""
    sensor = RangeBearing(np.array([5.0, 0.01]), sensor_position=np.array([-200.0, 300.0]))
    truth = TrackingModel(NearlyConstantTurn(TAU, noise_intensity=0.05, turn_rate_intensity=1e-4), sensor,
                          np.append(X0, 0.05),
                          np.diag([100.0, 100.0, 4.0, 4.0, 1e-3]))
    zs = simulate(truth, jax.random.PRNGKey(5), 25).measurements
    x05, p05 = np.append(X0, 0.0), np.diag(np.append(np.diag(P0), 0.01))
    members = [
        (ExtendedKalmanFilter(), TrackingModel(ConstantVelocity(TAU, noise_intensity=0.05), sensor, X0, P0)),
        (ExtendedKalmanFilter(), TrackingModel(NearlyConstantTurn(TAU, noise_intensity=0.05,
                                                                  turn_rate_intensity=1e-4), sensor, x05, p05)),
    ]
    imm = InteractingMultipleModel(members, np.array([[0.9, 0.1], [0.2, 0.8]]), np.array([0.5, 0.5]))
    sm = imm_smoother(imm, zs)
    assert sm.smoothed_mean.shape == (25, 5) and sm.member_means[0].shape == (25, 4)
    assert sm.member_covs[1].shape == (25, 5, 5) and bool(sm.ok)
    np.testing.assert_allclose(np.sum(sm.smoothed_mode_probs, -1), 1.0, rtol=0, atol=1e-12)
    assert np.min(np.linalg.eigvalsh(np.asarray(sm.smoothed_cov))) > -1e-9
    with pytest.raises(InputError, match="imm"):
        imm_smoother(KalmanFilter(), zs)


def test_gradient_wrt_markov_logits_matches_central_differences():
    """d Σ smoothed positions / d (Markov logits) on the CV + CT case, 40 steps: rtol 1e-5."""
    truth, _ = _truth_model()
    zs = simulate(truth, jax.random.PRNGKey(6), T_MC).measurements[:40]
    members = [(KalmanFilter(), _linear(_cv_F())), (KalmanFilter(), _linear(_ct_F()))]

    @jax.jit
    def f(lg):
        imm = InteractingMultipleModel.from_logits(members, lg, np.array([0.5, 0.5]))
        return jnp.sum(imm_smoother(imm, zs, throw=False).smoothed_mean[:, :2])

    logits = jnp.array([[2.0, -1.0], [-1.5, 1.0]])
    g = np.asarray(jax.jit(jax.grad(f))(logits))
    h = 1e-5
    fd = np.zeros((2, 2))
    for i in range(2):
        for j in range(2):
            e = jnp.zeros((2, 2)).at[i, j].set(h)
            fd[i, j] = (f(logits + e) - f(logits - e)) / (2 * h)
    assert np.all(np.abs(fd) > 1e-3)
    np.testing.assert_allclose(g, fd, rtol=1e-5)

"""IMM filter (jaxtrack.filters._imm): oracles FilterPy's IMMEstimator, a NumPy textbook IMM."""

from __future__ import annotations

import copy

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.filters import (
    ExtendedKalmanFilter,
    InteractingMultipleModel,
    KalmanFilter,
    SquareRootKalmanFilter,
    run_filter,
    run_imm,
)
from jaxtrack.models import (
    ConstantVelocity,
    CoordinatedTurn,
    LinearGaussianModel,
    NearlyConstantTurn,
    RangeBearing,
    TrackingModel,
)

TAU = 1.0
X0 = np.array([0.0, 0.0, 10.0, 0.0])
P0 = np.diag([100.0, 100.0, 25.0, 25.0])
R2 = np.diag([25.0, 16.0])
H2 = np.hstack([np.eye(2), np.zeros((2, 2))])
PTRANS = np.array([[0.95, 0.05], [0.10, 0.90]])


def _maneuvering_truth(T, rng):
    """CV legs and a coordinated turn: x = [x, y, vx, vy]."""
    x = X0.copy()
    out = []
    for k in range(T):
        omega = 0.08 if 60 <= k < 100 or 150 <= k < 170 else 0.0
        F = np.asarray(CoordinatedTurn(TAU, turn_rate=omega, noise_intensity=0.0).transition_matrix(0))
        x = F @ x + rng.normal(0, 0.05, 4) * np.array([0.5, 0.5, 1, 1])
        out.append(x)
    return np.array(out)


def _cv_model(q, x0=X0, p0=P0):
    cv = ConstantVelocity(TAU, noise_intensity=q)
    F, Q = np.asarray(cv.transition_matrix(0)), np.asarray(cv.noise_cov(0))
    return LinearGaussianModel(F, Q, H2, R2, x0, p0)


@pytest.fixture(scope="module")
def linear_data():
    rng = np.random.default_rng(20)
    truth = _maneuvering_truth(200, rng)
    zs = truth[:, :2] + rng.normal(size=(200, 2)) * np.sqrt(np.diag(R2))
    return zs


def _filterpy_imm(models, mu, M):
    from filterpy.kalman import IMMEstimator, KalmanFilter as FPKalman

    fs = []
    for m in models:
        f = FPKalman(dim_x=4, dim_z=2)
        f.x, f.P = np.array(m.initial_mean), np.array(m.initial_cov)
        f.F, f.Q = np.array(m.F), np.array(m.Q)
        f.H, f.R = np.array(m.H), np.array(m.R)
        fs.append(f)
    return IMMEstimator(fs, np.asarray(mu), np.asarray(M))


@pytest.mark.parametrize("first_step", ["predict", "update"])
def test_linear_members_match_filterpy(linear_data, first_step):
    """Two CV members (q = 0.01, 4.0) vs FilterPy's IMMEstimator over 200 steps, to 1e-10.

    FilterPy's order: ``update(z)`` updates every member and sets ``μ = c̄ Λ / Σ``, then
    recomputes ``c̄ = μ P`` and the mixing weights ``ω``; ``predict()`` mixes with ``ω`` and
    predicts each member. ``c̄`` is first computed in the constructor from the given ``mu``.
    Mapping to jaxtrack:

    - FilterPy ``predict(); update(z)`` per step == ``first_step="predict"`` with
      ``initial_probs = mu`` (priors and mode probabilities one transition before z_0);
    - FilterPy ``update(z); predict()`` per step: step 0 updates the members' own priors (no
      mixing, no transition) but weighs them with ``c̄ = mu P`` from the constructor; that is
      ``first_step="update"`` (no mixing / transition at step 0, ``c̄ = initial_probs``) with
      ``initial_probs = mu @ P``.
    """
    zs = linear_data
    models = [_cv_model(0.01), _cv_model(4.0, x0=X0 + np.array([1.0, -1.0, 0.0, 0.5]))]
    mu0 = np.array([0.7, 0.3])
    fp = _filterpy_imm(models, mu0, PTRANS)
    means, covs, mus = [], [], []
    for z in zs:
        if first_step == "predict":
            fp.predict()
            fp.update(z)
        else:
            fp.update(z)
        means.append(fp.x.copy())
        covs.append(fp.P.copy())
        mus.append(fp.mu.copy())
        if first_step == "update":
            fp.predict()
    init = mu0 if first_step == "predict" else mu0 @ PTRANS
    imm = InteractingMultipleModel([(KalmanFilter(), m) for m in models], PTRANS, init)
    res = run_imm(imm, zs, first_step=first_step)
    assert bool(res.ok)
    mus = np.array(mus)
    assert mus[:, 1].min() < 0.15 and mus[:, 1].max() > 0.75  # modes actually switch
    np.testing.assert_allclose(res.mode_probs, mus, rtol=0, atol=1e-10)
    np.testing.assert_allclose(res.filtered_mean, np.array(means), rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(res.filtered_cov, np.array(covs), rtol=1e-10, atol=1e-10)


def test_one_member_equals_its_filter(linear_data):
    zs = linear_data
    model = _cv_model(0.5)
    for first_step in ("update", "predict"):
        ref = run_filter(KalmanFilter(), model, zs, first_step=first_step)
        res = run_imm(InteractingMultipleModel([(KalmanFilter(), model)], [[1.0]]), zs, first_step=first_step)
        np.testing.assert_allclose(res.filtered_mean, ref.filtered_mean, rtol=1e-14, atol=1e-12)
        np.testing.assert_allclose(res.filtered_cov, ref.filtered_cov, rtol=1e-14, atol=1e-12)
        np.testing.assert_allclose(res.log_likelihood, ref.log_likelihood, rtol=1e-14)
        np.testing.assert_array_equal(res.mode_probs, 1.0)


def test_a_run_that_overflows_is_not_ok(linear_data):
    """A measurement that overflows the update (1e300 m) makes the run non-finite: ok is False
    (the step checks the members' posteriors, the mode probabilities and the log-likelihood)."""
    zs = np.array(linear_data[:20])
    imm = InteractingMultipleModel([(KalmanFilter(), _cv_model(0.01)), (KalmanFilter(), _cv_model(4.0))], PTRANS)
    assert bool(run_imm(imm, zs).ok)
    zs[12] = [1e300, -1e300]
    res = run_imm(imm, zs, throw=False)
    assert not bool(res.ok)
    assert not np.all(np.isfinite(np.asarray(res.filtered_cov[12:])))


# --------------------------------------------------------------------------------------------
# nonlinear: EKF members, NumPy IMM from the textbook equations (BLK 2001 §11.6.6)

SENSOR = np.array([-500.0, 300.0])
RB_STD = np.array([5.0, 0.01])


def _np_rb(x):
    d = x[:2] - SENSOR
    r = np.hypot(*d)
    h = np.array([r, np.arctan2(d[1], d[0])])
    H = np.zeros((2, x.size))
    H[0, :2] = d / r
    H[1, :2] = np.array([-d[1], d[0]]) / r**2
    return h, H


def _np_turn_functions(theta):
    """``s = sin θ/θ``, ``c = (1 − cos θ)/θ`` and their derivatives, without cancellation.

    Closed forms of ``s'`` and ``c'`` cancel catastrophically for small θ (the NCT member's ω
    passes near 0 when mixed with a CV member), so below |θ| = 0.05 their Taylor series are used
    (truncation error < θ⁹/10⁷).
    """
    s = np.sinc(theta / np.pi)
    c = 0.5 * theta * np.sinc(theta / (2 * np.pi)) ** 2  # 2 sin²(θ/2)/θ
    if abs(theta) < 0.05:
        t2 = theta * theta
        ds = theta * (-1 / 3 + t2 * (1 / 30 + t2 * (-1 / 840 + t2 / 45360)))
        dc = 0.5 + t2 * (-1 / 8 + t2 * (1 / 144 - t2 / 5760))
    else:
        ds = (theta * np.cos(theta) - np.sin(theta)) / theta**2
        dc = (theta * np.sin(theta) - (1 - np.cos(theta))) / theta**2
    return s, c, ds, dc


def _np_ct(omega, x, q):
    """CT (known ω) or NCT (ω = x[4] when omega is None): mean, Jacobian, Q."""
    n = x.size
    w = x[4] if omega is None else omega
    theta = w * TAU
    sn, cs = np.sin(theta), np.cos(theta)
    s, c, ds, dc = _np_turn_functions(theta)
    a, b = TAU * s, TAU * c  # sin(ωτ)/ω, (1 − cos ωτ)/ω
    F4 = np.array([[1, 0, a, -b], [0, 1, b, a], [0, 0, cs, -sn], [0, 0, sn, cs]])
    Q1 = q * np.array([[TAU**3 / 3, TAU**2 / 2], [TAU**2 / 2, TAU]])
    Q = np.zeros((n, n))
    Q[:4, :4] = np.kron(Q1, np.eye(2))
    fx = np.concatenate([F4 @ x[:4], x[4:]])
    J = np.eye(n)
    J[:4, :4] = F4
    if omega is None:
        vx, vy = x[2], x[3]
        da, db = TAU**2 * ds, TAU**2 * dc  # ∂a/∂ω, ∂b/∂ω
        J[:4, 4] = [da * vx - db * vy, db * vx + da * vy, -TAU * (vx * sn + vy * cs), TAU * (vx * cs - vy * sn)]
        Q[4, 4] = 1e-4 * TAU
    return fx, J, Q


def _np_cv(x, q):
    F = np.eye(4)
    F[:2, 2:] = TAU * np.eye(2)
    Q = np.kron(q * np.array([[TAU**3 / 3, TAU**2 / 2], [TAU**2 / 2, TAU]]), np.eye(2))
    return F @ x, F, Q


def _np_ekf_cycle(x, P, z, motion):
    fx, F, Q = motion(x)
    xp, Pp = fx, F @ P @ F.T + Q
    h, H = _np_rb(xp)
    R = np.diag(RB_STD**2)
    nu = z - h
    nu[1] = (nu[1] + np.pi) % (2 * np.pi) - np.pi
    S = H @ Pp @ H.T + R
    W = Pp @ H.T @ np.linalg.inv(S)
    IWH = np.eye(x.size) - W @ H
    Pu = IWH @ Pp @ IWH.T + W @ R @ W.T
    ll = -0.5 * (nu @ np.linalg.solve(S, nu) + np.log(np.linalg.det(S)) + 2 * np.log(2 * np.pi))
    return xp + W @ nu, Pu, ll


def _np_imm(zs, motions, dims, x0s, p0s, ptrans, mu0):
    """Textbook IMM (BLK 2001 eqs. 11.6.6-6 … -15), ``first_step="predict"``, prefix augmentation
    with mean 0 and variance 0 for missing components."""
    M, N = len(motions), max(dims)
    xs, Ps, mu = [np.array(x) for x in x0s], [np.array(p) for p in p0s], np.array(mu0)
    out_x, out_P, out_mu, total = [], [], [], 0.0

    def emb(x, P):
        xe, Pe = np.zeros(N), np.zeros((N, N))
        xe[: x.size], Pe[: x.size, : x.size] = x, P
        return xe, Pe

    for z in zs:
        cbar = mu @ ptrans
        xe = [emb(x, P) for x, P in zip(xs, Ps)]
        new = []
        for j in range(M):
            w = ptrans[:, j] * mu / cbar[j]
            x0 = sum(w[i] * xe[i][0] for i in range(M))
            P0 = sum(w[i] * (xe[i][1] + np.outer(xe[i][0] - x0, xe[i][0] - x0)) for i in range(M))
            n = dims[j]
            new.append(_np_ekf_cycle(x0[:n], P0[:n, :n], z, motions[j]))
        lam = np.exp([ll for _, _, ll in new])
        total += np.log(lam @ cbar)
        mu = lam * cbar / (lam @ cbar)
        xs, Ps = [x for x, _, _ in new], [P for _, P, _ in new]
        xe = [emb(x, P) for x, P in zip(xs, Ps)]
        x = sum(mu[j] * xe[j][0] for j in range(M))
        P = sum(mu[j] * (xe[j][1] + np.outer(xe[j][0] - x, xe[j][0] - x)) for j in range(M))
        out_x.append(x)
        out_P.append(P)
        out_mu.append(mu)
    return np.array(out_x), np.array(out_P), np.array(out_mu), total


@pytest.fixture(scope="module")
def rb_data():
    rng = np.random.default_rng(7)
    truth = _maneuvering_truth(120, rng)
    d = truth[:, :2] - SENSOR
    zs = np.stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])], axis=1)
    return zs + rng.normal(size=zs.shape) * RB_STD


def test_ekf_members_match_numpy_imm(rb_data):
    """CT with ω = 0.08 and ω = −0.08 rad/s (EKF), range–bearing, vs the NumPy IMM to 1e-9."""
    zs = rb_data
    sensor = RangeBearing(RB_STD, sensor_position=SENSOR)
    omegas, q = (0.08, -0.08), 0.05
    models = [TrackingModel(CoordinatedTurn(TAU, turn_rate=w, noise_intensity=q), sensor, X0, P0) for w in omegas]
    mu0 = np.array([0.5, 0.5])
    imm = InteractingMultipleModel([(ExtendedKalmanFilter(), m) for m in models], PTRANS, mu0)
    res = run_imm(imm, zs, first_step="predict")
    motions = [lambda x, w=w: _np_ct(w, x, q) for w in omegas]
    x, P, mu, ll = _np_imm(zs, motions, [4, 4], [X0, X0], [P0, P0], PTRANS, mu0)
    assert np.ptp(mu[:, 0]) > 0.5
    np.testing.assert_allclose(res.mode_probs, mu, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.filtered_mean, x, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.filtered_cov, P, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.log_likelihood, ll, rtol=1e-9)


def test_cv_plus_nearly_constant_turn_members(rb_data):
    """CV (4 states) + NCT (5 states, ω in the state): prefix augmentation, vs NumPy, to 1e-9."""
    zs = rb_data
    sensor = RangeBearing(RB_STD, sensor_position=SENSOR)
    q = 0.05
    x05, p05 = np.append(X0, 0.05), np.diag(np.append(np.diag(P0), 0.01))
    models = [
        TrackingModel(ConstantVelocity(TAU, noise_intensity=q), sensor, X0, P0),
        TrackingModel(NearlyConstantTurn(TAU, noise_intensity=q, turn_rate_intensity=1e-4), sensor, x05, p05),
    ]
    mu0 = np.array([0.6, 0.4])
    imm = InteractingMultipleModel([(ExtendedKalmanFilter(), m) for m in models], PTRANS, mu0)
    res = run_imm(imm, zs, first_step="predict")
    motions = [lambda x: _np_cv(x, q), lambda x: _np_ct(None, x, q)]
    x, P, mu, ll = _np_imm(zs, motions, [4, 5], [X0, x05], [P0, p05], PTRANS, mu0)
    assert res.filtered_mean.shape == (120, 5) and res.member_means[0].shape == (120, 4)
    np.testing.assert_allclose(res.mode_probs, mu, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.filtered_mean, x, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.filtered_cov, P, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.log_likelihood, ll, rtol=1e-9)


def test_gradients_match_central_differences(linear_data):
    """d log-likelihood / d (transition logits, process-noise intensity) vs central differences."""
    zs = jnp.asarray(linear_data[:60])
    base, m2 = _cv_model(1.0), _cv_model(4.0)  # built outside the trace (NumPy inside)

    def loglik(logits, log_q):
        # The constructor checks concrete arrays; a traced Q goes in with tree_at.
        Q = ConstantVelocity(TAU, noise_intensity=jnp.exp(log_q)).noise_cov(0)
        m1 = eqx.tree_at(lambda m: m.Q, base, Q)
        imm = InteractingMultipleModel.from_logits([(KalmanFilter(), m1), (KalmanFilter(), m2)], logits)
        return run_imm(imm, zs, throw=False).log_likelihood

    logits = jnp.asarray(np.log(PTRANS))
    log_q = jnp.asarray(np.log(0.05))
    g_logits, g_q = jax.jit(jax.grad(loglik, argnums=(0, 1)))(logits, log_q)
    f = jax.jit(loglik)
    h = 1e-5
    fd = np.zeros((2, 2))
    for i in range(2):
        for j in range(2):
            e = np.zeros((2, 2))
            e[i, j] = h
            fd[i, j] = (f(logits + e, log_q) - f(logits - e, log_q)) / (2 * h)
    fd_q = (f(logits, log_q + h) - f(logits, log_q - h)) / (2 * h)
    assert np.all(np.abs(fd) > 1e-3)
    np.testing.assert_allclose(g_logits, fd, rtol=1e-5)
    np.testing.assert_allclose(g_q, fd_q, rtol=1e-5)


def test_vmap_and_mask(linear_data):
    zs = jnp.asarray(linear_data[:50])
    models = [_cv_model(0.01), _cv_model(4.0)]
    imm = InteractingMultipleModel([(KalmanFilter(), m) for m in models], PTRANS)
    mask = np.ones(50, bool)
    mask[10:15] = False
    res = run_imm(imm, zs, mask=mask)
    # A missing step: μ_k = c̄_k = μ_{k-1} P.
    np.testing.assert_allclose(res.mode_probs[12], res.mode_probs[11] @ PTRANS, rtol=1e-13)
    batch = jax.vmap(lambda z: run_imm(imm, z, throw=False).log_likelihood)(jnp.stack([zs, zs + 1.0]))
    np.testing.assert_allclose(batch[0], run_imm(imm, zs).log_likelihood, rtol=1e-12)


def test_input_errors():
    m = _cv_model(1.0)
    kf = KalmanFilter()
    with pytest.raises(InputError, match="transition_probs"):
        InteractingMultipleModel([(kf, m), (kf, m)], np.ones((2, 3)) / 3)
    with pytest.raises(InputError, match="transition_probs"):
        InteractingMultipleModel([(kf, m), (kf, m)], [[0.5, 0.6], [0.5, 0.5]])
    with pytest.raises(InputError, match="transition_probs"):
        InteractingMultipleModel([(kf, m), (kf, m)], [[1.5, -0.5], [0.5, 0.5]])
    with pytest.raises(InputError, match="transition_probs"):
        InteractingMultipleModel([(kf, m), (kf, m), (kf, m)], PTRANS)
    with pytest.raises(InputError, match="initial_probs"):
        InteractingMultipleModel([(kf, m), (kf, m)], PTRANS, [0.5, 0.6])
    with pytest.raises(InputError, match="members"):
        InteractingMultipleModel([], np.zeros((0, 0)))
    with pytest.raises(InputError, match="first_step"):
        run_imm(InteractingMultipleModel([(kf, m)], [[1.0]]), np.zeros((3, 2)), first_step="x")
    copy.deepcopy(m)  # models stay usable


def test_float32_logits_build_and_row_check_follows_the_dtype():
    """from_logits with float32 logits (softmax rows sum to 1 ± 3e-8) builds; a float64 matrix
    whose rows are off by 1e-6 is still refused."""
    members = [(KalmanFilter(), _cv_model(0.1)), (KalmanFilter(), _cv_model(4.0))]
    logits = jnp.asarray(np.log([[0.95, 0.05], [0.1, 0.9]]), jnp.float32) + jnp.float32(0.3)
    imm = InteractingMultipleModel.from_logits(members, logits)
    np.testing.assert_allclose(np.asarray(imm.transition_probs), [[0.95, 0.05], [0.1, 0.9]], atol=1e-6)
    with pytest.raises(InputError, match="rows must sum to 1"):
        InteractingMultipleModel(members, np.array([[0.95, 0.05 + 1e-6], [0.1, 0.9]]))


def test_square_root_members_equal_covariance_members(linear_data, rb_data):
    """Square-root members (factors in predict/update, mixing in covariance form) equal the
    covariance-form members: SR-KF vs KF (linear, 200 steps) to 1e-9, SR-UKF vs UKF (range-bearing,
    CT ±0.08) to 1e-8; the IMM smoother with SR-KF members equals the KF-member smoother."""
    from jaxtrack.filters import SquareRootUnscentedKalmanFilter, UnscentedKalmanFilter, imm_smoother

    models = [_cv_model(0.01), _cv_model(4.0)]
    a = InteractingMultipleModel([(KalmanFilter(), m) for m in models], PTRANS)
    b = InteractingMultipleModel([(SquareRootKalmanFilter(), models[0]), (KalmanFilter(), models[1])], PTRANS)
    ra, rb = run_imm(a, linear_data), run_imm(b, linear_data)
    np.testing.assert_allclose(rb.filtered_mean, ra.filtered_mean, rtol=0, atol=1e-9 * np.abs(ra.filtered_mean).max())
    np.testing.assert_allclose(rb.filtered_cov, ra.filtered_cov, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(rb.mode_probs, ra.mode_probs, rtol=0, atol=1e-9)
    np.testing.assert_allclose(rb.log_likelihood, ra.log_likelihood, rtol=1e-11)
    sa, sb = imm_smoother(a, linear_data), imm_smoother(b, linear_data)
    np.testing.assert_allclose(sb.smoothed_mean, sa.smoothed_mean, rtol=0, atol=1e-9 * np.abs(sa.smoothed_mean).max())
    np.testing.assert_allclose(sb.smoothed_mode_probs, sa.smoothed_mode_probs, rtol=0, atol=1e-9)

    sensor = RangeBearing(RB_STD, sensor_position=SENSOR)
    ct = [TrackingModel(CoordinatedTurn(TAU, turn_rate=w, noise_intensity=0.05), sensor, X0, P0) for w in (0.08, -0.08)]
    u = InteractingMultipleModel([(UnscentedKalmanFilter(), m) for m in ct], PTRANS)
    v = InteractingMultipleModel([(SquareRootUnscentedKalmanFilter(), m) for m in ct], PTRANS)
    ru, rv = run_imm(u, rb_data), run_imm(v, rb_data)
    np.testing.assert_allclose(rv.filtered_mean, ru.filtered_mean, rtol=0, atol=1e-8 * np.abs(ru.filtered_mean).max())
    np.testing.assert_allclose(rv.mode_probs, ru.mode_probs, rtol=0, atol=1e-8)


def test_traced_markov_matrix_that_is_not_stochastic_is_flagged(linear_data):
    """Issue 37, cause 3: a Markov matrix built under jit whose row sums to 0.95 ran with ok=True and
    a wrong log-likelihood (the constructor checks only concrete matrices). Now ok=False, and the
    same traced path with a valid matrix stays ok and equals the eager result."""
    zs = jnp.asarray(linear_data[:30])
    models = [_cv_model(0.01), _cv_model(4.0)]

    @jax.jit
    def run(P, mu):
        imm = InteractingMultipleModel([(KalmanFilter(), m) for m in models], P, initial_probs=mu)
        res = run_imm(imm, zs, throw=False)
        return res.ok, res.log_likelihood

    half = jnp.array([0.5, 0.5])
    ok, ll = run(jnp.asarray(PTRANS), half)
    assert bool(ok)
    np.testing.assert_allclose(ll, run_imm(InteractingMultipleModel([(KalmanFilter(), m) for m in models], PTRANS),
                                           zs).log_likelihood, rtol=1e-13)
    short_row = jnp.asarray(PTRANS).at[0].set(jnp.array([0.90, 0.05]))  # row 0 sums to 0.95
    negative = jnp.array([[1.1, -0.1], [0.1, 0.9]])
    for P, mu in ((short_row, half), (negative, half), (jnp.asarray(PTRANS), jnp.array([0.6, 0.6]))):
        assert not bool(run(P, mu)[0]), (P, mu)
    with pytest.raises(Exception, match="not stochastic"):
        jax.jit(lambda P: run_imm(InteractingMultipleModel([(KalmanFilter(), m) for m in models], P),
                                  zs).log_likelihood)(short_row).block_until_ready()

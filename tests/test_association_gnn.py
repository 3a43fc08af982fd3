"""Assignment, GNN and the association input (``L``) against independent references.

Oracles: ``scipy.optimize.linear_sum_assignment`` (optimal cost), brute-force enumeration of all
joint events (GNN), hand-computed weights (``log_likelihood_ratios``) and
``scipy.stats.multivariate_normal`` (``measurement_likelihoods``). Random cases come from
``np.random.default_rng(seed)``. Each jitted function is compiled once per shape at module level
and vmapped over batches, so the file runs in a few seconds.
"""

import itertools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize
import scipy.stats

from jaxtrack import InputError
from jaxtrack.association._assignment import GNN, linear_assignment
from jaxtrack.association._gating import gate_threshold, log_likelihood_ratios, measurement_likelihoods
from jaxtrack.filters import KalmanFilter, SquareRootKalmanFilter, UnscentedKalmanFilter
from jaxtrack.models import ConstantVelocity, RangeBearing, TrackingModel, constant_velocity

_assign = jax.jit(jax.vmap(linear_assignment))  # (cost, valid), batched
_assign_one = jax.jit(linear_assignment)  # eager calls dispatch the solver op by op: seconds
_gnn = jax.jit(jax.vmap(GNN()))
BATCH = 100  # matrices per (kind, shape)


# ----------------------------------------------------------------------------- linear_assignment


def _random_costs(rng, kind, shape):
    """A batch ``(BATCH, R, C)`` of cost matrices of one kind."""
    R, C = shape
    if kind == "uniform":
        return rng.uniform(-5.0, 10.0, (BATCH, R, C))
    if kind == "integer":  # values 0..3: many ties and many optimal assignments
        return rng.integers(0, 4, (BATCH, R, C)).astype(float)
    if kind == "inf":  # 35% forbidden pairs; some cases have no complete finite assignment
        c = rng.uniform(0.0, 10.0, (BATCH, R, C))
        return np.where(rng.random((BATCH, R, C)) < 0.35, np.inf, c)
    if kind == "forbidden_rows":  # one or two rows all +inf (every other case also a column)
        c = rng.integers(0, 6, (BATCH, R, C)).astype(float)
        c = np.where(rng.random((BATCH, R, C)) < 0.2, np.inf, c)
        for b in range(BATCH):
            c[b, rng.choice(R, size=1 + b % 2, replace=False)] = np.inf
            if b % 2:
                c[b, :, rng.integers(C)] = np.inf
        return c
    raise ValueError(kind)


def _scipy_reference(c):
    """SciPy's optimum of the maximum-cardinality, then minimum-cost matching of finite pairs.

    SciPy raises "cost matrix is infeasible" when no complete finite assignment exists, so the
    problem is made feasible by R dummy columns of cost BIG (each row may always take one): with
    BIG larger than any possible saving on the real pairs (costs in [−5, 10], ≤ 7 pairs), SciPy
    uses as few dummies as possible (= the largest matching of finite pairs) and, among those,
    the cheapest. Returns (optimal cost of the real pairs, number of real pairs).
    """
    R, C = c.shape
    big = 1e4
    aug = np.hstack([c, np.full((R, R), big)])
    rows, cols = scipy.optimize.linear_sum_assignment(aug)
    real = cols < C
    return float(c[rows[real], cols[real]].sum()), int(real.sum())


@pytest.mark.parametrize("shape", [(5, 5), (4, 7), (7, 4)])
def test_linear_assignment_matches_scipy(shape):
    rng = np.random.default_rng(20261205 + shape[0] * 10 + shape[1])
    kinds = ["uniform", "integer", "inf", "forbidden_rows"]
    costs = np.concatenate([_random_costs(rng, kind, shape) for kind in kinds])  # 400 matrices
    row_to_col, total = map(np.asarray, _assign(jnp.asarray(costs), jnp.ones(costs.shape, bool)))
    assert row_to_col.shape == (len(costs), shape[0]) and total.shape == (len(costs),)
    infeasible = 0
    for b, c in enumerate(costs):
        ref_cost, ref_pairs = _scipy_reference(c)
        r = row_to_col[b]
        assigned = np.flatnonzero(r >= 0)
        # A matching of allowed pairs, as large as SciPy's, and its reported cost is its own.
        assert len(set(r[assigned])) == len(assigned)
        assert np.all(np.isfinite(c[assigned, r[assigned]]))
        assert len(assigned) == ref_pairs
        assert total[b] == pytest.approx(c[assigned, r[assigned]].sum(), abs=1e-12)
        assert abs(total[b] - ref_cost) <= 1e-12, (b, total[b], ref_cost)
        if np.isfinite(c).all():  # the same problem as plain SciPy: same optimal cost
            rows, cols = scipy.optimize.linear_sum_assignment(c)
            assert abs(total[b] - c[rows, cols].sum()) <= 1e-12
        infeasible += ref_pairs < min(shape)
        # All-forbidden rows are never assigned.
        assert np.all(r[~np.isfinite(c).any(axis=1)] == -1)
    # The +inf kinds must exercise the infeasible branch (SciPy itself would raise there).
    assert infeasible >= 20


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_linear_assignment_optax_issue_1273(dtype):
    # google-deepmind/optax#1273: a 3×3 matrix on which the solver was reported to return
    # ([-1, -1, -1], [0, 1, 2]); scipy gives rows (0, 1, 2) → columns (1, 0, 2), cost 4.0446343.
    c = np.array([[2.1536477, 2.7017763, 2.0492606],
                  [0.8976828, 2.7900887, 1.3230644],
                  [0.8135518, 1.4669538, 0.44517508]], dtype)
    row_to_col, total = _assign_one(jnp.asarray(c))
    rows, cols = scipy.optimize.linear_sum_assignment(c)
    assert np.asarray(row_to_col).tolist() == cols.tolist() == [1, 0, 2]
    assert total.dtype == dtype
    assert float(total) == pytest.approx(float(c[rows, cols].sum()), rel=4 * float(np.finfo(dtype).eps))
    assert float(total) == pytest.approx(4.0446343, abs=1e-6)


def test_linear_assignment_valid_mask_and_edges():
    # Three small problems padded into the (4, 7) shape compiled above, padding given by `valid`
    # (padded entries hold attractive garbage, −100, that must not be used).
    c = np.array([[1.0, 2.0, 3.0], [4.0, 0.5, 6.0]])
    cost = np.full((3, 4, 7), -100.0)
    cost[:, :2, :3] = c
    masks = np.zeros((3, 4, 7), bool)
    masks[:, :2, :3] = True
    masks[0, 1, :] = False  # a padded row is never assigned
    masks[1, :, 0] = False  # a padded column is never used
    masks[2] = False  # nothing allowed
    # Tiled to the batch size of the (4, 7) case above, so the compiled program is reused.
    r, t = _assign(jnp.asarray(np.resize(cost, (4 * BATCH, 4, 7))), jnp.asarray(np.resize(masks, (4 * BATCH, 4, 7))))
    assert r[:3].tolist() == [[0, -1, -1, -1], [2, 1, -1, -1], [-1, -1, -1, -1]] and t[:3].tolist() == [1.0, 3.5, 0.0]
    r, t = _assign_one(jnp.zeros((2, 0)))
    assert r.tolist() == [-1, -1] and float(t) == 0.0


# ----------------------------------------------------------------------------------------- GNN

T_TRACKS, M_MEAS = 3, 4


def _random_log_weights(rng, n, T=T_TRACKS, M=M_MEAS, gate_prob=0.45):
    L = rng.normal(0.0, 2.0, (n, T, 1 + M))
    L[:, :, 1:] = np.where(rng.random((n, T, M)) < gate_prob, -np.inf, L[:, :, 1:])
    # Some tracks must be detected (P_D·P_G·r = 1 → missed weight 0): infeasible scans occur.
    L[:, :, 0] = np.where(rng.random((n, T)) < 0.3, -np.inf, L[:, :, 0])
    valid = rng.random((n, T)) < 0.85
    return L, valid


def _brute_force(L, valid):
    """The maximum-weight joint event by enumeration: (weight, columns per track or None)."""
    T, Mp1 = L.shape
    tracks = np.flatnonzero(valid)
    best, best_event = -np.inf, None
    for event in itertools.product(range(Mp1), repeat=len(tracks)):
        taken = [j for j in event if j > 0]
        if len(taken) != len(set(taken)):
            continue
        w = sum(L[t, j] for t, j in zip(tracks, event))
        if w > best:
            best, best_event = w, dict(zip(tracks, event))
    return best, best_event


def _check_association_shape(a, valid):
    beta = np.asarray(a.association_probabilities)
    assert np.all(beta[~valid] == 0.0)
    np.testing.assert_array_equal(beta[valid].sum(axis=1), 1.0)
    assert set(np.unique(beta)) <= {0.0, 1.0}
    np.testing.assert_array_equal(a.clutter_probabilities, 1.0 - beta[:, 1:].sum(axis=0))
    assert float(a.residual) == 0.0


def test_gnn_equals_brute_force():
    rng = np.random.default_rng(7)
    L, valid = _random_log_weights(rng, 300)
    out = _gnn(jnp.asarray(L), jnp.asarray(valid))
    infeasible = 0
    for b in range(len(L)):
        a = jax.tree.map(lambda x: np.asarray(x[b]), out)
        _check_association_shape(a, valid[b])
        best, event = _brute_force(L[b], valid[b])
        if not np.isfinite(best):  # no joint event with positive probability
            infeasible += 1
            assert not a.ok and a.log_normalizer == -np.inf
            continue
        assert a.ok
        assert abs(float(a.log_normalizer) - best) <= 1e-12
        expected = np.zeros_like(L[b])
        for t, j in event.items():
            expected[t, j] = 1.0  # continuous random weights: the best event is unique
        np.testing.assert_array_equal(a.association_probabilities, expected)
    assert 5 <= infeasible <= 150  # both branches exercised


def test_gnn_all_gated_out_is_all_missed():
    rng = np.random.default_rng(11)
    L = np.full((300, T_TRACKS, 1 + M_MEAS), -np.inf)
    L[:, :, 0] = np.log(1.0 - rng.uniform(0.1, 0.99, (300, T_TRACKS)))
    valid = rng.random((300, T_TRACKS)) < 0.8
    out = _gnn(jnp.asarray(L), jnp.asarray(valid))
    expected = np.zeros_like(L)
    expected[:, :, 0] = valid
    np.testing.assert_array_equal(out.association_probabilities, expected)
    np.testing.assert_array_equal(out.clutter_probabilities, 1.0)
    np.testing.assert_allclose(out.log_normalizer, np.where(valid, L[:, :, 0], 0.0).sum(axis=1), rtol=0, atol=1e-12)
    assert np.all(out.ok)


def test_gnn_padding_invariance():
    rng = np.random.default_rng(13)
    L, valid = _random_log_weights(rng, 300)
    base = _gnn(jnp.asarray(L), jnp.asarray(valid))
    # Two invalid tracks inserted at rows 1 and 3 holding finite garbage (even attractive
    # weights), and two padded measurement columns (−inf) appended: nothing may change.
    T2, M2 = T_TRACKS + 2, M_MEAS + 2
    rows = np.array([0, 2, 4])  # where the original tracks sit
    Lp = rng.normal(5.0, 1.0, (300, T2, 1 + M2))
    Lp[:, rows, : 1 + M_MEAS] = L
    Lp[:, rows, 1 + M_MEAS:] = -np.inf
    validp = np.zeros((300, T2), bool)
    validp[:, rows] = valid
    padded = _gnn(jnp.asarray(Lp), jnp.asarray(validp))
    beta = np.asarray(padded.association_probabilities)
    np.testing.assert_array_equal(beta[:, rows, : 1 + M_MEAS], base.association_probabilities)
    assert np.all(beta[:, [1, 3]] == 0.0) and np.all(beta[:, :, 1 + M_MEAS:] == 0.0)
    np.testing.assert_array_equal(padded.clutter_probabilities[:, :M_MEAS], base.clutter_probabilities)
    np.testing.assert_array_equal(padded.clutter_probabilities[:, M_MEAS:], 1.0)
    np.testing.assert_allclose(padded.log_normalizer, base.log_normalizer, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(padded.ok, base.ok)


# ------------------------------------------------------------------------------- gates and L


def test_gate_threshold():
    assert gate_threshold(0.99, 2) == pytest.approx(scipy.stats.chi2.ppf(0.99, 2), rel=1e-15)
    assert gate_threshold(0.95, 3) == pytest.approx(7.814727903251178, rel=1e-12)
    assert gate_threshold(1.0, 2) == math.inf
    for bad in (0.0, -0.1, 1.5, float("nan")):
        with pytest.raises(InputError, match="prob_gate"):
            gate_threshold(bad, 2)
    with pytest.raises(InputError, match="meas_dim"):
        gate_threshold(0.9, 0)


def test_log_likelihood_ratios_by_hand():
    loglik = np.array([[-3.0, -7.5, np.nan], [-4.0, -2.5, -1.0]])
    nis = np.array([[1.0, 12.0, np.nan], [9.0, 0.5, 0.2]])
    pd, lam, pg, r = np.array([0.9, 0.8]), 1e-3, 0.99, np.array([1.0, 0.5])
    gamma = gate_threshold(pg, 2)  # 9.2103…: nis 12 is outside, 9 inside
    all_valid = jnp.array([True, True, True])

    @jax.jit  # one compilation for the three calls; P_D, λ, P_G, r are traced
    def weights(pd, lam, pg, r, pd_scalar, pd_bad):
        gated = log_likelihood_ratios(
            jnp.asarray(loglik), jnp.asarray(nis), jnp.array([True, True]), jnp.array([True, True, False]),
            prob_detect=pd, clutter_density=lam, gate_threshold=gamma, prob_gate=pg, existence=r)
        # An invalid track is neutral: [0, −inf, …]; without a gate (default) nis 12 is taken.
        ungated, _ = log_likelihood_ratios(jnp.asarray(loglik), jnp.asarray(nis), jnp.array([False, True]),
                                           all_valid, prob_detect=pd_scalar, clutter_density=lam)
        # Traced, a bad value cannot raise: it becomes NaN (so `ok` is False downstream).
        bad, _ = log_likelihood_ratios(jnp.asarray(loglik), jnp.asarray(nis), jnp.array([True, True]),
                                       all_valid, prob_detect=pd_bad, clutter_density=lam)
        return gated, ungated, bad

    (L, in_gate), L2, L3 = weights(pd, lam, pg, r, 0.9, 1.2)
    ninf = -np.inf
    expected = np.array([
        [math.log1p(-0.9 * 0.99), math.log(0.9) - 3.0 - math.log(1e-3), ninf, ninf],
        [math.log1p(-0.5 * 0.8 * 0.99), math.log(0.8) + math.log(0.5) - 4.0 - math.log(1e-3),
         math.log(0.8) + math.log(0.5) - 2.5 - math.log(1e-3), ninf],
    ])
    # rtol 1e-14, not 1e-15: XLA's CPU log1p is a few ulp off (here 8e-15 relative at 1 − 0.396).
    np.testing.assert_allclose(L, expected, rtol=1e-14, atol=0)
    np.testing.assert_array_equal(in_gate, [[True, False, False], [True, True, False]])
    np.testing.assert_array_equal(L2[0], [0.0, ninf, ninf, ninf])
    assert float(L2[1, 0]) == pytest.approx(math.log1p(-0.9), rel=1e-14)
    assert float(L2[1, 3]) == pytest.approx(math.log(0.9) - 1.0 - math.log(1e-3), rel=1e-15)
    assert np.isnan(np.asarray(L3)[:, 0]).all()
    # Concrete values out of range raise, naming the argument.
    for name, kwargs in [("prob_detect", dict(prob_detect=1.2, clutter_density=lam)),
                         ("clutter_density", dict(prob_detect=0.9, clutter_density=0.0)),
                         ("existence", dict(prob_detect=0.9, clutter_density=lam, existence=-0.1)),
                         ("prob_gate", dict(prob_detect=0.9, clutter_density=lam, prob_gate=0.0))]:
        with pytest.raises(InputError, match=name):
            log_likelihood_ratios(jnp.asarray(loglik), jnp.asarray(nis), jnp.array([True, True]), all_valid, **kwargs)


def _scan(seed, T=2, M=5):
    """Two tracks of a 2-D constant-velocity model and a scan with padded (NaN) measurements."""
    rng = np.random.default_rng(seed)
    model = constant_velocity(1.0, dim=2, accel_psd=0.5, measurement_std=2.0, initial_cov=np.eye(4) * 10.0)
    means = rng.normal(0.0, 5.0, (T, 4))
    G = rng.normal(size=(T, 4, 4))
    covs = G @ np.swapaxes(G, 1, 2) + 2.0 * np.eye(4)
    z = rng.normal(0.0, 6.0, (M, 2))
    valid = np.ones(M, bool)
    valid[[1, 4]] = False
    z[~valid] = np.nan
    return model, means, covs, z, valid


def test_measurement_likelihoods_kalman_equals_gaussian_density():
    model, means, covs, z, valid = _scan(3)
    H, R = np.asarray(model.H), np.asarray(model.R)
    loglik, nis, cond = jax.jit(jax.vmap(
        lambda x, P: measurement_likelihoods(KalmanFilter(), model, x, P, jnp.asarray(z), jnp.asarray(valid), 0)
    ))(jnp.asarray(means), jnp.asarray(covs))
    assert loglik.shape == nis.shape == (2, 5) and cond.mean.shape == (2, 5, 4)
    assert all(np.isfinite(leaf).all() for leaf in jax.tree.leaves(cond))
    for t, (x, P) in enumerate(zip(means, covs)):
        S = H @ P @ H.T + R
        ref = scipy.stats.multivariate_normal(H @ x, S)
        y = z[valid] - H @ x
        np.testing.assert_allclose(loglik[t, valid], ref.logpdf(z[valid]), rtol=0, atol=1e-12)
        np.testing.assert_allclose(nis[t, valid], np.einsum("ij,ij->i", y, np.linalg.solve(S, y.T).T),
                                   rtol=1e-12, atol=1e-12)
        assert np.all(np.asarray(loglik[t])[~valid] == -np.inf) and np.all(np.asarray(nis[t])[~valid] == np.inf)
        np.testing.assert_allclose(cond.innovation_cov[t, 0], S, rtol=1e-13)


def test_padded_nan_measurements_leave_values_and_gradients_finite():
    model, means, covs, z, valid = _scan(5)
    gamma = gate_threshold(0.999, 2)

    def scan_score(pd, lam, means):
        loglik, nis, _ = jax.vmap(
            lambda x, P: measurement_likelihoods(KalmanFilter(), model, x, P, jnp.asarray(z), jnp.asarray(valid), 0)
        )(means, jnp.asarray(covs))
        L, in_gate = log_likelihood_ratios(loglik, nis, jnp.ones(2, bool), jnp.asarray(valid), prob_detect=pd,
                                           clutter_density=lam, gate_threshold=gamma, prob_gate=0.999)
        # A PDA-style normaliser per track plus the GNN best event: both read every column.
        return jnp.sum(jax.nn.logsumexp(L, axis=1)) + GNN()(L).log_normalizer, (L, in_gate)

    pd, lam = 0.85, 2e-3
    value_and_grad = jax.jit(jax.value_and_grad(scan_score, argnums=(0, 1, 2), has_aux=True))
    (value, (L, in_gate)), grads = value_and_grad(pd, lam, jnp.asarray(means))
    assert np.asarray(in_gate).sum() >= 3  # detections take part, not only misses
    assert np.isfinite(value) and all(np.isfinite(g).all() for g in grads)  # also ∂/∂ track means
    assert not np.isnan(np.asarray(L)).any()
    assert np.all(np.asarray(L)[:, 1:][:, ~valid] == -np.inf)
    # The gradients are the derivatives (central differences, relative step 1e-6).
    for i, (x, h) in enumerate([(pd, 1e-6), (lam, 2e-9)]):
        args_p, args_m = [pd, lam, jnp.asarray(means)], [pd, lam, jnp.asarray(means)]
        args_p[i], args_m[i] = x + h, x - h
        fd = (value_and_grad(*args_p)[0][0] - value_and_grad(*args_m)[0][0]) / (2 * h)
        assert float(grads[i]) == pytest.approx(float(fd), rel=1e-6)


def test_measurement_likelihoods_any_filter_and_angle_wrapping():
    # A range–bearing track seen near bearing ±π: the model's residual wraps the innovation, so a
    # bearing written as −π + 0.003 or π + 0.003 is the same measurement (NIS ≈ 0.32, not ~10⁵).
    model = TrackingModel(ConstantVelocity(1.0, noise_intensity=0.1), RangeBearing(noise_std=[1.0, 0.01]),
                          jnp.array([-100.0, 1.0, 0.0, 0.0]), jnp.eye(4))
    x, P = jnp.array([-100.0, 0.5, 0.0, 0.0]), jnp.eye(4)
    z = jnp.array([[100.0, -np.pi + 0.003], [100.0, np.pi + 0.003], [np.nan, np.nan]])
    valid = jnp.array([True, True, False])
    lin, means, covs, zs, valid_s = _scan(3)

    @jax.jit  # one compilation for the three filters
    def run(x, P, xl, Pl, zl, vl):
        ukf = measurement_likelihoods(UnscentedKalmanFilter(), model, x, P, z, valid, 0)
        kf = measurement_likelihoods(KalmanFilter(), lin, xl, Pl, zl, vl, 0)
        sr = measurement_likelihoods(SquareRootKalmanFilter(), lin, xl, jnp.linalg.cholesky(Pl), zl, vl, 0)
        return ukf[:2], kf[:2], sr[:2]

    (loglik, nis), kf, sr = run(x, P, jnp.asarray(means[0]), jnp.asarray(covs[0]), jnp.asarray(zs), jnp.asarray(valid_s))
    np.testing.assert_allclose(loglik[0], loglik[1], rtol=1e-12)
    assert 0.1 < float(nis[0]) < 1.0 and np.isfinite(np.asarray(loglik[:2])).all()
    # A square-root filter carries Cholesky factors (P and S): same likelihoods and NIS as the KF.
    np.testing.assert_allclose(sr[0], kf[0], rtol=1e-12)
    np.testing.assert_allclose(sr[1], kf[1], rtol=1e-12)


def test_gnn_pipeline_matches_stone_soup_gnn_with_2d_assignment():
    # Stone Soup's GNNWith2DAssignment on the same augmented layout, with distances −L: a
    # DistanceHypothesiser whose measure is −log(P_D N(z; ẑ, S)/λ) and whose missed distance is
    # −log(1 − P_D P_G), behind a Mahalanobis gate √γ. (With probability hypotheses Stone Soup
    # would maximise a sum of probabilities, not of log weights, so distances are used.) Tracks
    # sit at the detections' time, so Stone Soup's prediction (dt = 0) is the identity.
    import datetime

    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.gater.distance import DistanceGater
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.measures import Mahalanobis, Measure
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel
    from stonesoup.models.transition.linear import ConstantVelocity as SSConstantVelocity
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import KalmanUpdater

    pd, pg, lam = 0.9, 0.99, 1e-3
    gamma = gate_threshold(pg, 2)

    class NegLogLikelihoodRatio(Measure):
        def __call__(self, prediction, detection):
            z, zhat = np.ravel(detection.state_vector), np.ravel(prediction.state_vector)
            return -(math.log(pd) + scipy.stats.multivariate_normal(zhat, np.asarray(prediction.covar)).logpdf(z)
                     - math.log(lam))

    t0 = datetime.datetime(2026, 1, 1)
    ss_model = LinearGaussian(ndim_state=4, mapping=(0, 1), noise_covar=np.diag([4.0, 4.0]))  # = constant_velocity's H, R
    predictor = KalmanPredictor(CombinedLinearGaussianTransitionModel([SSConstantVelocity(0.1)] * 2))
    hypothesiser = DistanceHypothesiser(predictor, KalmanUpdater(ss_model), NegLogLikelihoodRatio(),
                                        missed_distance=-math.log1p(-pd * pg), include_all=True)
    ss_gnn = GNNWith2DAssignment(DistanceGater(hypothesiser, Mahalanobis(), gate_threshold=math.sqrt(gamma)))

    model = constant_velocity(1.0, dim=2, accel_psd=0.5, measurement_std=2.0, initial_cov=np.eye(4))
    rng = np.random.default_rng(17)
    S_, T, M = 20, 3, 4
    means = rng.normal(0.0, 3.0, (S_, T, 4))
    covs = np.broadcast_to(np.eye(4) * 2.0, (S_, T, 4, 4))
    zs = rng.normal(0.0, 7.0, (S_, M, 2))

    @jax.jit
    @jax.vmap
    def ours(means, covs, z):
        valid = jnp.ones(M, bool)
        loglik, nis, _ = jax.vmap(lambda x, P: measurement_likelihoods(KalmanFilter(), model, x, P, z, valid, 0))(means, covs)
        L, _ = log_likelihood_ratios(loglik, nis, jnp.ones(T, bool), valid, prob_detect=pd, clutter_density=lam,
                                     gate_threshold=gamma, prob_gate=pg)
        return GNN()(L).association_probabilities

    beta = np.asarray(ours(jnp.asarray(means), jnp.asarray(covs), jnp.asarray(zs)))
    detected = 0
    for s in range(S_):
        tracks = [Track([GaussianState(m.reshape(-1, 1), c, timestamp=t0)]) for m, c in zip(means[s], covs[s])]
        dets = [Detection(z.reshape(-1, 1), timestamp=t0, measurement_model=ss_model) for z in zs[s]]
        hypotheses = ss_gnn.associate(set(tracks), set(dets), t0)
        expected = np.zeros((T, 1 + M))
        for t, track in enumerate(tracks):
            h = hypotheses[track]
            expected[t, 1 + dets.index(h.measurement) if h else 0] = 1.0
        np.testing.assert_array_equal(beta[s], expected, err_msg=f"scenario {s}")
        detected += int(expected[:, 1:].sum())
    assert 15 <= detected <= 45  # detections and misses both occur

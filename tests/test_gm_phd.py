"""The GM-PHD filter (Vo & Ma 2006) with a fixed component budget: Stone Soup's GM-PHD as an
oracle, the closed-form one-step update, the overflow flag, a gradient and the input checks.

Two shapes only (the Stone Soup scenario; one small case shared by the other tests), so the
file compiles ``run_phd`` five times (three forward programs: the Stone Soup scenario, the small
case with each reduction; one gradient per reduction), and Stone Soup's merging twice more on its
own (its fast and its loop form)."""

from datetime import datetime, timedelta

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.filters import KalmanFilter
from jaxtrack.models import LinearGaussianModel
from _multitarget_cases import new_style
from jaxtrack.multitarget import GMPHD, CapacityWarning, GaussianMixture, StoneSoupReduction, run_phd

# ---------------------------------------------------------------- the Stone Soup scenario
# Stone Soup's state order (x, vx, y, vy); its CV model with q = 0.3 m²/s³, dt = 1 s.
SS_T, SS_M = 50, 12
SS_PD, SS_PS = 0.9, 0.99
SS_CLUTTER_RATE, SS_AREA = 3.0, 200.0**2
SS_KAPPA = SS_CLUTTER_RATE / SS_AREA
SS_PRUNE, SS_MERGE = 1e-6, 5.0
SS_CAPACITY = 60
SS_BIRTH_W = 0.25
SS_BIRTH_M = np.array([0.0, 0.0, 0.0, 0.0])
SS_BIRTH_P = np.diag([80.0, 2.0, 80.0, 2.0]) ** 2


def _stonesoup_models():
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )

    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(0.3), ConstantVelocity(0.3)])
    measurement = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=np.diag([0.75, 0.75]))
    return transition, measurement


def _scenario(seed=3):
    """Four targets over 50 scans (two born late, one dies), P_D misses and Poisson clutter."""
    transition, measurement = _stonesoup_models()
    rng = np.random.default_rng(seed)
    F = transition.matrix(time_interval=timedelta(seconds=1))
    Q = transition.covar(time_interval=timedelta(seconds=1))
    H, R = measurement.matrix(), measurement.covar()
    starts = [np.array([-60.0, 1.0, -40.0, 1.2]), np.array([50.0, -1.1, 30.0, 0.2]),
              np.array([0.0, 0.5, 60.0, -1.3]), np.array([-20.0, 0.8, -70.0, 0.9])]
    life = [(0, 50), (0, 35), (10, 50), (20, 50)]
    states = [s.copy() for s in starts]
    z = np.full((SS_T, SS_M, 2), np.nan)
    valid = np.zeros((SS_T, SS_M), bool)
    for k in range(SS_T):
        scan = []
        for i, (b, d) in enumerate(life):
            if k > b:
                states[i] = F @ states[i] + rng.multivariate_normal(np.zeros(4), Q)
            if b <= k < d and rng.random() < SS_PD:
                scan.append(H @ states[i] + rng.multivariate_normal(np.zeros(2), R))
        for _ in range(rng.poisson(SS_CLUTTER_RATE)):
            scan.append(rng.uniform(-100.0, 100.0, 2))
        assert len(scan) <= SS_M
        if scan:
            z[k, : len(scan)] = np.asarray(scan)
            valid[k, : len(scan)] = True
    return z, valid, (F, Q, H, R)


# A time-0 intensity for the first two targets (jaxtrack's `initial_*`; in Stone Soup the mixture
# the loop starts from, one step before the first scan), in Stone Soup's state order.
SS_INITIAL_W = np.array([0.9, 0.7])
SS_INITIAL_M = np.array([[-61.0, 1.0, -41.0, 1.2], [51.0, -1.0, 30.0, 0.2]])
SS_INITIAL_P = np.broadcast_to(np.diag([10.0, 1.0, 10.0, 1.0]) ** 2, (2, 4, 4))


def _stonesoup_phd(z, valid, gate=None, initial=False):
    """Stone Soup's GM-PHD as in its tutorial: the GM hypothesiser over a distance hypothesiser
    (``include_all=True`` without a ``gate``), ``PHDUpdater``, ``GaussianMixtureReducer``; the birth
    component (tag "birth") joins the reduced mixture at each scan's time. ``initial``: the loop
    starts from the ``SS_INITIAL_*`` mixture, timed one step before the first scan."""
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.gaussianmixture import GaussianMixtureHypothesiser
    from stonesoup.measures import Mahalanobis
    from stonesoup.mixturereducer.gaussianmixture import GaussianMixtureReducer
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import TaggedWeightedGaussianState
    from stonesoup.updater.kalman import KalmanUpdater
    from stonesoup.updater.pointprocess import PHDUpdater

    transition, measurement = _stonesoup_models()
    kalman = KalmanUpdater(measurement)
    base = DistanceHypothesiser(KalmanPredictor(transition), kalman, Mahalanobis(),
                                missed_distance=3 if gate is None else gate, include_all=gate is None)
    hypothesiser = GaussianMixtureHypothesiser(base, order_by_detection=True)
    updater = PHDUpdater(kalman, clutter_spatial_density=SS_KAPPA, prob_detection=SS_PD, prob_survival=SS_PS)
    reducer = GaussianMixtureReducer(prune_threshold=SS_PRUNE, merge_threshold=SS_MERGE)
    start = datetime(2026, 1, 1)
    reduced, history = [], []
    if initial:
        reduced = [TaggedWeightedGaussianState(state_vector=m.reshape(4, 1), covar=P, weight=w,
                                               timestamp=start - timedelta(seconds=1))
                   for w, m, P in zip(SS_INITIAL_W, SS_INITIAL_M, SS_INITIAL_P)]
    for k in range(z.shape[0]):
        t = start + timedelta(seconds=k)
        birth = TaggedWeightedGaussianState(state_vector=SS_BIRTH_M, covar=SS_BIRTH_P, weight=SS_BIRTH_W,
                                            tag=TaggedWeightedGaussianState.BIRTH, timestamp=t)
        detections = [Detection(zj, timestamp=t, measurement_model=measurement) for zj in z[k][valid[k]]]
        hypotheses = hypothesiser.hypothesise(reduced + [birth], detections, t, order_by_detection=True)
        reduced = list(reducer.reduce(list(updater.update(hypotheses))))
        history.append((np.array([float(c.weight) for c in reduced]),
                        np.array([np.asarray(c.state_vector, float).ravel() for c in reduced]).reshape(-1, 4),
                        np.array([np.asarray(c.covar, float) for c in reduced]).reshape(-1, 4, 4)))
    return history


def _sorted(w, m, P):
    order = np.argsort(-w, kind="stable")
    return w[order], m[order], P[order]


def _matched(a, b):
    """``b`` reordered to match ``a`` component by component (weights capped at 1 tie, so sorting
    by weight alone would pair different components): an assignment on weight and mean."""
    from scipy.optimize import linear_sum_assignment

    cost = np.abs(a[0][:, None] - b[0][None, :]) + np.abs(a[1][:, None, :] - b[1][None, :, :]).sum(-1)
    _, cols = linear_sum_assignment(cost)
    return tuple(x[cols] for x in b)


@pytest.mark.parametrize("gate, initial", [(None, False), (3.0, False), (None, True)])
def test_equals_stonesoup_gm_phd(gate, initial):
    """50 scans against Stone Soup's GM-PHD, without a gate and with its tutorial's
    ``missed_distance=3`` (one compiled program: the gate is an array leaf), and from a time-0
    intensity (``initial_*``: two components, predicted into the first scan like any survivor)."""
    pytest.importorskip("stonesoup")
    z, valid, (F, Q, H, R) = _scenario()
    model = LinearGaussianModel(F, Q, H, R, SS_BIRTH_M, SS_BIRTH_P)
    start = dict(initial=GaussianMixture(SS_INITIAL_W, SS_INITIAL_M, SS_INITIAL_P)) if initial else {}
    phd = GMPHD(KalmanFilter(), model, prob_survival=SS_PS, prob_detect=SS_PD, clutter_density=SS_KAPPA,
                birth=GaussianMixture([SS_BIRTH_W], [SS_BIRTH_M], [SS_BIRTH_P]), capacity=SS_CAPACITY,
                reduction=StoneSoupReduction(SS_PRUNE, SS_MERGE), gate=np.inf if gate is None else gate, **start)
    result = run_phd(phd, z, valid)
    assert not bool(result.overflow)
    if initial:  # the start matters: by the first scan both targets are held with weight ~1
        assert float(result.cardinality[0]) > 1.5
        assert float(run_phd(eqx.tree_at(lambda f: f.initial, phd, None, is_leaf=lambda x: x is None),
                             z, valid).cardinality[0]) < 1.0
    reference = _stonesoup_phd(z, valid, gate, initial)
    worst = {"weight": 0.0, "mean": 0.0, "cov": 0.0}
    for k, (w_ss, m_ss, P_ss) in enumerate(reference):
        act = np.asarray(result.active[k])
        w, m, P = _sorted(np.asarray(result.weights[k])[act], np.asarray(result.means[k])[act],
                          np.asarray(result.covs[k])[act])
        assert w.shape == w_ss.shape, f"scan {k}: {w.shape[0]} components, Stone Soup {w_ss.shape[0]}"
        w_ss, m_ss, P_ss = _matched((w, m, P), (w_ss, m_ss, P_ss))
        worst["weight"] = max(worst["weight"], np.max(np.abs(w - w_ss), initial=0.0))
        worst["mean"] = max(worst["mean"], np.max(np.abs(m - m_ss), initial=0.0))
        worst["cov"] = max(worst["cov"], np.max(np.abs(P - P_ss) / (1.0 + np.abs(P_ss)), initial=0.0))
    print("largest differences over", len(reference), "scans:", worst)
    assert worst["weight"] <= 1e-10
    assert worst["mean"] <= 1e-10  # metres and m/s
    assert worst["cov"] <= 1e-10  # relative (1 + |P|)
    # The run was not trivial: targets were found and components merged.
    assert np.asarray(result.num_estimates)[-1] >= 2


# ---------------------------------------------------------------- one small shared case
# Every test below runs scans of the same shape (T = 4, M = 3) through GMPHDs that differ only in
# array leaves, so they share one compiled forward program.
DT = 1.0
F_CV = np.array([[1, DT, 0, 0], [0, 1, 0, 0], [0, 0, 1, DT], [0, 0, 0, 1.0]])
Q_CV = 0.1 * np.kron(np.eye(2), np.array([[DT**3 / 3, DT**2 / 2], [DT**2 / 2, DT]]))
H_CV = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
R_CV = np.diag([1.0, 1.5])
B_MEAN = np.array([1.0, 0.0, -2.0, 0.0])
B_COV = np.diag([25.0, 4.0, 16.0, 4.0])
SMALL_T, SMALL_M = 4, 3
SMALL = {"prob_survival": 0.95, "prob_detect": 0.8, "clutter_density": 1e-3, "birth_weights": [0.3],
             "birth_means": [B_MEAN], "birth_covs": [B_COV], "capacity": 8, "prune_threshold": 1e-12,
             "merge_threshold": 1e-6}
# Two targets near the birth mean and one clutter point: merges happen, nothing overflows.
TWO_TARGETS = [[[2.0, -1.0], [-6.0, 4.0]], [[3.1, -0.8]], [[4.0, -0.5], [-7.5, 4.9], [9.0, 9.0]],
               [[5.2, -0.1], [-8.4, 5.6]]]


def _small(**kwargs):
    model = LinearGaussianModel(F_CV, Q_CV, H_CV, R_CV, B_MEAN, B_COV)
    return GMPHD(KalmanFilter(), model, **new_style({**SMALL, **kwargs}))


def _scans(points):
    """Padded (4, 3, 2) scans from a list of up to 4 lists of 2-vectors (later scans empty)."""
    z = np.full((SMALL_T, SMALL_M, 2), np.nan)
    valid = np.zeros((SMALL_T, SMALL_M), bool)
    for k, scan in enumerate(points):
        for j, p in enumerate(scan):
            z[k, j], valid[k, j] = p, True
    return z, valid


def _vo_ma_reference(z, valid, *, ps, pd, kappa, T, U, J_max):
    """Vo & Ma (2006) Tables I-II transcribed with lists (standard-form Kalman update), with this
    library's budget: at most J_max merging passes, the rest left over."""
    comps = []
    for k in range(z.shape[0]):
        pred = [(ps * w, F_CV @ m, F_CV @ P @ F_CV.T + Q_CV) for w, m, P in comps]
        pred.append((SMALL['birth_weights'][0], B_MEAN, B_COV))
        out = [((1 - pd) * w, m, P) for w, m, P in pred]
        for zj in z[k][valid[k]]:
            terms = []
            for w, m, P in pred:
                S = H_CV @ P @ H_CV.T + R_CV
                K = P @ H_CV.T @ np.linalg.inv(S)
                y = zj - H_CV @ m
                q = np.exp(-0.5 * y @ np.linalg.solve(S, y)) / np.sqrt(np.linalg.det(2 * np.pi * S))
                terms.append((pd * w * q, m + K @ y, (np.eye(4) - K @ H_CV) @ P))
            den = kappa + sum(t[0] for t in terms)
            out += [(t[0] / den, t[1], t[2]) for t in terms]
        rest = [c for c in out if c[0] > T]
        comps = []
        while rest and len(comps) < J_max:
            j = int(np.argmax([c[0] for c in rest]))
            mj = rest[j][1]
            close = [(c[1] - mj) @ np.linalg.solve(c[2], c[1] - mj) <= U for c in rest]
            group = [c for c, f in zip(rest, close) if f]
            w = sum(c[0] for c in group)
            m = sum(c[0] * c[1] for c in group) / w
            P = sum(c[0] * (c[2] + np.outer(m - c[1], m - c[1])) for c in group) / w
            comps.append((w, m, P))
            rest = [c for c, f in zip(rest, close) if not f]
    return comps


def test_one_step_matches_closed_form_update():
    """Table II for one birth component, one measurement: missed ``(1 − P_D) w`` at the prior and
    ``P_D w q / (κ + P_D w q)`` at the Kalman update."""
    pd, kappa, w = 0.8, 1e-3, 0.3
    zk = np.array([3.0, -1.0])
    z, valid = _scans([[zk]])
    result = run_phd(_small(), z, valid)
    S = H_CV @ B_COV @ H_CV.T + R_CV
    y = zk - H_CV @ B_MEAN
    q = np.exp(-0.5 * y @ np.linalg.solve(S, y)) / np.sqrt(np.linalg.det(2 * np.pi * S))
    K = B_COV @ H_CV.T @ np.linalg.inv(S)
    m_upd = B_MEAN + K @ y
    P_upd = (np.eye(4) - K @ H_CV) @ B_COV
    w_det = pd * w * q / (kappa + pd * w * q)
    w_miss = (1 - pd) * w
    act = np.asarray(result.active[0])
    assert act.sum() == 2
    got = _sorted(np.asarray(result.weights[0])[act], np.asarray(result.means[0])[act],
                  np.asarray(result.covs[0])[act])
    want = _sorted(np.array([w_miss, w_det]), np.stack([B_MEAN, m_upd]), np.stack([B_COV, P_upd]))
    for a, b in zip(got, want):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(result.cardinality[0], w_miss + w_det, rtol=1e-12)
    np.testing.assert_allclose(result.updated_cardinality[0], w_miss + w_det, rtol=1e-12)
    # Extraction (Table III): one estimate, at the detected component, when w_det > 0.5.
    assert w_det > 0.5
    assert int(result.num_estimates[0]) == 1 and np.asarray(result.estimate_mask[0]).sum() == 1
    np.testing.assert_allclose(result.estimates[0, 0], m_upd, rtol=1e-12)


def test_multi_step_matches_vo_ma_transcription():
    """Four scans with merging (U = 4) against the list transcription of Tables I-II."""
    z, valid = _scans(TWO_TARGETS)
    result = run_phd(_small(merge_threshold=4.0, prune_threshold=1e-4), z, valid)
    assert not bool(result.overflow)
    ref = _vo_ma_reference(z, valid, ps=0.95, pd=0.8, kappa=1e-3, T=1e-4, U=4.0, J_max=8)
    act = np.asarray(result.active[-1])
    assert act.sum() == len(ref) >= 2
    # Slots are filled in decreasing seed weight, as the transcription emits them.
    np.testing.assert_allclose(np.asarray(result.weights[-1])[act], [c[0] for c in ref], rtol=1e-12)
    np.testing.assert_allclose(np.asarray(result.means[-1])[act], [c[1] for c in ref], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(result.covs[-1])[act], [c[2] for c in ref], rtol=1e-11, atol=1e-12)
    assert np.asarray(result.updated_cardinality[-1]) > np.asarray(result.cardinality[-1])  # pruning


def test_budget_overflow_is_flagged():
    """Capacity 8 without merging (U ≈ 0, T ≈ 0): the third scan updates 9 predicted components
    on 3 measurements, (1 + 3)·9 = 36 components for 8 slots."""
    z, valid = _scans(TWO_TARGETS)
    with pytest.warns(CapacityWarning, match="capacity"):
        result = run_phd(_small(prune_threshold=1e-300, merge_threshold=1e-12), z, valid)
    assert bool(result.overflow)
    assert int(np.sum(result.num_dropped)) > 0 and float(np.sum(result.dropped_weight)) > 0.0
    assert int(result.final.num_dropped) == int(np.sum(result.num_dropped))
    assert np.all(np.asarray(result.active).sum(axis=1)[2:] == 8)
    # Nothing is lost in silence: kept + dropped weight is what the reduction received.
    kept = np.asarray(result.cardinality)
    np.testing.assert_allclose(kept + np.asarray(result.dropped_weight), result.updated_cardinality, rtol=1e-12)
    # The same run without `warn` is silent, and the flag is still set.
    assert bool(run_phd(_small(prune_threshold=1e-300, merge_threshold=1e-12), z, valid, warn=False).overflow)


@pytest.mark.parametrize("reduction", ["vo-ma", "stonesoup"])
def test_gradient_matches_central_differences(reduction):
    """d(final expected cardinality)/d(P_D, κ, birth weight) through predict, update and the
    merging passes, on scans where no prune or merge decision flips within ±h. With Stone Soup's
    reduction the forward pass is the fast ``while_loop`` merge and the derivatives those of its
    loop form (a ``custom_jvp``), so reverse mode works there too."""
    z, valid = _scans(TWO_TARGETS)

    def run(pd, kappa, bw):
        phd = _small(prob_detect=pd, clutter_density=kappa, birth_weights=jnp.reshape(bw, (1,)),
                     merge_threshold=4.0, prune_threshold=1e-4, reduction=reduction)
        return run_phd(phd, z, valid, warn=False)

    x0 = (0.8, 1e-3, 0.3)
    grads = jax.grad(lambda *x: run(*x).cardinality[-1], argnums=(0, 1, 2))(*map(jnp.asarray, x0))
    for i, g in enumerate(grads):
        h = 1e-6 * x0[i]
        plus = run(*[x + (h if j == i else 0.0) for j, x in enumerate(x0)])
        minus = run(*[x - (h if j == i else 0.0) for j, x in enumerate(x0)])
        assert np.array_equal(np.asarray(plus.active), np.asarray(minus.active))
        fd = (float(plus.cardinality[-1]) - float(minus.cardinality[-1])) / (2 * h)
        assert abs(float(g) - fd) <= 1e-6 * abs(fd), (i, float(g), fd)


def _merge_inputs(seed, K=300, n=2):
    """``K`` candidates (more than two of the fast merge's chunks), in clusters so that merges
    happen (and merged weights reach the cap of 1), some weights tied, some not kept."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-20.0, 20.0, (40, n))
    means = centres[rng.integers(0, 40, K)] + rng.normal(0.0, 0.7, (K, n))
    A = rng.normal(0.0, 0.6, (K, n, n))
    covs = A @ np.swapaxes(A, 1, 2) + 0.3 * np.eye(n)
    weights = rng.uniform(1e-3, 0.9, K)
    weights[10:20] = weights[5]  # ties: Stone Soup pops the later one
    keep = rng.random(K) < 0.9
    return weights, means, covs, keep


@pytest.mark.parametrize("capacity", [300, 40])
@pytest.mark.parametrize("reduction", ["stonesoup", "vo-ma"])
def test_fast_merge_equals_its_loop_form(reduction, capacity):
    """Both mergings: the fast ``while_loop`` form (what the filters run) against the fixed-loop
    form (its derivative rule) on 300 candidates in clusters (three of Table II's chunks), with
    room for every slot and with components left over (counted), one input and a vmapped batch
    of three. Stone Soup's merging is the same arithmetic in the same order (1e-13); Table II's
    fast form sums chunk by chunk (rounding only, 1e-13 too)."""
    from jaxtrack.multitarget._reduction import _merge_loops, _merge_stonesoup, _merge_vo_ma

    ss = reduction == "stonesoup"
    merge = _merge_stonesoup if ss else _merge_vo_ma
    U, free = jnp.asarray(4.0), (jnp.zeros(2), jnp.eye(2))
    fast = jax.jit(jax.vmap(lambda *a: merge(capacity, U, *free, *a)))
    loops = jax.jit(lambda *a: _merge_loops(capacity, ss, U, *free, *a))
    batch = [_merge_inputs(seed) for seed in range(3)]
    got = fast(*(jnp.asarray(np.stack(x)) for x in zip(*batch)))
    for i, inputs in enumerate(batch):
        want = loops(*map(jnp.asarray, inputs))
        w, m, P, a, n_drop, w_drop = (np.asarray(x[i]) for x in got)
        assert np.array_equal(a, np.asarray(want[3])) and int(n_drop) == int(want[4])
        assert a.sum() < capacity if capacity == 300 else (a.all() and n_drop > 0)
        if ss:
            assert np.max(w) == 1.0  # the cap was reached
        else:
            assert np.max(w) > 1.0  # Table II has no cap: clusters merged into one component
        np.testing.assert_allclose(w, want[0], rtol=1e-13, atol=0.0)
        np.testing.assert_allclose(m, want[1], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(P, want[2], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(w_drop, want[5], rtol=1e-13)


@pytest.mark.parametrize("reduction", ["stonesoup", "vo-ma"])
def test_batched_merge_runs_members_in_turn(reduction, monkeypatch):
    """Under ``jax.vmap`` on CPU the fast merging runs the batch's members one after another, each
    its own ``while_loop``: every member's values are its own unbatched call's, bit for bit, with
    components left over (capacity 40). The side-by-side form (the vmapped ``while_loop``, what
    other platforms run) agrees to rounding, and is the one traced when asked for (no ``scan``
    over the members)."""
    from jaxtrack.multitarget import _reduction

    merge = _reduction._merge_stonesoup if reduction == "stonesoup" else _reduction._merge_vo_ma
    U, free = jnp.asarray(4.0), (jnp.zeros(2), jnp.eye(2))
    batch = [_merge_inputs(seed) for seed in range(3)]
    stacked = tuple(jnp.asarray(np.stack(x)) for x in zip(*batch))

    def batched():
        return jax.vmap(lambda *a: merge(40, U, *free, *a))

    assert "scan" in str(jax.make_jaxpr(batched())(*stacked))
    in_turn = jax.jit(batched())(*stacked)
    monkeypatch.setattr(_reduction, "_BATCHED", "side-by-side")
    assert "scan" not in str(jax.make_jaxpr(batched())(*stacked))
    side = jax.jit(batched())(*stacked)
    single = jax.jit(lambda *a: merge(40, U, *free, *a))
    for i, inputs in enumerate(batch):
        want = single(*map(jnp.asarray, inputs))
        assert int(want[4]) > 0  # components left over
        for a, b, c in zip(in_turn, side, want):
            assert np.array_equal(np.asarray(a[i]), np.asarray(c))
            np.testing.assert_allclose(np.asarray(b[i]), np.asarray(c), rtol=1e-13, atol=1e-13)


def test_undetected_births_false_drops_the_birth_missed_term():
    """``undetected_births=False``: the first scan's updated intensity lacks exactly the birth
    component's missed-detection term ``(1 − P_D) w_b`` of Table I (nothing else changes)."""
    z, valid = _scans(TWO_TARGETS)
    keep, drop = (run_phd(_small(undetected_births=u), z, valid, warn=False) for u in (True, False))
    want = (1.0 - SMALL["prob_detect"]) * SMALL["birth_weights"][0]
    np.testing.assert_allclose(float(keep.updated_cardinality[0] - drop.updated_cardinality[0]), want, rtol=1e-13)
    with pytest.raises(InputError, match="undetected_births"):
        _small(undetected_births="no")


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"prob_detect": 1.5}, "prob_detect"),
        ({"prob_survival": 0.0}, "prob_survival"),
        ({"clutter_density": -1.0}, "clutter_density"),
        ({"birth_means": [[0.0, 0.0]], "birth_covs": [np.eye(2)]}, "birth"),  # a 2-state mixture, 4-state model
        ({"capacity": 0}, "capacity"),
        ({"gate": 0.0}, "gate"),
        ({"initial_weights": [0.1] * 9, "initial_means": [B_MEAN] * 9, "initial_covs": [B_COV] * 9}, "capacity"),
    ],
)
def test_bad_arguments_raise_input_error(kwargs, name):
    with pytest.raises(InputError, match=f"`{name}`"):
        _small(**kwargs)


@pytest.mark.parametrize(
    "args, name",
    [(([-0.1], [B_MEAN], [B_COV]), "weights"), (([0.1], [B_MEAN], [-B_COV]), "covs"),
     (([0.1], [B_MEAN[:2]], [B_COV]), "covs"), (([0.1, 0.2], [B_MEAN], [B_COV]), "means"),
     (([np.nan], [B_MEAN], [B_COV]), "weights")],
)
def test_a_bad_gaussian_mixture_names_its_argument(args, name):
    with pytest.raises(InputError, match=f"`{name}`"):
        GaussianMixture(*args)


def test_the_former_keywords_still_build_the_same_filter_with_a_warning():
    """``birth_weights=…``, ``prune_threshold=…``, ``reduction="stonesoup"`` (one release): a
    DeprecationWarning naming the new form, and the same filter; a bad value names the old keyword."""
    model = LinearGaussianModel(F_CV, Q_CV, H_CV, R_CV, B_MEAN, B_COV)
    old = dict(SMALL, reduction="stonesoup", initial_weights=[0.5], initial_means=[B_MEAN], initial_covs=[B_COV])
    with pytest.warns(DeprecationWarning, match="GaussianMixture|StoneSoupReduction"):
        legacy = GMPHD(KalmanFilter(), model, **old)
    new = GMPHD(KalmanFilter(), model, **new_style(old))
    assert eqx.tree_equal(legacy, new)
    assert isinstance(new.reduction, StoneSoupReduction) and float(new.reduction.prune_threshold) == 1e-12
    with pytest.warns(DeprecationWarning), pytest.raises(InputError, match="`birth_weights`"):
        GMPHD(KalmanFilter(), model, **dict(SMALL, birth_weights=[-0.1]))
    with pytest.raises(InputError, match="`reduction`"):
        GMPHD(KalmanFilter(), model, **dict(new_style(SMALL), reduction="greedy"))
    with pytest.raises(InputError, match="unexpected keyword"):
        GMPHD(KalmanFilter(), model, **dict(new_style(SMALL), prune_treshold=1e-3))


def test_bad_scans_raise_input_error():
    phd = _small()
    z, valid = _scans([[[0.0, 0.0]]])
    with pytest.raises(InputError, match="`measurements`"):
        run_phd(phd, np.zeros((1, SMALL_M, 3)), valid)
    with pytest.raises(InputError, match="`valid`"):
        run_phd(phd, z, valid[:, :2])
    with pytest.raises(InputError, match="`phd`"):
        run_phd(object(), z, valid)


def test_gospa_gradient_matches_central_differences():
    """d(Σ_k GOSPA_k)/d(P_D, κ, birth weight): the extracted estimates are merged means, weighted
    by the updated weights, so the GOSPA of a run is differentiable in the three wherever no prune,
    merge or extraction decision flips (checked: the same active slots and estimate masks at ±h)."""
    from jaxtrack.montecarlo import gospa

    z, valid = _scans(TWO_TARGETS)
    truth = jnp.asarray([[[2.0, -1.0], [-6.0, 4.0]], [[3.0, -0.8], [-7.0, 4.5]], [[4.0, -0.5], [-7.8, 5.0]],
                         [[5.0, -0.2], [-8.5, 5.5]]])

    def run(pd, kappa, bw):
        phd = _small(prob_detect=pd, clutter_density=kappa, birth_weights=jnp.reshape(bw, (1,)),
                     merge_threshold=4.0, prune_threshold=1e-4)
        r = run_phd(phd, z, valid, warn=False)
        g = jax.vmap(lambda x, y, m: gospa(x, jnp.ones(2, bool), y, m, cutoff=10.0).distance)(
            truth, r.estimates[..., jnp.array([0, 2])], r.estimate_mask)
        return jnp.sum(g), (r.active, r.estimate_mask)

    f = jax.jit(jax.value_and_grad(run, argnums=(0, 1, 2), has_aux=True))
    x0 = (0.8, 1e-3, 0.3)
    (_, aux), grads = f(*map(jnp.asarray, x0))
    assert int(np.sum(aux[1][-1])) == 2  # two estimates at the last scan
    assert max(abs(float(g)) for g in grads) > 1e-6
    for i, g in enumerate(grads):
        h = 1e-6 * x0[i]
        (plus, aux_p), _ = f(*[jnp.asarray(x + (h if j == i else 0.0)) for j, x in enumerate(x0)])
        (minus, aux_m), _ = f(*[jnp.asarray(x - (h if j == i else 0.0)) for j, x in enumerate(x0)])
        assert all(np.array_equal(np.asarray(a), np.asarray(b)) for a, b in zip(aux_p, aux_m))
        fd = (float(plus) - float(minus)) / (2 * h)
        assert abs(float(g) - fd) <= 1e-6 * max(abs(fd), 1e-3), (i, float(g), fd)

"""Per-run detections in ``monte_carlo``: each run draws its own missed detections from its own key.

Checked here: the results do not depend on the chunk size (1 vs 4 devices: ``test_sharding.py``,
cases ``kf_detect`` and ``ekf_detect`` of ``_sharded_cases.py``); run ``i``'s detections are those
of ``simulate(truth, fold_in(key, i), T, detection_probability=p)`` (replay); explicit per-run
masks give the same result as the equivalent draws; the NIS degrees of freedom and bounds follow
each run's detections (exact counts); the matched filter stays consistent; the detection rate is
``p``; ``covariance="shared"`` is refused.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.stats

from jaxtrack import InputError
from jaxtrack.filters import ExtendedKalmanFilter, KalmanFilter, run_filter
from jaxtrack.models import LinearGaussianModel, NonlinearGaussianModel, constant_velocity
from jaxtrack.montecarlo import monte_carlo, monte_carlo_sweep, normalized_squared_error, simulate
from jaxtrack.montecarlo import _run as mc_run

FIELDS = ("mse", "mean_error", "nees", "nees_std", "nees_bounds", "nis", "nis_dof", "nis_bounds", "anees",
          "anees_bounds")
P_D = 0.7
# One number of steps and of runs (block 512) wherever possible: every distinct shape or schedule
# structure is one more compilation, and compiling, not running, is what these tests spend.
T = 50
M = 300


def cv(accel_psd=0.5):
    """4-state 2-D constant velocity [x, y, vx, vy], position measurements (m = 2)."""
    prior = jnp.diag(jnp.asarray([100.0, 100.0, 10.0, 10.0]) ** 2)
    return constant_velocity(1.0, dim=2, accel_psd=accel_psd, measurement_std=10.0, initial_cov=prior)


FILTERS = {"kf": KalmanFilter(), "ekf": ExtendedKalmanFilter()}


def detections(model, key, num_runs=M, num_steps=T, p=P_D):
    """Every run's detections, (M, T), replayed one run at a time with simulate."""
    keys = jax.vmap(lambda i: jax.random.fold_in(key, i))(jnp.arange(num_runs))
    return np.asarray(jax.vmap(lambda k: simulate(model, k, num_steps, detection_probability=p).detected)(keys))


def assert_identical(a, b, label=""):
    assert (a.num_runs, a.num_failed) == (b.num_runs, b.num_failed), label
    for field in FIELDS:
        np.testing.assert_array_equal(np.asarray(getattr(a, field)), np.asarray(getattr(b, field)),
                                      err_msg=f"{label}: {field}")


@pytest.mark.parametrize("name", ["kf", "ekf"])
def test_chunk_size_does_not_change_the_results(name):
    # 1100 runs: three blocks of 512, the last one padded.
    key = jax.random.key(11)
    kw = dict(num_steps=T, filter=FILTERS[name], detection_probability=P_D, covariance="per_run", progress=False)
    results = [monte_carlo(cv(), key, 1100, chunk_size=c, **kw) for c in (1, 7, 2048)]
    for c, res in zip((7, 2048), results[1:]):
        assert_identical(res, results[0], f"chunk {c}")
    assert not results[0].shared_covariance
    # The comparison has teeth: another key changes the statistics.
    other = monte_carlo(cv(), jax.random.key(12), 1100, **kw)
    assert not np.array_equal(np.asarray(other.nis_dof), np.asarray(results[0].nis_dof))


def test_a_run_replays_with_simulate_and_its_detection_mask():
    """A 1-run Monte Carlo is simulate(fold_in(key, 0), detection_probability) then run_filter
    with the simulated detections as the mask: errors, NEES and NIS to 1e-12."""
    model, key = cv(), jax.random.key(7)
    filt = KalmanFilter()
    res = monte_carlo(model, key, 1, num_steps=T, filter=filt, detection_probability=P_D, progress=False)
    traj = simulate(model, jax.random.fold_in(key, 0), T, detection_probability=P_D)
    assert 0 < int(traj.detected.sum()) < T  # some steps missed, some detected
    out = run_filter(filt, model, traj.measurements, mask=traj.detected)
    err = traj.states - out.filtered_mean
    nees = jax.vmap(normalized_squared_error)(err, out.filtered_cov)
    nis = jax.vmap(normalized_squared_error)(out.innovation, out.innovation_cov)
    np.testing.assert_allclose(res.mean_error, err, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(res.mse, err**2, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(res.nees, nees, rtol=1e-12)
    np.testing.assert_allclose(res.nis, nis, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(res.nis_dof, 2.0 * np.asarray(traj.detected))
    # The detections do not change the simulated states and measurements.
    plain = simulate(model, jax.random.fold_in(key, 0), T)
    np.testing.assert_array_equal(plain.states, traj.states)
    np.testing.assert_array_equal(plain.measurements, traj.measurements)
    assert bool(jnp.all(plain.detected))


def test_every_run_of_a_block_draws_its_own_detections():
    """Run i (any block, any start) uses simulate(fold_in(key, i))'s detections: a block's
    schedule is a function of the key and the run indices only."""
    model, key = cv(), jax.random.key(5)
    common = mc_run._Common(KalmanFilter(), jnp.ones((T, 2), bool), "update", jnp.full((T,), P_D), None)
    obs = np.asarray(mc_run._block_observed(common, key, jnp.asarray(256), 64, jnp.float64))  # (T, 64, 2)
    expected = detections(model, key)[256:]  # runs 256 … 299 of the block's 64
    np.testing.assert_array_equal(obs[:, :44, 0].T, expected)
    np.testing.assert_array_equal(obs[..., 1], obs[..., 0])  # whole measurement vector missing together
    # Independent runs: the runs' masks differ (a shared draw would make every row the same).
    assert len({row.tobytes() for row in expected}) == 44


def test_matched_filter_is_consistent_and_detects_at_the_rate_p():
    model, M = cv(), 2000
    res = monte_carlo(model, jax.random.key(21), M, num_steps=T, detection_probability=P_D, progress=False)
    assert not res.shared_covariance and res.num_runs == M
    lo, hi = np.asarray(res.anees_bounds)
    assert lo < float(res.anees) < hi, (float(res.anees), lo, hi)
    # Innovations of the matched filter are white: Σ_k Σ_i NIS_ik ~ χ²(Σ_k D_k).
    total_dof = float(np.sum(res.nis_dof) * M)
    total_nis = float(np.sum(res.nis) * M)
    assert scipy.stats.chi2.ppf(0.0005, total_dof) < total_nis < scipy.stats.chi2.ppf(0.9995, total_dof)
    # Detections: M·T Bernoulli(p) draws, each of the two components counted.
    frac = float(np.mean(res.nis_dof)) / 2.0
    se = np.sqrt(P_D * (1 - P_D) / (M * T))
    assert abs(frac - P_D) < 4 * se, (frac, se)
    # Per step (M draws each) too: a draw shared by the runs would put every step at 0 or 1.
    per_step = np.asarray(res.nis_dof) / 2.0
    assert np.all(np.abs(per_step - P_D) < 5 * np.sqrt(P_D * (1 - P_D) / M)), per_step


def test_per_step_detection_probability():
    num_runs = 2000
    p = np.tile([0.2, 0.5, 1.0, 0.9, 0.35], T // 5)
    res = monte_carlo(cv(), jax.random.key(2), num_runs, num_steps=T, detection_probability=p, progress=False)
    frac = np.asarray(res.nis_dof) / 2.0
    assert np.all(np.abs(frac - p) < 4.5 * np.sqrt(p * (1 - p) / num_runs) + 1e-15), frac
    np.testing.assert_array_equal(frac[2::5], 1.0)  # P_D = 1: every run detects


def test_nis_dof_and_bounds_follow_the_exact_counts():
    """p = 0.5, m = 2: about one observed component per step on average; dof and bounds are
    those of the exact detection counts (replayed with simulate), a step no run observes (a gap
    in the shared mask) has dof 0 and bounds [0, 0]."""
    model, key = cv(), jax.random.key(8)
    gap = np.ones(T, bool)
    gap[4] = False
    res = monte_carlo(model, key, M, num_steps=T, mask=gap, detection_probability=0.5, confidence=0.9,
                      progress=False)
    det = detections(model, key, p=0.5) & gap
    total = 2.0 * det.sum(axis=0)  # Σ_i d_ik
    np.testing.assert_array_equal(np.asarray(res.nis_dof), total / M)
    assert abs(float(np.mean(np.delete(np.asarray(res.nis_dof), 4))) - 1.0) < 4 * np.sqrt(0.25 / (M * (T - 1))) * 2
    expected = np.stack([scipy.stats.chi2.ppf(0.05, total), scipy.stats.chi2.ppf(0.95, total)], -1) / M
    expected[4] = 0.0
    np.testing.assert_allclose(np.asarray(res.nis_bounds), expected, rtol=1e-12)
    assert res.nis_dof[4] == 0.0 and res.nis[4] == 0.0
    assert np.all(np.asarray(res.nis_bounds)[total > 0, 0] > 0)


def test_explicit_per_run_masks_equal_the_detection_draws():
    """mask (M, T) and (M, T, m) holding the draws give the detection_probability result, bit for
    bit (M = 300: the block is padded to 512 rows, padding rows clamp to the last mask row)."""
    model, key = cv(), jax.random.key(4)
    kw = dict(num_steps=T, progress=False)
    drawn = monte_carlo(model, key, M, detection_probability=P_D, **kw)
    det = detections(model, key)
    by_mask = monte_carlo(model, key, M, mask=det, **kw)
    by_mask3 = monte_carlo(model, key, M, mask=np.repeat(det[..., None], 2, axis=-1), **kw)
    assert_identical(by_mask, drawn, "(M, T) mask")
    assert_identical(by_mask3, drawn, "(M, T, m) mask")
    # A shared mask is AND-ed with the detections.
    shared = np.ones((T, 2), bool)
    shared[3, 1] = False
    both = monte_carlo(model, key, M, mask=shared, detection_probability=P_D, **kw)
    assert_identical(both, monte_carlo(model, key, M, mask=det[..., None] & shared, **kw), "shared AND drawn")
    np.testing.assert_array_equal(np.asarray(both.nis_dof)[3], det[:, 3].sum() / M)
    assert not by_mask.shared_covariance  # a per-run mask takes the per-run path


def _square(x, k):
    return x * x


def _identity(x, k):
    return x


def test_failed_runs_are_left_out_of_the_dof_sums():
    """Truth x_k = x_{k-1}² + w overflows when |x_0| > 1: those runs are excluded from every sum,
    the NIS degrees of freedom included."""
    truth = NonlinearGaussianModel(_square, _identity, 1e-8 * np.eye(1), 1e-2 * np.eye(1), np.zeros(1),
                                   0.5 * np.eye(1))
    filter_model = LinearGaussianModel(np.eye(1), 1e-2 * np.eye(1), np.eye(1), 1e-2 * np.eye(1), np.zeros(1),
                                       np.eye(1))
    key = jax.random.key(0)
    with pytest.warns(RuntimeWarning, match="non-finite"):
        res = monte_carlo(truth, key, M, num_steps=T, filter_model=filter_model, detection_probability=0.6,
                          progress=False)
    keys = jax.vmap(lambda i: jax.random.fold_in(key, i))(jnp.arange(M))
    trajs = jax.vmap(lambda k: simulate(truth, k, T, detection_probability=0.6, throw=False))(keys)
    ok = np.all(np.isfinite(np.asarray(trajs.states)), axis=(1, 2))
    assert 0 < res.num_failed == int((~ok).sum()) < M
    counts = np.asarray(trajs.detected)[ok].sum(axis=0).astype(float)
    np.testing.assert_array_equal(np.asarray(res.nis_dof), counts / res.num_runs)


def test_sweep_takes_detection_probability():
    values = [0.1, 2.0]
    key = jax.random.key(6)
    res = monte_carlo_sweep(lambda q: (cv(q), cv(0.5)), values, key, M, num_steps=T, detection_probability=P_D,
                            progress=False)
    for q, r in zip(values, res):
        single = monte_carlo(cv(q), key, M, num_steps=T, filter_model=cv(0.5), detection_probability=P_D,
                             progress=False)
        assert_identical(r, single, f"q = {q}")
    # Common random numbers: both values see the same detections, those of a per-run mask.
    np.testing.assert_array_equal(res[0].nis_dof, res[1].nis_dof)
    np.testing.assert_array_equal(res[0].nis_dof, 2.0 * detections(cv(), key).sum(axis=0) / M)


def test_input_errors():
    model, key = cv(), jax.random.key(0)
    kw = dict(num_steps=5, progress=False)
    with pytest.raises(InputError, match="own measurement schedule"):
        monte_carlo(model, key, 10, detection_probability=0.7, covariance="shared", **kw)
    with pytest.raises(InputError, match="per-run `mask`"):
        monte_carlo(model, key, 10, mask=np.ones((10, 5), bool), covariance="shared", **kw)
    # "auto" picks the per-run path (checked in the tests above: shared_covariance is False).
    for bad in (0.0, 1.5, np.nan, np.full(4, 0.5), -0.1):
        with pytest.raises(InputError, match="detection_probability"):
            monte_carlo(model, key, 10, detection_probability=bad, **kw)
    with pytest.raises(InputError, match="detection_probability"):
        simulate(model, key, 5, detection_probability=np.ones(3))
    with pytest.raises(InputError, match="detection_probability"):
        jax.jit(lambda p: simulate(model, key, 5, detection_probability=p).states)(0.5)
    with pytest.raises(InputError, match="`mask` must have shape"):
        monte_carlo(model, key, 10, mask=np.ones((11, 5), bool), **kw)
    with pytest.raises(InputError, match="boolean"):
        monte_carlo(model, key, 10, mask=np.ones((10, 5)), **kw)

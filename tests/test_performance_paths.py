"""The fast paths compute what the general path computes.

- ``run_filter_batch``: the shared-covariance path against the per-run path and against
  ``run_filter`` run by run (1e-10), its automatic selection, its ``save`` modes;
- ``monte_carlo``: both paths give the same statistics (1e-10), the path is chosen
  automatically, results do not depend on the chunk size and the chunk size does not recompile;
- the building blocks: the unrolled small linear algebra, the rank-m Joseph evaluation, and the
  per-step noise (Threefry bit for bit, batch-independent, standard normal).

No timing is asserted here; ``benchmarks/peers.py`` measures speed.
"""

import math

import jax
import jax.extend.random as jer
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.stats

import jaxtrack
from jaxtrack.filters import (
    ExtendedKalmanFilter,
    KalmanFilter,
    UnscentedKalmanFilter,
    condition_linearized,
    run_filter,
    run_filter_batch,
)
from jaxtrack.filters import _batch as batch_mod
from jaxtrack.filters._batch import balanced_block, per_run_block
from jaxtrack.filters._linalg import cholesky, congruence, matmul, tril_inverse
from jaxtrack.models import LinearGaussianModel, constant_velocity
from jaxtrack.montecarlo import monte_carlo, simulate
from jaxtrack.montecarlo import _run as mc_run
from jaxtrack.montecarlo._noise import key_words, step_normals, threefry2x32

T = 30
B = 40
FIRST_STEPS = ("update", "predict")


def assert_close(actual, desired, rtol, err_msg=""):
    """``rtol`` plus an absolute tolerance scaled to the largest entry (means cross zero)."""
    desired = np.asarray(desired)
    atol = rtol * max(float(np.max(np.abs(desired))), 1e-300)
    np.testing.assert_allclose(np.asarray(actual), desired, rtol=rtol, atol=atol, err_msg=err_msg)


def cv_model(**kw):
    prior = jnp.diag(jnp.asarray([100.0, 100.0, 10.0, 10.0]) ** 2)
    return constant_velocity(1.0, dim=2, accel_psd=0.5, measurement_std=10.0, initial_cov=prior, **kw)


def time_varying_model(rng, num_steps=T):
    """Per-step F, Q, H, R and a known input b: every per-step code path of the mean pass."""
    taus = rng.uniform(0.5, 2.0, num_steps)
    F = np.stack([np.kron(np.array([[1.0, t], [0.0, 1.0]]), np.eye(2)) for t in taus])
    Q = np.stack([np.kron(np.array([[t**3 / 3, t**2 / 2], [t**2 / 2, t]]), np.eye(2)) for t in taus])
    H = np.stack([np.hstack([np.eye(2), 0.01 * k * np.ones((2, 2))]) for k in range(num_steps)])
    R = np.stack([np.diag(rng.uniform(20.0, 40.0, 2)) for _ in range(num_steps)])
    b = rng.normal(size=(num_steps, 4))
    return LinearGaussianModel(F, Q, H, R, np.array([0.0, 0.0, 1.0, -1.0]), np.diag([1e4, 1e4, 1e2, 1e2]),
                               transition_offset=b)


def batch_of(model, num_runs=B, num_steps=T, seed=0):
    keys = jax.random.split(jax.random.key(seed), num_runs)
    return jax.vmap(lambda k: simulate(model, k, num_steps).measurements)(keys)


HISTORIES = ("filtered_mean", "predicted_mean", "innovation")
COVARIANCES = ("filtered_cov", "predicted_cov", "innovation_cov", "num_observed")


@pytest.mark.parametrize("first_step", FIRST_STEPS)
@pytest.mark.parametrize("mask_kind", ["none", "steps", "components"])
def test_shared_and_per_run_paths_agree(first_step, mask_kind):
    model = cv_model()
    zs = batch_of(model)
    rng = np.random.default_rng(1)
    mask = {"none": None, "steps": rng.random(T) < 0.8, "components": rng.random((T, 2)) < 0.8}[mask_kind]
    shared = run_filter_batch(KalmanFilter(), model, zs, mask=mask, first_step=first_step)
    per_run = run_filter_batch(KalmanFilter(), model, zs, mask=mask, first_step=first_step, covariance="per_run")
    assert shared.shared_covariance and not per_run.shared_covariance
    for name in HISTORIES + ("log_likelihood", "final_mean"):
        assert_close(getattr(shared, name), getattr(per_run, name), 1e-10, err_msg=name)
    for name in COVARIANCES:
        ref = getattr(per_run, name)
        assert_close(jnp.broadcast_to(getattr(shared, name), ref.shape), ref, 1e-12, err_msg=name)
    assert_close(jnp.broadcast_to(shared.final_cov, per_run.final_cov.shape), per_run.final_cov, 1e-12)
    assert bool(jnp.all(shared.ok)) and bool(jnp.all(per_run.ok))


# Each first-step convention once and each block layout once (both crossed: 20.6 s of a worker;
# these two: about 10 s; the other two combinations run with --runslow).
@pytest.mark.parametrize(("num_steps", "first_step"), [
    (T, "predict"), (29, "update"),
    pytest.param(T, "update", marks=pytest.mark.slow), pytest.param(29, "predict", marks=pytest.mark.slow)])
def test_shared_path_matches_run_filter_run_by_run(first_step, num_steps):
    """Time-varying F, Q, H, R and a known input: run i of the batch is run_filter on run i.

    29 steps is prime: the blocked mean pass then ends with a shorter block. Masked entries
    hold NaN, which must not reach the block products.
    """
    rng = np.random.default_rng(2)
    model = time_varying_model(rng, num_steps)
    zs = batch_of(model, num_runs=6, num_steps=num_steps)
    mask = rng.random((num_steps, 2)) < 0.85
    assert batch_mod._block_length(2, num_steps) == (6 if num_steps == T else 8)
    zs = jnp.where(mask[None], zs, jnp.nan)
    res = run_filter_batch(KalmanFilter(), model, zs, mask=mask, first_step=first_step)
    assert res.shared_covariance and bool(jnp.all(res.ok))
    zs = jnp.where(mask[None], zs, 0.0)
    for i in range(zs.shape[0]):
        one = run_filter(KalmanFilter(), model, zs[i], mask=mask, first_step=first_step)
        run_i = res.run(i)
        for name in HISTORIES + ("filtered_cov", "predicted_cov", "innovation_cov", "final_mean", "final_cov"):
            assert_close(getattr(run_i, name), getattr(one, name), 1e-10, err_msg=f"run {i} {name}")
        np.testing.assert_allclose(float(run_i.log_likelihood), float(one.log_likelihood), rtol=1e-10)


def test_fixed_gain_uses_the_shared_path():
    """A supplied (suboptimal) gain is data-free too: the shared path applies and agrees."""
    model = cv_model()
    zs = batch_of(model)
    W = 0.5 * run_filter(KalmanFilter(), model, zs[0]).final_cov[:, :2] / 100.0
    shared = run_filter_batch(KalmanFilter(gain=W), model, zs)
    per_run = run_filter_batch(KalmanFilter(gain=W), model, zs, covariance="per_run")
    assert shared.shared_covariance
    for name in HISTORIES + ("log_likelihood",):
        assert_close(getattr(shared, name), getattr(per_run, name), 1e-10, err_msg=name)


def test_automatic_path_selection():
    model = cv_model()
    zs = batch_of(model, num_runs=5, num_steps=10)
    per_run_mask = np.random.default_rng(3).random((5, 10)) < 0.8
    assert run_filter_batch(KalmanFilter(), model, zs).shared_covariance
    assert run_filter_batch(KalmanFilter(), model, zs, mask=np.ones(10, bool)).shared_covariance
    assert not run_filter_batch(KalmanFilter(), model, zs, mask=per_run_mask).shared_covariance
    assert not run_filter_batch(KalmanFilter(), model, zs, nan_as_missing=True).shared_covariance
    assert not run_filter_batch(ExtendedKalmanFilter(), model, zs).shared_covariance
    assert not run_filter_batch(UnscentedKalmanFilter(), model, zs).shared_covariance
    with pytest.raises(jaxtrack.InputError, match="covariance='shared'"):
        run_filter_batch(ExtendedKalmanFilter(), model, zs, covariance="shared")
    with pytest.raises(jaxtrack.InputError, match="covariance='shared'"):
        run_filter_batch(KalmanFilter(), model, zs, mask=per_run_mask, covariance="shared")


def test_per_run_path_matches_run_filter_with_per_run_masks_and_nans():
    model = cv_model()
    zs = np.array(batch_of(model, num_runs=7))
    rng = np.random.default_rng(4)
    masks = rng.random((7, T)) < 0.8
    zs[rng.random(zs.shape) < 0.05] = np.nan
    res = run_filter_batch(KalmanFilter(), model, zs, mask=masks, nan_as_missing=True)
    ekf = run_filter_batch(ExtendedKalmanFilter(), model, zs, mask=masks, nan_as_missing=True)
    for i in range(7):
        one = run_filter(KalmanFilter(), model, zs[i], mask=masks[i], nan_as_missing=True)
        assert_close(res.filtered_mean[i], one.filtered_mean, 1e-12)
        assert_close(res.filtered_cov[i], one.filtered_cov, 1e-12)
        # On a linear model the EKF is the Kalman filter.
        assert_close(ekf.filtered_mean[i], one.filtered_mean, 1e-10)
        np.testing.assert_allclose(float(res.log_likelihood[i]), float(one.log_likelihood), rtol=1e-12)


@pytest.mark.parametrize("covariance", ["shared", "per_run"])
def test_save_modes(covariance):
    model = cv_model()
    zs = batch_of(model, num_runs=9, num_steps=12)
    full = run_filter_batch(KalmanFilter(), model, zs, covariance=covariance)
    mean = run_filter_batch(KalmanFilter(), model, zs, save="mean", covariance=covariance)
    final = run_filter_batch(KalmanFilter(), model, zs, save="final", covariance=covariance)
    for name in HISTORIES[1:] + COVARIANCES:
        assert getattr(mean, name) is None and getattr(final, name) is None, name
    assert final.filtered_mean is None
    np.testing.assert_array_equal(mean.filtered_mean, full.filtered_mean)
    for res in (mean, final):
        np.testing.assert_array_equal(res.final_mean, full.final_mean)
        np.testing.assert_array_equal(res.log_likelihood, full.log_likelihood)
    assert full.filtered_mean.shape == (9, 12, 4)
    assert full.filtered_cov.shape == ((12, 4, 4) if covariance == "shared" else (9, 12, 4, 4))
    single = run_filter(KalmanFilter(), model, zs[0], save="mean")
    assert single.filtered_cov is None
    np.testing.assert_allclose(single.filtered_mean, full.filtered_mean[0], rtol=1e-10)


def test_batch_input_errors_name_the_argument():
    model = cv_model()
    zs = batch_of(model, num_runs=3, num_steps=10)
    with pytest.raises(jaxtrack.InputError, match="measurements"):
        run_filter_batch(KalmanFilter(), model, zs[0])
    with pytest.raises(jaxtrack.InputError, match="mask"):
        run_filter_batch(KalmanFilter(), model, zs, mask=np.ones((3, 9), bool))
    with pytest.raises(jaxtrack.InputError, match="covariance"):
        run_filter_batch(KalmanFilter(), model, zs, covariance="both")
    with pytest.raises(jaxtrack.InputError, match="save"):
        run_filter_batch(KalmanFilter(), model, zs, save="some")
    bad = np.array(zs)
    bad[1, 2, 0] = np.nan
    with pytest.raises(jaxtrack.InputError, match="non-finite"):
        run_filter_batch(KalmanFilter(), model, bad)


# ---------------------------------------------------------------------------------------------
# Monte Carlo


def _assert_same_statistics(a, b, rtol):
    for name in ("mse", "mean_error", "nees", "nees_std", "nis"):
        assert_close(getattr(a, name), getattr(b, name), rtol, err_msg=name)
    assert a.num_runs == b.num_runs and a.num_failed == b.num_failed


@pytest.mark.parametrize("first_step", FIRST_STEPS)
def test_monte_carlo_paths_agree(first_step):
    """Shared covariance (chosen automatically) and per-run covariance: same statistics."""
    truth = cv_model()
    small_q = constant_velocity(1.0, dim=2, accel_psd=0.05, measurement_std=10.0,
                                initial_cov=truth.initial_cov)
    mask = np.random.default_rng(5).random((T, 2)) < 0.8
    kw = dict(num_steps=T, filter_model=small_q, mask=mask, first_step=first_step, progress=False)
    auto = monte_carlo(truth, jax.random.key(4), 300, **kw)
    per_run = monte_carlo(truth, jax.random.key(4), 300, covariance="per_run", **kw)
    assert auto.shared_covariance and not per_run.shared_covariance
    _assert_same_statistics(auto, per_run, 1e-10)


def test_monte_carlo_ekf_runs_per_run_and_agrees_on_a_linear_model():
    model = cv_model()
    kf = monte_carlo(model, jax.random.key(6), 200, num_steps=T, progress=False)
    ekf = monte_carlo(model, jax.random.key(6), 200, num_steps=T, filter=ExtendedKalmanFilter(), progress=False)
    assert kf.shared_covariance and not ekf.shared_covariance
    _assert_same_statistics(kf, ekf, 1e-10)
    with pytest.raises(jaxtrack.InputError, match="covariance='shared'"):
        monte_carlo(model, jax.random.key(6), 20, num_steps=T, filter=ExtendedKalmanFilter(),
                    covariance="shared", progress=False)


@pytest.mark.parametrize("covariance", ["auto", "per_run"])
def test_monte_carlo_chunk_size_changes_nothing_and_never_recompiles(covariance, monkeypatch):
    """The compiled unit is a block of fixed size: any chunk size gives the same sums (bit for
    bit) from one compilation, and so does any number of runs dealt into blocks of that size."""
    traces = []
    for name in ("_shared_block", "_per_run_block"):
        original = getattr(mc_run, name)

        def counted(*args, _original=original, _name=name, **kwargs):
            traces.append(_name)  # runs once per trace, i.e. per compilation
            return _original(*args, **kwargs)

        monkeypatch.setattr(mc_run, name, counted)
    model = cv_model()
    largest = mc_run._SHARED_BLOCK if covariance == "auto" else mc_run._PER_RUN_BLOCK
    num_runs = largest + 7  # two blocks, the second padded
    block = balanced_block(num_runs, largest)
    results = [
        monte_carlo(model, jax.random.key(8), num_runs, num_steps=13, chunk_size=chunk,
                    covariance=covariance, progress=False)
        for chunk in (1, 100, 333, 5 * block)
    ]
    # Another number of runs that is dealt into blocks of the same size: the same compilation.
    assert balanced_block(2 * block - 1, largest) == block
    results.append(monte_carlo(model, jax.random.key(8), 2 * block - 1, num_steps=13,
                               covariance=covariance, progress=False))
    for other in results[1:4]:
        for name in ("mse", "nees", "nis", "nees_std", "mean_error"):
            np.testing.assert_array_equal(getattr(other, name), getattr(results[0], name), err_msg=name)
    # One compilation at most (none if an earlier test compiled the same block): its trace
    # calls the block function once; the re-run that drops failed runs reuses that trace
    # (montecarlo._engine.run_excluding_failures).
    assert len(traces) in (0, 1) and len(set(traces)) <= 1, traces


@pytest.mark.parametrize("shape", [(6, 6), (2, 4), (9, 9)])
def test_congruence_is_a_p_at_and_exactly_symmetric(shape):
    """filters._linalg.congruence (the UKF's affine prediction): a p aᵀ from its lower triangle,
    per run under vmap as alone; n > 7 falls back to two products."""
    rng = np.random.default_rng(4)
    a = jnp.asarray(rng.standard_normal((5,) + shape))
    b = rng.standard_normal((5, shape[1], shape[1]))
    p = jnp.asarray(b @ np.swapaxes(b, 1, 2))
    got = np.asarray(jax.vmap(congruence)(a, p))
    want = np.asarray(a) @ np.asarray(p) @ np.swapaxes(np.asarray(a), 1, 2)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13 * np.abs(want).max())
    np.testing.assert_array_equal(got, np.swapaxes(got, 1, 2))
    np.testing.assert_allclose(congruence(a[0], p[0]), got[0], rtol=1e-15)


def test_blocks_are_balanced_and_sized_for_the_cpus():
    """Runs are dealt into as few blocks of at most ``largest`` as possible, padded by less than
    one grain a block; one CPU gets the cache-sized block, two get one XLA splits over both."""
    for num_runs in (1, 7, 200, 511, 512, 513, 1000, 4096, 4103, 5000, 10_000, 100_000, 1_000_003):
        block = balanced_block(num_runs, 4096)
        num_blocks = -(-num_runs // block)
        assert block <= 4096 and num_blocks == max(1, -(-num_runs // 4096)), num_runs
        if num_runs > 512:
            assert block % 512 == 0 and num_blocks * block - num_runs < 512 * num_blocks, num_runs
        else:
            assert block == 1 << (num_runs - 1).bit_length(), num_runs
    assert balanced_block(10_000, 4096) == 3584  # 10,752 computed, not 12,288
    assert balanced_block(10_000, 512) == 512 and balanced_block(300, 128) == 128
    assert per_run_block(1) == 512 and per_run_block(2) == 4096 and per_run_block(64) == 16384


def test_monte_carlo_replays_with_simulate_exactly():
    """Run i of a (padded, multi-block) Monte Carlo is simulate(fold_in(key, i)): same draws."""
    model = cv_model()
    key = jax.random.key(9)
    i = 5
    res = monte_carlo(model, key, 1, num_steps=12, progress=False)
    traj = simulate(model, jax.random.fold_in(key, 0), 12)
    filt = run_filter(KalmanFilter(), model, traj.measurements)
    assert_close(res.mse, (traj.states - filt.filtered_mean) ** 2, 1e-12)
    # Batched simulation is run by run the same numbers (the batch is the trailing axis).
    x0, eps0, step = mc_run._simulated_block(model, mc_run.noise_factors(model, 12), "update", key, 0, 8)
    one = simulate(model, jax.random.fold_in(key, i), 12)
    x, z, _ = step(x0, eps0, 0)
    np.testing.assert_array_equal(x[:, i], one.states[0])
    np.testing.assert_array_equal(z[:, i], one.measurements[0])


def _square(x, k):
    return x * x


def _identity(x, k):
    return x


def test_failed_runs_are_excluded_the_same_way_on_both_paths():
    """Truth x_k = x_{k-1}² + w: runs that start with |x_0| > 1 overflow, the others stay small.
    The filter model is linear, so the shared path applies; it must drop the same runs (by
    re-running the block without them) and give the per-run path's statistics."""
    truth = jaxtrack.models.NonlinearGaussianModel(
        _square, _identity, 1e-8 * np.eye(1), 1e-2 * np.eye(1), np.zeros(1), 0.5 * np.eye(1))
    filter_model = LinearGaussianModel(np.eye(1), 1e-2 * np.eye(1), np.eye(1), 1e-2 * np.eye(1), np.zeros(1), np.eye(1))
    kw = dict(num_steps=40, filter_model=filter_model, progress=False)
    with pytest.warns(RuntimeWarning, match="non-finite"):
        shared = monte_carlo(truth, jax.random.key(0), 300, **kw)
    with pytest.warns(RuntimeWarning, match="non-finite"):
        per_run = monte_carlo(truth, jax.random.key(0), 300, covariance="per_run", **kw)
    assert shared.shared_covariance and not per_run.shared_covariance
    assert 0 < shared.num_failed < 300 and shared.num_failed + shared.num_runs == 300
    assert bool(jnp.all(jnp.isfinite(shared.mse))) and bool(jnp.all(jnp.isfinite(shared.nees)))
    _assert_same_statistics(shared, per_run, 1e-10)


# ---------------------------------------------------------------------------------------------
# Building blocks


@pytest.mark.parametrize("d", [1, 2, 3, 4, 6])
def test_small_cholesky_and_inverse(d):
    rng = np.random.default_rng(d)
    G = rng.standard_normal((d, d))
    A = G @ G.T + d * np.eye(d)
    L = np.asarray(cholesky(jnp.asarray(A)))
    np.testing.assert_allclose(L, np.linalg.cholesky(A), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(np.asarray(tril_inverse(jnp.asarray(L))) @ L, np.eye(d), atol=1e-13)
    batched = jax.vmap(cholesky)(jnp.stack([jnp.asarray(A), 2 * jnp.asarray(A)]))
    np.testing.assert_allclose(batched[1], np.linalg.cholesky(2 * A), rtol=1e-13, atol=1e-13)
    not_pd = -np.eye(d)
    assert np.isnan(np.asarray(cholesky(jnp.asarray(not_pd)))).any()


@pytest.mark.parametrize(("sa", "sb"), [((3, 4), (4, 5)), ((4,), (4, 2)), ((3, 4), (4,)), ((4,), (4,)), ((20, 20), (20, 3))])
def test_matmul_is_the_matrix_product(sa, sb):
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal(sa), rng.standard_normal(sb)
    np.testing.assert_allclose(np.asarray(matmul(jnp.asarray(a), jnp.asarray(b))), a @ b, rtol=1e-13, atol=1e-13)


def test_rank_m_joseph_matches_the_dense_joseph_form():
    """(I − WH) P (I − WH)ᵀ + W R Wᵀ for suboptimal gains and informative measurements."""
    rng = np.random.default_rng(11)
    for trial in range(20):
        n, m = 6, 3
        G = rng.standard_normal((n, n))
        P = G @ G.T * 10.0 ** rng.uniform(-2, 6)
        H = rng.standard_normal((m, n))
        R = np.diag(10.0 ** rng.uniform(-4, 2, m))
        W = P @ H.T @ np.linalg.inv(H @ P @ H.T + R) * (1 + 0.2 * rng.standard_normal((n, m)))
        A = np.eye(n) - W @ H
        dense = A @ P @ A.T + W @ R @ W.T
        post = condition_linearized(jnp.zeros(n), jnp.asarray(P), jnp.zeros(m), jnp.asarray(H),
                                    jnp.asarray(R), jnp.ones(m, bool), jnp.asarray(W))
        assert_close(post.cov, 0.5 * (dense + dense.T), 1e-12, err_msg=f"trial {trial}")
        np.testing.assert_array_equal(post.cov, post.cov.T)


def test_threefry_matches_jax_bit_for_bit():
    rng = np.random.default_rng(0)
    key = rng.integers(0, 2**32, 2, dtype=np.uint64).astype(np.uint32)
    counts = rng.integers(0, 2**32, (2, 500), dtype=np.uint64).astype(np.uint32)
    ref = np.asarray(jer.threefry_2x32(jnp.asarray(key), jnp.asarray(counts.reshape(-1)))).reshape(2, 500)
    mine = np.stack([np.asarray(a) for a in threefry2x32(*(jnp.asarray(v) for v in (key[0], key[1], counts[0], counts[1])))])
    np.testing.assert_array_equal(mine, ref)


def test_step_normals_are_standard_normal_and_batch_independent():
    keys = jax.random.split(jax.random.key(12), 3)
    words = key_words(keys)
    batched = step_normals(words, 7, 6, jnp.float64)  # (6, 3)
    for i in range(3):
        np.testing.assert_array_equal(batched[:, i], step_normals(words[i], 7, 6, jnp.float64))
    # A step's numbers do not depend on how many are drawn.
    np.testing.assert_array_equal(step_normals(words[0], 7, 2, jnp.float64), batched[:2, 0])
    draws = np.asarray(jax.vmap(lambda k: step_normals(words[0], k, 5, jnp.float64))(jnp.arange(40_000))).ravel()
    n = draws.size
    assert abs(draws.mean()) < 4 / math.sqrt(n)
    assert abs(draws.var() - 1) < 4 * math.sqrt(2 / n)
    assert scipy.stats.kstest(draws, "norm").pvalue > 1e-3
    # Neighbouring steps and components are uncorrelated.
    grid = draws.reshape(-1, 5)
    assert abs(np.corrcoef(grid[:-1, 0], grid[1:, 0])[0, 1]) < 4 / math.sqrt(grid.shape[0])
    assert abs(np.corrcoef(grid[:, 0], grid[:, 1])[0, 1]) < 4 / math.sqrt(grid.shape[0])
    f32 = step_normals(words, 7, 6, jnp.float32)
    assert f32.dtype == jnp.float32 and bool(jnp.all(jnp.isfinite(f32)))

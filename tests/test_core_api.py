"""The core's public surface: manual stepping, covariance strategies, the Monte Carlo engine."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxtrack
from jaxtrack.filters import (
    AutoCovariance,
    ConsiderKalmanFilter,
    ExtendedKalmanFilter,
    FilterState,
    KalmanFilter,
    PerRunCovariance,
    SharedCovariance,
    StandardForm,
    run_filter,
    run_filter_batch,
)
from jaxtrack.models import constant_velocity
from jaxtrack.montecarlo import monte_carlo, monte_carlo_map, run_mesh, simulate


@pytest.fixture(scope="module")
def cv():
    prior = jnp.diag(jnp.array([100.0, 100.0, 10.0, 10.0]) ** 2)
    return constant_velocity(1.0, dim=2, accel_psd=0.5, measurement_std=10.0, initial_cov=prior)


@pytest.mark.parametrize("first_step", ["update", "predict"])
def test_manual_stepping_equals_run_filter_to_the_bit(cv, first_step):
    """init + step in a Python loop (as a real-time loop would) is the scan of run_filter."""
    zs = simulate(cv, jax.random.key(0), 30).measurements
    mask = np.ones((30, 2), bool)
    mask[7, 1] = False
    mask[12] = False
    ref = run_filter(KalmanFilter(), cv, zs, mask=jnp.asarray(mask), first_step=first_step)
    kf = KalmanFilter()
    step = jax.jit(kf.step, static_argnames="first_step")
    state = kf.init(cv)
    assert isinstance(state, FilterState) and int(state.step) == 0
    zs_nan = np.where(mask, np.asarray(zs), np.nan)  # missing components may hold NaN
    for k in range(30):
        state, out = step(cv, state, zs_nan[k], jnp.asarray(mask[k]), first_step=first_step)
        np.testing.assert_array_equal(out.conditioned.mean, ref.filtered_mean[k])
        np.testing.assert_array_equal(out.predicted_cov, ref.predicted_cov[k])
    assert int(state.step) == 30 and bool(state.ok)
    np.testing.assert_array_equal(state.cov, ref.final_cov)
    np.testing.assert_array_equal(state.log_likelihood, ref.log_likelihood)


def test_standard_form_equals_joseph_with_optimal_gain(cv):
    zs = simulate(cv, jax.random.key(1), 50).measurements
    a = run_filter(KalmanFilter(), cv, zs)
    b = run_filter(KalmanFilter(form=StandardForm()), cv, zs)
    np.testing.assert_allclose(b.filtered_cov, a.filtered_cov, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(b.filtered_mean, a.filtered_mean, rtol=1e-10, atol=1e-9)
    with pytest.raises(jaxtrack.InputError, match="`gain`"):
        KalmanFilter(gain=jnp.zeros((4, 2)), form=StandardForm())


def test_covariance_strategy_follows_the_filters_declaration(cv):
    """The shared path is chosen because the filter says its covariances are data-free."""
    zs = jax.vmap(lambda k: simulate(cv, k, 40).measurements)(jax.random.split(jax.random.key(2), 6))
    assert KalmanFilter().covariance_is_data_free(cv)
    assert not ExtendedKalmanFilter().covariance_is_data_free(cv)
    assert run_filter_batch(KalmanFilter(), cv, zs).shared_covariance
    assert not run_filter_batch(ExtendedKalmanFilter(), cv, zs).shared_covariance
    shared = run_filter_batch(KalmanFilter(), cv, zs, covariance=SharedCovariance())
    per_run = run_filter_batch(KalmanFilter(), cv, zs, covariance=PerRunCovariance())
    auto = run_filter_batch(KalmanFilter(), cv, zs, covariance=AutoCovariance())
    assert shared.shared_covariance and auto.shared_covariance and not per_run.shared_covariance
    np.testing.assert_allclose(shared.filtered_mean, per_run.filtered_mean, rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(shared.log_likelihood, per_run.log_likelihood, rtol=1e-10)
    with pytest.raises(jaxtrack.InputError, match="covariance='shared'"):
        run_filter_batch(ExtendedKalmanFilter(), cv, zs, covariance=SharedCovariance())
    with pytest.raises(jaxtrack.InputError, match="`covariance`"):
        run_filter_batch(KalmanFilter(), cv, zs, covariance=object())


def test_consider_filter_takes_the_shared_path_and_agrees(cv):
    """A library filter other than KalmanFilter declares data-free covariances and gets the
    shared path (no isinstance test): both paths agree."""
    from jaxtrack.filters import consider_model

    model = consider_model(cv.F, cv.Q, cv.H, cv.R, cv.initial_mean, cv.initial_cov,
                           consider_matrix=jnp.ones((2, 1)), consider_mean=jnp.zeros(1),
                           consider_cov=jnp.eye(1) * 4.0)
    zs = jax.vmap(lambda k: simulate(model, k, 30).measurements)(jax.random.split(jax.random.key(3), 5))
    cf = ConsiderKalmanFilter(4)
    shared = run_filter_batch(cf, model, zs)
    per_run = run_filter_batch(cf, model, zs, covariance="per_run")
    assert shared.shared_covariance and not per_run.shared_covariance
    np.testing.assert_allclose(shared.filtered_mean, per_run.filtered_mean, rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(shared.filtered_cov, per_run.filtered_cov[0], rtol=1e-10, atol=1e-8)


def _draws(key, scale):
    x = jax.random.normal(key, (3,)) * scale
    return {"x": x, "x2": x * x, "positive": jnp.sum(x) > 0}


def test_monte_carlo_map_is_replayable_and_chunk_independent():
    key = jax.random.key(7)
    scale = jnp.asarray(2.0)
    sums = monte_carlo_map(_draws, key, 1000, args=scale, block_size=64)
    again = monte_carlo_map(_draws, key, 1000, args=scale, block_size=64, chunk_size=7)
    on_mesh = monte_carlo_map(_draws, key, 1000, args=scale, block_size=64, mesh=run_mesh())
    stacked = monte_carlo_map(_draws, key, 1000, args=scale, block_size=64, reduce="stack")
    for other in (again, on_mesh):
        for name in sums:
            np.testing.assert_array_equal(other[name], sums[name])
    assert stacked["x"].shape == (1000, 3)
    # Run 417 replayed on its own: the same draws, to rounding (the block's fused program and
    # the eager calls may round the normal's transform differently in the last bit).
    np.testing.assert_allclose(stacked["x"][417], _draws(jax.random.fold_in(key, 417), scale)["x"], rtol=4e-16)
    np.testing.assert_allclose(stacked["x"].sum(0), sums["x"], rtol=1e-12, atol=1e-12)
    assert int(sums["positive"]) == int(np.sum(stacked["positive"]))
    # The statistic is right: E[x²] = 4 per component, within 5 standard errors (var x² = 2·16).
    assert np.all(np.abs(sums["x2"] / 1000 - 4.0) < 5 * np.sqrt(32.0 / 1000))


def test_monte_carlo_map_rejects_bad_arguments():
    with pytest.raises(jaxtrack.InputError, match="`num_runs`"):
        monte_carlo_map(_draws, jax.random.key(0), 0, args=1.0)
    with pytest.raises(jaxtrack.InputError, match="`reduce`"):
        monte_carlo_map(_draws, jax.random.key(0), 4, args=1.0, reduce="mean")
    with pytest.raises(jaxtrack.InputError, match="`fn`"):
        monte_carlo_map(3, jax.random.key(0), 4)


def test_monte_carlo_accepts_strategy_objects(cv):
    a = monte_carlo(cv, jax.random.key(0), 64, num_steps=20, progress=False, covariance=PerRunCovariance())
    b = monte_carlo(cv, jax.random.key(0), 64, num_steps=20, progress=False, covariance="per_run")
    np.testing.assert_array_equal(a.nees, b.nees)
    assert not a.shared_covariance


def test_plotting_leaves_the_users_backend_alone():
    """Importing jaxtrack.plotting must not switch matplotlib's backend (notebooks keep inline)."""
    import subprocess
    import sys

    code = ("import matplotlib; matplotlib.use('svg'); import jaxtrack.plotting; "
            "print(matplotlib.get_backend())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().lower() == "svg"

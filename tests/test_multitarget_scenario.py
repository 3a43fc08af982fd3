"""Multi-target scenarios: Poisson clutter, detection probability, origins, determinism, capacity.

Statistical checks use 99% two-sided bounds (z = 2.5758 for normal approximations, chi-square
quantiles for variances), each stated next to its assertion. One scenario (4 crossing targets,
100 steps, P_D = 0.9, λ = 10) is simulated once for 20 runs (2,000 scans) and shared.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from jaxtrack import InputError
from jaxtrack.montecarlo import psd_sqrt
from jaxtrack.montecarlo._noise import step_normals
from jaxtrack.multitarget import (
    CLUTTER,
    PADDING,
    CapacityWarning,
    Scenario,
    crossing_targets,
    simulate_scenario,
    simulate_scenarios,
)
from jaxtrack.multitarget._scenario import DETECTION_STREAM, TARGET_STREAM, _uniforms, poisson_inverse_cdf, stream_words

KEY = jax.random.key(20261205)
NUM_RUNS = 20
Z99 = 2.5758  # two-sided 99% normal quantile


def _range_bearing(states):
    """``h(x) = [‖p‖, atan2(y, x)]`` of the radar at the origin (NumPy, independent of the model code)."""
    return np.stack([np.hypot(states[..., 0], states[..., 1]), np.arctan2(states[..., 1], states[..., 0])], axis=-1)


@pytest.fixture(scope="module")
def scenario():
    return crossing_targets(num_targets=4, num_steps=100)


@pytest.fixture(scope="module")
def runs(scenario):
    out = simulate_scenarios(scenario, KEY, NUM_RUNS)
    return jax.tree.map(np.asarray, out)


def test_clutter_count_is_poisson(scenario, runs):
    lam = float(scenario.clutter_rate)
    counts = runs.scans.num_clutter.ravel()
    n = counts.size
    assert n == 2000
    # Mean: |c̄ − λ| <= 2.5758 √(λ/n) = 0.182 for λ = 10, n = 2000.
    assert abs(counts.mean() - lam) <= Z99 * np.sqrt(lam / n)
    # Variance (index of dispersion): (n − 1) s² / λ ~ χ²(n − 1) under Poisson(λ); 99% bounds
    # [1839.9, 2165.7], i.e. s² in [9.20, 10.83].
    dispersion = (n - 1) * counts.var(ddof=1) / lam
    assert stats.chi2.ppf(0.005, n - 1) <= dispersion <= stats.chi2.ppf(0.995, n - 1)
    assert not runs.overflow.any()


@pytest.mark.parametrize("lam", [0.0, 0.3, 10.0, 1000.0])
def test_poisson_inversion_matches_scipy(lam):
    # The inverse CDF is exact: for u away from the CDF's jumps it equals SciPy's ppf (the least
    # c with F(c) >= u), also for λ = 1000, where e^{−λ} underflows in linear space.
    u = np.random.default_rng(7).uniform(size=2000)
    got = np.asarray(jax.jit(poisson_inverse_cdf)(jnp.asarray(u), lam))
    expected = stats.poisson.ppf(u, lam) if lam > 0 else np.zeros_like(u)
    np.testing.assert_array_equal(got, expected)


def test_clutter_positions_uniform_over_region(scenario, runs):
    region = np.asarray(scenario.clutter_region)
    is_clutter = runs.scans.origin == CLUTTER
    points = runs.scans.measurements[is_clutter]  # (≈20,000, 2): range (m), bearing (rad)
    assert points.shape[0] == runs.scans.num_clutter.sum()  # nothing dropped at this capacity
    unit = (points - region[:, 0]) / (region[:, 1] - region[:, 0])
    assert np.all((unit >= 0) & (unit < 1))
    for c in range(2):
        assert stats.kstest(unit[:, c], "uniform").pvalue > 1e-3


def test_detections_alive_and_origins(scenario, runs):
    birth, death = np.asarray(scenario.birth_step), np.asarray(scenario.death_step)
    k = np.arange(scenario.num_steps)[:, None]
    np.testing.assert_array_equal(runs.alive, np.broadcast_to((k >= birth) & (k < death), runs.alive.shape))
    assert not np.any(runs.detected & ~runs.alive)  # dead or unborn targets are never detected
    # P̂_D over alive target-steps (n = 20·340 = 6,800): |P̂ − 0.9| <= 2.5758 √(0.9·0.1/n) = 0.0094.
    n_alive = runs.alive.sum()
    p_hat = runs.detected.sum() / n_alive
    assert abs(p_hat - 0.9) <= Z99 * np.sqrt(0.9 * 0.1 / n_alive)

    scans = runs.scans
    # Each target appears exactly once in a scan where it is detected, never otherwise.
    per_target = (scans.origin[..., None] == np.arange(scenario.max_targets)).sum(axis=-2)
    np.testing.assert_array_equal(per_target, runs.detected.astype(int))
    # Layout: detections first (in target order), then clutter, then padding; nothing lost.
    num_det = runs.detected.sum(-1)
    slot = np.arange(scenario.max_measurements)
    np.testing.assert_array_equal(scans.origin >= 0, slot < num_det[..., None])
    np.testing.assert_array_equal(scans.origin == CLUTTER,
                                  (slot >= num_det[..., None]) & (slot < (num_det + scans.num_clutter)[..., None]))
    np.testing.assert_array_equal(scans.valid, scans.origin != PADDING)
    target_slots = np.where(scans.origin >= 0, scans.origin, 99)
    assert np.all(np.diff(target_slots, axis=-1)[(scans.origin[..., 1:] >= 0)] > 0)
    np.testing.assert_array_equal(scans.valid.sum(-1) + scans.num_dropped, num_det + scans.num_clutter)
    assert not scans.overflow.any() and not scans.num_dropped.any()


def test_target_measurements_have_covariance_r(scenario, runs):
    model = scenario.model
    r_idx, k_idx, slot = np.nonzero(runs.scans.origin >= 0)
    j = runs.scans.origin[r_idx, k_idx, slot]
    z = runs.scans.measurements[r_idx, k_idx, slot]
    # The stored measurement is that target's drawn measurement, bit for bit.
    np.testing.assert_array_equal(z, runs.target_measurements[r_idx, k_idx, j])
    h = _range_bearing(runs.states[r_idx, k_idx, j])
    R = np.asarray(model.measurement_noise_cov(0))
    w = (z - h) / np.sqrt(np.diag(R))  # R is diagonal: whitened residuals ~ N(0, I)
    n = w.shape[0]  # ≈ 6,100 detections
    assert n > 5000
    # Mean of each component: |w̄| <= 2.5758/√n (≈ 0.033).
    assert np.all(np.abs(w.mean(0)) <= Z99 / np.sqrt(n))
    # Σ w_c² ~ χ²(n) for each component (variance 1 in units of R): 99% chi-square bounds
    # (≈ [0.954, 1.047] · n).
    ss = (w**2).sum(0)
    assert np.all((stats.chi2.ppf(0.005, n) <= ss) & (ss <= stats.chi2.ppf(0.995, n)))
    # Off-diagonal: the sample correlation is within ±2.5758/√n (≈ 0.033).
    assert abs(np.corrcoef(w.T)[0, 1]) <= Z99 / np.sqrt(n)


def test_run_i_reproduces_single_run_and_key_stream(scenario, runs):
    i = 7
    run_key = jax.random.fold_in(KEY, i)
    one = jax.tree.map(np.asarray, simulate_scenario(scenario, run_key))
    jax.tree.map(lambda a, b: np.testing.assert_array_equal(a, b[i]), one, runs)

    # Recompute run i from the documented streams, target by target, with the single-target
    # noise machinery (step_normals under the target's key words, psd_sqrt factors).
    model = scenario.model
    T, N, n = scenario.num_steps, scenario.max_targets, model.state_dim
    Lq = np.asarray(psd_sqrt(model.process_noise_cov(0)))
    Lr = np.asarray(psd_sqrt(model.measurement_noise_cov(0)))
    F = np.asarray(model.transition_model.transition_matrix(0))
    x0 = np.asarray(scenario.initial_states)
    birth, death = np.asarray(scenario.birth_step), np.asarray(scenario.death_step)
    words = stream_words(run_key, TARGET_STREAM, jnp.arange(N))  # (N, 2)
    draw = jax.jit(jax.vmap(lambda k: step_normals(words, k, n + 2, jnp.float64)))
    eps_all = np.asarray(draw(jnp.arange(T)))  # (T, n + m, N)
    h_all = _range_bearing(one.states)
    for j in range(N):
        eps = eps_all[:, :, j]
        x = one.states[:, j]
        np.testing.assert_array_equal(x[: birth[j] + 1], np.broadcast_to(x0[j], (birth[j] + 1, n)))
        ks = np.arange(birth[j] + 1, death[j])
        np.testing.assert_allclose(x[ks], x[ks - 1] @ F.T + eps[ks, :n] @ Lq.T, rtol=1e-12, atol=1e-9)
        np.testing.assert_array_equal(x[death[j]:], np.broadcast_to(x[death[j] - 1], (T - death[j], n)))
        np.testing.assert_allclose(one.target_measurements[:, j], h_all[:, j] + eps[:, n:] @ Lr.T,
                                   rtol=1e-12, atol=1e-12)
    u = np.asarray(_uniforms(stream_words(run_key, DETECTION_STREAM), T, N, jnp.float64))
    np.testing.assert_array_equal(one.detected, one.alive & (u < 0.9))


def test_overflow_is_counted_flagged_and_warned(runs):
    # The shared scenario with 3 slots instead of 48 (≈3.4 detections + 10 clutter points a scan).
    small = crossing_targets(num_targets=4, num_steps=100, max_measurements=3)
    with pytest.warns(CapacityWarning, match=r"max_measurements=3") as record:
        out = jax.tree.map(np.asarray, simulate_scenarios(small, KEY, NUM_RUNS))
    scans = out.scans
    assert out.overflow.all() and scans.overflow.mean() > 0.99
    assert scans.num_dropped.min() >= 0 and scans.num_dropped.sum() > 0
    # No silent truncation: stored + dropped = detections + clutter drawn, in every scan.
    total = out.detected.sum(-1) + scans.num_clutter
    np.testing.assert_array_equal(scans.valid.sum(-1) + scans.num_dropped, total)
    np.testing.assert_array_equal(scans.overflow, total > 3)
    message = str(record[0].message)
    assert f"{int(scans.overflow.sum())} of 2000 scans" in message
    assert f"largest count seen: {int(total.max())}" in message
    # The capacity only decides what is stored: the same key with 48 slots (the shared runs)
    # holds the same first 3 measurements, the same truth and the same counts.
    np.testing.assert_array_equal(out.states, runs.states)
    np.testing.assert_array_equal(out.detected, runs.detected)
    np.testing.assert_array_equal(scans.num_clutter, runs.scans.num_clutter)
    np.testing.assert_array_equal(scans.origin, runs.scans.origin[..., :3])
    np.testing.assert_array_equal(scans.measurements, runs.scans.measurements[..., :3, :])


def _base_args(scenario):
    return dict(
        model=scenario.model,
        initial_states=np.asarray(scenario.initial_states),
        birth_step=np.asarray(scenario.birth_step),
        death_step=np.asarray(scenario.death_step),
        detection_probability=0.9,
        clutter_rate=10.0,
        clutter_region=np.asarray(scenario.clutter_region),
        max_measurements=48,
        num_steps=100,
    )


@pytest.mark.parametrize(
    "name, value",
    [
        ("model", "radar"),
        ("initial_states", np.zeros((4, 3))),
        ("initial_states", np.full((4, 4), np.nan)),
        ("birth_step", np.array([0, 1, 2])),
        ("birth_step", np.array([0.0, 1.0, 2.0, 3.0])),
        ("birth_step", np.array([-1, 0, 0, 0])),
        ("death_step", np.array([0, 95, 90, 85])),
        ("detection_probability", 1.2),
        ("detection_probability", np.full((5,), 0.9)),
        ("clutter_rate", -1.0),
        ("clutter_rate", np.ones(2)),
        ("clutter_region", np.zeros((2,))),
        ("clutter_region", np.array([[0.0, 1e4], [0.5, -0.5]])),
        ("max_measurements", 0),
        ("num_steps", 0),
    ],
)
def test_input_errors_name_the_argument(scenario, name, value):
    args = _base_args(scenario)
    args[name] = value
    model = args.pop("model")
    pos = [args.pop(a) for a in ("initial_states", "birth_step", "death_step")]
    with pytest.raises(InputError, match=f"`{name}`"):
        Scenario(model, *pos, **args)


def test_entry_point_errors_and_detection_probability_shapes(scenario):
    with pytest.raises(InputError, match="`num_runs`"):
        simulate_scenarios(scenario, KEY, 0)
    with pytest.raises(InputError, match="`scenario`"):
        simulate_scenario("scenario", KEY)
    with pytest.raises(InputError, match="`key`"):
        simulate_scenario(scenario, 1.5)
    args = _base_args(scenario)
    model = args.pop("model")
    pos = [args.pop(a) for a in ("initial_states", "birth_step", "death_step")]
    for pd in (0.5, [0.0, 0.5, 0.9, 1.0], np.full((100, 4), 0.25)):
        args["detection_probability"] = pd
        s = Scenario(model, *pos, **args)
        assert s.detection_probability.shape == (100, 4)
        np.testing.assert_array_equal(s.detection_probability, np.broadcast_to(pd, (100, 4)))
    assert float(s.clutter_density) == pytest.approx(10.0 / (1e4 * np.pi / 2))

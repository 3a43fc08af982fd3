"""The Williams (2015) scenario of García-Fernández's PMBM reference, and ``Scenario(truth_states=...)``.

The truth is drawn once from a key and shared by every run; the statistical checks on it (the
midpoint, the recursion's increments) and on the simulated scans (clutter counts, detections) use
99.9% bounds, each stated next to its assertion. Three runs (243 scans) are simulated once and
shared.
"""

import jax
import numpy as np
import pytest
from scipy import stats

from jaxtrack import InputError
from jaxtrack.multitarget import (
    CLUTTER,
    CapacityWarning,
    Scenario,
    Williams15Settings,
    simulate_scenario,
    simulate_scenarios,
    williams15,
)

KEY = jax.random.key(2015)
NUM_RUNS = 3
Z999 = 3.2905  # two-sided 99.9% normal quantile


@pytest.fixture(scope="module")
def built():
    return williams15()


@pytest.fixture(scope="module")
def runs(built):
    scenario, _ = built
    return jax.tree.map(np.asarray, simulate_scenarios(scenario, KEY, NUM_RUNS))


def test_definition_and_settings(built):
    scenario, settings = built
    model = scenario.model
    # jaxtrack's layout [x, y, vx, vy]: the reference's kron(I2, [[1, T], [0, 1]]) reordered.
    F = np.block([[np.eye(2), np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])
    Q = 0.01 * np.kron(np.array([[1 / 3, 1 / 2], [1 / 2, 1.0]]), np.eye(2))
    np.testing.assert_allclose(model.F, F, atol=0)
    np.testing.assert_allclose(model.Q, Q, rtol=1e-15)
    np.testing.assert_array_equal(model.H, np.eye(2, 4))
    np.testing.assert_array_equal(model.R, np.eye(2))
    assert (scenario.num_steps, scenario.max_targets, scenario.max_measurements) == (81, 4, 40)
    np.testing.assert_array_equal(scenario.detection_probability, np.full((81, 4), 0.9))
    assert float(scenario.clutter_rate) == 10.0
    np.testing.assert_array_equal(scenario.clutter_region, [[0.0, 300.0], [0.0, 300.0]])
    assert float(scenario.clutter_density) == pytest.approx(10.0 / 90_000.0, rel=1e-15)
    # The default capacity: P(Poisson(10) + Binomial(4, 0.9) > 40) = 3.3e-11 per scan.
    total = np.convolve(stats.poisson.pmf(np.arange(200), 10.0), stats.binom.pmf(np.arange(5), 4, 0.9))
    assert total[41:].sum() < 1e-10

    assert isinstance(settings, Williams15Settings)
    birth_cov = np.diag([150.0**2, 150.0**2, 1.0, 1.0])
    assert (float(settings.prob_survival), float(settings.prob_detect)) == (0.99, 0.9)
    assert float(settings.clutter_density) == pytest.approx(float(scenario.clutter_density), rel=1e-15)
    np.testing.assert_array_equal(settings.birth_weights, [0.005])
    np.testing.assert_array_equal(settings.birth_means, [[100.0, 100.0, 0.0, 0.0]])
    np.testing.assert_array_equal(settings.birth_covs, [birth_cov])
    np.testing.assert_array_equal(settings.initial_weights, [3.0])
    np.testing.assert_array_equal(settings.initial_means, settings.birth_means)
    np.testing.assert_array_equal(settings.initial_covs, settings.birth_covs)
    gospa = (settings.gospa_cutoff, settings.gospa_order, settings.gospa_alpha)
    assert gospa == (10.0, 2.0, 2.0) and settings.num_runs == 100


def test_truth_is_deterministic_in_the_key_and_shared_by_every_run(built, runs):
    scenario, _ = built
    truth = np.asarray(scenario.truth_states)
    assert truth.shape == (81, 4, 4) and np.all(np.isfinite(truth))
    np.testing.assert_array_equal(np.asarray(williams15(0)[0].truth_states), truth)
    np.testing.assert_array_equal(np.asarray(williams15(jax.random.key(0))[0].truth_states), truth)
    other = np.asarray(williams15(1)[0].truth_states)
    assert np.all(other != truth)
    # Every run has the same truth; the measurements differ between runs.
    np.testing.assert_array_equal(runs.states, np.broadcast_to(truth, runs.states.shape))
    np.testing.assert_array_equal(scenario.initial_states, truth[0])
    assert np.all(runs.target_measurements[0] != runs.target_measurements[1])
    # Run i is simulate_scenario with fold_in(key, i), as without a fixed truth.
    one = jax.tree.map(np.asarray, simulate_scenario(scenario, jax.random.fold_in(KEY, 2)))
    jax.tree.map(lambda a, b: np.testing.assert_array_equal(a, b[2]), one, runs)


def test_alive_masks(built, runs):
    scenario, _ = built
    np.testing.assert_array_equal(scenario.birth_step, [0, 0, 0, 0])
    np.testing.assert_array_equal(scenario.death_step, [40, 81, 81, 81])
    k = np.arange(81)
    expected = np.stack([k <= 39, k <= 80, k <= 80, k <= 80], axis=-1)
    for r in range(NUM_RUNS):
        np.testing.assert_array_equal(runs.alive[r], expected)
    assert not runs.detected[:, 40:, 0].any()
    assert not (runs.scans.origin[:, 40:] == 0).any()


def test_midpoint_states_near_the_centre(built):
    truth = np.asarray(built[0].truth_states)
    # x_40 − [150, 150, 0, 0] ~ N(0, 0.1 I), 16 numbers: Σ d²/0.1 ~ χ²(16), below its 99.9%
    # quantile 39.25; every position within 1.5 m of 150 (4.7σ).
    d = truth[40] - np.array([150.0, 150.0, 0.0, 0.0])
    assert np.sum(d**2) / 0.1 <= stats.chi2.ppf(0.999, 16)
    assert np.all(np.abs(d[:, :2]) < 1.5)
    # The targets meet mid-scenario: every pair within 3 m at step 40, spread apart at the ends.
    pos = truth[:, :, :2]
    i, j = np.triu_indices(4, 1)
    gaps = np.linalg.norm(pos[:, i] - pos[:, j], axis=-1)  # (81, 6) pairwise distances, m
    assert gaps[40].max() < 3.0 and gaps[[0, 80]].max() > 10.0


@pytest.mark.parametrize("key", [0, 1])
def test_forward_backward_increments_have_covariance_q(key):
    scenario, _ = williams15(key)
    truth = np.asarray(scenario.truth_states)
    F, Q = np.asarray(scenario.model.F), np.asarray(scenario.model.Q)
    # d_k = x_{k+1} − F x_k: w_k after the midpoint (forward), −w'_k before it (backward:
    # F x_k = x_{k+1} + w'_k), every one N(0, Q), independent over k and targets.
    d = truth[1:] - truth[:-1] @ F.T  # (80, 4, 4)
    L = np.linalg.cholesky(Q)
    for part in (d[:40], d[40:], d):  # backward half, forward half, all 4 × 80
        e = np.linalg.solve(L, part.reshape(-1, 4).T).T  # whitened: N(0, I₄)
        n = e.shape[0]
        # Whitened mean per component: |ē| <= 3.2905/√n.
        assert np.all(np.abs(e.mean(0)) <= Z999 / np.sqrt(n))
        # Σ|e|² ~ χ²(4n): within its two-sided 99.9% bounds.
        ss = np.sum(e**2)
        assert stats.chi2.ppf(0.0005, 4 * n) <= ss <= stats.chi2.ppf(0.9995, 4 * n)
        # Likelihood-ratio test of Cov = Q (known zero mean; Anderson 2003, §10.8):
        # n [tr S − log det S − 4] ~ χ²(10) for S the whitened sample covariance, below its
        # 99.9% quantile 29.59.
        S = e.T @ e / n
        lr = n * (np.trace(S) - np.linalg.slogdet(S)[1] - 4)
        assert lr <= stats.chi2.ppf(0.999, 10)


def test_clutter_and_detections(runs):
    scans = runs.scans
    counts = scans.num_clutter.ravel()
    n_scans = counts.size
    assert n_scans == 243
    # Σ counts ~ Poisson(10 · 243): within its two-sided 99.9% bounds ([2278, 2584]).
    lo, hi = stats.poisson.ppf([0.0005, 0.9995], 10.0 * n_scans)
    assert lo <= counts.sum() <= hi
    assert not runs.overflow.any() and not scans.num_dropped.any()
    points = scans.measurements[scans.origin == CLUTTER]
    assert points.shape[0] == counts.sum()
    assert np.all((points >= 0.0) & (points <= 300.0))
    # Detections: Binomial(alive target-steps, 0.9), within its two-sided 99.9% bounds.
    n_alive = int(runs.alive.sum())
    assert n_alive == NUM_RUNS * (40 + 3 * 81)
    lo, hi = stats.binom.ppf([0.0005, 0.9995], n_alive, 0.9)
    assert lo <= runs.detected.sum() <= hi
    assert not np.any(runs.detected & ~runs.alive)
    # A detection is H x + v, v ~ N(0, I₂) m: every component within |v| < 5.5 (P = 3.8e-8 each,
    # 6.5e-5 over the ≈1,700 components).
    r, k, slot = np.nonzero(scans.origin >= 0)
    j = scans.origin[r, k, slot]
    v = scans.measurements[r, k, slot] - runs.states[r, k, j, :2]
    assert np.all(np.abs(v) < 5.5)


def test_fixed_truth_uses_the_same_streams(built):
    # Simulate with plant noise, then give that run's states as the fixed truth: the same key
    # gives the same detections, measurements and clutter (the streams do not move).
    scenario, _ = built
    drawn = Scenario(
        scenario.model, np.asarray(scenario.truth_states[0]), np.asarray(scenario.birth_step),
        np.asarray(scenario.death_step), detection_probability=0.9, clutter_rate=10.0,
        clutter_region=np.asarray(scenario.clutter_region), max_measurements=40, num_steps=81,
    )
    first = jax.tree.map(np.asarray, simulate_scenario(drawn, KEY))
    fixed = Scenario(
        scenario.model, None, np.asarray(scenario.birth_step), np.asarray(scenario.death_step),
        detection_probability=0.9, clutter_rate=10.0, clutter_region=np.asarray(scenario.clutter_region),
        max_measurements=40, num_steps=81, truth_states=first.states,
    )
    again = jax.tree.map(np.asarray, simulate_scenario(fixed, KEY))
    jax.tree.map(np.testing.assert_array_equal, again, first)


def test_capacity_warning_is_kept(built):
    small, _ = williams15(max_measurements=4)
    with pytest.warns(CapacityWarning, match=r"max_measurements=4"):
        out = simulate_scenario(small, KEY)
    assert bool(out.overflow)
    with pytest.raises(InputError, match="`max_measurements`"):
        williams15(max_measurements=0)
    with pytest.raises(InputError, match="`key`"):
        williams15(1.5)


def _args(scenario, **changes):
    args = dict(
        birth_step=np.asarray(scenario.birth_step), death_step=np.asarray(scenario.death_step),
        detection_probability=0.9, clutter_rate=10.0, clutter_region=np.asarray(scenario.clutter_region),
        max_measurements=40, num_steps=81, initial_states=None, truth_states=np.asarray(scenario.truth_states),
    )
    args.update(changes)
    pos = [args.pop(a) for a in ("initial_states", "birth_step", "death_step")]
    return pos, args


@pytest.mark.parametrize(
    "name, changes",
    [
        ("truth_states", dict(truth_states=np.zeros((80, 4, 4)))),
        ("truth_states", dict(truth_states=np.zeros((81, 4, 3)))),
        ("truth_states", dict(truth_states=np.zeros((81, 4)))),
        ("truth_states", dict(truth_states=np.zeros((81, 0, 4)))),
        ("truth_states", dict(truth_states=np.full((81, 4, 4), np.inf))),
        ("truth_states", dict(truth_states="truth")),
        ("birth_step", dict(truth_states=np.zeros((81, 3, 4)))),  # N = 3 from truth_states, 4 birth steps
        ("initial_states", dict(initial_states=np.zeros((4, 4)))),  # both given
        ("initial_states", dict(truth_states=None)),  # neither given
    ],
)
def test_truth_states_errors_name_the_argument(built, name, changes):
    scenario, _ = built
    pos, args = _args(scenario, **changes)
    with pytest.raises(InputError, match=f"`{name}`"):
        Scenario(scenario.model, *pos, **args)

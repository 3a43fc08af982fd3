"""Sensor management by gradient (jaxtrack.design._sensor_management).

Oracles: a plain-NumPy Kalman recursion (tests/_sensor_management_cases.py) and the library's own
``KalmanFilter`` for the cost; the exhaustive optimum over all ``N^T`` schedules (NumPy) for the
gradient design; Stone Soup's ``BruteForceSensorManager`` for the greedy schedule; central finite
differences for the gradients. Every test uses one of two small scenarios, so each jitted function
compiles once per scenario.
"""

from __future__ import annotations

import functools
import itertools
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.design import (
    NotConvergedWarning,
    SensorSchedulingProblem,
    greedy_sensor_schedule,
    relaxed_schedule_cost,
    relaxed_sensor_schedule,
    schedule_cost,
    simulate_sensor_schedule,
)
from jaxtrack.filters import KalmanFilter, run_filter
from jaxtrack.models import constant_velocity
from jaxtrack.montecarlo import gospa

from _sensor_management_cases import all_schedules, numpy_costs, numpy_relaxed_cost, scenario, stonesoup_schedule

T_SMALL = 7  # 3^7 = 2187 schedules: exhaustive in NumPy in well under a second


@functools.cache
def small():
    """Three targets, one sensor, seven scans."""
    sc = scenario(3, T_SMALL, seed=7)
    return sc, sc.problem()


@functools.cache
def two_sensors():
    """Three targets, two sensors of different noise, four scans (9^4 = 6561 schedules)."""
    sc = scenario(3, 4, seed=2, noise_std=(10.0, 25.0))
    return sc, sc.problem()


@functools.cache
def exhaustive(which):
    sc, problem = {"small": small, "two": two_sensors}[which]()
    schedules = all_schedules(problem)
    costs = numpy_costs(problem, schedules)
    best = int(np.argmin(costs))
    return schedules[best], costs[best], costs


@functools.cache
def relaxed(which):
    sc, problem = {"small": small, "two": two_sensors}[which]()
    with warnings.catch_warnings():
        warnings.simplefilter("error", NotConvergedWarning)
        return relaxed_sensor_schedule(problem)


@functools.cache
def greedy(which):
    sc, problem = {"small": small, "two": two_sensors}[which]()
    return greedy_sensor_schedule(problem)


def test_schedule_cost_equals_numpy_recursion_and_kalman_filter():
    sc, problem = small()
    rng = np.random.default_rng(0)
    schedules = rng.integers(0, sc.num_targets, size=(4, T_SMALL))
    expected = numpy_costs(problem, schedules[:, :, None])
    got = np.array([float(schedule_cost(problem, s)) for s in schedules])
    np.testing.assert_allclose(got, expected, rtol=1e-12)

    # The library's Kalman filter, one target at a time, its looks as the measurement mask; the
    # prior sits one scan before the first look (first_step="predict").
    schedule = schedules[0]
    total = 0.0
    for i, model in enumerate(sc.models()):
        result = run_filter(KalmanFilter(), model, jnp.zeros((T_SMALL, 2)), mask=jnp.asarray(schedule == i),
                            first_step="predict")
        P = np.asarray(result.filtered_cov)
        total += np.sum(P[:, 0, 0] + P[:, 1, 1])
    np.testing.assert_allclose(got[0], total, rtol=1e-12)


def test_relaxed_cost_at_one_hot_weights_is_the_discrete_cost():
    sc, problem = two_sensors()
    schedule = np.array([[0, 1], [2, 2], [1, 0], [0, 0]])
    w = np.eye(sc.num_targets)[schedule]
    np.testing.assert_allclose(float(relaxed_schedule_cost(problem, w)), float(schedule_cost(problem, schedule)),
                               rtol=1e-14)
    np.testing.assert_allclose(float(schedule_cost(problem, schedule)), numpy_costs(problem, schedule[None])[0],
                               rtol=1e-12)


def test_relaxed_cost_is_the_information_form_with_fractional_looks():
    """A look of weight w adds w·HᵀR⁻¹H to the information (NumPy, explicit inverses)."""
    sc, problem = two_sensors()
    w = np.random.default_rng(2).uniform(0.0, 1.0, (problem.num_scans, problem.num_sensors, problem.num_targets))
    np.testing.assert_allclose(float(relaxed_schedule_cost(problem, w)), numpy_relaxed_cost(problem, w), rtol=1e-11)


@pytest.mark.parametrize("which", ["small", "two"])
def test_gradient_design_finds_the_exhaustive_optimum_and_beats_greedy(which):
    best_schedule, best_cost, costs = exhaustive(which)
    design, (greedy_schedule, greedy_cost) = relaxed(which), greedy(which)
    _, problem = {"small": small, "two": two_sensors}[which]()
    np.testing.assert_allclose(design.cost, numpy_costs(problem, design.schedule[None])[0], rtol=1e-12)
    np.testing.assert_allclose(greedy_cost, numpy_costs(problem, greedy_schedule[None])[0], rtol=1e-12)
    assert design.cost <= greedy_cost * (1 + 1e-12)
    assert design.cost <= design.rounded_cost * (1 + 1e-12)
    np.testing.assert_allclose(design.cost, best_cost, rtol=1e-12)
    # The scenarios are ones where looking ahead pays: greedy is not optimal.
    assert greedy_cost > best_cost * (1 + 1e-3)
    assert np.all(np.abs(design.weights.max(axis=-1) - 1) < 0.1)  # the relaxation settled


@pytest.mark.parametrize("which", ["small", "two"])
def test_greedy_equals_stonesoup_brute_force_manager(which):
    pytest.importorskip("stonesoup")
    sc, problem = {"small": small, "two": two_sensors}[which]()
    schedule, _ = greedy(which)
    np.testing.assert_array_equal(schedule.reshape(sc.num_scans, -1), stonesoup_schedule(sc))


def test_greedy_is_the_per_scan_brute_force():
    """Independent of Stone Soup: at every scan, the greedy look is the best one-scan extension of
    its own prefix among all N looks (NumPy costs of the prefix schedules)."""
    sc, problem = small()
    schedule, _ = greedy("small")
    for k in range(T_SMALL):
        trials = np.repeat(schedule[None], sc.num_targets, axis=0)
        trials[:, k] = np.arange(sc.num_targets)
        prefix = SensorSchedulingProblem(sc.models(), k + 1)
        costs = numpy_costs(prefix, trials[:, : k + 1, None])
        assert schedule[k] == int(np.argmin(costs))


def _full_evaluation_search(problem, schedule, rtol=1e-12):
    """The local search as it was before it became incremental: every neighbour (each scan's joint
    look replaced by each of the N^S joint looks, scan-major; then every exchange of two looks in
    ``np.triu_indices`` order, same-scan ones included) costed in FULL, the first cheapest taken
    while it improves by more than ``rtol·|J|``. Python loop, NumPy neighbours."""
    from jaxtrack.design._sensor_management import _discrete_cost

    T, S = schedule.shape
    configs = np.array(list(itertools.product(range(problem.num_targets), repeat=S)))
    cost = eqx.filter_jit(jax.vmap(_discrete_cost, in_axes=(None, 0)))
    J, moves = float(_discrete_cost(problem, jnp.asarray(schedule))), 0
    while True:
        singles = np.repeat(schedule[None], T * len(configs), axis=0)
        singles[np.arange(len(singles)), np.repeat(np.arange(T), len(configs))] = np.tile(configs, (T, 1))
        a, b = np.triu_indices(T * S, k=1)
        swaps = np.repeat(schedule.reshape(1, T * S), len(a), axis=0)
        rows = np.arange(len(a))
        swaps[rows, a], swaps[rows, b] = swaps[rows, b], swaps[rows, a].copy()
        trials = np.concatenate([singles, swaps.reshape(-1, T, S)])
        costs = np.asarray(cost(problem, jnp.asarray(trials, jnp.int32)))
        best = int(np.argmin(costs))
        if not costs[best] < J - rtol * abs(J):
            return schedule, J, moves
        schedule, J, moves = trials[best], float(costs[best]), moves + 1


@pytest.mark.parametrize("which", ["small", "two"])
def test_incremental_local_search_equals_full_evaluation(which):
    """The search recosts only the targets a move changes (per-target tables for single moves, two
    recursions per exchange): from random schedules it must take the same moves, reach the same
    schedule and the same J as costing every neighbour in full."""
    from jaxtrack.design._sensor_management import _polish

    _, problem = {"small": small, "two": two_sensors}[which]()
    T, S, N = problem.num_scans, problem.num_sensors, problem.num_targets
    # Four starts: the shape relaxed_sensor_schedule's own call compiled.
    starts = np.random.default_rng(5).integers(0, N, (4, T, S)).astype(np.int32)
    schedules, J, moves, still = _polish(problem, jnp.asarray(starts), jnp.asarray(T * S * N, jnp.int32),
                                         jnp.asarray(1e-12))
    assert np.sum(np.asarray(moves)) > 0 and not np.any(np.asarray(still))
    for r in range(len(starts)):
        ref_schedule, ref_J, ref_moves = _full_evaluation_search(problem, starts[r])
        np.testing.assert_array_equal(np.asarray(schedules)[r], ref_schedule)
        assert int(np.asarray(moves)[r]) == ref_moves
        np.testing.assert_allclose(float(np.asarray(J)[r]), ref_J, rtol=1e-13)


def test_screened_local_search_stops_at_a_local_optimum_of_the_full_neighbourhood():
    """The screened search prices only a few exchanges per iteration, so its path may differ from
    the best-improvement one; where it stops, costing every neighbour in full (the NumPy-built
    neighbours of _full_evaluation_search) must find no improving move, and its J must be the
    schedule's exact cost."""
    from jaxtrack.design._schedule_search import _screened_polish

    _, problem = two_sensors()
    T, S, N = problem.num_scans, problem.num_sensors, problem.num_targets
    starts = np.random.default_rng(5).integers(0, N, (4, T, S)).astype(np.int32)
    schedules, J, moves, still = _screened_polish(problem, jnp.asarray(starts), jnp.asarray(T * S * N, jnp.int32),
                                                  jnp.asarray(1e-12), k=2)
    assert np.sum(np.asarray(moves)) > 0 and not np.any(np.asarray(still))
    schedules = np.asarray(schedules)
    np.testing.assert_allclose(np.asarray(J), numpy_costs(problem, schedules), rtol=1e-12)
    for r in range(len(starts)):
        _, ref_J, ref_moves = _full_evaluation_search(problem, schedules[r])
        assert ref_moves == 0
        np.testing.assert_allclose(ref_J, float(np.asarray(J)[r]), rtol=1e-13)


def _central_difference(f, x, direction, h):
    return (f(x + h * direction) - f(x - h * direction)) / (2 * h)


def test_relaxed_cost_gradients_match_finite_differences():
    sc, problem = two_sensors()
    rng = np.random.default_rng(1)
    w = rng.uniform(0.1, 1.0, (problem.num_scans, problem.num_sensors, problem.num_targets))
    cost = jax.jit(lambda p, w: relaxed_schedule_cost(p, w))
    g = np.asarray(jax.grad(cost, argnums=1)(problem, jnp.asarray(w)))
    fd = np.zeros_like(w)
    for idx in np.ndindex(w.shape):
        e = np.zeros_like(w)
        e[idx] = 1.0
        fd[idx] = _central_difference(lambda x: float(cost(problem, x)), w, e, 1e-5)
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-6 * np.max(np.abs(g)))

    # R of each sensor, along symmetric directions (R stays a covariance).
    def of_R(R):
        return cost(eqx.tree_at(lambda p: p.measurement_noise_cov, problem, R), jnp.asarray(w))

    R = np.asarray(problem.measurement_noise_cov)
    gR = np.asarray(jax.grad(of_R)(jnp.asarray(R)))
    for s, (a, b) in [(0, (0, 0)), (0, (0, 1)), (1, (1, 1)), (1, (0, 1))]:
        E = np.zeros_like(R)
        E[s, a, b] = E[s, b, a] = 1.0
        fd = _central_difference(lambda x: float(of_R(jnp.asarray(x))), R, E, 1e-3)
        np.testing.assert_allclose(np.sum(gR * E), fd, rtol=1e-6)


def test_schedule_cost_is_differentiable_in_the_noise():
    """``∂J/∂σ²`` of a fixed discrete schedule: positive (more noise, more error) and equal to
    finite differences; the gradient design's cost moves with R as the filter says."""
    sc, problem = small()
    schedule = relaxed("small").schedule

    def of_scale(a):
        return schedule_cost(eqx.tree_at(lambda p: p.measurement_noise_cov, problem, a * problem.measurement_noise_cov),
                             schedule)

    d = float(jax.grad(of_scale)(1.0))
    fd = _central_difference(lambda a: float(of_scale(a)), 1.0, 1.0, 1e-4)
    assert d > 0
    np.testing.assert_allclose(d, fd, rtol=1e-6)


def test_the_cost_is_the_expected_squared_gospa_of_a_monte_carlo_of_the_schedule():
    """4,000 runs of two schedules of the two-sensor case (3 targets, noise 10 and 25 m): the mean
    over runs of Σ_k Σ_i ‖H(x̂ − x)‖² equals J within 4 standard errors (two-sided, a false failure
    has probability 6e-5 under the normal approximation of a mean of 4,000 runs), and Σ_k GOSPA_k²
    (p = 2, α = 2, cut-off beyond every error) equals that sum run by run to 1e-12: J is the expected
    squared GOSPA summed over the scans. The two schedules share the targets' paths (common
    random numbers), and the better schedule's mean is the lower one by more than 4 SE of the
    paired difference."""
    _, problem = two_sensors()
    best, _, _ = exhaustive("two")
    worst = np.zeros_like(best)  # both sensors always at target 0
    key = jax.random.key(3)
    sims = [simulate_sensor_schedule(problem, sched, key, 4000) for sched in (best, worst)]
    np.testing.assert_array_equal(np.asarray(sims[0].truth), np.asarray(sims[1].truth))
    totals = []
    for sched, sim in zip((best, worst), sims):
        sq = np.sum(np.asarray(sim.errors) ** 2, axis=(1, 2, 3))
        J = float(schedule_cost(problem, sched))
        se = sq.std(ddof=1) / np.sqrt(sq.size)
        assert abs(sq.mean() - J) <= 4 * se, (sq.mean(), J, se)
        totals.append(sq)
    valid = jnp.ones(problem.num_targets, bool)
    per_scan = jax.jit(jax.vmap(jax.vmap(
        lambda t, e: gospa(t, valid, e, valid, cutoff=1e6, order=2).distance)))(sims[0].truth, sims[0].estimates)
    np.testing.assert_allclose(np.sum(np.asarray(per_scan) ** 2, axis=1), totals[0], rtol=1e-12)
    diff = totals[1] - totals[0]
    assert diff.mean() > 4 * diff.std(ddof=1) / np.sqrt(diff.size), diff.mean()


def test_unsettled_relaxation_warns():
    _, problem = small()
    with pytest.warns(NotConvergedWarning, match="did not settle"):
        relaxed_sensor_schedule(problem, steps=2, entropy_weight=(0.0, 0.0))


def _model(**kw):
    args = dict(accel_psd=1.0, measurement_std=10.0, initial_cov=np.diag([100.0, 100.0, 4.0, 4.0]))
    args.update(kw)
    return constant_velocity(1.0, **args)


@pytest.mark.parametrize(
    "build, name",
    [
        (lambda: SensorSchedulingProblem([], 5), "models"),
        (lambda: SensorSchedulingProblem(_model(), 5), "models"),
        (lambda: SensorSchedulingProblem([_model(), "x"], 5), r"models\[1\]"),
        (lambda: SensorSchedulingProblem([constant_velocity(np.ones(5), accel_psd=1.0, measurement_std=10.0,
                                                            initial_cov=np.eye(4))], 5), r"models\[0\]"),
        (lambda: SensorSchedulingProblem([_model(), constant_velocity(1.0, dim=3, accel_psd=1.0, measurement_std=1.0,
                                                                     initial_cov=np.eye(6))], 5), r"models\[1\]"),
        (lambda: SensorSchedulingProblem([_model()], 0), "num_scans"),
        (lambda: SensorSchedulingProblem([_model()], 2.5), "num_scans"),
        (lambda: SensorSchedulingProblem([_model(), _model(measurement_std=3.0)], 5), "measurement_noise_cov"),
        (lambda: SensorSchedulingProblem([_model()], 5, measurement_noise_cov=np.diag([1.0, -1.0])),
         "measurement_noise_cov"),
        (lambda: SensorSchedulingProblem([_model()], 5, measurement_noise_cov=np.eye(3)), "measurement_noise_cov"),
        (lambda: SensorSchedulingProblem([_model()], 5, weight=np.diag([1.0, 1.0, -1.0, 0.0])), "weight"),
        (lambda: SensorSchedulingProblem([_model()], 5, weight=np.eye(2)), "weight"),
        (lambda: SensorSchedulingProblem([_model(), _model()], 5, target_weights=[1.0, -1.0]), "target_weights"),
        (lambda: SensorSchedulingProblem([_model(), _model()], 5, target_weights=[1.0, np.nan]), "target_weights"),
        (lambda: _model(initial_cov=np.diag([100.0, 100.0, 4.0, -4.0])), "initial_cov"),
        (lambda: schedule_cost(small()[1], np.zeros(T_SMALL + 1, int)), "schedule"),
        (lambda: schedule_cost(small()[1], np.full(T_SMALL, 3)), "schedule"),
        (lambda: schedule_cost(small()[1], np.full(T_SMALL, -1)), "schedule"),
        (lambda: schedule_cost(small()[1], np.zeros(T_SMALL)), "schedule"),
        (lambda: schedule_cost(two_sensors()[1], np.zeros(4, int)), "schedule"),
        (lambda: schedule_cost("problem", np.zeros(T_SMALL, int)), "problem"),
        (lambda: relaxed_schedule_cost(small()[1], np.ones((T_SMALL, 2))), "weights"),
        (lambda: relaxed_schedule_cost(small()[1], -np.ones((T_SMALL, 3))), "weights"),
        (lambda: relaxed_schedule_cost(small()[1], np.full((T_SMALL, 3), np.inf)), "weights"),
        (lambda: relaxed_sensor_schedule(small()[1], steps=0), "steps"),
        (lambda: relaxed_sensor_schedule(small()[1], learning_rate=0.0), "learning_rate"),
        (lambda: relaxed_sensor_schedule(small()[1], entropy_weight=(0.0, -1.0)), "entropy_weight"),
        (lambda: relaxed_sensor_schedule(small()[1], entropy_weight=(0.0, np.inf)), "entropy_weight"),
        (lambda: relaxed_sensor_schedule(small()[1], entropy_weight=1.0), "entropy_weight"),
        (lambda: relaxed_sensor_schedule(small()[1], starts=0), "starts"),
        (lambda: relaxed_sensor_schedule(small()[1], key=1.5), "key"),
        (lambda: relaxed_sensor_schedule(small()[1], init=np.zeros((T_SMALL, 2))), "init"),
        (lambda: relaxed_sensor_schedule(small()[1], max_moves=0), "max_moves"),
        (lambda: relaxed_sensor_schedule(small()[1], settle=1.5), "settle"),
        (lambda: relaxed_sensor_schedule(small()[1], exchanges=0), "exchanges"),
        (lambda: relaxed_sensor_schedule(small()[1], exchanges=2.0), "exchanges"),
        (lambda: greedy_sensor_schedule(None), "problem"),
        (lambda: simulate_sensor_schedule(small()[1], np.zeros(T_SMALL, int), jax.random.key(0), 0), "num_runs"),
        (lambda: simulate_sensor_schedule(small()[1], np.zeros(T_SMALL, int), jax.random.key(0), 2, separation=0.0),
         "separation"),
        (lambda: simulate_sensor_schedule(small()[1], np.full(T_SMALL, 3), jax.random.key(0), 2), "schedule"),
    ],
)
def test_bad_inputs_name_the_argument(build, name):
    with pytest.raises(InputError, match=f"`{name}"):
        build()


def test_out_of_range_index_under_jit_is_nan_not_a_missing_look():
    _, problem = small()
    cost = jax.jit(schedule_cost)
    assert np.isnan(float(cost(problem, jnp.full(T_SMALL, 3))))
    assert np.isfinite(float(cost(problem, jnp.zeros(T_SMALL, jnp.int32))))

"""Sampling-period design (Ho 1968 Sec. III): targets T33–T35 of specs/ho-sensitivity.md, gradient
schedules against the exhaustive integer optimum, and a Monte Carlo check of maneuver compensation."""

import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.applications import ho_sensitivity as ho
from jaxtrack.design import (
    allocate_rates,
    exhaustive_counts,
    ho_reduction,
    local_search,
    newton_uniform_period,
    relaxed_segment_design,
    round_counts,
    segment_exchange,
)
from jaxtrack.models import ho_plant
from jaxtrack.sensitivity import Autodiff

L_POS = jnp.diag(jnp.array([1.0, 0.0]))


def test_T33_newton_iterates_and_quadratic_convergence():
    r = ho.newton_example()
    np.testing.assert_allclose(r.taus, [0.1, 0.145801, 0.137330, 0.137153, 0.13715278], atol=5e-7)
    assert r.converged and r.costs[-1] == pytest.approx(1000.0, abs=1e-6)
    err = np.abs(r.taus - 0.13715278)
    assert all(err[i + 1] <= 10 * err[i] ** 2 for i in range(3))  # quadratic: e_{i+1} ≤ C e_i²
    ad = newton_uniform_period(lambda t: ho_plant(jnp.full(50, t)), 0.1, 1000.0, L_POS, method=Autodiff())
    np.testing.assert_allclose(ad.taus, r.taus, rtol=1e-12)


def test_newton_damped_and_time_fixed_reach_the_same_period():
    fn = lambda t: ho_plant(jnp.full(50, t))  # noqa: E731
    damped = newton_uniform_period(fn, 0.1, 1000.0, L_POS, step_factor=0.5, max_iter=60)
    tf = newton_uniform_period(fn, 0.1, 1000.0, L_POS, sensitivity="time-fixed")
    for r in (damped, tf):
        assert r.converged and r.taus[-1] == pytest.approx(0.13715278, abs=1e-8)
    assert len(damped.taus) > 10  # λ = 1/2 converges linearly (halving the error each step)
    with pytest.raises(InputError, match="step_factor"):
        newton_uniform_period(fn, 0.1, 1000.0, L_POS, step_factor=1.5)


@pytest.mark.parametrize("g, optimum, counts", [(1.0, 585.8, (8, 1, 1, 10, 20)), (10.0, 1416.0, (1, 1, 1, 17, 20))])
def test_T34_gradient_design_against_exhaustive_optimum(g, optimum, counts):
    problem = ho.segment_problem(g)
    best, J_best, n = exhaustive_counts(problem, 40, hi=20)  # computed here, not copied
    assert n == 62_871 and best == counts and J_best == pytest.approx(optimum, abs=0.05)
    relaxed = relaxed_segment_design(problem, 40, hi=20)
    assert relaxed.counts.sum() == pytest.approx(40.0, abs=1e-6)
    assert np.all(relaxed.counts >= 1 - 1e-9) and np.all(relaxed.counts <= 20 + 1e-9)
    # Continuous optimum alone: within 0.1% (1 g) and 1.5% (10 g: a local minimum, 1435.7).
    assert relaxed.cost <= J_best * (1.001 if g == 1.0 else 1.015)
    rounded = round_counts(relaxed.counts, 40, 1, 20)
    polished, J = local_search(problem, rounded, hi=20)
    assert J <= 1.01 * J_best  # the acceptance bound; in fact it lands on the optimum
    assert polished == counts


def test_T34_ho_rule_and_exchange():
    problem = ho.segment_problem(1.0)
    assert ho_reduction(problem, ho.UNIFORM, 10) == (10, 5, 5, 10, 10)
    assert problem.cost((10, 5, 5, 10, 10)) == pytest.approx(893.55, abs=5e-3)
    counts, costs = segment_exchange(problem, (8, 8, 8, 8, 8), max_relative_change=0.25)
    assert sum(counts) == 40 and all(np.diff(costs) < 0)
    assert costs[-1] < 0.5 * costs[0]  # 1062.3 → about 441
    # Without caps the terminal-only cost is degenerate: samples pile into the last segment.
    assert counts[-1] >= 30


def test_count_gradient_is_the_chain_rule_of_the_segment_sensitivity():
    problem = ho.segment_problem(1.0)
    s = problem.segment_sensitivities((10, 10, 10, 10, 10)).time_fixed
    np.testing.assert_allclose(problem.count_gradient((10, 10, 10, 10, 10)), -s * 0.01, rtol=1e-12)


@pytest.mark.parametrize("g, max_ratio", [(1.0, 0.25), (10.0, 0.10)])
def test_per_step_design_beats_uniform_and_ho_rule(g, max_ratio):
    ps = ho.per_step_example(g)
    uniform = ho.terminal_position_variance(ho.UNIFORM, g)
    ho_rule = ho.terminal_position_variance(ho.HO_RULE_1G if g == 1.0 else ho.HO_RULE_10G, g)
    assert ps.cost < max_ratio * uniform and ps.cost < max_ratio * ho_rule  # 1 g: 212.9 vs 876.3
    assert np.sum(ps.taus[1:]) == pytest.approx(4.9, rel=1e-12) and np.all(ps.taus > 0)
    assert ps.times[-1] == pytest.approx(5.0, rel=1e-12)
    np.testing.assert_allclose(ps.history[-1], ps.cost, rtol=1e-3)


def test_per_step_design_with_minimum_period():
    ps = ho.per_step_example(1.0, min_period=0.05)
    assert np.all(ps.taus[1:] >= 0.05 - 1e-12)
    uniform = ho.terminal_position_variance(ho.UNIFORM, 1.0)
    assert ps.cost < 0.65 * uniform  # 528.4: 40% below uniform even at ≥ 0.05 s between samples


def test_running_cost_objective_runs_and_differs():
    problem = ho.segment_problem(1.0)
    a = relaxed_segment_design(problem, 40, hi=20, objective="running", steps=100)
    b = relaxed_segment_design(problem, 40, hi=20, steps=100)
    assert np.abs(a.counts - b.counts).max() > 1.0
    with pytest.raises(InputError, match="objective"):
        relaxed_segment_design(problem, 40, objective="final")


def test_T35_allocation_algebra():
    rng = np.random.default_rng(3)
    for _ in range(20):
        m = int(rng.integers(2, 6))
        s = rng.normal(size=m) * 50
        c = rng.uniform(5, 15, size=m)
        cap = float(rng.uniform(10, 60))
        dc = allocate_rates(c, s, cap)
        np.testing.assert_allclose(s * dc, np.full(m, s[0] * dc[0]), rtol=1e-10, atol=1e-12)
        assert np.sum(c + dc) == pytest.approx(cap, rel=1e-12)
    with pytest.raises(InputError, match="nonzero"):
        allocate_rates([1.0, 2.0], [1.0, 0.0], 3.0)


def test_allocation_of_three_staggered_trajectories():
    a = ho.allocation_example()
    assert list(np.asarray(a.stage)) == [34, 19, 4]
    assert a.new_total_rate == pytest.approx(25.0, rel=1e-12)
    assert np.all(np.asarray(a.delta_c) < 0)  # over capacity: every rate drops
    np.testing.assert_allclose(a.dJ_predicted, a.dJ_predicted[0], rtol=1e-12)
    actual = np.asarray(a.dJ_actual)
    assert np.all(actual > 0) and actual.max() / actual.min() < 1.15  # nearly equal, as intended


def test_maneuver_compensation_monte_carlo():
    """III-D: 10 g → 13 g for 10 samples from 2.5 s; eq. (80) shortens τ by 0.0144 s. 20,000 runs;
    a variance estimate's relative error is below 3·sqrt(2/M) = 3% with 99.7% probability."""
    mc = ho.maneuver_monte_carlo(20_000, seed=1)
    theory, hw = mc.theory, mc.rel_halfwidth
    assert theory.uncompensated / theory.nominal - 1 > 0.09  # +9.6% without compensation
    assert abs(theory.compensated / theory.nominal - 1) < 0.02  # first-order: −1.7%
    for name in ("uncompensated", "compensated"):
        assert abs(getattr(mc, name) / getattr(theory, name) - 1) < hw
    assert abs(mc.compensated / theory.nominal - 1) < hw + 0.02
    assert mc.uncompensated / theory.nominal - 1 > hw + 0.03


def test_maneuver_indices_analytic_equal_autodiff():
    ex = ho.maneuver_example()
    from jaxtrack.design import maneuver_period_change

    a = maneuver_period_change(ex.model_fn, 0.1, 10.0, 3.0, L_POS)
    b = maneuver_period_change(ex.model_fn, 0.1, 10.0, 3.0, L_POS, method=Autodiff())
    assert a.delta_tau == pytest.approx(b.delta_tau, rel=1e-10)
    assert a.delta_tau == pytest.approx(-0.0143819, abs=5e-7) and a.s_a > 0 and a.s_tau > 0

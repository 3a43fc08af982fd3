"""Every concrete check has a traced twin (issue 37, cause 3): what a constructor rejects on concrete
values is flagged (``ok=False``, or an error with ``throw=True``) when the same value is traced
under ``jit``, so a transformation never turns a rejected input into a silent answer.

Property-based over the family of bad values; each entry point is compiled once (the bad value
is a traced argument of the same shape), so the examples cost run time only.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxtrack import InputError
from jaxtrack.filters import ExtendedKalmanFilter, InteractingMultipleModel, run_filter, run_imm
from jaxtrack.models import ConstantVelocity, CoordinatedTurn, RangeBearing, TrackingModel
from jaxtrack.montecarlo import differentiable_monte_carlo, simulate

SETTINGS = settings(max_examples=8, deadline=None, derandomize=True)
NON_FINITE = st.sampled_from([np.nan, np.inf, -np.inf])
X0 = np.array([0.0, 0.0, 10.0, 5.0])
P0 = np.diag([100.0, 100.0, 25.0, 25.0])
SENSOR = RangeBearing(noise_std=(5.0, 0.01), sensor_position=(-500.0, 300.0))
KEY = jax.random.key(0)
T = 6


def _ct(turn_rate, sample_period=1.0, noise_intensity=0.1):
    return TrackingModel(CoordinatedTurn(sample_period, turn_rate=turn_rate, noise_intensity=noise_intensity), SENSOR,
                         X0, P0)


Z = simulate(_ct(0.05), KEY, T).measurements


@jax.jit
def _simulate_ok(turn_rate):
    return simulate(_ct(turn_rate), KEY, T, throw=False).ok


@jax.jit
def _filter_ok(turn_rate):
    return run_filter(ExtendedKalmanFilter(), _ct(turn_rate), Z, throw=False).ok


@jax.jit
def _filter_prior_ok(mean):
    model = eqx.tree_at(lambda m: m.initial_mean, _ct(0.05), mean)
    return run_filter(ExtendedKalmanFilter(), model, Z, throw=False).ok


@jax.jit
def _range_ok(sample_period, noise_intensity, noise_std):
    """Trajectory.ok and FilterResult.ok of a model whose ranged parameters are traced."""
    sensor = RangeBearing(noise_std=noise_std, sensor_position=(-500.0, 300.0))
    model = TrackingModel(CoordinatedTurn(sample_period, turn_rate=0.05, noise_intensity=noise_intensity), sensor, X0,
                          P0)
    return simulate(model, KEY, T, throw=False).ok, run_filter(ExtendedKalmanFilter(), model, Z, throw=False).ok


GOOD_STD = np.array([5.0, 0.01])

_MEMBERS = [(ExtendedKalmanFilter(), _ct(0.0)),
            (ExtendedKalmanFilter(), TrackingModel(ConstantVelocity(1.0, noise_intensity=2.0), SENSOR, X0, P0))]


@jax.jit
def _imm_ok(p):
    return run_imm(InteractingMultipleModel(_MEMBERS, p), Z, throw=False).ok


def test_good_values_are_ok_traced():
    """The twins do not flag good inputs (else the tests below could not fail)."""
    assert bool(_simulate_ok(0.05)) and bool(_filter_ok(0.05)) and bool(_filter_prior_ok(jnp.asarray(X0)))
    assert bool(_imm_ok(jnp.array([[0.9, 0.1], [0.2, 0.8]])))
    assert all(map(bool, _range_ok(1.0, 0.1, GOOD_STD)))
    assert all(map(bool, _range_ok(0.5, 0.0, GOOD_STD)))  # a zero noise intensity is allowed


@SETTINGS
@given(tau=st.one_of(st.just(0.0), st.floats(-10.0, -1e-6)))
def test_sample_period_not_positive(tau):
    """A period <= 0 is rejected concrete; traced it becomes NaN, so both results say ok=False."""
    with pytest.raises(InputError, match="sample_period"):
        CoordinatedTurn(tau, turn_rate=0.05, noise_intensity=0.1)
    assert not any(map(bool, _range_ok(tau, 0.1, GOOD_STD)))


@SETTINGS
@given(q=st.floats(-5.0, -1e-6), which=st.sampled_from(["noise_intensity", "noise_std"]))
def test_negative_noise_level(q, which):
    std = GOOD_STD.copy()
    if which == "noise_std":
        std[0] = q
        with pytest.raises(InputError, match="noise_std"):
            RangeBearing(noise_std=std)
        assert not any(map(bool, _range_ok(1.0, 0.1, std)))
    else:
        with pytest.raises(InputError, match="noise_intensity"):
            CoordinatedTurn(1.0, turn_rate=0.05, noise_intensity=q)
        assert not any(map(bool, _range_ok(1.0, q, GOOD_STD)))


def test_the_twin_keeps_good_values_and_their_gradient():
    """Bit for bit and the same derivative as without the twin (it only acts where the value is bad)."""
    def period_sum(tau):
        return jnp.sum(CoordinatedTurn(tau, turn_rate=0.05, noise_intensity=0.1).noise_cov(0))

    tau = 0.7
    np.testing.assert_array_equal(jax.jit(period_sum)(tau), period_sum(tau))
    q1 = tau**3 / 3 + tau**2 / 2 + tau**2 / 2 + tau  # Q_1d summed, q = 0.1 on two axes
    dq1 = tau**2 + 2 * tau + 1
    np.testing.assert_allclose(jax.grad(period_sum)(tau), 2 * 0.1 * dq1, rtol=1e-14)
    np.testing.assert_allclose(period_sum(tau), 2 * 0.1 * q1, rtol=1e-14)


@SETTINGS
@given(bad=NON_FINITE)
def test_non_finite_turn_rate(bad):
    with pytest.raises(InputError, match="turn_rate"):
        CoordinatedTurn(1.0, turn_rate=bad, noise_intensity=0.1)
    assert not bool(_simulate_ok(bad))
    assert not bool(_filter_ok(bad))


def test_simulate_under_jit_raises_with_throw():
    """``Trajectory.ok`` is also an error by default (``throw=True``), as for ``run_filter``."""
    f = jax.jit(lambda w: simulate(_ct(w), KEY, T).states)
    assert np.all(np.isfinite(f(0.05)))
    with pytest.raises(Exception, match="non-finite state or measurement"):
        jax.block_until_ready(f(jnp.nan))


@SETTINGS
@given(bad=NON_FINITE, where=st.integers(0, 3))
def test_non_finite_prior_mean(bad, where):
    mean = X0.copy()
    mean[where] = bad
    with pytest.raises(InputError, match="initial_mean"):
        TrackingModel(CoordinatedTurn(1.0, turn_rate=0.05, noise_intensity=0.1), SENSOR, mean, P0)
    assert not bool(_filter_prior_ok(jnp.asarray(mean)))


@SETTINGS
@given(row=st.integers(0, 1), delta=st.floats(1e-4, 0.5).map(lambda d: d * np.random.default_rng(0).choice([-1, 1])))
def test_non_stochastic_transition_probs(row, delta):
    """Rows that do not sum to 1 (or a negative entry): rejected concrete, ok=False traced."""
    p = np.array([[0.9, 0.1], [0.2, 0.8]])
    p[row, 0] += delta
    with pytest.raises(InputError, match="transition_probs"):
        InteractingMultipleModel(_MEMBERS, p)
    assert not bool(_imm_ok(jnp.asarray(p)))


@jax.jit
def _dmc_anees(sample_period):
    model = TrackingModel(CoordinatedTurn(sample_period, turn_rate=0.05, noise_intensity=0.1), SENSOR, X0, P0)
    return differentiable_monte_carlo(model, KEY, 8, num_steps=T, filter=ExtendedKalmanFilter()).anees


def test_differentiable_monte_carlo_flags_a_traced_bad_period():
    """The Monte Carlo entry that may be traced: every run fails, is left out and reported (a warning
    naming the count) and the statistics are NaN, not a number computed backwards in time."""
    assert np.isfinite(float(_dmc_anees(1.0)))
    with pytest.warns(RuntimeWarning, match="8 of 8 runs produced a non-finite estimate"):
        value = float(jax.block_until_ready(_dmc_anees(-1.0)))
    assert np.isnan(value)

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
from jaxtrack.montecarlo import simulate

SETTINGS = settings(max_examples=8, deadline=None, derandomize=True)
NON_FINITE = st.sampled_from([np.nan, np.inf, -np.inf])
X0 = np.array([0.0, 0.0, 10.0, 5.0])
P0 = np.diag([100.0, 100.0, 25.0, 25.0])
SENSOR = RangeBearing(noise_std=(5.0, 0.01), sensor_position=(-500.0, 300.0))
KEY = jax.random.key(0)
T = 6


def _ct(turn_rate):
    return TrackingModel(CoordinatedTurn(turn_rate, 1.0, 0.1), SENSOR, X0, P0)


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


_MEMBERS = [(ExtendedKalmanFilter(), _ct(0.0)),
            (ExtendedKalmanFilter(), TrackingModel(ConstantVelocity(1.0, 2.0), SENSOR, X0, P0))]


@jax.jit
def _imm_ok(p):
    return run_imm(InteractingMultipleModel(_MEMBERS, p), Z, throw=False).ok


def test_good_values_are_ok_traced():
    """The twins do not flag good inputs (else the tests below could not fail)."""
    assert bool(_simulate_ok(0.05)) and bool(_filter_ok(0.05)) and bool(_filter_prior_ok(jnp.asarray(X0)))
    assert bool(_imm_ok(jnp.array([[0.9, 0.1], [0.2, 0.8]])))


@SETTINGS
@given(bad=NON_FINITE)
def test_non_finite_turn_rate(bad):
    with pytest.raises(InputError, match="turn_rate"):
        CoordinatedTurn(bad, 1.0, 0.1)
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
        TrackingModel(CoordinatedTurn(0.05, 1.0, 0.1), SENSOR, mean, P0)
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

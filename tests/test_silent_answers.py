"""Inputs that used to give a silent wrong answer: each is now an error, a False ``ok``, an
``overflow`` flag or a NaN, eagerly and under ``jax.jit``.

- association: a NaN or ``+inf`` in a valid row of ``L`` (every method: ``ok`` False);
  ``LoopyBP``'s ``num_iters``/``damping`` (construction error; a traced damping: ``ok`` False);
  JPDA beyond its cluster caps (``Association.overflow`` and a ``CapacityWarning``);
- ``pda_update`` with a row of ``β`` that is not a probability row (error; traced: NaN);
- GOSPA/OSPA with a NaN valid point (NaN distance) or a traced bad cutoff/order (run-time error);
- ``fit_detection_and_clutter`` on scans that are all padding (error; traced: ``ok`` False).

Small sizes; every jitted function is built once at module level (or in a module fixture).
"""

from __future__ import annotations

import dataclasses
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxtrack  # noqa: F401  (float64)
from jaxtrack._validation import InputError
from jaxtrack.association import GNN, JPDA, PDA, Association, LoopyBP, pda_update
from jaxtrack.filters import KalmanFilter
from jaxtrack.filters._updates import Conditioned
from jaxtrack.models import constant_velocity
from jaxtrack.montecarlo._ospa import gospa, ospa
from jaxtrack.multitarget import CapacityWarning, OnePointInitiator, Tracker, fit_detection_and_clutter

NINF = -np.inf
LOG_MISS = float(np.log(0.2))

# ---------------------------------------------------------------------------------------------
# Association: non-finite entries of L.

METHODS = {"GNN": GNN(), "PDA": PDA(), "JPDA": JPDA(), "LoopyBP": LoopyBP(num_iters=5)}
# LoopyBP with a traced damping: one program for this test and the damping test below.
_bp = jax.jit(lambda damping, L, valid: LoopyBP(num_iters=5, damping=damping)(L, valid))
_JITTED = {name: jax.jit(lambda L, valid, m=m: m(L, valid)) for name, m in METHODS.items()}
_JITTED["LoopyBP"] = lambda L, valid: _bp(jnp.asarray(0.0), L, valid)
# Eagerly (op by op; the loops inside are traced and compiled again at every eager call, the
# costly part of this file) only the answers that were wrong: JPDA's with a NaN (read as gated
# out) and GNN's with +inf (accepted); the rest runs the same code, checked under jit.
EAGER = {"GNN": np.inf, "JPDA": np.nan}


def _log_weights(bad=None):
    """``L`` ``(3, 1 + 3)``: two valid tracks sharing measurement 0, a padded row of NaN, and
    ``bad`` (if given) at track 1, measurement 1."""
    L = np.array([
        [LOG_MISS, 1.0, 0.5, NINF],
        [LOG_MISS, 0.3, NINF, -0.2],
        [np.nan, np.nan, np.inf, np.nan],  # padding: anything goes
    ])
    if bad is not None:
        L[1, 2] = bad
    return jnp.asarray(L), jnp.asarray([True, True, False])


@pytest.mark.parametrize("name", list(METHODS))
def test_nonfinite_valid_row_is_not_ok(name):
    """NaN or +inf in a valid row: ok False for every method, eager and jitted (JPDA's log-space
    sums used to read a NaN as −inf, "gated out", and answer ok=True); −inf and a padded row of
    garbage stay ok. No method has a capacity to overflow here."""
    def check_bad(got, bad):
        assert not bool(got.ok), (name, bad)
        assert not bool(got.overflow)
        assert not np.isfinite(float(got.log_normalizer))

    jitted = _JITTED[name]
    good = jitted(*_log_weights())
    assert bool(good.ok) and not bool(good.overflow)
    assert np.all(np.isfinite(np.asarray(good.association_probabilities)))
    for bad in (np.nan, np.inf):
        check_bad(jitted(*_log_weights(bad)), bad)
    if name in EAGER:
        check_bad(METHODS[name](*_log_weights(EAGER[name])), EAGER[name])


def test_association_overflow_field_is_last():
    names = [f.name for f in dataclasses.fields(Association)]
    assert names[-2:] == ["ok", "overflow"]


# ---------------------------------------------------------------------------------------------
# LoopyBP's options.


def test_loopybp_rejects_bad_options():
    """num_iters < 1 and damping outside [0, 1) (1 never updates: residual 0, "converged")."""
    for damping in (1.0, 1.5, -0.1, np.nan):
        with pytest.raises(InputError, match="`damping`"):
            LoopyBP(damping=damping)
    for num_iters in (0, -3, True):
        with pytest.raises(InputError, match="`num_iters`"):
            LoopyBP(num_iters=num_iters)
    LoopyBP(num_iters=1, damping=0.0)
    LoopyBP(damping=jnp.asarray(0.999))


def test_loopybp_traced_damping_out_of_range_is_not_ok():
    """A traced damping skips the constructor's check: out of [0, 1) it gives ok False (1 used
    to report residual 0, "converged", with the messages never updated)."""
    for damping, ok in ((0.5, True), (1.0, False), (-0.5, False), (np.nan, False)):
        assert bool(_bp(jnp.asarray(damping), *_log_weights()).ok) == ok, damping
    # Also with no measurement at all (no message to carry a NaN damping).
    L = jnp.full((3, 1), LOG_MISS)
    for damping, ok in ((0.5, True), (1.0, False)):
        assert bool(_bp(jnp.asarray(damping), L, jnp.ones(3, bool)).ok) == ok, damping


# ---------------------------------------------------------------------------------------------
# JPDA beyond its cluster caps. min(T, M) = 3 > max_exact = 2: the cluster path.

_OVERLAP = jnp.asarray(np.concatenate(
    [np.full((3, 1), LOG_MISS), np.random.default_rng(5).normal(size=(3, 3))], axis=1
))  # three tracks gating all three measurements: one cluster of 3
_CAPPED = JPDA(max_exact=2, max_cluster_tracks=2)
_capped_jit = jax.jit(lambda L, valid: _CAPPED(L, valid))


def test_jpda_overflow_flag_and_warning():
    """A cluster of 3 tracks over ``max_cluster_tracks=2``: overflow True (and ok False), jitted
    and eager, and the eager call warns naming the caps. With one track padded, the cluster of 2
    fits: overflow False, no warning, exact marginals (and a NaN in a valid row is reported on
    the cluster path too)."""
    three, two = jnp.ones(3, bool), jnp.asarray([True, True, False])
    for valid in (three, two):
        exact = np.asarray(_JITTED["JPDA"](_OVERLAP, valid).association_probabilities)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no warning under jit: the flag is the answer there
            jitted = _capped_jit(_OVERLAP, valid)
            if valid is two:
                eager = _CAPPED(_OVERLAP, valid)
        if valid is three:
            with pytest.warns(CapacityWarning, match="max_cluster_tracks=2.*LoopyBP"):
                eager = _CAPPED(_OVERLAP, valid)
        for got in (eager, jitted):
            error = np.abs(np.asarray(got.association_probabilities) - exact).max()
            if valid is three:
                assert bool(got.overflow) and not bool(got.ok)
                assert error > 0.05  # what the flag is for
            else:
                assert bool(got.ok) and not bool(got.overflow) and error < 1e-12
    assert not bool(_capped_jit(_OVERLAP.at[1, 2].set(np.nan), two).ok)


# ---------------------------------------------------------------------------------------------
# pda_update's β row.

_N, _M = 2, 2
_COND = Conditioned(
    mean=jnp.asarray([[1.0, 0.0], [0.0, 1.0]]),
    cov=jnp.broadcast_to(0.5 * jnp.eye(_N), (_M, _N, _N)),
    innovation=jnp.asarray([[1.0], [-1.0]]),
    innovation_cov=jnp.ones((_M, 1, 1)),
    log_likelihood=jnp.zeros(_M),
    gain=jnp.full((_M, _N, 1), 0.5),
)
_X, _P = jnp.zeros(_N), jnp.eye(_N)
_pda_jit = jax.jit(pda_update, static_argnames="form")
_BAD_ROWS = {
    "negative": [1.2, -0.2, 0.0],
    "sum-low": [0.5, 0.2, 0.0],
    "sum-high": [0.5, 0.4, 0.3],
    "nan": [np.nan, 0.5, 0.5],
}


@pytest.mark.parametrize("form", ["mixture"])
def test_pda_update_rejects_rows_that_are_not_probabilities(form):
    """Eager: InputError naming `association_row`; jitted: NaN mean and covariance (not a
    finite wrong moment). A row of zeros (padding) and a row off 1 by rounding are fine."""
    for name, row in _BAD_ROWS.items():
        with pytest.raises(InputError, match="`association_row`"):
            pda_update(_COND, jnp.asarray(row), _X, _P, form=form)
        mean, cov = _pda_jit(_COND, jnp.asarray(row), _X, _P, form=form)
        assert np.all(np.isnan(np.asarray(mean))) and np.all(np.isnan(np.asarray(cov))), name
    for row in ([0.0, 0.0, 0.0], [0.2, 0.3, 0.5 + 1e-13]):
        for call in (pda_update, _pda_jit):
            mean, cov = call(_COND, jnp.asarray(row), _X, _P, form=form)
            assert np.all(np.isfinite(np.asarray(mean))) and np.all(np.isfinite(np.asarray(cov)))


# ---------------------------------------------------------------------------------------------
# GOSPA / OSPA.


def _both(truth, tv, est, ev, cutoff, order):
    g = gospa(truth, tv, est, ev, cutoff=cutoff, order=order)
    return g.distance, g.localisation, ospa(truth, tv, est, ev, cutoff=cutoff, order=order).distance


_metrics_jit = jax.jit(_both)


def _sets(bad_truth=None, bad_estimate=None):
    truth = np.array([[0.0, 0.0], [3.0, 0.0], [np.nan, np.nan]])  # row 2 is padding
    est = np.array([[0.1, 0.0], [9.0, 9.0]])
    if bad_truth is not None:
        truth[1, 0] = bad_truth
    if bad_estimate is not None:
        est[1, 1] = bad_estimate
    return (jnp.asarray(truth), jnp.asarray([True, True, False]), jnp.asarray(est),
            jnp.asarray([True, True]))


def test_gospa_nan_valid_point_is_nan():
    """A NaN (or infinite) coordinate of a valid point: NaN distances (it used to pass as a
    missed/false point at a finite c^p/2); padding holding NaN stays finite."""
    cutoff, order = jnp.asarray(2.0), jnp.asarray(2.0)
    assert np.all(np.isfinite(_metrics_jit(*_sets(), cutoff, order)))
    for kw in (dict(bad_truth=np.nan), dict(bad_estimate=np.nan), dict(bad_truth=np.inf)):
        assert np.all(np.isnan(_metrics_jit(*_sets(**kw), cutoff, order))), kw
    # Eagerly (each call traces the assignment solver's loops again): one case (OSPA shares
    # GOSPA's assignment, checked under jit above).
    assert np.isnan(float(gospa(*_sets(bad_estimate=np.nan), cutoff=2.0).distance))


def test_gospa_bad_cutoff_or_order():
    """Eager: InputError naming the argument. Traced: a run-time error naming it (it used to be
    a NaN in every value, which said nothing of the cause)."""
    for fn in (gospa, ospa):
        with pytest.raises(InputError, match="`cutoff`"):
            fn(*_sets(), cutoff=-1.0)
        with pytest.raises(InputError, match="`order`"):
            fn(*_sets(), cutoff=1.0, order=0.5)
    for cutoff, order, name in ((0.0, 2.0, "`cutoff`"), (-1.0, 2.0, "`cutoff`"), (2.0, 0.5, "`order`")):
        with pytest.raises(Exception, match=name):
            jax.block_until_ready(_metrics_jit(*_sets(), jnp.asarray(cutoff), jnp.asarray(order)))


# ---------------------------------------------------------------------------------------------
# fit_detection_and_clutter on scans that are all padding.


@pytest.fixture(scope="module")
def small_tracker():
    model = constant_velocity(1.0, dim=1, accel_psd=0.1, measurement_std=1.0,
                              initial_mean=np.zeros(2), initial_cov=np.diag([100.0, 4.0]))
    return Tracker(KalmanFilter(), model, PDA(), OnePointInitiator(np.zeros(2), np.diag([100.0, 4.0])),
                   prob_detect=0.8, clutter_density=0.01, capacity=2, clutter_volume=100.0)


def test_fit_on_all_padding_is_not_ok(small_tracker):
    """No valid measurement anywhere: InputError naming `valid` (concrete), ok False (traced)."""
    z = jnp.zeros((3, 2, 1))
    none = jnp.zeros((3, 2), bool)
    with pytest.raises(InputError, match="`valid`"):
        fit_detection_and_clutter(small_tracker, z, none)

    @eqx.filter_jit
    def fit(valid):
        return fit_detection_and_clutter(small_tracker, z, valid, num_iterations=2).ok

    assert not bool(fit(none))
    assert bool(fit(none.at[0, 0].set(True)))

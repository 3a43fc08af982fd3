"""Degenerate input to the multi-target layer is answered by an error naming the argument, a
warning, or ``ok=False`` — never by a number that looks right (issue: "no silent answer").

Each case was a silent answer before: ``Tracker(clutter_density=inf)`` accepted; a NaN
measurement marked valid tracked as a number by trackers, GM-PHD and PMBM; a traced NaN or 1.5
``P_D`` giving NaN tracks with no flag on ``TrackerResult``; ``clutter_density = 0`` accepted by
the GM-PHD and PMBM (a measurement no component reaches is then 0/0); a JPDA cluster beyond its
caps flagged only deep inside the step's association, not counted by the tracker.
"""

from __future__ import annotations

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from _multitarget_cases import RUN_KEY, methods, scenario
from jaxtrack import InputError
from jaxtrack.association import JPDA
from jaxtrack.filters import KalmanFilter
from jaxtrack.multitarget import (
    GMPHD,
    PMBM,
    CapacityWarning,
    OnePointInitiator,
    Tracker,
    run_multitarget,
    run_tracker,
    simulate_scenario,
)


@pytest.fixture(scope="module")
def case():
    scen, settings = scenario()
    truth = simulate_scenario(scen, RUN_KEY)
    z = np.asarray(truth.scans.measurements)[:6]
    v = np.asarray(truth.scans.valid)[:6]
    return scen, settings, methods(scen, settings), z, v


def _with_nan(z, v):
    z = z.copy()
    k, j = 3, int(np.flatnonzero(v[3])[0])
    z[k, j, 0] = np.nan
    return z, k


@pytest.mark.parametrize("name", ["jpda", "phd", "pmbm"])
def test_a_nan_measurement_marked_valid_is_refused_eagerly_and_flagged_traced(case, name):
    _, _, methods, z, v = case
    bad, k = _with_nan(z, v)
    with pytest.raises(InputError, match="measurements"):
        run_multitarget(methods[name], bad, v)
    # Traced, the check cannot run on the host: the scan's `ok` says it (the scans before are ok;
    # a NaN that got into a mixture keeps the later scans not ok too).
    ok = np.asarray(jax.jit(lambda zz: run_multitarget(methods[name], zz, v, warn=False).ok)(bad))
    assert not ok[k] and np.all(ok[:k])
    assert np.all(np.asarray(jax.jit(lambda zz: run_multitarget(methods[name], zz, v, warn=False).ok)(z)))


def test_tracker_refuses_an_infinite_clutter_density(case):
    scen, s, _, _, _ = case
    init = OnePointInitiator(np.asarray(s.birth_means[0]), np.asarray(s.birth_covs[0]))
    for bad in (np.inf, np.nan, 0.0):
        with pytest.raises(InputError, match="clutter_density"):
            Tracker(KalmanFilter(), scen.model, JPDA(), init, prob_detect=0.9, clutter_density=bad, capacity=8)


@pytest.mark.parametrize("bad", [np.nan, 1.5, 0.0])
def test_a_traced_bad_detection_probability_is_not_ok(case, bad):
    _, _, methods, z, v = case
    tracker = methods["jpda"]

    def run(pd):
        return run_tracker(eqx.tree_at(lambda t: t.prob_detect, tracker, pd), z, v, warn=False).ok

    ok = jax.jit(run)(jnp.asarray(bad))
    assert not bool(np.any(ok))
    assert bool(np.all(jax.jit(run)(jnp.asarray(0.9))))  # the same compiled scan with a good P_D


def test_zero_clutter_density_is_refused_by_the_phd_and_pmbm(case):
    scen, s, _, _, _ = case
    common = dict(prob_survival=0.99, prob_detect=0.9, clutter_density=0.0, birth=s.birth)
    with pytest.raises(InputError, match="clutter_density"):
        GMPHD(KalmanFilter(), scen.model, capacity=8, **common)
    with pytest.raises(InputError, match="clutter_density"):
        PMBM(KalmanFilter(), scen.model, max_tracks=8, max_hypotheses=2, **common)


def test_a_jpda_cluster_beyond_its_caps_is_counted_and_warned(case):
    """Eight targets within a few metres of each other (one gating cluster of 8 tracks) and an exact
    JPDA capped at clusters of 2 tracks: the tracker counts each such scan, warns, and marks it not ok."""
    _, _, methods, z, v = case
    rng = np.random.default_rng(3)
    z = np.full((6, 24, 2), np.nan)
    z[:, :8] = np.array([100.0, 100.0]) + 2.0 * rng.standard_normal((6, 8, 2))
    v = np.zeros((6, 24), bool)
    v[:, :8] = True
    tracker = eqx.tree_at(lambda t: t.association, methods["jpda"],
                          JPDA(max_exact=2, max_cluster_tracks=2, max_cluster_measurements=4, max_large_clusters=1))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = run_tracker(tracker, z, v)
    failures = int(result.final.num_association_failures)
    assert failures > 0 and failures == int(np.sum(~np.asarray(result.ok)))
    assert int(tracker.capacity_events(result.final)) >= failures
    assert any(issubclass(w.category, CapacityWarning) and "association" in str(w.message) for w in caught)


@pytest.mark.parametrize("family", ["phd", "cphd"])
def test_estimates_beyond_max_estimates_are_counted_and_warned(case, family):
    """A GM-(C)PHD with one estimate slot on a scenario of several targets: the estimates that do
    not fit are counted as capacity events (they were dropped without a word before) and warned."""
    from jaxtrack.multitarget import GMCPHD, run_cphd, run_phd

    scen, s, _, z, v = case
    common = dict(prob_survival=s.prob_survival, prob_detect=s.prob_detect, birth=s.birth, initial=s.initial,
                  clutter_density=s.clutter_density, capacity=24, max_estimates=1)
    if family == "phd":
        method, run = GMPHD(KalmanFilter(), scen.model, **common), run_phd
    else:
        method, run = GMCPHD(KalmanFilter(), scen.model, clutter_rate=s.clutter_rate, max_cardinality=12,
                             **common), run_cphd
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = run_multitarget(method, z, v)
    detail = run(method, z, v, warn=False)
    found = np.asarray(detail.num_estimates if family == "phd" else detail.map_cardinality)
    expected = int(np.sum(np.maximum(found - 1, 0)))
    assert expected > 0  # the case has several targets
    mixture = result.final if family == "phd" else result.final.mixture
    assert int(mixture.num_unreported) == expected
    assert int(result.capacity_events[-1]) == expected + int(mixture.num_dropped)
    assert any(issubclass(w.category, CapacityWarning) and "max_estimates=1" in str(w.message) for w in caught)


def test_a_step_jitted_by_hand_compiles(case):
    """``jax.jit(lambda s, z, v: tracker.step(s, z, v))`` (the tracker closed over): its parameter
    checks used to inspect a staged comparison and raised TracerArrayConversionError."""
    _, _, methods, z, v = case
    tracker = methods["jpda"]
    step = jax.jit(lambda s, zz, vv: tracker.step(s, zz, vv))
    by_hand, info = step(tracker.init(), z[0], v[0])
    filtered, _ = eqx.filter_jit(tracker.step)(tracker.init(), z[0], v[0])
    assert bool(info.ok) and eqx.tree_equal(by_hand, filtered)


def test_one_clutter_vocabulary_across_the_constructors(case):
    """``clutter_density`` κ, Stone Soup's ``clutter_spatial_density`` κ, or ``clutter_rate`` λ with
    ``clutter_volume`` V build the same method; contradictions and doubles are refused by name."""
    from jaxtrack.multitarget import GMCPHD, PMB

    scen, s, methods, _, _ = case
    kappa, rate, volume = float(scen.clutter_density), float(scen.clutter_rate), float(scen.clutter_volume)
    assert kappa == rate / volume and float(scen.clutter_spatial_density) == kappa
    common = dict(prob_survival=0.99, prob_detect=0.9, birth=s.birth)
    init = OnePointInitiator(np.asarray(s.birth_means[0]), np.asarray(s.birth_covs[0]))
    builders = {
        "Tracker": lambda **c: Tracker(KalmanFilter(), scen.model, JPDA(), init, prob_detect=0.9, capacity=8, **c),
        "GMPHD": lambda **c: GMPHD(KalmanFilter(), scen.model, capacity=8, **common, **c),
        "PMB": lambda **c: PMB(KalmanFilter(), scen.model, max_tracks=8, **common, **c),
        "PMBM": lambda **c: PMBM(KalmanFilter(), scen.model, max_tracks=8, max_hypotheses=2, **common, **c),
    }
    for name, build in builders.items():
        forms = [build(clutter_density=kappa), build(clutter_spatial_density=kappa),
                 build(clutter_rate=rate, clutter_volume=volume)]
        assert all(float(f.clutter_density) == kappa for f in forms), name
        with pytest.raises(InputError, match="clutter_spatial_density"):
            build(clutter_density=kappa, clutter_spatial_density=kappa)
        with pytest.raises(InputError, match="clutter_rate"):
            build(clutter_density=2 * kappa, clutter_rate=rate, clutter_volume=volume)
        with pytest.raises(InputError, match="clutter_density"):
            build()
    cphd = [GMCPHD(KalmanFilter(), scen.model, capacity=8, max_cardinality=4, clutter_rate=rate, **common, **c)
            for c in (dict(clutter_density=kappa), dict(clutter_volume=volume))]
    assert np.isclose(float(cphd[0].clutter_pdf), float(cphd[1].clutter_pdf), rtol=1e-15)
    with pytest.raises(InputError, match="clutter_spatial_density"):  # meant 1/V up to 0.1.0
        GMCPHD(KalmanFilter(), scen.model, capacity=8, max_cardinality=4, clutter_rate=rate,
               clutter_spatial_density=kappa, **common)

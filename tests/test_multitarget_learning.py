"""The tracker's scan log-likelihood, its gradient, and the fit of P_D and the clutter density.

Scenario: four targets on parallel tracks 40 m apart (constant velocity, σ = 1 m, P_D = 0.8) and
Poisson clutter, 1 point per scan on average, uniform over a 200 m × 200 m box, simulated with
:func:`simulate_scenarios`. Tracker: Kalman filter, exact JPDA with integrated existence (JIPDA,
``P_S = 1``, new tracks at existence 0.5), 12 slots. One tracker and one data shape serve the fit
tests, so the fit compiles once.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack.association import JPDA, LoopyBP
from jaxtrack.filters import KalmanFilter
from jaxtrack.models import constant_velocity
from jaxtrack.multitarget import (
    IntegratedExistence,
    OnePointInitiator,
    Scenario,
    Tracker,
    TrackManagement,
    fit_detection_and_clutter,
    run_tracker,
    simulate_scenarios,
)

# Long programs: compiled at XLA's default level (tests/conftest.py; alone, cold:
# 77.7 against 50.6 CPU-s)
pytestmark = pytest.mark.xla_optimized

Q, SIGMA, P_D, RATE = 0.05, 1.0, 0.8, 1.0
REGION = np.array([[0.0, 200.0], [0.0, 200.0]])
VOLUME = 200.0 * 200.0
DENSITY = RATE / VOLUME
NUM_RUNS, NUM_STEPS, MAX_MEAS, CAPACITY = 3, 60, 8, 12
PRIOR_MEAN = np.array([100.0, 100.0, 0.0, 0.0])
PRIOR_COV = np.diag([1e4, 1e4, 4.0, 4.0])


def _model():
    return constant_velocity(1.0, dim=2, accel_psd=Q, measurement_std=SIGMA,
                             initial_mean=PRIOR_MEAN, initial_cov=PRIOR_COV)


def _tracker(association=None, existence=True):
    return Tracker(
        KalmanFilter(), _model(), JPDA(max_exact=MAX_MEAS) if association is None else association,
        OnePointInitiator(PRIOR_MEAN, PRIOR_COV), prob_detect=P_D, clutter_density=DENSITY,
        capacity=CAPACITY, clutter_volume=VOLUME, management=TrackManagement(2, 3, 5),
        existence=IntegratedExistence(1.0) if existence else None,
    )


@pytest.fixture(scope="module")
def scans():
    x0 = np.array([[20.0, y, 1.5, 0.0] for y in (40.0, 80.0, 120.0, 160.0)])
    scenario = Scenario(_model(), x0, [0] * 4, [NUM_STEPS] * 4, detection_probability=P_D,
                        clutter_rate=RATE, clutter_region=REGION, max_measurements=MAX_MEAS,
                        num_steps=NUM_STEPS)
    truth = simulate_scenarios(scenario, jax.random.key(3), NUM_RUNS)
    assert not np.any(truth.overflow)
    return np.asarray(truth.scans.measurements), np.asarray(truth.scans.valid)


def _with(tracker, theta):
    """The tracker at (P_D, λ, σ): σ enters R (and with it every update and the initiation)."""
    pd, lam, sigma = theta
    return eqx.tree_at(lambda t: (t.prob_detect, t.clutter_density, t.model.R), tracker,
                       (pd, lam, sigma**2 * jnp.eye(2)))


@eqx.filter_jit
def _value_and_grad(theta, tracker, z, valid, mode):
    """The run's total log-likelihood, its gradient (``jax.grad``, or ``jax.jacfwd`` for
    ``mode="forward"``), and the discrete decisions made."""

    def total(theta):
        result = run_tracker(_with(tracker, theta), z, valid, warn=False)
        beta = result.association_probabilities
        decisions = (result.status, result.track_id, beta > 0, beta[..., 1:] > beta[..., :1])
        value = jnp.sum(result.log_likelihood)
        return value, (value, decisions)

    if mode == "forward":
        grad, aux = jax.jacfwd(total, has_aux=True)(theta)
    else:
        grad, aux = jax.grad(total, has_aux=True)(theta)
    return aux, grad


# JIPDA in the default suite (it runs the JPDA marginals and the existence terms); plain JPDA and
# LoopyBP each compile another reverse-mode program (~17 s cold), so they run with --runslow.
@pytest.mark.parametrize("association", [pytest.param("jpda", marks=pytest.mark.slow), "jipda",
                                         pytest.param("loopy_bp", marks=pytest.mark.slow)])
def test_gradient_equals_central_differences(scans, association):
    """∂ℓ/∂(P_D, λ, σ) through the soft association = central differences, with the same
    decisions (statuses, ids, gates, hits) at ±h, away from the optimum so that no component is
    near 0. JPDA and JIPDA: ``jax.grad``. LoopyBP: ``jax.jacfwd`` (the fit's mode), because its
    reverse-mode gradient through the tracker is NaN (``jaxtrack/association/_jpda.py``, open)."""
    z, valid = scans[0][0, :40], scans[1][0, :40]
    assoc = LoopyBP(num_iters=20) if association == "loopy_bp" else JPDA(max_exact=MAX_MEAS)
    tracker = _tracker(assoc, existence=association != "jpda")
    mode = "forward" if association == "loopy_bp" else "reverse"
    theta = jnp.array([0.7, 1.5 * DENSITY, 1.2])
    (value, decisions), grad = _value_and_grad(theta, tracker, z, valid, mode)
    assert np.isfinite(float(value)) and np.all(np.isfinite(grad))
    fd = []
    for i in range(3):
        h = 1e-6 * float(theta[i])  # relative step: rounding ~1e-16·|ℓ|/h, truncation ~h²
        (up, dec_up), _ = _value_and_grad(theta.at[i].add(h), tracker, z, valid, mode)
        (down, dec_down), _ = _value_and_grad(theta.at[i].add(-h), tracker, z, valid, mode)
        for a, b, c in zip(jax.tree.leaves(decisions), jax.tree.leaves(dec_up), jax.tree.leaves(dec_down)):
            np.testing.assert_array_equal(b, a)
            np.testing.assert_array_equal(c, a)
        fd.append((float(up) - float(down)) / (2 * h))
    fd = np.array(fd)
    rel = np.abs(np.asarray(grad) - fd) / np.abs(fd)
    assert np.all(rel <= 1e-6), (np.asarray(grad), fd, rel)


def test_fit_recovers_detection_probability_and_clutter_density(scans):
    """From (0.6, 2λ): P̂_D and λ̂ within 3 standard errors of the truth (measured: P̂_D =
    0.7970 ± 0.0163, −0.18 SE; λ̂V = 1.044 ± 0.076 for λV = 1, +0.58 SE), in 4 Newton steps."""
    z, valid = scans
    fit = fit_detection_and_clutter(_tracker(), z, valid, init=(0.6, 2.0 * DENSITY))
    assert bool(fit.ok) and bool(fit.converged)
    assert int(fit.num_iterations) <= 8
    hist = np.asarray(fit.log_likelihood_history)
    assert np.all(np.diff(hist) >= 0)  # Armijo steps only ever raise ℓ
    pd, pd_se = float(fit.prob_detect), float(fit.prob_detect_se)
    lam, lam_se = float(fit.clutter_density), float(fit.clutter_density_se)
    assert 0.0 < pd_se < 0.05 and 0.0 < lam_se < 0.2 * DENSITY
    assert abs(pd - P_D) <= 3 * pd_se, (pd, pd_se)
    assert abs(lam - DENSITY) <= 3 * lam_se, (lam * VOLUME, lam_se * VOLUME)
    # The fitted tracker carries the estimates; the observed information is positive definite.
    assert float(fit.tracker.prob_detect) == pd and float(fit.tracker.clutter_density) == lam
    assert np.all(np.linalg.eigvalsh(np.asarray(fit.observed_information)) > 0)


def _separated_clutter(rng, min_distance=60.0):
    """Clutter-only scans in the fit's data shape: Poisson(2) points per scan, uniform over the
    region, each at least ``min_distance`` from every point of the two scans before (where the
    tracks they start are predicted), so that no track ever weighs a measurement: every
    Gaussian factor is below exp(−90), under the rounding of the association's sum."""
    z = np.full((NUM_RUNS, NUM_STEPS, MAX_MEAS, 2), np.nan)
    valid = np.zeros((NUM_RUNS, NUM_STEPS, MAX_MEAS), bool)
    for r in range(NUM_RUNS):
        for k in range(NUM_STEPS):
            recent = z[r, max(k - 2, 0):k][valid[r, max(k - 2, 0):k]]
            for j in range(min(rng.poisson(2.0), MAX_MEAS)):
                while True:
                    p = REGION[:, 0] + (REGION[:, 1] - REGION[:, 0]) * rng.uniform(size=2)
                    if len(recent) == 0 or np.min(np.linalg.norm(recent - p, axis=1)) >= min_distance:
                        break
                z[r, k, j], valid[r, k, j] = p, True
    return z, valid


def test_clutter_only_mle_is_mean_count_over_volume():
    """No targets: ∂ℓ/∂λ = Σ_k (M_k/λ − V), so λ̂ = mean count / V exactly and its standard error
    is √(Σ M_k) / (K V) (the Poisson count term alone; P_D held at 0.8). The tracks born from the
    clutter stay, but weigh no measurement, so log Z does not depend on λ."""
    z, valid = _separated_clutter(np.random.default_rng(11))
    tracker = _tracker()
    result = jax.vmap(lambda zr, vr: run_tracker(tracker, zr, vr, warn=False).association_probabilities)(z, valid)
    assert float(jnp.max(result[..., 1:])) < 1e-30  # no track weighs any measurement
    fit = fit_detection_and_clutter(tracker, z, valid, init=(P_D, 3.0 * DENSITY), estimate=("clutter_density",))
    total, scans_ = valid.sum(), NUM_RUNS * NUM_STEPS
    assert bool(fit.ok) and bool(fit.converged)
    # Exact up to the stopping rule: a Newton decrement ≤ 1e-14 nats leaves a relative error of at
    # most √(2e-14 / ΣM) ≈ 5e-9 in λ̂ (measured 7.5e-11).
    np.testing.assert_allclose(float(fit.clutter_density), total / (scans_ * VOLUME), rtol=1e-8)
    np.testing.assert_allclose(float(fit.clutter_density_se), np.sqrt(total) / (scans_ * VOLUME), rtol=1e-6)
    assert float(fit.prob_detect) == P_D and float(fit.prob_detect_se) == 0.0

"""Observer-trajectory design by gradient on the terminal position PCRLB (issue 21).

Stated acceptance (CI sizes: 32 fixed truths for the objective, 50 adam steps, an 8 × 12 grid, 300
Monte Carlo runs; ``reproduce``-size numbers in the notebook):

- the designed path lowers the terminal position bound (trace of the position block of the PCRLB,
  m²) by a factor ≥ 3 against the study's own maneuver (geometry R2: 3°/s turns, same speed);
- it is at or below the brute-force optimum of a grid of one-turn maneuvers (turn start × new heading
  at the full rate) times 1.01 — the grid is a restricted family inside the design's, so the
  design may beat it (it does, by far);
- its Monte Carlo terminal RMSE (EKF and PLKF, 300 paired runs on truths from the prior) is lower:
  the 95% paired interval of the RMSE ratio designed/study (``time_averaged_rmse_ratio`` over the
  last sample) lies below 1.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.applications.bearings_tma import bounds as tb
from jaxtrack.applications.bearings_tma import geometry
from jaxtrack.applications.bearings_tma.scenario import SAMPLE_PERIOD, SPEED, TURN_RATE
from jaxtrack.design import constrained_turn_rates, design_observer_path, observer_states


def test_observer_states_match_study_path_for_constant_rate_arcs():
    # R2's first turn: 90° → 0° at 3°/s from t = 240 s takes 30 s. Per 20-s interval: 60° then 30°.
    s = geometry("R2")
    w = np.zeros(48)
    w[12] = -TURN_RATE
    w[13] = -0.5 * TURN_RATE
    xo = observer_states(jnp.asarray(w), initial_heading=math.pi / 2, speed=SPEED, sample_period=SAMPLE_PERIOD)
    # Up to sample 12 identical; afterwards a slightly different turn (slower second part) → close.
    np.testing.assert_allclose(xo[:13], s.observer[:13], atol=1e-9)
    np.testing.assert_allclose(xo[14:25, 2:], s.observer[14:25, 2:], atol=1e-9)  # same heading after the turn
    assert np.max(np.abs(np.asarray(xo[14:25, :2] - s.observer[14:25, :2]))) < 60.0
    # Speed is constant and the limit holds for any control.
    c = jnp.linspace(-50, 50, 48)
    r = constrained_turn_rates(c, TURN_RATE)
    assert np.all(np.abs(np.asarray(r)) <= TURN_RATE)
    xo = observer_states(r, initial_heading=0.0, speed=SPEED, sample_period=SAMPLE_PERIOD)
    np.testing.assert_allclose(np.hypot(xo[:, 2], xo[:, 3]), SPEED, rtol=1e-12)
    # Exact arcs: chord length v·dt·sinc(ω dt / 2).
    chord = np.hypot(*np.diff(np.asarray(xo[:, :2]), axis=0).T)
    half = np.asarray(r) * SAMPLE_PERIOD / 2
    np.testing.assert_allclose(chord, SPEED * SAMPLE_PERIOD * np.sinc(half / np.pi), rtol=1e-12)


def test_gradient_through_the_bound_matches_central_differences():
    obj = tb.design_objective(jax.random.key(5), 32)
    psi0 = math.pi / 2

    @jax.jit
    def f(c):
        return obj(observer_states(constrained_turn_rates(c, TURN_RATE), initial_heading=psi0, speed=SPEED,
                                   sample_period=SAMPLE_PERIOD))

    c = jnp.asarray(np.random.default_rng(0).normal(size=48) * 0.5)
    g = jax.jit(jax.grad(f))(c)
    e = jnp.zeros(48).at[20].set(1.0)
    h = 1e-5
    fd = (f(c + h * e) - f(c - h * e)) / (2 * h)
    np.testing.assert_allclose(float(g[20]), float(fd), rtol=1e-5)


def test_design_inputs_are_validated():
    with pytest.raises(InputError, match="max_turn_rate"):
        design_observer_path(lambda x: jnp.sum(x**2), jnp.zeros(3), max_turn_rate=0.0, initial_heading=0.0,
                             speed=1.0, sample_period=1.0)
    with pytest.raises(InputError, match="initial_controls"):
        design_observer_path(lambda x: jnp.sum(x**2), jnp.asarray([jnp.nan]), max_turn_rate=1.0,
                             initial_heading=0.0, speed=1.0, sample_period=1.0)


@pytest.fixture(scope="module")
def study():
    return tb.design_study(jax.random.key(2), 32, num_steps=50, turn_starts=np.arange(0, 48, 6),
                           new_headings=np.radians(np.arange(0, 360, 30)))


def test_design_beats_study_maneuver_and_grid(study):
    d = study.design
    # The bound decreases over the iterations (best iterate returned) …
    hist = np.asarray(d.history)
    assert hist[-1] < 0.5 * hist[0]
    assert float(d.objective) <= hist.min() * (1 + 1e-12)
    # … by a factor ≥ 3 against the study's own maneuver (measured 3.6 with 64 truths, 150 steps),
    assert study.factor >= 3.0, study.factor
    # … and is within 1% of (here: below) the brute-force grid optimum.
    assert float(d.objective) <= 1.01 * float(study.grid_best), (float(d.objective), float(study.grid_best))
    # The designed path respects the limit and the speed.
    assert np.all(np.abs(np.asarray(d.turn_rates)) <= TURN_RATE)
    np.testing.assert_allclose(np.hypot(d.observer[:, 2], d.observer[:, 3]), SPEED, rtol=1e-12)


def test_design_lowers_monte_carlo_rmse(study):
    v = tb.validate_design(study.design.observer, jax.random.key(3), 300)
    for ratio, lo, hi in (v.ekf, v.plkf):
        assert hi < 1.0, (ratio, lo, hi)


@pytest.mark.slow
def test_design_full_size():
    """Reproduction size: 64 truths, 150 steps, the 24 × 24 grid, 2000 paired Monte Carlo runs."""
    st = tb.design_study(jax.random.key(2), 64, num_steps=150)
    assert st.factor >= 3.5  # measured 3.69
    assert float(st.design.objective) <= 1.01 * float(st.grid_best)  # measured 657 vs 1213 m²
    # The factor holds on 512 fresh truths (not an artefact of the 64 fixed ones): measured 3.64.
    fresh = tb.design_objective(jax.random.key(77), 512)
    assert float(fresh(st.study_observer)) / float(fresh(st.design.observer)) >= 3.3
    v = tb.validate_design(st.design.observer, jax.random.key(3), 2000)
    for ratio, lo, hi in (v.ekf, v.plkf):
        assert hi < 0.8, (ratio, lo, hi)

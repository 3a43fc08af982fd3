"""jaxtrack.learning.fit beyond the statsmodels comparison: many runs with masks, other
parametrisations, filters and optimisers, input errors. The models and data come from
tests/test_learning_mle.py (the same cached build functions, so the loop compiles once per model).
"""

import jax.numpy as jnp
import numpy as np
import optax
import pytest

import jaxtrack
from jaxtrack.filters import ExtendedKalmanFilter, KalmanFilter, run_filter
from jaxtrack.learning import Bounded, PositiveScalar, SPDMatrix, fit
from jaxtrack.models import LinearGaussianModel

from _learning_cases import T, _builder_for, _case, _simulate


def test_many_runs_with_masks_sum_of_run_likelihoods():
    F, H, Qs, R1, a0, P0, theta = _case("constant_velocity")
    ys = np.stack([_simulate(F, H, Qs, R1, a0, P0, theta, seed=s) for s in (1, 2, 3)])
    mask = np.ones(ys.shape[:2], bool)
    mask[0, 50:80] = False
    mask[2, ::7] = False
    ys[0, 60] = np.nan  # missing entries may hold anything
    build = _builder_for("constant_velocity")
    params = {"theta": PositiveScalar.from_value(np.ones(2))}
    f = fit(build, params, ys, mask=mask)
    assert bool(f.ok) and bool(f.converged)
    assert f.log_likelihood_history.shape == (201,)
    assert np.all(np.diff(np.asarray(f.log_likelihood_history)) >= -1e-9)
    # The objective is the sum of the runs' log-likelihoods with their masks.
    total = sum(
        float(run_filter(KalmanFilter(), f.model, np.nan_to_num(ys[r]), mask=mask[r]).log_likelihood) for r in range(3)
    )
    np.testing.assert_allclose(float(f.log_likelihood), total, rtol=1e-12)
    # A maximum: zero gradient, and the SEs are finite and positive.
    se = np.asarray(f.standard_errors()["theta"])
    assert np.all(np.isfinite(se)) and np.all(se > 0)
    assert float(f.gradient_norm_history[-1]) < 1e-5


def test_other_parametrisations_and_filters():
    # R through a Bounded link and Q as a 1×1 SPDMatrix: same optimum as the log link.
    F, H, Qs, R1, a0, P0, theta = _case("local_level")
    y = _simulate(F, H, Qs, R1, a0, P0, theta, seed=7)
    ref = fit(_builder_for("local_level"), {"theta": PositiveScalar.from_value(np.ones(2))}, y)

    def build(p):
        return LinearGaussianModel(jnp.eye(1), p["Q"](), jnp.eye(1), p["r"]() * jnp.eye(1), jnp.zeros(1), 10.0 * jnp.eye(1))

    # Through the EKF (equal to the KF on a linear model): any jaxtrack filter plugs in.
    f = fit(build, {"Q": SPDMatrix.from_value(jnp.eye(1)), "r": Bounded.from_value(1.0, lo=0.0, hi=10.0)}, y,
            filter=ExtendedKalmanFilter())
    np.testing.assert_allclose(f.natural_params["Q"][0, 0], ref.natural_params["theta"][0], rtol=1e-6)
    np.testing.assert_allclose(f.natural_params["r"], ref.natural_params["theta"][1], rtol=1e-6)
    # Parametrisation-invariant SEs on the natural scale (at the same optimum).
    np.testing.assert_allclose(f.standard_errors()["Q"][0, 0], ref.standard_errors()["theta"][0], rtol=1e-4)
    with pytest.raises(jaxtrack.InputError, match="entrywise"):
        f.confidence_intervals(method="transformed")


def test_input_errors():
    F, H, Qs, R1, a0, P0, theta = _case("local_level")
    build = _builder_for("local_level")
    y = np.zeros((T, 1))
    p = {"theta": PositiveScalar.from_value(np.ones(2))}
    with pytest.raises(jaxtrack.InputError, match="`num_iterations`"):
        fit(build, p, y, num_iterations=0)
    with pytest.raises(jaxtrack.InputError, match="`measurements`"):
        fit(build, p, np.zeros((T, 2)))
    with pytest.raises(jaxtrack.InputError, match="`mask`"):
        fit(build, p, y, mask=np.ones(T))
    with pytest.raises(jaxtrack.InputError, match="`build`"):
        fit(lambda q: 1.0, p, y)
    with pytest.raises(jaxtrack.InputError, match="`params`"):
        fit(build, {"theta": jnp.array([1, 2])}, y)


def test_nonfinite_step_stops_and_keeps_last_finite_iterate():
    F, H, Qs, R1, a0, P0, theta = _case("local_level")
    y = _simulate(F, H, Qs, R1, a0, P0, theta, seed=7)

    def build(p):
        th = p["theta"]()
        # A model that fails (NaN noise) beyond r = 3: the fit must stop before handing it back.
        r = jnp.where(th[1] > 3.0, jnp.nan, th[1])
        return LinearGaussianModel(jnp.eye(1), th[0] * jnp.eye(1), jnp.eye(1), r * jnp.eye(1), jnp.zeros(1), 10.0 * jnp.eye(1))

    # A first-order optax optimiser through the same loop: gradient *ascent* of the negative
    # log-likelihood from r = 2.5 (above the optimum r ≈ 1.05)
    # walks r upwards into the failing region.
    f = fit(build, {"theta": PositiveScalar.from_value(np.array([0.5, 2.5]))}, y,
            optimizer=optax.sgd(-0.2), num_iterations=50)
    assert not bool(f.ok) and not bool(f.converged)
    assert 0 < int(f.num_iterations) < 50
    assert np.all(np.isfinite(np.asarray(f.log_likelihood_history)))
    assert float(f.natural_params["theta"][1]) <= 3.0
    np.testing.assert_allclose(
        float(f.log_likelihood), float(run_filter(KalmanFilter(), f.model, y).log_likelihood), rtol=1e-12
    )

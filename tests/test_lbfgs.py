"""jaxtrack.learning.LBFGS, the default optimiser of fit: one objective evaluation per iteration.

- The minimum of the Rosenbrock function and of an ill-conditioned quadratic agree with SciPy's
  L-BFGS-B (the oracle; gradient from the same JAX function) to 1e-8.
- A non-finite region next to the path shrinks the step and the minimum is still found.
- The property the class exists for: tracing `fit` evaluates the user's model once inside the
  loop (``build`` is called three times in all: the argument check, the loop, the fitted model),
  where optax's L-BFGS calls it six times (four copies of the objective in the compiled loop).
"""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from scipy import optimize

import jaxtrack
from jaxtrack.learning import LBFGS, PositiveScalar, fit
from jaxtrack.models import LinearGaussianModel

from _learning_cases import _case, _simulate


def _minimise(f, x0, num_iterations=200, gtol=1e-10):
    vg = jax.value_and_grad(f)

    def evaluate(x):
        v, g = vg(x)
        return v, v, g, jnp.isfinite(v) & jnp.all(jnp.isfinite(g))

    def converged(v1, v0, g):
        return jnp.sqrt(jnp.dot(g, g)) <= gtol

    run = jax.jit(lambda x: LBFGS().minimise(evaluate, x, num_iterations, converged, x.dtype))
    return run(jnp.asarray(x0, jnp.float64))


def rosenbrock(x):
    return jnp.sum(100.0 * (x[1:] - x[:-1] ** 2) ** 2 + (1.0 - x[:-1]) ** 2)


A = jnp.diag(jnp.logspace(0, 4, 6))


def quadratic(x):
    return 0.5 * x @ A @ x - jnp.sum(x)


@pytest.mark.parametrize("f, x0", [(rosenbrock, [-1.2, 1.0, -0.5, 0.8]), (quadratic, np.ones(6))],
                         ids=["rosenbrock", "quadratic"])
def test_minimum_agrees_with_scipy(f, x0):
    x, hist, ghist, it, converged, ok = _minimise(f, x0)
    assert bool(ok) and bool(converged) and 0 < int(it) < 200
    # The history is the objective at the accepted iterates: it never increases.
    h = np.asarray(hist)[: int(it) + 1]
    assert np.all(np.diff(h) <= 1e-12 * np.abs(h[:-1]))
    ref = optimize.minimize(lambda v: float(f(jnp.asarray(v))), np.asarray(x0, float),
                            jac=lambda v: np.asarray(jax.grad(f)(jnp.asarray(v))), method="L-BFGS-B",
                            options={"gtol": 1e-12, "ftol": 1e-15, "maxiter": 1000})
    np.testing.assert_allclose(np.asarray(x), ref.x, rtol=1e-8, atol=1e-8)


def test_nonfinite_trial_points_shrink_the_step():
    # NaN beyond x₀ = 1.5 along the first steepest-descent ray (the minimum is at 1): the
    # expansion of the first line search reaches the NaN region and must come back.
    def f(x):
        v = jnp.sum((x - 1.0) ** 2) * 1e-3
        return jnp.where(x[0] > 1.5, jnp.nan, v)

    x, hist, _, it, converged, ok = _minimise(f, [-30.0, 1.0])
    assert bool(ok) and bool(converged)
    np.testing.assert_allclose(np.asarray(x), [1.0, 1.0], atol=1e-6)
    assert np.all(np.isfinite(np.asarray(hist)))


def test_a_nonfinite_start_is_not_ok():
    x, hist, _, it, converged, ok = _minimise(lambda x: jnp.sum(x) * jnp.nan, [1.0, 2.0])
    assert not bool(ok) and not bool(converged) and int(it) == 0
    np.testing.assert_array_equal(np.asarray(x), [1.0, 2.0])


def test_fit_traces_the_model_once_inside_the_loop():
    F, H, Qs, R1, a0, P0, theta = _case("local_level")
    y = _simulate(F, H, Qs, R1, a0, P0, theta, seed=7)
    calls = {"n": 0}

    def make_build():
        def build(p):  # a new function object per fit: no compilation is reused
            calls["n"] += 1
            th = p["theta"]()
            return LinearGaussianModel(jnp.eye(1), th[0] * jnp.eye(1), jnp.eye(1), th[1] * jnp.eye(1),
                                       jnp.zeros(1), 10.0 * jnp.eye(1))
        return build

    p0 = {"theta": PositiveScalar.from_value(np.ones(2))}
    f = fit(make_build(), p0, y)
    assert calls["n"] == 3 and bool(f.converged)
    calls["n"] = 0
    g = fit(make_build(), p0, y, optimizer=optax.lbfgs())
    assert calls["n"] == 6
    # Both optimisers find the same maximum.
    np.testing.assert_allclose(np.asarray(f.natural_params["theta"]), np.asarray(g.natural_params["theta"]), rtol=1e-6)


def test_settings_are_checked():
    with pytest.raises(jaxtrack.InputError, match="`c1` and `c2`"):
        LBFGS(c1=0.5, c2=0.1)
    with pytest.raises(jaxtrack.InputError, match="`memory_size`"):
        LBFGS(memory_size=0)
    with pytest.raises(jaxtrack.InputError, match="`max_linesearch_steps`"):
        LBFGS(max_linesearch_steps=0)

"""jaxtrack.estimation.equality_constrained_lsq against NumPy's lstsq on the KKT system and
SciPy's constrained minimiser."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize

from jaxtrack import InputError
from jaxtrack.estimation import equality_constrained_lsq


def random_problem(rng, k=6, c=3, full=False):
    jac = rng.normal(size=(c, k))
    b = rng.normal(size=c)
    if full:
        g = rng.normal(size=(k, k))
        d = g @ g.T + 0.5 * np.eye(k)
    else:
        d = rng.uniform(0.2, 5.0, size=k)
    return d, jac, b


@pytest.mark.parametrize("full", [False, True])
def test_matches_lstsq_on_the_kkt_system(full):
    rng = np.random.default_rng(0)
    for k, c in ((6, 3), (4, 1), (5, 5)):
        d, jac, b = random_problem(rng, k, c, full)
        dm = np.diag(d) if d.ndim == 1 else d
        kkt = np.block([[dm, -jac.T], [jac, np.zeros((c, c))]])
        ref = np.linalg.lstsq(kkt, np.concatenate([np.zeros(k), b]), rcond=None)[0]
        sol = equality_constrained_lsq(d, jac, b)
        np.testing.assert_allclose(np.asarray(sol.solution), ref[:k], rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(np.asarray(sol.multipliers), ref[k:], rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(jac @ np.asarray(sol.solution), b, atol=1e-12)
        # Closed form: e* = D⁻¹J'(J D⁻¹ J')⁻¹ b, F* = ½ a'b.
        dinv_jt = np.linalg.solve(dm, jac.T)
        np.testing.assert_allclose(np.asarray(sol.solution), dinv_jt @ np.linalg.solve(jac @ dinv_jt, b), rtol=1e-9)
        np.testing.assert_allclose(float(sol.cost), 0.5 * float(np.asarray(sol.multipliers) @ b), rtol=1e-10)


def test_matches_scipy_minimize():
    rng = np.random.default_rng(1)
    d, jac, b = random_problem(rng)
    res = scipy.optimize.minimize(lambda e: 0.5 * np.sum(d * e * e), np.zeros(6), jac=lambda e: d * e,
                                  constraints=[{"type": "eq", "fun": lambda e: jac @ e - b, "jac": lambda e: jac}],
                                  method="SLSQP", options={"ftol": 1e-14, "maxiter": 500})
    sol = equality_constrained_lsq(d, jac, b)
    np.testing.assert_allclose(np.asarray(sol.solution), res.x, rtol=1e-6, atol=1e-8)


def test_multipliers_are_the_cost_gradient():
    rng = np.random.default_rng(2)
    d, jac, b = random_problem(rng)
    grad = jax.grad(lambda r: equality_constrained_lsq(d, jac, r).cost)(jnp.asarray(b))
    np.testing.assert_allclose(np.asarray(grad), np.asarray(equality_constrained_lsq(d, jac, b).multipliers), rtol=1e-10)


def test_docstring_example_and_dtype():
    sol = equality_constrained_lsq(jnp.array([1.0, 4.0]), jnp.array([[1.0, 1.0]]), jnp.array([5.0]))
    np.testing.assert_allclose(np.asarray(sol.solution), [4.0, 1.0], rtol=1e-14)
    sol32 = equality_constrained_lsq(np.array([1.0, 4.0], np.float32), np.array([[1.0, 1.0]], np.float32),
                                     np.array([5.0], np.float32))
    assert sol32.solution.dtype == jnp.float32


def test_input_errors():
    with pytest.raises(InputError, match="weights"):
        equality_constrained_lsq(np.array([1.0, -1.0]), np.ones((1, 2)), np.ones(1))
    with pytest.raises(InputError, match="rhs"):
        equality_constrained_lsq(np.ones(2), np.ones((1, 2)), np.ones(2))
    with pytest.raises(InputError, match="jacobian"):
        equality_constrained_lsq(np.ones(2), np.ones((3, 2)), np.ones(3))
    with pytest.raises(InputError, match="weights"):
        equality_constrained_lsq(np.ones(3), np.ones((1, 2)), np.ones(1))

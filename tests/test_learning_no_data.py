"""Fitting without data (issue 37, cause 4): a mask that observes nothing is refused by name
(concrete), or gives ``ok=False`` (a mask traced inside ``jit``/``vmap``), in every fit.

It used to return the starting model with ``ok=True``: with no observed entry every iterate has
the same zero log-likelihood, so the loop "converges" at once.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.learning import PositiveScalar, fit, fit_em
from jaxtrack.models import LinearGaussianModel

F, H = jnp.array([[1.0, 1.0], [0.0, 1.0]]), jnp.array([[1.0, 0.0]])
MODEL = LinearGaussianModel(F, 0.1 * jnp.eye(2), H, jnp.eye(1), jnp.zeros(2), 10.0 * jnp.eye(2))
Z = jnp.asarray(np.random.default_rng(0).normal(size=(2, 30, 1)))
NONE = jnp.zeros((2, 30), bool)


def build(p):
    return LinearGaussianModel(F, p["q"]() * jnp.eye(2), H, jnp.eye(1), jnp.zeros(2), 10.0 * jnp.eye(2))


START = {"q": PositiveScalar.from_value(0.5)}


def test_concrete_mask_with_nothing_observed_is_refused():
    with pytest.raises(InputError, match="`mask` marks no measurement as observed"):
        fit_em(MODEL, Z, mask=NONE, num_iterations=5)
    with pytest.raises(InputError, match="`mask` marks no measurement as observed"):
        fit(build, START, Z, mask=NONE)
    # One observed entry is data: accepted.
    assert bool(fit_em(MODEL, Z, mask=NONE.at[0, 3].set(True), num_iterations=2).ok)


def test_fit_imm_refuses_it_and_the_log_likelihood_of_no_data_is_zero():
    from jaxtrack.filters import InteractingMultipleModel, KalmanFilter
    from jaxtrack.learning import fit_imm, imm_log_likelihood

    def build_imm(p):
        return InteractingMultipleModel([(KalmanFilter(), build(p)), (KalmanFilter(), MODEL)],
                                        jnp.array([[0.9, 0.1], [0.1, 0.9]]))

    with pytest.raises(InputError, match="`mask` marks no measurement as observed"):
        fit_imm(build_imm, START, Z, mask=NONE, num_iterations=2)
    assert float(imm_log_likelihood(build_imm, START, Z, mask=NONE)) == 0.0


def test_traced_mask_with_nothing_observed_is_not_ok():
    """The traced twin: one data set of a vmapped fit observes nothing → that fit's ok is False."""
    masks = jnp.stack([jnp.ones((2, 30), bool), NONE])
    ok = jax.vmap(lambda m: fit(build, START, Z, mask=m, num_iterations=20).ok)(masks)
    assert np.asarray(ok).tolist() == [True, False]

"""Public Monte Carlo entry points: integer seeds where a key is expected, and a clear error when a
host-loop entry point is traced (issue 37: JAX's internal PRNG TypeError, and a bare
ConcretizationTypeError about ``is_fully_addressable`` with no word of differentiable_monte_carlo)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.bounds import pcrlb
from jaxtrack.models import constant_velocity
from jaxtrack.montecarlo import (differentiable_monte_carlo, monte_carlo, monte_carlo_map, monte_carlo_sweep,
                                 simulate)

P0 = jnp.diag(jnp.array([100.0, 100.0, 10.0, 10.0]) ** 2)


def cv(q=0.5):
    return constant_velocity(1.0, dim=2, accel_psd=q, measurement_std=10.0, initial_cov=P0)


def _sum_of_measurements(key, model):
    return jnp.sum(simulate(model, key, 5).measurements)


CALLS = {  # entry point -> call(key); each result compared leaf by leaf
    "simulate": lambda key: simulate(cv(), key, 5).measurements,
    "monte_carlo": lambda key: monte_carlo(cv(), key, 20, num_steps=5, progress=False).mse,
    "monte_carlo_sweep": lambda key: monte_carlo_sweep(lambda q: cv(q), [0.5], key, 20, num_steps=5,
                                                       progress=False)[0].mse,
    "monte_carlo_map": lambda key: monte_carlo_map(_sum_of_measurements, key, 20, args=cv(), progress=False),
    "differentiable_monte_carlo": lambda key: differentiable_monte_carlo(cv(), key, 20, num_steps=5).mse,
    "pcrlb": lambda key: pcrlb(cv(), key, 3, 5).bound,
}


@pytest.mark.parametrize("entry", CALLS)
def test_an_int_seed_is_the_key_of_that_seed(entry):
    call = CALLS[entry]
    np.testing.assert_array_equal(np.asarray(call(7)), np.asarray(call(jax.random.key(7))))
    np.testing.assert_array_equal(np.asarray(call(np.int64(7))), np.asarray(call(jax.random.key(7))))
    for bad in (7.0, True, jnp.zeros(3)):
        with pytest.raises(InputError, match="`key` must be a PRNG key"):
            call(bad)


def test_legacy_uint32_keys_still_work():
    np.testing.assert_array_equal(np.asarray(CALLS["simulate"](jax.random.PRNGKey(3))),
                                  np.asarray(simulate(cv(), jax.random.PRNGKey(3), 5).measurements))


@pytest.mark.parametrize("transform", ["grad", "jit", "vmap"])
def test_traced_monte_carlo_names_differentiable_monte_carlo(transform):
    def objective(q):
        return monte_carlo(cv(), jax.random.key(0), 20, num_steps=5, filter_model=cv(q), progress=False).mse.sum()

    fn = {"grad": jax.grad(objective), "jit": jax.jit(objective), "vmap": jax.vmap(objective)}[transform]
    arg = jnp.asarray([0.5, 1.0]) if transform == "vmap" else jnp.asarray(0.5)
    with pytest.raises(InputError, match="differentiable_monte_carlo"):
        fn(arg)


def test_traced_sweep_and_map_name_it_too():
    with pytest.raises(InputError, match="monte_carlo_map .*differentiable_monte_carlo"):
        jax.grad(lambda q: monte_carlo_map(_sum_of_measurements, jax.random.key(0), 4, args=cv(q),
                                           progress=False))(0.5)
    with pytest.raises(InputError, match="monte_carlo_sweep .*differentiable_monte_carlo"):
        jax.jit(lambda k: monte_carlo_sweep(lambda q: cv(q), [0.5], k, 4, num_steps=5,
                                            progress=False)[0].mse.sum())(jax.random.key(0))

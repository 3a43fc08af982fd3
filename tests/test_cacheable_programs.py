"""The entry points' jitted programs hold no host callback, so JAX's persistent compilation cache
keeps them, and ``throw=True`` still raises, eagerly and under ``jit``.

JAX refuses to write a program with a host callback (an ``equinox.error_if``) to its persistent
cache: the CLI's next run, every notebook kernel and every test process after
``jax.clear_caches()`` compiled it again (a profiled suite: 147 s of XLA compile in such programs,
``_run_filter_jit`` alone 54 s). ``throw`` is now applied outside the jitted function
(:func:`jaxtrack._validation.throw_unless_ok`): read on the host when the result is concrete, an
``error_if`` in the caller's own trace when it is not.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack.filters import (
    InteractingMultipleModel,
    KalmanFilter,
    imm_smoother,
    rts_smoother,
    run_filter,
    run_filter_batch,
    run_imm,
)
from jaxtrack.models import LinearGaussianModel, constant_velocity
from jaxtrack.montecarlo import simulate

T = 5
MODEL = LinearGaussianModel(np.array([[1.0, 1.0], [0.0, 1.0]]), 0.1 * np.eye(2), np.array([[1.0, 0.0]]),
                            np.array([[0.5]]), np.zeros(2), np.eye(2))
Z = np.linspace(0.0, 1.0, T)[:, None]
# Finite measurements whose squares overflow: the log-likelihood is -inf, the result not ok.
Z_OVERFLOW = np.full((T, 1), 1e200)


def _callbacks(fn, *args):
    """The host callbacks in the program JAX compiles for ``fn(*args)`` (``fn`` jitted)."""
    text = str(jax.make_jaxpr(fn)(*args))
    return text.count("callback")


def _imm():
    cv = constant_velocity(1.0, dim=1, accel_psd=0.1, measurement_std=1.0, initial_cov=np.eye(2))
    return InteractingMultipleModel([(KalmanFilter(), cv), (KalmanFilter(), cv)], np.array([[0.9, 0.1], [0.1, 0.9]]))


def test_run_filter_and_smoother_programs_have_no_host_callback():
    from jaxtrack.filters._run import _run_filter_jit
    from jaxtrack.filters._smoother import _rts_backward

    z = jnp.asarray(Z)
    obs = jnp.ones((T, 1), bool)
    assert _callbacks(lambda zz: _run_filter_jit(KalmanFilter(), MODEL, zz, obs, "update", "all", False), z) == 0
    filtered = run_filter(KalmanFilter(), MODEL, Z)
    assert _callbacks(lambda f: _rts_backward(MODEL, f), filtered) == 0


def test_simulate_program_has_no_host_callback():
    from jaxtrack.montecarlo._simulate import _simulate_jit

    assert _callbacks(lambda k: _simulate_jit(MODEL, k, T, "update", None), jax.random.key(0)) == 0
    # A traced prior keeps its run-time checks, in the caller's program.
    assert _callbacks(lambda m: simulate(eqx.tree_at(lambda x: x.initial_mean, MODEL, m), 0, T).states,
                      jnp.zeros(2)) >= 2


def test_batch_and_imm_programs_have_no_host_callback():
    from jaxtrack.filters._batch import _run_per_run, _run_shared
    from jaxtrack.filters._imm import _run_imm_jit

    z = jnp.broadcast_to(jnp.asarray(Z), (3, T, 1))
    obs = jnp.ones((T, 1), bool)
    assert _callbacks(lambda zz: _run_shared(KalmanFilter(), MODEL, zz, obs, "update", "all"), z) == 0
    assert _callbacks(lambda zz: _run_per_run(KalmanFilter(), MODEL, zz, obs, "update", "all"), z) == 0
    assert _callbacks(lambda zz: _run_imm_jit(_imm(), zz, obs, "update"), jnp.asarray(Z)) == 0


@pytest.mark.parametrize("call", ["run_filter", "rts_smoother", "run_filter_batch", "run_imm", "imm_smoother"])
def test_throw_still_raises_eagerly_and_under_jit(call):
    fns = {
        "run_filter": lambda z: run_filter(KalmanFilter(), MODEL, z),
        "rts_smoother": lambda z: rts_smoother(MODEL, z),
        "run_filter_batch": lambda z: run_filter_batch(KalmanFilter(), MODEL, jnp.stack([z, z])),
        "run_imm": lambda z: run_imm(_imm(), z),
        "imm_smoother": lambda z: imm_smoother(_imm(), z),
    }
    fn = fns[call]
    assert bool(jnp.all(fn(Z).ok))  # a finite run passes
    with pytest.raises(eqx.EquinoxRuntimeError, match="non-finite"):
        fn(Z_OVERFLOW)
    if call in ("run_filter", "rts_smoother"):  # the same helper serves all five: two suffice
        # Under the caller's jit the check is an error_if in the caller's program.
        with pytest.raises(Exception, match="non-finite"):
            jax.block_until_ready(jax.jit(fn)(jnp.asarray(Z_OVERFLOW)))


def test_simulate_throw_raises_eagerly():
    big = eqx.tree_at(lambda m: m.F, MODEL, np.array([[1e200, 1.0], [0.0, 1e200]]))
    traj = simulate(big, 0, T, throw=False)
    assert not bool(traj.ok)
    with pytest.raises(eqx.EquinoxRuntimeError, match="non-finite state or measurement"):
        simulate(big, 0, T)

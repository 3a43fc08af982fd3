"""Simulation of truth and measurements from a state-space model and a PRNG key."""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from .._validation import InputError, check_covariance, check_finite, covariance_ok, is_concrete
from ..filters._base import FirstStep
from ..filters._linalg import matmul
from ._noise import key_words, step_normals
from ..models import AbstractStateSpaceModel, at_step


class Trajectory(NamedTuple):
    """One simulated run: ``states`` ``(T, n)`` and ``measurements`` ``(T, m)``."""

    states: Float[Array, "T n"]
    measurements: Float[Array, "T m"]


def psd_sqrt(cov: Array) -> Array:
    """A factor ``L`` with ``L Lᵀ = cov`` for a positive *semi*definite ``cov``.

    Plant noise is often singular (noise on the velocity only), where a Cholesky factor is NaN;
    the symmetric eigendecomposition handles it. Tiny negative eigenvalues from rounding clip to 0.

    **Arguments:**

    - ``cov``: a symmetric positive semidefinite matrix, ``(..., n, n)`` (leading axes batch).

    **Returns:** ``L``, shape ``(..., n, n)``, in the square root of ``cov``'s units.
    """
    eigvals, eigvecs = jnp.linalg.eigh(cov)
    return eigvecs * jnp.sqrt(jnp.clip(eigvals, 0.0))[..., None, :]


class NoiseFactors(NamedTuple):
    """Square-root noise factors, constant ``(n, n)`` or per step ``(T, n, n)``, and the prior's."""

    process: Array
    measurement: Array
    prior: Array


def noise_factors(model: AbstractStateSpaceModel, num_steps: int) -> NoiseFactors:
    """Factor Q, R and the prior covariance once, outside the per-run scan.

    **Arguments:**

    - ``model``: the state-space model.
    - ``num_steps``: ``T``, used when the model's covariances vary per step.

    **Returns:** :class:`NoiseFactors`: ``L_Q`` ``(n, n)`` or ``(T, n, n)``, ``L_R`` ``(m, m)`` or
    ``(T, m, m)``, and the prior's factor ``(n, n)``, in the square root of the covariances' units.
    """
    if model.num_steps is None:
        Lq = psd_sqrt(model.process_noise_cov(0))
        Lr = psd_sqrt(model.measurement_noise_cov(0))
    else:
        ks = jnp.arange(num_steps)
        Lq = jax.vmap(lambda k: psd_sqrt(model.process_noise_cov(k)))(ks)
        Lr = jax.vmap(lambda k: psd_sqrt(model.measurement_noise_cov(k)))(ks)
    return NoiseFactors(Lq, Lr, psd_sqrt(model.initial_cov))


def step_keys(key: PRNGKeyArray) -> tuple[PRNGKeyArray, PRNGKeyArray]:
    """Split a run's key into the prior-draw key and the base key of the per-step draws.

    **Arguments:**

    - ``key``: the run's PRNG key.

    **Returns:** ``(prior_key, steps_key)``, two PRNG keys.
    """
    prior_key, steps_key = jax.random.split(key)
    return prior_key, steps_key


def draw_initial_state(model, factors: NoiseFactors, prior_key) -> Array:
    """Draw ``x_0 = m_0 + L_0 ε`` from the model's prior ``N(m_0, P_0)``.

    **Arguments:**

    - ``model``: the state-space model; ``factors``: its :class:`NoiseFactors`.
    - ``prior_key``: the run's prior-draw key (:func:`step_keys`).

    **Returns:** ``x_0``, shape ``(n,)``, in the model's state units.
    """
    n = model.state_dim
    eps = jax.random.normal(prior_key, (n,), model.initial_mean.dtype)
    return model.initial_mean + matmul(factors.prior, eps)


def simulate_step(model, factors: NoiseFactors, first_step: FirstStep, x_prev, steps_key, k):
    """Draw ``x_k`` from ``x_{k-1}`` and then ``z_k``.

    Step ``k``'s ``n + m`` standard normal numbers come from the run's ``steps_key`` and the
    step index alone (see :func:`step_noise`): the plant noise uses the first ``n``, the
    measurement noise the last ``m``.

    **Arguments:**

    - ``model``: the state-space model; ``factors``: its :class:`NoiseFactors`.
    - ``first_step``: ``"update"`` (no transition into step 0) or ``"predict"``.
    - ``x_prev``: ``x_{k-1}``, ``(n,)`` (at ``k = 0`` under ``"update"``: the drawn ``x_0``).
    - ``steps_key``: the run's per-step key (:func:`step_keys`); ``k``: the step index.

    **Returns:** ``(x_k, z_k)``, shapes ``(n,)`` and ``(m,)``, in the model's units.
    """
    eps = step_noise(steps_key, k, model.state_dim + model.meas_dim, model.initial_mean.dtype)
    return advance(model, factors, first_step, x_prev, eps, k)


def step_noise(steps_key: PRNGKeyArray, k, num: int, dtype) -> Array:
    """Step ``k``'s ``num`` standard normal numbers for a run with per-step key ``steps_key``.

    One Threefry-2x32 evaluation per number, counter ``(k, j)`` (see :mod:`._noise`): the same
    numbers whether a run is simulated alone or in a batch of any size.

    **Arguments:**

    - ``steps_key``: the run's per-step PRNG key; ``k``: the step index.
    - ``num``: how many numbers; ``dtype``: their floating dtype.

    **Returns:** ``(num,)`` standard normal numbers.
    """
    return step_normals(key_words(steps_key), k, num, dtype)


def advance(model, factors: NoiseFactors, first_step: FirstStep, x_prev, eps, k):
    """``x_k = f_k(x_{k-1}) + L_Q ε_w``, ``z_k = h_k(x_k) + L_R ε_v`` given ``eps = (ε_w, ε_v)``.

    ``x_prev`` ``(n, *B)`` and ``eps`` ``(n + m, *B)`` may carry a trailing batch axis (the
    model's functions are then mapped over it). The noise products use ``matmul``, which sums in
    the same order with or without the batch axis, so a run replayed alone by :func:`simulate`
    reproduces the Monte Carlo harness's run exactly.

    **Arguments:**

    - ``model``: the state-space model; ``factors``: its :class:`NoiseFactors`.
    - ``first_step``: ``"update"`` (``x_0`` is ``x_prev`` at ``k = 0``) or ``"predict"``.
    - ``x_prev``: ``x_{k-1}``, ``(n,)`` or ``(n, B)``; ``eps``: ``(n + m,)`` or ``(n + m, B)`` standard
      normals.
    - ``k``: the step index.

    **Returns:** ``(x_k, z_k)``, shapes ``(n,)`` and ``(m,)`` (``(n, B)`` and ``(m, B)`` batched), in the
    model's units.
    """
    n = model.state_dim
    transition, measurement = model.transition, model.measurement
    if x_prev.ndim == 2:
        transition = jax.vmap(transition, in_axes=(1, None), out_axes=1)
        measurement = jax.vmap(measurement, in_axes=(1, None), out_axes=1)
    x = transition(x_prev, k) + matmul(at_step(factors.process, k, 2), eps[:n])
    if first_step == "update":
        # The prior is on x_0 itself: no transition into step 0.
        x = jnp.where(k == 0, x_prev, x)
    return x, measurement(x, k) + matmul(at_step(factors.measurement, k, 2), eps[n:])


@eqx.filter_jit
def _simulate_jit(model, key, num_steps, first_step):
    factors = noise_factors(model, num_steps)
    prior_key, steps_key = step_keys(key)
    x0 = draw_initial_state(model, factors, prior_key)

    num = model.state_dim + model.meas_dim
    dtype = model.initial_mean.dtype

    def step(carry, k):
        # Step k's draws were made in step k−1 (see montecarlo._run._simulated_block): the
        # carried value is computed once instead of inside every consumer. Same numbers as
        # simulate_step.
        x_prev, eps = carry
        x, z = advance(model, factors, first_step, x_prev, eps, k)
        return (x, step_noise(steps_key, k + 1, num, dtype)), (x, z)

    init = (x0, step_noise(steps_key, 0, num, dtype))
    _, (xs, zs) = jax.lax.scan(step, init, jnp.arange(num_steps))
    return _guard_traced_model(model, Trajectory(xs, zs))


def _check_model_values(model: AbstractStateSpaceModel) -> None:
    """Eager checks of the values :func:`simulate` draws from (prior, noise covariances).

    The constructors check these, but a model edited with ``eqx.tree_at`` (or a custom
    subclass) bypasses them, and a NaN prior would otherwise give NaN states without a word.
    Only concrete values are checked here; traced ones by :func:`_guard_traced_model`.
    """
    check_finite("initial_mean", model.initial_mean)
    check_covariance("initial_cov", model.initial_cov, definite=False)
    for name in ("Q", "R"):
        value = getattr(model, name, None)
        if value is not None:
            label = "process_noise_cov" if name == "Q" else "measurement_noise_cov"
            check_finite(label, value)


def _guard_traced_model(model: AbstractStateSpaceModel, out):
    """Attach ``equinox.error_if`` checks of a traced prior (and noise covariances) to ``out``.

    Under ``jit``/``vmap``/``grad`` the eager checks cannot see the values; a NaN or indefinite
    prior would give NaN (or meaningless) states silently. One ``(n, n)`` eigvalsh, outside the
    scan.
    """
    if is_concrete(model.initial_mean) and is_concrete(model.initial_cov):
        checks = []
    else:
        checks = [
            ("initial_mean", jnp.all(jnp.isfinite(model.initial_mean)), "finite"),
            ("initial_cov", covariance_ok(model.initial_cov, definite=False),
             "a finite, symmetric, positive semidefinite covariance"),
        ]
    for name in ("Q", "R"):
        value = getattr(model, name, None)
        if value is not None and not is_concrete(value):
            label = "process_noise_cov" if name == "Q" else "measurement_noise_cov"
            checks.append((label, jnp.all(jnp.isfinite(value)), "finite"))
    for label, ok, what in checks:
        out = eqx.error_if(out, ~ok, f"jaxtrack.simulate: the model's `{label}` must be {what}.")
    return out


def simulate(
    model: AbstractStateSpaceModel,
    key: PRNGKeyArray,
    num_steps: int | None = None,
    *,
    first_step: FirstStep = "update",
) -> Trajectory:
    """Simulate one run of truth and measurements.

    The initial state is drawn from the model's prior ``N(initial_mean, initial_cov)``; with
    ``first_step="update"`` that draw *is* ``x_0``, with ``"predict"`` it is ``x_{-1}`` and
    ``x_0 = f_0(x_{-1}) + w_0`` (the same conventions as :func:`jaxtrack.filters.run_filter`).

    The run's key is split once into a prior key and a per-step key; step ``k``'s noise is a
    function of the per-step key and ``k`` only (one Threefry-2x32 hash per number, with
    ``jax.random.normal``'s transform; see :func:`step_noise`), so a trajectory does not depend on
    how many steps are simulated after it, and the Monte Carlo harness reproduces it exactly for
    the same run key. Keys must use JAX's default Threefry implementation.

    **Arguments:** ``model``; ``key``, a PRNG key; ``num_steps`` ``T`` (defaults to the model's
    per-step length); ``first_step`` as in ``run_filter``.

    **Returns:** a :class:`Trajectory` with ``states`` ``(T, n)`` and ``measurements`` ``(T, m)``.
    Use ``jax.vmap`` over keys for a batch.

    **Raises:** ``InputError`` for a bad ``num_steps`` or ``first_step``, a model function
    returning the wrong shape, or (concrete values) a non-finite prior mean, a prior covariance
    that is not positive semidefinite, or non-finite noise covariances; under tracing the value
    checks become ``equinox`` runtime errors naming the same arguments.
    """
    if not isinstance(model, AbstractStateSpaceModel):
        raise InputError(f"`model` must be a jaxtrack state-space model; got {type(model).__name__}.")
    num_steps = _resolve_num_steps(model, num_steps)
    if first_step not in ("update", "predict"):
        raise InputError(f"`first_step` must be 'update' or 'predict'; got {first_step!r}.")
    model.check_functions()
    _check_model_values(model)
    return _simulate_jit(model, key, num_steps, first_step)


def _resolve_num_steps(model, num_steps) -> int:
    model_steps = model.num_steps
    if num_steps is None:
        if model_steps is None:
            raise InputError("`num_steps` is required for a time-invariant model.")
        return model_steps
    if not isinstance(num_steps, int) or num_steps < 1:
        raise InputError(f"`num_steps` must be a positive int; got {num_steps!r}.")
    if model_steps is not None and model_steps != num_steps:
        raise InputError(
            f"`num_steps` is {num_steps} but the model's per-step arrays have {model_steps} steps."
        )
    return num_steps

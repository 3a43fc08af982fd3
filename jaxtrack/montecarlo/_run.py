"""The Monte Carlo harness: vmap over run keys, fixed-size chunks, streaming statistics.

Follow one run from the top: :func:`monte_carlo` validates its inputs and loops over chunks with
a progress bar; each chunk is one call of the jitted :func:`_chunk_sums`, which ``vmap``s
:func:`_run_once` over the chunk's run indices and adds the per-step sums to the running totals.
:func:`_run_once` is one ``lax.scan`` whose step draws the truth and the measurement
(:func:`~jaxtrack.montecarlo.simulate_step`), runs the filter's single step function
(:func:`~jaxtrack.filters.filter_step`) and emits the squared error, NEES and NIS of that step.
Nothing per run is kept, so memory does not grow with the number of runs.
"""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray
from tqdm.auto import tqdm

from .._validation import InputError, check_shape
from ..filters import AbstractFilter, KalmanFilter, filter_step
from ..filters._base import FirstStep, _Carry
from ..models import AbstractStateSpaceModel
from ._metrics import chi2_mean_bounds, normalized_squared_error
from ._simulate import (
    _resolve_num_steps,
    draw_initial_state,
    noise_factors,
    simulate_step,
    step_keys,
)


class _Sums(NamedTuple):
    """Per-step sums over the runs seen so far (all float64 under the default precision)."""

    error: Array  # (T, n): Σ (x − x̂)
    squared_error: Array  # (T, n): Σ (x − x̂)²
    nees: Array  # (T,): Σ NEES
    nees_sq: Array  # (T,): Σ NEES², for the empirical spread
    nis: Array  # (T,): Σ NIS
    num_ok: Array  # (): runs that stayed finite
    num_failed: Array  # (): runs that produced a non-finite value (excluded from the sums)


class MonteCarloResult(eqx.Module):
    """Statistics of a Monte Carlo run of ``num_runs`` runs over ``T`` steps.

    **Fields:**

    - ``mse`` ``(T, n)``: mean squared error of each state component at each step.
    - ``mean_error`` ``(T, n)``: mean of ``x − x̂`` (the bias; 0 for a linear filter).
    - ``nees`` ``(T,)``: NEES averaged over runs; ``nees_bounds`` ``(T, 2)`` its two-sided bounds.
    - ``nees_std`` ``(T,)``: the empirical standard deviation of NEES over runs.
    - ``nis`` ``(T,)``: NIS averaged over runs; ``nis_dof`` ``(T,)`` its degrees of freedom (the
      measurement components observed); ``nis_bounds`` ``(T, 2)``.
    - ``anees`` ``()``: NEES averaged over runs and steps and divided by ``n`` (1 when
      consistent). ``anees_bounds`` ``(2,)``: the per-step χ²(M·n)/(M·n) bounds. Averaging over
      steps cannot increase the variance of the per-step average (steps are positively
      correlated at worst completely), so these bounds are valid and conservative for ``anees``.
    - ``num_runs``: runs that contributed; ``num_failed``: runs excluded because the filter
      produced a non-finite value (a warning is issued when this is not 0).
    - ``confidence``: the probability content of the bounds (default 0.95).
    """

    mse: Float[Array, "T n"]
    mean_error: Float[Array, "T n"]
    nees: Float[Array, " T"]
    nees_std: Float[Array, " T"]
    nees_bounds: Float[Array, "T 2"]
    nis: Float[Array, " T"]
    nis_dof: Float[Array, " T"]
    nis_bounds: Float[Array, "T 2"]
    anees: Float[Array, ""]
    anees_bounds: Float[Array, " 2"]
    num_runs: int = eqx.field(static=True)
    num_failed: int = eqx.field(static=True)
    confidence: float = eqx.field(static=True)

    def rmse(self, components: tuple[int, ...] | None = None) -> Float[Array, " T"]:
        """Root of the summed mean squared error over ``components`` (all states if None).

        For a 2-D constant-velocity state ``[x, y, vx, vy]``, ``rmse((0, 1))`` is the position RMSE.
        """
        mse = self.mse if components is None else self.mse[:, jnp.asarray(components)]
        return jnp.sqrt(jnp.sum(mse, axis=-1))

    def fraction_nees_inside(self) -> Float[Array, ""]:
        """Fraction of steps whose run-averaged NEES lies within its bounds (≈ confidence)."""
        inside = (self.nees >= self.nees_bounds[:, 0]) & (self.nees <= self.nees_bounds[:, 1])
        return jnp.mean(inside)


def _run_once(filter, filter_model, truth, factors, observed, first_step, key):
    """One fused run: simulate, filter and score each step in one scan. Returns per-step terms."""
    prior_key, steps_key = step_keys(key)
    x0 = draw_initial_state(truth, factors, prior_key)
    dtype = filter_model.initial_cov.dtype
    carry0 = (
        _Carry(
            filter_model.initial_mean,
            filter_model.initial_cov,
            jnp.zeros((), dtype),
            jnp.ones((), bool),
        ),
        x0,
    )

    def step(carry, inputs):
        filt, x_prev = carry
        k, obs = inputs
        x, z = simulate_step(truth, factors, first_step, x_prev, steps_key, k)
        z = jnp.where(obs, z, 0.0)
        filt, (_, _, post) = filter_step(filter, filter_model, first_step, filt, k, z, obs)
        error = x - post.mean
        nees = normalized_squared_error(error, post.cov)
        nis = normalized_squared_error(post.innovation, post.innovation_cov)
        return (filt, x), (error, nees, nis)

    (filt, _), per_step = jax.lax.scan(step, carry0, (jnp.arange(observed.shape[0]), observed))
    ok = filt.ok & jnp.all(jnp.isfinite(per_step[1])) & jnp.all(jnp.isfinite(per_step[2]))
    return per_step, ok


@eqx.filter_jit
def _chunk_sums(sums, start, key, filter, filter_model, truth, observed, first_step, chunk_size, num_runs):
    factors = noise_factors(truth, observed.shape[0])
    run_index = start + jnp.arange(chunk_size)
    valid = run_index < num_runs
    keys = jax.vmap(lambda i: jax.random.fold_in(key, i))(run_index)
    (err, nees, nis), ok = jax.vmap(
        lambda k: _run_once(filter, filter_model, truth, factors, observed, first_step, k)
    )(keys)
    use = valid & ok
    w = use.astype(err.dtype)

    def wsum(a):
        # Zero, not multiply: a failed run may hold NaN, and NaN·0 is NaN.
        a = jnp.where(use.reshape((-1,) + (1,) * (a.ndim - 1)), a, 0.0)
        return jnp.sum(a, axis=0)

    return _Sums(
        sums.error + wsum(err),
        sums.squared_error + wsum(err**2),
        sums.nees + wsum(nees),
        sums.nees_sq + wsum(nees**2),
        sums.nis + wsum(nis),
        sums.num_ok + jnp.sum(w),
        sums.num_failed + jnp.sum((valid & ~ok).astype(w.dtype)),
    )


def monte_carlo(
    truth: AbstractStateSpaceModel,
    key: PRNGKeyArray,
    num_runs: int,
    *,
    num_steps: int | None = None,
    filter: AbstractFilter | None = None,
    filter_model: AbstractStateSpaceModel | None = None,
    mask: ArrayLike | None = None,
    first_step: FirstStep = "update",
    chunk_size: int = 1000,
    confidence: float = 0.95,
    progress: bool = True,
) -> MonteCarloResult:
    """Monte Carlo evaluation of a filter: ``num_runs`` simulated runs, streaming statistics.

    Each run draws its truth and measurements from ``truth`` and filters them with ``filter``
    built on ``filter_model`` (defaults: the Kalman filter on the true model, i.e. a matched
    filter). Runs are ``jax.vmap``-ed in chunks of ``chunk_size`` (the last chunk is padded, so
    there is one compilation), and only per-step sums are kept, so memory is
    ``O(chunk_size · T · n)`` whatever ``num_runs`` is.

    Run ``i`` uses the key ``jax.random.fold_in(key, i)`` and the same per-step draws as
    :func:`simulate`, so results do not depend on ``chunk_size`` (to float rounding of the sums),
    and run ``i`` can be replayed alone with ``simulate(truth, jax.random.fold_in(key, i), T)``.

    **Arguments:**

    - ``truth``: the model that generates the data.
    - ``key``: a PRNG key; ``num_runs``: the number of runs ``M``.
    - ``num_steps``: ``T`` (defaults to the models' per-step length).
    - ``filter``, ``filter_model``: the estimator and the model it assumes (may differ from
      ``truth``, e.g. a wrong Q); both must have the truth's state and measurement sizes.
    - ``mask``: shared measurement mask, ``(T,)`` or ``(T, m)``, True = observed.
    - ``first_step``: where the prior sits, as in :func:`~jaxtrack.filters.run_filter`; the
      truth's prior is the distribution of the initial state, the filter model's prior is what
      the filter assumes.
    - ``chunk_size``: runs per compiled batch; ``confidence``: content of the χ² bounds;
      ``progress``: show a progress bar.

    **Returns:** a :class:`MonteCarloResult`.
    """
    filter = KalmanFilter() if filter is None else filter
    filter_model = truth if filter_model is None else filter_model
    if not isinstance(filter, AbstractFilter):
        raise InputError(f"`filter` must be a jaxtrack filter; got {type(filter).__name__}.")
    for name, model in (("truth", truth), ("filter_model", filter_model)):
        if not isinstance(model, AbstractStateSpaceModel):
            raise InputError(f"`{name}` must be a jaxtrack state-space model; got {type(model).__name__}.")
    filter.check_model(filter_model)
    if (filter_model.state_dim, filter_model.meas_dim) != (truth.state_dim, truth.meas_dim):
        raise InputError(
            f"`filter_model` has (state, measurement) sizes {(filter_model.state_dim, filter_model.meas_dim)} "
            f"but `truth` has {(truth.state_dim, truth.meas_dim)}."
        )
    if not isinstance(num_runs, int) or num_runs < 1:
        raise InputError(f"`num_runs` must be a positive int; got {num_runs!r}.")
    if not isinstance(chunk_size, int) or chunk_size < 1:
        raise InputError(f"`chunk_size` must be a positive int; got {chunk_size!r}.")
    if first_step not in ("update", "predict"):
        raise InputError(f"`first_step` must be 'update' or 'predict'; got {first_step!r}.")
    num_steps = _resolve_num_steps(truth, num_steps if num_steps is not None else filter_model.num_steps)
    _resolve_num_steps(filter_model, num_steps)
    m = truth.meas_dim
    if mask is None:
        observed = jnp.ones((num_steps, m), bool)
    else:
        mask = jnp.asarray(mask)
        check_shape("mask", mask, [(num_steps,), (num_steps, m)])
        if mask.dtype != bool:
            raise InputError(f"`mask` must be boolean (True = observed); got dtype {mask.dtype}.")
        observed = jnp.broadcast_to(mask[:, None] if mask.ndim == 1 else mask, (num_steps, m))

    chunk_size = min(chunk_size, num_runs)
    n = truth.state_dim
    dtype = filter_model.initial_cov.dtype
    sums = _Sums(
        jnp.zeros((num_steps, n), dtype),
        jnp.zeros((num_steps, n), dtype),
        jnp.zeros((num_steps,), dtype),
        jnp.zeros((num_steps,), dtype),
        jnp.zeros((num_steps,), dtype),
        jnp.zeros((), dtype),
        jnp.zeros((), dtype),
    )
    num_chunks = math.ceil(num_runs / chunk_size)
    with tqdm(total=num_runs, desc="Monte Carlo", unit="run", disable=not progress) as bar:
        for c in range(num_chunks):
            start = c * chunk_size
            sums = _chunk_sums(
                sums, jnp.asarray(start), key, filter, filter_model, truth, observed,
                first_step, chunk_size, num_runs,
            )
            # Wait for the chunk, so the bar reports finished runs rather than dispatched ones.
            sums = jax.block_until_ready(sums)
            bar.update(min(chunk_size, num_runs - start))
    return _summarize(sums, observed, n, confidence)


def _summarize(sums: _Sums, observed, n, confidence) -> MonteCarloResult:
    num_ok = int(sums.num_ok)
    num_failed = int(sums.num_failed)
    if num_failed:
        warnings.warn(
            f"jaxtrack.monte_carlo: {num_failed} of {num_ok + num_failed} runs produced a "
            f"non-finite estimate and were left out of the statistics.",
            RuntimeWarning,
            stacklevel=3,
        )
    if num_ok == 0:
        raise FloatingPointError("jaxtrack.monte_carlo: every run produced a non-finite estimate.")
    mean_nees = sums.nees / num_ok
    nees_var = jnp.maximum(sums.nees_sq / num_ok - mean_nees**2, 0.0)
    nis_dof = jnp.sum(observed, axis=-1).astype(sums.nis.dtype)
    nees_b = chi2_mean_bounds(np.full(mean_nees.shape, n), num_ok, confidence)
    return MonteCarloResult(
        mse=sums.squared_error / num_ok,
        mean_error=sums.error / num_ok,
        nees=mean_nees,
        nees_std=jnp.sqrt(nees_var * num_ok / max(num_ok - 1, 1)),
        nees_bounds=jnp.asarray(nees_b),
        nis=sums.nis / num_ok,
        nis_dof=nis_dof,
        nis_bounds=jnp.asarray(chi2_mean_bounds(np.asarray(nis_dof), num_ok, confidence)),
        anees=jnp.mean(mean_nees) / n,
        anees_bounds=jnp.asarray(nees_b[0] / n),
        num_runs=num_ok,
        num_failed=num_failed,
        confidence=confidence,
    )

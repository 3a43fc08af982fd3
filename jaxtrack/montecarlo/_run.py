"""The Monte Carlo harness: blocks of runs, fused simulate-filter-score scans, streaming sums.

Follow one run from the top: :func:`monte_carlo` validates its inputs and dispatches blocks of
runs (a fixed, compiled size that does not depend on ``chunk_size``) to the one Monte Carlo
engine (:func:`~jaxtrack.montecarlo._engine.run_blocks`: run ``i`` from ``fold_in(key, i)``,
blocks accumulated in order, mesh sharding, progress bar); each block is one call of
:func:`_block_delta`, whose ``lax.scan`` over steps draws the
truth and the measurement (the draws of :func:`~jaxtrack.montecarlo.simulate`), updates the
filter and adds the step's error, NEES and NIS, summed over the block's runs, to the running
totals. Nothing per run is kept, so memory does not grow with the number of runs or steps.

Two paths, chosen automatically (``covariance="auto"``):

- **shared covariance**: a :class:`~jaxtrack.filters.KalmanFilter` on a
  :class:`~jaxtrack.models.LinearGaussianModel` filter model. Its covariances and gains do not
  depend on the data, so they (and the factors NEES and NIS need) are computed once per call by
  the filter's own step function on zero data; each block then propagates only the truth and
  the estimates, as ``(n, block)`` matrices.
- **per-run covariance**: any other filter (EKF, UKF) or filter model, or runs with their own
  measurement schedules (a detection probability, per-run masks). Each step ``vmap``s the
  fused per-run step: :func:`~jaxtrack.montecarlo.simulate_step` and
  :meth:`~jaxtrack.filters.AbstractFilter.step`.

Per-run schedules (:func:`_block_observed`): run ``i``'s missed detections are drawn from its own
key (:func:`~jaxtrack.montecarlo._simulate.draw_detections` on ``fold_in(key, i)``) and its rows
of a per-run mask are sliced by run index, so a block's schedule, like its draws, depends only on
the key and the run indices.
"""

from __future__ import annotations

import warnings
from typing import Any, Callable, NamedTuple, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from .._validation import InputError, check_shape
from ..filters import AbstractFilter, KalmanFilter, mean_step
from ..filters._base import FirstStep
from ..filters._batch import (
    CovarianceMode,
    SharedCovariance,
    mean_maps,
    resolve_covariance,
    shared_covariances,
)
from ..filters._linalg import all_rows, cholesky_and_inverse, matmul, sum_rows
from ..models import AbstractStateSpaceModel
from ._metrics import chi2_mean_bounds
from ._noise import key_words, step_normals
from ._engine import block_size_for, check_mesh, run_blocks
from ._sharding import RUN_AXIS, SWEEP_AXIS, axis_size
from ._simulate import (
    _resolve_num_steps,
    advance,
    check_detection_probability,
    draw_detections,
    draw_initial_state,
    noise_factors,
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
    nis_dof: Array  # (T,): Σ observed measurement components (NIS degrees of freedom) over the runs


class MonteCarloResult(eqx.Module):
    """Statistics of a Monte Carlo run of ``num_runs`` runs over ``T`` steps.

    **Fields:**

    - ``mse`` ``(T, n)``: mean squared error of each state component at each step.
    - ``mean_error`` ``(T, n)``: mean of ``x − x̂`` (the bias; 0 for a linear filter).
    - ``nees`` ``(T,)``: NEES averaged over runs; ``nees_bounds`` ``(T, 2)`` its two-sided bounds.
    - ``nees_std`` ``(T,)``: the empirical standard deviation of NEES over runs.
    - ``nis`` ``(T,)``: NIS averaged over runs; ``nis_dof`` ``(T,)`` its degrees of freedom (the
      measurement components observed, averaged over the runs: with per-run detections or
      masks, a run's NIS at step ``k`` is χ²(d_ik) with ``d_ik`` its own observed components);
      ``nis_bounds`` ``(T, 2)``: the bounds of the run average, from χ²(Σ_i d_ik) / M (a sum of
      independent χ²(d_i) is χ²(Σ d_i)); ``[0, 0]`` at steps no run observed.
    - ``anees`` ``()``: NEES averaged over runs and steps and divided by ``n`` (1 when
      consistent). ``anees_bounds`` ``(2,)``: the per-step χ²(M·n)/(M·n) bounds. Averaging over
      steps cannot increase the variance of the per-step average (steps are positively
      correlated at worst completely), so these bounds are valid and conservative for ``anees``.
    - ``num_runs``: runs that contributed; ``num_failed``: runs excluded because the filter
      produced a non-finite value (a warning is issued when this is not 0).
    - ``confidence``: the probability content of the bounds (default 0.95).
    - ``shared_covariance``: True when the filter's covariances were computed once for all runs
      (see :func:`monte_carlo`), False when every run carried its own.
    - ``precision_warning``: True when the statistics were accumulated in a floating type
      narrower than float64 and the ANEES or the mean NIS exceed ``PRECISION_MARGIN`` (10) times
      their upper bounds (a ``RuntimeWarning`` naming float32 is issued too). A mismodelled
      filter rarely exceeds its bound by more than a few times; float32 round-off of a
      near-singular covariance (long runs, tiny process noise, large states) gives 10²–10⁵.
      Float64 results never set it: there such a ratio is a modelling error, not round-off.
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
    shared_covariance: bool = eqx.field(static=True, default=False)
    precision_warning: bool = eqx.field(static=True, default=False)

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


# Runs per compiled block. The block is the unit of compilation and of device work; it does
# not depend on `chunk_size` (which only sets how often progress is reported), so changing the
# chunk size never recompiles. Fewer runs than a block use the next power of two.
_SHARED_BLOCK = 2048  # shared covariance: (n, block) state, wide element-wise loops
_PER_RUN_BLOCK = 512  # per-run covariance: (block, n, n) carries stay in cache


class _StepSums(NamedTuple):
    """One step's sums over the runs of a block (an entry of the scan's per-step output)."""

    error: Array  # (n,)
    squared_error: Array  # (n,)
    nees: Array  # ()
    nees_sq: Array  # ()
    nis: Array  # ()


def _run_keys(key, start, block):
    """Run ``i`` of the study uses ``fold_in(key, i)``: its prior key and its per-step key words."""
    run_index = start + jnp.arange(block)
    keys = jax.vmap(lambda i: jax.random.fold_in(key, i))(run_index)
    prior_keys, steps_keys = jax.vmap(step_keys)(keys)
    return prior_keys, key_words(steps_keys)


def _simulated_block(truth, factors, first_step, key, start, block):
    """The truth of ``block`` runs: ``(initial state (n, block), step 0's draws, step function)``.

    Runs are the trailing axis; the draws are exactly those of :func:`simulate` for each run.
    The step function maps ``(x_{k-1}, draws_k, k)`` to ``(x_k, z_k, draws_{k+1})``: each step's
    draws are made one step ahead and carried by the scan, because a value that crosses the loop
    boundary is materialised once, while one computed in the same step would be fused into, and
    recomputed by, each of its consumers (the hash and the inverse error function several times).
    """
    prior_keys, words = _run_keys(key, start, block)
    x0 = jax.vmap(lambda k: draw_initial_state(truth, factors, k), out_axes=1)(prior_keys)
    num = truth.state_dim + truth.meas_dim
    dtype = truth.initial_mean.dtype

    def truth_step(x_prev, eps, k):
        x, z = advance(truth, factors, first_step, x_prev, eps, k)
        return x, z, step_normals(words, k + 1, num, dtype)

    return x0, step_normals(words, 0, num, dtype), truth_step


def _per_run_block(filter, filter_model, truth, factors, observed, first_step, key, start, use):
    """Per-run covariance path for one block: a scan over steps of the ``vmap``-ed filter step.

    Every run carries its own filter state; each step simulates the block's truth, filters (the
    single step function :func:`~jaxtrack.filters.filter_step`, ``vmap``-ed over runs) and adds
    the step's error, NEES and NIS of the runs where ``use`` to the per-step sums. ``observed``
    is the schedule shared by the runs, ``(T, m)``, or each run's own, ``(T, block, m)``.
    Returns ``(per-step sums, ok per run)``.
    """
    block = use.shape[0]
    x0, eps0, truth_step = _simulated_block(truth, factors, first_step, key, start, block)

    def one(filt, x, z, k, obs):
        filt, (_, _, post) = filter.step(filter_model, filt, z, obs, first_step=first_step)
        error = x - post.mean
        nees, nis = filter.consistency(post, error)
        return filt, error, nees, nis

    def step(carry, inputs):
        filt, x_prev, eps, ok = carry
        k, obs = inputs
        x, z, eps = truth_step(x_prev, eps, k)
        filt, error, nees, nis = jax.vmap(one, in_axes=(0, 1, 1, None, obs_axis))(filt, x, z, k, obs)
        ok = ok & filt.ok & jnp.isfinite(nees) & jnp.isfinite(nis)
        return (filt, x, eps, ok), _masked_sums(use, error, nees, nis, axis=0)

    obs_axis = None if observed.ndim == 2 else 0
    filt0 = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a, (block,) + a.shape), filter.init(filter_model))
    ks = jnp.arange(observed.shape[0])
    init = (filt0, x0, eps0, jnp.ones((block,), bool))
    (_, _, _, ok), sums = jax.lax.scan(step, init, (ks, observed))
    return sums, ok


def _masked_sums(use, error, nees, nis, axis):
    """Sums over the runs (``axis`` of ``error``) where ``use``.

    The terms are stacked and summed by one product with the 0/1 weights (one kernel instead of
    five reductions). Excluded runs are zeroed first, not only weighted, because an excluded run
    may hold NaN and NaN·0 is NaN.
    """
    n = error.shape[0 if axis == -1 else 1]
    if axis == 0:
        error = error.T
    terms = jnp.concatenate([error, error * error, jnp.stack([nees, nees * nees, nis])])
    terms = jnp.where(use[None, :], terms, 0.0)
    sums = terms @ use.astype(terms.dtype)
    return _StepSums(sums[:n], sums[n:2 * n], sums[2 * n], sums[2 * n + 1], sums[2 * n + 2])


def _shared_block(truth, factors, filter_model, cov, maps, nees_factor, observed, first_step, key, start, use):
    """Shared-covariance path for one block: truth, measurements and means of ``block`` runs.

    The filter's covariances, gains and the inverse Cholesky factors that NEES and NIS need are
    the same for every run (``cov``, ``maps``, ``nees_factor``: computed once per Monte Carlo
    call); only the truth and the estimates are per run, held as ``(n, block)`` matrices so that
    each step is a few element-wise loops over the block. The draws are those of
    :func:`simulate` for the same run key. Returns ``(per-step sums, ok per run)``.
    """
    block = use.shape[0]
    x0, eps0, truth_step = _simulated_block(truth, factors, first_step, key, start, block)
    m0 = jnp.broadcast_to(filter_model.initial_mean[:, None], x0.shape)

    def step(carry, inputs):
        x_prev, eps, est, ok = carry
        k, obs, gain, s_inv, p_inv, mp = inputs
        x, z, eps = truth_step(x_prev, eps, k)
        post, innovation = mean_step(mp, gain, est, z, obs)
        error = x - post
        w_e = matmul(p_inv, error)
        w_y = matmul(s_inv, innovation)
        nees = sum_rows(w_e * w_e)
        nis = sum_rows(w_y * w_y)
        ok = ok & all_rows(jnp.isfinite(error)) & jnp.isfinite(nees) & jnp.isfinite(nis)
        return (x, eps, post, ok), _masked_sums(use, error, nees, nis, axis=-1)

    ks = jnp.arange(observed.shape[0])
    inputs = (ks, observed, cov.gain, cov.innovation_chol_inv, nees_factor, maps)
    init = (x0, eps0, m0, jnp.ones((block,), bool))
    (_, _, _, ok), sums = jax.lax.scan(step, init, inputs)
    return sums, ok


@eqx.filter_jit
def _shared_setup(filter, filter_model, truth, observed, first_step):
    """Once per Monte Carlo call: noise factors of the truth, the filter's shared covariances,
    its mean maps and the inverse Cholesky factors of the filtered covariances (for NEES)."""
    num_steps = observed.shape[0]
    factors = noise_factors(truth, num_steps)
    cov = shared_covariances(filter, filter_model, observed, first_step)
    maps = mean_maps(filter, filter_model, cov.gain, first_step)
    nees_factor = jax.vmap(cholesky_and_inverse)(cov.filtered_cov)[1]
    return factors, cov, maps, nees_factor


class _Common(eqx.Module):
    """What every block and every swept value share: the filter, the schedule, the prior's place.

    ``detection`` (``P_D`` per step) and ``run_mask`` (every run's own mask) are None unless
    given; either one gives every run its own schedule (:func:`_block_observed`).
    """

    filter: AbstractFilter
    observed: Array  # (T, m)
    first_step: str = eqx.field(static=True)
    detection: Array | None = None  # (T,) detection probability
    run_mask: Array | None = None  # (M, T, m) per-run masks


def _block_observed(common: _Common, key, start, block, dtype):
    """The measurement schedule of runs ``start … start+block−1``: None when every run shares
    ``common.observed``, else ``(T, block, m)``: the shared mask AND the run's rows of the per-run
    mask AND its detections (a missed detection removes the whole measurement vector).

    Run ``i``'s detections are :func:`~jaxtrack.montecarlo._simulate.draw_detections` of
    ``fold_in(key, i)``, exactly those of ``simulate(truth, fold_in(key, i), T,
    detection_probability=P_D)``. Padding runs (``i ≥ M``) read the last run's mask row (the index
    is clamped, never out of range); ``valid`` excludes them from the statistics.
    """
    if common.detection is None and common.run_mask is None:
        return None
    run_index = start + jnp.arange(block)
    obs = jnp.broadcast_to(common.observed, (block,) + common.observed.shape)  # (block, T, m)
    if common.run_mask is not None:
        rows = jnp.minimum(run_index, common.run_mask.shape[0] - 1)
        obs = obs & jnp.take(common.run_mask, rows, axis=0)
    if common.detection is not None:
        keys = jax.vmap(lambda i: jax.random.fold_in(key, i))(run_index)
        detected = jax.vmap(lambda k: draw_detections(k, common.detection, dtype))(keys)  # (block, T)
        obs = obs & detected[:, :, None]
    return jnp.swapaxes(obs, 0, 1)


class _Models(eqx.Module):
    """What one Monte Carlo (one value of a sweep) runs: the truth, the filter's model and, on the
    shared-covariance path, what :func:`_shared_setup` computed once (None on the per-run path)."""

    truth: AbstractStateSpaceModel
    filter_model: AbstractStateSpaceModel
    setup: Any = None


def _block_delta(common: _Common, models: _Models, key, start, valid) -> _Sums:
    """The sums of one block of runs ``start … start+block−1`` (those where ``valid``).

    The block function handed to :func:`~jaxtrack.montecarlo._engine.run_blocks`. The per-step
    sums are accumulated inside the scan, so nothing per run is kept. A run that turns
    non-finite is excluded from the statistics: if any did, the block is run again with those
    runs masked out (same draws), which costs nothing in the usual case. The block is a pure
    function of its start index and the key, so where it runs (which device, which host) cannot
    change it.
    """
    filter, observed, first_step = common.filter, common.observed, common.first_step
    truth, filter_model, setup = models.truth, models.filter_model, models.setup
    per_run_obs = _block_observed(common, key, start, valid.shape[0], truth.initial_mean.dtype)
    if setup is None:
        factors = noise_factors(truth, observed.shape[0])
        obs = observed if per_run_obs is None else per_run_obs
        run = lambda use: _per_run_block(  # noqa: E731
            filter, filter_model, truth, factors, obs, first_step, key, start, use)
    else:
        factors, cov, maps, nees_factor = setup
        run = lambda use: _shared_block(  # noqa: E731
            truth, factors, filter_model, cov, maps, nees_factor, observed, first_step, key, start, use)
    step_sums, ok = run(valid)
    use = valid & ok
    step_sums = jax.lax.cond(jnp.all(ok | ~valid), lambda: step_sums, lambda: run(use)[0])
    w = use.astype(step_sums.nees.dtype)
    # NIS degrees of freedom of the runs that count: integers, summed exactly in any order.
    if per_run_obs is None:
        dof = jnp.sum(observed, axis=-1).astype(w.dtype) * jnp.sum(w)
    else:
        dof = jnp.sum(per_run_obs, axis=-1).astype(w.dtype) @ w
    return _Sums(*step_sums, jnp.sum(w), jnp.sum((valid & ~ok).astype(w.dtype)), dof)


class _Prepared(NamedTuple):
    filter: AbstractFilter
    filter_model: AbstractStateSpaceModel
    num_steps: int
    observed: Array
    shared: bool
    block: int
    detection: Array | None  # (T,) P_D, or None
    run_mask: Array | None  # (M, T, m), or None


def _prepare(truth, num_runs, num_steps, filter, filter_model, mask, first_step, chunk_size, covariance,
             detection_probability=None):
    """Validate a Monte Carlo call; choose the path and the block size."""
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
    observed, run_mask = jnp.ones((num_steps, m), bool), None
    if mask is not None:
        mask = jnp.asarray(mask)
        # A 2-D mask that fits both (T, m) and (M, T) (M = T = m) is read as the shared (T, m).
        check_shape("mask", mask, [(num_steps,), (num_steps, m), (num_runs, num_steps), (num_runs, num_steps, m)])
        if mask.dtype != bool:
            raise InputError(f"`mask` must be boolean (True = observed); got dtype {mask.dtype}.")
        if mask.ndim == 1 or mask.shape == (num_steps, m):
            observed = jnp.broadcast_to(mask[:, None] if mask.ndim == 1 else mask, (num_steps, m))
        else:
            run_mask = jnp.broadcast_to(mask[..., None] if mask.ndim == 2 else mask, (num_runs, num_steps, m))
    detection = None
    if detection_probability is not None:
        detection = jnp.asarray(check_detection_probability(detection_probability, num_steps),
                                truth.initial_mean.dtype)

    schedule_is_shared = detection is None and run_mask is None
    if not schedule_is_shared and (covariance == "shared" or isinstance(covariance, SharedCovariance)):
        raise InputError(
            "`covariance='shared'` does not apply with "
            + ("a `detection_probability`" if detection is not None else "a per-run `mask`")
            + ": every run then has its own measurement schedule, so the filter's covariances and gains "
            "differ from run to run and cannot be computed once for all; use covariance='auto' or 'per_run'."
        )
    shared = resolve_covariance(covariance, filter, filter_model, schedule_is_shared).shared
    block = block_size_for(num_runs, _SHARED_BLOCK if shared else _PER_RUN_BLOCK)
    return _Prepared(filter, filter_model, num_steps, observed, shared, block, detection, run_mask)


def _zero_sums(num_steps, n, dtype, lead=()):
    z = lambda *shape: jnp.zeros(lead + shape, dtype)  # noqa: E731
    return _Sums(z(num_steps, n), z(num_steps, n), z(num_steps), z(num_steps), z(num_steps), z(), z(), z(num_steps))


def monte_carlo(
    truth: AbstractStateSpaceModel,
    key: PRNGKeyArray,
    num_runs: int,
    *,
    num_steps: int | None = None,
    filter: AbstractFilter | None = None,
    filter_model: AbstractStateSpaceModel | None = None,
    mask: ArrayLike | None = None,
    detection_probability: float | ArrayLike | None = None,
    first_step: FirstStep = "update",
    chunk_size: int = 1000,
    confidence: float = 0.95,
    progress: bool = True,
    covariance: CovarianceMode = "auto",
    mesh: Mesh | None = None,
    mesh_axis: str = RUN_AXIS,
) -> MonteCarloResult:
    """Monte Carlo evaluation of a filter: ``num_runs`` simulated runs, streaming statistics.

    Each run draws its truth and measurements from ``truth`` and filters them with ``filter``
    built on ``filter_model`` (defaults: the Kalman filter on the true model, i.e. a matched
    filter). Simulation, filtering and scoring are fused in one scan per block of runs, and
    only per-step sums over runs are kept: memory is ``O(T · n)`` plus one block's state,
    whatever ``num_runs`` is (10⁶ runs × 200 steps of a 4-state model stay far below 1 GB).

    **Shared covariance (automatic).** When ``filter`` is a
    :class:`~jaxtrack.filters.KalmanFilter` (optimal or fixed gain) and ``filter_model`` a
    :class:`~jaxtrack.models.LinearGaussianModel`, the filter's covariances and gains are the same
    in every run (the mask is shared), so they are computed once and only the truth and the
    estimates are propagated per run. The truth model may be anything. Other filters (EKF, UKF)
    run with a covariance per run, and so does every filter when runs have their own measurement
    schedules (``detection_probability`` or a per-run ``mask``: the covariances then differ from
    run to run). ``covariance="per_run"`` forces the general path (the statistics agree to
    rounding); ``"shared"`` raises ``InputError`` where it does not apply.

    Run ``i`` uses the key ``jax.random.fold_in(key, i)`` and the same per-step draws as
    :func:`simulate`, so results do not depend on ``chunk_size`` at all, and run ``i`` can be
    replayed alone with ``simulate(truth, jax.random.fold_in(key, i), T)``.

    **Missed detections.** With ``detection_probability`` ``P_D``, each run draws its own
    detections, independently per step, from its own key: run ``i``'s are
    ``simulate(truth, fold_in(key, i), T, detection_probability=P_D).detected`` (filter it with
    ``run_filter(..., mask=detected)`` to replay it), so they too do not depend on ``chunk_size``
    or on the devices. A detection is the whole measurement vector: at a missed step every
    component is missing. The statistics follow each run's schedule: a run's NIS at step ``k``
    has its own observed components as degrees of freedom, ``nis_dof`` is their average over the
    runs and ``nis_bounds`` come from the χ² of their sum; NEES is unaffected (the whole state is
    scored at every step).

    **Many devices and hosts.** With ``mesh`` (e.g. :func:`~jaxtrack.montecarlo.run_mesh`), the
    blocks of runs are dealt out along the mesh axis ``mesh_axis``, one per device per round, and
    their sums are added in block order: the result is identical, bit for bit, to the
    single-device result for the same key. Across hosts, call ``jax.distributed.initialize`` in
    every process first and make the same call in each; every process gets the result.

    **Arguments:**

    - ``truth``: the model that generates the data.
    - ``key``: a PRNG key; ``num_runs``: the number of runs ``M``.
    - ``num_steps``: ``T`` (defaults to the models' per-step length).
    - ``filter``, ``filter_model``: the estimator and the model it assumes (may differ from
      ``truth``, e.g. a wrong Q); both must have the truth's state and measurement sizes.
    - ``mask``: measurement mask, True = observed: shared by all runs, ``(T,)`` or ``(T, m)``, or
      one per run, ``(M, T)`` or ``(M, T, m)`` (row ``i`` is run ``i``'s; held in memory whole,
      ``M·T·m`` bytes). A 2-D mask that fits both ``(T, m)`` and ``(M, T)`` is read as ``(T, m)``.
    - ``detection_probability``: None (every step detected), or ``P_D`` in ``(0, 1]``, a float or one
      per step ``(T,)``; a fixed value (not traced, not differentiated). Missed detections are
      AND-ed with ``mask``. Either this or a per-run mask selects the per-run covariance path.
    - ``first_step``: where the prior sits, as in :func:`~jaxtrack.filters.run_filter`; the
      truth's prior is the distribution of the initial state, the filter model's prior is what
      the filter assumes.
    - ``chunk_size``: runs between progress updates (the compiled block size is fixed, so
      any chunk size reuses one compilation); ``confidence``: content of the χ² bounds;
      ``progress``: show a progress bar.
    - ``covariance``: ``"auto"`` (default), ``"shared"`` or ``"per_run"`` (see above; ``"shared"`` with
      per-run schedules raises ``InputError``).
    - ``mesh``, ``mesh_axis``: a ``jax.sharding.Mesh`` and the name of its axis to share runs
      along (default ``"runs"``); None runs on the default device.

    **Returns:** a :class:`MonteCarloResult`.
    """
    prep = _prepare(truth, num_runs, num_steps, filter, filter_model, mask, first_step, chunk_size, covariance,
                    detection_probability)
    filter, filter_model, num_steps, observed, shared, block, detection, run_mask = prep
    setup = _shared_setup(filter, filter_model, truth, observed, first_step) if shared else None
    if mesh is not None:
        check_mesh(mesh, (mesh_axis,))
    n = truth.state_dim
    sums = run_blocks(
        _block_delta, _zero_sums(num_steps, n, filter_model.initial_cov.dtype),
        common=_Common(filter, observed, first_step, detection, run_mask),
        value=_Models(truth, filter_model, setup), key=key,
        num_runs=num_runs, block=block, mesh=mesh, run_axis=mesh_axis, chunk_size=chunk_size,
        progress=progress, desc="Monte Carlo")
    return _summarize(sums, n, confidence, shared)


def monte_carlo_sweep(
    models: Callable[[Any], AbstractStateSpaceModel | tuple[AbstractStateSpaceModel, AbstractStateSpaceModel]],
    values: Sequence[Any] | ArrayLike,
    key: PRNGKeyArray,
    num_runs: int,
    *,
    num_steps: int | None = None,
    filter: AbstractFilter | None = None,
    mask: ArrayLike | None = None,
    detection_probability: float | ArrayLike | None = None,
    first_step: FirstStep = "update",
    chunk_size: int = 1000,
    confidence: float = 0.95,
    progress: bool = True,
    covariance: CovarianceMode = "auto",
    mesh: Mesh | None = None,
    sweep_axis: str = SWEEP_AXIS,
    run_axis: str = RUN_AXIS,
) -> list[MonteCarloResult]:
    """Monte Carlo at every value of a parameter: one :class:`MonteCarloResult` per value.

    ``models(value)`` builds the truth model for one value, or a pair ``(truth, filter_model)``
    (e.g. a filter designed for a nominal sampling period run on a truth with another one).
    Every value uses the same key, hence the same run keys and draws (common random numbers: the
    differences between values are not blurred by independent noise), and result ``j`` equals
    ``monte_carlo(truth_j, key, num_runs, filter_model=filter_model_j, ...)`` to the last bit.

    The models of all values must have the same structure (types, shapes, static fields), so
    that they stack into one batch. With ``mesh``, the values are shared out along the mesh axis
    ``sweep_axis`` (padded to a multiple of its size) and the runs of each value along
    ``run_axis``; either axis may be absent (e.g. ``run_mesh(axis_name="sweep")`` shares values
    only, :func:`~jaxtrack.montecarlo.sweep_mesh` builds both). Results do not depend on the mesh.

    **Arguments:** ``models``, ``values`` (a sequence, or an array whose leading axis indexes the
    values); the rest as :func:`monte_carlo` (``filter``, ``mask`` and ``detection_probability`` are
    common to all values: every value sees the same per-run detections, common random numbers).

    Example — RMSE against the sampling period, on 4 devices::

        def models(tau):
            return constant_velocity(tau, accel_psd=0.5, measurement_std=10.0, initial_cov=P0)

        res = monte_carlo_sweep(models, [0.5, 1.0, 2.0, 4.0], jax.random.key(0), 10_000,
                                num_steps=100, mesh=run_mesh(axis_name="sweep"))
        final_rmse = [float(r.rmse((0,))[-1]) for r in res]
    """
    values = list(values)
    if not values:
        raise InputError("`values` must hold at least one parameter value.")
    pairs = []
    for v in values:
        built = models(v)
        truth, filter_model = built if isinstance(built, tuple) else (built, None)
        pairs.append((truth, filter_model))
    preps = [
        _prepare(t, num_runs, num_steps, filter, fm, mask, first_step, chunk_size, covariance, detection_probability)
        for t, fm in pairs
    ]
    pairs = [(t, p.filter_model) for (t, _), p in zip(pairs, preps)]
    prep = preps[0]
    filter, observed, shared, block = prep.filter, prep.observed, prep.shared, prep.block
    if any(p.num_steps != prep.num_steps or p.shared != shared for p in preps):
        raise InputError("Every value's models must have the same number of steps and the same filter path.")

    def same_structure(a, b):
        leaves_a, leaves_b = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
        return jax.tree_util.tree_structure(a) == jax.tree_util.tree_structure(b) and all(
            np.shape(x) == np.shape(y) for x, y in zip(leaves_a, leaves_b))

    for j, pair in enumerate(pairs):
        if not same_structure(pair, pairs[0]):
            raise InputError(
                f"The models built for value {j} differ in structure or shapes from those of value 0; "
                "a sweep needs models that stack (same types, static fields and array shapes)."
            )
    setups = [_shared_setup(filter, fm, t, observed, first_step) if shared else None for t, fm in pairs]

    mesh = Mesh(np.asarray(jax.devices()[:1]), (run_axis,)) if mesh is None else mesh
    check_mesh(mesh, (sweep_axis, run_axis))
    num_values = len(values)
    share = axis_size(mesh, sweep_axis)
    padded = -(-num_values // share) * share
    # Padding repeats the last value; its results are dropped.
    per_value = [_Models(t, fm, su) for (t, fm), su in zip(pairs, setups)]
    per_value += [per_value[-1]] * (padded - num_values)
    dyn, static = eqx.partition(per_value[0], eqx.is_array)
    stacked = eqx.combine(
        jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *(eqx.partition(v, eqx.is_array)[0] for v in per_value)),
        static)
    n = pairs[0][0].state_dim
    sums = run_blocks(
        _block_delta, _zero_sums(prep.num_steps, n, prep.filter_model.initial_cov.dtype, (padded,)),
        common=_Common(filter, observed, first_step, prep.detection, prep.run_mask), value=stacked, key=key,
        num_runs=num_runs,
        block=block, mesh=mesh, run_axis=run_axis, sweep_axis=sweep_axis, chunk_size=chunk_size,
        progress=progress, desc="Monte Carlo sweep")
    return [
        _summarize(jax.tree_util.tree_map(lambda a: a[j], sums), n, confidence, shared)
        for j in range(num_values)
    ]


# How far above their upper bounds the ANEES or mean NIS of a reduced-precision Monte Carlo must be
# before the result is flagged as a likely float32 failure (see MonteCarloResult.precision_warning).
PRECISION_MARGIN = 10.0


def _precision_suspect(dtype, anees, anees_hi, nis, nis_hi) -> bool:
    """True when a < float64 result's ANEES or mean NIS is above PRECISION_MARGIN × its bound."""
    if np.dtype(dtype).itemsize >= 8:
        return False
    mean_nis, mean_nis_hi = float(np.mean(nis)), float(np.mean(nis_hi))
    return bool(float(anees) > PRECISION_MARGIN * float(anees_hi)
                or (mean_nis_hi > 0 and mean_nis > PRECISION_MARGIN * mean_nis_hi))


def _summarize(sums: _Sums, n, confidence, shared=False) -> MonteCarloResult:
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
    # Run i's NIS at step k is χ²(d_ik) (its observed components); the runs are independent, so
    # the sum over runs is χ²(D_k), D_k = Σ_i d_ik, and the run average lies in
    # [χ²_{D_k}⁻¹(α/2), χ²_{D_k}⁻¹(1 − α/2)] / M: chi2_mean_bounds of D_k for one "run", over M.
    # With one schedule for all runs D_k = M·d_k and this is chi2_mean_bounds(d_k, M) exactly.
    nis_dof = sums.nis_dof / num_ok
    nees_b = chi2_mean_bounds(np.full(mean_nees.shape, n), num_ok, confidence)
    nis_b = chi2_mean_bounds(np.asarray(sums.nis_dof), 1, confidence) / num_ok
    anees = jnp.mean(mean_nees) / n
    suspect = _precision_suspect(sums.nees.dtype, anees, nees_b[0][1] / n, sums.nis / num_ok, nis_b[:, 1])
    if suspect:
        warnings.warn(
            f"jaxtrack.monte_carlo: ANEES {float(anees):.3g} (upper bound {float(nees_b[0][1] / n):.3g}) or mean "
            f"NIS far outside their bounds in {np.dtype(sums.nees.dtype).name}: float32 round-off in the "
            "covariances is a likely cause; rerun in float64 (unset JAXTRACK_ENABLE_X64) to tell it from "
            "a mismodelled filter.",
            RuntimeWarning,
            stacklevel=3,
        )
    return MonteCarloResult(
        mse=sums.squared_error / num_ok,
        mean_error=sums.error / num_ok,
        nees=mean_nees,
        nees_std=jnp.sqrt(nees_var * num_ok / max(num_ok - 1, 1)),
        nees_bounds=jnp.asarray(nees_b),
        nis=sums.nis / num_ok,
        nis_dof=nis_dof,
        nis_bounds=jnp.asarray(nis_b),
        anees=anees,
        anees_bounds=jnp.asarray(nees_b[0] / n),
        num_runs=num_ok,
        num_failed=num_failed,
        confidence=confidence,
        shared_covariance=shared,
        precision_warning=suspect,
    )

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

from typing import Any, Callable, NamedTuple, Sequence

import equinox as eqx
import jax
from jax.ad_checkpoint import checkpoint_name
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh
from jaxtyping import Array, ArrayLike, PRNGKeyArray

from .._validation import InputError, as_key, check_shape
from ..filters import AbstractFilter, InteractingMultipleModel, KalmanFilter, mean_step
from ..filters._base import FirstStep
from ..filters._batch import (
    CovarianceMode,
    SharedCovariance,
    balanced_block,
    mean_maps,
    resolve_covariance,
    shared_covariances,
)
from ..filters._linalg import all_rows, cholesky_and_inverse, marginal_cov, matmul, sum_rows, take_components
from ..models import AbstractStateSpaceModel
from ._metrics import normalized_squared_error
from ._result import MonteCarloResult, _estimator_fields, _key_fields, _masked_sums, _Sums, _summarize, _zero_sums
from ._noise import key_words, step_normals
from ._engine import check_mesh, refuse_traced, run_blocks, run_excluding_failures
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


# Runs per compiled block. The block is the unit of compilation and of device work; it does
# not depend on `chunk_size` (which only sets how often progress is reported), so changing the
# chunk size never recompiles. Fewer runs than a block use the next power of two; more are
# dealt into blocks of at most this size, evened out (filters._batch.balanced_block). The sizes
# are constants, not the machine's (run_filter_batch sizes its blocks by the CPUs, see
# filters._batch.per_run_block): the sums over a block's runs round by its size, and a key must
# give the same statistics to the last bit on every machine, and every host of a mesh must
# compile the same block.
_SHARED_BLOCK = 2048  # shared covariance: (n, block) state, wide element-wise loops
# Per-run covariance: 4,096 runs, where XLA splits the block's loops over 2 threads (512, which
# keeps the (block, n, n) carries in cache, was never split: range-bearing UKF 16,384 x 200 on
# 2 CPUs 1.73 s at 512, 1.20 s at 4,096, EKF 1.25 -> 0.91 s; on one CPU 4,096 is 14-16% slower).
_PER_RUN_BLOCK = 4096
# An IMM step is many small kernels (M members' predict/update, mixing, combination): their
# fixed cost per kernel is amortised over more runs in a wider block (3-member IMM, 8,192 × 200:
# 0.42–0.46 M steps/s at 512, 0.53–0.60 at 2,048, 0.50 at 8,192).
_IMM_BLOCK = 2048
# A filter with `needs_key` (a particle filter) draws from fold_in(run key, _FILTER_STREAM): a stream
# of its own, apart from the run's truth draws and detections. The constant is arbitrary (ASCII "filt").
_FILTER_STREAM = 0x66696C74


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


def _scored(x, mean, components):
    """``x[tc] − x̂[fc]``: the truth and the filter compared on the scored components."""
    tc, fc = components
    return take_components(x, tc) - take_components(mean, fc)


# What the rematerialised Monte Carlo step keeps for the backward pass: the simulated truth and
# measurements (they do not depend on the filter's parameters, so recomputing them, random bits
# included, would only lengthen the program).
_SAVE_TRUTH = jax.checkpoint_policies.save_only_these_names("truth_state", "truth_measurement")


def _per_run_block(filter, filter_model, truth, factors, observed, first_step, components, key, start, use,
                   stacked=False):
    """Per-run covariance path for one block: a scan over steps of the ``vmap``-ed filter step.

    Every run carries its own filter state; each step simulates the block's truth, filters (the
    single step function :meth:`~jaxtrack.filters.AbstractFilter.step`, or
    :meth:`~jaxtrack.filters.InteractingMultipleModel.step`, ``vmap``-ed over runs) and adds
    the step's error, NEES and NIS (and an IMM's mode probabilities) of the runs where ``use``
    to the per-step sums. ``observed`` is the schedule shared by the runs, ``(T, m)``, or each
    run's own, ``(T, block, m)``; ``components`` the scored ``(truth, filter)`` indices.
    Returns ``(per-step sums, ok per run)``.
    """
    block = use.shape[0]
    x0, eps0, truth_step = _simulated_block(truth, factors, first_step, key, start, block)
    fc = components[1]
    imm = isinstance(filter, InteractingMultipleModel)

    def one(filt, x, z, k, obs):
        if imm:
            # An IMM has no single innovation: NIS is not scored (0, with 0 degrees of freedom).
            filt, out = filter.step(filt, z, obs, first_step=first_step)
            error = _scored(x, out.filtered_mean, components)
            nees = normalized_squared_error(error, marginal_cov(out.filtered_cov, fc))
            return filt, error, nees, jnp.zeros((), error.dtype), out.mode_probs
        filt, (_, _, post) = filter.step(filter_model, filt, z, obs, first_step=first_step)
        error = _scored(x, post.mean, components)
        nees, nis = filter.consistency(post, error, fc)
        return filt, error, nees, nis, jnp.zeros((0,), error.dtype)

    def step(carry, inputs):
        filt, x_prev, eps, ok = carry
        k, obs = inputs
        x, z, eps = truth_step(x_prev, eps, k)
        x, z = checkpoint_name(x, "truth_state"), checkpoint_name(z, "truth_measurement")
        filt, error, nees, nis, modes = jax.vmap(one, in_axes=(0, 1, 1, None, obs_axis))(filt, x, z, k, obs)
        ok = ok & filt.ok & jnp.isfinite(nees) & jnp.isfinite(nis)
        return (filt, x, eps, ok), _masked_sums(None if stacked else use, error, nees, nis, axis=0, modes=modes)

    obs_axis = None if observed.ndim == 2 else 0
    if not imm and filter.needs_key:
        # A filter that draws (a particle filter): run i's own key, fold_in(fold_in(key, i), tag),
        # a stream apart from the run's truth draws (split) and detections (another tag).
        run_keys = jax.vmap(lambda i: jax.random.fold_in(key, i))(start + jnp.arange(block))
        filt0 = jax.vmap(lambda k: filter.init(filter_model, key=jax.random.fold_in(k, _FILTER_STREAM)))(run_keys)
    else:
        init_state = filter.init() if imm else filter.init(filter_model)
        filt0 = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a, (block,) + a.shape), init_state)
    ks = jnp.arange(observed.shape[0])
    init = (filt0, x0, eps0, jnp.ones((block,), bool))
    # Rematerialised step: under `grad` the backward pass recomputes a step from its carry
    # instead of reading ~10³ stored intermediates per step (each a stacked buffer written in the
    # forward scan and read back in the backward one). For the README's IMM gradient this cuts the
    # compiled program by a third and its run time by 20-30 % (less memory traffic); without
    # `grad` it changes nothing.
    (_, _, _, ok), sums = jax.lax.scan(jax.checkpoint(step, prevent_cse=False, policy=_SAVE_TRUTH), init,
                                       (ks, observed))
    return sums, ok


def _shared_block(truth, factors, filter_model, cov, maps, nees_factor, observed, first_step, components, key, start,
                  use, stacked=False):
    """Shared-covariance path for one block: truth, measurements and means of ``block`` runs.

    The filter's covariances, gains and the inverse Cholesky factors that NEES and NIS need are
    the same for every run (``cov``, ``maps``, ``nees_factor``: computed once per Monte Carlo
    call); only the truth and the estimates are per run, held as ``(n, block)`` matrices so that
    each step is a few element-wise loops over the block. The draws are those of
    :func:`simulate` for the same run key; ``components`` the scored ``(truth, filter)`` indices
    (``nees_factor`` is then that of the marginal covariance). Returns ``(per-step sums, ok per run)``.
    """
    block = use.shape[0]
    x0, eps0, truth_step = _simulated_block(truth, factors, first_step, key, start, block)
    m0 = jnp.broadcast_to(filter_model.initial_mean[:, None], x0.shape)

    def step(carry, inputs):
        x_prev, eps, est, ok = carry
        k, obs, gain, s_inv, p_inv, mp = inputs
        x, z, eps = truth_step(x_prev, eps, k)
        post, innovation = mean_step(mp, gain, est, z, obs)
        error = _scored(x, post, components)
        w_e = matmul(p_inv, error)
        w_y = matmul(s_inv, innovation)
        nees = sum_rows(w_e * w_e)
        nis = sum_rows(w_y * w_y)
        ok = ok & all_rows(jnp.isfinite(error)) & jnp.isfinite(nees) & jnp.isfinite(nis)
        return (x, eps, post, ok), _masked_sums(None if stacked else use, error, nees, nis, axis=-1)

    ks = jnp.arange(observed.shape[0])
    inputs = (ks, observed, cov.gain, cov.innovation_chol_inv, nees_factor, maps)
    init = (x0, eps0, m0, jnp.ones((block,), bool))
    (_, _, _, ok), sums = jax.lax.scan(step, init, inputs)
    return sums, ok


@eqx.filter_jit
def _shared_setup(filter, filter_model, truth, observed, first_step, filter_components=None):
    """Once per Monte Carlo call: noise factors of the truth, the filter's shared covariances,
    its mean maps and the inverse Cholesky factors of the filtered covariances (for NEES; of
    their marginals over ``filter_components`` when given)."""
    num_steps = observed.shape[0]
    factors = noise_factors(truth, num_steps)
    cov = shared_covariances(filter, filter_model, observed, first_step)
    maps = mean_maps(filter, filter_model, cov.gain, first_step)
    nees_factor = jax.vmap(cholesky_and_inverse)(marginal_cov(cov.filtered_cov, filter_components))[1]
    return factors, cov, maps, nees_factor


class _Common(eqx.Module):
    """What every block and every swept value share: the filter, the schedule, the prior's place.

    ``detection`` (``P_D`` per step) and ``run_mask`` (every run's own mask) are None unless
    given; either one gives every run its own schedule (:func:`_block_observed`).
    ``components``: the scored ``(truth_components, filter_components)``, each None for all.
    """

    filter: AbstractFilter | InteractingMultipleModel
    observed: Array  # (T, m)
    first_step: str = eqx.field(static=True)
    detection: Array | None = None  # (T,) detection probability
    run_mask: Array | None = None  # (M, T, m) per-run masks
    components: tuple = eqx.field(static=True, default=(None, None))
    # True (differentiable_monte_carlo): each run's per-step terms are kept and summed after the
    # block's scan, over the runs that stayed finite, instead of a second pass without them.
    stacked: bool = eqx.field(static=True, default=False)


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
    runs masked out (same draws), which costs nothing in the usual case (``common.stacked``: the
    runs' per-step terms are kept and summed once ``ok`` is known, one pass). The block is a pure
    function of its start index and the key, so where it runs (which device, which host) cannot
    change it.
    """
    filter, observed, first_step, components = common.filter, common.observed, common.first_step, common.components
    truth, filter_model, setup = models.truth, models.filter_model, models.setup
    per_run_obs = _block_observed(common, key, start, valid.shape[0], truth.initial_mean.dtype)
    if setup is None:
        factors = noise_factors(truth, observed.shape[0])
        obs = observed if per_run_obs is None else per_run_obs
        run = lambda use, stacked=False: _per_run_block(  # noqa: E731
            filter, filter_model, truth, factors, obs, first_step, components, key, start, use, stacked)
    else:
        factors, cov, maps, nees_factor = setup
        run = lambda use, stacked=False: _shared_block(  # noqa: E731
            truth, factors, filter_model, cov, maps, nees_factor, observed, first_step, components, key, start, use,
            stacked)
    if common.stacked:
        # One pass; the terms (T, …, block) are summed over the runs that stayed finite. Under grad
        # the block holds per-step residuals of that size anyway, and the rerun's scan of a cond
        # cost 15 % of the EKF gradient (20,000 × 200: 4.8 → 4.1 forward passes, same run).
        (error, nees, nis, modes), ok = run(valid, True)
        axis = 0 if setup is None else -1
        step_sums = jax.vmap(lambda e, a, b, m: _masked_sums(valid & ok, e, a, b, axis, m))(error, nees, nis, modes)
    else:
        step_sums, ok = run_excluding_failures(run, valid)
    use = valid & ok
    w = use.astype(step_sums.nees.dtype)
    # NIS degrees of freedom of the runs that count: integers, summed exactly in any order.
    if isinstance(filter, InteractingMultipleModel):  # NIS not scored (no single innovation)
        dof = jnp.zeros(observed.shape[:1], w.dtype)
    elif per_run_obs is None:
        dof = jnp.sum(observed, axis=-1).astype(w.dtype) * jnp.sum(w)
    else:
        dof = jnp.sum(per_run_obs, axis=-1).astype(w.dtype) @ w
    e, e2, nees, nees2, nis, modes = step_sums
    return _Sums(e, e2, nees, nees2, nis, jnp.sum(w), jnp.sum((valid & ~ok).astype(w.dtype)), dof, modes)


class _Prepared(NamedTuple):
    filter: AbstractFilter | InteractingMultipleModel
    filter_model: AbstractStateSpaceModel | None  # None for an IMM (it holds its members' models)
    num_steps: int
    observed: Array
    shared: bool
    block: int
    detection: Array | None  # (T,) P_D, or None
    run_mask: Array | None  # (M, T, m), or None
    components: tuple  # (truth_components, filter_components), each None for all
    num_scored: int  # n, the scored components
    num_modes: int  # K, an IMM's modes (0 for one filter)
    estimator: dict  # filter_name, filter_model_name, filter_model_source of the MonteCarloResult


def _check_components(name, components, dim):
    """``components``: None, or distinct state indices in ``[0, dim)``; returned as a tuple of ints."""
    if components is None:
        return None
    try:
        out = tuple(int(c) for c in components)
    except TypeError:
        raise InputError(f"`{name}` must be a sequence of state indices; got {components!r}.") from None
    if not out or len(set(out)) != len(out) or min(out) < 0 or max(out) >= dim:
        raise InputError(f"`{name}` must hold distinct state indices in [0, {dim}); got {out}.")
    return out


def _prepare_models(truth, filter, filter_model, truth_components, filter_components):
    """The filter and its model(s), checked against the truth; the scored components."""
    filter = KalmanFilter() if filter is None else filter
    imm = isinstance(filter, InteractingMultipleModel)
    if imm and filter_model is not None:
        raise InputError("`filter_model` must be None when `filter` is an InteractingMultipleModel "
                         "(the IMM holds its members' models).")
    filter_model = None if imm else (truth if filter_model is None else filter_model)
    if not (imm or isinstance(filter, AbstractFilter)):
        raise InputError(f"`filter` must be a jaxtrack filter or an InteractingMultipleModel; "
                         f"got {type(filter).__name__}.")
    for name, model in (("truth", truth),) + ((("filter_model", filter_model),) if not imm else ()):
        if not isinstance(model, AbstractStateSpaceModel):
            raise InputError(f"`{name}` must be a jaxtrack state-space model; got {type(model).__name__}.")
    if not imm:
        filter.check_model(filter_model)
    n_f = filter.state_dim if imm else filter_model.state_dim
    m_f = filter.models[0].meas_dim if imm else filter_model.meas_dim
    if m_f != truth.meas_dim:
        who = "`filter`'s member models measure" if imm else "`filter_model` measures"
        raise InputError(f"{who} {m_f} components but `truth` measures {truth.meas_dim}.")
    tc = _check_components("truth_components", truth_components, truth.state_dim)
    fc = _check_components("filter_components", filter_components, n_f)
    n_t = truth.state_dim if tc is None else len(tc)
    n_s = n_f if fc is None else len(fc)
    if n_t != n_s:
        what = "`filter_model`" if tc is None and fc is None and not imm else "the scored filter components"
        raise InputError(
            f"{what} compare {n_s} state components with {n_t} of `truth` (state sizes: filter {n_f}, truth "
            f"{truth.state_dim}); pass `truth_components` and `filter_components` to say which correspond."
        )
    return filter, filter_model, (tc, fc), n_s, (filter.num_modes if imm else 0)


def _prepare(truth, num_runs, num_steps, filter, filter_model, mask, first_step, chunk_size, covariance,
             detection_probability=None, truth_components=None, filter_components=None):
    """Validate a Monte Carlo call; choose the path and the block size."""
    given = filter_model is not None  # read before _prepare_models puts the truth in its place
    filter, filter_model, components, num_scored, num_modes = _prepare_models(
        truth, filter, filter_model, truth_components, filter_components)
    estimator = _estimator_fields(filter, filter_model, given)
    if not isinstance(num_runs, int) or num_runs < 1:
        raise InputError(f"`num_runs` must be a positive int; got {num_runs!r}.")
    if not isinstance(chunk_size, int) or chunk_size < 1:
        raise InputError(f"`chunk_size` must be a positive int; got {chunk_size!r}.")
    if first_step not in ("update", "predict"):
        raise InputError(f"`first_step` must be 'update' or 'predict'; got {first_step!r}.")
    filter_models = filter.models if filter_model is None else (filter_model,)
    if num_steps is None:
        num_steps = next((fm.num_steps for fm in filter_models if fm.num_steps is not None), None)
    num_steps = _resolve_num_steps(truth, num_steps)
    for fm in filter_models:
        _resolve_num_steps(fm, num_steps)
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
    if filter_model is None:  # an IMM: every run carries its own mixture
        if covariance == "shared" or isinstance(covariance, SharedCovariance):
            raise InputError("`covariance='shared'` does not apply to an InteractingMultipleModel: its mode "
                             "probabilities, hence its covariances, depend on each run's data.")
        shared = False
    else:
        shared = resolve_covariance(covariance, filter, filter_model, schedule_is_shared).shared
    largest = _SHARED_BLOCK if shared else (_IMM_BLOCK if filter_model is None else _PER_RUN_BLOCK)
    block = balanced_block(num_runs, largest)
    return _Prepared(filter, filter_model, num_steps, observed, shared, block, detection, run_mask, components,
                     num_scored, num_modes, estimator)


def monte_carlo(
    truth: AbstractStateSpaceModel,
    key: PRNGKeyArray | int,
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
    truth_components: Sequence[int] | None = None,
    filter_components: Sequence[int] | None = None,
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
    - ``key``: a PRNG key, or an int seed (``jax.random.key(seed)``); ``num_runs``: the number of runs ``M``.
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
    - ``truth_components``, ``filter_components``: when the filter's state is not the truth's
      (a 4-state constant-velocity filter on a truth with a turn rate, a 5-state turn filter on
      a 4-state truth), the truth indices and the filter indices that correspond, in the same
      order, equally many; None means all of that state. Errors, MSE and NEES are over these
      components only; the NEES is that of the filter's marginal covariance over them
      (χ²(len) when consistent).

    **IMM.** ``filter`` may be an :class:`~jaxtrack.filters.InteractingMultipleModel`
    (``filter_model`` None: the IMM holds its members' models). Every run then carries its own
    mixture; the combined estimate (BLK 2001 eqs. 11.6.6-14, -15) is scored, the mean mode
    probabilities per step are streamed into ``mode_probs`` ``(T, K)``, and NIS is not scored
    (the IMM has no single innovation; ``nis`` and ``nis_dof`` are 0).

    **Returns:** a :class:`MonteCarloResult`. Its ``filter_name``, ``filter_model_name`` and
    ``filter_model_source`` say which filter ran on which model, ``"truth"`` when ``filter_model``
    was not given (the matched, best-case filter above); :meth:`MonteCarloResult.summary` says it
    in words.
    """
    key = as_key(key)
    refuse_traced("monte_carlo", key, truth, filter, filter_model, mask, detection_probability)
    prep = _prepare(truth, num_runs, num_steps, filter, filter_model, mask, first_step, chunk_size, covariance,
                    detection_probability, truth_components, filter_components)
    filter_model, num_steps, shared = prep.filter_model, prep.num_steps, prep.shared
    setup = (_shared_setup(prep.filter, filter_model, truth, prep.observed, first_step, prep.components[1])
             if shared else None)
    if mesh is not None:
        check_mesh(mesh, (mesh_axis,))
    sums = run_blocks(
        _block_delta, _zero_sums(num_steps, prep.num_scored, truth.initial_cov.dtype, num_modes=prep.num_modes),
        common=_Common(prep.filter, prep.observed, first_step, prep.detection, prep.run_mask, prep.components),
        value=_Models(truth, filter_model, setup), key=key,
        num_runs=num_runs, block=prep.block, mesh=mesh, run_axis=mesh_axis, chunk_size=chunk_size,
        progress=progress, desc="Monte Carlo")
    return _summarize(sums, prep.num_scored, confidence, shared, prep.components[1], **_key_fields(key),
                      **prep.estimator)


def monte_carlo_sweep(
    models: Callable[[Any], AbstractStateSpaceModel | tuple[AbstractStateSpaceModel, AbstractStateSpaceModel]],
    values: Sequence[Any] | ArrayLike,
    key: PRNGKeyArray | int,
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
    truth_components: Sequence[int] | None = None,
    filter_components: Sequence[int] | None = None,
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
    key = as_key(key)
    refuse_traced("monte_carlo_sweep", key, values)
    values = list(values)
    if not values:
        raise InputError("`values` must hold at least one parameter value.")
    pairs = []
    for v in values:
        built = models(v)
        truth, filter_model = built if isinstance(built, tuple) else (built, None)
        pairs.append((truth, filter_model))
    preps = [
        _prepare(t, num_runs, num_steps, filter, fm, mask, first_step, chunk_size, covariance, detection_probability,
                 truth_components, filter_components)
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
    setups = [_shared_setup(filter, fm, t, observed, first_step, prep.components[1]) if shared else None
              for t, fm in pairs]

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
    n = prep.num_scored
    sums = run_blocks(
        _block_delta, _zero_sums(prep.num_steps, n, pairs[0][0].initial_cov.dtype, (padded,), prep.num_modes),
        common=_Common(filter, observed, first_step, prep.detection, prep.run_mask, prep.components), value=stacked,
        key=key,
        num_runs=num_runs,
        block=block, mesh=mesh, run_axis=run_axis, sweep_axis=sweep_axis, chunk_size=chunk_size,
        progress=progress, desc="Monte Carlo sweep")
    return [
        _summarize(jax.tree_util.tree_map(lambda a: a[j], sums), n, confidence, shared, prep.components[1],
                   **_key_fields(key), **preps[j].estimator)
        for j in range(num_values)
    ]

"""Batches of runs: :func:`run_filter_batch`, with a shared-covariance path for linear models.

Two paths, one result type:

- **Per-run covariance** (the general path): every run carries its own covariance. It is
  ``jax.vmap`` of the very scan :func:`~jaxtrack.filters.run_filter` runs, over blocks of runs
  small enough to stay in cache. Any filter, any model, masks that differ between runs.
- **Shared covariance**: for a :class:`~jaxtrack.filters.KalmanFilter` on a
  :class:`~jaxtrack.models.LinearGaussianModel` whose runs share one measurement schedule, the
  covariances, gains and innovation covariances do not depend on the data. They are computed
  once, by the same step function on zero data, and only the means go through the batch.
  With shared gains the mean recursion is affine, so ``L`` steps of all runs are one matrix
  product ``(B, L·m) @ (L·m, ·)`` instead of ``B·L`` small matrix-vector products.

``covariance="auto"`` picks the shared path whenever it applies (see :func:`run_filter_batch`).
The two paths execute the same recursion and agree to rounding (tested to 1e-10).
"""

from __future__ import annotations

import abc
import math
import os
from typing import ClassVar, Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._validation import InputError, check_shape, is_concrete, throw_unless_ok
from ..models import AbstractStateSpaceModel
from ._base import (
    AbstractFilter,
    FilterResult,
    FirstStep,
    Save,
    _scan_filter,
    check_run_arguments,
    raise_nonfinite_measurements,
)
from ._kalman import MeanMap, mean_step
from ._linalg import cholesky_and_inverse

CovarianceMode = Literal["auto", "shared", "per_run"]

def _schedulable_cpus() -> int:
    """The CPUs this process may run on (its affinity mask, as XLA's thread pool sizes itself)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity call (macOS, Windows)
        return os.cpu_count() or 1


def per_run_block(cpus: int | None = None) -> int:
    """Runs per ``vmap``-ed block on :func:`run_filter_batch`'s per-run path.

    (Monte Carlo keeps a fixed 4,096, ``montecarlo._run._PER_RUN_BLOCK``: its sums over a block's
    runs round by the block's size, and a key gives the same statistics on every machine. Here
    each run is computed alone, with no sum across runs.)

    Every leaf of a per-run step is ``(block, …)``: a few states or sigma points per run. XLA's
    CPU backend splits an element-wise loop over that leading run axis across its threads only
    when the loop costs enough: a block of 512 runs of a 4-state UKF never does, so on two cores
    one sat idle. Measured on 2 cores, 4-state range–bearing, 16,384 × 200 (best of 3):
    ``run_filter_batch`` UKF 0.77 s at 512, 0.49 s at 4,096 (10,240 × 200); EKF 0.79 s at 512,
    0.63 at 2,048, 0.59 at 4,096 and 8,192; ``monte_carlo`` UKF 1.73 s at 512, 1.20 at 4,096,
    EKF 1.25 → 0.91 s. With one core nothing is split and the smaller block stays in cache
    (UKF ``monte_carlo`` 1.68 s at 512, 1.95 s at 4,096): 512 there.

    **Arguments:** ``cpus``: the CPUs to plan for (default: those this process may run on).

    **Returns:** 512 for one CPU, else ``2048 · cpus`` up to 16,384 (above 2 CPUs not measured).
    """
    cpus = _schedulable_cpus() if cpus is None else cpus
    return 512 if cpus <= 1 else min(2048 * cpus, 16384)


_RUN_BLOCK = per_run_block()


def balanced_block(num_runs: int, largest: int, grain: int = 512) -> int:
    """Runs per block for ``num_runs`` runs in as few blocks of at most ``largest`` as possible,
    made as equal as multiples of ``grain`` allow, so that the last block's padding stays small.

    A fixed block pads the last one: 10,000 runs in blocks of 4,096 compute 12,288 (23% wasted),
    in three blocks of 3,584 they compute 10,752 (7.5%). Up to ``grain`` runs: the next power of
    two (small batches of different sizes share one compiled block).

    **Arguments:** ``num_runs`` ``M ≥ 1``; ``largest`` the most runs a block may hold (a multiple of
    ``grain`` when above it); ``grain`` the step of block sizes.

    **Returns:** the block size, a Python int.
    """
    if num_runs <= grain or largest <= grain:
        return min(largest, 1 << max(0, (num_runs - 1).bit_length()))
    num_blocks = -(-num_runs // largest)
    per_block = -(-num_runs // num_blocks)
    return min(largest, grain * -(-per_block // grain))


class BatchFilterResult(eqx.Module):
    """Output of :func:`run_filter_batch` for ``B`` runs of ``T`` steps.

    Per-run fields have a leading batch axis ``B``. Covariance fields have it only on the
    per-run path; on the shared-covariance path (``shared_covariance`` True) every run has the
    same covariances, stored once.

    **Fields** (``n`` states, ``m`` measurement components; ``None`` where ``save`` drops them):

    - ``filtered_mean`` ``(B, T, n)``; ``predicted_mean`` ``(B, T, n)``; ``innovation``
      ``(B, T, m)``: as in :class:`~jaxtrack.filters.FilterResult`, per run.
    - ``filtered_cov``, ``predicted_cov`` ``(T, n, n)`` shared or ``(B, T, n, n)`` per run;
      ``innovation_cov`` ``(T, m, m)`` or ``(B, T, m, m)``; ``num_observed`` ``(T,)`` or ``(B, T)``.
    - ``log_likelihood`` ``(B,)``; ``final_mean`` ``(B, n)``; ``final_cov`` ``(n, n)`` or
      ``(B, n, n)``; ``ok`` ``(B,)`` bool.
    - ``shared_covariance``: which path produced the result (static).
    """

    filtered_mean: Float[Array, "B T n"] | None
    filtered_cov: Float[Array, "*B T n n"] | None
    predicted_mean: Float[Array, "B T n"] | None
    predicted_cov: Float[Array, "*B T n n"] | None
    innovation: Float[Array, "B T m"] | None
    innovation_cov: Float[Array, "*B T m m"] | None
    num_observed: Float[Array, "*B T"] | None
    log_likelihood: Float[Array, " B"]
    final_mean: Float[Array, "B n"]
    final_cov: Float[Array, "*B n n"]
    ok: Bool[Array, " B"]
    shared_covariance: bool = eqx.field(static=True)

    @property
    def num_runs(self) -> int:
        return self.log_likelihood.shape[0]

    def run(self, i: int) -> FilterResult:
        """Run ``i`` as a :class:`~jaxtrack.filters.FilterResult` (shared fields are shared)."""

        def pick(x, shared_ndim):
            if x is None:
                return None
            return x if self.shared_covariance and x.ndim == shared_ndim else x[i]

        return FilterResult(
            pick(self.filtered_mean, -1),
            pick(self.filtered_cov, 3),
            pick(self.predicted_mean, -1),
            pick(self.predicted_cov, 3),
            pick(self.innovation, -1),
            pick(self.innovation_cov, 3),
            pick(self.num_observed, 1),
            self.log_likelihood[i],
            self.final_mean[i],
            pick(self.final_cov, 2),
            self.ok[i],
        )


class SharedCovariances(NamedTuple):
    """Everything the shared-covariance path needs from the data-free covariance pass.

    All have a leading time axis ``T``; ``ok`` is a scalar (all covariances finite).
    """

    predicted_cov: Array  # (T, n, n)
    filtered_cov: Array  # (T, n, n)
    gain: Array  # (T, n, m), zero columns where missing
    innovation_cov: Array  # (T, m, m)
    innovation_chol_inv: Array  # (T, m, m): L⁻¹ with S = L Lᵀ
    log_likelihood_offset: Array  # (T,): log det S + (observed components) log 2π
    num_observed: Array  # (T,)
    ok: Array  # ()


def covariance_pass(filter: AbstractFilter, model: AbstractStateSpaceModel, observed, first_step: FirstStep):
    """The data-free covariance pass: :meth:`~jaxtrack.filters.AbstractFilter.step` on zero data.

    The one place where a filter's covariances are computed without data; used by
    :func:`jaxtrack.covariance.covariance_recursion`, the shared-covariance path of
    :func:`run_filter_batch` and :func:`~jaxtrack.montecarlo.monte_carlo`. Because it is the same
    step function as every filter run, the covariances and gains are exactly those of
    :func:`~jaxtrack.filters.run_filter` on any data with the schedule ``observed`` ``(T, m)``
    whenever ``filter.covariance_is_data_free(model)``. Traceable; returns the per-step
    ``(predicted_cov, filtered_cov, gain, innovation_cov)``, each with a leading ``T``.

    **Arguments:**

    - ``filter``: the filter strategy; ``model``: the state-space model.
    - ``observed``: boolean ``(T, m)``, the measurement schedule.
    - ``first_step``: ``"update"`` or ``"predict"``, as in :func:`~jaxtrack.filters.run_filter`.

    **Returns:** ``(predicted_cov, filtered_cov, gain, innovation_cov)``, shapes ``(T, n, n)``,
    ``(T, n, n)``, ``(T, n, m)``, ``(T, m, m)``.
    """
    dtype = model.initial_cov.dtype
    zeros = jnp.zeros(observed.shape, dtype)
    state = filter.init(model)
    state = eqx.tree_at(lambda s: s.mean, state, jnp.zeros_like(state.mean))

    def step(state, inputs):
        z, obs = inputs
        state, (_, pred_cov, post) = filter.step(model, state, z, obs, first_step=first_step)
        return state, (pred_cov, post.cov, post.gain, post.innovation_cov)

    return jax.lax.scan(step, state, (zeros, observed))[1]


def shared_covariances(filter, model, observed, first_step: FirstStep) -> SharedCovariances:
    """:func:`covariance_pass` plus the factors the shared mean pass needs (traceable).

    **Arguments:**

    - ``filter``: the filter strategy; ``model``: the state-space model.
    - ``observed``: boolean ``(T, m)``, the measurement schedule.
    - ``first_step``: ``"update"`` or ``"predict"``.

    **Returns:** :class:`SharedCovariances` (leading axis ``T``; ``ok`` a scalar).
    """
    dtype = model.initial_cov.dtype
    pred_cov, filt_cov, gain, innov_cov = covariance_pass(filter, model, observed, first_step)
    # The same factorisation condition_linearized applies to the same S.
    chol, chol_inv = jax.vmap(cholesky_and_inverse)(innov_cov)
    num_obs = jnp.sum(observed.astype(dtype), axis=-1)
    offset = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
    offset = offset + num_obs * math.log(2.0 * math.pi)
    ok = jnp.all(jnp.isfinite(filt_cov)) & jnp.all(jnp.isfinite(offset))
    return SharedCovariances(pred_cov, filt_cov, gain, innov_cov, chol_inv, offset, num_obs, ok)


def mean_maps(filter, model, gain, first_step: FirstStep) -> MeanMap:
    """The filter's :meth:`~jaxtrack.filters.KalmanFilter.mean_map` at every step (leading ``T``).

    **Arguments:**

    - ``filter``: a :class:`~jaxtrack.filters.KalmanFilter`; ``model``: the state-space model.
    - ``gain``: the shared gains, ``(T, n, m)``; ``first_step``: ``"update"`` or ``"predict"``.

    **Returns:** :class:`~jaxtrack.filters.MeanMap` with a leading axis ``T``.
    """
    return jax.vmap(lambda k: filter.mean_map(model, gain[k], k, first_step))(jnp.arange(gain.shape[0]))


# Inputs per block of the blocked mean pass: about 16 measurement components, so that a block
# is a GEMM of a few tens of columns (measured best on 2-D and 3-D position measurements).
_BLOCK_INPUTS = 16


def _block_length(meas_dim: int, num_steps: int) -> int:
    """Steps per block: ``_BLOCK_INPUTS / m``, or a nearby divisor of ``T`` (no remainder)."""
    target = max(1, min(_BLOCK_INPUTS // meas_dim, num_steps))
    for length in range(target, max(1, target // 2) - 1, -1):
        if num_steps % length == 0:
            return length
    return target


class _BlockMaps(NamedTuple):
    """Affine maps of the mean recursion over blocks of ``L`` steps (leading axis: the block).

    For a block that starts from the mean ``x`` (``n``) with the block's measurements ``z``
    (``L·m``, flattened step-major), every output of the block is ``z @ from_z + x @ from_x +
    const``; the outputs are the columns (see :func:`_block_outputs`).
    """

    from_z: Array  # (nb, L·m, d)
    from_x: Array  # (nb, n, d)
    const: Array  # (nb, d)


def _block_outputs(save, x, z, steps):
    """The mean recursion over one block: ``x`` ``(n,)``, ``z`` ``(L, m)``, ``steps`` the
    per-step maps (leading ``L``). Returns the concatenated outputs ``(d,)``:
    ``[x at the block's end (n)]`` for ``save="final"``, ``[filtered (L·n)]`` for ``"mean"``,
    ``[filtered, predicted (L·n), innovation (L·m)]`` for ``"all"``, then always the whitened
    innovations ``L⁻¹ y`` ``(L·m)`` for the log-likelihood. Each step is :func:`mean_step`.
    """
    maps, gain, chol_inv, observed = steps
    filtered, predicted, innovations, whitened = [], [], [], []
    for j in range(z.shape[0]):
        mp = jax.tree_util.tree_map(lambda a: a[j], maps)
        predicted.append(mp.transition @ x + mp.offset)
        x, y = mean_step(mp, gain[j], x, z[j], observed[j])
        innovations.append(y)
        whitened.append(chol_inv[j] @ y)
        filtered.append(x)
    head = {"final": [x], "mean": filtered, "all": filtered + predicted + innovations}[save]
    return jnp.concatenate(head + whitened)


def _block_maps(save, steps, length: int) -> _BlockMaps:
    """:class:`_BlockMaps` of consecutive blocks of ``length`` steps covering ``steps``.

    The block recursion is affine in ``(x, z)``, so its maps are its Jacobians (exact: forward
    mode through an affine function) and its value at zero.
    """
    maps = steps[0]
    n, m = maps.transition.shape[-1], steps[1].shape[-1]
    dtype = maps.transition.dtype
    blocks = jax.tree_util.tree_map(lambda a: a.reshape((-1, length) + a.shape[1:]), steps)

    def one(block_steps):
        def f(x, z):
            out = _block_outputs(save, x, z, block_steps)
            return out, out  # the value at zero comes back as aux: one evaluation, not two

        x0, z0 = jnp.zeros((n,), dtype), jnp.zeros((length, m), dtype)
        (d_x, d_z), const = jax.jacfwd(f, argnums=(0, 1), has_aux=True)(x0, z0)
        return _BlockMaps(d_z.reshape(-1, length * m).T, d_x.T, const)

    return jax.vmap(one)(blocks)


def _mean_pass(filter, model, cov: SharedCovariances, z, observed, first_step, save):
    """Means of ``B`` runs with shared gains, a block of ``L`` steps at a time.

    With shared gains the mean recursion is affine in the measurements (:class:`_MeanMaps`),
    so the outputs of ``L`` consecutive steps are one affine map of the mean at the block's
    start and the block's ``L·m`` measurements (:func:`_block_maps`). Each block is then one
    matrix product ``(B, L·m) @ (L·m, d)`` over all runs, read straight from the measurements'
    ``(B, T, m)`` layout and written straight into the ``(B, T, ·)`` histories: no transposes,
    and on a CPU a GEMM instead of ``L`` memory-bound element-wise passes. The result equals the
    step-by-step recursion up to rounding (the tests hold it to 1e-10 against the per-run path).

    ``z``: ``(B, T, m)`` (entries marked missing may hold anything). The log-likelihood is
    ``−½ Σ_k (|L_k⁻¹ y_k|² + log det S_k + m_k log 2π)``. ``ok`` is checked on the final mean and
    the log-likelihood, which every step's mean reaches through the innovations and the
    recursion (non-finite values never cancel in a sum of products).

    **Returns:** ``(final_mean (B, n), log_likelihood (B,), ok (B,), histories)`` where the
    histories are ``()``, ``(filtered_mean,)`` or ``(filtered_mean, predicted_mean, innovation)``
    (each ``(B, T, ·)``) for ``save`` ``"final"``, ``"mean"``, ``"all"``.
    """
    num_runs, num_steps, m = z.shape
    n = model.state_dim
    dtype = model.initial_cov.dtype
    maps = mean_maps(filter, model, cov.gain, first_step)
    steps = (maps, cov.gain, cov.innovation_chol_inv, observed)
    length = _block_length(m, num_steps)
    num_blocks, rest = divmod(num_steps, length)
    split = num_blocks * length
    head = jax.tree_util.tree_map(lambda a: a[:split], steps)
    tail = jax.tree_util.tree_map(lambda a: a[split:], steps)
    main_maps = _block_maps(save, head, length)
    widths = {"final": (), "mean": (n,), "all": (n, n, m)}[save]
    # Flat (B, T·d) buffers: a block's columns are its steps, step-major, as in (B, T, d).
    z_flat = z.reshape(num_runs, num_steps * m)
    obs_flat = observed.reshape(num_steps * m)

    def apply(carry, bmaps, start, steps_in_block):
        x, ss, hists = carry
        z_b = jax.lax.dynamic_slice_in_dim(z_flat, start * m, steps_in_block * m, axis=1)
        obs_b = jax.lax.dynamic_slice_in_dim(obs_flat, start * m, steps_in_block * m)
        z_b = jnp.where(obs_b[None], z_b, 0.0)  # missing entries may be NaN; 0 · NaN is NaN in a GEMM
        out = z_b @ bmaps.from_z + x @ bmaps.from_x + bmaps.const[None]
        whitened = out[:, out.shape[1] - steps_in_block * m:]
        ss = ss + jnp.sum(whitened * whitened, axis=1)
        col, new_hists = 0, []
        for h, d in zip(hists, widths):
            part = out[:, col:col + steps_in_block * d]
            new_hists.append(jax.lax.dynamic_update_slice_in_dim(h, part, start * d, axis=1))
            col += steps_in_block * d
        x_end = out[:, (steps_in_block - 1) * n:steps_in_block * n] if save != "final" else out[:, :n]
        return x_end, ss, tuple(new_hists)

    x0 = jnp.broadcast_to(model.initial_mean.astype(dtype), (num_runs, n))
    hists = tuple(jnp.zeros((num_runs, num_steps * d), dtype) for d in widths)
    carry = (x0, jnp.zeros((num_runs,), dtype), hists)

    def body(j, carry):
        return apply(carry, jax.tree_util.tree_map(lambda a: a[j], main_maps), j * length, length)

    carry = jax.lax.fori_loop(0, num_blocks, body, carry)
    if rest:
        tail_maps = jax.tree_util.tree_map(lambda a: a[0], _block_maps(save, tail, rest))
        carry = apply(carry, tail_maps, split, rest)
    x, ss, hists = carry
    ll = -0.5 * (ss + jnp.sum(cov.log_likelihood_offset))
    ok = jnp.all(jnp.isfinite(x), axis=1) & jnp.isfinite(ll)
    hists = tuple(h.reshape(num_runs, num_steps, d) for h, d in zip(hists, widths))
    return x, ll, ok, hists


@eqx.filter_jit
def _run_shared(filter, model, z, observed, first_step, save):
    cov = shared_covariances(filter, model, observed, first_step)
    x, ll, ok, hist = _mean_pass(filter, model, cov, z, observed, first_step, save)
    ok = ok & cov.ok
    hist = tuple(hist) + (None,) * (3 - len(hist))
    keep_cov = save == "all"
    result = BatchFilterResult(
        filtered_mean=hist[0],
        filtered_cov=cov.filtered_cov if keep_cov else None,
        predicted_mean=hist[1],
        predicted_cov=cov.predicted_cov if keep_cov else None,
        innovation=hist[2],
        innovation_cov=cov.innovation_cov if keep_cov else None,
        num_observed=cov.num_observed if keep_cov else None,
        log_likelihood=ll,
        final_mean=x,
        final_cov=cov.filtered_cov[-1],
        ok=ok,
        shared_covariance=True,
    )
    return result


def map_blocks(fn, args, block: int):
    """``jax.vmap(fn)`` over the runs (leading axis of every leaf of ``args``), ``block`` at a time.

    The batch is padded to a multiple of ``block`` (with copies of the first run) and the result
    cut back.

    **Arguments:**

    - ``fn``: the per-run function of one run's ``args``.
    - ``args``: a pytree whose every leaf has the leading run axis ``M``.
    - ``block``: runs per vmapped block (clipped to ``[1, M]``).

    **Returns:** the pytree of ``fn``'s outputs, each leaf with the leading axis ``M``.
    """
    leaves = jax.tree_util.tree_leaves(args)
    num = leaves[0].shape[0]
    block = max(1, min(block, num))
    num_blocks = -(-num // block)
    pad = num_blocks * block - num

    def split(a):
        if pad:
            a = jnp.concatenate([a, jnp.broadcast_to(a[:1], (pad,) + a.shape[1:])])
        return a.reshape((num_blocks, block) + a.shape[1:])

    out = jax.lax.map(jax.vmap(fn), jax.tree_util.tree_map(split, args))
    return jax.tree_util.tree_map(lambda a: a.reshape((num_blocks * block,) + a.shape[2:])[:num], out)


@eqx.filter_jit
def _run_per_run(filter, model, z, observed, first_step, save):
    per_run_mask = observed.ndim == 3
    z = _zero_missing(z, observed)

    def one(args):
        data, i = args
        z_i, obs_i = data if per_run_mask else (data, observed)
        # A filter that draws (a particle filter): run i uses fold_in(filter.key, i).
        if filter.needs_key:
            return _scan_filter(eqx.tree_at(lambda f: f.key, filter, jax.random.fold_in(filter.key, i)),
                                model, z_i, obs_i, first_step, save)
        return _scan_filter(filter, model, z_i, obs_i, first_step, save)

    runs = jnp.arange(z.shape[0])
    largest = _RUN_BLOCK if filter.batch_block is None else filter.batch_block
    block = balanced_block(z.shape[0], largest)
    res = map_blocks(one, ((z, observed) if per_run_mask else z, runs), block)
    result = BatchFilterResult(
        res.filtered_mean, res.filtered_cov, res.predicted_mean, res.predicted_cov,
        res.innovation, res.innovation_cov, res.num_observed, res.log_likelihood,
        res.final_mean, res.final_cov, res.ok, shared_covariance=False,
    )
    return result


def _maybe_throw(result, throw):
    # Outside the jitted batch (no host callback in it: the persistent compilation cache keeps it).
    if not throw:
        return result
    return throw_unless_ok(
        result,
        result.ok,
        "jaxtrack: at least one run of the batch produced a non-finite mean, covariance or "
        "log-likelihood. Likely causes: (a) a measurement is NaN/inf (pass nan_as_missing=True "
        "to skip them); (b) R or the prior covariance is not positive definite; (c) units "
        "differ by many orders of magnitude; (d) a run diverged. Pass throw=False to get the "
        "result with `ok` False for those runs.",
    )


class AbstractCovarianceStrategy(eqx.Module):
    """How a batch of runs gets its covariances: once for all runs, or one per run.

    A strategy object for :func:`run_filter_batch` and :func:`~jaxtrack.montecarlo.monte_carlo`
    (``covariance=``), in the spirit of diffrax's ``adjoint=``: the choice of *how* is an object
    that owns its behaviour, and the filter declares what it can do
    (:meth:`~jaxtrack.filters.AbstractFilter.covariance_is_data_free`).
    """

    shared: ClassVar[bool]

    @abc.abstractmethod
    def applies(self, filter: AbstractFilter, model: AbstractStateSpaceModel, mask_is_shared: bool) -> bool:
        """Whether this strategy computes what running every run alone would."""

    @abc.abstractmethod
    def run_batch(self, filter, model, z, observed, first_step, save, throw) -> "BatchFilterResult":
        """Filter the batch ``z`` ``(B, T, m)`` (already validated)."""


class SharedCovariance(AbstractCovarianceStrategy):
    """Covariances, gains and innovation covariances computed once for the whole batch.

    Applies when the filter's covariances do not depend on the data (the Kalman filter on a
    linear model) and every run has the same measurement schedule. One data-free
    :func:`covariance_pass` serves all runs; only the means are propagated per run, ``L`` steps
    of all runs per matrix product (the mean recursion with fixed gains is affine:
    :meth:`~jaxtrack.filters.KalmanFilter.mean_map`).
    """

    shared: ClassVar[bool] = True

    def applies(self, filter, model, mask_is_shared):
        return bool(mask_is_shared and filter.covariance_is_data_free(model))

    def run_batch(self, filter, model, z, observed, first_step, save, throw):
        return _maybe_throw(_run_shared(filter, model, z, observed, first_step, save), throw)


class PerRunCovariance(AbstractCovarianceStrategy):
    """Every run carries its own covariance: ``vmap`` of the single-run scan, in blocks of runs.

    Always applies (EKF, UKF, per-run masks, any model).
    """

    shared: ClassVar[bool] = False

    def applies(self, filter, model, mask_is_shared):
        return True

    def run_batch(self, filter, model, z, observed, first_step, save, throw):
        return _maybe_throw(_run_per_run(filter, model, z, observed, first_step, save), throw)


class AutoCovariance(eqx.Module):
    """Pick :class:`SharedCovariance` where it applies, else :class:`PerRunCovariance` (the default)."""


CovarianceMode = Literal["auto", "shared", "per_run"] | AbstractCovarianceStrategy | AutoCovariance
_BY_NAME = {"auto": AutoCovariance, "shared": SharedCovariance, "per_run": PerRunCovariance}


def resolve_covariance(covariance, filter, model, mask_is_shared: bool) -> AbstractCovarianceStrategy:
    """The concrete strategy for ``covariance`` (an object, or ``"auto"``/``"shared"``/``"per_run"``).

    Raises ``InputError`` for an unknown value or a :class:`SharedCovariance` that does not apply.

    **Arguments:**

    - ``covariance``: an :class:`AbstractCovarianceStrategy` or ``"auto"``, ``"shared"``, ``"per_run"``.
    - ``filter``: the filter strategy; ``model``: the state-space model.
    - ``mask_is_shared``: whether every run has the same measurement schedule.

    **Returns:** an :class:`AbstractCovarianceStrategy` (``"auto"`` resolves to shared or per-run).
    """
    if isinstance(covariance, str):
        if covariance not in _BY_NAME:
            raise InputError(f"`covariance` must be 'auto', 'shared' or 'per_run'; got {covariance!r}.")
        covariance = _BY_NAME[covariance]()
    if isinstance(covariance, AutoCovariance):
        shared = SharedCovariance()
        return shared if shared.applies(filter, model, mask_is_shared) else PerRunCovariance()
    if not isinstance(covariance, AbstractCovarianceStrategy):
        raise InputError(
            "`covariance` must be SharedCovariance(), PerRunCovariance(), AutoCovariance() or one of "
            f"'auto', 'shared', 'per_run'; got {covariance!r}."
        )
    if not covariance.applies(filter, model, mask_is_shared):
        raise InputError(
            "`covariance='shared'` (SharedCovariance) needs a filter whose covariances do not depend "
            "on the data (a KalmanFilter on a LinearGaussianModel) and one measurement schedule for "
            "every run (a mask of shape (T,) or (T, m), and nan_as_missing=False); use "
            "covariance='auto' or 'per_run'."
        )
    return covariance


@jax.jit
def _all_observed_finite(z, observed):
    observed = observed if observed.ndim == 3 else observed[None]
    return jnp.all(jnp.isfinite(z) | ~observed)


def _zero_missing(z, observed):
    """Zero measurements the schedule marks missing, so NaN there cannot reach the arithmetic."""
    return jnp.where(observed if observed.ndim == 3 else observed[None], z, 0.0)


def _prepare_batch(model, measurements, mask, nan_as_missing):
    z = jnp.asarray(measurements)
    if not jnp.issubdtype(z.dtype, jnp.floating):
        z = z.astype(model.initial_mean.dtype)
    m = model.meas_dim
    if z.ndim == 2 and m == 1:
        z = z[..., None]
    check_shape("measurements", z, [(None, None, m)])
    num_runs, num_steps = z.shape[:2]
    if num_runs == 0 or num_steps == 0:
        raise InputError(f"`measurements` must have at least one run and one step; got shape {z.shape}.")
    model_steps = model.num_steps
    if model_steps is not None and model_steps != num_steps:
        raise InputError(
            f"`measurements` has {num_steps} steps but the model's per-step arrays have "
            f"{model_steps}; they must agree."
        )
    if mask is None:
        observed = jnp.ones((num_steps, m), bool)
    else:
        mask = jnp.asarray(mask)
        check_shape("mask", mask, [(num_steps,), (num_steps, m), (num_runs, num_steps), (num_runs, num_steps, m)])
        if mask.dtype != bool:
            raise InputError(f"`mask` must be boolean (True = observed); got dtype {mask.dtype}.")
        if mask.ndim == 2 and (num_steps, m) == (num_runs, num_steps):
            raise InputError(
                f"A 2-D `mask` of shape {mask.shape} is ambiguous here (it could be (T, m) or "
                f"(B, T)); pass a 3-D per-run mask (B, T, m) or a 1-D shared mask (T,)."
            )
        if mask.ndim == 1 or mask.shape == (num_steps, m):
            observed = jnp.broadcast_to(mask[:, None] if mask.ndim == 1 else mask, (num_steps, m))
        else:
            observed = jnp.broadcast_to(mask[..., None] if mask.ndim == 2 else mask, z.shape)
    if nan_as_missing:
        finite = jnp.isfinite(z)
        observed = (observed if observed.ndim == 3 else observed[None]) & finite  # per run now
    elif is_concrete(z) and not bool(_all_observed_finite(z, observed)):
        raise_nonfinite_measurements(
            np.asarray(~jnp.isfinite(z) & (observed if observed.ndim == 3 else observed[None])))
    # Missing entries (NaN included) are zeroed inside the jitted run, fused with its first pass.
    return z, observed


def run_filter_batch(
    filter: AbstractFilter,
    model: AbstractStateSpaceModel,
    measurements: ArrayLike,
    *,
    mask: ArrayLike | None = None,
    first_step: FirstStep = "update",
    save: Save = "all",
    nan_as_missing: bool = False,
    throw: bool = True,
    covariance: CovarianceMode = "auto",
) -> BatchFilterResult:
    """Run ``filter`` on ``B`` runs of measurements at once, each from the same ``model``.

    Equivalent to ``jax.vmap`` of :func:`~jaxtrack.filters.run_filter` over runs, and faster:

    - **Shared covariance** (chosen by ``covariance="auto"`` when it applies): a
      :class:`~jaxtrack.filters.KalmanFilter` on a :class:`~jaxtrack.models.LinearGaussianModel`
      with one measurement schedule for all runs (``mask`` ``None``, ``(T,)`` or ``(T, m)``, and
      ``nan_as_missing=False``). The Kalman covariances and gains do not depend on the data, so
      one data-free covariance pass serves the whole batch and only the means are propagated
      per run, a block of steps of all runs per matrix product. Covariance fields of the
      result are stored once, without the batch axis.
    - **Per-run covariance** (otherwise, or ``covariance="per_run"``): every run has its own
      covariance, as for an EKF/UKF (the Jacobians depend on the state) or per-run masks.

    Both paths run the same step function (:func:`~jaxtrack.filters.filter_step`) for the
    covariances and agree to rounding.

    **Arguments:** as :func:`~jaxtrack.filters.run_filter`, except

    - ``measurements``: ``(B, T, m)`` (or ``(B, T)`` when ``m = 1``).
    - ``mask``: ``None``, shared ``(T,)`` / ``(T, m)``, or per run ``(B, T)`` / ``(B, T, m)``
      (a 2-D mask that fits both readings, ``B == T == m``, is refused as ambiguous).
    - ``save``: ``"all"``, ``"final"``, or ``"mean"`` (filtered means only, plus the final state
      and the log-likelihoods; the cheapest way to get every estimate).
    - ``throw``: raise if any run became non-finite (``throw=False``: read ``result.ok``).
    - ``covariance``: a strategy, :class:`AutoCovariance` (default, also ``"auto"``),
      :class:`SharedCovariance` (``"shared"``; ``InputError`` if it does not apply) or
      :class:`PerRunCovariance` (``"per_run"``).

    **Returns:** a :class:`BatchFilterResult`; ``result.run(i)`` is run ``i`` as a
    :class:`~jaxtrack.filters.FilterResult`.

    Example::

        zs = jax.vmap(lambda k: simulate(model, k, 200).measurements)(keys)   # (B, 200, 2)
        res = run_filter_batch(KalmanFilter(), model, zs)
        res.shared_covariance, res.filtered_mean.shape, res.filtered_cov.shape
        # True, (B, 200, 4), (200, 4, 4)
    """
    check_run_arguments(filter, model, first_step, save)
    z, observed = _prepare_batch(model, measurements, mask, nan_as_missing)
    strategy = resolve_covariance(covariance, filter, model, observed.ndim == 2)
    return strategy.run_batch(filter, model, z, observed, first_step, save, throw)

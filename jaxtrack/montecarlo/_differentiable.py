"""Differentiable Monte Carlo: the blocked harness inside one trace, so ``jax.grad`` goes through it.

:func:`~jaxtrack.montecarlo.monte_carlo` drives its blocks from a host loop (progress bar,
interruptible waits, concrete counts), so it cannot be traced: ``jax.grad`` of a Monte Carlo
metric raises ``ConcretizationTypeError``. :func:`differentiable_monte_carlo` runs the *same* block
function (:func:`~jaxtrack.montecarlo._run._block_delta`: same draws, same filter step, same
sums) as the body of a ``lax.scan`` over blocks, with every block wrapped in ``jax.checkpoint``:

- **common random numbers by construction**: run ``i`` is drawn from ``fold_in(key, i)`` as in
  ``monte_carlo``, so with a fixed key the objective is a deterministic, smooth function of the
  model parameters (reparameterised draws: ``x_k = f(x_{k-1}) + chol(Q) ε``) and its gradient is
  the pathwise (infinitesimal perturbation analysis) estimator;
- **memory O(one block + totals)**: reverse mode stores only the scan's carry (the per-step sums,
  ``O(T·n)``) at each block boundary and recomputes a block's forward pass while its cotangent is
  propagated (Griewank & Walther 2008, *Evaluating Derivatives*, ch. 12: checkpointing), instead
  of keeping every run's every step — ``O(M·T·n²)``, tens of GB for 10⁵ × 200.

No mesh: the scan runs on the default device (sharding a differentiated scan over devices is
not needed at these sizes; see :func:`~jaxtrack.montecarlo.monte_carlo` for the sharded forward).
"""

from __future__ import annotations

import math
import warnings
from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, PRNGKeyArray

from .._validation import InputError, as_key, is_concrete
from ..filters import AbstractFilter
from ..filters._base import FirstStep
from ..filters._batch import CovarianceMode
from ..models import AbstractStateSpaceModel
from ._engine import add_totals, block_size_for
from ._metrics import chi2_mean_bounds
from ._result import MonteCarloResult, _key_fields, _precision_suspect, _run_averages, _Sums, _zero_sums
from ._run import _block_delta, _Common, _Models, _prepare, _shared_setup

__all__ = ["differentiable_monte_carlo"]


def _scan_blocks(common_dyn, models_dyn, key, statics, num_runs, block, num_blocks, zero):
    """Σ over blocks of :func:`_block_delta`, accumulated in block order by a ``lax.scan``.

    The block is a checkpointed function of *explicit* arguments (the arrays of the filter and the
    models, the key, the start index): nothing traced is closed over, so ``jax.checkpoint`` saves
    only those inputs and the gradient reaches every model parameter.
    """
    common_static, models_static = statics

    def one_block(common_dyn, models_dyn, key, start):
        common = eqx.combine(common_dyn, common_static)
        models = eqx.combine(models_dyn, models_static)
        valid = start + jnp.arange(block) < num_runs
        return _block_delta(common, models, key, start, valid)

    if num_blocks > 1:
        # With one block, checkpointing it saves no memory (its residuals are live during its
        # backward pass either way) and would put a third copy of the step in the program.
        one_block = jax.checkpoint(one_block)

    def body(totals, start):
        return add_totals(totals, one_block(common_dyn, models_dyn, key, start), start), None

    starts = jnp.arange(num_blocks) * block
    totals, _ = jax.lax.scan(body, zero, starts)
    return totals


def _bounds_host(num_ok, nis_dof, n, confidence, num_steps):
    """χ² bounds exactly as :func:`~jaxtrack.montecarlo._result._summarize` computes them (host)."""
    num_ok = max(int(num_ok), 1)
    nees_b = np.asarray(chi2_mean_bounds(np.full(num_steps, n), num_ok, confidence), dtype=nis_dof.dtype)
    nis_b = np.asarray(chi2_mean_bounds(np.asarray(nis_dof), 1, confidence) / num_ok, dtype=nis_dof.dtype)
    return nees_b, nis_b


def _warn_failed(num_failed, num_total):
    if int(num_failed):
        warnings.warn(
            f"jaxtrack.differentiable_monte_carlo: {int(num_failed)} of {int(num_total)} runs produced a "
            "non-finite estimate and were left out of the statistics (and of the gradient).",
            RuntimeWarning, stacklevel=2)


def _summarize_traced(sums: _Sums, n, num_runs, confidence, shared, components, key,
                      estimator=None) -> MonteCarloResult:
    """:func:`~jaxtrack.montecarlo._result._summarize` for traced sums: the same formulas.

    The statistics divide by the (traced) count of finite runs, exactly as ``monte_carlo`` does.
    The χ² bounds (scipy quantiles: no gradient) come from a ``pure_callback`` on stopped
    gradients. The static fields ``num_runs``/``num_failed``/``precision_warning`` are exact when
    the call is not traced; under a trace they are ``num_runs`` requested, 0 and False, and a
    failed run is reported by a ``jax.debug.callback`` warning. ``estimator``: the static
    ``filter_name``/``filter_model_name``/``filter_model_source`` (strings: unaffected by a trace).
    """
    num_ok = sums.num_ok
    dtype = sums.nees.dtype
    T = sums.nees.shape[0]
    averages = _run_averages(sums, num_ok, n)
    anees = averages["anees"]
    shapes = (jax.ShapeDtypeStruct((T, 2), dtype), jax.ShapeDtypeStruct((T, 2), dtype))
    nees_b, nis_b = jax.pure_callback(
        lambda k, d: _bounds_host(k, d, n, confidence, T), shapes,
        jax.lax.stop_gradient(num_ok), jax.lax.stop_gradient(sums.nis_dof), vmap_method="sequential")
    concrete = is_concrete(num_ok) and is_concrete(sums.nees)
    if concrete:
        num_ok_int, num_failed = int(num_ok), int(sums.num_failed)
        _warn_failed(num_failed, num_ok_int + num_failed)
        if num_ok_int == 0:
            raise FloatingPointError("jaxtrack.differentiable_monte_carlo: every run produced a non-finite estimate.")
        suspect = _precision_suspect(dtype, anees, nees_b[0][1] / n, sums.nis / num_ok, nis_b[:, 1])
    else:
        num_ok_int, num_failed, suspect = num_runs, 0, False
        jax.debug.callback(_warn_failed, sums.num_failed, sums.num_failed + num_ok)
    return MonteCarloResult(
        **averages,
        nees_bounds=nees_b,
        nis_bounds=nis_b,
        anees_bounds=nees_b[0] / n,
        num_runs=num_ok_int,
        num_failed=num_failed,
        confidence=confidence,
        shared_covariance=shared,
        precision_warning=suspect,
        components=components,
        **_key_fields(key),
        **(estimator or {}),
    )


def differentiable_monte_carlo(
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
    confidence: float = 0.95,
    covariance: CovarianceMode = "auto",
    block_size: int | None = None,
    truth_components: Sequence[int] | None = None,
    filter_components: Sequence[int] | None = None,
) -> MonteCarloResult:
    r""":func:`~jaxtrack.montecarlo.monte_carlo` that ``jax.grad``, ``jax.jit`` and ``jax.vmap`` go through.

    The same statistics as ``monte_carlo`` for the same key and arguments (the same block
    function, draws and block order: equal to rounding, ~1e-15 relative), computed by a
    ``lax.scan`` over blocks of runs in one trace, each block under ``jax.checkpoint``. So
    ``truth`` and ``filter_model`` may be built from traced parameters inside the function being
    differentiated, e.g.::

        def loss(log_q):
            fm = constant_velocity(1.0, accel_psd=jnp.exp(log_q), measurement_std=10.0, initial_cov=P0)
            res = differentiable_monte_carlo(truth, key, 10_000, num_steps=200, filter_model=fm)
            return jnp.mean(jnp.sum(res.mse[:, :2], axis=-1))      # time-averaged position MSE

        g = jax.grad(loss)(0.0)

    **Common random numbers.** The key is fixed, so the objective ``J_M(θ)`` is a smooth
    deterministic function of θ (every draw is reparameterised, ``x_k = f(x_{k−1}) + chol(Q_k) ε_k``,
    ``z_k = h(x_k) + chol(R_k) η_k``, with ``ε, η`` fixed) and ``∇J_M`` is the pathwise
    (IPA) estimator of ``∇E[J]`` (Glasserman 2004, *Monte Carlo Methods in Financial
    Engineering*, §7.2, eq. (7.14)); finite differences of ``J_M`` with the same key converge to it.
    Not differentiable in ``detection_probability`` (discrete draws) and the set of finite runs
    is locally constant. Parameters of the *truth's* noise covariances (``Q``, ``R``, the prior)
    enter through their square-root factors (:func:`~jaxtrack.montecarlo.psd_sqrt`, the factor
    ``monte_carlo`` draws with, ``V √Λ`` from an eigendecomposition): where the eigenvalues are
    distinct this is smooth and finite differences with the same key converge to the gradient;
    where they repeat (``kron(Q₁, q·I₂)``, ``σ²I``) the computed eigenvector basis, and so each
    draw, may jump as the parameter moves, and the gradient holds that basis fixed
    (``psd_sqrt``'s custom JVP): still the pathwise estimator of ``∇E[J]`` (the law of the draws
    does not depend on the basis), but not the limit of same-key finite differences. The
    filter's model, and the truth's dynamics and measurement functions, have no such restriction.

    **Memory.** Reverse mode keeps the per-step sums at each block boundary (``O(B·T·n)`` for
    ``B`` blocks) and one block's per-step residuals, recomputing each block's forward pass once
    (checkpointing; Griewank & Walther 2008, ch. 12): its memory does not grow with the runs
    (10⁵ runs × 200 steps of a 4-state KF: ≈ 0.95 GB peak RSS of the whole process). Measured on
    CPU (``benchmarks/mc_gradient.py``, 2·10⁴ runs × 200 steps, gradient of the position MSE):
    the gradient costs 2.4 forward passes on the shared covariance path (KF) and 4.0-4.3 on the
    per-run path (EKF: the forward pass, each block's and each step's recomputation and the
    transpose; ``benchmarks/measured/mc_gradient_issue35.txt``). A statistic of the errors
    alone does not pay for the NEES/NIS (their tangents are dead code); one of the NEES or NIS
    does. Failed runs are found in the same pass (each run's per-step terms are summed once its
    ``ok`` is known), not by a second pass as in ``monte_carlo``. No ``mesh``: one device; no
    progress bar.

    **Arguments:** as :func:`~jaxtrack.montecarlo.monte_carlo` (``truth``, ``key``, ``num_runs``,
    ``num_steps``, ``filter``, ``filter_model``, ``mask``, ``detection_probability``,
    ``first_step``, ``confidence``, ``covariance``, ``truth_components``, ``filter_components``),
    plus ``block_size``: runs per block (default: ``monte_carlo``'s, 2,048 shared / 512 per-run
    covariance; the results do not depend on it beyond rounding; smaller blocks lower the peak
    memory of the gradient).

    **Returns:** a :class:`MonteCarloResult` whose arrays are traced (differentiable) under a
    transformation. Under a trace, ``num_runs`` is the requested count, ``num_failed`` 0 and
    ``precision_warning`` False (static fields cannot hold traced counts); runs that turn
    non-finite are still excluded and reported by a warning from the device.
    """
    key = as_key(key)
    prep = _prepare(truth, num_runs, num_steps, filter, filter_model, mask, first_step, 1000, covariance,
                    detection_probability, truth_components, filter_components)
    block = prep.block
    if block_size is not None:
        if isinstance(block_size, bool) or not isinstance(block_size, (int, np.integer)) or block_size < 1:
            raise InputError(f"`block_size` must be a positive int; got {block_size!r}.")
        block = block_size_for(num_runs, int(block_size))
    setup = (_shared_setup(prep.filter, prep.filter_model, truth, prep.observed, first_step, prep.components[1])
             if prep.shared else None)
    common = _Common(prep.filter, prep.observed, first_step, prep.detection, prep.run_mask, prep.components,
                     stacked=True)
    models = _Models(truth, prep.filter_model, setup)
    common_dyn, common_static = eqx.partition(common, eqx.is_array)
    models_dyn, models_static = eqx.partition(models, eqx.is_array)
    zero = _zero_sums(prep.num_steps, prep.num_scored, truth.initial_cov.dtype, num_modes=prep.num_modes)
    sums = _scan_blocks_jit(common_dyn, models_dyn, key, (common_static, models_static), num_runs, block,
                            math.ceil(num_runs / block), zero)
    return _summarize_traced(sums, prep.num_scored, num_runs, confidence, prep.shared, prep.components[1], key,
                             prep.estimator)


# Compiled once per (static structure, sizes); inside an outer trace the jit is inlined.
_scan_blocks_jit = eqx.filter_jit(_scan_blocks)

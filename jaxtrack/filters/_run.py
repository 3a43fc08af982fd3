"""``run_filter``: one filter run, checked, through the ``scan=`` strategy of its choice.

Above ``_base`` (the filter's base class, its result and the sequential scan) and ``_parallel``
(the strategies, which import ``_base``), so that neither of those imports the other back.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike

from .._validation import covariance_ok, is_concrete, throw_unless_ok
from ..models import AbstractStateSpaceModel
from ._base import AbstractFilter, FilterResult, FirstStep, Save, check_run_arguments, prepare_measurements
from ._parallel import AbstractTimeScan, AutoScan, Sequential, resolve_scan


@eqx.filter_jit
def _run_filter_jit(filter, model, measurements, observed, first_step, save, check_noise, scan=Sequential()):
    # `scan` is resolved (Sequential or ParallelInTime); Sequential's pass is `_scan_filter`.
    result = scan.filter_pass(filter, model, measurements, observed, first_step, save)
    # An indefinite or non-finite prior can run to a finite, meaningless result. The model's
    # constructor rejects it when the prior is concrete; under tracing (a prior built inside
    # jit/vmap/grad) only this check sees it. One (n, n) eigvalsh per run, outside the scan.
    # Semidefinite is accepted: a prior may know some components exactly (e.g. a consider
    # filter's known parameter), which the constructors cannot build but tree_at can.
    ok = covariance_ok(model.initial_cov, definite=False) & jnp.all(jnp.isfinite(model.initial_mean))
    if check_noise:
        # Traced noise covariances (e.g. built from a traced τ, where a negative τ makes Q
        # negative definite, or a non-symmetric R) were not seen by the constructor. One batched
        # eigvalsh over the stored Q and R, outside the scan; skipped for concrete models.
        ok = ok & _noise_ok(model)
    # `throw` is applied by the caller, outside this program (`throw_unless_ok`): no host callback
    # in it, so the persistent compilation cache keeps it.
    return eqx.tree_at(lambda r: r.ok, result, result.ok & ok)


_FILTER_FAILED = (
    "jaxtrack: the filter produced a non-finite mean, covariance or log-likelihood, or its "
    "model's prior (`initial_mean`, `initial_cov`) or noise covariances (`process_noise_cov`, "
    "`measurement_noise_cov`) are not valid covariances. Likely causes: (a) a measurement is "
    "NaN/inf (pass nan_as_missing=True to skip them); (b) R or the prior covariance is not "
    "symmetric positive definite, or Q not positive semidefinite (e.g. a negative sampling "
    "period), or a model parameter built under jit/vmap/grad is outside its range (a sampling "
    "period <= 0, a negative noise level: the constructors check concrete values and turn "
    "traced ones that fail into NaN); (c) units differ by many orders of magnitude (e.g. rad vs deg, m vs km); (d) the "
    "state diverged; (e) an extended or iterated Kalman filter linearised a sensor model where its "
    "Jacobian is undefined (NaN): the predicted mean on the sensor's position, e.g. a prior mean of 0 "
    "with the sensor at the origin - start the prior elsewhere or use the unscented filter. "
    "Pass throw=False to get the result with ok=False instead."
)


def _stored_noise(model):
    """The model's stored ``Q`` and ``R`` arrays (fields of the built-in models), if any."""
    Q, R = getattr(model, "Q", None), getattr(model, "R", None)
    return tuple(a if isinstance(a, jax.Array) else None for a in (Q, R))


def _noise_ok(model) -> Array:
    Q, R = _stored_noise(model)
    ok = jnp.ones((), bool)
    if Q is not None:
        ok = ok & covariance_ok(Q, definite=False)
    if R is not None:
        ok = ok & covariance_ok(R)
    return ok


def _model_is_traced(model) -> bool:
    """Whether any array of ``model`` is a tracer (built or passed inside jit/vmap/grad)."""
    return not all(is_concrete(leaf) for leaf in jax.tree_util.tree_leaves(model))


def run_filter(
    filter: AbstractFilter,
    model: AbstractStateSpaceModel,
    measurements: ArrayLike,
    *,
    mask: ArrayLike | None = None,
    first_step: FirstStep = "update",
    save: Save = "all",
    nan_as_missing: bool = False,
    throw: bool = True,
    scan: AbstractTimeScan = AutoScan(),
) -> FilterResult:
    """Run ``filter`` on ``model`` over ``measurements``: one jitted ``lax.scan`` (or associative scan).

    **Arguments:**

    - ``filter``: a filter strategy, e.g. ``KalmanFilter()``, ``ExtendedKalmanFilter()``,
      ``UnscentedKalmanFilter()``.
    - ``model``: an :class:`~jaxtrack.models.AbstractStateSpaceModel`; it holds the prior.
    - ``measurements``: shape ``(T, m)`` (or ``(T,)`` when ``m = 1``), in the model's units.
    - ``mask``: optional boolean, ``(T,)`` for whole steps or ``(T, m)`` per component; True means
      observed. Missing components are removed from the update and from the log-likelihood.
    - ``first_step``: ``"update"`` (default) — the model's prior is on the state at the first
      measurement, so step 0 is an update only (Ho 1968, dynamax); ``"predict"`` — the prior is one
      transition before the first measurement (FilterPy's ``predict(); update(z)``).
    - ``save``: ``"all"`` keeps per-step histories; ``"final"`` keeps only the log-likelihood and
      the final state (memory independent of ``T``); ``"mean"`` keeps the filtered means
      ``(T, n)`` besides those (the other histories are ``None``).
    - ``nan_as_missing``: treat NaN measurements as missing. Off by default: a NaN where the mask
      says observed raises ``InputError`` (or, under tracing, makes ``ok`` False).
    - ``throw``: raise at run time if the result is non-finite or the model's prior (and, for a
      model built under ``jit``/``vmap``/``grad``, its ``Q`` and ``R``) is not a valid
      covariance. Use ``throw=False`` inside ``vmap`` and read ``result.ok`` per run.
    - ``scan``: how time is traversed, a :class:`~jaxtrack.filters.AbstractTimeScan`:
      :class:`~jaxtrack.filters.Sequential` (one ``lax.scan``, any filter),
      :class:`~jaxtrack.filters.ParallelInTime` (an associative scan, ``O(log T)`` deep; the
      ``KalmanFilter`` on a linear model) or :class:`~jaxtrack.filters.AutoScan` (default:
      sequential on CPU, parallel on an accelerator for long runs). The result is the same.

    **Returns:** a :class:`FilterResult`.

    **Raises:** ``InputError`` for wrong shapes, a mask that is not boolean, non-finite
    measurements, a model the filter cannot handle, or a ``scan`` that does not apply.

    Example::

        model = jaxtrack.models.constant_velocity(0.1, dim=2, accel_psd=1.0,
                                                  measurement_std=5.0, initial_cov=100 * jnp.eye(4))
        result = run_filter(KalmanFilter(), model, zs)
        result.filtered_mean.shape  # (T, 4)
    """
    check_run_arguments(filter, model, first_step, save)
    z, observed = prepare_measurements(model, measurements, mask, nan_as_missing)
    scan = resolve_scan(scan, filter, model, z.shape[0])
    result = _run_filter_jit(filter, model, z, observed, first_step, save, _model_is_traced(model), scan)
    return throw_unless_ok(result, result.ok, _FILTER_FAILED) if throw else result

"""What a Monte Carlo run returns: the streamed per-step sums and their summary statistics.

:class:`_Sums` is what every block of runs adds to (per-step sums over runs, nothing per run);
:func:`_summarize` turns the totals into a :class:`MonteCarloResult` with χ² bounds
(:func:`~jaxtrack.montecarlo.chi2_mean_bounds`); :func:`summarize_runs` does the same from
statistics kept per run.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, UInt32

from .._export import Exportable
from .._validation import InputError
from ..filters import InteractingMultipleModel
from ..models import TrackingModel
from ._metrics import chi2_mean_bounds


class _StepSums(NamedTuple):
    """One step's sums over the runs of a block (an entry of the scan's per-step output)."""

    error: Array  # (n,)
    squared_error: Array  # (n,)
    nees: Array  # ()
    nees_sq: Array  # ()
    nis: Array  # ()
    mode_probs: Array  # (K,): an IMM's mode probabilities (K = 0 for one filter)


def _masked_sums(use, error, nees, nis, axis, modes=None):
    """Sums over the runs (``axis`` of ``error``) where ``use``.

    Each group of terms (errors and their squares; NEES, NEES², NIS; mode probabilities) is
    stacked and summed by one product with the 0/1 weights (one kernel per group instead of a
    reduction per term). The groups are kept apart so that under ``jax.grad`` of a statistic
    of one group (an MSE) the others' tangents are dead code that JAX removes: in one product
    the NEES/NIS tangents (through every run's Cholesky factors, each step) would be live and
    transposed with zero cotangents (EKF Monte Carlo gradient of the MSE, 4,096 × 100: 2.05 →
    0.87 s, 8.2 → 4.6 forward passes, compile 14 → 6 s). Excluded runs are zeroed first, not
    only weighted, because an excluded run may hold NaN and NaN·0 is NaN. ``modes``:
    ``(block, K)`` mode probabilities, or None. ``use`` None: the terms themselves,
    ``(error, nees, nis, modes)``, for the caller to sum (``_Common.stacked``).
    """
    if use is None:
        return error, nees, nis, modes
    n = error.shape[0 if axis == -1 else 1]
    if axis == 0:
        error = error.T
    weights = use.astype(error.dtype)

    def total(terms):
        return jnp.where(use[None, :], terms, 0.0) @ weights

    errors = total(jnp.concatenate([error, error * error]))
    scores = total(jnp.stack([nees, nees * nees, nis]))
    K = 0 if modes is None else modes.shape[-1]
    probs = total(modes.T) if K else jnp.zeros((0,), error.dtype)
    return _StepSums(errors[:n], errors[n:], scores[0], scores[1], scores[2], probs)


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
    mode_probs: Array  # (T, K): Σ mode probabilities (an IMM's K modes; K = 0 for one filter)


class MonteCarloResult(Exportable, eqx.Module):
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
    - ``mode_probs`` ``(T, K)``: for an :class:`~jaxtrack.filters.InteractingMultipleModel`
      filter, its ``K`` mode probabilities ``μ_j(k)`` averaged over runs; None for one filter.
    - ``components``: the filter state components scored (``filter_components`` of
      :func:`monte_carlo`), in the order of ``mse``'s columns; None when the whole state is.

    - ``key`` ``(k,)`` uint32: the raw words of the PRNG key the study was run with
      (``jax.random.key_data``), and ``key_impl``: its implementation's name (e.g.
      ``"threefry2x32"``); ``jax.random.wrap_key_data(result.key, impl=result.key_impl)`` gives
      the key back, so a saved result says how to rerun it. None when not set by the caller.
    - ``filter_name``: the estimator's class name (``"KalmanFilter"``, ``"ExtendedKalmanFilter"``…);
      for an IMM its members' too, ``"InteractingMultipleModel(KalmanFilter, ExtendedKalmanFilter)"``.
    - ``filter_model_name``: the class name of the model the filter ran, with a
      :class:`~jaxtrack.models.TrackingModel`'s transition and measurement classes
      (``"TrackingModel(CoordinatedTurn, RangeBearing)"``, ``"LinearGaussianModel"``); for an IMM
      its members' models, comma-separated, in member order.
    - ``filter_model_source``: where that model came from: ``"truth"`` (no ``filter_model`` was
      given, so the filter ran the truth's own model: a matched, best-case filter that knows
      every parameter of the truth, a known turn schedule included), ``"given"`` (the
      ``filter_model`` passed) or ``"imm"`` (the IMM's own member models).
      These three are None in a result saved before they were recorded (its file still loads).

    **Export** (:mod:`jaxtrack._export`): :meth:`to_dict` (NumPy arrays or JSON-ready lists),
    :meth:`save` to one ``.npz`` and :meth:`load` back, bit for bit (both carry
    ``format_version`` 1), :meth:`to_xarray` (dims ``time``, ``component``, ``bound``, ``mode``)
    and :meth:`to_pandas` (one row per step) with the optional ``export`` extra.
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
    mode_probs: Float[Array, "T K"] | None = None
    components: tuple[int, ...] | None = eqx.field(static=True, default=None)
    key: UInt32[Array, " k"] | None = None
    key_impl: str | None = eqx.field(static=True, default=None)
    # Static strings, not leaves: they name the estimator, and being part of the tree structure
    # they pass through jit, vmap and grad (differentiable_monte_carlo) untouched.
    filter_name: str | None = eqx.field(static=True, default=None)
    filter_model_name: str | None = eqx.field(static=True, default=None)
    filter_model_source: str | None = eqx.field(static=True, default=None)

    _export_kind = "jaxtrack.MonteCarloResult"
    _export_dims = {
        "mse": ("time", "component"), "mean_error": ("time", "component"), "nees": ("time",),
        "nees_std": ("time",), "nees_bounds": ("time", "bound"), "nis": ("time",), "nis_dof": ("time",),
        "nis_bounds": ("time", "bound"), "anees": (), "anees_bounds": ("bound",),
        "mode_probs": ("time", "mode"), "key": ("key_word",),
    }
    _export_units = {
        "mse": "state units squared", "mean_error": "state units", "nees": "1 (chi-square, n dof)",
        "nees_std": "1", "nees_bounds": "1", "nis": "1 (chi-square, nis_dof dof)", "nis_dof": "components",
        "nis_bounds": "1", "anees": "1 (per state component)", "anees_bounds": "1", "mode_probs": "probability",
        "key": "raw PRNG key words (uint32)",
    }

    def rmse(self, components: tuple[int, ...] | None = None) -> Float[Array, " T"]:
        """Root of the summed mean squared error over ``components`` (all states if None).

        For a 2-D constant-velocity state ``[x, y, vx, vy]``, ``rmse((0, 1))`` is the position RMSE.
        ``components`` index the columns of ``mse`` (the scored components, in their order).
        """
        mse = self.mse if components is None else self.mse[:, jnp.asarray(components)]
        return jnp.sqrt(jnp.sum(mse, axis=-1))

    def fraction_nees_inside(self) -> Float[Array, ""]:
        """Fraction of steps whose run-averaged NEES lies within its bounds (≈ confidence)."""
        inside = (self.nees >= self.nees_bounds[:, 0]) & (self.nees <= self.nees_bounds[:, 1])
        return jnp.mean(inside)

    def summary(self) -> str:
        """A short plain-text report of the study: runs, consistency, accuracy and the estimator.

        One line each: the runs (and how many failed), the ANEES against its bounds, the RMSE at
        the last step over all scored components (and the final mean mode probabilities of an
        IMM), and which filter ran on which model. When the filter ran the truth's own model
        (``filter_model_source == "truth"``) that line says so: such a filter is matched, a
        best case, and ``filter_model=`` gives the mismatched study.

        For a result with concrete arrays (not one traced inside ``jax.grad``/``jax.jit`` or a
        ``vmap``-ed batch of results). **Returns:** the text, lines separated by ``"\\n"``.
        """
        num_steps, n = self.mse.shape[-2], self.mse.shape[-1]
        anees, (lo, hi) = float(self.anees), (float(b) for b in self.anees_bounds)
        if lo <= anees <= hi:
            verdict = "inside (consistent)"
        elif anees > hi:
            verdict = "ABOVE the upper bound (the filter's covariance is too small: optimistic)"
        else:
            verdict = "below the lower bound (the filter's covariance is too large: pessimistic)"
        scored = "the whole state" if self.components is None else f"components {list(self.components)}"
        lines = [
            f"Monte Carlo: {self.num_runs} runs ({self.num_failed} failed, left out), {num_steps} steps, "
            f"{n} scored components ({scored}).",
            f"ANEES {anees:.4g}, {self.confidence:.0%} bounds [{lo:.4g}, {hi:.4g}]: {verdict}.",
            f"Final-step RMSE over the {n} scored components: {float(self.rmse()[-1]):.4g} (state units).",
        ]
        if self.mode_probs is not None:
            probs = ", ".join(f"{float(p):.3f}" for p in self.mode_probs[-1])
            lines.append(f"Final mean mode probabilities: {probs}.")
        if self.precision_warning:
            lines.append("Precision warning: statistics in float32 far outside their bounds; rerun in float64.")
        lines.append(self._estimator_line())
        return "\n".join(lines)

    def _estimator_line(self) -> str:
        """The summary's line naming the filter and the model it ran, and what that means."""
        filt, model = self.filter_name or "an unrecorded filter", self.filter_model_name or "an unrecorded model"
        if self.filter_model_source == "truth":
            # Issue 37: a default filter model is the truth itself, so the filter knows what a real
            # one cannot (a turn schedule, the exact noise): say so where the numbers are read.
            return (f"Estimator: {filt} on {model}, the truth's own model (no filter_model given): a matched, "
                    "best-case filter that knows every parameter of the truth, including any known turn "
                    "schedule; pass filter_model= for a mismatched study.")
        if self.filter_model_source == "given":
            return (f"Estimator: {filt} on {model}, the filter_model given (its own assumptions, which may "
                    "differ from the truth).")
        if self.filter_model_source == "imm":
            return f"Estimator: {filt} on its members' own models: {model}."
        return "Estimator: not recorded (a result saved before jaxtrack recorded the filter and its model)."


def _zero_sums(num_steps, n, dtype, lead=(), num_modes=0):
    z = lambda *shape: jnp.zeros(lead + shape, dtype)  # noqa: E731
    return _Sums(z(num_steps, n), z(num_steps, n), z(num_steps), z(num_steps), z(num_steps), z(), z(), z(num_steps),
                 z(num_steps, num_modes))




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


def _run_averages(sums: _Sums, num_ok, n) -> dict:
    """The per-step run averages of a :class:`MonteCarloResult` from the summed statistics over
    ``num_ok`` finite runs (a Python int, or a traced count in
    :func:`~jaxtrack.montecarlo.differentiable_monte_carlo`): one set of formulas for both."""
    mean_nees = sums.nees / num_ok
    nees_var = jnp.maximum(sums.nees_sq / num_ok - mean_nees**2, 0.0)
    return dict(
        mse=sums.squared_error / num_ok,
        mean_error=sums.error / num_ok,
        nees=mean_nees,
        # n − 1 denominator of the empirical spread (1 for a single run)
        nees_std=jnp.sqrt(nees_var * num_ok / jnp.maximum(num_ok - 1, 1)),
        nis=sums.nis / num_ok,
        nis_dof=sums.nis_dof / num_ok,
        anees=jnp.mean(mean_nees) / n,
        mode_probs=sums.mode_probs / num_ok if sums.mode_probs.shape[-1] else None,
    )


def _summarize(sums: _Sums, n, confidence, shared=False, components=None, key=None, key_impl=None,
               filter_name=None, filter_model_name=None, filter_model_source=None) -> MonteCarloResult:
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
        raise FloatingPointError(
            "jaxtrack.monte_carlo: every run produced a non-finite estimate. Common causes: an "
            "extended or iterated Kalman filter whose prior mean sits on a sensor's position (its "
            "Jacobian is undefined there; start the prior elsewhere or use the unscented filter), "
            "or noise covariances that are not positive definite. run_filter on one run with "
            "throw=True names the failing check."
        )
    averages = _run_averages(sums, num_ok, n)
    mean_nees, anees = averages["nees"], averages["anees"]
    # Run i's NIS at step k is χ²(d_ik) (its observed components); the runs are independent, so
    # the sum over runs is χ²(D_k), D_k = Σ_i d_ik, and the run average lies in
    # [χ²_{D_k}⁻¹(α/2), χ²_{D_k}⁻¹(1 − α/2)] / M: chi2_mean_bounds of D_k for one "run", over M.
    # With one schedule for all runs D_k = M·d_k and this is chi2_mean_bounds(d_k, M) exactly.
    nees_b = chi2_mean_bounds(np.full(mean_nees.shape, n), num_ok, confidence)
    nis_b = chi2_mean_bounds(np.asarray(sums.nis_dof), 1, confidence) / num_ok
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
        **averages,
        nees_bounds=jnp.asarray(nees_b),
        nis_bounds=jnp.asarray(nis_b),
        anees_bounds=jnp.asarray(nees_b[0] / n),
        num_runs=num_ok,
        num_failed=num_failed,
        confidence=confidence,
        shared_covariance=shared,
        precision_warning=suspect,
        components=components,
        key=key,
        key_impl=key_impl,
        filter_name=filter_name,
        filter_model_name=filter_model_name,
        filter_model_source=filter_model_source,
    )


def summarize_runs(
    error: ArrayLike,
    nees: ArrayLike,
    *,
    nis: ArrayLike | None = None,
    nis_dof: ArrayLike | None = None,
    mode_probs: ArrayLike | None = None,
    ok: ArrayLike | None = None,
    confidence: float = 0.95,
    components: Sequence[int] | None = None,
    key=None,
    filter=None,
    filter_model=None,
) -> MonteCarloResult:
    """The :class:`MonteCarloResult` of per-run statistics kept whole, as :func:`monte_carlo` makes it.

    For a Monte Carlo that :func:`monte_carlo` cannot run in one go (an estimator beside the
    filter that needs the whole run, such as a smoother, in the same pass of
    :func:`~jaxtrack.montecarlo.monte_carlo_map`): return each run's error, NEES, NIS (and an
    IMM's mode probabilities) from the run function with ``reduce="stack"``, and summarise them
    here with the same formulas and χ² bounds (:func:`_summarize`), so one pass gives both the
    per-run errors (paired intervals) and the streamed statistics.

    **Arguments** (``M`` runs, ``T`` steps, ``n`` scored components):

    - ``error`` ``(M, T, n)``: ``x − x̂_{k/k}`` on the scored components; ``nees`` ``(M, T)``.
    - ``nis`` ``(M, T)`` and ``nis_dof`` ``(M, T)`` (each run's observed components per step), or
      None for none scored (an IMM: 0 with 0 degrees of freedom).
    - ``mode_probs`` ``(M, T, K)`` or None; ``ok`` ``(M,)`` bool (None: all): runs with False, or
      with a non-finite value, are left out and counted in ``num_failed``, as in :func:`monte_carlo`.
    - ``confidence``; ``components`` (the filter indices ``error`` holds); ``key`` (the study's
      PRNG key, recorded); ``filter``, ``filter_model``: the estimator and its model, recorded by
      name (``filter_model`` None: the IMM's own, or not recorded).

    **Returns:** a :class:`MonteCarloResult` (``shared_covariance`` False).
    """
    error = jnp.asarray(error)
    nees = jnp.asarray(nees, error.dtype)
    if error.ndim != 3 or nees.shape != error.shape[:2]:
        raise InputError(f"`error` must be (M, T, n) and `nees` (M, T); got {error.shape} and {nees.shape}.")
    M, T, n = error.shape
    zeros = jnp.zeros((M, T), error.dtype)
    nis = zeros if nis is None else jnp.asarray(nis, error.dtype)
    nis_dof = zeros if nis_dof is None else jnp.asarray(nis_dof, error.dtype)
    for name, value in (("nis", nis), ("nis_dof", nis_dof)):
        if value.shape != (M, T):
            raise InputError(f"`{name}` must be (M, T) = {(M, T)}; got {value.shape}.")
    modes = jnp.zeros((M, T, 0), error.dtype) if mode_probs is None else jnp.asarray(mode_probs, error.dtype)
    if modes.shape[:2] != (M, T) or modes.ndim != 3:
        raise InputError(f"`mode_probs` must be (M, T, K); got {modes.shape}.")
    use = jnp.ones((M,), bool) if ok is None else jnp.asarray(ok, bool).reshape(M)
    use = use & jnp.all(jnp.isfinite(error), axis=(1, 2)) & jnp.all(jnp.isfinite(nees), axis=1) \
        & jnp.all(jnp.isfinite(nis), axis=1)
    # Excluded runs are zeroed, not weighted: NaN·0 is NaN.
    w = lambda x: jnp.sum(jnp.where(use.reshape((M,) + (1,) * (x.ndim - 1)), x, 0.0), axis=0)  # noqa: E731
    sums = _Sums(w(error), w(error * error), w(nees), w(nees * nees), w(nis), jnp.sum(use).astype(error.dtype),
                 jnp.sum(~use).astype(error.dtype), w(nis_dof), w(modes))
    if filter is not None and filter_model is None and not isinstance(filter, InteractingMultipleModel):
        raise InputError("`filter_model` is needed with `filter` (the model the filter ran), except for an IMM.")
    fields = {} if filter is None else _estimator_fields(filter, filter_model, filter_model is not None)
    keys = {} if key is None else _key_fields(key)
    return _summarize(sums, n, confidence, False, None if components is None else tuple(components), **keys,
                      **fields)


def _key_fields(key) -> dict:
    """``key`` and ``key_impl`` of a :class:`MonteCarloResult` for the study's PRNG key: a typed
    key (``jax.random.key``) or a raw uint32 one (``jax.random.PRNGKey``)."""
    import jax

    if jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key):
        return {"key": jax.random.key_data(key), "key_impl": str(jax.random.key_impl(key))}
    return {"key": jnp.asarray(key), "key_impl": str(jax.config.jax_default_prng_impl)}


def _model_name(model) -> str:
    """A model's class name; a TrackingModel's with its transition and measurement classes, which
    say what the filter assumed (``TrackingModel(CoordinatedTurn, RangeBearing)``: a known turn)."""
    name = type(model).__name__
    if isinstance(model, TrackingModel):
        name += f"({type(model.transition_model).__name__}, {type(model.measurement_model).__name__})"
    return name


def _estimator_fields(filter, filter_model, given: bool) -> dict:
    """The estimator fields of a :class:`MonteCarloResult`, from the resolved ``filter`` (the
    default KalmanFilter filled in) and ``filter_model`` (the truth when none was given; None for
    an IMM). ``given``: whether the caller passed a ``filter_model``: when not, the filter ran the
    truth's own model, which the result must say (issue 37)."""
    if isinstance(filter, InteractingMultipleModel):
        members = ", ".join(type(f).__name__ for f in filter.filters)
        return {"filter_name": f"{type(filter).__name__}({members})",
                "filter_model_name": ", ".join(_model_name(m) for m in filter.models),
                "filter_model_source": "imm"}
    return {"filter_name": type(filter).__name__, "filter_model_name": _model_name(filter_model),
            "filter_model_source": "given" if given else "truth"}

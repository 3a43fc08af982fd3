"""The filter family's base class, its result type and the one scan that drives every filter.

A filter is a strategy object (``KalmanFilter()``, ``ExtendedKalmanFilter()``,
``UnscentedKalmanFilter()``) with one ``predict`` and one ``update``, composed into one public
step (:meth:`AbstractFilter.step` on a :class:`FilterState`). :func:`run_filter` (``_run``) is
one ``lax.scan`` of that step (``_scan_filter``, here). The same step function is what
:mod:`jaxtrack.montecarlo` runs inside ``vmap``, so a Monte Carlo run and a single run execute
exactly the same arithmetic.

Layering: this module imports neither ``_parallel`` (the ``scan=`` strategies, which import
this one) nor ``_run`` (:func:`run_filter`, above both), nor any layer above the filters.
"""

from __future__ import annotations

import abc
from typing import ClassVar, Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._export import Exportable
from .._validation import InputError, check_shape, is_concrete
from ..models import AbstractStateSpaceModel
from ._linalg import all_rows, marginal_cov, normalized_squared_error
from ._updates import (  # noqa: F401  (re-exported: the update functions' historical home)
    AbstractUpdateForm,
    Conditioned,
    JosephForm,
    StandardForm,
    condition_linearized,
    condition_on_moments,
    gaussian_log_likelihood,
    masked_noise,
    symmetrize,
)

FirstStep = Literal["update", "predict"]
Save = Literal["all", "final", "mean"]


class FilterState(eqx.Module):
    """The state a filter carries from one measurement to the next (one trajectory).

    **Fields:** ``mean`` ``(n,)`` and ``cov`` ``(n, n)``: the filtered ``x̂_{k/k}``, ``P_{k/k}``
    (before the first step: the prior); ``log_likelihood`` ``()``: the sum of the innovation
    log-densities so far; ``step`` ``()`` int: the index ``k`` of the next measurement;
    ``ok`` ``()`` bool: False once a mean, covariance or the log-likelihood became non-finite.

    A square-root filter (``AbstractFilter.square_root`` True) carries the lower Cholesky factor
    ``L`` (``P = L Lᵀ``) in ``cov`` instead of ``P``; so do its :class:`StepOutput` and
    :class:`Conditioned` (``cov``, ``predicted_cov``, and the factor of ``S`` in
    ``innovation_cov``).

    Made by :meth:`AbstractFilter.init`, advanced by :meth:`AbstractFilter.step`; it is a pytree,
    so it can be carried by ``lax.scan``, batched by ``vmap`` and saved between calls.
    """

    mean: Float[Array, " n"]
    cov: Float[Array, "n n"]
    log_likelihood: Float[Array, ""]
    step: Int[Array, ""]
    ok: Bool[Array, ""]


class StepOutput(NamedTuple):
    """What one :meth:`AbstractFilter.step` produces besides the new state.

    ``predicted_mean`` ``(n,)``, ``predicted_cov`` ``(n, n)``: ``x̂_{k/k-1}``, ``P_{k/k-1}`` (the
    prior at ``k = 0`` with ``first_step="update"``); ``conditioned``: the update's
    :class:`Conditioned` (filtered moments, innovation, its covariance, the gain, the step's
    log-likelihood).
    """

    predicted_mean: Float[Array, " n"]
    predicted_cov: Float[Array, "n n"]
    conditioned: Conditioned


class AbstractFilter(eqx.Module):
    """A Gaussian filter: one :meth:`predict` and one :meth:`update`, composed by :meth:`step`.

    Concrete filters are final classes; wrap, don't subclass. Every method acts on ONE trajectory
    (no batch axis); batches come from ``jax.vmap``. :func:`run_filter` is one ``lax.scan`` of
    :meth:`step`, and :mod:`jaxtrack.montecarlo` runs the same :meth:`step` inside ``vmap``.

    Manual stepping (a real-time loop: one measurement at a time, as it arrives)::

        kf = KalmanFilter()
        state = kf.init(model)
        step = jax.jit(kf.step)                    # compiled once
        for z in sensor:                           # z: (m,), NaN-free; mask with `observed`
            state, out = step(model, state, z)
            print(state.mean, out.conditioned.innovation)

    ``step`` reads the measurement index from ``state.step`` (per-step model arrays are indexed
    by it) and returns the same filtered moments as :func:`run_filter` to the last bit.

    ``square_root`` (class-level flag): True for filters whose states carry Cholesky factors
    instead of covariances (:class:`~jaxtrack.filters.SquareRootKalmanFilter`,
    :class:`~jaxtrack.filters.SquareRootUnscentedKalmanFilter`); :func:`run_filter` then squares
    them once at the end and also returns the factors.

    ``needs_key`` (class-level flag): True for filters that draw random numbers (the
    :class:`~jaxtrack.filters.ParticleFilter`): their ``init(model, key=...)`` takes a PRNG key, and
    batches and Monte Carlo runs give every run its own (:mod:`jaxtrack.montecarlo`: from the run's key).

    ``batch_block`` (class-level): runs per ``vmap``-ed block in
    :func:`~jaxtrack.filters.run_filter_batch` when every run carries its own covariance (None: the
    batch's default, 4,096 on 2 CPUs, see ``filters._batch.per_run_block``); a filter whose step
    keeps much larger buffers per run may set a smaller one.
    """

    square_root: ClassVar[bool] = False
    needs_key: ClassVar[bool] = False
    # Runs per vmapped block of run_filter_batch's per-run path; None: the batch's default.
    batch_block: ClassVar[int | None] = None

    @abc.abstractmethod
    def predict(
        self, model: AbstractStateSpaceModel, mean: Array, cov: Array, k: Array
    ) -> tuple[Array, Array]:
        """Propagate ``N(mean, cov)`` at step ``k−1`` to step ``k``: returns ``(mean, cov)``."""

    @abc.abstractmethod
    def update(
        self,
        model: AbstractStateSpaceModel,
        mean: Array,
        cov: Array,
        z: Array,
        observed: Array,
        k: Array,
    ) -> Conditioned:
        """Condition the prediction at step ``k`` on ``z`` (components where ``observed``)."""

    def check_model(self, model: AbstractStateSpaceModel) -> None:
        """Raise ``InputError`` if this filter cannot run on ``model`` (trace-time check)."""

    def covariance_is_data_free(self, model: AbstractStateSpaceModel) -> bool:
        """Whether this filter's covariances and gains on ``model`` do not depend on the data.

        When True (the Kalman filter on a linear model), batches of runs that share a
        measurement schedule can compute the covariances once for all runs
        (:class:`~jaxtrack.filters.SharedCovariance`); the filter then also provides
        ``mean_map``. The default is False: every run carries its own covariance.
        """
        return False

    def consistency(
        self, conditioned: Conditioned, error: Array, components: tuple[int, ...] | None = None
    ) -> tuple[Array, Array]:
        """NEES and NIS of one step: ``eᵀ P⁻¹ e`` for the estimation error ``e`` and ``yᵀ S⁻¹ y``.

        The hook :mod:`jaxtrack.montecarlo` scores every run with, so that a filter carrying its
        covariances in another form (a square-root filter's Cholesky factors) is scored from that
        form without squaring it.

        **Arguments:**

        - ``conditioned``: the step's :class:`Conditioned` (filtered covariance, innovation and
          its covariance, missing components decoupled).
        - ``error``: ``x − x̂_{k/k}`` in the state's units: ``(n,)``, or ``(len(components),)``.
        - ``components``: None (the whole state), or the state indices ``error`` holds; the NEES
          is then that of the marginal ``P[c, c]`` (the sub-state's own χ²(len(c)) statistic).

        **Returns:** ``(nees, nis)``, two dimensionless scalars.
        """
        return (
            normalized_squared_error(error, marginal_cov(conditioned.cov, components)),
            normalized_squared_error(conditioned.innovation, conditioned.innovation_cov),
        )

    def init(self, model: AbstractStateSpaceModel) -> FilterState:
        """The state before the first measurement: the model's prior, log-likelihood 0, step 0."""
        dtype = model.initial_cov.dtype
        return FilterState(
            model.initial_mean,
            model.initial_cov,
            jnp.zeros((), dtype),
            jnp.zeros((), jnp.int32),
            jnp.ones((), bool),
        )

    def step(
        self,
        model: AbstractStateSpaceModel,
        state: FilterState,
        z: ArrayLike,
        observed: ArrayLike | None = None,
        *,
        first_step: FirstStep = "update",
    ) -> tuple[FilterState, StepOutput]:
        """One predict + update: the single step function every filter run executes.

        **Arguments:**

        - ``model``: the state-space model; ``state``: the :class:`FilterState` after
          measurement ``k − 1`` (``k = state.step``; from :meth:`init` before the first).
        - ``z``: measurement ``k``, ``(m,)``, in the model's units.
        - ``observed``: optional boolean ``(m,)``, True where ``z`` is observed (default: all).
          Missing components of ``z`` are ignored (they may hold NaN).
        - ``first_step``: where the prior sits, as in :func:`run_filter`: with ``"update"`` step 0
          does not predict.

        **Returns:** ``(new_state, StepOutput)``.
        """
        k = state.step
        z = jnp.asarray(z, state.mean.dtype)
        observed = jnp.ones(z.shape, bool) if observed is None else jnp.asarray(observed)
        z = jnp.where(observed, z, 0.0)
        pred_mean, pred_cov = self.predict(model, state.mean, state.cov, k)
        if first_step == "update":
            # The prior already sits at the first measurement: no transition into step 0.
            at_start = k == 0
            pred_mean = jnp.where(at_start, state.mean, pred_mean)
            pred_cov = jnp.where(at_start, state.cov, pred_cov)
        post = self.update(model, pred_mean, pred_cov, z, observed, k)
        ll = state.log_likelihood + post.log_likelihood
        # `all_rows` (ands) rather than jnp.all (a reduction, a kernel of its own per step under vmap).
        finite = (all_rows(jnp.isfinite(post.mean)) & all_rows(all_rows(jnp.isfinite(post.cov)))
                  & jnp.isfinite(ll))
        new_state = FilterState(post.mean, post.cov, ll, k + 1, state.ok & finite)
        return new_state, StepOutput(pred_mean, pred_cov, post)


class FilterResult(Exportable, eqx.Module):
    """Output of :func:`run_filter` for one trajectory of ``T`` steps.

    With ``save="final"`` the per-step histories are ``None`` and only the final state, the
    log-likelihood and the status are kept (memory independent of ``T``); with ``save="mean"``
    ``filtered_mean`` is kept as well.

    **Fields** (``n`` states, ``m`` measurement components):

    - ``filtered_mean`` ``(T, n)``, ``filtered_cov`` ``(T, n, n)``: ``x̂_{k/k}``, ``P_{k/k}``.
    - ``predicted_mean`` ``(T, n)``, ``predicted_cov`` ``(T, n, n)``: ``x̂_{k/k-1}``,
      ``P_{k/k-1}`` (at ``k = 0`` with ``first_step="update"``: the prior).
    - ``innovation`` ``(T, m)``: ``z_k − ẑ_{k/k-1}``, 0 in missing components.
    - ``innovation_cov`` ``(T, m, m)``: ``S_k``; identity rows/columns in missing components.
    - ``num_observed`` ``(T,)``: measurement components used at each step (NIS degrees of freedom).
    - ``log_likelihood`` ``()``: ``Σ_k log N(innovation_k; 0, S_k)`` over observed components.
    - ``final_mean`` ``(n,)``, ``final_cov`` ``(n, n)``: the last filtered state.
    - ``ok`` ``()`` bool: False if any mean, covariance or the log-likelihood became non-finite,
      or (:func:`run_filter`) the prior is not finite and positive definite.
    - Square-root filters only (``None`` otherwise): ``filtered_cov_factor`` ``(T, n, n)``,
      ``predicted_cov_factor`` ``(T, n, n)``, ``innovation_cov_factor`` ``(T, m, m)``,
      ``final_cov_factor`` ``(n, n)``: the lower Cholesky factors the filter propagated, of which
      the covariance fields above are the products ``L Lᵀ`` (formed once, after the scan).

    **Export** (:mod:`jaxtrack._export`): ``to_dict()``, ``save(path)`` / ``FilterResult.load(path)``
    (one ``.npz``, bit for bit), ``to_xarray()`` and ``to_pandas()`` (one row per step) with the
    optional ``export`` extra.
    """

    filtered_mean: Float[Array, "T n"] | None
    filtered_cov: Float[Array, "T n n"] | None
    predicted_mean: Float[Array, "T n"] | None
    predicted_cov: Float[Array, "T n n"] | None
    innovation: Float[Array, "T m"] | None
    innovation_cov: Float[Array, "T m m"] | None
    num_observed: Float[Array, " T"] | None
    log_likelihood: Float[Array, ""]
    final_mean: Float[Array, " n"]
    final_cov: Float[Array, "n n"]
    ok: Bool[Array, ""]
    filtered_cov_factor: Float[Array, "T n n"] | None = None
    predicted_cov_factor: Float[Array, "T n n"] | None = None
    innovation_cov_factor: Float[Array, "T m m"] | None = None
    final_cov_factor: Float[Array, "n n"] | None = None

    _export_kind = "jaxtrack.FilterResult"
    _export_dims = {
        "filtered_mean": ("time", "state"), "filtered_cov": ("time", "state", "state_col"),
        "predicted_mean": ("time", "state"), "predicted_cov": ("time", "state", "state_col"),
        "innovation": ("time", "measurement"), "innovation_cov": ("time", "measurement", "measurement_col"),
        "num_observed": ("time",), "log_likelihood": (), "final_mean": ("state",),
        "final_cov": ("state", "state_col"), "ok": (),
        "filtered_cov_factor": ("time", "state", "state_col"), "predicted_cov_factor": ("time", "state", "state_col"),
        "innovation_cov_factor": ("time", "measurement", "measurement_col"), "final_cov_factor": ("state", "state_col"),
    }
    _export_units = {
        "filtered_mean": "state units", "filtered_cov": "state units squared", "predicted_mean": "state units",
        "predicted_cov": "state units squared", "innovation": "measurement units",
        "innovation_cov": "measurement units squared", "num_observed": "components", "log_likelihood": "nats",
        "final_mean": "state units", "final_cov": "state units squared", "filtered_cov_factor": "state units",
        "predicted_cov_factor": "state units", "innovation_cov_factor": "measurement units",
        "final_cov_factor": "state units",
    }


def _outer_factor(L: Array) -> Array:
    """``L Lᵀ`` over the last two axes: a covariance from its (lower) Cholesky factor."""
    return jnp.matmul(L, jnp.swapaxes(L, -1, -2))


def _scan_filter(filter, model, measurements, observed, first_step, save):
    """:meth:`AbstractFilter.step` over every measurement, as one ``lax.scan``."""
    dtype = model.initial_cov.dtype

    def step(state, inputs):
        z, obs = inputs
        state, (pm, pc, post) = filter.step(model, state, z, obs, first_step=first_step)
        if save == "final":
            return state, None
        if save == "mean":
            return state, post.mean
        return state, (
            post.mean,
            post.cov,
            pm,
            pc,
            post.innovation,
            post.innovation_cov,
            jnp.sum(obs.astype(dtype)),
        )

    final, hist = jax.lax.scan(step, filter.init(model), (measurements, observed))
    if save == "final":
        hist = (None,) * 7
    elif save == "mean":
        hist = (hist,) + (None,) * 6
    if filter.square_root:
        # The scan carried Cholesky factors; the covariances are formed once, here, so that every
        # filter's FilterResult holds covariances (the smoother and users read them) and the
        # factors are kept beside them.
        fm, fL, pm, pL, inn, sL, nobs = hist
        square = lambda L: None if L is None else _outer_factor(L)  # noqa: E731
        return FilterResult(
            fm, square(fL), pm, square(pL), inn, square(sL), nobs, final.log_likelihood,
            final.mean, _outer_factor(final.cov), final.ok, fL, pL, sL, final.cov,
        )
    return FilterResult(*hist, final.log_likelihood, final.mean, final.cov, final.ok)


def check_run_arguments(filter, model, first_step, save) -> None:
    """The argument checks every filter entry point makes (raises ``InputError``).

    **Arguments:**

    - ``filter``: the filter strategy; ``model``: the state-space model.
    - ``first_step``: must be ``"update"`` or ``"predict"``; ``save``: must be ``"all"``, ``"final"`` or
      ``"mean"``.

    **Returns:** ``None``.
    """
    if first_step not in ("update", "predict"):
        raise InputError(f"`first_step` must be 'update' or 'predict'; got {first_step!r}.")
    if save not in ("all", "final", "mean"):
        raise InputError(f"`save` must be 'all', 'final' or 'mean'; got {save!r}.")
    if not isinstance(filter, AbstractFilter):
        raise InputError(f"`filter` must be a jaxtrack filter; got {type(filter).__name__}.")
    if not isinstance(model, AbstractStateSpaceModel):
        raise InputError(f"`model` must be a jaxtrack state-space model; got {type(model).__name__}.")
    filter.check_model(model)


def raise_nonfinite_measurements(bad: np.ndarray):
    """Raise the ``InputError`` for non-finite measurements the mask marks observed (``bad``).

    **Arguments:**

    - ``bad``: boolean NumPy ``(T, m)``, True at observed non-finite entries (at least one).

    **Returns:** never; always raises ``InputError``.
    """
    first = tuple(int(i) for i in np.argwhere(bad)[0])
    raise InputError(
        f"`measurements` has {int(bad.sum())} non-finite entries that the mask marks as "
        f"observed (first at index {first}). Mark them missing with `mask`, or pass "
        f"nan_as_missing=True to treat NaN as missing."
    )


def _observed_nonfinite(measurements, mask, shape) -> np.ndarray | None:
    """Boolean NumPy ``shape`` array, True at observed non-finite measurements; ``None`` if traced.

    Computed in NumPy from the caller's own arrays: inside a ``jit`` trace even a closed-over
    (concrete) array becomes a tracer as soon as a ``jnp`` operation touches it, so a check on
    ``jnp.isfinite(z)`` would call ``np.asarray`` on a tracer (``TracerArrayConversionError``;
    the README's ``jax.jit(jax.grad(loglik))``). When the measurements or the mask are traced
    the check is skipped and the filter's run-time status (``ok``, ``throw``) reports them.
    """
    if not (is_concrete(measurements) and (mask is None or is_concrete(mask))):
        return None
    try:
        z = np.asarray(measurements)
        observed = np.ones(shape, bool) if mask is None else np.asarray(mask, bool)
    except jax.errors.TracerArrayConversionError:  # e.g. a list holding tracers
        return None
    z = z.reshape(shape)
    observed = np.broadcast_to(observed[:, None] if observed.ndim == 1 else observed, shape)
    return ~np.isfinite(z) & observed


def prepare_measurements(
    model: AbstractStateSpaceModel,
    measurements: ArrayLike,
    mask: ArrayLike | None,
    nan_as_missing: bool,
) -> tuple[Array, Array]:
    """Validate measurements and mask; return ``(measurements, observed)`` with shapes (T, m).

    NaN entries are accepted only when ``nan_as_missing`` is True; they are then marked missing
    and replaced by 0 so that they cannot reach the arithmetic.

    **Arguments:**

    - ``model``: the state-space model.
    - ``measurements``: shape ``(T, m)`` (or ``(T,)`` when ``m = 1``), in the model's units.
    - ``mask``: optional boolean, ``(T,)`` or ``(T, m)``; True means observed.
    - ``nan_as_missing``: treat NaN measurements as missing.

    **Returns:** ``(measurements, observed)``: floats ``(T, m)`` with missing entries 0, and booleans
    ``(T, m)``.

    **Raises:** ``InputError`` for wrong shapes, a step count that disagrees with the model's, a mask
    that is not boolean, a model function returning the wrong shape, or (concrete) non-finite
    observed measurements.
    """
    # The model's functions first: a wrong output shape would otherwise fail (or broadcast)
    # deep inside the scan without naming the function.
    model.check_functions()
    z = jnp.asarray(measurements)
    if not jnp.issubdtype(z.dtype, jnp.floating):
        z = z.astype(model.initial_mean.dtype)
    m = model.meas_dim
    if z.ndim == 1 and m == 1:
        z = z[:, None]
    check_shape("measurements", z, [(None, m)])
    num_steps = z.shape[0]
    if num_steps == 0:
        raise InputError("`measurements` must have at least one step; got shape (0, m).")
    model_steps = model.num_steps
    if model_steps is not None and model_steps != num_steps:
        raise InputError(
            f"`measurements` has {num_steps} steps but the model's per-step arrays have "
            f"{model_steps}; they must agree (index k of a per-step array is the interval "
            f"ending at measurement k)."
        )
    if mask is None:
        observed = jnp.ones(z.shape, bool)
    else:
        mask = jnp.asarray(mask)
        check_shape("mask", mask, [(num_steps,), (num_steps, m)])
        if mask.dtype != bool:
            raise InputError(f"`mask` must be boolean (True = observed); got dtype {mask.dtype}.")
        observed = jnp.broadcast_to(mask[:, None] if mask.ndim == 1 else mask, z.shape)
    if nan_as_missing:
        finite = jnp.isfinite(z)
        observed = observed & finite
        z = jnp.where(finite, z, 0.0)
    else:
        bad = _observed_nonfinite(measurements, mask, z.shape)
        if bad is not None and bad.any():
            raise_nonfinite_measurements(bad)
    if not nan_as_missing:
        # Entries the mask marks missing may hold anything (NaN included): never let them in.
        z = jnp.where(observed, z, 0.0)
    return z, observed

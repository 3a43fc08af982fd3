"""The filter family's base class, its result type and the one scan that drives every filter.

A filter is a strategy object (``KalmanFilter()``, ``ExtendedKalmanFilter()``,
``UnscentedKalmanFilter()``) with one ``predict`` and one ``update``. :func:`run_filter` wraps
them in one step function and one ``lax.scan``. The same step function is what
:mod:`jaxtrack.montecarlo` runs inside ``vmap``, so a Monte Carlo run and a single run execute
exactly the same arithmetic.
"""

from __future__ import annotations

import abc
import math
from typing import ClassVar, Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._validation import InputError, check_shape, is_concrete
from ..models import AbstractStateSpaceModel
from ._linalg import cholesky_and_inverse, matmul, tril_inverse

FirstStep = Literal["update", "predict"]
Save = Literal["all", "final", "mean"]


def symmetrize(a: Array) -> Array:
    return 0.5 * (a + jnp.swapaxes(a, -1, -2))


class Conditioned(NamedTuple):
    """What one measurement update produces (one step, unbatched)."""

    mean: Float[Array, " n"]
    cov: Float[Array, "n n"]
    innovation: Float[Array, " m"]  # z − ẑ, 0 in missing components
    innovation_cov: Float[Array, "m m"]  # S; identity rows/columns in missing components
    log_likelihood: Float[Array, ""]  # log N(innovation; 0, S) over the observed components
    gain: Float[Array, "n m"]  # W used; zero columns in missing components


def masked_noise(R: Array, observed: Bool[Array, " m"]) -> Array:
    """Measurement noise with missing components decoupled: ``R`` on the observed block, ``I`` else.

    With the matching rows of ``H`` zeroed, ``S = H P Hᵀ + R`` is block diagonal with the identity
    on the missing block, so the gain has zero columns there and ``log det S`` and ``yᵀS⁻¹y`` equal
    those of the observed sub-vector: the update is exactly the one with only the observed rows
    of ``H`` and ``R``, without changing any array shape (so one compilation serves every mask).
    """
    both = observed[:, None] & observed[None, :]
    return jnp.where(both, R, 0.0) + jnp.diag(jnp.where(observed, 0.0, 1.0).astype(R.dtype))


def gaussian_log_likelihood(innovation, innovation_cov_chol, num_observed, chol_inv=None) -> Array:
    """``log N(y; 0, S)`` over ``num_observed`` components, given ``L = chol(S)`` (lower).

    With ``chol_inv = L⁻¹`` the innovation is whitened by a product rather than a triangular
    solve, which stays unbatched on the factor side under ``vmap`` (see ``_linalg``).
    """
    if chol_inv is None:
        chol_inv = tril_inverse(innovation_cov_chol)
    whitened = matmul(chol_inv, innovation)
    log_det = 2.0 * jnp.sum(jnp.log(jnp.diagonal(innovation_cov_chol)))
    return -0.5 * (whitened @ whitened + log_det + num_observed * math.log(2.0 * math.pi))


class AbstractUpdateForm(eqx.Module):
    """How a linearised update forms the filtered covariance from ``P``, ``H``, ``R`` and ``W``.

    A strategy object for :class:`~jaxtrack.filters.KalmanFilter` and
    :class:`~jaxtrack.filters.ExtendedKalmanFilter` (``form=``). ``PHt`` is ``P Hᵀ`` and ``H``, ``R``
    already have missing components removed (:func:`masked_noise`).
    """

    supports_any_gain: eqx.AbstractClassVar[bool]

    @abc.abstractmethod
    def covariance(self, cov: Array, PHt: Array, H: Array, R: Array, gain: Array) -> Array:
        """The filtered covariance ``P⁺`` ``(n, n)`` (symmetric)."""


class JosephForm(AbstractUpdateForm):
    """``P⁺ = (I − W H) P (I − W H)ᵀ + W R Wᵀ`` (Joseph; Ho 1968, eq. (4)): exact for any gain.

    The default. It is the actual error covariance of a filter with a suboptimal or fixed gain,
    and stays symmetric positive semi-definite under rounding.
    """

    supports_any_gain: ClassVar[bool] = True

    def covariance(self, cov, PHt, H, R, gain):
        # Joseph form evaluated through the rank-m structure of I − W H (P is symmetric, so
        # H P = (P Hᵀ)ᵀ): (I − W H) P = P − W (P Hᵀ)ᵀ, and (I − W H) P (I − W H)ᵀ = A P − (A P Hᵀ) Wᵀ
        # with A P = (I − W H) P. The same recursion as forming I − W H and two n×n×n products,
        # in about 4n²m multiply-adds instead of 2n³.
        AP = cov - matmul(gain, PHt.T)
        return AP - matmul(matmul(AP, H.T), gain.T) + matmul(matmul(gain, R), gain.T)


class StandardForm(AbstractUpdateForm):
    """``P⁺ = (I − W H) P = P − W (P Hᵀ)ᵀ`` (the textbook form; e.g. Lindgren & Gong 1978, eq. (38)).

    Valid only with the optimal gain ``W = P Hᵀ S⁻¹`` (a supplied gain raises ``InputError``).
    Cheaper than :class:`JosephForm` by about half, but rounding can make ``P⁺`` indefinite in
    ill-conditioned problems; studies use it where the paper does.
    """

    supports_any_gain: ClassVar[bool] = False

    def covariance(self, cov, PHt, H, R, gain):
        return cov - matmul(gain, PHt.T)


def condition_linearized(
    mean: Array,
    cov: Array,
    innovation: Array,
    H: Array,
    R: Array,
    observed: Array,
    gain: Array | None = None,
    form: AbstractUpdateForm = JosephForm(),
) -> Conditioned:
    """Update with a (linearised) measurement matrix; Joseph form (valid for any gain) by default.

    .. math::

        S = H P Hᵀ + R,\\quad W = P Hᵀ S^{-1}\\ (\\text{unless given}),\\quad
        x⁺ = x + W y,\\quad P⁺ = (I − W H) P (I − W H)ᵀ + W R Wᵀ

    (Ho 1968, eqs. (2)–(4)); ``form=StandardForm()`` gives ``P⁺ = (I − W H) P`` instead (see
    :class:`AbstractUpdateForm`). Missing components (``observed`` False) are removed as described
    in :func:`masked_noise`; a supplied gain has its columns for missing components zeroed.
    """
    obs_f = observed.astype(cov.dtype)
    H = H * obs_f[:, None]
    R = masked_noise(R, observed)
    innovation = jnp.where(observed, innovation, 0.0)
    # Small products go through `matmul` (element-wise loops under vmap, see `_linalg`).
    PHt = matmul(cov, H.T)
    S = symmetrize(matmul(H, PHt) + R)
    chol, chol_inv = cholesky_and_inverse(S)
    if gain is None:
        # W = P Hᵀ S⁻¹ = (P Hᵀ L⁻ᵀ) L⁻¹ with S = L Lᵀ. Products with L⁻¹ rather than a
        # triangular solve: for small m the factor is written out (no LAPACK call per run
        # under vmap), and a factor shared by a batch stays unbatched.
        gain = matmul(matmul(PHt, chol_inv.T), chol_inv)
    else:
        gain = gain * obs_f[None, :]
    new_cov = form.covariance(cov, PHt, H, R, gain)
    # The terms round differently; keep P exactly symmetric so that Cholesky factorisations
    # downstream (next S, smoother, NEES) see a symmetric matrix.
    new_cov = symmetrize(new_cov)
    new_mean = mean + matmul(gain, innovation)
    ll = gaussian_log_likelihood(innovation, chol, jnp.sum(obs_f), chol_inv)
    return Conditioned(new_mean, new_cov, innovation, S, ll, gain)


def condition_on_moments(
    mean: Array,
    cov: Array,
    innovation: Array,
    innovation_cov: Array,
    cross_cov: Array,
    observed: Array,
) -> Conditioned:
    """Update from moments (sigma-point filters): ``W = C S⁻¹``, ``P⁺ = P − W S Wᵀ``.

    ``cross_cov`` is ``C = Cov(x, z)`` (n, m) and ``innovation_cov`` is ``S = Cov(z)`` including R.
    Missing components are removed as in :func:`masked_noise`.
    """
    obs_f = observed.astype(cov.dtype)
    both = observed[:, None] & observed[None, :]
    S = jnp.where(both, innovation_cov, 0.0) + jnp.diag(1.0 - obs_f)
    S = symmetrize(S)
    C = cross_cov * obs_f[None, :]
    innovation = jnp.where(observed, innovation, 0.0)
    chol, chol_inv = cholesky_and_inverse(S)
    gain = matmul(matmul(C, chol_inv.T), chol_inv)
    # Symmetric in exact arithmetic; see condition_linearized.
    new_cov = symmetrize(cov - matmul(matmul(gain, S), gain.T))
    new_mean = mean + matmul(gain, innovation)
    ll = gaussian_log_likelihood(innovation, chol, jnp.sum(obs_f), chol_inv)
    return Conditioned(new_mean, new_cov, innovation, S, ll, gain)


class AbstractFilter(eqx.Module):
    """A Gaussian filter: one :meth:`predict` and one :meth:`update`.

    Concrete filters are final classes; wrap, don't subclass. Both methods act on ONE trajectory
    (no batch axis); batches come from ``jax.vmap``.
    """

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


class FilterResult(eqx.Module):
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
    - ``ok`` ``()`` bool: False if any mean, covariance or the log-likelihood became non-finite.
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


class _Carry(NamedTuple):
    mean: Array
    cov: Array
    log_likelihood: Array
    ok: Array


def filter_step(
    filter: AbstractFilter,
    model: AbstractStateSpaceModel,
    first_step: FirstStep,
    carry: _Carry,
    k: Array,
    z: Array,
    observed: Array,
):
    """One predict + update: the single step function every filter run executes.

    Returns ``(new_carry, (predicted_mean, predicted_cov, conditioned))``.
    """
    pred_mean, pred_cov = filter.predict(model, carry.mean, carry.cov, k)
    if first_step == "update":
        # The prior already sits at the first measurement: no transition into step 0.
        at_start = k == 0
        pred_mean = jnp.where(at_start, carry.mean, pred_mean)
        pred_cov = jnp.where(at_start, carry.cov, pred_cov)
    post = filter.update(model, pred_mean, pred_cov, z, observed, k)
    ll = carry.log_likelihood + post.log_likelihood
    finite = (
        jnp.all(jnp.isfinite(post.mean)) & jnp.all(jnp.isfinite(post.cov)) & jnp.isfinite(ll)
    )
    new_carry = _Carry(post.mean, post.cov, ll, carry.ok & finite)
    return new_carry, (pred_mean, pred_cov, post)


def _scan_filter(filter, model, measurements, observed, first_step, save):
    num_steps = measurements.shape[0]
    dtype = model.initial_cov.dtype
    init = _Carry(
        model.initial_mean,
        model.initial_cov,
        jnp.zeros((), dtype),
        jnp.ones((), bool),
    )

    def step(carry, inputs):
        k, z, obs = inputs
        carry, (pm, pc, post) = filter_step(filter, model, first_step, carry, k, z, obs)
        if save == "final":
            return carry, None
        if save == "mean":
            return carry, post.mean
        return carry, (
            post.mean,
            post.cov,
            pm,
            pc,
            post.innovation,
            post.innovation_cov,
            jnp.sum(obs.astype(dtype)),
        )

    ks = jnp.arange(num_steps)
    final, hist = jax.lax.scan(step, init, (ks, measurements, observed))
    if save == "final":
        hist = (None,) * 7
    elif save == "mean":
        hist = (hist,) + (None,) * 6
    return FilterResult(*hist, final.log_likelihood, final.mean, final.cov, final.ok)


@eqx.filter_jit
def _run_filter_jit(filter, model, measurements, observed, first_step, save, throw):
    result = _scan_filter(filter, model, measurements, observed, first_step, save)
    if throw:
        result = eqx.error_if(
            result,
            ~result.ok,
            "jaxtrack: the filter produced a non-finite mean, covariance or log-likelihood. "
            "Likely causes: (a) a measurement is NaN/inf (pass nan_as_missing=True to skip "
            "them); (b) R or the prior covariance is not positive definite; (c) units differ "
            "by many orders of magnitude (e.g. rad vs deg, m vs km); (d) the state diverged. "
            "Pass throw=False to get the result with ok=False instead.",
        )
    return result


def prepare_measurements(
    model: AbstractStateSpaceModel,
    measurements: ArrayLike,
    mask: ArrayLike | None,
    nan_as_missing: bool,
) -> tuple[Array, Array]:
    """Validate measurements and mask; return ``(measurements, observed)`` with shapes (T, m).

    NaN entries are accepted only when ``nan_as_missing`` is True; they are then marked missing
    and replaced by 0 so that they cannot reach the arithmetic.
    """
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
    finite = jnp.isfinite(z)
    if nan_as_missing:
        observed = observed & finite
        z = jnp.where(finite, z, 0.0)
    elif is_concrete(z):
        bad = np.asarray(~finite & observed)
        if bad.any():
            first = tuple(int(i) for i in np.argwhere(bad)[0])
            raise InputError(
                f"`measurements` has {int(bad.sum())} non-finite entries that the mask marks as "
                f"observed (first at index {first}). Mark them missing with `mask`, or pass "
                f"nan_as_missing=True to treat NaN as missing."
            )
    if not nan_as_missing:
        # Entries the mask marks missing may hold anything (NaN included): never let them in.
        z = jnp.where(observed, z, 0.0)
    return z, observed


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
) -> FilterResult:
    """Run ``filter`` on ``model`` over ``measurements`` with one jitted ``lax.scan``.

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
    - ``throw``: raise at run time if the result is non-finite. Use ``throw=False`` inside
      ``vmap`` and read ``result.ok`` per run.

    **Returns:** a :class:`FilterResult`.

    **Raises:** ``InputError`` for wrong shapes, a mask that is not boolean, non-finite
    measurements, or a model the filter cannot handle.

    Example::

        model = jaxtrack.models.constant_velocity(0.1, dim=2, accel_psd=1.0,
                                                  measurement_std=5.0, initial_cov=100 * jnp.eye(4))
        result = run_filter(KalmanFilter(), model, zs)
        result.filtered_mean.shape  # (T, 4)
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
    z, observed = prepare_measurements(model, measurements, mask, nan_as_missing)
    return _run_filter_jit(filter, model, z, observed, first_step, save, throw)

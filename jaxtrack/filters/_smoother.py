"""Rauch–Tung–Striebel fixed-interval smoother."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
from jaxtyping import Array, ArrayLike, Bool, Float

from .._export import Exportable
from .._validation import throw_unless_ok
from ..models import AbstractStateSpaceModel
from ._base import AbstractFilter, FilterResult, FirstStep, symmetrize
from ._kalman import KalmanFilter
from ._parallel import AbstractTimeScan, AutoScan, Sequential, resolve_scan
from ._run import run_filter


class SmootherResult(Exportable, eqx.Module):
    """Output of :func:`rts_smoother`.

    - ``smoothed_mean`` ``(T, n)``, ``smoothed_cov`` ``(T, n, n)``: ``x̂_{k/T-1}``, ``P_{k/T-1}``.
    - ``smoother_gain`` ``(T-1, n, n)``: ``G_k = P_{k/k} Φ_{k+1}ᵀ P_{k+1/k}⁻¹``.
    - ``filtered``: the forward pass, a :class:`FilterResult`.
    - ``ok`` ``()`` bool: False if the forward pass failed (``filtered.ok``) or any smoothed mean
      or covariance is non-finite. A singular predicted covariance ``P_{k+1/k}`` (``Q = 0`` with
      a singular ``F``) is not a failure: the gain then uses its pseudo-inverse,
      ``G_k = P_{k/k} Φ_{k+1}ᵀ P_{k+1/k}⁺``, which gives the exact smoothed moments.

    **Export** (:mod:`jaxtrack._export`): ``to_dict()``, ``save(path)`` / ``SmootherResult.load(path)``
    (one ``.npz``, bit for bit), ``to_xarray()`` and ``to_pandas()`` (one row per step) with the
    optional ``export`` extra.
    """

    smoothed_mean: Float[Array, "T n"]
    smoothed_cov: Float[Array, "T n n"]
    smoother_gain: Float[Array, "Tm1 n n"]
    filtered: FilterResult
    ok: Bool[Array, ""]

    _export_kind = "jaxtrack.SmootherResult"
    # The gains have T-1 steps, so their axis is not `time` (xarray needs one length per name).
    _export_dims = {"smoothed_mean": ("time", "state"), "smoothed_cov": ("time", "state", "state_col"),
                    "smoother_gain": ("gain_step", "state", "state_col"), "ok": ()}
    _export_units = {"smoothed_mean": "state units", "smoothed_cov": "state units squared", "smoother_gain": "1"}


_SMOOTHER_FAILED = (
    "jaxtrack: rts_smoother produced a non-finite smoothed mean or covariance. Likely causes: "
    "(a) non-finite filtered moments (see run_filter's error); (b) covariances whose units differ "
    "by many orders of magnitude, so P_{k+1/k} is numerically indefinite. (A singular P_{k+1/k}, "
    "e.g. Q = 0 with a singular F, is handled with a pseudo-inverse gain.) Pass throw=False "
    "to get the result with ok=False instead."
)


def _smoother_gain(P_f: Array, F: Array, P_p: Array) -> Array:
    """``G = P_f Fᵀ P_p⁻¹``, or ``P_f Fᵀ P_p⁺`` (pseudo-inverse) where ``P_p`` is singular.

    The regular case is a Cholesky solve (unchanged, bit for bit). ``P_p = F P_f Fᵀ + Q`` is
    singular when ``Q`` is and ``F`` is (e.g. ``Q = 0`` and a zero row of ``F``): its Cholesky
    factor then has a zero or NaN pivot and the inverse does not exist. The pseudo-inverse gain
    is then the exact one: ``x_{k+1} − x̂_{k+1/k}`` lies in the range of ``P_p`` almost surely,
    and ``P_f Fᵀ v = 0`` for every ``v`` in its null space (``vᵀ F P_f Fᵀ v = vᵀ P_p v = 0``), so
    ``E[x_k | x_{k+1}] = x̂_{k/k} + P_f Fᵀ P_p⁺ (x_{k+1} − x̂_{k+1/k})`` is the Gaussian
    conditional mean (the Gaussian conditional with a generalised inverse; Rao 1973, *Linear Statistical
    Inference*, ch. 8). ``P_p⁺``
    comes from ``eigh`` with eigenvalues below ``n·ε·λ_max`` treated as zero.

    **Arguments:** ``P_f`` ``P_{k/k}`` ``(n, n)``; ``F`` ``Φ_{k+1}`` ``(n, n)``; ``P_p``
    ``P_{k+1/k}`` ``(n, n)``.

    **Returns:** ``G_k``, ``(n, n)`` (dimensionless for a homogeneous state).
    """
    n = P_p.shape[-1]
    cutoff = n * jnp.finfo(P_p.dtype).eps
    chol = jnp.linalg.cholesky(P_p)
    G_chol = jsl.cho_solve((chol, True), F @ P_f).T
    # Regular: finite factor with pivots (squared) above the relative cutoff. A singular P_p
    # gives a NaN factor, or, when the zero pivot is the last one or rounding leaves it tiny
    # but positive, a finite factor with a (near-)zero pivot and a huge or NaN gain.
    pivots = jnp.diagonal(chol) ** 2
    regular = (
        jnp.all(jnp.isfinite(G_chol))
        & jnp.all(pivots > cutoff * jnp.max(jnp.abs(jnp.diagonal(P_p))))
    )
    # Double `where`: in the regular case the pseudo-inverse sees the identity, so neither its
    # value nor its derivative (eigh's is singular at repeated eigenvalues) can reach G.
    P_safe = jnp.where(regular, jnp.eye(n, dtype=P_p.dtype), P_p)
    lam, V = jnp.linalg.eigh(P_safe)
    keep = lam > cutoff * jnp.max(lam)
    inv_lam = jnp.where(keep, 1.0 / jnp.where(keep, lam, 1.0), 0.0)
    G_pinv = ((P_f @ F.T) @ V * inv_lam[None, :]) @ V.T
    return jnp.where(regular, G_chol, G_pinv)


def _rts_scan(model, filtered: FilterResult) -> tuple[Array, Array, Array]:
    """The sequential backward pass (one reverse ``lax.scan``): smoothed means, covariances, gains."""

    def step(carry, inputs):
        next_mean, next_cov = carry
        k, m_f, P_f, m_p_next, P_p_next = inputs
        # Φ_{k+1} linearised at the filtered estimate (exact for a linear model).
        F = model.transition_jacobian(m_f, k + 1)
        G = _smoother_gain(P_f, F, P_p_next)
        mean = m_f + G @ (next_mean - m_p_next)
        cov = symmetrize(P_f + G @ (next_cov - P_p_next) @ G.T)
        return (mean, cov), (mean, cov, G)

    T = filtered.filtered_mean.shape[0]
    last = (filtered.filtered_mean[-1], filtered.filtered_cov[-1])
    inputs = (
        jnp.arange(T - 1),
        filtered.filtered_mean[:-1],
        filtered.filtered_cov[:-1],
        filtered.predicted_mean[1:],
        filtered.predicted_cov[1:],
    )
    _, (means, covs, gains) = jax.lax.scan(step, last, inputs, reverse=True)
    means = jnp.concatenate([means, last[0][None]])
    covs = jnp.concatenate([covs, last[1][None]])
    return means, covs, gains


@eqx.filter_jit
def _rts_backward(model, filtered: FilterResult, scan: AbstractTimeScan = Sequential()):
    # `scan` is resolved (Sequential or ParallelInTime); Sequential's pass is `_rts_scan`.
    means, covs, gains = scan.smoother_pass(model, filtered)
    return _with_status(SmootherResult(means, covs, gains, filtered, filtered.ok))


def _with_status(result: SmootherResult) -> SmootherResult:
    """Set ``ok`` from the smoothed moments (``throw`` is the caller's, outside the jitted pass:
    no host callback in it, so the persistent compilation cache keeps it)."""
    finite = jnp.all(jnp.isfinite(result.smoothed_mean)) & jnp.all(jnp.isfinite(result.smoothed_cov))
    return eqx.tree_at(lambda r: r.ok, result, result.filtered.ok & finite)


def rts_smoother(
    model: AbstractStateSpaceModel,
    measurements: ArrayLike,
    *,
    filter: AbstractFilter | None = None,
    mask: ArrayLike | None = None,
    first_step: FirstStep = "update",
    nan_as_missing: bool = False,
    throw: bool = True,
    scan: AbstractTimeScan = AutoScan(),
) -> SmootherResult:
    r"""Rauch–Tung–Striebel smoother: a forward filter, then one reverse scan (``lax.scan`` by default).

    .. math::

        G_k = P_{k/k} Φ_{k+1}ᵀ P_{k+1/k}^{-1},\quad
        x̂_{k/N} = x̂_{k/k} + G_k (x̂_{k+1/N} − x̂_{k+1/k}),\quad
        P_{k/N} = P_{k/k} + G_k (P_{k+1/N} − P_{k+1/k}) G_kᵀ

    (Rauch, Tung & Striebel 1965); where ``P_{k+1/k}`` is singular (``Q = 0`` with a singular ``Φ``)
    the inverse is replaced by the pseudo-inverse, which is exact there. ``filter`` defaults to :class:`KalmanFilter`; with an
    :class:`ExtendedKalmanFilter` it is the extended RTS smoother (Φ linearised at the filtered
    estimate). Arguments as :func:`run_filter`; ``throw=True`` (default) also raises at run time
    (``equinox``'s runtime error, whose message lists the likely causes) when a smoothed mean or
    covariance is non-finite; with ``throw=False`` read :attr:`SmootherResult.ok`. ``scan``
    traverses time in both passes: :class:`~jaxtrack.filters.Sequential` (two ``lax.scan``),
    :class:`~jaxtrack.filters.ParallelInTime` (two associative scans, Särkkä & García-Fernández
    2021; the ``KalmanFilter`` on a linear model) or :class:`~jaxtrack.filters.AutoScan`
    (default: sequential on CPU); the result is the same.

    **Returns:** a :class:`SmootherResult` (``T`` steps, ``n`` states).

    **Raises:** ``InputError`` as :func:`run_filter` (a ``scan`` that does not apply included);
    with ``throw=True`` a runtime error if the forward or backward pass produced non-finite values
    (e.g. a singular predicted covariance).
    """
    filter = KalmanFilter() if filter is None else filter
    measurements = jnp.asarray(measurements)
    scan = resolve_scan(scan, filter, model, measurements.shape[0] if measurements.ndim else 0)
    filtered = run_filter(
        filter,
        model,
        measurements,
        mask=mask,
        first_step=first_step,
        save="all",
        nan_as_missing=nan_as_missing,
        throw=throw,
        scan=scan,
    )
    if filtered.filtered_mean.shape[0] == 1:
        empty = jnp.zeros((0,) + filtered.filtered_cov.shape[1:], filtered.filtered_cov.dtype)
        return SmootherResult(filtered.filtered_mean, filtered.filtered_cov, empty, filtered, filtered.ok)
    result = _rts_backward(model, filtered, scan)
    return throw_unless_ok(result, result.ok, _SMOOTHER_FAILED) if throw else result


def lag_one_covariances(result: SmootherResult) -> Float[Array, "Tm1 n n"]:
    r"""Lag-one smoothed cross-covariances ``Cov(x_{k+1}, x_k | z_{0:T-1}) = P_{k+1/T-1} G_kᵀ``.

    .. math::

        P_{k+1,k/N} = P_{k+1/N} G_kᵀ

    (de Jong 1989, "Smoothing and interpolation with the state-space model", *JASA* 84: the
    smoothed covariance of consecutive states from the RTS gain). It equals Shumway & Stoffer's
    lag-one covariance smoother (1982; 2017, *Time Series Analysis and Its Applications*, 4th
    ed., Property 6.3), started from ``P_{N,N-1/N} = (I − K_N H_N) Φ_N P_{N-1/N-1}``, but
    needs no second backward pass:
    ``x_k − x̂_{k/N} = (x_k − x̂_{k/k} − G_k(x_{k+1} − x̂_{k+1/k})) − G_k(x̂_{k+1/N} − x_{k+1})``, whose
    first bracket is independent of ``x_{k+1}`` and of all measurements, so
    ``Cov(x_k, x_{k+1} | Z) = G_k P_{k+1/N}``. It is what the EM M-step for ``F`` and ``Q`` needs
    (:func:`jaxtrack.learning.fit_em`), as ``E[x_{k+1} x_kᵀ | Z] = P_{k+1,k/N} + x̂_{k+1/N} x̂_{k/N}ᵀ``.
    With the pseudo-inverse gain (singular ``P_{k+1/k}``) it is exact as well (same argument).

    **Arguments:**

    - ``result``: a :class:`SmootherResult` of ``T`` steps from :func:`rts_smoother`.

    **Returns:** ``(T-1, n, n)``: entry ``k`` is ``Cov(x_{k+1}, x_k | Z)`` in state units squared
    (row: step ``k+1``, column: step ``k``); ``(0, n, n)`` when ``T = 1``.
    """
    # A pure function of the existing fields: P_{k+1/N} is smoothed_cov[1:], G_k smoother_gain.
    return jnp.matmul(result.smoothed_cov[1:], jnp.swapaxes(result.smoother_gain, -1, -2))

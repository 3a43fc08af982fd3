"""From a filter's predictions to the association input: per-pair likelihoods, gates, ``L``.

Three steps, each a pure function of arrays:

1. :func:`measurement_likelihoods`: for ONE track, any jaxtrack filter's ``update`` vmapped over
   the scan's ``M`` measurements gives ``log N(z_j; ẑ, S)`` and the normalised innovation squared
   ``yᵀ S⁻¹ y`` per measurement (``vmap`` over tracks for the ``(T, M)`` tables);
2. :func:`gate_threshold`: the χ² gate ``γ`` with ``P(χ²_m ≤ γ) = P_G`` (host side);
3. :func:`log_likelihood_ratios`: the ``(T, 1 + M)`` log-weight matrix ``L`` of
   :mod:`jaxtrack.association` and the gate mask.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._validation import InputError, check_shape, is_concrete, nan_where_traced
from ..filters._base import AbstractFilter, Conditioned
from ..filters._linalg import cholesky_and_inverse, matmul, tril_inverse
from ..models import AbstractStateSpaceModel


def gate_threshold(prob_gate: float, meas_dim: int) -> float:
    r"""The ellipsoidal gate ``γ`` for gate probability ``P_G``: ``P(χ²_m ≤ γ) = P_G``.

    A measurement of a track is in its gate when its normalised innovation squared
    ``yᵀ S⁻¹ y ≤ γ`` (the validation region of Bar-Shalom, Daum & Huang 2009, "The probabilistic
    data association filter", IEEE Control Syst. Mag. 29(6)); for a correct Gaussian
    prediction the true measurement falls inside with probability ``P_G``.

    **Arguments:**

    - ``prob_gate``: ``P_G``, a Python or NumPy scalar in ``(0, 1]``; 1 means no gate.
    - ``meas_dim``: ``m``, the measurement dimension (the χ² degrees of freedom), a positive int.

    **Returns:** ``γ`` as a Python float (dimensionless; ``inf`` for ``P_G = 1``), computed on the
    host with ``scipy.stats.chi2.ppf``, so it can be a static argument or a constant.

    **Raises:** :class:`~jaxtrack.InputError` naming ``prob_gate`` (not in ``(0, 1]`` or not a
    concrete scalar) or ``meas_dim`` (not a positive integer).

    Example:

    >>> round(gate_threshold(0.99, 2), 4)
    9.2103
    >>> gate_threshold(1.0, 3)
    inf
    """
    if isinstance(meas_dim, (bool, np.bool_)) or not isinstance(meas_dim, (int, np.integer)) or meas_dim < 1:
        raise InputError(f"`meas_dim` must be a positive integer; got {meas_dim!r}.")
    if not is_concrete(prob_gate) or np.ndim(prob_gate) != 0:
        raise InputError(f"`prob_gate` must be a concrete scalar in (0, 1]; got {prob_gate!r}.")
    p = float(prob_gate)
    if not 0.0 < p <= 1.0:
        raise InputError(f"`prob_gate` must be in (0, 1] (1 = no gate); got {p}.")
    if p == 1.0:
        return math.inf
    from scipy.stats import chi2  # host-only dependency, imported where it is used

    return float(chi2.ppf(p, int(meas_dim)))


def _checked_probability(name: str, x, dtype, *, open_low: bool, shapes) -> Array:
    """A probability argument as an array: raises when concrete and outside its range, NaN where
    traced and outside it (``nan_where_traced``), so that a bad value is never a silent answer."""
    x = jnp.asarray(x, dtype)
    check_shape(name, x, shapes)

    def bad(v):
        return ~((v > 0.0 if open_low else v >= 0.0) & (v <= 1.0))

    if is_concrete(x):
        # Checked in NumPy: under jit a concrete (closed-over) value's jnp comparison is staged as
        # a tracer, which cannot be inspected here (a tracker's step jitted by hand hit this).
        if np.any(bad(np.asarray(x))):
            interval = "(0, 1]" if open_low else "[0, 1]"
            raise InputError(f"`{name}` must be in {interval}; got {np.asarray(x)}.")
        return x
    return nan_where_traced(x, bad)


def log_likelihood_ratios(
    innovation_log_likelihood: Float[ArrayLike, "T M"],
    nis: Float[ArrayLike, "T M"],
    valid_tracks: Bool[ArrayLike, " T"],
    valid_measurements: Bool[ArrayLike, " M"],
    *,
    prob_detect: Float[ArrayLike, "*T"],
    clutter_density: Float[ArrayLike, "*M"],
    gate_threshold: float | Float[ArrayLike, ""] = math.inf,
    prob_gate: Float[ArrayLike, "*T"] = 1.0,
    existence: Float[ArrayLike, "*T"] | None = None,
) -> tuple[Float[Array, "T Mp1"], Bool[Array, "T M"]]:
    r"""The log-weight matrix ``L`` of one scan (the input of every association method).

    With ``r_t`` the existence probability of track ``t`` (1 when not given), the weights are the
    factors of the joint association event's probability in JIPDA (Mušicki & Evans 2004, "Joint
    integrated probabilistic data association: JIPDA", IEEE Trans. Aerosp. Electron. Syst. 40(3),
    the a posteriori joint-event probability; with ``r = 1`` it is the JPDA one, as in Stone
    Soup's ``PDAHypothesiser``):

    .. math::

        L[t, 0] = \log(1 − r_t P_D^t P_G^t), \qquad
        L[t, j] = \log P_D^t + \log r_t + \log N(z_j; ẑ_t, S_t) − \log λ_j
        \quad (j ≥ 1, \text{ in the gate}),

    and ``L[t, j] = −inf`` outside the gate (``nis[t, j] > γ``) or when the track or the
    measurement is padding. The detection weight uses the untruncated density: JIPDA's
    ``P_D P_G · p_j / λ`` has the gate-truncated ``p_j = N(z_j; ẑ, S) / P_G``, so ``P_G`` cancels
    there and survives only in the missed weight. Rows of invalid tracks are ``[0, −inf, …]``
    (never detected, weight 1), so they are neutral even for a method that ignores
    ``valid_tracks``.

    **Arguments:**

    - ``innovation_log_likelihood``: ``log N(z_j; ẑ_t, S_t)``, ``(T, M)`` (from
      :func:`measurement_likelihoods` vmapped over tracks), in log of inverse measurement units.
      Entries outside the gate or of padding may be anything, NaN included: they are replaced
      before any arithmetic, so neither the values nor their gradients see them.
    - ``nis``: ``yᵀ S⁻¹ y``, ``(T, M)``, dimensionless (NaN counts as outside the gate).
    - ``valid_tracks``: boolean ``(T,)``; ``valid_measurements``: boolean ``(M,)``.
    - ``prob_detect``: ``P_D``, in ``(0, 1]``, shape ``()`` or per track ``(T,)``.
    - ``clutter_density``: ``λ``, clutter measurements per unit measurement-space volume, > 0,
      shape ``()`` or per measurement ``(M,)`` (a non-homogeneous clutter map).
    - ``gate_threshold``: ``γ`` (:func:`gate_threshold`), a scalar; ``inf`` (default): no gate.
    - ``prob_gate``: ``P_G``, the probability mass inside ``γ``, in ``(0, 1]``, ``()`` or ``(T,)``;
      must match ``gate_threshold`` (default 1, no gate).
    - ``existence``: optional ``r``, in ``[0, 1]``, ``()`` or ``(T,)`` (JIPDA); default 1.

    ``prob_detect``, ``clutter_density``, ``prob_gate`` and ``existence`` may be traced, and ``L``
    is differentiable in each of them. Concrete values outside their ranges raise; traced ones
    become NaN in ``L`` (``ok`` False downstream).

    **Returns:** ``(L, in_gate)``: ``L`` ``(T, 1 + M)`` in the dtype of the log-likelihoods;
    ``in_gate`` boolean ``(T, M)``, True where ``L[:, 1:]`` is a detection weight.

    **Raises:** :class:`~jaxtrack.InputError` naming the argument for a wrong shape or a
    concrete value out of range.
    """
    loglik = jnp.asarray(innovation_log_likelihood)
    if not jnp.issubdtype(loglik.dtype, jnp.floating):
        loglik = loglik.astype(jnp.result_type(float))
    dtype = loglik.dtype
    check_shape("innovation_log_likelihood", loglik, [(None, None)])
    T, M = loglik.shape
    nis = jnp.asarray(nis, dtype)
    check_shape("nis", nis, [(T, M)])
    valid_tracks = jnp.asarray(valid_tracks, bool)
    check_shape("valid_tracks", valid_tracks, [(T,)])
    valid_measurements = jnp.asarray(valid_measurements, bool)
    check_shape("valid_measurements", valid_measurements, [(M,)])

    pd = _checked_probability("prob_detect", prob_detect, dtype, open_low=True, shapes=[(), (T,)])
    pg = _checked_probability("prob_gate", prob_gate, dtype, open_low=True, shapes=[(), (T,)])
    r = (jnp.ones((), dtype) if existence is None else
         _checked_probability("existence", existence, dtype, open_low=False, shapes=[(), (T,)]))
    lam = jnp.asarray(clutter_density, dtype)
    check_shape("clutter_density", lam, [(), (M,)])
    if is_concrete(lam):
        if not np.all(np.asarray(lam) > 0.0) or not np.all(np.isfinite(np.asarray(lam))):
            raise InputError(f"`clutter_density` must be finite and > 0; got {np.asarray(lam)}.")
    else:
        lam = nan_where_traced(lam, lambda v: ~(v > 0.0))
    gamma = jnp.asarray(gate_threshold, dtype)
    check_shape("gate_threshold", gamma, [()])

    pd_t = jnp.broadcast_to(pd, (T,))
    r_t = jnp.broadcast_to(r, (T,))
    pg_t = jnp.broadcast_to(pg, (T,))
    lam_m = jnp.broadcast_to(lam, (M,))

    # NaN NIS compares False, so a NaN pair is outside the gate.
    in_gate = valid_tracks[:, None] & valid_measurements[None, :] & (nis <= gamma)
    # Double where: out-of-gate entries (possibly NaN or ±inf) are replaced *before* the sum, so
    # the gradient of the selected branch never multiplies them (0 · NaN would be NaN).
    safe_loglik = jnp.where(in_gate, loglik, 0.0)
    detection = (jnp.log(pd_t) + jnp.log(r_t))[:, None] + safe_loglik - jnp.log(lam_m)[None, :]
    detection = jnp.where(in_gate, detection, -jnp.inf)
    missed = jnp.where(valid_tracks, jnp.log1p(-(r_t * pd_t * pg_t)), 0.0)
    return jnp.concatenate([missed[:, None], detection], axis=1), in_gate


def measurement_likelihoods(
    filter: AbstractFilter,
    model: AbstractStateSpaceModel,
    predicted_mean: Float[Array, " n"],
    predicted_cov: Float[Array, "n n"],
    measurements: Float[ArrayLike, "M m"],
    valid_measurements: Bool[ArrayLike, " M"],
    k,
) -> tuple[Float[Array, " M"], Float[Array, " M"], Conditioned]:
    r"""Each measurement of a scan conditioned on ONE track's prediction: likelihoods and NIS.

    ``filter.update(model, x̂, P, z_j, observed, k)`` is ``jax.vmap``-ed over the ``M``
    measurements, so any jaxtrack filter (Kalman, extended, unscented, square-root) gives its own
    ``ẑ``, ``S`` and innovation (angle components wrapped by the model's ``residual``). From each
    :class:`~jaxtrack.filters.Conditioned`:

    .. math::

        \ell_j = \log N(y_j; 0, S) \quad(\texttt{log\_likelihood}), \qquad
        \mathrm{nis}_j = y_jᵀ S⁻¹ y_j = \lVert L_S^{-1} y_j \rVert^2,\ S = L_S L_Sᵀ

    (the NIS of Bar-Shalom, Li & Kirubarajan 2001, §5.4.2), with ``L_S`` the Cholesky factor of the
    innovation covariance (carried directly by a square-root filter).

    Padded measurements (``valid_measurements`` False) may hold anything, NaN included: they are
    replaced by zeros before the update, so no NaN reaches a value or a gradient; their
    ``log_likelihood`` is ``−inf`` and their ``nis`` ``+inf`` (outside every gate), and their
    rows of the returned ``Conditioned`` are the (finite, meaningless) update on ``z = 0``.

    **Arguments:**

    - ``filter``: any :class:`~jaxtrack.filters.AbstractFilter`; ``model``: its model.
    - ``predicted_mean``: ``x̂_{k/k−1}``, ``(n,)``; ``predicted_cov``: ``P_{k/k−1}``, ``(n, n)``
      (its Cholesky factor for a square-root filter), in the state's units.
    - ``measurements``: ``(M, m)``, in the model's measurement units (radians for angles).
    - ``valid_measurements``: boolean ``(M,)``.
    - ``k``: the step index (per-step model arrays are read at ``k``), an int scalar.

    **Returns:** ``(log_likelihood, nis, conditioned)``: ``(M,)`` log densities (log of inverse
    measurement units), ``(M,)`` dimensionless NIS, and the ``Conditioned`` batch with a leading
    ``M`` axis (the filtered mean and covariance of "measurement ``j`` is this track's").
    """
    dtype = jnp.asarray(predicted_mean).dtype
    z = jnp.asarray(measurements, dtype)
    check_shape("measurements", z, [(None, None)])
    M, m = z.shape
    valid = jnp.asarray(valid_measurements, bool)
    check_shape("valid_measurements", valid, [(M,)])
    z_safe = jnp.where(valid[:, None], z, 0.0)
    observed = jnp.ones((m,), bool)
    square_root = filter.square_root

    def one(zj):
        cond = filter.update(model, predicted_mean, predicted_cov, zj, observed, k)
        if square_root:
            chol_inv = tril_inverse(cond.innovation_cov)
        else:
            _, chol_inv = cholesky_and_inverse(cond.innovation_cov)
        whitened = matmul(chol_inv, cond.innovation)
        return cond.log_likelihood, whitened @ whitened, cond

    loglik, nis, conditioned = jax.vmap(one)(z_safe)
    loglik = jnp.where(valid, loglik, -jnp.inf)
    nis = jnp.where(valid, nis, jnp.inf)
    return loglik, nis, conditioned

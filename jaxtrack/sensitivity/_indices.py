r"""Sensitivity matrices and indices for a parameter α (Ho 1968, Sec. II-C to II-E), analytic or autodiff.

A parameter ``α`` enters through ``model_fn(α) -> LinearGaussianModel`` (see
:mod:`jaxtrack.sensitivity._recursions` for how, and for the index conventions):

- :func:`covariance_sensitivity`: ``∂P_{k/k-1}/∂α``, ``∂P_{k/k}/∂α`` for every step, by the forward
  recursion (46)–(48) or ``jax.jacfwd``/``jax.jacrev``;
- :func:`sensitivity_index`: ``S_α = ∂J/∂α`` for ``J = tr(L_{T/T} P_{T/T})`` by the adjoint
  (43), (52)–(54) pulled back through ``model_fn``, or ``jax.grad``;
- :func:`time_fixed_sensitivity`: the time-fixed correction (50);
- :func:`segment_sensitivity`: Ho's segment indices ``s(τ_i)`` (Convention 3 of the spec).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError, covariance_ok, is_concrete
from ..covariance import covariance_recursion
from ..filters._base import FirstStep
from ..models import LinearGaussianModel
from ._recursions import (
    Adjoint,
    Analytic,
    Autodiff,
    GainArg,
    Method,
    ModelFn,
    _analytic_adjoint,
    _check_first_step,
    _check_method,
    _check_weight,
    _gain_and_tangent,
    _gain_value,
    _history,
    _i_minus_wh,
    _model_of,
    _previous_filtered,
    _stepwise,
    adjoint,
    tangent_recursion,
)

__all__ = [
    "CovarianceSensitivity",
    "SegmentSensitivity",
    "covariance_sensitivity",
    "sensitivity_index",
    "time_fixed_sensitivity",
    "segment_sensitivity",
]


class CovarianceSensitivity(eqx.Module):
    """$∂P_{k/k-1}/∂α$ and $∂P_{k/k}/∂α$ for every step (eqs. (44), (46)–(47)).

    Shapes ``(T, n, n, *α.shape)``, as ``jax.jacfwd`` would return them; units of ``P`` per
    unit of ``α`` (e.g. ft²/s for τ in seconds).
    """

    d_predicted_cov: Float[Array, "T n n ..."]
    d_filtered_cov: Float[Array, "T n n ..."]


class SegmentSensitivity(NamedTuple):
    """Segment sensitivities of ``J`` to each segment's period (spec §4.1, Convention 3).

    - ``time_fixed`` ``(S,)``: ``s_i`` with the segment boundaries held fixed in time (Ho's
      ``s(τ_i)``, Figs. 8, 11, 13), units of ``J`` per second.
    - ``sample_fixed`` ``(S,)``: ``∂J/∂τ_i`` with the sample count held fixed (eq. (52)).
    - ``stage_count`` ``(S,)``: ``|K_i|``, the intervals each segment owns.
    - ``segment_end`` ``(S,)``: ``e_i``, the index of each segment's last sample.
    """

    time_fixed: np.ndarray
    sample_fixed: np.ndarray
    stage_count: np.ndarray
    segment_end: np.ndarray


def _checked_inputs(model_fn: ModelFn, alpha: ArrayLike, method, first_step, num_steps=None):
    """The common entry checks: ``(method, alpha as a float array, model_fn(alpha))``.

    ``num_steps`` is checked against the model's per-step length here, so a mismatch names
    ``num_steps`` (the covariance recursion underneath would blame its internal measurements).
    """
    method = _check_method(method)
    _check_first_step(first_step)
    alpha = jnp.asarray(alpha, dtype=jnp.result_type(float))
    model = _model_of(model_fn, alpha)
    if num_steps is not None:
        if not isinstance(num_steps, (int, np.integer)) or isinstance(num_steps, bool) or num_steps < 1:
            raise InputError(f"`num_steps` must be a positive int; got {num_steps!r}.")
        if model.num_steps is not None and model.num_steps != num_steps:
            raise InputError(
                f"`num_steps` is {num_steps} but `model_fn(alpha)` has per-step arrays of "
                f"{model.num_steps} steps; pass num_steps={model.num_steps} or leave it out."
            )
    return method, alpha, model


def _guard_traced_model(model: LinearGaussianModel, out):
    """Attach run-time checks of ``model_fn(alpha)``'s covariances to ``out`` when they are traced.

    A model built eagerly is checked by its constructor (e.g. a negative τ raises
    ``InputError``); under ``jit``/``vmap``/``grad`` the constructor cannot look at the values, and
    an invalid model (a negative τ makes Ho's Q and R negative) gives a finite, meaningless
    index. ``equinox.error_if`` raises at run time instead. One batched ``eigvalsh`` over the
    model's covariances, outside the recursions.
    """
    leaves = (model.Q, model.R, model.initial_cov)
    if all(is_concrete(a) for a in leaves):
        return out
    checks = (
        ("process_noise_cov", covariance_ok(model.Q, definite=False)),
        ("measurement_noise_cov", covariance_ok(model.R)),
        ("initial_cov", covariance_ok(model.initial_cov)),
    )
    for name, ok in checks:
        out = eqx.error_if(
            out,
            ~ok,
            f"jaxtrack: `model_fn(alpha)` gives a model whose `{name}` is not a finite, symmetric, "
            f"positive {'semi' if name == 'process_noise_cov' else ''}definite covariance; "
            f"check `alpha` (e.g. a sampling period τ must be > 0, a noise level ≥ 0).",
        )
    return out


def covariance_sensitivity(
    model_fn: ModelFn,
    alpha: ArrayLike,
    num_steps: int | None = None,
    *,
    method: Method = Analytic(),
    gain: GainArg = None,
    mask: ArrayLike | None = None,
    first_step: FirstStep = "update",
) -> CovarianceSensitivity:
    r"""Sensitivity matrices $∂P_{k/k-1}/∂α$, $∂P_{k/k}/∂α$ of every step (Ho 1968, Sec. II-C).

    ``α`` is any scalar or array parameter on which the model depends through
    ``model_fn(α) -> LinearGaussianModel``: a sampling period (Φ and Q depend on τ), a plant-noise
    level ``d`` (only Q), a measurement-noise level ``r`` (only R), a whole per-step schedule
    ``τ_k``, a prior scale…

    - ``method=Analytic()``: the forward recursion (46)–(48) driven by
      ``(∂Φ/∂α, ∂Q/∂α, ∂R/∂α, ∂P_{0/-1}/∂α)`` from ``jax.jvp(model_fn)``, one pass per component
      of α (vmapped).
    - ``method=Autodiff()``: ``jax.jacfwd`` (default) or ``jax.jacrev`` (``Autodiff("rev")``) of
      :func:`~jaxtrack.covariance.covariance_recursion`.

    With the optimal gain (``gain=None``) or a fixed gain array, ``A'_k = 0`` (eq. (48)); a gain
    given as a function ``gain(α)`` contributes its ``A'_k``. These are SAMPLE-fixed derivatives:
    for the time-fixed derivative of a change of τ use :func:`time_fixed_sensitivity` (eq. (50)).

    **Arguments:**

    - ``model_fn``: ``α -> LinearGaussianModel`` (pure, jax-traceable).
    - ``alpha``: the nominal parameter, shape ``()`` or any array shape ``a``.
    - ``num_steps``: ``T``; defaults to the model's per-step length.
    - ``gain``: ``None`` (optimal), a fixed ``(n, m)``/``(T, n, m)`` array, or ``gain(α)``.
    - ``mask``: optional missing-measurement mask ``(T,)`` or ``(T, m)``.
    - ``first_step``: ``"update"`` (prior on the first sample) or ``"predict"``.

    **Returns:** :class:`CovarianceSensitivity` with arrays of shape ``(T, n, n, *a)``.

    **Raises:** :class:`~jaxtrack.InputError` for a bad ``method``, ``model_fn``, ``first_step``
    or ``num_steps`` (not the model's per-step length); under tracing, ``equinox``'s runtime
    error for a model whose covariances are invalid (e.g. a negative τ).

    >>> import jax.numpy as jnp
    >>> from jaxtrack.models import ho_plant
    >>> s = covariance_sensitivity(lambda tau: ho_plant(jnp.full(50, tau)), 0.1)
    >>> round(float(s.d_filtered_cov[-1, 0, 0]), 3)   # ∂P_T(1,1)/∂τ, ft²/s (spec T8)
    2701.741
    """
    method, alpha, model = _checked_inputs(model_fn, alpha, method, first_step, num_steps)

    if isinstance(method, Autodiff):

        def covs(a):
            h = _history(model_fn(a), num_steps, _gain_value(gain, a), mask, first_step)
            return h.predicted_cov, h.filtered_cov

        jac = jax.jacrev if method.mode == "rev" else jax.jacfwd
        d_pred, d_filt = jac(covs)(alpha)
        return _guard_traced_model(model, CovarianceSensitivity(d_pred, d_filt))

    history = _history(model, num_steps, _gain_value(gain, alpha), mask, first_step)

    def along(direction):
        _, tangent = jax.jvp(model_fn, (alpha,), (direction,))
        _, dW = _gain_and_tangent(gain, alpha, direction)
        return tangent_recursion(model, tangent, history, gain_tangent=dW, first_step=first_step)

    size = int(np.prod(alpha.shape))
    basis = jnp.eye(size, dtype=alpha.dtype).reshape(size, *alpha.shape)
    d_pred, d_filt = jax.vmap(along)(basis)  # (size, T, n, n)

    def to_jac(a):
        return jnp.moveaxis(a, 0, -1).reshape(*a.shape[1:], *alpha.shape)

    return _guard_traced_model(model, CovarianceSensitivity(to_jac(d_pred), to_jac(d_filt)))


def _model_cotangent(model, history, adj: Adjoint, first_step) -> LinearGaussianModel:
    """``∂J/∂(F, Q, H, R, P_{0/-1})`` from the adjoint: the analytic backward pass.

    Per step k (each follows from ``ΔJ = Σ tr(L ΔZ)``, eqs. (41), (53)–(54)):
    ``∂J/∂Q_k = L_{k/k-1}``, ``∂J/∂Φ_k = 2 L_{k/k-1} Φ_k P_{k-1/k-1}``,
    ``∂J/∂R_k = W_kᵀ L_{k/k} W_k``, ``∂J/∂H_k = −2 W_kᵀ L_{k/k}(I−W_kH_k)P_{k/k-1}``.
    """
    T = history.filtered_cov.shape[0]
    F, H = _stepwise(model, T)
    W, P_pred = history.gain, history.predicted_cov
    P_prev = _previous_filtered(model, history)
    mT = lambda a: jnp.swapaxes(a, -1, -2)  # noqa: E731
    L_filt, L_pred = adj
    I_WH = _i_minus_wh(W, H)
    cQ = L_pred
    cF = 2.0 * L_pred @ F @ P_prev
    cR = mT(W) @ L_filt @ W
    cH = -2.0 * mT(W) @ L_filt @ I_WH @ P_pred
    if first_step == "update":
        cP0 = L_pred[0]
        cQ = cQ.at[0].set(0.0)
        cF = cF.at[0].set(0.0)
    else:
        cP0 = F[0].T @ L_pred[0] @ F[0]

    def fit(cot, field):
        # A time-invariant field is shared by every step: its cotangent is the sum over steps.
        return jnp.sum(cot, axis=0) if field.ndim == cot.ndim - 1 else cot

    zeros = jax.tree_util.tree_map(jnp.zeros_like, model)
    return eqx.tree_at(
        lambda m: (m.F, m.Q, m.H, m.R, m.initial_cov),
        zeros,
        (fit(cF, model.F), fit(cQ, model.Q), fit(cH, model.H), fit(cR, model.R), cP0),
    )


def sensitivity_index(
    model_fn: ModelFn,
    alpha: ArrayLike,
    weight: ArrayLike,
    num_steps: int | None = None,
    *,
    method: Method = Analytic(),
    gain: GainArg = None,
    mask: ArrayLike | None = None,
    first_step: FirstStep = "update",
) -> Float[Array, "..."]:
    r"""Sensitivity index ``S_α = ∂J/∂α`` of ``J = tr(L_{T/T} P_{T/T})`` (Ho 1968, eqs. (51)–(54)).

    .. math::

        S_α = \mathrm{tr}\Big(L_{T/T}\frac{∂P_{T/T}}{∂α}\Big)
            = \sum_j \mathrm{tr}\Big(L_{j/j}\frac{∂Z_{j/j}}{∂α}\Big) \qquad (52)

    - ``method=Analytic()``: the adjoint (43) turned into ``∂J/∂(Φ_k, Q_k, R_k, H_k, P_{0/-1})``
      (the local-variation sum (52)–(54) term by term), pulled back to α with
      ``jax.vjp(model_fn)``: one backward pass for ALL components of α.
    - ``method=Autodiff()``: ``jax.grad`` (default) or ``jax.jacfwd`` (``Autodiff("fwd")``).

    **Arguments:** as :func:`covariance_sensitivity`, plus ``weight`` = ``L_{T/T}`` ``(n, n)``,
    finite. ``J = tr(L P)`` depends only on the symmetric part of ``L`` (``P`` is symmetric), so
    a non-symmetric weight is replaced by ``(L + Lᵀ)/2``: both methods then differentiate the
    same ``J`` (the analytic adjoint assumes a symmetric ``L``).

    **Returns:** ``S_α``, the shape of ``alpha``; units of ``J`` per unit of ``α``. Sample-fixed;
    see :func:`segment_sensitivity` for Ho's time-fixed segment indices.

    **Raises:** :class:`~jaxtrack.InputError` for a bad ``method``, ``model_fn``, ``first_step``,
    ``num_steps`` (not the model's per-step length) or ``weight`` (wrong shape, non-finite);
    under tracing, ``equinox``'s runtime error for a non-finite ``weight`` or a model whose
    covariances are invalid (e.g. a negative τ).
    """
    method, alpha, model = _checked_inputs(model_fn, alpha, method, first_step, num_steps)
    L_T = _check_weight(weight, model.state_dim)

    if isinstance(method, Autodiff):

        def J(a):
            h = _history(model_fn(a), num_steps, _gain_value(gain, a), mask, first_step)
            return jnp.trace(L_T @ h.filtered_cov[-1])

        index = jax.jacfwd(J)(alpha) if method.mode == "fwd" else jax.grad(J)(alpha)
        return _guard_traced_model(model, index)

    W_nominal = _gain_value(gain, alpha)
    history = _history(model, num_steps, W_nominal, mask, first_step)
    adj = _analytic_adjoint(model, history, L_T)
    _, pull_model = jax.vjp(model_fn, alpha)
    (index,) = pull_model(_model_cotangent(model, history, adj, first_step))
    if callable(gain):
        # A' of eq. (48): tr(L_k A'_k) = 2 tr(L_k b_k ∂W_kᵀ), b_k = W_k S_k − P_{k/k-1} H_kᵀ.
        T = history.filtered_cov.shape[0]
        _, H = _stepwise(model, T)
        R = jax.vmap(model.measurement_noise_cov)(jnp.arange(T))
        P_pred, W = history.predicted_cov, history.gain
        S = H @ P_pred @ jnp.swapaxes(H, -1, -2) + R
        bracket = W @ S - P_pred @ jnp.swapaxes(H, -1, -2)
        cW = 2.0 * adj.filtered @ bracket
        gain_value, pull_gain = jax.vjp(gain, alpha)
        if gain_value.ndim == 2:
            cW = jnp.sum(cW, axis=0)
        (from_gain,) = pull_gain(cW)
        index = index + from_gain
    return _guard_traced_model(model, index)


def time_fixed_sensitivity(
    d_filtered_cov: ArrayLike,
    filtered_cov: ArrayLike,
    tau: ArrayLike,
    stages: ArrayLike | None = None,
) -> Float[Array, "T n n"]:
    r"""Time-fixed sampling-period sensitivity (Ho 1968, Sec. II-D, eq. (50), Figs. 2–3).

    .. math::

        \frac{∂P'_{k/k}}{∂τ} = \frac{∂P_{k/k}}{∂τ} + \frac{k}{τ}\,[P_{k-1/k-1}(τ) − P_{k/k}(τ)] \qquad (50)

    ``∂P_{k/k}/∂τ`` holds the sample index fixed (sample ``k`` moves to time ``k(τ+Δτ)``);
    ``∂P'`` interpolates linearly in time between consecutive POSTERIOR covariances back to the
    original time ``kτ``, so it is the derivative at a fixed time. ``k`` is the number of
    intervals whose period changed (the time shift is ``kΔτ``).

    **Arguments:**

    - ``d_filtered_cov``: ``∂P_{k/k}/∂τ``, ``(T, n, n)`` (e.g. from
      :func:`covariance_sensitivity` with a uniform τ).
    - ``filtered_cov``: ``P_{k/k}``, ``(T, n, n)``.
    - ``tau``: the period τ, seconds, scalar > 0.
    - ``stages``: ``k`` for each step, ``(T,)``; by default the step index (uniform τ with the prior
      on the first sample: sample ``k`` has ``k`` intervals before it).

    **Returns:** ``∂P'_{k/k}/∂τ``, ``(T, n, n)``; step 0 is unchanged.
    """
    dP = jnp.asarray(d_filtered_cov)
    P = jnp.asarray(filtered_cov)
    if dP.shape != P.shape or dP.ndim != 3:
        raise InputError(
            f"`d_filtered_cov` and `filtered_cov` must both be (T, n, n); got {dP.shape} and {P.shape}."
        )
    T = P.shape[0]
    k = jnp.arange(T, dtype=P.dtype) if stages is None else jnp.asarray(stages, P.dtype)
    if k.shape != (T,):
        raise InputError(f"`stages` must have shape ({T},); got {k.shape}.")
    slope = jnp.concatenate([jnp.zeros_like(P[:1]), P[:-1] - P[1:]], axis=0)
    return dP + (k / jnp.asarray(tau, P.dtype))[:, None, None] * slope


def segment_sensitivity(
    model_fn: ModelFn,
    segment_taus: ArrayLike,
    counts: Sequence[int],
    weight: ArrayLike,
    *,
    method: Method = Analytic(),
) -> SegmentSensitivity:
    r"""Ho's segment sensitivities ``s(τ_i)`` with segment boundaries fixed in time (spec §4.1).

    Convention 3 of ``specs/ho-sensitivity.md`` (it reproduces the memo's 227 and 331 ft²/s):

    .. math::

        s_i = \sum_{k∈K_i}\mathrm{tr}\Big(L_{k/k}\frac{∂Z_{k/k}}{∂τ_i}\Big)
            + \frac{|K_i|}{τ_i}\,\mathrm{tr}\big(L_{e_i/e_i}(P_{e_i-1/e_i-1} − P_{e_i/e_i})\big)

    the sample-fixed index (52) plus the time-fixed correction (50) applied at the END of segment
    ``i`` (``e_i``, its last sample, with ``k = |K_i|`` intervals) and carried to ``T`` by the
    adjoint. ``K_i`` are the steps whose preceding interval lies in segment ``i``: ``n_i`` of them,
    ``n_1 − 1`` for the first segment because the prior sits on the first sample (the memo is
    ambiguous there; spec §6 item 3).

    **Arguments:**

    - ``model_fn``: ``segment_taus -> LinearGaussianModel`` with ``Σ counts`` steps, prior on the
      first sample (``first_step="update"``), e.g.
      ``lambda t: ho_plant(jnp.repeat(t, counts, total_repeat_length=sum(counts)))``.
    - ``segment_taus``: ``(S,)`` periods τ_i, seconds.
    - ``counts``: ``(n_1, …, n_S)`` samples per segment.
    - ``weight``: ``L_{T/T}``, ``(n, n)``.
    - ``method``: how the sample-fixed index and the adjoint are computed.

    **Returns:** :class:`SegmentSensitivity` (numpy arrays).
    """
    counts = [int(c) for c in counts]
    taus = jnp.asarray(segment_taus, dtype=jnp.result_type(float))
    if taus.shape != (len(counts),):
        raise InputError(f"`segment_taus` must have shape ({len(counts)},) to match `counts`; got {taus.shape}.")
    model = _model_of(model_fn, taus)
    T = sum(counts)
    sample_fixed = sensitivity_index(model_fn, taus, weight, T, method=method)
    adj = adjoint(model, weight, T, method=method if isinstance(method, Analytic) else Autodiff("rev"))
    P = covariance_recursion(model, T).filtered_cov
    ends = np.cumsum(counts) - 1
    stage_count = np.array(counts) - np.eye(len(counts), dtype=int)[0]
    e = jnp.asarray(ends)
    prev = jnp.asarray(np.maximum(ends - 1, 0))
    correction = jnp.einsum("sij,sji->s", adj.filtered[e], P[prev] - P[e])
    correction = jnp.where(jnp.asarray(ends) > 0, correction, 0.0) * jnp.asarray(stage_count) / taus
    return SegmentSensitivity(
        np.asarray(sample_fixed + correction), np.asarray(sample_fixed), stage_count, ends
    )

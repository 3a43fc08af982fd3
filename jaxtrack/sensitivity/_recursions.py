r"""First-order covariance sensitivity: Ho's (1968) recursions and their autodiff twins.

Everything here is first order in the parameter change and is available two ways, with one call
shape, selected by ``method``:

- :class:`Analytic` — the memo's own recursions: local variations (31)/(53)–(54), the forward
  sensitivity matrices (46)–(48), error-transition matrices (34)–(35), the adjoint (42)–(43) and
  the sensitivity index (51)–(52);
- :class:`Autodiff` — ``jax.jacfwd``/``jax.jacrev``/``jax.grad`` through
  :func:`jaxtrack.covariance.covariance_recursion`, the same scan the filters run.

The tests hold each pair against the other to rounding.

How a parameter enters
----------------------
A parameter ``α`` (a scalar, or an array such as one τ per step) enters through a *model
function* ``model_fn(α) -> LinearGaussianModel``: Ho's ``∂Φ/∂α, ∂Q/∂α, ∂R/∂α, ∂P_{0/-1}/∂α``
are its Jacobian, which the analytic path obtains with ``jax.jvp`` (forward) or pulls back with
``jax.vjp`` (the adjoint path) — the chain rule through the model's construction, not through the
filter. A gain that depends on α (a suboptimal filter, eq. (48)) is passed as a function
``gain(α)``; an array gain is held fixed; ``None`` means the optimal gain, for which ``A' = 0``.

Index conventions (as in :mod:`jaxtrack.models`): per-step arrays are indexed by the step they
lead INTO, so ``F[k]`` is Ho's ``Φ_{k-1}`` and ``Q[k]`` his ``Q_{k-1}``. With
``first_step="update"`` (Ho's examples) the prior ``P_{0/-1}`` sits on the first sample and
``F[0]``, ``Q[0]`` are unused.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError
from ..covariance import CovarianceHistory, covariance_recursion
from ..filters._base import FirstStep
from ..models import LinearGaussianModel

__all__ = [
    "Analytic",
    "Autodiff",
    "LocalVariation",
    "Adjoint",
    "CovarianceSensitivity",
    "SegmentSensitivity",
    "local_variations",
    "tangent_recursion",
    "error_transition",
    "adjoint",
    "first_order_variation",
    "multistage_variation",
    "covariance_sensitivity",
    "sensitivity_index",
    "time_fixed_sensitivity",
    "segment_sensitivity",
]

ModelFn = Callable[[Array], LinearGaussianModel]
GainArg = ArrayLike | Callable[[Array], Array] | None


class Analytic(eqx.Module):
    """Compute with Ho's (1968) analytic recursions (forward (46)–(48); adjoint (42)–(43), (52))."""


class Autodiff(eqx.Module):
    """Compute by automatic differentiation through the covariance recursion.

    ``mode``: ``"fwd"`` (``jax.jacfwd``; cheapest for few parameters and the default for
    sensitivity matrices) or ``"rev"`` (``jax.jacrev``/``jax.grad``; cheapest for a scalar
    criterion of many parameters and the default for indices and adjoints). ``None`` picks the
    cheaper one for the function it is passed to.
    """

    mode: Literal["fwd", "rev"] | None = eqx.field(default=None, static=True)

    def __check_init__(self):
        if self.mode not in (None, "fwd", "rev"):
            raise InputError(f"`Autodiff(mode=...)` must be 'fwd', 'rev' or None; got {self.mode!r}.")


Method = Analytic | Autodiff


class LocalVariation(NamedTuple):
    """One-stage (local) variations, all steps: ``ΔZ_{k/k-1}``, ``ΔZ_{k/k}``, each ``(T, n, n)``.

    Per unit of the parameter when built from a tangent (``∂Z/∂α``, eqs. (53)–(54)).
    """

    predicted_cov: Float[Array, "T n n"]
    filtered_cov: Float[Array, "T n n"]


class Adjoint(NamedTuple):
    """Adjoint matrices ``L_{k/k}`` (eqs. (42)–(43)) and ``L_{k/k-1} = (I−W_kH_k)ᵀ L_{k/k} (I−W_kH_k)``.

    ``L_{k/k} = ∂J/∂P_{k/k}`` and ``L_{k/k-1} = ∂J/∂P_{k/k-1}`` (symmetric) for
    ``J = tr(L_{T/T} P_{T/T})``; each ``(T, n, n)``, dimension of ``J`` per unit of ``P``.
    """

    filtered: Float[Array, "T n n"]
    predicted: Float[Array, "T n n"]


class CovarianceSensitivity(eqx.Module):
    """``∂P_{k/k-1}/∂α`` and ``∂P_{k/k}/∂α`` for every step (eqs. (44), (46)–(47)).

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


# ----------------------------------------------------------------------------------------------
# Inputs


def _check_method(method) -> Method:
    if not isinstance(method, (Analytic, Autodiff)):
        raise InputError(f"`method` must be Analytic() or Autodiff(); got {method!r}.")
    return method


def _check_first_step(first_step) -> None:
    if first_step not in ("update", "predict"):
        raise InputError(f"`first_step` must be 'update' or 'predict'; got {first_step!r}.")


def _model_of(model_fn: ModelFn, alpha: Array) -> LinearGaussianModel:
    if not callable(model_fn):
        raise InputError("`model_fn` must be a function alpha -> LinearGaussianModel.")
    model = model_fn(alpha)
    if not isinstance(model, LinearGaussianModel):
        raise InputError(
            f"`model_fn` must return a LinearGaussianModel; got {type(model).__name__}. "
            "Covariance sensitivities need a linear(ised) model: linearise a nonlinear one first."
        )
    return model


def _gain_and_tangent(gain: GainArg, alpha, dalpha):
    """The gain schedule and its tangent along ``dalpha`` (zero unless ``gain`` depends on α)."""
    if gain is None:
        return None, None
    if callable(gain):
        return jax.jvp(gain, (alpha,), (dalpha,))
    return jnp.asarray(gain), None


def _gain_value(gain: GainArg, alpha):
    if callable(gain):
        return gain(alpha)
    return None if gain is None else jnp.asarray(gain)


def _per_step(W: Array | None, num_steps: int) -> Array | None:
    if W is None or W.ndim == 3:
        return W
    return jnp.broadcast_to(W, (num_steps, *W.shape))


def _history(model, num_steps, gain, mask, first_step) -> CovarianceHistory:
    return covariance_recursion(model, num_steps, gain=gain, mask=mask, first_step=first_step)


def _previous_filtered(model: LinearGaussianModel, history: CovarianceHistory) -> Array:
    """``P_{k-1/k-1}`` aligned with step ``k``; step 0 gets ``initial_cov`` (``P_{-1/-1}`` in
    predict-first mode, unused in update-first mode)."""
    return jnp.concatenate([model.initial_cov[None], history.filtered_cov[:-1]], axis=0)


def _i_minus_wh(W: Array, H: Array) -> Array:
    """``I − W_k H_k`` for a stack of steps ``(T, n, n)`` (explicit batch axis on ``I``)."""
    WH = W @ H
    return jnp.eye(WH.shape[-1], dtype=WH.dtype)[None] - WH


def _stepwise(model: LinearGaussianModel, num_steps: int):
    ks = jnp.arange(num_steps)
    F = jax.vmap(model.transition_matrix)(ks)
    H = jax.vmap(model.measurement_matrix)(ks)
    return F, H


# ----------------------------------------------------------------------------------------------
# Analytic first-order recursions


def local_variations(
    model: LinearGaussianModel,
    tangent: LinearGaussianModel,
    history: CovarianceHistory,
    *,
    gain_tangent: ArrayLike | None = None,
    first_step: FirstStep = "update",
) -> LocalVariation:
    r"""One-stage local variations for every step (Ho 1968, eqs. (31), (53)–(54)).

    .. math::

        ΔZ_{k/k-1} = ΔQ_{k-1} + ΔΦ_{k-1} P_{k-1/k-1} Φ_{k-1}ᵀ + Φ_{k-1} P_{k-1/k-1} ΔΦ_{k-1}ᵀ

        ΔZ_{k/k} = (I − W_kH_k) ΔZ_{k/k-1} (I − W_kH_k)ᵀ + W_k ΔR_k W_kᵀ + A'_k
            − W_k ΔH_k P_{k/k-1}(I − W_kH_k)ᵀ − (I − W_kH_k) P_{k/k-1} ΔH_kᵀ W_kᵀ

    with ``ΔZ_{0/-1} = ΔP_{0/-1}`` and ``A'_k`` of eq. (48) (zero unless ``gain_tangent`` is
    given). These are the changes ``ΔP`` would make in ONE stage if ``ΔP_{k-1/k-1} = 0``; the
    ``ΔH`` terms go beyond the memo (which recasts ``ΔH`` as a ``ΔΦ``, eqs. (11)–(15)) and are
    the exact first-order effect of a measurement-matrix change at fixed or optimal gain.

    **Arguments** (``T`` steps, ``n`` states, ``m`` measurement components):

    - ``model``: the nominal :class:`~jaxtrack.models.LinearGaussianModel`.
    - ``tangent``: a model-shaped pytree of variations (``ΔΦ`` in ``F``, ``ΔQ`` in ``Q``, ``ΔR``
      in ``R``, ``ΔH`` in ``H``, ``ΔP_{0/-1}`` in ``initial_cov``), e.g. the tangent of
      ``jax.jvp(model_fn, (α,), (1.0,))``; per unit of α for ``∂Z/∂α``.
    - ``history``: the nominal :class:`~jaxtrack.covariance.CovarianceHistory`.
    - ``gain_tangent``: ``ΔW_k``, ``(n, m)`` or ``(T, n, m)``, for a gain schedule that changes.
    - ``first_step``: as in :func:`~jaxtrack.filters.run_filter`.

    **Returns:** :class:`LocalVariation` ``(ΔZ_{k/k-1}, ΔZ_{k/k})``, each ``(T, n, n)``.
    """
    _check_first_step(first_step)
    T = history.filtered_cov.shape[0]
    n = model.state_dim
    F, H = _stepwise(model, T)
    dF, dH = _stepwise(tangent, T)
    ks = jnp.arange(T)
    dQ = jax.vmap(tangent.process_noise_cov)(ks)
    dR = jax.vmap(tangent.measurement_noise_cov)(ks)
    P_prev = _previous_filtered(model, history)
    P_pred, W = history.predicted_cov, history.gain
    R = jax.vmap(model.measurement_noise_cov)(ks)

    mT = lambda a: jnp.swapaxes(a, -1, -2)  # noqa: E731
    dZ_pred = dQ + dF @ P_prev @ mT(F) + F @ P_prev @ mT(dF)
    if first_step == "update":
        dZ_pred = dZ_pred.at[0].set(tangent.initial_cov)
    else:
        # P_{0/-1} = F_0 P_{-1/-1} F_0ᵀ + Q_0: a change of initial_cov propagates in one stage.
        dZ_pred = dZ_pred.at[0].add(F[0] @ tangent.initial_cov @ F[0].T)
    I_WH = _i_minus_wh(W, H)
    dZ_filt = (
        I_WH @ dZ_pred @ mT(I_WH)
        + W @ dR @ mT(W)
        - W @ dH @ P_pred @ mT(I_WH)
        - I_WH @ P_pred @ mT(dH) @ mT(W)
    )
    if gain_tangent is not None:
        dW = _per_step(jnp.asarray(gain_tangent), T)
        S = H @ P_pred @ mT(H) + R
        bracket = W @ S - P_pred @ mT(H)  # eq. (48); zero for the optimal gain (B.7)
        dZ_filt = dZ_filt + bracket @ mT(dW) + dW @ mT(bracket)
    return LocalVariation(dZ_pred, dZ_filt)


def tangent_recursion(
    model: LinearGaussianModel,
    tangent: LinearGaussianModel,
    history: CovarianceHistory,
    *,
    gain_tangent: ArrayLike | None = None,
    first_step: FirstStep = "update",
) -> tuple[Float[Array, "T n n"], Float[Array, "T n n"]]:
    r"""Forward sensitivity recursion (Ho 1968, eqs. (46)–(48); (32) for a finite first-order ΔP).

    .. math::

        \frac{∂P_{k/k}}{∂α} = (I − W_kH_k)\frac{∂P_{k/k-1}}{∂α}(I − W_kH_k)ᵀ
            + W_k\frac{∂R_k}{∂α}W_kᵀ + A'_k \qquad (46)

        \frac{∂P_{k+1/k}}{∂α} = Φ_k\frac{∂P_{k/k}}{∂α}Φ_kᵀ + \frac{∂Q_k}{∂α}
            + \frac{∂Φ_k}{∂α}P_{k/k}Φ_kᵀ + Φ_kP_{k/k}\frac{∂Φ_k}{∂α}ᵀ \qquad (47)

    i.e. the propagation of the local variations :func:`local_variations`:
    ``∂P_{k/k} = (I−W_kH_k)Φ_{k-1} ∂P_{k-1/k-1} Φ_{k-1}ᵀ(I−W_kH_k)ᵀ + ∂Z_{k/k}`` (eq. (32)),
    one ``jax.lax.scan``. Arguments as for :func:`local_variations`.

    **Returns:** ``(∂P_{k/k-1}/∂α, ∂P_{k/k}/∂α)``, each ``(T, n, n)``.
    """
    local = local_variations(model, tangent, history, gain_tangent=gain_tangent, first_step=first_step)
    T = history.filtered_cov.shape[0]
    F, H = _stepwise(model, T)
    I_WH = _i_minus_wh(history.gain, H)
    zero = jnp.zeros_like(model.initial_cov)

    def step(dP_filt_prev, inputs):
        F_k, I_WH_k, dZp, dZf = inputs
        dP_pred = F_k @ dP_filt_prev @ F_k.T + dZp
        dP_filt = I_WH_k @ (dP_pred - dZp) @ I_WH_k.T + dZf
        return dP_filt, (dP_pred, dP_filt)

    if first_step == "update":
        F = F.at[0].set(jnp.zeros_like(F[0]))  # no transition into the first sample
    _, (dP_pred, dP_filt) = jax.lax.scan(step, zero, (F, I_WH, local.predicted_cov, local.filtered_cov))
    return dP_pred, dP_filt


def error_transition(
    model: LinearGaussianModel,
    history: CovarianceHistory,
) -> Float[Array, "T n n"]:
    r"""Error-transition matrices ``D_{T,j}`` for ``j = 0, …, T`` (Ho 1968, eqs. (34)–(35)).

    .. math::

        D_{T,j} = D_{T,j+1}(I − W_{j+1}H_{j+1})Φ_j, \qquad D_{T,T} = I

    (``T`` is the last step; the result's row ``j`` is ``D_{T,j}``, so the last row is ``I``).
    ``D_{T,j}`` carries an error present after the update at ``j`` to the error after the update
    at ``T`` (with fixed gains), so a local variation ``ΔZ_{j/j}`` changes ``P_{T/T}`` by
    ``D_{T,j} ΔZ_{j/j} D_{T,j}ᵀ`` (eq. (33)).

    **Returns:** ``(T+1 steps, n, n)``: shape ``(num_steps, n, n)``.
    """
    T = history.filtered_cov.shape[0]
    F, H = _stepwise(model, T)
    I_WH = _i_minus_wh(history.gain, H)
    # M_{j+1} = (I − W_{j+1}H_{j+1}) Φ_j maps the error after update j to after update j+1.
    M = I_WH[1:] @ F[1:]

    def step(D_next, M_next):
        D = D_next @ M_next
        return D, D

    eye = jnp.eye(model.state_dim, dtype=F.dtype)
    _, D = jax.lax.scan(step, eye, M, reverse=True)
    return jnp.concatenate([D, eye[None]], axis=0)


def _analytic_adjoint(model, history, weight) -> Adjoint:
    T = history.filtered_cov.shape[0]
    F, H = _stepwise(model, T)
    I_WH = _i_minus_wh(history.gain, H)
    # F_next[k] = Φ_k (into step k+1); the last entry is unused.
    F_next = jnp.concatenate([F[1:], jnp.zeros_like(F[:1])], axis=0)

    def step(L_next_pred, inputs):
        F_k, I_WH_k, is_last = inputs
        # eq. (43): L_{k/k} = Φ_kᵀ L_{k+1/k} Φ_k, with L_{k+1/k} = (I−W H)ᵀ L_{k+1/k+1} (I−W H).
        L_filt = jnp.where(is_last, weight, F_k.T @ L_next_pred @ F_k)
        L_pred = I_WH_k.T @ L_filt @ I_WH_k
        return L_pred, (L_filt, L_pred)

    is_last = jnp.arange(T) == T - 1
    zero = jnp.zeros_like(weight)
    _, (L_filt, L_pred) = jax.lax.scan(step, zero, (F_next, I_WH, is_last), reverse=True)
    return Adjoint(L_filt, L_pred)


def _check_weight(weight, n) -> Array:
    L = jnp.asarray(weight)
    if L.shape != (n, n):
        raise InputError(f"`weight` (L_T/T) must have shape ({n}, {n}); got {L.shape}.")
    return L


def adjoint(
    model: LinearGaussianModel,
    weight: ArrayLike,
    num_steps: int | None = None,
    *,
    method: Method = Analytic(),
    gain: ArrayLike | None = None,
    mask: ArrayLike | None = None,
    first_step: FirstStep = "update",
) -> Adjoint:
    r"""Adjoint matrices of ``J = tr(L_{T/T} P_{T/T})`` (Ho 1968, eqs. (41)–(43)).

    .. math::

        L_{k-1/k-1} = Φ_{k-1}ᵀ(I − W_kH_k)ᵀ L_{k/k}(I − W_kH_k)Φ_{k-1}, \qquad
        ΔJ = \sum_j \mathrm{tr}(L_{j/j} ΔZ_{j/j}) \qquad (41)–(43)

    run backwards from ``L_{T/T} = weight``. ``L_{k/k} = ∂J/∂P_{k/k}``: the terminal cost per unit
    change of the covariance at step ``k``, with gains held fixed or recomputed optimally (the two
    agree to first order at the optimum; spec §2.3). Fig. 9 of the memo plots its diagonal.

    - ``method=Analytic()``: the backward recursion (43).
    - ``method=Autodiff()``: reverse mode: ``L_{k/k-1} = ∂J/∂Q_{k-1}`` and
      ``L_{k/k} = Φ_kᵀ (∂J/∂Q_k) Φ_k`` by ``jax.grad`` through the covariance recursion
      (symmetrised). With ``gain`` given the gains are held; otherwise they are recomputed.

    **Arguments:** ``model`` (:class:`~jaxtrack.models.LinearGaussianModel`), ``weight``
    ``L_{T/T}`` ``(n, n)`` (e.g. ``diag(1, 0)`` for the position variance; Ho's "rss" error,
    eq. (40), is a sum of variances), ``num_steps``, ``gain`` ``(n, m)``/``(T, n, m)`` (fixed
    suboptimal gains), ``mask``, ``first_step``.

    **Returns:** :class:`Adjoint` ``(L_{k/k}, L_{k/k-1})``, each ``(T, n, n)``.
    """
    method = _check_method(method)
    _check_first_step(first_step)
    L_T = _check_weight(weight, model.state_dim)
    history = _history(model, num_steps, gain, mask, first_step)
    if isinstance(method, Analytic):
        return _analytic_adjoint(model, history, L_T)
    T = history.filtered_cov.shape[0]
    F, _ = _stepwise(model, T)
    Q = jax.vmap(model.process_noise_cov)(jnp.arange(T))
    if method.mode == "fwd":
        raise InputError("`adjoint` is a gradient of one scalar: use Autodiff('rev') or Autodiff().")

    def J(Q_steps, P0):
        m = eqx.tree_at(lambda m: (m.Q, m.initial_cov), model, (Q_steps, P0))
        P_T = covariance_recursion(m, T, gain=gain, mask=mask, first_step=first_step).filtered_cov[-1]
        return jnp.trace(L_T @ P_T)

    gQ, gP0 = jax.grad(J, argnums=(0, 1))(Q, model.initial_cov)
    sym = lambda a: 0.5 * (a + jnp.swapaxes(a, -1, -2))  # noqa: E731
    gQ, gP0 = sym(gQ), sym(gP0)
    L_pred = gQ.at[0].set(gP0) if first_step == "update" else gQ
    F_next = jnp.concatenate([F[1:], jnp.zeros_like(F[:1])], axis=0)
    L_filt = jnp.swapaxes(F_next, -1, -2) @ jnp.concatenate([gQ[1:], L_T[None]], axis=0) @ F_next
    L_filt = L_filt.at[-1].set(L_T)
    return Adjoint(L_filt, L_pred)


def first_order_variation(
    model: LinearGaussianModel,
    tangent: LinearGaussianModel,
    num_steps: int | None = None,
    *,
    first_step: FirstStep = "update",
) -> Float[Array, "n n"]:
    r"""First-order ``ΔP_{T/T}`` as a sum of local variations (Ho 1968, eqs. (31), (33)).

    .. math::  ΔP_{T/T} = \sum_j D_{T,j}\, ΔZ_{j/j}\, D_{T,j}ᵀ

    with ``ΔZ`` of eq. (31) from the finite variations in ``tangent`` (a model-shaped pytree:
    ``ΔΦ, ΔQ, ΔR, ΔH, ΔP_{0/-1}``) and ``D`` of eq. (34). Equal to the linearisation of the full
    recursion (``jax.jvp``); the exact change differs by ``O(ε²)``
    (:func:`~jaxtrack.sensitivity.exact_variation_recursion`).

    **Returns:** ``ΔP_{T/T}``, ``(n, n)``.
    """
    history = _history(model, num_steps, None, None, first_step)
    local = local_variations(model, tangent, history, first_step=first_step)
    D = error_transition(model, history)
    return jnp.sum(D @ local.filtered_cov @ jnp.swapaxes(D, -1, -2), axis=0)


def multistage_variation(
    model: LinearGaussianModel,
    tangent: LinearGaussianModel,
    boundaries: Sequence[int],
    num_steps: int | None = None,
    *,
    first_step: FirstStep = "update",
) -> tuple[Float[Array, "n n"], Float[Array, "S n n"]]:
    r"""``ΔP_{T/T}`` from multistage local variations (Ho 1968, eqs. (36)–(37), Fig. 1).

    The time axis is cut at samples ``j_1 < … < j_S = T``. On each piece ``(j_{i-1}, j_i]`` the
    first-order recursion (37) runs from ``ΔZ^{(j_{i-1})}_{j_{i-1}/j_{i-1}} = 0`` (the initial
    condition lost in the OCR; spec §6 item 14), and the pieces are carried to ``T`` by the
    error-transition matrices:

    .. math::  ΔP_{T/T} = \sum_i D_{T,j_i}\, ΔZ^{(j_{i-1})}_{j_i/j_i}\, D_{T,j_i}ᵀ \qquad (36)

    The first piece starts with ``ΔP_{0/-1}`` itself (the ``ΔZ_{0/-1}`` of eq. (31)).

    **Arguments:** ``tangent`` as in :func:`first_order_variation`; ``boundaries``: the sample
    indices ``j_1, …, j_S`` (increasing; the last one is ``T − 1``, the final sample).

    **Returns:** ``(ΔP_{T/T}, pieces)`` where ``pieces[i] = ΔZ^{(j_{i-1})}_{j_i/j_i}``.
    """
    history = _history(model, num_steps, None, None, first_step)
    T = history.filtered_cov.shape[0]
    b = [int(j) for j in boundaries]
    if not b or b != sorted(set(b)) or b[0] < 0 or b[-1] != T - 1:
        raise InputError(
            f"`boundaries` must be increasing sample indices ending at the final sample {T - 1}; got {boundaries!r}."
        )
    local = local_variations(model, tangent, history, first_step=first_step)
    F, H = _stepwise(model, T)
    I_WH = _i_minus_wh(history.gain, H)
    if first_step == "update":
        F = F.at[0].set(jnp.zeros_like(F[0]))
    restart = np.zeros(T, bool)
    restart[[j + 1 for j in b[:-1]]] = True  # the recursion restarts after each boundary sample

    def step(dP_prev, inputs):
        F_k, I_WH_k, dZf, fresh = inputs
        carried = jnp.where(fresh, jnp.zeros_like(dP_prev), dP_prev)
        dP = I_WH_k @ F_k @ carried @ F_k.T @ I_WH_k.T + dZf  # eq. (37)
        return dP, dP

    # The filtered local variation already contains the predicted one (eq. (31)).
    _, dP_all = jax.lax.scan(
        step, jnp.zeros_like(model.initial_cov), (F, I_WH, local.filtered_cov, jnp.asarray(restart))
    )
    D = error_transition(model, history)
    idx = jnp.asarray(b)
    pieces = dP_all[idx]
    total = jnp.sum(D[idx] @ pieces @ jnp.swapaxes(D[idx], -1, -2), axis=0)
    return total, pieces


# ----------------------------------------------------------------------------------------------
# Sensitivity matrices and indices for a parameter α, analytic or autodiff


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
    r"""Sensitivity matrices ``∂P_{k/k-1}/∂α``, ``∂P_{k/k}/∂α`` of every step (Ho 1968, Sec. II-C).

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

    **Raises:** :class:`~jaxtrack.InputError` for a bad ``method``, ``model_fn`` or
    ``first_step``.

    >>> import jax.numpy as jnp
    >>> from jaxtrack.models import ho_plant
    >>> s = covariance_sensitivity(lambda tau: ho_plant(jnp.full(50, tau)), 0.1)
    >>> round(float(s.d_filtered_cov[-1, 0, 0]), 3)   # ∂P_T(1,1)/∂τ, ft²/s (spec T8)
    2701.741
    """
    method = _check_method(method)
    _check_first_step(first_step)
    alpha = jnp.asarray(alpha, dtype=jnp.result_type(float))
    model = _model_of(model_fn, alpha)

    if isinstance(method, Autodiff):

        def covs(a):
            h = _history(model_fn(a), num_steps, _gain_value(gain, a), mask, first_step)
            return h.predicted_cov, h.filtered_cov

        jac = jax.jacrev if method.mode == "rev" else jax.jacfwd
        d_pred, d_filt = jac(covs)(alpha)
        return CovarianceSensitivity(d_pred, d_filt)

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

    return CovarianceSensitivity(to_jac(d_pred), to_jac(d_filt))


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

    **Arguments:** as :func:`covariance_sensitivity`, plus ``weight`` = ``L_{T/T}`` ``(n, n)``.

    **Returns:** ``S_α``, the shape of ``alpha``; units of ``J`` per unit of ``α``. Sample-fixed;
    see :func:`segment_sensitivity` for Ho's time-fixed segment indices.
    """
    method = _check_method(method)
    _check_first_step(first_step)
    alpha = jnp.asarray(alpha, dtype=jnp.result_type(float))
    model = _model_of(model_fn, alpha)
    L_T = _check_weight(weight, model.state_dim)

    if isinstance(method, Autodiff):

        def J(a):
            h = _history(model_fn(a), num_steps, _gain_value(gain, a), mask, first_step)
            return jnp.trace(L_T @ h.filtered_cov[-1])

        return jax.jacfwd(J)(alpha) if method.mode == "fwd" else jax.grad(J)(alpha)

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
    return index


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

r"""First-order covariance sensitivity: Ho's (1968) recursions and their autodiff twins.

This module holds the method strategies, the model-level recursions (local variations, forward
tangent recursion, error-transition matrices, adjoint, first-order and multistage variations) and
their shared inputs; :mod:`jaxtrack.sensitivity._indices` builds the parameter-level sensitivity
matrices and indices on them. Everything is first order in the parameter change and is available
two ways, with one call shape, selected by ``method``:

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

from .._validation import InputError, check_finite, is_concrete
from ..covariance import CovarianceHistory, covariance_recursion
from ..filters._base import FirstStep
from ..models import LinearGaussianModel

__all__ = [
    "Analytic",
    "Autodiff",
    "LocalVariation",
    "Adjoint",
    "local_variations",
    "tangent_recursion",
    "error_transition",
    "adjoint",
    "first_order_variation",
    "multistage_variation",
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

    **Arguments:**

    - ``model``: the :class:`~jaxtrack.models.LinearGaussianModel`.
    - ``history``: its :class:`~jaxtrack.covariance.CovarianceHistory` (gains ``W``, ``(num_steps, n, m)``).

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
    """``weight`` checked (shape, finite) and replaced by its symmetric part ``(L + Lᵀ)/2``.

    ``J = tr(L P) = tr(sym(L) P)`` for every symmetric ``P``, so only ``sym(L)`` is observable;
    the analytic recursions (adjoint (43), index (52)) assume a symmetric ``L`` (they use
    ``L_{k/k} = ∂J/∂P_{k/k}``, which is symmetric), while ``jax.grad`` differentiates ``tr(L P)``
    as written. Symmetrising makes both methods compute the same derivative of the same ``J``
    (a non-symmetric weight is a legitimate way to write a cross term, so it is not rejected).
    A non-finite weight raises ``InputError`` (concrete) or an ``equinox`` runtime error
    (traced).
    """
    L = jnp.asarray(weight)
    if L.shape != (n, n):
        raise InputError(f"`weight` (L_T/T) must have shape ({n}, {n}); got {L.shape}.")
    check_finite("weight", L)
    if not is_concrete(L):
        L = eqx.error_if(L, ~jnp.all(jnp.isfinite(L)), "`weight` (L_T/T) must be finite.")
    return 0.5 * (L + L.T)


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
    ``L_{T/T}`` ``(n, n)``, finite; only its symmetric part ``(L + Lᵀ)/2`` is used, since
    ``J = tr(L P)`` depends on nothing else (e.g. ``diag(1, 0)`` for the position variance; Ho's "rss" error,
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

    **Arguments:**

    - ``model``: the :class:`~jaxtrack.models.LinearGaussianModel`.
    - ``tangent``: the variations, a model-shaped pytree (same structure and shapes as ``model``).
    - ``num_steps``: ``T``; defaults to the model's per-step length.
    - ``first_step``: ``"update"`` (default) or ``"predict"``, as in
      :func:`~jaxtrack.covariance.covariance_recursion`.

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

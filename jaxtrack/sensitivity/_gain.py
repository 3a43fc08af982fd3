r"""Second-order effect of a gain change about the optimum (Ho 1968, Sec. II-F, eqs. (55)–(64)).

At the optimal gain ``W°`` the first-order terms vanish (eq. (B.7)), so a gain change
``ΔW_k`` costs ``ΔZ_{k/k} = ΔW_k S_k ΔW_kᵀ`` (eq. (57)), a SECOND-order, positive-semidefinite
change that propagates with the usual error transition (58)–(62):

.. math::

    ΔJ = \sum_k \mathrm{tr}(L_{k/k}\,ΔW_k S_k ΔW_kᵀ)
       = \sum_k \mathrm{tr}[(ΔW_kᵀ L_{k/k} ΔW_k) S_k] \qquad (61), (64)

with ``S_k = H_k P_{k/k-1} H_kᵀ + R_k`` and the adjoint ``L_{k/k}`` (eq. (62)). Allocating an
allowable ``(ΔJ)_k`` per step makes ``{ΔW_k : tr[(ΔW_kᵀ L_{k/k} ΔW_k) S_k] ≤ (ΔJ)_k}`` an ellipsoid
around ``W°_k``: the tolerance a designer may spend on a cheaper, suboptimal gain schedule.

The analytic quadratic form ``2 (S_k ⊗ L_{k/k})`` is the Hessian of ``J`` with respect to
``vec(W_k)`` at the optimum; :func:`gain_hessian` gives it both ways.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError
from ..covariance import covariance_recursion
from ..filters._base import FirstStep
from ..models import LinearGaussianModel
from ._recursions import Analytic, Method, _analytic_adjoint, _check_method, _check_weight, _i_minus_wh

__all__ = [
    "GainEllipsoid",
    "gain_variation_cost",
    "gain_variation_recursion",
    "allowable_gain_ellipsoid",
    "gain_hessian",
]


def _vec(W: Array) -> Array:
    """Column-major vec, so that ``vec(A X B) = (Bᵀ ⊗ A) vec(X)``."""
    return jnp.swapaxes(W, -1, -2).reshape(*W.shape[:-2], -1)


def gain_variation_cost(
    adjoint_filtered: ArrayLike,
    innovation_cov: ArrayLike,
    dW: ArrayLike,
) -> Float[Array, " T"]:
    r"""Terminal-cost increase of each step's gain change, ``tr[(ΔW_kᵀ L_{k/k} ΔW_k) S_k]`` (eq. (64)).

    **Arguments:** ``adjoint_filtered`` ``L_{k/k}`` ``(T, n, n)`` (e.g.
    :func:`~jaxtrack.sensitivity.adjoint`), ``innovation_cov`` ``S_k`` ``(T, m, m)`` (the
    :class:`~jaxtrack.covariance.CovarianceHistory`), ``dW`` ``ΔW_k`` ``(T, n, m)`` or
    ``(n, m)``.

    **Returns:** ``(ΔJ)_k`` per step, ``(T,)``, in units of ``J``; their sum is the
    second-order ``ΔJ`` of changing all gains at once (eq. (61)).
    """
    L, S, dW = (jnp.asarray(a) for a in (adjoint_filtered, innovation_cov, dW))
    if dW.ndim == 2:
        dW = jnp.broadcast_to(dW, (L.shape[0], *dW.shape))
    return jnp.einsum("tia,tij,tjb,tba->t", dW, L, dW, S)


def gain_variation_recursion(
    model: LinearGaussianModel,
    dW: ArrayLike,
    num_steps: int | None = None,
    *,
    first_step: FirstStep = "update",
) -> Float[Array, "T n n"]:
    r"""Second-order ``ΔP_{k/k}`` of gain changes about the optimum (Ho 1968, eqs. (55)–(58)).

    .. math::

        ΔP_{k/k} = (I − W°_kH_k)Φ_{k-1} ΔP_{k-1/k-1} Φ_{k-1}ᵀ(I − W°_kH_k)ᵀ + ΔW_k S_k ΔW_kᵀ,
        \qquad ΔP_{0/-1} = 0 \qquad (56)

    (the ``ΔP H ᵀΔWᵀ`` terms of ``B_k`` are third order and dropped). Compare with the exact
    covariance of the suboptimal filter, ``covariance_recursion(model, gain=W° + ΔW)``: the
    difference is third order in ``ΔW``.

    **Arguments:**

    - ``model``: the :class:`~jaxtrack.models.LinearGaussianModel`.
    - ``dW``: the gain changes ``ΔW``, ``(n, m)`` (every step) or ``(T, n, m)``.
    - ``num_steps``: ``T``; defaults to the model's per-step length.
    - ``first_step``: ``"update"`` (default) or ``"predict"``.

    **Returns:** ``ΔP_{k/k}``, ``(T, n, n)``.

    **Raises:** ``InputError`` for a ``dW`` of the wrong shape.
    """
    history = covariance_recursion(model, num_steps, first_step=first_step)
    T = history.filtered_cov.shape[0]
    dW = jnp.asarray(dW)
    if dW.ndim == 2:
        dW = jnp.broadcast_to(dW, (T, *dW.shape))
    if dW.shape != history.gain.shape:
        raise InputError(f"`dW` must have shape {history.gain.shape[1:]} or {history.gain.shape}; got {dW.shape}.")
    ks = jnp.arange(T)
    F = jax.vmap(model.transition_matrix)(ks)
    H = jax.vmap(model.measurement_matrix)(ks)
    if first_step == "update":
        F = F.at[0].set(jnp.zeros_like(F[0]))
    I_WH = _i_minus_wh(history.gain, H)
    dZ = dW @ history.innovation_cov @ jnp.swapaxes(dW, -1, -2)  # eq. (57)

    def step(dP_prev, inputs):
        F_k, I_WH_k, dZ_k = inputs
        dP = I_WH_k @ F_k @ dP_prev @ F_k.T @ I_WH_k.T + dZ_k  # eq. (58)
        return dP, dP

    _, dP = jax.lax.scan(step, jnp.zeros_like(model.initial_cov), (F, I_WH, dZ))
    return dP


class GainEllipsoid(eqx.Module):
    r"""The allowable gain region ``{ΔW : vec(ΔW)ᵀ M vec(ΔW) ≤ budget}`` of one step (eq. (64)).

    ``M = S_k ⊗ L_{k/k}`` (``nm × nm``, column-major ``vec``), so
    ``vec(ΔW)ᵀ M vec(ΔW) = tr[(ΔWᵀ L_{k/k} ΔW) S_k]``. Directions with a zero eigenvalue of
    ``M`` cost nothing to second order (for ``L_T = diag(1, 0)``, gain errors that only disturb
    states the criterion ignores).
    """

    shape_matrix: Float[Array, "nm nm"]
    budget: Float[Array, ""]
    gain_shape: tuple[int, int] = eqx.field(static=True)

    def cost(self, dW: ArrayLike) -> Array:
        """Second-order ``ΔJ`` of a gain change ``ΔW`` ``(n, m)``."""
        v = _vec(jnp.asarray(dW))
        return v @ self.shape_matrix @ v

    def contains(self, dW: ArrayLike) -> Array:
        """Whether ``ΔW`` keeps the second-order degradation within the budget."""
        return self.cost(dW) <= self.budget

    def semi_axes(self) -> tuple[Array, Array]:
        """``(lengths, directions)``: semi-axis lengths ``sqrt(budget/λ)`` (``inf`` where ``λ = 0``)
        and the matching unit gain changes, ``(nm,)`` and ``(nm, n, m)``."""
        lam, vecs = jnp.linalg.eigh(self.shape_matrix)
        tiny = 1e-12 * jnp.max(jnp.abs(lam))
        lengths = jnp.where(lam > tiny, jnp.sqrt(self.budget / jnp.where(lam > tiny, lam, 1.0)), jnp.inf)
        n, m = self.gain_shape
        directions = jnp.swapaxes(vecs.T.reshape(-1, m, n), -1, -2)
        return lengths, directions


def allowable_gain_ellipsoid(adjoint_filtered_k: ArrayLike, innovation_cov_k: ArrayLike, budget: ArrayLike) -> GainEllipsoid:
    r"""The ellipsoid of gain changes at one step whose cost (64) is at most ``budget``.

    **Arguments:** ``L_{k/k}`` ``(n, n)``, ``S_k`` ``(m, m)``, ``budget`` ``(ΔJ)_k`` ≥ 0 (units
    of ``J``). Allocating ``ΔJ = Σ_k (ΔJ)_k`` over steps gives the "tube" of allowable gains
    around ``W°_k`` that Sec. II-F describes.
    """
    L, S = jnp.asarray(adjoint_filtered_k), jnp.asarray(innovation_cov_k)
    if L.ndim != 2 or S.ndim != 2:
        raise InputError(f"`adjoint_filtered_k` and `innovation_cov_k` must be matrices; got {L.shape}, {S.shape}.")
    return GainEllipsoid(jnp.kron(S, L), jnp.asarray(budget, L.dtype), (L.shape[0], S.shape[0]))


def gain_hessian(
    model: LinearGaussianModel,
    weight: ArrayLike,
    step: int,
    num_steps: int | None = None,
    *,
    method: Method = Analytic(),
    first_step: FirstStep = "update",
) -> Float[Array, "nm nm"]:
    r"""Hessian of ``J = tr(L_T P_T)`` with respect to ``vec(W_k)`` at the optimal gains (eq. (64)).

    - ``Analytic()``: ``2 (S_k ⊗ L_{k/k})`` from the adjoint (62).
    - ``Autodiff()``: ``jax.hessian`` of ``J`` through the Joseph-form covariance recursion with
      the gain at step ``k`` replaced by ``W°_k + ΔW`` (all other gains held optimal).

    **Arguments:**

    - ``model``: the :class:`~jaxtrack.models.LinearGaussianModel`.
    - ``weight``: ``L_T``, ``(n, n)``; ``step``: ``k``, in ``[0, T)``.
    - ``num_steps``: ``T``; defaults to the model's per-step length.
    - ``method``: ``Analytic()`` (default) or ``Autodiff()``.
    - ``first_step``: ``"update"`` (default) or ``"predict"``.

    **Returns:** ``(nm, nm)`` in column-major ``vec`` order.

    **Raises:** ``InputError`` for a ``step`` out of range.
    """
    method = _check_method(method)
    history = covariance_recursion(model, num_steps, first_step=first_step)
    L_T = _check_weight(weight, model.state_dim)
    T = history.filtered_cov.shape[0]
    if not 0 <= step < T:
        raise InputError(f"`step` must be in [0, {T}); got {step}.")
    if isinstance(method, Analytic):
        L = _analytic_adjoint(model, history, L_T).filtered[step]
        return 2.0 * jnp.kron(history.innovation_cov[step], L)

    def J(v):
        n, m = history.gain.shape[1:]
        dW = jnp.swapaxes(v.reshape(m, n), 0, 1)
        gains = history.gain.at[step].add(dW)
        # Gains after step k stay at the ORIGINAL optimum: with all later gains re-optimised the
        # Hessian would be smaller (the memo's ΔJ holds the rest of the schedule fixed, eq. (59)).
        P_T = covariance_recursion(model, T, gain=gains, first_step=first_step).filtered_cov[-1]
        return jnp.trace(L_T @ P_T)

    v0 = jnp.zeros(history.gain.shape[1] * history.gain.shape[2], history.gain.dtype)
    return jax.hessian(J)(v0)

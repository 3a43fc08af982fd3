"""Exact (all-order) one-stage variation equations of the Kalman covariance (Ho 1968, Sec. II-B, App. B).

A finite change of the prior, the dynamics, the noises or the gain,

.. math::

    P_{0/-1} → P_{0/-1} + ΔP_{0/-1},\\quad Φ_k → Φ_k + ΔΦ_k,\\quad Q_k → Q_k + ΔQ_k,\\quad
    R_k → R_k + ΔR_k,\\quad W_k → W_k + ΔW_k \\qquad \\text{(Ho 1968, eq. (10))}

changes the covariances by ``ΔP`` that obey recursions written around a nominal filter. The
recursions here are EXACT, not linearised: the nominal plus the variation equals the covariance
of the perturbed filter to rounding. Their first-order parts are the local variations of
:mod:`jaxtrack.sensitivity._recursions`; what the first order leaves out is the gain terms
``A``, ``B`` of eqs. (18), (20) and the ``ΔΦ``-products of eq. (26).

The one-step functions act on single matrices (no batch axis; ``jax.vmap`` them for batches) and
are differentiable. :func:`exact_variation_recursion` runs them over a whole linear model with
one ``jax.lax.scan``.

Equations (21) and the transposes of (B.11) are missing or garbled in the OCR of the memo; the
forms used here are those reconstructed and verified in ``specs/ho-sensitivity.md`` §2.1–2.2.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError, is_concrete
from ..covariance import covariance_recursion
from ..filters._base import FirstStep
from ..models import LinearGaussianModel

__all__ = [
    "UpdateVariation",
    "GainVariation",
    "CovarianceVariation",
    "update_variation",
    "prediction_variation",
    "optimal_gain_variation",
    "value_of_information",
    "exact_variation_recursion",
]


class UpdateVariation(NamedTuple):
    """The exact change of the updated covariance ``P_{k/k}`` and its gain terms (one step).

    - ``dP`` ``(n, n)``: ``ΔP_{k/k}`` (Ho 1968, eq. (17)).
    - ``A`` ``(n, n)``: first-order gain term (eq. (18)); zero if ``ΔW = 0`` or ``W`` is optimal.
    - ``B`` ``(n, n)``: second- and third-order gain terms (eq. (20)); zero if ``ΔW = 0``.
    """

    dP: Float[Array, "n n"]
    A: Float[Array, "n n"]
    B: Float[Array, "n n"]


class GainVariation(NamedTuple):
    """The gain change that re-optimises the filter for perturbed statistics (one step).

    - ``dW_opt`` ``(n, m)``: ``ΔW° = π₂ π₁⁻¹`` (Ho 1968, eq. (B.9)).
    - ``pi1`` ``(m, m)``: ``π₁ = H (P+ΔP) Hᵀ + R + ΔR``, the perturbed innovation covariance.
    - ``pi2`` ``(n, m)``: ``π₂ = (I − WH)(P+ΔP)Hᵀ − W (R+ΔR)`` (eq. (B.10)).
    - ``gain_term`` ``(n, n)``: ``(A + B)° = −π₂ π₁⁻¹ π₂ᵀ`` (eqs. (21), (B.12)), negative
      semidefinite, for ANY nominal ``W``.
    """

    dW_opt: Float[Array, "n m"]
    pi1: Float[Array, "m m"]
    pi2: Float[Array, "n m"]
    gain_term: Float[Array, "n n"]


def _identity_like(P: Array) -> Array:
    return jnp.eye(P.shape[-1], dtype=P.dtype)


def update_variation(
    P_pred: ArrayLike,
    H: ArrayLike,
    R: ArrayLike,
    W: ArrayLike,
    dP_pred: ArrayLike,
    dR: ArrayLike,
    dW: ArrayLike,
) -> UpdateVariation:
    r"""Exact change of the Joseph-form update for finite ``ΔP_{k/k-1}``, ``ΔR_k``, ``ΔW_k``.

    .. math::

        ΔP_{k/k} = (I − W H) ΔP_{k/k-1} (I − W H)ᵀ + W ΔR Wᵀ + A + B
        \qquad \text{(Ho 1968, eq. (17))}

        A = [W (H P H^T + R) − P Hᵀ] ΔWᵀ + ΔW [W (H P Hᵀ + R) − P Hᵀ]ᵀ
        \qquad \text{(eq. (18))}

        B = [W (H ΔP Hᵀ + ΔR) − ΔP Hᵀ] ΔWᵀ + ΔW [\,\cdot\,]ᵀ
            + ΔW [H (P + ΔP) Hᵀ + R + ΔR] ΔWᵀ \qquad \text{(eq. (20))}

    with ``P = P_{k/k-1}``. Exact for an ARBITRARY nominal gain ``W`` (the update is the Joseph
    form, Ho 1968, eq. (3)): ``P_{k/k} + ΔP_{k/k}`` is the covariance after updating
    ``P + ΔP`` with gain ``W + ΔW`` and noise ``R + ΔR``. The OCR's ``ΔP_k`` in the second
    bracket of (20) is ``ΔR_k`` (spec §2.1).

    **Arguments** (``n`` states, ``m`` measurement components):

    - ``P_pred``: nominal ``P_{k/k-1}``, shape ``(n, n)``.
    - ``H``: measurement matrix ``H_k``, shape ``(m, n)`` (not varied: a ``ΔH`` is recast as a
      ``ΔΦ``, eqs. (11)–(15)).
    - ``R``: nominal ``R_k``, shape ``(m, m)``.
    - ``W``: nominal gain ``W_k``, shape ``(n, m)``, optimal or not.
    - ``dP_pred``, ``dR``, ``dW``: the finite variations ``ΔP_{k/k-1}`` ``(n, n)``, ``ΔR_k``
      ``(m, m)``, ``ΔW_k`` ``(n, m)``.

    Units are those of the covariances (e.g. ft² and ft²/s² for Ho's plant).

    **Returns:** :class:`UpdateVariation` ``(dP, A, B)``.
    """
    P, H, R, W, dP, dR, dW = (jnp.asarray(a) for a in (P_pred, H, R, W, dP_pred, dR, dW))
    I_WH = _identity_like(P) - W @ H
    # Bracket of (18): vanishes for the optimal gain (B.7), which is why A = 0 there.
    nominal_bracket = W @ (H @ P @ H.T + R) - P @ H.T
    A = nominal_bracket @ dW.T + dW @ nominal_bracket.T
    variation_bracket = W @ (H @ dP @ H.T + dR) - dP @ H.T
    perturbed_S = H @ (P + dP) @ H.T + (R + dR)
    B = variation_bracket @ dW.T + dW @ variation_bracket.T + dW @ perturbed_S @ dW.T
    dP_filt = I_WH @ dP @ I_WH.T + W @ dR @ W.T + A + B
    return UpdateVariation(dP_filt, A, B)


def prediction_variation(
    Phi: ArrayLike,
    P_filt: ArrayLike,
    dP_filt: ArrayLike,
    dQ: ArrayLike,
    dPhi: ArrayLike,
) -> Float[Array, "n n"]:
    r"""Exact change of the predicted covariance for finite ``ΔP_{k/k}``, ``ΔQ_k``, ``ΔΦ_k``.

    .. math::

        ΔP_{k+1/k} = Φ ΔP_{k/k} Φᵀ + ΔQ
            + ΔΦ (P_{k/k} + ΔP_{k/k}) Φᵀ + Φ (P_{k/k} + ΔP_{k/k}) ΔΦᵀ
            + ΔΦ (P_{k/k} + ΔP_{k/k}) ΔΦᵀ \qquad \text{(Ho 1968, eq. (26))}

    so ``P_{k+1/k} + ΔP_{k+1/k} = (Φ + ΔΦ)(P_{k/k} + ΔP_{k/k})(Φ + ΔΦ)ᵀ + Q + ΔQ`` (eq. (B.1)).
    With ``ΔΦ = 0`` this is eq. (27). ``ΔΦ`` is a change of the dynamics that the filter also
    uses (Sec. II-G(5)); a filter whose ``Φ`` differs from the truth is not covered.

    **Arguments:**

    - ``Phi``: nominal ``Φ_k``, shape ``(n, n)``.
    - ``P_filt``: nominal ``P_{k/k}``, shape ``(n, n)``.
    - ``dP_filt``: ``ΔP_{k/k}``, shape ``(n, n)``.
    - ``dQ``: ``ΔQ_k``, shape ``(n, n)``.
    - ``dPhi``: ``ΔΦ_k``, shape ``(n, n)``.

    **Returns:** ``ΔP_{k+1/k}``, shape ``(n, n)``.
    """
    Phi, P, dP, dQ, dPhi = (jnp.asarray(a) for a in (Phi, P_filt, dP_filt, dQ, dPhi))
    P_new = P + dP
    return (
        Phi @ dP @ Phi.T
        + dQ
        + dPhi @ P_new @ Phi.T
        + Phi @ P_new @ dPhi.T
        + dPhi @ P_new @ dPhi.T
    )


def optimal_gain_variation(
    P_pred: ArrayLike,
    H: ArrayLike,
    R: ArrayLike,
    W: ArrayLike,
    dP_pred: ArrayLike,
    dR: ArrayLike,
) -> GainVariation:
    r"""The gain change ``ΔW°`` that makes ``W + ΔW°`` optimal for ``P + ΔP``, ``R + ΔR``.

    .. math::

        π_1 = H (P + ΔP) Hᵀ + R + ΔR, \qquad
        π_2 = (I − W H)(P + ΔP) Hᵀ − W (R + ΔR) \qquad \text{(Ho 1968, eq. (B.10))}

        ΔW° = π_2 π_1^{-1} \qquad \text{(eq. (B.9))}, \qquad
        (A + B)° = −π_2 π_1^{-1} π_2ᵀ \le 0 \qquad \text{(eqs. (21), (B.12))}

    ``P = P_{k/k-1}``. Valid for ANY nominal gain ``W``: with ``ΔW = ΔW°`` the update variation
    (17) is ``(I − WH) ΔP (I − WH)ᵀ + W ΔR Wᵀ + (A + B)°``. Eq. (21) is missing from the OCR; this
    is the form reconstructed from (B.9)–(B.12) (spec §2.1), and the transpose on the last term
    of (B.11) that the OCR drops is restored.

    **Arguments:**

    - ``P_pred``: nominal ``P_{k/k-1}``, shape ``(n, n)``.
    - ``H``: ``H_k``, shape ``(m, n)``.
    - ``R``: nominal ``R_k``, shape ``(m, m)``.
    - ``W``: nominal gain ``W_k``, shape ``(n, m)``, optimal or not.
    - ``dP_pred``: ``ΔP_{k/k-1}``, shape ``(n, n)``; ``P + ΔP`` must be positive semidefinite.
    - ``dR``: ``ΔR_k``, shape ``(m, m)``; ``π₁`` must be positive definite (it is a Cholesky
      factor's input).

    **Returns:** :class:`GainVariation` ``(dW_opt, pi1, pi2, gain_term)``.
    """
    P, H, R, W, dP, dR = (jnp.asarray(a) for a in (P_pred, H, R, W, dP_pred, dR))
    I_WH = _identity_like(P) - W @ H
    P_new, R_new = P + dP, R + dR
    pi1 = H @ P_new @ H.T + R_new
    pi2 = I_WH @ P_new @ H.T - W @ R_new
    chol = jnp.linalg.cholesky(pi1)
    dW_opt = jsl.cho_solve((chol, True), pi2.T).T  # π₂ π₁⁻¹ with π₁ symmetric
    gain_term = -dW_opt @ pi2.T
    return GainVariation(dW_opt, pi1, pi2, gain_term)


def value_of_information(
    P_pred: ArrayLike,
    H: ArrayLike,
    R: ArrayLike,
    W_opt: ArrayLike,
    dP_pred: ArrayLike,
    dR: ArrayLike,
) -> Float[Array, "n n"]:
    r"""``B°_k``: how much re-optimising the gain lowers ``P_{k/k}`` after a change of statistics.

    .. math::

        B°_k = −v\, [H (P + ΔP) Hᵀ + R + ΔR]^{-1} vᵀ, \qquad
        v = −(I − W° H) ΔP Hᵀ + W° ΔR \qquad \text{(Ho 1968, eq. (21))}

    with ``P = P_{k/k-1}`` and the nominal gain ``W°`` optimal for ``P``, ``R``. Then (eqs.
    (28)–(30)) the readjusted variation minus the held-gain variation is
    ``ΔP°_{k/k} − ΔP_{k/k} = B°_k``: negative semidefinite (the paper says "negative definite")
    and of second and third order in the variations, so first-order sampling-period studies may
    drop it but suboptimal-gain studies may not. For an optimal ``W°``, ``v = −π₂`` and ``B°``
    is the ``(A + B)°`` of :func:`optimal_gain_variation`; written with ``v`` it avoids the
    cancellation ``(I − W°H)PHᵀ − W°R = 0`` (eq. (B.7)) inside ``π₂``.

    **Arguments:**

    - ``P_pred``: nominal ``P_{k/k-1}``, shape ``(n, n)``.
    - ``H``: ``H_k``, shape ``(m, n)``.
    - ``R``: nominal ``R_k``, shape ``(m, m)``.
    - ``W_opt``: the optimal nominal gain ``W°_k = P Hᵀ (H P Hᵀ + R)⁻¹``, shape ``(n, m)``.
    - ``dP_pred``: ``ΔP_{k/k-1}``, shape ``(n, n)``.
    - ``dR``: ``ΔR_k``, shape ``(m, m)``.

    **Returns:** ``B°_k``, shape ``(n, n)``, negative semidefinite.
    """
    P, H, R, W, dP, dR = (jnp.asarray(a) for a in (P_pred, H, R, W_opt, dP_pred, dR))
    I_WH = _identity_like(P) - W @ H
    v = -I_WH @ dP @ H.T + W @ dR
    pi1 = H @ (P + dP) @ H.T + R + dR
    chol = jnp.linalg.cholesky(pi1)
    return -v @ jsl.cho_solve((chol, True), v.T)


class CovarianceVariation(eqx.Module):
    """Exact covariance and gain variations of a linear filter over ``T`` steps.

    - ``predicted_cov`` ``(T, n, n)``: ``ΔP_{k/k-1}`` (``ΔP_{0/-1}`` at ``k = 0`` when
      ``first_step="update"``).
    - ``filtered_cov`` ``(T, n, n)``: ``ΔP_{k/k}``.
    - ``gain`` ``(T, n, m)``: the gain change ``ΔW_k`` used (zero when gains are held).

    Add them to the nominal :class:`~jaxtrack.covariance.CovarianceHistory` to get the perturbed
    filter's covariances.
    """

    predicted_cov: Float[Array, "T n n"]
    filtered_cov: Float[Array, "T n n"]
    gain: Float[Array, "T n m"]


def _check_same_measurement_matrix(model, perturbed_model) -> None:
    a, b = model.H, perturbed_model.H
    if a.shape != b.shape or (
        is_concrete(a) and is_concrete(b) and not np.array_equal(np.asarray(a), np.asarray(b))
    ):
        raise InputError(
            "`model` and `perturbed_model` must share H: Ho's variations have no ΔH; recast a "
            "measurement change as a ΔΦ of an augmented or transformed state (Ho 1968, eqs. (11)–(15))."
        )


def _resolve_variation_steps(model, perturbed_model, num_steps) -> int:
    if num_steps is not None:
        if not isinstance(num_steps, int) or num_steps < 1:
            raise InputError(f"`num_steps` must be a positive int; got {num_steps!r}.")
        return num_steps
    lengths = {t for t in (model.num_steps, perturbed_model.num_steps) if t is not None}
    if not lengths:
        raise InputError("`num_steps` is required when both models are time-invariant.")
    if len(lengths) > 1:
        raise InputError(
            f"`model` has {model.num_steps} steps but `perturbed_model` has "
            f"{perturbed_model.num_steps}; they must describe the same samples."
        )
    return lengths.pop()


@eqx.filter_jit
def _variation_scan(model, perturbed_model, nominal, readjust_gain, first_step):
    n, m = model.state_dim, model.meas_dim
    num_steps = nominal.filtered_cov.shape[0]
    dP0 = perturbed_model.initial_cov - model.initial_cov

    def step(carry, inputs):
        P_filt_prev, dP_filt_prev = carry
        k, P_pred, P_filt, W = inputs
        Phi = model.transition_matrix(k)
        dPhi = perturbed_model.transition_matrix(k) - Phi
        dQ = perturbed_model.process_noise_cov(k) - model.process_noise_cov(k)
        dP_pred = prediction_variation(Phi, P_filt_prev, dP_filt_prev, dQ, dPhi)
        if first_step == "update":
            # The prior sits on the first sample: ΔP_{0/-1} enters the first update directly.
            dP_pred = jnp.where(k == 0, dP_filt_prev, dP_pred)
        H = model.measurement_matrix(k)
        R = model.measurement_noise_cov(k)
        dR = perturbed_model.measurement_noise_cov(k) - R
        I_WH = jnp.eye(n, dtype=P_pred.dtype) - W @ H
        held = I_WH @ dP_pred @ I_WH.T + W @ dR @ W.T  # eq. (28)/(B.14): ΔW = 0
        if readjust_gain:
            g = optimal_gain_variation(P_pred, H, R, W, dP_pred, dR)
            dW, dP_filt = g.dW_opt, held + g.gain_term  # eqs. (17), (21)
        else:
            dW, dP_filt = jnp.zeros((n, m), P_pred.dtype), held
        return (P_filt, dP_filt), (dP_pred, dP_filt, dW)

    # With first_step="update" the carry's P at k = 0 is unused (no prediction into step 0);
    # with "predict" it is P_{-1/-1} = P_{0/-1} of the model, one transition before step 0.
    init = (model.initial_cov, dP0)
    xs = (jnp.arange(num_steps), nominal.predicted_cov, nominal.filtered_cov, nominal.gain)
    _, (dP_pred, dP_filt, dW) = jax.lax.scan(step, init, xs)
    return CovarianceVariation(dP_pred, dP_filt, dW)


def exact_variation_recursion(
    model: LinearGaussianModel,
    perturbed_model: LinearGaussianModel,
    num_steps: int | None = None,
    *,
    readjust_gain: bool = False,
    gain: ArrayLike | None = None,
    first_step: FirstStep = "update",
) -> CovarianceVariation:
    r"""Exact covariance variations of a Kalman filter over all steps (Ho 1968, eqs. (17), (26)).

    Starting from ``ΔP_{0/-1}``, alternate the exact prediction variation (26) and update
    variation (17):

    .. math::

        ΔP_{k/k-1} = Φ ΔP_{k-1/k-1} Φᵀ + ΔQ + ΔΦ (P + ΔP)_{k-1/k-1} Φᵀ
            + Φ (P + ΔP)_{k-1/k-1} ΔΦᵀ + ΔΦ (P + ΔP)_{k-1/k-1} ΔΦᵀ

        ΔP_{k/k} = (I − W_k H_k) ΔP_{k/k-1} (I − W_k H_k)ᵀ + W_k ΔR_k W_kᵀ + (A_k + B_k)

    (``Φ, ΔΦ, ΔQ`` of the interval ending at step ``k``), with the finite variations
    ``ΔΦ, ΔQ, ΔR, ΔP_{0/-1}`` the differences ``perturbed_model − model``. The gain term is

    - ``readjust_gain=False``: ``ΔW_k = 0`` and ``A_k = B_k = 0`` (eq. (28)): the filter keeps
      its nominal gains. With ``perturbed_model`` the TRUE statistics and ``model`` the filter's
      assumed ones, ``P + ΔP`` is the ACTUAL covariance of that filter (Sec. II-G(1)), i.e.
      :func:`jaxtrack.covariance.actual_covariance` (the memo cites "(17) and (25)"; it is (17)
      and (26)).
    - ``readjust_gain=True``: ``ΔW_k = ΔW°_k`` and ``(A_k + B_k)° = −π₂π₁⁻¹π₂ᵀ``
      (eqs. (21), (B.12)): the gain is re-optimised for the perturbed statistics at every step,
      so ``P + ΔP`` is the optimal covariance recursion of ``perturbed_model``, even with
      ``ΔΦ ≠ 0`` (Sec. II-G(2), (4), (5)). For an optimal nominal gain this term is ``B°_k``.

    Both are exact to rounding, of every order in the variations; dropping ``B°`` (the
    ``False`` branch against the ``True`` one) or the ``ΔΦ`` products costs ``O(ε²)``.

    **Arguments** (``n`` states, ``m`` measurement components, ``T`` steps):

    - ``model``: the nominal :class:`~jaxtrack.models.LinearGaussianModel` (``F, Q, H, R``,
      ``initial_cov``; means are ignored). Its covariance history (from
      :func:`~jaxtrack.covariance.covariance_recursion`) supplies ``P_{k/k-1}``, ``P_{k/k}``
      and ``W_k``.
    - ``perturbed_model``: the same model with ``Φ + ΔΦ``, ``Q + ΔQ``, ``R + ΔR``,
      ``P_{0/-1} + ΔP_{0/-1}``; ``H`` must be identical (a ``ΔH`` is recast as a ``ΔΦ``,
      eqs. (11)–(15)).
    - ``num_steps``: ``T``; defaults to the models' per-step length.
    - ``readjust_gain``: ``False`` holds the nominal gains, ``True`` re-optimises them (above).
    - ``gain``: optional nominal gains ``(n, m)`` or ``(T, n, m)`` when the nominal filter is
      itself suboptimal (then the ``A`` term of eq. (18) is nonzero under readjustment); the
      optimal gains of ``model`` by default.
    - ``first_step``: ``"update"`` (Ho's convention: ``P_{0/-1}`` is on the first sample, no
      prediction into step 0) or ``"predict"``, as in :func:`~jaxtrack.filters.run_filter`.

    **Returns:** a :class:`CovarianceVariation` with ``ΔP_{k/k-1}``, ``ΔP_{k/k}`` and ``ΔW_k``,
    each ``(T, ·, ·)``. Differentiable in every array of both models.

    **Raises:** :class:`~jaxtrack.InputError` if the models' ``H`` differ, their lengths
    disagree, or ``first_step`` is unknown.
    """
    for name, mdl in (("model", model), ("perturbed_model", perturbed_model)):
        if not isinstance(mdl, LinearGaussianModel):
            raise InputError(f"`{name}` must be a LinearGaussianModel; got {type(mdl).__name__}.")
    if (model.state_dim, model.meas_dim) != (perturbed_model.state_dim, perturbed_model.meas_dim):
        raise InputError(
            f"`model` has (n, m) = {(model.state_dim, model.meas_dim)} but `perturbed_model` has "
            f"{(perturbed_model.state_dim, perturbed_model.meas_dim)}."
        )
    _check_same_measurement_matrix(model, perturbed_model)
    if first_step not in ("update", "predict"):
        raise InputError(f"`first_step` must be 'update' or 'predict'; got {first_step!r}.")
    num_steps = _resolve_variation_steps(model, perturbed_model, num_steps)
    nominal = covariance_recursion(model, num_steps, gain=gain, first_step=first_step)
    return _variation_scan(model, perturbed_model, nominal, bool(readjust_gain), first_step)

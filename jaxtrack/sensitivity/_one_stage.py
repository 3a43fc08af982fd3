r"""One-stage trade-offs of the normalised 1/s² plant (Ho 1968, Sec. IV, Appendix C).

Sec. IV studies ONE predict/update stage of the position/velocity filter

.. math::

    x_k = \begin{bmatrix}1 & τ\\ 0 & 1\end{bmatrix} x_{k-1} + u_k,\quad
    Q = \mathrm{diag}(q_x, q_v),\quad z_k = [1\ 0]\,x_k + v_k,\quad E v_k^2 = R_x
    \qquad \text{(eqs. (89)–(91))}

in variables normalised so that ``P_{k-1/k-1} = [[1, p_xv], [p_xv, 1]]`` (Appendix C): a
normalised τ, ``q_x``, ``q_v``, ``r_x``. The closed forms below are what a designer reads off
the memo's nomogram (Fig. 15) and sensitivity curves (Figs. 16–17); every one is an elementwise
jnp function (broadcasts over arrays, differentiable), and the tests hold each against
``jax.jacfwd`` of :func:`one_stage_update`.

Corrections to the OCR (spec §4.4, §6): the ``τ`` and ``/R_x`` restored in (99); the ``+`` sign
of the ``k₁k₂ ∂R_x/∂τ`` term of (106); the numerator ``½ατ⁴`` of (111); (117) re-derived;
Appendix C's (C.8)–(C.12) reconstructed from ``P = N^{-1/2}P*N^{-1/2}``,
``Φ = N^{-1/2}Φ*N^{1/2}``, ``H = H*N^{1/2}``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError, check_covariance

__all__ = [
    "NormalizedCov",
    "Normalization",
    "one_stage_update",
    "one_stage_gain",
    "plant_noise_sensitivity",
    "period_sensitivity",
    "measurement_noise_sensitivity",
    "plant_noise_period_tradeoff",
    "measurement_noise_period_tradeoff",
    "predicted_position_variance",
    "updated_position_variance",
    "dimensionless_period_sensitivity",
    "normalize",
    "denormalize",
]


class NormalizedCov(NamedTuple):
    """Entries of a normalised 2×2 covariance (or of its derivative): ``p_x``, ``p_xv``, ``p_v``."""

    p_x: Array
    p_xv: Array
    p_v: Array


def _predicted(p_xv, tau, q_x, q_v):
    # eqs. (95)–(96): predicted entries from P_{k-1/k-1} = [[1, p_xv], [p_xv, 1]]
    m = 1.0 + 2.0 * p_xv * tau + tau**2 + q_x
    return m, p_xv + tau, 1.0 + q_v


def one_stage_update(p_xv: ArrayLike, tau: ArrayLike, q_x: ArrayLike, q_v: ArrayLike, r_x: ArrayLike) -> NormalizedCov:
    r"""Normalised ``P_{k/k}`` after one optimal stage (Ho 1968, eqs. (95)–(99)).

    With ``m = 1 + 2 p_xv τ + τ² + q_x`` (the predicted position variance),

    .. math::

        (p_x)_{k/k} = \frac{m}{m/R_x + 1},\quad
        (p_{xv})_{k/k} = \frac{p_{xv} + τ}{m/R_x + 1},\quad
        (p_v)_{k/k} = 1 + q_v − \frac{(p_{xv} + τ)^2/R_x}{1 + m/R_x} \qquad (99)

    **Arguments** (all normalised, dimensionless; arrays broadcast): ``p_xv`` the correlation
    of ``P_{k-1/k-1}`` (−1 < p_xv < 1), ``tau`` the normalised period (C.10), ``q_x``, ``q_v``
    the plant-noise variances (C.16), ``r_x`` the measurement-noise variance (C.13).

    **Returns:** :class:`NormalizedCov` of ``P_{k/k}``.
    """
    m, c, v = _predicted(*(jnp.asarray(a) for a in (p_xv, tau, q_x, q_v)))
    r = jnp.asarray(r_x)
    d = m / r + 1.0
    return NormalizedCov(m / d, c / d, v - (c**2 / r) / d)


def one_stage_gain(p_xv: ArrayLike, tau: ArrayLike, q_x: ArrayLike, r_x: ArrayLike) -> tuple[Array, Array]:
    r"""Gain components ``k₁ = (p_x)_{k/k-1}/(R_x + (p_x)_{k/k-1})``, ``k₂ = (p_xv)_{k/k-1}/(R_x + (p_x)_{k/k-1})`` (eq. (105)).

    **Arguments** (all normalised, dimensionless; arrays broadcast, shape ``(...)``):

    - ``p_xv``: the correlation of ``P_{k-1/k-1}`` (−1 < p_xv < 1); ``tau``: the normalised period (C.10).
    - ``q_x``: the position plant-noise variance (C.16); ``r_x``: the measurement-noise variance (C.13).

    **Returns:** ``(k₁, k₂)``, each of the broadcast shape ``(...)``, dimensionless.
    """
    m, c, _ = _predicted(jnp.asarray(p_xv), jnp.asarray(tau), jnp.asarray(q_x), 0.0)
    s = jnp.asarray(r_x) + m
    return m / s, c / s


def plant_noise_sensitivity(p_xv, tau, q_x, r_x, dqx_dalpha, dqv_dalpha) -> NormalizedCov:
    r"""``∂P_{k/k}/∂α`` for a plant-noise parameter α (Ho 1968, eq. (104)).

    .. math::

        \frac{∂p_x}{∂α} = (1−k_1)^2\frac{∂q_x}{∂α},\quad
        \frac{∂p_{xv}}{∂α} = −(1−k_1)k_2\frac{∂q_x}{∂α},\quad
        \frac{∂p_v}{∂α} = k_2^2\frac{∂q_x}{∂α} + \frac{∂q_v}{∂α}

    ``P_{k-1/k-1}`` is held fixed (one stage); ``R_x`` does not depend on α (eq. (103)).

    **Arguments** (all normalised, dimensionless; arrays broadcast, shape ``(...)``):

    - ``p_xv``, ``tau``, ``q_x``, ``r_x``: the stage, as in :func:`one_stage_gain`.
    - ``dqx_dalpha``, ``dqv_dalpha``: ``∂q_x/∂α`` and ``∂q_v/∂α``.

    **Returns:** :class:`NormalizedCov` of ``∂P_{k/k}/∂α``, entries of the broadcast shape ``(...)``.
    """
    k1, k2 = one_stage_gain(p_xv, tau, q_x, r_x)
    dqx, dqv = jnp.asarray(dqx_dalpha), jnp.asarray(dqv_dalpha)
    return NormalizedCov((1 - k1) ** 2 * dqx, -(1 - k1) * k2 * dqx, k2**2 * dqx + dqv)


def period_sensitivity(p_xv, tau, q_x, r_x, dqx_dtau, dqv_dtau, drx_dtau=0.0) -> NormalizedCov:
    r"""``∂P_{k/k}/∂τ`` of one stage (Ho 1968, eq. (106), sign of the ``k₁k₂`` term corrected).

    With ``c = 2τ + 2p_xv + ∂q_x/∂τ``:

    .. math::

        \frac{∂p_x}{∂τ} = (1−k_1)^2 c + k_1^2\frac{∂R_x}{∂τ},\quad
        \frac{∂p_{xv}}{∂τ} = (1−k_1)(1 − k_2c) + k_1k_2\frac{∂R_x}{∂τ},\quad
        \frac{∂p_v}{∂τ} = k_2^2c − 2k_2 + \frac{∂q_v}{∂τ} + k_2^2\frac{∂R_x}{∂τ}

    The OCR prints ``− k₁k₂ ∂R_x/∂τ``; the derivation and finite differences give ``+`` (spec §6
    item 7). ``drx_dtau`` is nonzero for presmoothed data (``R_x = β/τ``, eq. (115)).

    **Arguments** (all normalised, dimensionless; arrays broadcast, shape ``(...)``):

    - ``p_xv``, ``tau``, ``q_x``, ``r_x``: the stage, as in :func:`one_stage_gain`.
    - ``dqx_dtau``, ``dqv_dtau``: ``∂q_x/∂τ`` and ``∂q_v/∂τ``.
    - ``drx_dtau``: ``∂R_x/∂τ`` (default 0: unsmoothed data).

    **Returns:** :class:`NormalizedCov` of ``∂P_{k/k}/∂τ``, entries of the broadcast shape ``(...)``.
    """
    k1, k2 = one_stage_gain(p_xv, tau, q_x, r_x)
    c = 2 * jnp.asarray(tau) + 2 * jnp.asarray(p_xv) + jnp.asarray(dqx_dtau)
    dr = jnp.asarray(drx_dtau)
    return NormalizedCov(
        (1 - k1) ** 2 * c + k1**2 * dr,
        (1 - k1) * (1 - k2 * c) + k1 * k2 * dr,
        k2**2 * c - 2 * k2 + jnp.asarray(dqv_dtau) + k2**2 * dr,
    )


def measurement_noise_sensitivity(p_xv, tau, q_x, r_x, drx_dbeta) -> NormalizedCov:
    r"""``∂P_{k/k}/∂β`` for a measurement-noise parameter β (Ho 1968, eq. (107)):
    ``(k₁², k₁k₂, k₂²)·∂R_x/∂β``.

    **Arguments** (all normalised, dimensionless; arrays broadcast, shape ``(...)``):

    - ``p_xv``, ``tau``, ``q_x``, ``r_x``: the stage, as in :func:`one_stage_gain`.
    - ``drx_dbeta``: ``∂R_x/∂β``.

    **Returns:** :class:`NormalizedCov` of ``∂P_{k/k}/∂β``, entries of the broadcast shape ``(...)``.
    """
    k1, k2 = one_stage_gain(p_xv, tau, q_x, r_x)
    d = jnp.asarray(drx_dbeta)
    return NormalizedCov(k1**2 * d, k1 * k2 * d, k2**2 * d)


def plant_noise_period_tradeoff(p_xv: ArrayLike, tau: ArrayLike, alpha: ArrayLike) -> Array:
    r"""``(Δτ/τ)/(Δα/α)`` that keeps ``(p_x)_{k/k}`` fixed (Ho 1968, eqs. (110)–(112)).

    For the plant noise of eq. (108), ``q_x = ¼α²τ⁴``, ``q_v = α²τ²`` (α the normalised
    acceleration standard deviation) and unsmoothed data:

    .. math::

        Δτ = −\frac{½ατ^4}{2τ + 2p_{xv} + α^2τ^3}Δα \quad (111),\qquad
        \frac{Δτ}{τ} = −\frac12\,\frac{1}{1 + 2(τ + p_{xv})/(α^2τ^3)}\,\frac{Δα}{α} \quad (112)

    → 0 for small ``α²τ³`` and → −½ for large. The numerator of (111) is missing in the OCR.
    Use: a maneuvering target raises α; this is the period cut that restores accuracy.

    **Arguments** (all normalised, dimensionless; arrays broadcast, shape ``(...)``):

    - ``p_xv``: the correlation of ``P_{k-1/k-1}``; ``tau``: the normalised period.
    - ``alpha``: the normalised acceleration standard deviation of eq. (108).

    **Returns:** ``(Δτ/τ)/(Δα/α)``, dimensionless, in ``[−½, 0]``, the broadcast shape ``(...)``.
    """
    p_xv, tau, alpha = (jnp.asarray(a) for a in (p_xv, tau, alpha))
    return -0.5 / (1.0 + 2.0 * (tau + p_xv) / (alpha**2 * tau**3))


def measurement_noise_period_tradeoff(p_xv: ArrayLike, tau: ArrayLike, alpha: ArrayLike, beta: ArrayLike) -> Array:
    r"""``(Δτ/τ)/(Δβ/β)`` that keeps ``(p_x)_{k/k}`` fixed with smoothed data (eqs. (113)–(117)).

    ``R_x = β/τ`` (perfect presmoothing, eq. (115)) and ``q_x = ¼α²τ⁴``. With
    ``m = 1 + 2p_xvτ + τ² + q_x``:

    .. math::  \frac{Δτ}{τ} = \frac{Δβ/β}{1 − τR_x(2τ + 2p_{xv} + α^2τ^3)/m^2} \qquad (117)

    The OCR of (117) is garbled; this is the form derived from (114) and checked against finite
    differences (spec §4.4). Its limits are the reverse of the memo's text: a small ``β`` gives
    ``Δτ/τ → Δβ/β``, a large ``β`` gives ``Δτ/τ → 0``.

    **Arguments** (all normalised, dimensionless; arrays broadcast, shape ``(...)``):

    - ``p_xv``: the correlation of ``P_{k-1/k-1}``; ``tau``: the normalised period.
    - ``alpha``: the normalised acceleration standard deviation; ``beta``: the presmoothing
      parameter of ``R_x = β/τ``.

    **Returns:** ``(Δτ/τ)/(Δβ/β)``, dimensionless, the broadcast shape ``(...)``.
    """
    p_xv, tau, alpha, beta = (jnp.asarray(a) for a in (p_xv, tau, alpha, beta))
    m = 1.0 + 2.0 * p_xv * tau + tau**2 + 0.25 * alpha**2 * tau**4
    r_x = beta / tau
    return 1.0 / (1.0 - tau * r_x * (2 * tau + 2 * p_xv + alpha**2 * tau**3) / m**2)


def predicted_position_variance(a: ArrayLike, tau: ArrayLike) -> Array:
    r"""$(p_x)_{k/k-1} = 1 + aτ + τ^2$ (Ho 1968, eq. (128)); ``a = 2p_xv`` (130) or ``2p_xv + α``
    for ``q_x = ατ`` (131).

    **Arguments** (normalised, dimensionless; arrays broadcast, shape ``(...)``):

    - ``a``: the coefficient of τ (``2p_xv`` or ``2p_xv + α``); ``tau``: the normalised period.

    **Returns:** ``(p_x)_{k/k-1}``, dimensionless, the broadcast shape ``(...)``.
    """
    tau = jnp.asarray(tau)
    return 1.0 + jnp.asarray(a) * tau + tau**2


def updated_position_variance(a: ArrayLike, tau: ArrayLike, r_x: ArrayLike) -> Array:
    r"""$(p_x)_{k/k} = \big(1/r_x + 1/(p_x)_{k/k-1}\big)^{-1}$ (Ho 1968, eq. (129)): the nomogram of Fig. 15.

    **Arguments** (normalised, dimensionless; arrays broadcast, shape ``(...)``):

    - ``a``, ``tau``: as in :func:`predicted_position_variance`; ``r_x``: the measurement-noise variance.

    **Returns:** ``(p_x)_{k/k}``, dimensionless, the broadcast shape ``(...)``.
    """
    return 1.0 / (1.0 / jnp.asarray(r_x) + 1.0 / predicted_position_variance(a, tau))


def dimensionless_period_sensitivity(a: ArrayLike, tau: ArrayLike, r_x: ArrayLike) -> Array:
    r"""$(Δp_x/p_x)_{k/k} \,/\, (Δτ/τ)$ for constant ``r_x`` (Ho 1968, eq. (134), Figs. 16–17).

    .. math::  \frac{τ(a + 2τ)}{[(1 + aτ + τ^2)/r_x + 1](1 + aτ + τ^2)}

    Invariant under the Appendix C normalisation (eq. (135)): the same number in feet.

    **Arguments** (normalised, dimensionless; arrays broadcast, shape ``(...)``):

    - ``a``, ``tau``: as in :func:`predicted_position_variance`; ``r_x``: the measurement-noise variance.

    **Returns:** ``(Δp_x/p_x)_{k/k}/(Δτ/τ)``, dimensionless, the broadcast shape ``(...)``.
    """
    a, tau = jnp.asarray(a), jnp.asarray(tau)
    m = predicted_position_variance(a, tau)
    return tau * (a + 2 * tau) / ((m / jnp.asarray(r_x) + 1.0) * m)


class Normalization(NamedTuple):
    """A dimensional stage in Appendix C's normalised variables.

    - ``P``: ``N^{-1/2} P*_{k-1/k-1} N^{-1/2} = [[1, ρ], [ρ, 1]]`` (C.7), dimensionless.
    - ``tau``: ``τ = τ* sqrt(p_v*/p_x*)`` (C.10, eqs. (122)–(123)).
    - ``Q``: ``N^{-1/2} Q* N^{-1/2}`` (C.16).
    - ``r_x``: ``R*/p_x*`` (C.13, eq. (125)).
    - ``scale``: ``sqrt(p_x*), sqrt(p_v*)`` — the diagonal of ``N^{1/2}`` (ft, ft/s).
    """

    P: Float[Array, "2 2"]
    tau: Array
    Q: Float[Array, "2 2"]
    r_x: Array
    scale: Float[Array, " 2"]


def normalize(P_prev: ArrayLike, tau: ArrayLike, Q: ArrayLike, r: ArrayLike) -> Normalization:
    r"""Normalise one stage of the position/velocity filter (Ho 1968, Appendix C, eqs. (118)–(127)).

    ``N = diag(p_x*, p_v*)`` from the dimensional ``P*_{k-1/k-1}`` (renewed at every stage, so
    the normalised formulas are one-stage relations). Position-only measurements
    ``H* = [1 0]`` map to ``H = [1 0]`` (C.13); general ``H* = [h₁ h₂]`` cannot be brought to
    that form by rescaling the measurement and is not supported.

    **Arguments:** ``P_prev`` ``P*_{k-1/k-1}`` ``(2, 2)`` (ft², ft²/s, ft²/s²), ``tau`` τ* (s),
    ``Q`` ``Q*`` ``(2, 2)``, ``r`` ``R*`` (ft²).

    **Returns:** :class:`Normalization`.
    """
    P = jnp.asarray(P_prev)
    if P.shape != (2, 2):
        raise InputError(f"`P_prev` must be the 2×2 position/velocity covariance; got shape {P.shape}.")
    check_covariance("P_prev", P)
    Q = jnp.asarray(Q)
    if Q.shape != (2, 2):
        raise InputError(f"`Q` must have shape (2, 2); got {Q.shape}.")
    scale = jnp.sqrt(jnp.diagonal(P))
    inv = 1.0 / scale
    return Normalization(
        P * inv[:, None] * inv[None, :],
        jnp.asarray(tau) * scale[1] / scale[0],
        Q * inv[:, None] * inv[None, :],
        jnp.asarray(r) / P[0, 0],
        scale,
    )


def denormalize(P: ArrayLike, scale: ArrayLike) -> Float[Array, "2 2"]:
    """Back to dimensional units: ``N^{1/2} P N^{1/2}`` (Appendix C, inverse of (C.9)).

    **Arguments:**

    - ``P``: a normalised covariance, ``(2, 2)``, dimensionless.
    - ``scale``: the diagonal of ``N^{1/2}``, ``(2,)``: ``sqrt(p_x*)`` (ft), ``sqrt(p_v*)`` (ft/s), as in
      :attr:`Normalization.scale`.

    **Returns:** the dimensional covariance, ``(2, 2)`` (ft², ft²/s, ft²/s²).
    """
    s = jnp.asarray(scale)
    return jnp.asarray(P) * s[:, None] * s[None, :]

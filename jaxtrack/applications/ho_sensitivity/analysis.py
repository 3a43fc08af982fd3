"""Sec. III-E and Sec. IV analyses of Ho (1968): segment sensitivities, the value of a velocity
measurement (adjoint), and the one-stage examples of Sec. IV-B.

Numerics: :mod:`jaxtrack.sensitivity` (segment indices, adjoint, one-stage closed forms) and
:func:`jaxtrack.covariance.covariance_recursion`.
"""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ...covariance import covariance_recursion
from ...models import LinearGaussianModel, sample_times
from ...sensitivity import (
    Analytic,
    SegmentSensitivity,
    normalize,
    one_stage_update,
    segment_sensitivity,
    updated_position_variance,
)
from .scenario import POSITION, SEC4_P, UNIFORM, adjoint_history, sample_index, scenario, segment_model_fn


def segment_sensitivities(
    counts: Sequence[int] = UNIFORM, g: float = 1.0, *, smoothed: bool = False, method=Analytic()
) -> SegmentSensitivity:
    """Ho's ``s(τ_i)`` (Figs. 8, 11, 13) for a scheme: time-fixed (Convention 3) and sample-fixed.

    **Arguments:** ``counts`` samples per segment ``(S,)``; ``g`` plant noise in g; ``smoothed``
    for Example 2's ``R = 10³/τ``; ``method`` ``Analytic()`` or ``Autodiff()``.

    **Returns:** :class:`~jaxtrack.sensitivity.SegmentSensitivity`, ``(S,)`` arrays in ft² of
    terminal position variance per second of segment period. In the smoothed case the first
    sample's ``R(τ_1)`` counts toward ``s_1`` (its true derivative); the spec's reference omits
    that term (415.4 there, 324.3 here for 1 g); segments 2–5 are unaffected.
    """
    counts = tuple(counts)
    taus = 1.0 / jnp.asarray(counts, dtype=jnp.result_type(float))
    return segment_sensitivity(segment_model_fn(counts, g, smoothed=smoothed), taus, counts, POSITION, method=method)


class VelocityMeasurementValue(eqx.Module):
    """Sec. III-E: the value of one extra velocity measurement (all ft² unless stated).

    - ``L22``: adjoint ``L_{k/k}(2,2)`` at the measurement time, ft² per (ft/s)².
    - ``P22``: ``P_{k/k}(2,2)`` there, (ft/s)².
    - ``estimate``: the paper's first-order gain ``L22·(P22 − R_v)``.
    - ``actual_reduction``: the exact drop of ``P_T(1,1)`` with the measurement processed and all
      later gains re-optimised.
    - ``terminal``: ``P_T(1,1)`` without it.
    """

    L22: Float[Array, ""]
    P22: Float[Array, ""]
    estimate: Float[Array, ""]
    actual_reduction: Float[Array, ""]
    terminal: Float[Array, ""]


def velocity_measurement_estimate(t: float, g: float, velocity_var: float = 100.0) -> VelocityMeasurementValue:
    """Sec. III-E: value of one extra velocity measurement at time ``t`` (Figs. 9, 12).

    The actual reduction runs the covariance recursion with a two-component measurement
    ``[position, velocity]`` whose velocity component is present only at ``t``: with independent
    noises this equals the velocity update after the position update at ``t``, the later gains
    re-optimised.

    **Arguments:** ``t`` sample time, s (on the (10,…) scheme); ``g`` plant noise in g;
    ``velocity_var`` ``R_v``, (ft/s)².

    **Returns:** :class:`VelocityMeasurementValue`.
    """
    model, taus = scenario(UNIFORM, g)
    times = np.asarray(sample_times(taus))
    k = sample_index(times, t)
    hist = covariance_recursion(model)
    L, _ = adjoint_history(UNIFORM, g)
    P = hist.filtered_cov[k]
    # Measure [position, velocity] with independent noises (R_p, R_v); velocity only at sample k.
    R = jnp.diag(jnp.stack([model.R[..., 0, 0], jnp.asarray(velocity_var, P.dtype)]))
    with_velocity = LinearGaussianModel(model.F, model.Q, jnp.eye(2, dtype=P.dtype), R, model.initial_mean, model.initial_cov)
    mask = np.ones((times.shape[0], 2), bool)
    mask[:, 1] = np.arange(times.shape[0]) == k
    J_new = covariance_recursion(with_velocity, mask=jnp.asarray(mask)).filtered_cov[-1, 0, 0]
    J0 = hist.filtered_cov[-1, 0, 0]
    L22 = jnp.asarray(L[k, 1, 1])
    return VelocityMeasurementValue(L22=L22, P22=P[1, 1], estimate=L22 * (P[1, 1] - velocity_var),
                                    actual_reduction=J0 - J_new, terminal=J0)


class Sec4Example1(eqx.Module):
    """Sec. IV-B Example 1 (eqs. (136)–(139)), dimensionless unless stated.

    ``rho`` ρ; ``tau_scale`` τ/τ*; ``r_x``; ``alpha`` α (``q_x = ατ``); ``a = 2ρ + α``; ``tau``
    the normalised period; ``p_x`` the normalised ``(p_x)_{k/k}`` by eq. (129); ``p_x_ft2``
    ``(p_x*)_{k/k}`` in ft² from the full 2×2 one-stage map (99).
    """

    rho: Float[Array, ""]
    tau_scale: Float[Array, ""]
    r_x: Float[Array, ""]
    alpha: Float[Array, ""]
    a: Float[Array, ""]
    tau: Float[Array, ""]
    p_x: Float[Array, ""]
    p_x_ft2: Float[Array, ""]


def sec4_example1(tau_star: float = 0.1) -> Sec4Example1:
    """Sec. IV-B Example 1 (eqs. (136)–(139)): normalise P*(1 s), take one stage with τ*.

    **Arguments:** ``tau_star`` the physical period τ*, s.

    **Returns:** :class:`Sec4Example1`.
    """
    q_star = np.diag([0.259 * tau_star, 104.0 * tau_star])
    n = normalize(SEC4_P, tau_star, q_star, 1e4)
    rho = float(n.P[0, 1])
    scale = float(n.scale[1] / n.scale[0])
    alpha = 0.259 / (SEC4_P[0, 0] * scale)
    a = 2 * rho + alpha
    tau = float(n.tau)
    p_x = float(updated_position_variance(a, tau, n.r_x))
    full = one_stage_update(n.P[0, 1], n.tau, n.Q[0, 0], n.Q[1, 1], n.r_x)
    values = (rho, scale, float(n.r_x), alpha, a, tau, p_x, float(full.p_x) * SEC4_P[0, 0])
    return Sec4Example1(*(jnp.asarray(v) for v in values))


class Sec4Example3(eqx.Module):
    """Sec. IV-B Example 3: ``p_x`` the operating point ``(p_x)_{k/k}`` at τ = 1, a = 1, r_x = 1;
    ``a_needed`` the ``a`` that keeps it at τ = 2 with ``r_x = 1``; ``r_x_needed`` the ``r_x``
    that keeps it at τ = 2 with ``a = 1`` (all dimensionless)."""

    p_x: Float[Array, ""]
    a_needed: Float[Array, ""]
    r_x_needed: Float[Array, ""]


def sec4_example3() -> Sec4Example3:
    """Sec. IV-B Example 3: keep ``(p_x)_{k/k} = 0.75`` while τ goes 1 → 2 (eqs. (128)–(129)).

    Closed-form inverses of (129): ``1/p = 1/r_x + 1/(1 + aτ + τ²)``.

    **Returns:** :class:`Sec4Example3`.
    """
    p = float(updated_position_variance(1.0, 1.0, 1.0))
    m_needed = 1.0 / (1.0 / p - 1.0)  # with r_x = 1
    tau = 2.0
    a_needed = (m_needed - 1.0 - tau**2) / tau
    m = 1.0 + tau + tau**2  # a = 1
    r_needed = 1.0 / (1.0 / p - 1.0 / m)
    return Sec4Example3(jnp.asarray(p), jnp.asarray(a_needed), jnp.asarray(r_needed))

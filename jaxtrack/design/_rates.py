"""Sampling design over time and across targets (Ho 1968, Sec. III-C/D) and per-step periods.

- :func:`per_step_design` — one period per step (fixed number of samples over a fixed span).
- :func:`allocate_rates` — III-C, eqs. (75)–(78): real-time rate allocation across trajectories.
- :func:`maneuver_period_change` — III-D, eqs. (79)–(80): the period cut that offsets a detected
  increase of the acceleration noise.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, ArrayLike

from .._validation import InputError
from ..covariance import covariance_recursion
from ..models import LinearGaussianModel
from ..sensitivity import Analytic, sensitivity_index
from ._schedules import Objective, _weight

# ----------------------------------------------------------------------------------------------
# Per-step periods


class PerStepDesign(NamedTuple):
    """Result of :func:`per_step_design`: ``taus`` ``(N,)`` (``taus[0]`` unused: the prior sits on
    the first sample), ``times`` ``(N,)`` sample times, ``cost`` J, ``history`` J per step."""

    taus: np.ndarray
    times: np.ndarray
    cost: float
    history: np.ndarray


def per_step_design(
    model_fn: Callable[[Array], LinearGaussianModel],
    num_samples: int,
    span: float,
    weight: ArrayLike,
    *,
    first_time: float | None = None,
    min_period: float = 0.0,
    objective: Objective = "terminal",
    steps: int = 400,
    learning_rate: float = 0.05,
) -> PerStepDesign:
    r"""One sampling period per step, optimised with optax (fixed sample count, fixed span).

    The ``N − 1`` intervals between the first and the last sample are
    ``τ_k = τ_min + (span − (N−1)τ_min)·softmax(θ)_k``, so they are positive, at least
    ``min_period`` (a radar's fastest revisit) and sum to ``span`` for every θ; Adam minimises
    ``tr(L P_T)`` or ``Σ_k tr(L P_{k/k})`` over θ, starting from the uniform schedule. The prior
    sits on the first sample (``first_step="update"``).

    **Arguments:** ``model_fn`` ``taus (N,) -> LinearGaussianModel``, ``num_samples`` N,
    ``span`` seconds from the first to the last sample, ``weight`` L, ``first_time`` (only for the
    returned ``times``; defaults to ``span/(N−1)``), ``min_period``, ``objective``, ``steps``,
    ``learning_rate``.

    **Returns:** :class:`PerStepDesign`.
    """
    N = int(num_samples)
    if N < 2:
        raise InputError(f"`num_samples` must be at least 2; got {num_samples}.")
    if not 0 <= min_period * (N - 1) < span:
        raise InputError(f"`min_period` × (N − 1) must be below `span`; got {min_period} × {N - 1} ≥ {span}.")
    L = _weight(weight, model_fn(jnp.full(N, span / (N - 1))).state_dim)
    if objective not in ("terminal", "running"):
        raise InputError(f"`objective` must be 'terminal' or 'running'; got {objective!r}.")
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise InputError(f"`steps` must be a positive int; got {steps!r}.")
    theta, hist, J = _per_step_run(model_fn, jnp.zeros(N - 1), L, float(span), float(min_period), objective,
                                   int(steps), float(learning_rate))
    taus = np.asarray(_per_step_taus(theta, span, min_period))
    t0 = span / (N - 1) if first_time is None else first_time
    times = t0 + np.concatenate([[0.0], np.cumsum(taus[1:])])
    return PerStepDesign(taus, times, float(J), np.asarray(hist))


def _per_step_taus(theta, span, min_period):
    N1 = theta.shape[0]
    intervals = min_period + (span - N1 * min_period) * jax.nn.softmax(theta)
    return jnp.concatenate([intervals[:1], intervals])  # taus[0] is unused (prior on the first sample)


@eqx.filter_jit
def _per_step_run(model_fn, theta0, L, span, min_period, objective, steps, learning_rate):
    def cost(theta):
        P = covariance_recursion(model_fn(_per_step_taus(theta, span, min_period))).filtered_cov
        if objective == "terminal":
            return jnp.trace(L @ P[-1])
        return jnp.sum(jnp.einsum("ij,kji->k", L, P))

    opt = optax.adam(learning_rate)

    def step(carry, _):
        theta, state = carry
        J, g = jax.value_and_grad(cost)(theta)
        updates, state = opt.update(g / (jnp.abs(J) + 1e-30), state)
        return (optax.apply_updates(theta, updates), state), J

    (theta, _), hist = jax.lax.scan(step, (theta0, opt.init(theta0)), None, length=steps)
    return theta, hist, cost(theta)


# ----------------------------------------------------------------------------------------------
# III-C and III-D


def allocate_rates(rates: ArrayLike, sensitivities: ArrayLike, capacity: float) -> np.ndarray:
    r"""Real-time rate changes that equalise the terminal degradations (Ho 1968, eqs. (75)–(78)).

    .. math::

        s^{(1)}Δc_1 = s^{(2)}Δc_2 = …,\qquad \sum_i (c_i + Δc_i) = \mathcal{L}

        Δc_1 = \frac{\mathcal{L} − \sum_i c_i}{s^{(1)}\sum_i 1/s^{(i)}},\qquad
        Δc_i = s^{(1)}Δc_1/s^{(i)} \qquad (78)

    ``s^{(i)} = ∂J^{(i)}/∂c_i`` is trajectory i's sensitivity to its iteration rate from its current
    stage to its end (with ``c = 1/τ``, ``s_c = −τ² s_τ``). If ``Σc_i > ℒ`` every ``Δc_i < 0`` and
    each trajectory loses the same ``ΔJ = s Δc > 0``.

    **Arguments:** ``rates`` ``c_i`` ``(m,)`` (Hz), ``sensitivities`` ``s^{(i)}`` ``(m,)`` (nonzero;
    any sign), ``capacity`` ℒ (Hz). **Returns:** ``Δc`` ``(m,)``.
    """
    c = np.asarray(rates, float)
    s = np.asarray(sensitivities, float)
    if c.shape != s.shape or c.ndim != 1:
        raise InputError(f"`rates` and `sensitivities` must be 1-D of one length; got {c.shape}, {s.shape}.")
    if np.any(s == 0) or not np.all(np.isfinite(s)):
        raise InputError("`sensitivities` must be finite and nonzero (eq. (78) divides by each).")
    inv = np.sum(1.0 / s)
    if inv == 0:
        raise InputError("Σ 1/s_i = 0: the equal-degradation allocation (78) has no solution.")
    dc1 = (capacity - c.sum()) / (s[0] * inv)
    return s[0] * dc1 / s


class ManeuverCompensation(NamedTuple):
    """Result of :func:`maneuver_period_change`: ``delta_tau`` (s) and the indices it used,
    ``s_tau = ∂J_{k+m}/∂τ`` and ``s_a = ∂J_{k+m}/∂a`` (units of J per s and per unit of a)."""

    delta_tau: float
    s_tau: float
    s_a: float


def maneuver_period_change(
    model_fn: Callable[[Array, Array], LinearGaussianModel],
    tau: float,
    a: float,
    delta_a: float,
    weight: ArrayLike,
    *,
    time_fixed: bool = False,
    method=Analytic(),
) -> ManeuverCompensation:
    r"""Period change that offsets an acceleration-noise increase (Ho 1968, Sec. III-D, (79)–(80)).

    .. math::  Δτ = −\Big(\frac{∂J_{k+m}}{∂τ}\Big)^{-1}\frac{∂J_{k+m}}{∂a}\,Δa \qquad (80)

    ``model_fn(τ, a)`` is the ``m``-stage model from the detection stage ``k`` (its
    ``initial_cov`` = ``P_{k/k}``, use ``first_step="predict"`` semantics: every stage predicts),
    with the acceleration-noise level ``a``; the indices are run with zero initial sensitivities
    at ``k`` (the memo's "zero initial values"). ``time_fixed=True`` adds the correction (50)
    with ``k = m`` to ``∂J/∂τ``. ``m = 1`` is eq. (79).

    **Arguments:**

    - ``model_fn``: ``(τ, a) -> LinearGaussianModel``, the ``m``-stage model described above.
    - ``tau``: the sampling period ``τ`` (s); ``a``: the acceleration-noise level.
    - ``delta_a``: the increase ``Δa`` (units of ``a``).
    - ``weight``: ``L``, ``(n, n)``; ``J = tr(L P)``.
    - ``time_fixed``: add the time-fixed correction (50).
    - ``method``: the sensitivity method, ``Analytic()`` (default) or ``Autodiff()``.

    **Returns:** :class:`ManeuverCompensation`.
    """
    L = jnp.asarray(weight, dtype=jnp.result_type(float))

    def J_of(tau_, a_):
        return covariance_recursion(model_fn(tau_, a_), first_step="predict").filtered_cov

    s_tau = sensitivity_index(lambda t: model_fn(t, jnp.asarray(a)), tau, L, method=method, first_step="predict")
    s_a = sensitivity_index(lambda x: model_fn(jnp.asarray(tau), x), a, L, method=method, first_step="predict")
    if time_fixed:
        P = J_of(jnp.asarray(tau), jnp.asarray(a))
        m = P.shape[0]
        s_tau = s_tau + (m / tau) * jnp.trace(L @ ((P[-2] if m > 1 else model_fn(tau, a).initial_cov) - P[-1]))
    s_tau, s_a = float(s_tau), float(s_a)
    return ManeuverCompensation(-s_a * delta_a / s_tau, s_tau, s_a)

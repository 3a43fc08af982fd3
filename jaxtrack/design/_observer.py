"""Observer-trajectory design by gradient on the posterior Cramér–Rao bound (bearings-only tracking).

A bearings-only observer must maneuver to make the range observable (Lindgren & Gong 1977; Nardone
& Aidala 1981). Here the maneuver itself is the design variable: the observer sails at a fixed speed
with a per-interval turn rate ``ω_k = ω_max · tanh(c_k)`` (so the turn-rate limit holds for any
real control ``c``: the constraint is enforced by the parametrisation, no projection), its path
is integrated exactly arc by arc, and the controls are optimised with optax to minimise the
**trace of the position block of the terminal PCRLB** (Tichavský, Muravchik & Nehorai 1998,
eq. (21), by :func:`jaxtrack.bounds.pcrlb`), of the relative-state bearings-only model
(:class:`jaxtrack.models.RelativeBearingModel`) with the expectation over truths drawn from the
prior, under fixed keys (common random numbers: the objective is a smooth deterministic function
of the controls). The criterion is the A-optimal one (the bound on the terminal position MSE,
m²), not ``−log det J``: it is what a tracker is judged by and has the same units as the MSE a
Monte Carlo measures.

Conventions: compass headings ``ψ`` (rad clockwise from +y/north), velocity ``v (sin ψ, cos ψ)``,
states ``[x, y, ẋ, ẏ]`` (m, m/s), samples ``k = 0, …, K`` every ``sample_period`` s.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from .._validation import InputError, check_finite, check_shape
from ..bounds import pcrlb
from ..models import RelativeBearingModel, constant_velocity_transition

__all__ = [
    "ObserverDesign",
    "constrained_turn_rates",
    "observer_states",
    "bearing_position_bound",
    "design_observer_path",
]


def constrained_turn_rates(controls: ArrayLike, max_turn_rate: ArrayLike) -> Array:
    """Turn rates within the limit for any real controls: ``ω_k = ω_max · tanh(c_k)``.

    **Arguments:** ``controls`` ``(K,)`` (dimensionless, any real); ``max_turn_rate`` ``()`` rad/s.

    **Returns:** ``(K,)`` rad/s, ``|ω_k| < ω_max``.
    """
    c = jnp.asarray(controls)
    c = c.astype(jnp.result_type(c, float))
    return jnp.asarray(max_turn_rate, c.dtype) * jnp.tanh(c)


def observer_states(
    turn_rates: ArrayLike,
    *,
    initial_heading: ArrayLike,
    speed: ArrayLike,
    sample_period: ArrayLike,
    start: ArrayLike = (0.0, 0.0),
) -> Array:
    """Observer states at the samples of a constant-speed path with a constant turn rate per interval.

    Over interval ``k`` the heading turns at ``ω_k``: ``ψ_{k+1} = ψ_k + ω_k t_s``, and the
    displacement is the exact arc ``v t_s sinc(ω_k t_s / 2) (sin, cos)(ψ_k + ω_k t_s / 2)``
    (finite and smooth through ``ω = 0``, so the path is differentiable in ``ω``).

    **Arguments:**

    - ``turn_rates``: ``(K,)`` rad/s (positive = clockwise, compass convention).
    - ``initial_heading``: ``ψ_0``, rad clockwise from north; ``speed``: m/s; ``sample_period``: s.
    - ``start``: ``(2,)`` position at ``t = 0``, m.

    **Returns:** ``(K+1, 4)`` ``[x, y, ẋ, ẏ]`` (m, m/s), velocity the one at the sample.
    """
    w = jnp.asarray(turn_rates)
    w = w.astype(jnp.result_type(w, float))
    check_shape("turn_rates", w, [(None,)])
    dtype = w.dtype
    dt = jnp.asarray(sample_period, dtype)
    v = jnp.asarray(speed, dtype)
    psi0 = jnp.asarray(initial_heading, dtype)
    p0 = jnp.asarray(start, dtype)
    check_shape("start", p0, [(2,)])
    half = 0.5 * w * dt
    psi = psi0 + jnp.concatenate([jnp.zeros((1,), dtype), jnp.cumsum(w * dt)])
    mid = psi[:-1] + half
    # jnp.sinc(x) = sin(πx)/(πx), with a finite derivative at 0.
    arc = v * dt * jnp.sinc(half / jnp.pi)
    steps = jnp.stack([arc * jnp.sin(mid), arc * jnp.cos(mid)], axis=-1)
    pos = p0[None, :] + jnp.concatenate([jnp.zeros((1, 2), dtype), jnp.cumsum(steps, axis=0)])
    vel = v * jnp.stack([jnp.sin(psi), jnp.cos(psi)], axis=-1)
    return jnp.concatenate([pos, vel], axis=-1)


def _bearing_model(observer, target_mean, target_cov, bearing_std, sample_period):
    """The relative-state bearings-only model of an observer track (prior on ``x_R(0)``, ``first_step="update"``)."""
    xo = observer
    dt = jnp.asarray(sample_period, xo.dtype)
    phi = constant_velocity_transition(dt, dtype=xo.dtype)
    # u(k) = x_O(k+1) − Φ x_O(k) (Lindgren & Gong eq. 67b, general path); entry 0 is the unused
    # transition into step 0 under first_step="update".
    u = jnp.concatenate([jnp.zeros((1, 4), xo.dtype), xo[1:] - xo[:-1] @ phi.T], axis=0)
    m0 = jnp.asarray(target_mean, xo.dtype) - xo[0]
    return RelativeBearingModel(u, dt, jnp.asarray(bearing_std, xo.dtype) ** 2, m0, jnp.asarray(target_cov, xo.dtype))


def bearing_position_bound(
    observer: ArrayLike,
    target_mean: ArrayLike,
    target_cov: ArrayLike,
    bearing_std: ArrayLike,
    sample_period: ArrayLike,
    key: PRNGKeyArray,
    num_runs: int,
) -> Array:
    """Trace of the position block of the terminal PCRLB of a bearings-only observer track (m²).

    The model is :class:`~jaxtrack.models.RelativeBearingModel` with the observer input
    ``u(k) = x_O(k+1) − Φ x_O(k)`` (Lindgren & Gong eq. 67b), compass bearings with σ
    ``bearing_std``, no target plant noise, and the prior ``x_T(0) ~ N(target_mean, target_cov)``
    (so ``x_R(0) ~ N(target_mean − x_O(0), target_cov)``); the bound is
    :func:`jaxtrack.bounds.pcrlb` (Tichavský et al. 1998, eq. 21) over ``num_runs`` truths drawn
    from ``key``, ``first_step="update"`` (a bearing at every sample ``k = 0, …, K``).
    Differentiable in ``observer`` (and the other arrays).

    **Arguments:**

    - ``observer``: ``(K+1, 4)`` observer states (m, m/s), e.g. :func:`observer_states`.
    - ``target_mean`` ``(4,)``: the target's state at ``t = 0`` (m, m/s); ``target_cov`` ``(4, 4)``.
    - ``bearing_std``: rad; ``sample_period``: s; ``key``, ``num_runs``: the truths.

    **Returns:** ``()``, m², the bound on ``E‖r̂_R(K) − r_R(K)‖²``.
    """
    xo = jnp.asarray(observer)
    xo = xo.astype(jnp.result_type(xo, float))
    check_shape("observer", xo, [(None, 4)])
    model = _bearing_model(xo, target_mean, target_cov, bearing_std, sample_period)
    B = pcrlb(model, key, num_runs).bound
    return B[-1, 0, 0] + B[-1, 1, 1]


class ObserverDesign(eqx.Module):
    """An observer path designed by gradient (:func:`design_observer_path`).

    - ``controls`` ``(K,)``: the optimised unconstrained controls; ``turn_rates`` ``(K,)`` rad/s.
    - ``observer`` ``(K+1, 4)``: the designed observer states (m, m/s).
    - ``objective`` ``()``: the objective at the returned controls (units of the objective).
    - ``history`` ``(S+1,)``: the objective at the start and after each of the ``S`` optimiser steps.
    """

    controls: Float[Array, " K"]
    turn_rates: Float[Array, " K"]
    observer: Float[Array, "K1 4"]
    objective: Float[Array, ""]
    history: Float[Array, " S1"]


def design_observer_path(
    objective,
    initial_controls: ArrayLike,
    *,
    max_turn_rate: float,
    initial_heading: float,
    speed: float,
    sample_period: float,
    start: ArrayLike = (0.0, 0.0),
    optimizer=None,
    num_steps: int = 200,
) -> ObserverDesign:
    """Design an observer's turn-rate sequence by gradient descent (optax) on ``objective``.

    The path is :func:`observer_states` of ``constrained_turn_rates(controls, max_turn_rate)``:
    constant speed, the turn-rate limit enforced by the ``tanh`` parametrisation. The objective
    (e.g. :func:`bearing_position_bound` with fixed keys) is minimised on the log scale (a bound
    spans decades; the log makes the step size scale-free); the best iterate is returned.

    **Arguments:**

    - ``objective``: ``observer (K+1, 4) -> ()``, differentiable, positive.
    - ``initial_controls``: ``(K,)`` the starting controls (e.g. ``arctanh`` of a known maneuver's
      rates over ``max_turn_rate``, clipped).
    - ``max_turn_rate``: rad/s; ``initial_heading``: rad (compass); ``speed``: m/s;
      ``sample_period``: s; ``start``: ``(2,)`` m.
    - ``optimizer``: an optax optimizer (default ``optax.adam(0.05)``); ``num_steps``: ``S ≥ 0``.

    **Returns:** :class:`ObserverDesign`.

    **Raises:** ``InputError`` for non-finite controls, a non-positive limit, speed or period, or
    ``num_steps < 0``.
    """
    import optax

    c0 = jnp.asarray(initial_controls)
    c0 = c0.astype(jnp.result_type(c0, float))
    check_shape("initial_controls", c0, [(None,)])
    check_finite("initial_controls", c0)
    for name, val in (("max_turn_rate", max_turn_rate), ("speed", speed), ("sample_period", sample_period)):
        if not np.isfinite(val) or val <= 0:
            raise InputError(f"`{name}` must be positive and finite; got {val!r}.")
    if not isinstance(num_steps, (int, np.integer)) or num_steps < 0:
        raise InputError(f"`num_steps` must be a non-negative int; got {num_steps!r}.")
    opt = optax.adam(0.05) if optimizer is None else optimizer

    def path(c):
        return observer_states(constrained_turn_rates(c, max_turn_rate), initial_heading=initial_heading,
                               speed=speed, sample_period=sample_period, start=start)

    def loss(c):
        return jnp.log(objective(path(c)))

    value_and_grad = jax.value_and_grad(loss)

    @eqx.filter_jit
    def step(c, state):
        val, g = value_and_grad(c)
        updates, state = opt.update(g, state, c)
        return optax.apply_updates(c, updates), state, val

    c, state = c0, opt.init(c0)
    history, best_val, best_c = [], np.inf, c0
    for _ in range(int(num_steps)):
        c_new, state, val = step(c, state)
        val = float(val)
        history.append(val)
        if val < best_val:
            best_val, best_c = val, c
        c = c_new
    final = float(loss(c))
    history.append(final)
    if final < best_val:
        best_val, best_c = final, c
    rates = constrained_turn_rates(best_c, max_turn_rate)
    return ObserverDesign(best_c, rates, path(best_c), jnp.exp(jnp.asarray(best_val, c0.dtype)),
                          jnp.exp(jnp.asarray(history, c0.dtype)))

"""Sec. III of Ho (1968) on the Sec. III-E plant: sampling-period design examples.

The algorithms live in :mod:`jaxtrack.design` (Newton step III-A, segment exchange III-B, rate
allocation III-C, maneuver compensation III-D, relaxed/gradient and per-step designs); this module
sets them up on the 1/s² plant and returns their results.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ... import design
from ...covariance import covariance_recursion
from ...models import LinearGaussianModel, ho_plant
from ...sensitivity import sensitivity_index
from .scenario import POSITION, UNIFORM, history, measurement_var, sample_index, terminal_position_variance


def segment_problem(g: float = 1.0, *, smoothed: bool = False) -> design.SegmentProblem:
    """The five 1-s segments of Sec. III-E as a :class:`~jaxtrack.design.SegmentProblem` (J = P_T(1,1)).

    **Arguments:** ``g`` plant noise in g; ``smoothed`` for ``R = 10³/τ`` ft².
    **Returns:** :class:`~jaxtrack.design.SegmentProblem` over 5 segments.
    """

    def model_fn(taus):
        return ho_plant(taus, g=g, measurement_var=measurement_var(taus, smoothed))

    return design.SegmentProblem(model_fn, jnp.asarray(POSITION), 5)


def newton_example(target: float = 1000.0, *, sensitivity: str = "sample-fixed") -> design.NewtonResult:
    """III-A on 50 uniform samples, 1 g: the τ with P_T(1,1) = J* (spec T33).

    **Arguments:** ``target`` J* in ft²; ``sensitivity`` ``"sample-fixed"`` or ``"time-fixed"``.
    **Returns:** :class:`~jaxtrack.design.NewtonResult` (iterates of τ in s and J in ft²).
    """
    return design.newton_uniform_period(lambda t: ho_plant(jnp.full(50, t)), 0.1, target, POSITION,
                                        sensitivity=sensitivity)


class ScheduleCost(eqx.Module):
    """A segment scheme and its terminal position variance: ``counts`` samples per 1-s segment
    (integers, or the relaxed design's continuous counts rounded to 0.01), ``cost`` J in ft²."""

    counts: tuple = eqx.field(static=True)
    cost: Float[Array, ""]


class DesignComparison(eqx.Module):
    """Schedules with the same sample budget and their J (see :func:`design_comparison`).

    ``exchange`` is ``None`` unless asked for; ``schemes_searched`` counts the exhaustive search.
    """

    uniform: ScheduleCost
    ho: ScheduleCost
    relaxed: ScheduleCost
    rounded: ScheduleCost
    gradient: ScheduleCost
    optimum: ScheduleCost
    schemes_searched: int = eqx.field(static=True)
    exchange: ScheduleCost | None = None


def _scheme(counts, cost) -> ScheduleCost:
    return ScheduleCost(tuple(counts), jnp.asarray(cost))


@functools.lru_cache(maxsize=8)
def design_comparison(g: float = 1.0, total: int = 40, hi: int = 20, *, exchange: bool = False) -> DesignComparison:
    """Schedules for ``total`` samples in five 1-s segments (caps 1 ≤ n_i ≤ ``hi``), with their J (ft²).

    ``uniform`` (8,8,8,8,8); ``ho``: Ho's rule applied to the 50-sample uniform scheme (remove 10
    from the least sensitive segments, 50% cap); ``relaxed``: optax on continuous counts;
    ``gradient``: that rounded and polished by the 1-exchange local search; ``optimum``: the
    exhaustive integer search; with ``exchange=True`` also ``exchange``: Ho's exchange algorithm
    with the corrected condition, from the uniform scheme (slower: sensitivities at every move).
    Cached: the same arguments return the same (immutable) result.

    **Arguments:** ``g`` plant noise in g; ``total`` sample budget; ``hi`` cap per segment;
    ``exchange`` also run the exchange algorithm.

    **Returns:** :class:`DesignComparison`.
    """
    problem = segment_problem(g)
    uniform = (total // 5,) * 5
    ho_counts = design.ho_reduction(problem, UNIFORM, sum(UNIFORM) - total)
    relaxed = design.relaxed_segment_design(problem, total, hi=hi)
    rounded = design.round_counts(relaxed.counts, total, 1, hi)
    polished, J_polished = design.local_search(problem, rounded, hi=hi)
    best, J_best, n_schemes = design.exhaustive_counts(problem, total, hi=hi)
    extra = None
    if exchange:
        counts, _ = design.segment_exchange(problem, uniform, max_relative_change=0.25)
        extra = _scheme(counts, problem.cost(counts))
    return DesignComparison(
        uniform=_scheme(uniform, problem.cost(uniform)),
        ho=_scheme(ho_counts, problem.cost(ho_counts)),
        relaxed=_scheme(np.round(relaxed.counts, 2).tolist(), relaxed.cost),
        rounded=_scheme(rounded, problem.cost(rounded)),
        gradient=_scheme(polished, J_polished),
        optimum=_scheme(best, J_best),
        schemes_searched=int(n_schemes),
        exchange=extra,
    )


def per_step_example(g: float = 1.0, *, min_period: float = 0.0) -> design.PerStepDesign:
    """Per-step periods for 50 samples between 0.1 s and 5.0 s (the span of the (10,…) scheme).

    **Arguments:** ``g`` plant noise in g; ``min_period`` the least τ_k, s.
    **Returns:** :class:`~jaxtrack.design.PerStepDesign`.
    """
    return design.per_step_design(lambda t: ho_plant(t, g=g), 50, 4.9, POSITION, first_time=0.1,
                                  min_period=min_period)


class ManeuverExample(eqx.Module):
    """III-D on the 1/s² plant (see :func:`maneuver_example`).

    - ``P_k`` ``(2, 2)``: ``P_{k/k}`` at detection (ft units).
    - ``stages``: ``m``, the samples after detection.
    - ``a``: the raised plant-noise level, g.
    - ``delta_tau``, ``tau``: eq. (80)'s period change and the new period, s.
    - ``nominal``, ``uncompensated``, ``compensated``: ``J_{k+m}``, ft².

    :meth:`model_fn` ``(tau, a) -> LinearGaussianModel`` is the model of those ``m`` stages.
    """

    P_k: Float[Array, "2 2"]
    stages: int = eqx.field(static=True)
    a: Float[Array, ""]
    delta_tau: Float[Array, ""]
    tau: Float[Array, ""]
    nominal: Float[Array, ""]
    uncompensated: Float[Array, ""]
    compensated: Float[Array, ""]

    def model_fn(self, tau, a) -> LinearGaussianModel:
        """The ``stages`` samples after detection at period ``tau`` (s) and plant noise ``a`` (g),
        prior ``P_k`` (``first_step="predict"``)."""
        return _maneuver_model(tau, a, self.P_k, self.stages)


def _maneuver_model(tau, a, P_k, stages) -> LinearGaussianModel:
    return ho_plant(jnp.full(stages, tau), g=a, initial_cov=P_k)


def maneuver_example(delta_g: float = 3.0, stages: int = 10, detect_time: float = 2.5, g: float = 10.0) -> ManeuverExample:
    """III-D on the 1/s² plant: at ``detect_time`` the acceleration noise rises from ``g`` to
    ``g + delta_g`` for ``stages`` samples (the filter knows it); eq. (80) gives the period cut.

    **Arguments:** ``delta_g``, ``g`` in g; ``stages`` samples; ``detect_time`` s (a sample time
    of the (10,…) scheme).

    **Returns:** :class:`ManeuverExample`.
    """
    hist, times = history(UNIFORM, g)
    k = sample_index(times, detect_time, "detect_time")
    P_k = hist.filtered_cov[k]

    def model_fn(tau, a):
        return _maneuver_model(tau, a, P_k, stages)

    comp = design.maneuver_period_change(model_fn, 0.1, g, delta_g, POSITION)

    def J(tau, a):
        return covariance_recursion(model_fn(tau, a), first_step="predict").filtered_cov[-1, 0, 0]

    tau_new = 0.1 + comp.delta_tau
    return ManeuverExample(
        P_k=P_k, delta_tau=jnp.asarray(comp.delta_tau), tau=jnp.asarray(tau_new), a=jnp.asarray(g + delta_g),
        nominal=J(0.1, g), uncompensated=J(0.1, g + delta_g), compensated=J(tau_new, g + delta_g), stages=stages,
    )


class AllocationExample(eqx.Module):
    """III-C rate allocation over ``M`` trajectories (see :func:`allocation_example`).

    - ``stage`` ``(M,)``: each trajectory's last processed sample index.
    - ``s_c`` ``(M,)``: rate indices ``−τ² s_τ``, ft² per Hz.
    - ``delta_c`` ``(M,)``: rate changes (eq. (78)), Hz.
    - ``dJ_predicted``, ``dJ_actual`` ``(M,)``: ``s_c Δc`` and the re-sampled change of J, ft².
    - ``capacity``, ``new_total_rate``: Hz.
    """

    stage: Int[Array, " M"]
    s_c: Float[Array, " M"]
    delta_c: Float[Array, " M"]
    dJ_predicted: Float[Array, " M"]
    dJ_actual: Float[Array, " M"]
    capacity: Float[Array, ""]
    new_total_rate: Float[Array, ""]


def allocation_example(capacity: float = 25.0, now: float = 3.5, starts=(0.0, 1.5, 3.0)) -> AllocationExample:
    """III-C: three staggered 5-s trajectories (1 g, 10 Hz nominal) share a capacity of
    ``capacity`` Hz at real time ``now``; eqs. (77)–(78) give the rate changes.

    Each trajectory's index is ``s_c = −τ² s_τ`` for a change of its period over its remaining
    samples, time-fixed (eq. (50) at its end); the predicted ``ΔJ = s_c Δc`` is equal across
    trajectories and the actual ``ΔJ`` re-samples the remaining time at the new rate.

    **Arguments:** ``capacity`` Hz; ``now`` s; ``starts`` start times, s ``(M,)``.

    **Returns:** :class:`AllocationExample`.
    """
    tau = 0.1
    L = jnp.asarray(POSITION)
    stages, s_c, dJ_actual = [], [], []
    for start in starts:
        k = int(round((now - start) / tau)) - 1  # current (last processed) sample index
        remaining = 49 - k

        def model_fn(t, k=k):
            taus = jnp.concatenate([jnp.full(k + 1, tau), jnp.full(remaining, 1.0) * t])
            return ho_plant(taus)

        s_tau = float(sensitivity_index(model_fn, tau, L))
        P = covariance_recursion(model_fn(tau)).filtered_cov
        s_tau += remaining / tau * float(P[-2, 0, 0] - P[-1, 0, 0])  # time-fixed, eq. (50)
        stages.append(k)
        s_c.append(-(tau**2) * s_tau)
    rates = np.full(len(starts), 1.0 / tau)
    dc = design.allocate_rates(rates, s_c, capacity)
    for k, d in zip(stages, dc):
        remaining_time = (49 - k) * tau
        n_new = max(1, int(round(remaining_time * (1.0 / tau + d))))
        taus = np.concatenate([np.full(k + 1, tau), np.full(n_new, remaining_time / n_new)])
        J_new = float(covariance_recursion(ho_plant(jnp.asarray(taus))).filtered_cov[-1, 0, 0])
        dJ_actual.append(J_new - terminal_position_variance(UNIFORM, 1.0))
    return AllocationExample(
        stage=jnp.asarray(stages), s_c=jnp.asarray(s_c), delta_c=jnp.asarray(dc),
        dJ_predicted=jnp.asarray(np.asarray(s_c) * dc), dJ_actual=jnp.asarray(dJ_actual),
        capacity=jnp.asarray(capacity, dtype=jnp.result_type(capacity, float)), new_total_rate=jnp.asarray(float(np.sum(rates + dc))),
    )

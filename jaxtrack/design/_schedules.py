r"""Sampling-schedule design (Ho 1968, Sec. III): Newton, segment exchange, gradient schedules with optax.

A designer has a budget of measurements (or of computation) and wants the schedule with the
smallest terminal error ``J = tr(L_{T/T} P_{T/T})``, or the period that just meets a requirement
``J*``. Every method here evaluates ``J`` with the data-free covariance recursion
(:func:`jaxtrack.covariance.covariance_recursion`) and its derivatives with
:mod:`jaxtrack.sensitivity` (Ho's analytic recursions by default; ``method=Autodiff()`` gives the
same numbers).

- :func:`newton_uniform_period` — III-A, eqs. (65)–(67): the uniform τ meeting ``J*``.
- :class:`SegmentProblem` — Ho's piecewise-uniform schedules: time split into equal segments,
  ``n_i`` equally spaced samples in segment ``i`` (Convention 2 of ``specs/ho-sensitivity.md``).
- :func:`ho_reduction`, :func:`segment_exchange` — III-B, eqs. (68)–(74), with the corrected
  optimality condition (equal ``∂J/∂n_i = −s_i τ_i²/D_i``, not equal ``s_i``; spec §6 item 10).
- :func:`relaxed_segment_design`, :func:`round_counts`, :func:`local_search`,
  :func:`exhaustive_counts` — gradient design over continuous sample counts with caps, rounding
  and an integer local search, and the brute-force optimum to judge them by.
(Per-step periods, rate allocation and maneuver compensation: :mod:`jaxtrack.design._rates`.)
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Callable, Sequence
from typing import Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, ArrayLike

from .._validation import InputError
from ..covariance import covariance_recursion
from ..models import LinearGaussianModel, segment_schedule
from ..sensitivity import Analytic, segment_sensitivity, sensitivity_index

__all__ = [
    "NewtonResult",
    "newton_uniform_period",
    "SegmentProblem",
    "ho_reduction",
    "segment_exchange",
    "exhaustive_counts",
    "RelaxedDesign",
    "relaxed_segment_design",
    "round_counts",
    "local_search",
    "NotConvergedWarning",
]

Objective = Literal["terminal", "running"]


class NotConvergedWarning(RuntimeWarning):
    """An iterative design stopped at its iteration cap before meeting its stopping rule.

    Every loop in this module is capped (``max_iter``, ``steps``, or a bound derived from the
    input). :func:`newton_uniform_period` reports non-convergence in its ``converged`` field;
    :func:`segment_exchange` and :func:`local_search`, whose results are plain tuples, issue this
    warning instead (their result is still the best scheme found).
    """


def _check_max_iter(max_iter) -> int:
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise InputError(f"`max_iter` must be a positive int; got {max_iter!r}.")
    return int(max_iter)


def _weight(weight, n) -> Array:
    L = jnp.asarray(weight, dtype=jnp.result_type(float))
    if L.shape != (n, n):
        raise InputError(f"`weight` (L_T/T) must have shape ({n}, {n}); got {L.shape}.")
    return L


# ----------------------------------------------------------------------------------------------
# III-A: uniform period by Newton's method


class NewtonResult(NamedTuple):
    """Iterates of :func:`newton_uniform_period`: ``taus`` ``(i+1,)`` s and ``costs`` ``(i+1,)`` (J at each)."""

    taus: np.ndarray
    costs: np.ndarray
    converged: bool


def newton_uniform_period(
    model_fn: Callable[[Array], LinearGaussianModel],
    tau0: float,
    target: float,
    weight: ArrayLike,
    *,
    step_factor: float = 1.0,
    sensitivity: Literal["sample-fixed", "time-fixed"] = "sample-fixed",
    tol: float = 1e-9,
    max_iter: int = 20,
    method=Analytic(),
) -> NewtonResult:
    r"""The uniform sampling period with ``tr(L P_T) = J*`` (Ho 1968, Sec. III-A, eqs. (65)–(67)).

    .. math::

        τ_{i+1} = τ_i + λ\,\frac{J^* − \mathrm{tr}(L_{T/T}(P_{T/T})_i)}{\mathrm{tr}(L_{T/T}(∂P_{T/T}/∂τ)_i)}
        \qquad (66),\ (67)

    ``∂P_{T/T}/∂τ`` comes from (46)–(47) (``sensitivity="sample-fixed"``: the number of samples is
    fixed, the horizon moves) or adds the time-fixed correction (50) with ``k = T`` intervals
    (``"time-fixed"``, the memo's note for a fixed horizon; spec §6 item 21). ``λ < 1`` damps the
    step when the plain iteration does not converge (the memo proves nothing about convergence).

    **Arguments:** ``model_fn`` ``τ -> LinearGaussianModel`` (fixed number of samples),
    ``tau0`` s, ``target`` ``J*`` (units of J), ``weight`` ``L_{T/T}``, ``step_factor`` λ,
    ``tol`` (stop when ``|J − J*| ≤ tol·J*``), ``max_iter``, ``method``.

    **Returns:** :class:`NewtonResult` with every iterate (``taus[0] = tau0``).
    """
    if sensitivity not in ("sample-fixed", "time-fixed"):
        raise InputError(f"`sensitivity` must be 'sample-fixed' or 'time-fixed'; got {sensitivity!r}.")
    if not 0 < step_factor <= 1:
        raise InputError(f"`step_factor` (λ) must be in (0, 1]; got {step_factor}.")
    if not (np.isfinite(target) and target > 0):
        raise InputError(f"`target` (J*) must be positive and finite; got {target}.")
    if not (np.isfinite(tau0) and tau0 > 0):
        raise InputError(f"`tau0` must be positive and finite; got {tau0}.")
    max_iter = _check_max_iter(max_iter)
    L = _weight(weight, model_fn(jnp.asarray(tau0)).state_dim)

    def cost_and_slope(tau):
        return _newton_cost_and_slope(model_fn, tau, L, sensitivity, method)

    taus, costs = [float(tau0)], []
    converged = False
    for _ in range(max_iter):
        J, dJ = (float(v) for v in cost_and_slope(jnp.asarray(taus[-1])))
        costs.append(J)
        if abs(J - target) <= tol * abs(target):
            converged = True
            break
        taus.append(taus[-1] + step_factor * (target - J) / dJ)
        if not np.isfinite(taus[-1]) or taus[-1] <= 0:
            raise InputError(
                f"Newton step left the feasible region (τ = {taus[-1]:.4g}); use a smaller `step_factor` "
                "or a closer `tau0`."
            )
    else:
        costs.append(float(cost_and_slope(jnp.asarray(taus[-1]))[0]))
        converged = abs(costs[-1] - target) <= tol * abs(target)
    return NewtonResult(np.array(taus), np.array(costs[: len(taus)]), converged)


@eqx.filter_jit
def _newton_cost_and_slope(model_fn, tau, L, sensitivity, method):
    P = covariance_recursion(model_fn(tau)).filtered_cov
    J = jnp.trace(L @ P[-1])
    dJ = sensitivity_index(model_fn, tau, L, method=method)
    if sensitivity == "time-fixed":
        T = P.shape[0] - 1
        dJ = dJ + (T / tau) * jnp.trace(L @ (P[-2] - P[-1]))  # eq. (50) at the last sample
    return J, dJ


# ----------------------------------------------------------------------------------------------
# III-B: piecewise-uniform schedules


class SegmentProblem(eqx.Module):
    """Ho's piecewise-uniform schedule design problem (Sec. III-B, III-E).

    The horizon is split into ``num_segments`` segments of ``segment_duration`` seconds; segment
    ``i`` holds ``n_i`` equally spaced samples, the prior sits on the first sample, the last
    sample ends the horizon (Convention 2). ``model_fn(taus)`` builds the model from the per-step
    periods ``(N,)`` (e.g. ``lambda t: ho_plant(t, g=10.0)``); ``J = tr(weight · P_T)``.
    """

    model_fn: Callable[[Array], LinearGaussianModel] = eqx.field(static=True)
    weight: Array
    num_segments: int = eqx.field(static=True)
    segment_duration: float = eqx.field(static=True, default=1.0)

    def check(self, counts) -> tuple[int, ...]:
        counts = tuple(int(c) for c in counts)
        if len(counts) != self.num_segments or min(counts) < 1:
            raise InputError(f"`counts` must be {self.num_segments} positive ints; got {counts}.")
        return counts

    def taus(self, counts) -> Array:
        return segment_schedule(self.check(counts), self.segment_duration)

    def cost(self, counts) -> float:
        """``J`` of an integer scheme."""
        return float(_terminal_cost(self, self.taus(counts)))

    def segment_sensitivities(self, counts, method=Analytic()):
        """Time-fixed ``s_i`` and sample-fixed ``∂J/∂τ_i`` (Convention 3)."""
        counts = self.check(counts)

        def fn(segment_taus):
            taus = jnp.repeat(segment_taus, jnp.asarray(counts), total_repeat_length=sum(counts))
            return self.model_fn(taus)

        taus = self.segment_duration / jnp.asarray(counts, dtype=float)
        return segment_sensitivity(fn, taus, counts, self.weight, method=method)

    def count_gradient(self, counts, method=Analytic()) -> np.ndarray:
        r"""``∂J/∂n_i = −s_i τ_i²/D`` (chain rule through ``τ_i = D/n_i``): the quantity whose
        equality across segments is the optimality condition (spec §3.2, correcting eq. (74))."""
        counts = self.check(counts)
        s = self.segment_sensitivities(counts, method).time_fixed
        tau = self.segment_duration / np.asarray(counts, float)
        return -s * tau**2 / self.segment_duration


@eqx.filter_jit
def _terminal_cost(problem: SegmentProblem, taus: Array) -> Array:
    P_T = covariance_recursion(problem.model_fn(taus)).filtered_cov[-1]
    return jnp.trace(problem.weight @ P_T)


def ho_reduction(problem: SegmentProblem, counts: Sequence[int], remove: int, *, cap: float = 0.5) -> tuple[int, ...]:
    """The memo's use of III-B in its example: remove ``remove`` samples from the segments with the
    lowest time-fixed ``s_i``, at most ``cap·n_i`` from each (Sec. III-E: (10,…) → (10,5,5,10,10)).

    **Arguments:**

    - ``problem``: the :class:`SegmentProblem`; ``counts``: the current scheme ``(n_1, …, n_S)``.
    - ``remove``: how many samples to remove in all.
    - ``cap``: the largest fraction of a segment's samples that may be removed (default 0.5).

    **Returns:** the new counts.

    **Raises:** ``InputError`` if ``remove`` would empty a segment or the cap does not allow it.
    """
    counts = list(problem.check(counts))
    if not 0 <= remove < sum(counts) - len(counts) + 1:
        raise InputError(f"`remove` must leave at least one sample per segment; got {remove}.")
    s = problem.segment_sensitivities(counts).time_fixed
    left = remove
    for i in np.argsort(s):
        take = min(left, int(np.floor(cap * counts[i])), counts[i] - 1)
        counts[i] -= take
        left -= take
        if left == 0:
            break
    if left:
        raise InputError(f"the cap {cap} allows removing only {remove - left} of {remove} samples.")
    return tuple(counts)


def segment_exchange(
    problem: SegmentProblem,
    counts: Sequence[int],
    *,
    max_relative_change: float = 0.25,
    condition: Literal["count-gradient", "equal-s"] = "count-gradient",
    max_iter: int = 50,
) -> tuple[tuple[int, ...], list[float]]:
    r"""Ho's segment-exchange algorithm (Sec. III-B, Fig. 5) at a fixed total sample count.

    Each pass computes the sensitivities, then moves samples from the segment where they help
    least (``u``) to the one where they help most (``l``), as many as the linearity constraint (73)
    allows (``|Δτ_i|/τ_i ≤ max_relative_change`` in both segments, at least one sample). With
    ``condition="count-gradient"`` "help" is measured by ``∂J/∂n_i = −s_iτ_i²/D`` (the correct
    first-order condition, spec §6 item 10); ``"equal-s"`` uses the memo's ``s_i`` (74), which
    coincides only when all ``τ_i²/D_i`` are equal. A move is kept only if ``J`` falls; the
    algorithm stops when no move helps.

    **Arguments:**

    - ``problem``: the :class:`SegmentProblem`; ``counts``: the starting scheme ``(n_1, …, n_S)``.
    - ``max_relative_change``: the bound ``c`` on ``|Δτ_i|/τ_i`` of (73) (default 0.25).
    - ``condition``: ``"count-gradient"`` (default) or ``"equal-s"``, as above.
    - ``max_iter``: the most passes.

    **Returns:** ``(counts, costs)`` — the final scheme and ``J`` after each accepted move.

    **Raises:** ``InputError`` for an unknown ``condition`` or a ``max_iter`` below 1. Issues
    :class:`NotConvergedWarning` when a move still helped at the ``max_iter``-th pass.
    """
    if condition not in ("count-gradient", "equal-s"):
        raise InputError(f"`condition` must be 'count-gradient' or 'equal-s'; got {condition!r}.")
    max_iter = _check_max_iter(max_iter)
    counts = list(problem.check(counts))
    costs = [problem.cost(counts)]
    for _ in range(max_iter):
        if condition == "count-gradient":
            benefit = -problem.count_gradient(counts)  # J decrease per added sample
        elif condition == "equal-s":
            benefit = problem.segment_sensitivities(counts).time_fixed
        else:
            raise InputError(f"`condition` must be 'count-gradient' or 'equal-s'; got {condition!r}.")
        improved = False
        for u, l in ((u, l) for u in np.argsort(benefit) for l in np.argsort(-benefit) if u != l):
            # (73): τ_u = D/n_u grows by n_u/(n_u − m) − 1 ≤ c, τ_l shrinks by m/(n_l + m) ≤ c.
            m_u = int(np.floor(counts[u] * max_relative_change / (1 + max_relative_change)))
            m_l = int(np.floor(counts[l] * max_relative_change / (1 - max_relative_change)))
            m = max(1, min(m_u, m_l, counts[u] - 1))
            if counts[u] - m < 1:
                continue
            trial = list(counts)
            trial[u] -= m
            trial[l] += m
            J = problem.cost(trial)
            if J < costs[-1]:
                counts, improved = trial, True
                costs.append(J)
                break
        if not improved:
            break
    else:
        warnings.warn(f"segment_exchange: still improving after `max_iter` = {max_iter} passes; the "
                      "scheme returned is the best so far, not a local optimum.", NotConvergedWarning, stacklevel=2)
    return tuple(counts), costs


def _compositions(total: int, parts: int, lo: int, hi: int) -> np.ndarray:
    """All integer vectors with ``parts`` entries in [lo, hi] summing to ``total``."""
    rows = []
    for head in itertools.product(range(lo, hi + 1), repeat=parts - 1):
        last = total - sum(head)
        if lo <= last <= hi:
            rows.append((*head, last))
    return np.array(rows, dtype=int)


def exhaustive_counts(problem: SegmentProblem, total: int, *, lo: int = 1, hi: int | None = None, chunk: int = 4096,
                      max_schemes: int = 10_000_000) -> tuple[tuple[int, ...], float, int]:
    """Brute-force integer optimum: ``J`` of every scheme with ``Σn_i = total``, ``lo ≤ n_i ≤ hi``,
    evaluated in vmapped chunks. **Returns:** ``(counts, J, number_of_schemes)``.

    **Arguments:**

    - ``problem``: the :class:`SegmentProblem`; ``total``: ``Σn_i``.
    - ``lo``, ``hi``: the bounds on each ``n_i`` (``hi`` defaults to ``total``).
    - ``chunk``: schemes per vmapped evaluation.
    - ``max_schemes``: the most candidate vectors ``(hi − lo + 1)^(S−1)`` to enumerate; beyond it
      the search would run for hours, so it is refused.

    **Raises:** ``InputError`` if no scheme satisfies the bounds or the search exceeds ``max_schemes``.
    """
    hi = total if hi is None else hi
    if lo > hi:
        raise InputError(f"`lo` must not exceed `hi`; got lo={lo}, hi={hi}.")
    candidates = (hi - lo + 1) ** (problem.num_segments - 1)
    if candidates > max_schemes:
        raise InputError(f"`total`/`hi` give {candidates:.3g} candidate schemes, above `max_schemes` = "
                         f"{max_schemes}; narrow [lo, hi] or use relaxed_segment_design.")
    schemes = _compositions(total, problem.num_segments, lo, hi)
    if len(schemes) == 0:
        raise InputError(f"no scheme of {problem.num_segments} segments in [{lo}, {hi}] sums to {total}.")
    D = problem.segment_duration
    taus = np.stack([np.repeat(D / s, s) for s in schemes])  # (S, total)
    cost = jax.jit(jax.vmap(lambda t: _terminal_cost(problem, t)))
    values = np.concatenate([np.asarray(cost(jnp.asarray(taus[i:i + chunk]))) for i in range(0, len(taus), chunk)])
    best = int(np.argmin(values))
    return tuple(int(c) for c in schemes[best]), float(values[best]), len(schemes)


# ----------------------------------------------------------------------------------------------
# Gradient design over relaxed (continuous) sample counts


class RelaxedDesign(NamedTuple):
    """Result of :func:`relaxed_segment_design`.

    - ``counts``: the continuous optimum ``(S,)``; ``cost``: its relaxed ``J``;
    - ``history``: relaxed ``J`` per optimiser step.
    """

    counts: np.ndarray
    cost: float
    history: np.ndarray


def _project_capped_simplex(x: Array, total: float, lo: Array, hi: Array) -> Array:
    """Euclidean projection onto ``{lo ≤ y ≤ hi, Σy = total}`` (bisection on the shift)."""

    def excess(shift):
        return jnp.sum(jnp.clip(x - shift, lo, hi)) - total

    a, b = jnp.min(x - hi) - 1.0, jnp.max(x - lo) + 1.0

    def body(_, ab):
        a, b = ab
        mid = 0.5 * (a + b)
        pos = excess(mid) > 0
        return jnp.where(pos, mid, a), jnp.where(pos, b, mid)

    a, b = jax.lax.fori_loop(0, 100, body, (a, b))
    return jnp.clip(x - 0.5 * (a + b), lo, hi)


def _relaxed_cost(problem: SegmentProblem, counts: Array, cap: int, objective: Objective) -> Array:
    """``J`` of continuous counts: each segment has ``cap`` sample slots of period ``D/n_i``; slot
    ``j`` is active with weight ``g = clip(n_i − j, 0, 1)`` (time advance ``g·τ_i``, measurement
    noise ``R/g``). At integer ``n_i`` this is exactly the integer scheme; in between, the last
    sample of a segment is a fractional one."""
    D = problem.segment_duration
    S = problem.num_segments
    j = jnp.arange(cap, dtype=counts.dtype)
    # Slot 0 of segment 1 carries the prior (first_step="update"): always fully active.
    gate = jnp.clip(counts[:, None] - j[None, :], 0.0, 1.0).at[0, 0].set(1.0)
    tau = (D / counts)[:, None] * jnp.ones((1, cap), counts.dtype)
    g = gate.reshape(S * cap)
    taus = (tau.reshape(S * cap)) * g + (1.0 - g) * 1e-12
    model = problem.model_fn(taus)
    g_floor = jnp.maximum(g, 1e-12)
    R = jax.vmap(model.measurement_noise_cov)(jnp.arange(S * cap)) / g_floor[:, None, None]
    F = jax.vmap(model.transition_matrix)(jnp.arange(S * cap))
    Q = jax.vmap(model.process_noise_cov)(jnp.arange(S * cap))
    model = eqx.tree_at(lambda m: (m.F, m.Q, m.R), model, (F, Q, R))
    P = covariance_recursion(model).filtered_cov
    if objective == "terminal":
        return jnp.trace(problem.weight @ P[-1])
    return jnp.sum(g * jnp.einsum("ij,kji->k", problem.weight, P))


def relaxed_segment_design(
    problem: SegmentProblem,
    total: int,
    *,
    lo: int = 1,
    hi: int = 20,
    objective: Objective = "terminal",
    steps: int = 300,
    learning_rate: float = 0.2,
    init: Sequence[float] | None = None,
) -> RelaxedDesign:
    r"""Gradient design of per-segment sample counts relaxed to continuous values (optax Adam).

    Minimises ``tr(L P_T)`` (``objective="terminal"``) or the running cost ``Σ_k tr(L P_{k/k})``
    (``"running"``) over ``lo ≤ n_i ≤ hi``, ``Σ n_i = total`` by projected Adam steps (the
    projection onto the capped simplex follows every step). The terminal-only cost is degenerate
    without the cap ``hi``: samples pile into the last segment (spec §5.5). Round the result with
    :func:`round_counts` and polish it with :func:`local_search`.

    **Arguments:**

    - ``problem``: the :class:`SegmentProblem`; ``total``: ``Σn_i``.
    - ``lo``, ``hi``: the bounds on each ``n_i``.
    - ``objective``: ``"terminal"`` (default) or ``"running"``.
    - ``steps``, ``learning_rate``: the Adam iterations and step size.
    - ``init``: optional starting counts ``(S,)`` (default: ``total/S`` each).

    **Returns:** :class:`RelaxedDesign`.

    **Raises:** ``InputError`` for an infeasible ``total`` or an unknown ``objective``.
    """
    S = problem.num_segments
    if not S * lo <= total <= S * hi:
        raise InputError(f"`total` = {total} is infeasible with {S} segments in [{lo}, {hi}].")
    if objective not in ("terminal", "running"):
        raise InputError(f"`objective` must be 'terminal' or 'running'; got {objective!r}.")
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise InputError(f"`steps` must be a positive int; got {steps!r}.")
    if init is not None and (np.shape(init) != (S,) or not np.all(np.isfinite(np.asarray(init, float)))):
        raise InputError(f"`init` must be {S} finite counts; got {init!r}.")
    x0 = jnp.full(S, total / S) if init is None else jnp.asarray(init, dtype=float)
    x, hist, J = _relaxed_run(problem, x0, float(total), float(lo), int(hi), objective, int(steps), float(learning_rate))
    return RelaxedDesign(np.asarray(x), float(J), np.asarray(hist))


@eqx.filter_jit
def _relaxed_run(problem, x0, total, lo, hi, objective, steps, learning_rate):
    S = problem.num_segments
    lo_a, hi_a = jnp.full(S, lo), jnp.full(S, float(hi))
    opt = optax.adam(learning_rate)

    def step(carry, _):
        x, state = carry
        J, grad = jax.value_and_grad(_relaxed_cost, argnums=1)(problem, x, hi, objective)
        # Adam normalises each coordinate, so a common component of the gradient (all n_i want
        # more samples) would swamp the differences that matter under Σn_i = total: keep only
        # the part tangent to the constraint before the step.
        updates, state = opt.update(grad - jnp.mean(grad), state)
        x = _project_capped_simplex(optax.apply_updates(x, updates), total, lo_a, hi_a)
        return (x, state), J

    x0p = _project_capped_simplex(x0, total, lo_a, hi_a)
    (x, _), hist = jax.lax.scan(step, (x0p, opt.init(x0p)), None, length=steps)
    return x, hist, _relaxed_cost(problem, x, hi, objective)


def round_counts(counts: ArrayLike, total: int, lo: int = 1, hi: int | None = None) -> tuple[int, ...]:
    """Largest-remainder rounding of continuous counts to integers with ``Σ = total`` within [lo, hi].

    **Arguments:**

    - ``counts``: continuous counts, shape ``(S,)``, finite.
    - ``total``: the required sum; ``lo``, ``hi``: the bounds on each count (``hi`` defaults to ``total``).

    **Returns:** the integer counts, a tuple of ``S`` ints.

    **Raises:** ``InputError`` for non-finite or empty ``counts``, ``lo > hi``, or a ``total``
    outside ``[S·lo, S·hi]`` (no integer vector meets it; the adjustment loop would never end).
    """
    x = np.asarray(counts, float)
    if x.ndim != 1 or x.size == 0:
        raise InputError(f"`counts` must be a non-empty 1-D array; got shape {x.shape}.")
    if not np.all(np.isfinite(x)):
        raise InputError(f"`counts` must be finite; got {x.tolist()}.")
    total, lo = _as_int("total", total), _as_int("lo", lo)
    hi = total if hi is None else _as_int("hi", hi)
    if lo > hi:
        raise InputError(f"`lo` must not exceed `hi`; got lo={lo}, hi={hi}.")
    S = len(x)
    if not S * lo <= total <= S * hi:
        raise InputError(f"`total` = {total} cannot be met by {S} counts in [{lo}, {hi}]: it must lie in "
                         f"[{S * lo}, {S * hi}].")
    base = np.clip(np.floor(x), lo, hi).astype(int)
    order = np.argsort(-(x - np.floor(x)))
    # Each pass over the S counts moves the sum by at least one while the total is feasible (some
    # count is then below hi, or above lo), so |Σ − total| passes always suffice: the cap is a guard.
    cap = S * (abs(int(base.sum()) - total) + 1)
    i = 0
    while base.sum() < total and i < cap:
        k = order[i % S]
        if base[k] < hi:
            base[k] += 1
        i += 1
    i = 0
    while base.sum() > total and i < cap:
        k = order[::-1][i % S]
        if base[k] > lo:
            base[k] -= 1
        i += 1
    if base.sum() != total:  # pragma: no cover - unreachable for a feasible total
        raise RuntimeError(f"round_counts did not reach the total {total} in {cap} steps.")
    return tuple(int(c) for c in base)


def _as_int(name: str, value) -> int:
    """``value`` as a Python int; InputError naming ``name`` if it is not a finite whole number."""
    try:
        f = float(value)
    except (TypeError, ValueError):
        raise InputError(f"`{name}` must be an integer; got {value!r}.") from None
    if not np.isfinite(f) or f != int(f):
        raise InputError(f"`{name}` must be an integer; got {value!r}.")
    return int(f)


def local_search(problem: SegmentProblem, counts: Sequence[int], *, lo: int = 1, hi: int | None = None, max_iter: int = 100) -> tuple[tuple[int, ...], float]:
    """Integer polish: move one sample between any two segments while ``J`` falls (best move first).

    **Arguments:**

    - ``problem``: the :class:`SegmentProblem`; ``counts``: the starting scheme ``(n_1, …, n_S)``.
    - ``lo``, ``hi``: the bounds on each ``n_i`` (``hi`` defaults to ``Σn_i``).
    - ``max_iter``: the most moves.

    **Returns:** ``(counts, J)`` at a 1-exchange local optimum. Issues
    :class:`NotConvergedWarning` when a move still helped at the ``max_iter``-th one.
    """
    max_iter = _check_max_iter(max_iter)
    counts = list(problem.check(counts))
    hi = sum(counts) if hi is None else hi
    best = problem.cost(counts)
    for _ in range(max_iter):
        trials = []
        for u, l in itertools.permutations(range(len(counts)), 2):
            if counts[u] - 1 >= lo and counts[l] + 1 <= hi:
                t = list(counts)
                t[u] -= 1
                t[l] += 1
                trials.append(t)
        if not trials:
            break
        D = problem.segment_duration
        taus = jnp.asarray(np.stack([np.repeat(D / np.array(t, float), t) for t in trials]))
        values = np.asarray(jax.vmap(lambda x: _terminal_cost(problem, x))(taus))
        k = int(np.argmin(values))
        if values[k] >= best:
            break
        counts, best = trials[k], float(values[k])
    else:
        warnings.warn(f"local_search: still improving after `max_iter` = {max_iter} moves; the scheme "
                      "returned is the best so far, not a 1-exchange optimum.", NotConvergedWarning, stacklevel=2)
    return tuple(counts), best

r"""Sensor management by gradient: which target each sensor looks at, scan by scan.

``N`` targets follow time-invariant linear-Gaussian models with known Gaussian priors and known
association. At each of ``T`` scans every one of ``S`` sensors makes ONE look, at one target of
its choosing, and measures it through that target's ``H`` with the sensor's noise ``R_s``; the
targets it does not look at are only predicted. The cost of a schedule is

.. math::

    J = \sum_{k=1}^{T} \sum_{i=1}^{N} c_i\,\mathrm{tr}\big(L\,P^{(i)}_{k/k}\big),

with ``L`` the state weight (by default ``H_1ᵀH_1``: for a position-measuring model such as
:func:`~jaxtrack.models.constant_velocity` the trace of the position block, m²) and ``c_i`` the
target weights. For linear-Gaussian models ``P_{k/k}`` does not depend on the measurements (it is
also the posterior Cramér–Rao bound), so the whole schedule can be designed before any
measurement is taken (Meier, Peschon & Dressler 1967).

In information form a look is an addition: with ``w_{k,s,i} ∈ {0, 1}`` saying whether sensor
``s`` looks at target ``i`` at scan ``k``,

.. math::

    Y^{(i)}_{k/k-1} = \big(F_i P^{(i)}_{k-1/k-1} F_iᵀ + Q_i\big)^{-1},\qquad
    Y^{(i)}_{k/k} = Y^{(i)}_{k/k-1} + \sum_s w_{k,s,i}\, H_iᵀ R_s^{-1} H_i .

The relaxation lets ``w_{k,s,·}`` range over the simplex: a fractional look adds a fraction of
the measurement's information, as a measurement of noise ``R_s / w`` would. It is computed in
covariance form (Woodbury's identity), which needs no ``n×n`` inverse and holds at ``w = 0``:

.. math::

    S = w\,H P Hᵀ + R_s,\qquad P^{+} = P − w\,P Hᵀ S^{-1} H P .

At a one-hot ``w`` this is the Kalman filter's covariance recursion exactly.

- :class:`SensorSchedulingProblem` — the targets, the sensors, the horizon and the weights.
- :func:`schedule_cost`, :func:`relaxed_schedule_cost` — ``J`` of a discrete schedule and of
  relaxed look weights (one ``lax.scan`` each; differentiable in every array of the problem).
- :func:`greedy_sensor_schedule` — the myopic brute-force manager: at each scan, the joint look
  of all sensors that minimises the cost after that scan (what Stone Soup's
  ``BruteForceSensorManager`` does with a reward equal to the fall in that cost; its stock
  ``UncertaintyRewardFunction`` rewards the fall in the Frobenius norm of the whole covariance
  instead, a different criterion).
- :func:`relaxed_sensor_schedule` — the non-myopic design: softmax look weights over the whole
  horizon, optimised by Adam with an entropy term annealed toward one-hot looks, rounded, then
  polished by a local search (one look reassigned, or two exchanged) on the exact discrete cost,
  evaluated incrementally: ``J = Σ_i J_i`` is a sum of per-target terms, and a move changes the
  looks of a few targets only, so only their recursions are redone.

??? cite "Reference"

    Meier, L., Peschon, J. & Dressler, R. M. (1967). Optimal control of measurement subsystems.
    *IEEE Transactions on Automatic Control*, 12(5), 528–536.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, ArrayLike, Float

from .._validation import (
    InputError,
    check_covariance,
    check_finite,
    check_shape,
    is_concrete,
)
from ..filters._linalg import cholesky_and_inverse, matmul
from ..models import LinearGaussianModel
from ._schedule_search import _configurations, _polish, _screened_polish
from ._schedules import NotConvergedWarning

__all__ = [
    "SensorScheduleDesign",
    "SensorSchedulingProblem",
    "greedy_sensor_schedule",
    "relaxed_schedule_cost",
    "relaxed_sensor_schedule",
    "schedule_cost",
]


# ----------------------------------------------------------------------------------------------
# The problem


class SensorSchedulingProblem(eqx.Module):
    r"""A sensor-scheduling problem: ``N`` targets, ``S`` sensors, ``T`` scans.

    Each target ``i`` follows its own time-invariant linear-Gaussian model (``F_i``, ``Q_i`` per
    scan period, ``H_i``) from its prior covariance ``P_0^{(i)}``, which sits one scan period
    before the first look (``first_step="predict"`` in :func:`~jaxtrack.filters.run_filter`'s
    terms). At scan ``k = 1 … T`` every target is predicted, then each sensor ``s`` (noise
    ``R_s``) looks at one target. The cost is ``J = Σ_k Σ_i c_i tr(L P^{(i)}_{k/k})``.

    **Arguments:**

    - ``models``: a non-empty sequence of ``N`` :class:`~jaxtrack.models.LinearGaussianModel`,
      one per target, all with the same state and measurement sizes ``n``, ``m`` and
      time-invariant ``F`` ``(n, n)``, ``Q`` ``(n, n)``, ``H`` ``(m, n)`` (one scan period; e.g.
      :func:`~jaxtrack.models.constant_velocity` with a scalar ``taus``). Their priors
      (``initial_cov``) are the targets' known estimates; their means are not used.
    - ``num_scans``: ``T``, a positive int.
    - ``measurement_noise_cov``: the sensors' ``R``: ``(m, m)`` for one sensor or ``(S, m, m)``
      for ``S`` sensors, positive definite, in the measurement's units (m² for positions).
      Default: the models' common ``R`` (one sensor); an error if the models' ``R`` differ.
    - ``weight``: ``L`` ``(n, n)``, positive semidefinite. Default ``H_1ᵀ H_1`` (the position
      block for a position-measuring model).
    - ``target_weights``: ``c`` ``(N,)``, finite, ≥ 0. Default ones.

    **Raises:** :class:`~jaxtrack.InputError` naming the argument: an empty or non-model
    ``models``, per-step (time-varying) models, mismatched sizes, ``num_scans < 1``, an ``R``
    that is not positive definite, a ``weight`` that is not positive semidefinite, negative or
    non-finite ``target_weights``. (A non-positive-definite prior is refused by the model's own
    constructor, naming ``initial_cov``.)
    """

    transition_matrix: Float[Array, "N n n"]
    process_noise_cov: Float[Array, "N n n"]
    measurement_matrix: Float[Array, "N m n"]
    measurement_noise_cov: Float[Array, "S m m"]
    initial_cov: Float[Array, "N n n"]
    weight: Float[Array, "n n"]
    target_weights: Float[Array, " N"]
    num_scans: int = eqx.field(static=True)

    def __init__(
        self,
        models: Sequence[LinearGaussianModel],
        num_scans: int,
        *,
        measurement_noise_cov: ArrayLike | None = None,
        weight: ArrayLike | None = None,
        target_weights: ArrayLike | None = None,
    ):
        if isinstance(models, LinearGaussianModel) or not isinstance(models, Sequence) or len(models) == 0:
            raise InputError("`models` must be a non-empty sequence of LinearGaussianModel, one per target; "
                             f"got {type(models).__name__}.")
        for i, model in enumerate(models):
            if not isinstance(model, LinearGaussianModel):
                raise InputError(f"`models[{i}]` must be a LinearGaussianModel; got {type(model).__name__}.")
            if model.F.ndim != 2 or model.Q.ndim != 2 or model.H.ndim != 2 or model.R.ndim != 2:
                raise InputError(f"`models[{i}]` must be time-invariant (F, Q, H, R of shapes (n, n), (n, n), "
                                 f"(m, n), (m, m): one scan period); got per-step stacks.")
            if model.b is not None:
                raise InputError(f"`models[{i}]` must have no transition offset (it does not change the "
                                 "covariances; drop it).")
        n, m = models[0].state_dim, models[0].meas_dim
        for i, model in enumerate(models):
            if (model.state_dim, model.meas_dim) != (n, m):
                raise InputError(f"`models[{i}]` has n = {model.state_dim}, m = {model.meas_dim}; "
                                 f"`models[0]` has n = {n}, m = {m}: all targets must match.")
        if isinstance(num_scans, bool) or not isinstance(num_scans, (int, np.integer)) or num_scans < 1:
            raise InputError(f"`num_scans` must be a positive int; got {num_scans!r}.")
        dtype = jnp.result_type(float)

        if measurement_noise_cov is None:
            R0 = np.asarray(models[0].R)
            if any(not np.array_equal(np.asarray(model.R), R0) for model in models[1:]):
                raise InputError("`measurement_noise_cov` must be given when the models' R differ: R is the "
                                 "sensor's, shared by every target it looks at.")
            R = jnp.asarray(models[0].R, dtype)[None]
        else:
            R = jnp.asarray(measurement_noise_cov, dtype)
            check_shape("measurement_noise_cov", R, [(m, m), (None, m, m)])
            if R.ndim == 2:
                R = R[None]
            if R.shape[0] == 0:
                raise InputError("`measurement_noise_cov` must hold at least one sensor's R; got shape "
                                 f"{R.shape}.")
        check_covariance("measurement_noise_cov", R)

        H = jnp.stack([jnp.asarray(model.H, dtype) for model in models])
        if weight is None:
            L = H[0].T @ H[0]
        else:
            L = jnp.asarray(weight, dtype)
            check_shape("weight", L, [(n, n)])
            check_covariance("weight", L, definite=False)
        if target_weights is None:
            c = jnp.ones(len(models), dtype)
        else:
            c = jnp.asarray(target_weights, dtype)
            check_shape("target_weights", c, [(len(models),)])
            check_finite("target_weights", c)
            if is_concrete(c) and np.any(np.asarray(c) < 0):
                raise InputError(f"`target_weights` must be ≥ 0; got {np.asarray(c).tolist()}.")

        self.transition_matrix = jnp.stack([jnp.asarray(model.F, dtype) for model in models])
        self.process_noise_cov = jnp.stack([jnp.asarray(model.Q, dtype) for model in models])
        self.measurement_matrix = H
        self.measurement_noise_cov = R
        self.initial_cov = jnp.stack([jnp.asarray(model.initial_cov, dtype) for model in models])
        self.weight = L
        self.target_weights = c
        self.num_scans = int(num_scans)

    @property
    def num_targets(self) -> int:
        """``N``."""
        return self.transition_matrix.shape[0]

    @property
    def num_sensors(self) -> int:
        """``S``."""
        return self.measurement_noise_cov.shape[0]

    def schedule_shape(self) -> tuple[int, ...]:
        """The shape of a discrete schedule: ``(T,)`` for one sensor, ``(T, S)`` for several."""
        return (self.num_scans,) if self.num_sensors == 1 else (self.num_scans, self.num_sensors)


# ----------------------------------------------------------------------------------------------
# The recursion


def _look(P: Array, H: Array, R: Array, w: Array) -> Array:
    """One (possibly fractional) look: ``Y⁺ = Y + w HᵀR⁻¹H``, in covariance form by Woodbury
    (``S = wHPHᵀ + R = LLᵀ``, ``A = PHᵀL⁻ᵀ``, ``P⁺ = P − w AAᵀ``): an ``m×m`` Cholesky factor,
    exact at ``w = 0``. The factor is written out entry by entry (``filters._linalg``): the
    local search evaluates thousands of schedules at once, and a batched LAPACK call per matrix
    cost ten times the arithmetic."""
    G = matmul(P, H.T)
    _, L_inv = cholesky_and_inverse(w * matmul(H, G) + R)
    A = matmul(G, L_inv.T)
    # P⁺ = P − w AAᵀ is symmetric up to P's own rounding, which the prediction keeps symmetric.
    return P - w * matmul(A, A.T)


def _target_scan(P: Array, F: Array, Q: Array, H: Array, R: Array, w: Array) -> Array:
    """Predict one target through one scan, then apply the ``S`` sensors' looks ``w`` ``(S,)`` in turn
    (information adds, so their order does not matter)."""
    P = matmul(matmul(F, P), F.T) + Q
    # F P Fᵀ rounds asymmetrically, and the asymmetry would grow over T scans: keep the
    # symmetric part.
    P = 0.5 * (P + P.T)

    def sensor(P, Rw):
        return _look(P, H, *Rw), None

    P, _ = jax.lax.scan(sensor, P, (R, w))
    return P


def _scan_costs(problem: SensorSchedulingProblem, P: Array, w: Array) -> tuple[Array, Array]:
    """All targets through one scan with look weights ``w`` ``(S, N)``: ``(P⁺ (N, n, n), Σ_i c_i tr(L P_i⁺))``."""
    P = jax.vmap(_target_scan, in_axes=(0, 0, 0, 0, None, 1))(
        P, problem.transition_matrix, problem.process_noise_cov, problem.measurement_matrix,
        problem.measurement_noise_cov, w)
    cost = jnp.sum(problem.target_weights * jnp.einsum("ab,iba->i", problem.weight, P))
    return P, cost


def _relaxed_cost(problem: SensorSchedulingProblem, weights: Array) -> Array:
    """``J`` of look weights ``(T, S, N)``: one ``lax.scan`` over the scans."""

    def scan(P, w):
        P, cost = _scan_costs(problem, P, w)
        return P, cost

    _, costs = jax.lax.scan(scan, problem.initial_cov, weights)
    return jnp.sum(costs)


def _one_hot(problem: SensorSchedulingProblem, schedule: Array) -> Array:
    """A ``(T, S)`` schedule as look weights ``(T, S, N)`` (an index outside ``[0, N)`` gives a zero row)."""
    return jax.nn.one_hot(schedule, problem.num_targets, dtype=problem.initial_cov.dtype)


def _discrete_cost(problem: SensorSchedulingProblem, schedule: Array) -> Array:
    bad = jnp.any((schedule < 0) | (schedule >= problem.num_targets))
    # A traced schedule cannot be checked on the host: an out-of-range index gives NaN, not the
    # cost of a schedule with a look missing.
    return jnp.where(bad, jnp.nan, _relaxed_cost(problem, _one_hot(problem, schedule)))


_discrete_cost_jit = eqx.filter_jit(_discrete_cost)
_relaxed_cost_jit = eqx.filter_jit(_relaxed_cost)


def _check_problem(problem) -> SensorSchedulingProblem:
    if not isinstance(problem, SensorSchedulingProblem):
        raise InputError(f"`problem` must be a SensorSchedulingProblem; got {type(problem).__name__}.")
    return problem


def _as_schedule(problem: SensorSchedulingProblem, schedule, name: str = "schedule") -> Array:
    """``schedule`` as an int array ``(T, S)``; InputError naming ``name`` for a wrong shape, a
    non-integer dtype or (when concrete) an index outside ``[0, N)``."""
    T, S, N = problem.num_scans, problem.num_sensors, problem.num_targets
    if is_concrete(schedule):
        schedule = np.asarray(schedule)
    if not jnp.issubdtype(schedule.dtype, jnp.integer):
        raise InputError(f"`{name}` must hold integer target indices; got dtype {schedule.dtype}.")
    check_shape(name, schedule, [problem.schedule_shape()] if S == 1 else [(T, S)])
    if is_concrete(schedule) and np.any((schedule < 0) | (schedule >= N)):
        bad = np.argwhere((schedule < 0) | (schedule >= N))[0]
        raise InputError(f"`{name}` must hold target indices in [0, {N}); entry {tuple(int(b) for b in bad)} "
                         f"is {schedule[tuple(bad)]}.")
    schedule = jnp.asarray(schedule, dtype=jnp.int32)
    return schedule.reshape(T, S)


def _as_weights(problem: SensorSchedulingProblem, weights) -> Array:
    T, S, N = problem.num_scans, problem.num_sensors, problem.num_targets
    w = jnp.asarray(weights, dtype=problem.initial_cov.dtype)
    check_shape("weights", w, [(T, N), (T, S, N)] if S == 1 else [(T, S, N)])
    check_finite("weights", w)
    if is_concrete(w) and np.any(np.asarray(w) < 0):
        raise InputError("`weights` must be ≥ 0 (a look's share of a measurement's information).")
    return w.reshape(T, S, N)


def _out_schedule(problem: SensorSchedulingProblem, schedule) -> np.ndarray:
    return np.asarray(schedule, dtype=np.int64).reshape(problem.schedule_shape())


def schedule_cost(problem: SensorSchedulingProblem, schedule: ArrayLike) -> Array:
    r"""``J = Σ_k Σ_i c_i tr(L P^{(i)}_{k/k})`` of a discrete schedule: the Kalman covariances of
    every target under the looks it gets, one ``lax.scan`` over the ``T`` scans.

    **Arguments:**

    - ``problem``: the :class:`SensorSchedulingProblem`.
    - ``schedule``: which target each sensor looks at, integer ``(T,)`` for one sensor or
      ``(T, S)``, entries in ``[0, N)``.

    **Returns:** ``J``, shape ``()``, in the units of ``tr(L P)`` (m² for positions), summed over
    the ``T`` scans. Differentiable in every array of ``problem`` (``R``, ``Q``, priors …).

    **Raises:** :class:`~jaxtrack.InputError` naming ``schedule`` (shape, dtype, an index outside
    ``[0, N)``) or ``problem``. Under tracing the indices cannot be checked: an out-of-range one
    gives NaN.
    """
    problem = _check_problem(problem)
    return _discrete_cost_jit(problem, _as_schedule(problem, schedule))


def relaxed_schedule_cost(problem: SensorSchedulingProblem, weights: ArrayLike) -> Array:
    r"""``J`` of relaxed look weights: sensor ``s`` at scan ``k`` adds ``w_{k,s,i} H_iᵀR_s^{-1}H_i``
    to target ``i``'s information (the module docstring's recursion).

    At a one-hot ``weights`` this is :func:`schedule_cost`; rows on the simplex are what
    :func:`relaxed_sensor_schedule` optimises, but any ``w ≥ 0`` is defined (``w`` looks' worth
    of information).

    **Arguments:**

    - ``problem``: the :class:`SensorSchedulingProblem`.
    - ``weights``: ``(T, S, N)`` (or ``(T, N)`` for one sensor), finite, ≥ 0, dimensionless.

    **Returns:** ``J``, shape ``()``. Differentiable in ``weights`` and in every array of
    ``problem``.

    **Raises:** :class:`~jaxtrack.InputError` naming ``weights`` (shape, non-finite or negative
    entries) or ``problem``.
    """
    problem = _check_problem(problem)
    return _relaxed_cost_jit(problem, _as_weights(problem, weights))


# ----------------------------------------------------------------------------------------------
# Greedy (myopic brute force)




@eqx.filter_jit
def _greedy(problem: SensorSchedulingProblem) -> tuple[Array, Array]:
    configs = jnp.asarray(_configurations(problem.num_targets, problem.num_sensors))

    def scan(P, _):
        # Every joint look's cost after this scan; the first of equal minima wins (as Stone Soup's
        # brute-force manager keeps the first configuration of largest reward).
        P_all, costs = jax.vmap(lambda c: _scan_costs(problem, P, _one_hot(problem, c)))(configs)
        best = jnp.argmin(costs)
        return P_all[best], (configs[best], costs[best])

    _, (schedule, costs) = jax.lax.scan(scan, problem.initial_cov, None, length=problem.num_scans)
    return schedule, jnp.sum(costs)


def greedy_sensor_schedule(problem: SensorSchedulingProblem) -> tuple[np.ndarray, float]:
    r"""The myopic brute-force schedule: at each scan, the joint look that minimises the cost of that scan.

    At scan ``k``, given the covariances the earlier choices left, every one of the ``N^S`` joint
    looks is tried and the one with the smallest ``Σ_i c_i tr(L P^{(i)}_{k/k})`` is kept (the
    first in ``itertools.product`` order among equals). The targets not looked at are predicted
    alike under every look, so this is the look of largest uncertainty reduction
    ``Σ_i c_i tr(L(P_{k/k-1} − P_{k/k}))``: Stone Soup's ``BruteForceSensorManager`` with such
    a reward (not its stock ``UncertaintyRewardFunction``, which uses the Frobenius norm of the
    whole covariance). It ignores what a look does to later scans. One jitted ``lax.scan``.

    **Arguments:** ``problem``: the :class:`SensorSchedulingProblem`.

    **Returns:** ``(schedule, J)``: integer ``(T,)`` (one sensor) or ``(T, S)``, and its cost
    (:func:`schedule_cost`).

    **Raises:** :class:`~jaxtrack.InputError` naming ``problem``.
    """
    problem = _check_problem(problem)
    schedule, cost = _greedy(problem)
    return _out_schedule(problem, schedule), float(cost)


# ----------------------------------------------------------------------------------------------
# Relaxed gradient design


class SensorScheduleDesign(NamedTuple):
    """Result of :func:`relaxed_sensor_schedule` (the best of its starts).

    - ``schedule``: the design, integer ``(T,)`` (one sensor) or ``(T, S)``; ``cost``: its ``J``
      (:func:`schedule_cost`).
    - ``rounded_schedule``, ``rounded_cost``: that start's relaxed weights rounded (the largest
      weight per scan and sensor), before the local search.
    - ``weights``: that start's final relaxed look weights ``(T, S, N)``; ``relaxed_cost``: their
      ``J`` (:func:`relaxed_schedule_cost`, without the entropy term).
    - ``history``: that start's relaxed ``J`` per Adam step ``(steps,)``.
    - ``moves``: how many local-search moves it made.
    - ``start_costs``: ``J`` after the local search of every start ``(starts,)``.
    """

    schedule: np.ndarray
    cost: float
    rounded_schedule: np.ndarray
    rounded_cost: float
    weights: np.ndarray
    relaxed_cost: float
    history: np.ndarray
    moves: int
    start_costs: np.ndarray


def _entropy(logits: Array) -> Array:
    """``Σ_{k,s} H(softmax(θ_{k,s}))`` in nats, from ``log_softmax`` (finite value and gradient
    where a weight underflows to 0)."""
    log_w = jax.nn.log_softmax(logits, axis=-1)
    return -jnp.sum(jnp.exp(log_w) * log_w)


@eqx.filter_jit
def _relaxed_run(problem, logits0, betas, learning_rate):
    """Adam on ``J(softmax θ) + β_j g Σ H`` from each of the starts ``logits0`` ``(R, T, S, N)``."""
    T, S, N = problem.num_scans, problem.num_sensors, problem.num_targets
    uniform = jnp.full((T, S, N), 1.0 / N, problem.initial_cov.dtype)
    # The entropy term's unit: the mean |∂J/∂w| at evenly split looks (units of J per look), so
    # that β is dimensionless and the same β suits m² or km², ten targets or two.
    scale = jax.lax.stop_gradient(jnp.mean(jnp.abs(jax.grad(lambda w: _relaxed_cost(problem, w))(uniform))))
    opt = optax.adam(learning_rate)

    def loss(logits, beta):
        J = _relaxed_cost(problem, jax.nn.softmax(logits, axis=-1))
        return J + beta * scale * _entropy(logits), J

    def one_start(logits0):
        def step(carry, beta):
            logits, state = carry
            (_, J), grad = jax.value_and_grad(loss, has_aux=True)(logits, beta)
            updates, state = opt.update(grad, state)
            return (optax.apply_updates(logits, updates), state), J

        (logits, _), history = jax.lax.scan(step, (logits0, opt.init(logits0)), betas)
        w = jax.nn.softmax(logits, axis=-1)
        return w, _relaxed_cost(problem, w), history

    return jax.vmap(one_start)(logits0)


def _positive_int(name, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise InputError(f"`{name}` must be a positive int; got {value!r}.")
    return int(value)


def _nonnegative_pair(name, value) -> tuple[float, float]:
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise InputError(f"`{name}` must be a pair (start, end); got {value!r}.")
    try:
        pair = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise InputError(f"`{name}` must be a pair of numbers; got {value!r}.") from None
    if not all(np.isfinite(v) and v >= 0 for v in pair):
        raise InputError(f"`{name}` must hold finite numbers ≥ 0; got {value!r}.")
    return pair


def relaxed_sensor_schedule(
    problem: SensorSchedulingProblem,
    *,
    steps: int = 300,
    learning_rate: float = 0.1,
    entropy_weight: tuple[float, float] = (0.0, 30.0),
    starts: int = 4,
    key: int = 0,
    init: ArrayLike | None = None,
    max_moves: int | None = None,
    settle: float = 0.9,
    exchanges: int | None = None,
) -> SensorScheduleDesign:
    r"""Non-myopic sensor schedule by gradient: relaxed looks over the whole horizon, Adam with an
    annealed entropy term, rounding and a local search.

    Each sensor's look at each scan becomes a softmax over the targets,
    ``w_{k,s,·} = softmax(θ_{k,s,·})``, and the logits ``θ`` ``(T, S, N)`` descend

    .. math::

        \mathcal{L}_j(θ) = J\big(w(θ)\big) + β_j\, g \sum_{k,s} H(w_{k,s,·}),\qquad
        H(w) = −\sum_i w_i \log w_i,

    by ``steps`` Adam steps (:func:`relaxed_schedule_cost` gives ``J``; ``g`` is the mean
    ``|∂J/∂w|`` at evenly split looks, so ``β`` is dimensionless). ``β_j`` rises from
    ``entropy_weight[0]`` to ``entropy_weight[1]`` (quadratically in ``j``): early on the looks
    may split, as the relaxed optimum wants; the entropy term then pushes every look to a single
    target (deterministic annealing toward one-hot). All ``T`` scans are optimised together, so a
    look may be spent now for a benefit later, which :func:`greedy_sensor_schedule` cannot do.
    The weights are rounded (the largest per scan and sensor) and polished by a best-improvement
    local search on the exact discrete cost (:func:`schedule_cost`) over single moves: the joint
    look of one scan changed (for one sensor: one look given to another target), or two looks
    exchanged. The search never makes the rounded schedule
    worse. It is incremental and exact: ``J = Σ_i J_i`` with ``J_i`` depending on target ``i``'s
    looks only; per iteration a table of every target's ``J_i`` with one scan's looks changed
    (``N·T·2^S`` one-target recursions) costs all ``T·N^S`` single moves, and each exchange redoes
    the two targets it touches — the same moves as costing every neighbour in full, at
    ``N·T·2^S + TS(TS−1)`` one-target recursions per iteration instead of
    ``(T·N^S + TS(TS−1)/2)·N``. This runs from ``starts`` starting logits (zeros, or ``init``, then standard normal
    draws from ``key``), vmapped, and the best is returned.

    The relaxation alone is a weak guide here: the relaxed optimum splits looks evenly over time,
    which says little about *when* to look, and the rounded schedule is often far from optimal;
    the exchange search does much of the work (``rounded_cost`` against ``cost`` shows how much).
    Nothing guarantees a cost below :func:`greedy_sensor_schedule`'s. Measured (defaults,
    ``tests/_sensor_management_cases.py`` scenarios): with one sensor, 3 targets and 7 scans the
    exhaustive optimum in 8 of 8 scenarios (greedy in 5); with two sensors, 3 targets and 4 scans
    the optimum in 1 of 3, within 0.63 % in the others, once 0.63 % above a greedy schedule that
    was optimal; on 5 targets × 40 scans 0.5 % below greedy, and on 8 targets × 3 sensors × 40
    scans 2.6 % below (``benchmarks/measured/sensor_management.txt``). Time: the local search
    dominates (1.6 s and 18 s there on 2 shared CPU cores, against 0.1 s and 11 s for Stone
    Soup's greedy ``BruteForceSensorManager``); ``steps=100`` or ``starts=1`` were measured and
    give up more than 0.1 % of ``J`` on one of the two, so the defaults stay.

    **Arguments:**

    - ``problem``: the :class:`SensorSchedulingProblem`.
    - ``steps``: Adam iterations, a positive int; ``learning_rate``: Adam's step on ``θ``, > 0.
    - ``entropy_weight``: ``(β_start, β_end)``, finite, ≥ 0.
    - ``starts``: how many starting points, a positive int; ``key``: the int seed of the random
      ones.
    - ``init``: optional first starting logits ``θ`` ``(T, S, N)`` (or ``(T, N)`` for one
      sensor), finite; default zeros (every look split evenly).
    - ``max_moves``: the most local-search moves per start (default ``T·S·N``).
    - ``settle``: the relaxation has settled when every look's largest weight is at least
      ``settle`` (in ``(0, 1]``); otherwise a :class:`NotConvergedWarning` says so.
    - ``exchanges``: ``None`` (default) prices every exchange at every iteration (the
      best-improvement path above); a positive int ``k`` screens them: each iteration prices every
      single move exactly and only the ``k`` exchanges whose estimate from the single-move table is
      best (each of the four rows an exchange changes priced alone, their interaction left out),
      and where none of these improves, one full evaluation takes an exchange the estimate missed
      or certifies the stop. The result is a local optimum of the same neighbourhood, reached by
      another path. Measured (``benchmarks/measured/sensor_management.txt``, 8 targets, 40 scans,
      2 shared cores): with 3 sensors the default takes 17.3 s (``J`` 2.58 % below greedy) and
      ``exchanges=32, starts=1`` 1.4 s (1.46 % below), Stone Soup's brute force 11.9 s; with 4
      sensors (4096 joint looks a scan for the brute force) ``exchanges=32, starts=1`` takes 2.3 s
      (7.8 % below greedy) against Stone Soup's 118 s; with 1 sensor and 5 targets it takes 0.54 s
      against Stone Soup's 0.15 s.

    **Returns:** :class:`SensorScheduleDesign`.

    **Raises:** :class:`~jaxtrack.InputError` naming the argument (``steps < 1``, a non-positive
    ``learning_rate``, a bad ``entropy_weight``, ``starts``, ``init``, ``max_moves``, ``settle``
    or ``exchanges``). Issues :class:`NotConvergedWarning` when the chosen start's weights did not
    settle toward one-hot (the rounding then decided more than the gradient did: give more
    ``steps`` or a larger final ``entropy_weight``) or when its local search was still improving
    at ``max_moves``.
    """
    problem = _check_problem(problem)
    steps = _positive_int("steps", steps)
    starts = _positive_int("starts", starts)
    try:
        learning_rate = float(learning_rate)
    except (TypeError, ValueError):
        raise InputError(f"`learning_rate` must be a positive number; got {learning_rate!r}.") from None
    if not (np.isfinite(learning_rate) and learning_rate > 0):
        raise InputError(f"`learning_rate` must be positive and finite; got {learning_rate!r}.")
    beta0, beta1 = _nonnegative_pair("entropy_weight", entropy_weight)
    try:
        settle = float(settle)
    except (TypeError, ValueError):
        raise InputError(f"`settle` must be a number in (0, 1]; got {settle!r}.") from None
    if not 0 < settle <= 1:
        raise InputError(f"`settle` must be in (0, 1]; got {settle}.")
    T, S, N = problem.num_scans, problem.num_sensors, problem.num_targets
    max_moves = T * S * N if max_moves is None else _positive_int("max_moves", max_moves)
    exchanges = None if exchanges is None else _positive_int("exchanges", exchanges)
    dtype = problem.initial_cov.dtype
    if init is None:
        first = jnp.zeros((T, S, N), dtype)
    else:
        first = jnp.asarray(init, dtype)
        check_shape("init", first, [(T, N), (T, S, N)] if S == 1 else [(T, S, N)])
        check_finite("init", first)
        first = first.reshape(T, S, N)
    if isinstance(key, bool) or not isinstance(key, (int, np.integer)):
        raise InputError(f"`key` must be an int seed; got {key!r}.")
    others = jax.random.normal(jax.random.key(int(key)), (starts - 1, T, S, N), dtype)
    logits0 = jnp.concatenate([first[None], others])
    ramp = (np.arange(steps) / max(steps - 1, 1)) ** 2
    betas = jnp.asarray(beta0 + (beta1 - beta0) * ramp, dtype)

    w, relaxed_J, history = _relaxed_run(problem, logits0, betas, jnp.asarray(learning_rate, dtype))
    w = np.asarray(w)
    if not np.all(np.isfinite(w)):
        raise InputError("the relaxed design gave non-finite weights; lower `learning_rate` or check the "
                         "problem's scales (e.g. covariances in m², not km²).")
    rounded = jnp.asarray(np.argmax(w, axis=-1), jnp.int32)
    search = _polish if exchanges is None else functools.partial(_screened_polish, k=exchanges)
    schedules, J, moves, still = search(problem, rounded, jnp.asarray(max_moves, jnp.int32),
                                        jnp.asarray(1e-12, dtype))
    J = np.asarray(J)
    best = int(np.argmin(J))
    peak = w[best].max(axis=-1)
    if np.any(peak < settle):
        loose = np.argwhere(peak < settle)
        warnings.warn(
            f"relaxed_sensor_schedule: the look weights did not settle to one-hot ({len(loose)} of {T * S} "
            f"looks have a largest weight below {settle}, the first at scan {int(loose[0][0])}); the rounding "
            "decided them. Give more `steps` or a larger final `entropy_weight`.",
            NotConvergedWarning, stacklevel=2)
    if bool(np.asarray(still)[best]):
        warnings.warn(f"relaxed_sensor_schedule: the local search was still improving after `max_moves` = "
                      f"{max_moves} moves; the schedule returned is the best so far.", NotConvergedWarning,
                      stacklevel=2)
    return SensorScheduleDesign(
        schedule=_out_schedule(problem, schedules[best]),
        cost=float(J[best]),
        rounded_schedule=_out_schedule(problem, rounded[best]),
        rounded_cost=float(_discrete_cost_jit(problem, rounded[best])),
        weights=w[best],
        relaxed_cost=float(np.asarray(relaxed_J)[best]),
        history=np.asarray(history)[best],
        moves=int(np.asarray(moves)[best]),
        start_costs=J,
    )

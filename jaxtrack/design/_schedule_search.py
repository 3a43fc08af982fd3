"""The exact local search of the sensor-scheduling design (:func:`~jaxtrack.design.relaxed_sensor_schedule`):
best-improvement moves on the discrete cost, priced incrementally.

The cost ``J = Σ_i c_i(looks of target i)`` is a sum over targets, and a move changes the looks of at
most two targets, so only those are recomputed: per iteration one table of every target's cost with
one scan's looks changed prices every single-scan move, and an exchange of two looks reruns its two
targets. The moves, their order and the accepted schedule are those of a full evaluation of every
neighbour (tests/test_sensor_management.py holds the two equal). The screened variant
(:func:`_screened_polish`) costs every single move but only the exchanges its estimate ranks best,
and certifies its stop by one full evaluation. The problem and its costs live in
:mod:`._sensor_management`.
"""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ..filters._linalg import cholesky_and_inverse, matmul

if TYPE_CHECKING:  # the problem's module imports this one
    from ._sensor_management import SensorSchedulingProblem

def _configurations(num_targets: int, num_sensors: int) -> np.ndarray:
    """Every joint look ``(N^S, S)``, in ``itertools.product`` order (sensor 1's choice slowest)."""
    return np.array(list(itertools.product(range(num_targets), repeat=num_sensors)), dtype=np.int32)


def _subset_factors(problem: SensorSchedulingProblem) -> Array:
    """``G_m = V_mᵀ`` ``(2^S, m, m)`` with ``V_m V_mᵀ = Σ_{s ∈ m} R_s^{-1}``, one per subset ``m`` of
    the sensors (bit ``s`` of ``m`` set when sensor ``s`` looks), zero for the empty subset. The
    looks of several sensors at one target and scan add their information, so one update with
    ``G_m H`` replaces ``|m|`` updates (the local search's recursions run ``S`` times fewer
    Cholesky factorisations, and a target not looked at costs a zero update)."""
    S = problem.num_sensors
    bits = jnp.asarray((np.arange(2**S)[:, None] >> np.arange(S)) & 1, problem.initial_cov.dtype)  # (2^S, S)
    L_inv = jax.vmap(lambda R: cholesky_and_inverse(R)[1])(problem.measurement_noise_cov)
    R_inv = jnp.einsum("sba,sbc->sac", L_inv, L_inv)  # R⁻¹ = L⁻ᵀL⁻¹
    W = jnp.einsum("ms,sab->mab", bits, R_inv)
    m = W.shape[-1]
    # The empty subset's W is 0: factor W + I there and zero the result.
    empty = (jnp.sum(bits, axis=-1) == 0)[:, None, None]
    V = jnp.linalg.cholesky(jnp.where(empty, jnp.eye(m, dtype=W.dtype)[None], W))
    return jnp.where(empty, 0.0, jnp.swapaxes(V, -1, -2))


def _target_cost(problem: SensorSchedulingProblem, factors: Array, target: Array, subsets: Array) -> Array:
    """``c_i Σ_k tr(L P^{(i)}_{k/k})`` of one target ``i`` (an int, may be traced) when the sensors
    in subset ``subsets[k]`` ``(T,)`` look at it at scan ``k`` (``factors``:
    :func:`_subset_factors`). ``J`` is the sum of these per-target terms, which is what makes the
    local search incremental. The update is the information sum in covariance form:
    ``G = G_m H``, ``P⁺ = P − P Gᵀ (I + G P Gᵀ)^{-1} G P`` (``I + GPGᵀ ≥ I``: a well-conditioned
    ``m×m`` Cholesky factor; exact no-op at ``G = 0``)."""
    F, Q, H, P0 = (a[target] for a in (problem.transition_matrix, problem.process_noise_cov,
                                        problem.measurement_matrix, problem.initial_cov))
    eye = jnp.eye(H.shape[0], dtype=P0.dtype)

    def scan(P, subset):
        P = matmul(matmul(F, P), F.T) + Q
        P = 0.5 * (P + P.T)  # as in _target_scan: keep rounding asymmetry from growing
        G = matmul(factors[subset], H)
        PG = matmul(P, G.T)
        _, L_inv = cholesky_and_inverse(eye + matmul(G, PG))
        A = matmul(PG, L_inv.T)
        P = P - matmul(A, A.T)
        return P, jnp.einsum("ab,ba->", problem.weight, P)

    _, traces = jax.lax.scan(scan, P0, subsets)
    return problem.target_weights[target] * jnp.sum(traces)


def _subsets_of(schedule: Array, target: Array) -> Array:
    """Which sensors look at ``target`` at each scan of ``schedule`` ``(T, S)``: ``(T,)`` subset
    indices (bit ``s`` set when sensor ``s`` does)."""
    S = schedule.shape[1]
    return jnp.sum((schedule == target).astype(jnp.int32) * (2 ** jnp.arange(S, dtype=jnp.int32))[None, :], axis=-1)


# The local search's one-target recursions run in chunks of this many (lax.map): a chunk's
# (chunk, n, n) intermediates stay in cache through the T scans. Measured on the 2-core CPU
# (benchmark scenarios): 128 is 20–25 % faster than one vmap over all (16 and 1024 lie between).
_CHUNK = 128


def _swap_pairs(num_scans: int, num_sensors: int) -> tuple[np.ndarray, np.ndarray]:
    """The flat positions ``(p, q)``, ``p < q``, of the exchanges worth trying, in
    ``np.triu_indices`` order: two looks at the same scan exchanged give a joint look of that scan,
    which the single moves (tried first) already cover, so those pairs are left out."""
    p, q = np.triu_indices(num_scans * num_sensors, k=1)
    keep = p // num_sensors != q // num_sensors
    return p[keep].astype(np.int32), q[keep].astype(np.int32)


def _single_table(problem: SensorSchedulingProblem, factors: Array, schedule: Array) -> tuple[Array, Array]:
    """``D[i, k, m]`` ``(N, T, 2^S)``: target ``i``'s ``J_i`` with row ``k`` of its looks set to the
    sensor subset ``m``, the other rows as in ``schedule`` (``N·T·2^S`` one-target recursions), and
    the rows themselves ``(N, T)`` (:func:`_subsets_of`)."""
    T, S, N = problem.num_scans, problem.num_sensors, problem.num_targets
    rows = jax.vmap(lambda i: _subsets_of(schedule, i))(jnp.arange(N))  # (N, T)

    def table_entry(i, k, m):
        return _target_cost(problem, factors, i, rows[i].at[k].set(m))

    i, k, m = (jnp.asarray(a.ravel(), jnp.int32)
               for a in np.meshgrid(np.arange(N), np.arange(T), np.arange(2**S), indexing="ij"))
    D = jax.lax.map(lambda x: table_entry(*x), (i, k, m), batch_size=_CHUNK).reshape(N, T, 2**S)
    return D, rows


def _refresh_table(problem: SensorSchedulingProblem, factors: Array, D: Array, rows: Array, schedule: Array
                   ) -> tuple[Array, Array]:
    """:func:`_single_table` of ``schedule`` from the table ``D`` and ``rows`` of the schedule before
    one move: ``D[i]`` depends on target ``i``'s own looks only, so only the targets whose rows the
    move changed (two for an exchange, at most ``2S`` for a joint-look change) are recomputed, one
    after another (a ``while_loop`` over their count: ``T·2^S`` recursions each instead of
    ``N·T·2^S`` in all). Each entry is the same one-target recursion as the full table's."""
    T, S, N = problem.num_scans, problem.num_sensors, problem.num_targets
    new_rows = jax.vmap(lambda i: _subsets_of(schedule, i))(jnp.arange(N))
    changed = jnp.any(new_rows != rows, axis=1)
    which = jnp.nonzero(changed, size=N, fill_value=0)[0]
    k, m = (jnp.asarray(a.ravel(), jnp.int32) for a in np.meshgrid(np.arange(T), np.arange(2**S), indexing="ij"))

    def one_target(j, D):
        i = which[j]
        row = jax.vmap(lambda k, m: _target_cost(problem, factors, i, new_rows[i].at[k].set(m)))(k, m)
        return D.at[i].set(row.reshape(T, 2**S))

    D = jax.lax.fori_loop(0, jnp.sum(changed), one_target, D)
    return D, new_rows


def _single_costs(problem: SensorSchedulingProblem, D: Array, rows: Array) -> tuple[Array, Array]:
    """From the table of :func:`_single_table`: the cost of every single move ``(T, N^S)`` (each
    scan's joint look replaced by each joint look, :func:`_configurations` order) and the current
    ``J_i`` ``(N,)``."""
    T, S, N = problem.num_scans, problem.num_sensors, problem.num_targets
    targets = jnp.arange(N)
    # Row subset each target gets under each joint look: bit s set when sensor s looks at it.
    configs = _configurations(N, S)
    subset_of = jnp.asarray(((configs[:, :, None] == np.arange(N)) * (2 ** np.arange(S))[None, :, None]).sum(1),
                            jnp.int32)  # (N^S, N)
    singles = jnp.sum(D[targets[None, None, :], jnp.arange(T)[:, None, None], subset_of[None]], axis=-1)
    # The current J_i: row 0 set to the subset it already has.
    return singles, D[targets, 0, rows[:, 0]]


def _move_costs(problem: SensorSchedulingProblem, factors: Array, schedule: Array) -> tuple[Array, Array, Array]:
    r"""The exact cost of every neighbour of ``schedule`` ``(T, S)``, recomputing only the targets a
    move changes.

    ``J = Σ_i J_i`` with ``J_i`` (:func:`_target_cost`) depending only on target ``i``'s own looks.

    - A single move changes the joint look of one scan ``k``: each target's row ``k`` becomes the
      set of sensors now looking at it, one of ``2^S`` subsets. The table
      ``D[i, k, m] = J_i`` (row ``k`` of ``i``'s looks set to subset ``m``, the other rows as they
      are) holds all of them (``N·T·2^S`` one-target recursions), and a move's cost is
      ``Σ_i D[i, k, m_i]``: ``T·N^S`` moves for the price of ``N·T·2^S`` recursions instead of
      ``T·N^S·N``.
    - An exchange of the looks at ``(k, s)`` and ``(l, s')`` (targets ``a ≠ b``) changes two rows
      of ``a`` and of ``b`` only: their two recursions are redone, the other ``N − 2`` targets' ``J_i``
      reused. An exchange of a target with itself is no move (cost ``+∞``, never taken).

    **Returns:** ``(singles (T, N^S), swaps (P,), per_target (N,))``: the costs of the single moves
    (the current joint look among them), of the exchanges of :func:`_swap_pairs` and the current
    ``J_i``.
    """
    T, S = problem.num_scans, problem.num_sensors
    dtype = problem.initial_cov.dtype
    D, rows = _single_table(problem, factors, schedule)
    singles, per_target = _single_costs(problem, D, rows)

    flat = schedule.reshape(T * S)
    p, q = (jnp.asarray(a) for a in _swap_pairs(T, S))

    def swap(p, q):
        a, b = flat[p], flat[q]
        trial = flat.at[p].set(b).at[q].set(a).reshape(T, S)
        ca = _target_cost(problem, factors, a, _subsets_of(trial, a))
        cb = _target_cost(problem, factors, b, _subsets_of(trial, b))
        return jnp.where(a == b, jnp.inf, jnp.sum(per_target.at[a].set(ca).at[b].set(cb)))

    swaps = jax.lax.map(lambda x: swap(*x), (p, q), batch_size=_CHUNK) if p.size else jnp.zeros((0,), dtype)
    return singles, swaps, per_target


def _apply_move(problem: SensorSchedulingProblem, schedule: Array, move: Array) -> Array:
    """The neighbour number ``move`` of ``schedule``: single moves first (scan-major, joint looks in
    :func:`_configurations` order), then the exchanges of :func:`_swap_pairs`."""
    T, S = schedule.shape
    configs = jnp.asarray(_configurations(problem.num_targets, S))
    num_single = T * configs.shape[0]
    k, j = jnp.divmod(jnp.minimum(move, num_single - 1), configs.shape[0])
    single = schedule.at[k].set(configs[j])
    p_all, q_all = _swap_pairs(T, S)
    if p_all.size == 0:
        return single
    idx = jnp.clip(move - num_single, 0, p_all.size - 1)
    p, q = jnp.asarray(p_all)[idx], jnp.asarray(q_all)[idx]
    flat = schedule.reshape(T * S)
    swapped = flat.at[p].set(flat[q]).at[q].set(flat[p]).reshape(T, S)
    return jnp.where(move < num_single, single, swapped)


def _total_cost(problem: SensorSchedulingProblem, factors: Array, schedule: Array) -> Array:
    """``J = Σ_i J_i`` of ``schedule`` ``(T, S)``: one one-target recursion per target."""
    return jnp.sum(jax.vmap(lambda i: _target_cost(problem, factors, i, _subsets_of(schedule, i)))(
        jnp.arange(problem.num_targets)))


def _take_best(problem, schedule, J, moves, costs, rtol, move_of=None, allowed=True):
    """One local-search step: the cheapest neighbour in ``costs`` (neighbour ``move_of[i]`` of
    :func:`_apply_move` for entry ``i``; default ``i``), taken when it lowers ``J`` by more than
    ``rtol·|J|`` (and ``allowed``). **Returns** the loop carry ``(schedule, J, moves, improved)``."""
    best = jnp.argmin(costs)
    improved = (costs[best] < J - rtol * jnp.abs(J)) & allowed
    move = best if move_of is None else move_of[best]
    return (jnp.where(improved, _apply_move(problem, schedule, move), schedule),
            jnp.where(improved, costs[best], J), moves + improved.astype(moves.dtype), improved)


def _polish_one(problem, schedule, max_iter, rtol):
    """Best-improvement local search on the exact discrete cost: every iteration takes the
    cheapest neighbour (:func:`_move_costs`; the first in :func:`_apply_move` order among equals)
    while it lowers ``J`` by more than ``rtol·|J|``."""

    factors = _subset_factors(problem)

    def costs_of(schedule):
        singles, swaps, per_target = _move_costs(problem, factors, schedule)
        return jnp.concatenate([singles.ravel(), swaps]), jnp.sum(per_target)

    def cond(carry):
        _, _, moves, improved = carry
        return improved & (moves < max_iter)

    def body(carry):
        schedule, J, moves, _ = carry
        return _take_best(problem, schedule, J, moves, costs_of(schedule)[0], rtol)

    J0 = _total_cost(problem, factors, schedule)
    schedule, J, moves, improved = jax.lax.while_loop(
        cond, body, (schedule, J0, jnp.asarray(0, jnp.int32), jnp.asarray(True)))
    # At the cap the loop stops without knowing whether one more move would help: look once more.
    still = jnp.min(costs_of(schedule)[0]) < J - rtol * jnp.abs(J)
    return schedule, J, moves, improved & still


@eqx.filter_jit
def _polish(problem, schedules, max_iter, rtol):
    """:func:`_polish_one` of each start ``(R, T, S)`` (a batched ``while_loop`` freezes each start
    once its own search has stopped)."""
    return jax.vmap(_polish_one, in_axes=(None, 0, None, None))(problem, schedules, max_iter, rtol)


def _exchange_estimates(problem: SensorSchedulingProblem, D: Array, rows: Array, per_target: Array,
                        schedule: Array) -> Array:
    r"""The cost of every exchange of :func:`_swap_pairs` estimated from the single-move table
    ``D`` (:func:`_single_table`): exchanging the looks at ``(k, s)`` (target ``a``) and ``(l, s')``
    (target ``b``) changes two rows of ``a`` and two of ``b``, and each row's change alone is priced
    exactly by ``D``; the estimate adds the four changes, leaving out only how the two changes of
    one target interact (``(P,)``, ``+∞`` for an exchange of a target with itself)."""
    T, S = schedule.shape
    flat = schedule.reshape(T * S)
    p, q = (jnp.asarray(x) for x in _swap_pairs(T, S))
    a, b = flat[p], flat[q]
    k, s = jnp.divmod(p, S)
    l, t = jnp.divmod(q, S)
    bit_s, bit_t = 2**s, 2**t

    def change(i, row, subset):
        return D[i, row, subset] - per_target[i]

    est = (jnp.sum(per_target)
           + change(a, k, rows[a, k] & ~bit_s) + change(a, l, rows[a, l] | bit_t)
           + change(b, l, rows[b, l] & ~bit_t) + change(b, k, rows[b, k] | bit_s))
    return jnp.where(a == b, jnp.inf, est)


def _screened_polish_one(problem, schedule, max_iter, rtol, k):
    """The local search of :func:`_polish_one` with the same neighbourhood and stopping rule and
    cheaper iterations: every single move is costed exactly from the table (:func:`_single_table`),
    but of the ``TS(TS − S)/2`` exchanges only the ``k`` best by their estimate
    (:func:`_exchange_estimates`, two recursions each); the cheapest of these is taken while it
    improves. When none does, one full evaluation (:func:`_move_costs`) looks for an exchange the
    estimate misranked, takes it and the screened search goes on. It stops where the full evaluation
    finds no improving move: at a local optimum of the same neighbourhood, though not necessarily the
    one the best-improvement path reaches."""

    factors = _subset_factors(problem)
    T, S = schedule.shape
    num_single = T * problem.num_targets**S
    p_all, q_all = (jnp.asarray(x) for x in _swap_pairs(T, S))
    k = min(k, int(p_all.size))

    def screened_step(carry):
        (schedule, J, moves, _), (D, rows) = carry
        singles, current = _single_costs(problem, D, rows)
        if k:
            _, idx = jax.lax.top_k(-_exchange_estimates(problem, D, rows, current, schedule), k)
            flat = schedule.reshape(T * S)

            def exact(p, q):
                a, b = flat[p], flat[q]
                trial = flat.at[p].set(b).at[q].set(a).reshape(T, S)
                ca = _target_cost(problem, factors, a, _subsets_of(trial, a))
                cb = _target_cost(problem, factors, b, _subsets_of(trial, b))
                return jnp.where(a == b, jnp.inf, jnp.sum(current.at[a].set(ca).at[b].set(cb)))

            swaps = jax.vmap(exact)(p_all[idx], q_all[idx])
            costs = jnp.concatenate([singles.ravel(), swaps])
            move_of = jnp.concatenate([jnp.arange(num_single, dtype=jnp.int32), num_single + idx.astype(jnp.int32)])
        else:
            costs = singles.ravel()
            move_of = jnp.arange(num_single, dtype=jnp.int32)
        step = _take_best(problem, schedule, J, moves, costs, rtol, move_of)
        # The table follows the move: only the targets whose looks it changed are recomputed.
        return step, _refresh_table(problem, factors, D, rows, step[0])

    def full_costs(schedule):
        singles, swaps, _ = _move_costs(problem, factors, schedule)
        return jnp.concatenate([singles.ravel(), swaps])

    def can_move(carry):
        return carry[3] & (carry[2] < max_iter)

    def outer_step(carry):
        schedule = carry[0]
        step, _ = jax.lax.while_loop(lambda c: can_move(c[0]), screened_step,
                                     ((*carry[:3], jnp.asarray(True)), _single_table(problem, factors, schedule)))
        schedule, J, moves, _ = step
        return _take_best(problem, schedule, J, moves, full_costs(schedule), rtol, allowed=moves < max_iter)

    J0 = _total_cost(problem, factors, schedule)
    schedule, J, moves, _ = jax.lax.while_loop(
        can_move, outer_step, (schedule, J0, jnp.asarray(0, jnp.int32), jnp.asarray(True)))
    still = jnp.min(full_costs(schedule)) < J - rtol * jnp.abs(J)
    return schedule, J, moves, still


@eqx.filter_jit
def _screened_polish(problem, schedules, max_iter, rtol, k: int):
    """:func:`_screened_polish_one` of each start ``(R, T, S)``, ``k`` exchanges costed per iteration
    (a Python int: static)."""
    return jax.vmap(_screened_polish_one, in_axes=(None, 0, None, None, None))(problem, schedules, max_iter, rtol, k)

"""Murty's k-best 2-D assignments over several cost matrices at once, with static shapes.

:func:`k_best_assignments` ranks the complete assignments of ``P`` "parent" cost matrices (e.g.
the global hypotheses of a PMBM filter, each with an additive cost ``−log w``) in ONE shared
priority queue, so the ``k`` best over all parents come out together. Every subproblem is solved
by :func:`~jaxtrack.association.linear_assignment`; the queue is a fixed-size array.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._validation import InputError
from ._assignment import linear_assignment


class KBestAssignments(eqx.Module):
    """The ``k`` best complete assignments, best first (:func:`k_best_assignments`).

    **Fields** (a leading batch axis when vmapped):

    - ``parent``: ``(k,)`` int32, the cost matrix (``0 … P − 1``) of each solution; −1 where
      there is no solution.
    - ``row_to_col``: ``(k, R)`` int32, the column of every row; −1 where there is no solution.
    - ``total_cost``: ``(k,)``, ``offsets[parent] + Σ_r cost[parent, r, row_to_col[r]]`` in the
      units of ``cost``, ascending; ``+inf`` where there is no solution.
    - ``valid``: ``(k,)`` bool, True for the first ``num_solutions`` entries.
    - ``num_solutions``: ``()`` int32, ``min(k, number of complete assignments of the valid
      parents)``.
    """

    parent: Int[Array, " k"]
    row_to_col: Int[Array, "k R"]
    total_cost: Float[Array, " k"]
    valid: Bool[Array, " k"]
    num_solutions: Int[Array, ""]


def check_problem(cost, offsets=None, valid_parents=None):
    """The argument checks shared by :func:`k_best_assignments` and
    :func:`~jaxtrack.association.gibbs_assignments`: ``cost`` as a float ``(P, R, C)`` tensor
    (a 2-D one gets ``P = 1``) with ``R ≤ C``, ``offsets`` ``(P,)`` in its dtype (default 0),
    ``valid_parents`` ``(P,)`` bool (default all True). **Raises:** :class:`~jaxtrack.InputError`
    naming the argument."""
    cost = jnp.asarray(cost)
    if cost.ndim not in (2, 3):
        raise InputError(f"`cost` must have shape (P, R, C) or (R, C); got shape {cost.shape}.")
    if not jnp.issubdtype(cost.dtype, jnp.floating):
        cost = cost.astype(jnp.result_type(float))
    if cost.ndim == 2:
        cost = cost[None]
    P, R, C = cost.shape
    if R > C:
        raise InputError(
            f"`cost` must have no more rows than columns (every row is assigned); got R={R} > C={C}."
        )
    if offsets is None:
        offsets = jnp.zeros((P,), cost.dtype)
    offsets = jnp.asarray(offsets)
    if offsets.shape != (P,):
        raise InputError(f"`offsets` must have shape ({P},) (one per cost matrix); got {offsets.shape}.")
    offsets = offsets.astype(cost.dtype)
    if valid_parents is None:
        valid_parents = jnp.ones((P,), bool)
    valid_parents = jnp.asarray(valid_parents)
    if valid_parents.shape != (P,):
        raise InputError(f"`valid_parents` must have shape ({P},); got {valid_parents.shape}.")
    return cost, offsets, valid_parents.astype(bool)


def check_count(name: str, value) -> int:
    """``value`` as a static Python int ``≥ 1`` (``k``, ``num_chains``, ``num_sweeps``), else
    :class:`~jaxtrack.InputError` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise InputError(f"`{name}` must be a static Python int >= 1; got {value!r}.")
    return value


def _solve(work, allowed, offset):
    """Best complete assignment of one masked matrix: (row_to_col, total, feasible)."""
    row_to_col, total = linear_assignment(work, allowed)
    feasible = jnp.all(row_to_col >= 0)
    total = offset + total
    feasible = feasible & jnp.isfinite(total)
    return row_to_col, jnp.where(feasible, total, jnp.inf), feasible


def _keep_best(queue, k):
    """The ``k`` best entries of ``queue`` (invalid ones last), in ascending order of total."""
    order = jnp.argsort(jnp.where(queue["valid"], queue["total"], jnp.inf), stable=True)[:k]
    return jax.tree.map(lambda x: x[order], queue)


def _concatenate(a, b):
    return jax.tree.map(lambda x, y: jnp.concatenate([x, y]), a, b)


def k_best_assignments(
    cost: Float[ArrayLike, "P R C"] | Float[ArrayLike, "R C"],
    k: int,
    offsets: Float[ArrayLike, " P"] | None = None,
    valid_parents: Bool[ArrayLike, " P"] | None = None,
) -> KBestAssignments:
    r"""The ``k`` lowest-cost complete assignments over ``P`` cost matrices (Murty's ranking).

    A *solution* is a pair ``(p, θ)``: a valid parent ``p`` and an assignment ``θ`` of EVERY row
    ``r`` of ``cost[p]`` to a distinct column with a finite entry; it costs
    ``offsets[p] + Σ_r cost[p, r, θ_r]``. The result lists the ``k`` cheapest solutions over all
    parents, ascending, each once (ties in any order); when fewer than ``k`` exist, the rest
    are invalid (parent −1, columns −1, total ``+inf``).

    **Algorithm:** K. G. Murty, "An algorithm for ranking all the assignments in order of
    increasing cost", Oper. Res. 16(3), 1968, with one priority queue for all parents and the
    partition of M. L. Miller, H. S. Stone & I. J. Cox, "Optimizing Murty's ranked assignment
    method", IEEE TAES 33(3), 1997 (see also D. F. Crouse, "On implementing 2D rectangular
    assignment algorithms", IEEE TAES 52(4), 2016). A queue node is a subproblem (parent, rows
    forced to a column, forbidden pairs) with its best solution. The queue starts with every
    valid parent's best solution. Each of the ``k`` steps pops the cheapest node, outputs it and
    splits its remaining space: with ``u_1 < u_2 < …`` its rows not yet forced and ``θ`` its
    solution, child ``i`` forces ``u_j → θ_{u_j}`` for ``j < i`` and forbids ``(u_i, θ_{u_i})``.
    The children partition the node's space minus ``θ``, so no solution is listed twice; they
    are solved together (``jax.vmap`` of :func:`~jaxtrack.association.linear_assignment` on the
    masked matrices; a child with a row left unassigned is infeasible). Static shapes: the queue
    holds ``k`` nodes, a ``lax.fori_loop`` runs the ``k`` pops.

    **Complexity:** ``k`` pops × ``R`` Hungarian solves of ``R × C`` (``O(R² C)`` each):
    ``O(k R³ C)`` time, plus ``P`` solves to start; memory ``O(k R C)``.

    **Arguments:**

    - ``cost``: ``(P, R, C)`` or ``(R, C)`` (then ``P = 1``), ``R ≤ C``, any real units;
      ``+inf`` (any non-finite entry) marks a forbidden pair.
    - ``k``: static Python int ``≥ 1``, the number of solutions.
    - ``offsets``: ``(P,)``, each parent's additive cost (e.g. ``−log`` of its weight), in the
      units of ``cost``; default 0. A parent with a non-finite offset has no solution.
    - ``valid_parents``: ``(P,)`` bool; False parents are left out. Default: all True.

    **Returns:** a :class:`KBestAssignments`. ``total_cost`` is differentiable in ``cost`` and
    ``offsets`` (the ranking itself is piecewise constant): ``∂ total_cost[i] / ∂ cost[p, r, c]``
    is 1 on the pairs of solution ``i``, ``∂ / ∂ offsets[p]`` is 1 for its parent.

    Jittable (``k`` static) and vmappable over a batch of cost tensors.

    Example (two parents; the second costs 0.5 more):

    >>> import jax.numpy as jnp
    >>> cost = jnp.array([[[1.0, 2.0], [2.0, 4.0]], [[0.0, 9.0], [9.0, 0.0]]])
    >>> best = k_best_assignments(cost, 3, offsets=jnp.array([0.0, 0.5]))
    >>> best.parent.tolist(), best.row_to_col.tolist(), best.total_cost.tolist()
    ([1, 0, 0], [[0, 1], [1, 0], [0, 1]], [0.5, 4.0, 5.0])
    """
    cost, offsets, valid_parents = check_problem(cost, offsets, valid_parents)
    P, R, C = cost.shape
    check_count("k", k)

    # The ranking is discrete: it runs on stopped values; the gradient comes from the gather below.
    work = jax.lax.stop_gradient(cost)
    work_offsets = jax.lax.stop_gradient(offsets)
    finite = jnp.isfinite(work)  # (P, R, C)
    rows = jnp.arange(R)
    cols = jnp.arange(C)

    # The initial queue: each parent's best solution, padded with k invalid nodes.
    sol0, total0, feasible0 = jax.vmap(_solve)(work, finite, work_offsets)
    invalid = {
        "parent": jnp.full((k,), -1, jnp.int32),
        "forced": jnp.full((k, R), -1, jnp.int32),
        "forbidden": jnp.zeros((k, R, C), bool),
        "sol": jnp.full((k, R), -1, jnp.int32),
        "total": jnp.full((k,), jnp.inf, cost.dtype),
        "valid": jnp.zeros((k,), bool),
    }
    roots = {
        "parent": jnp.arange(P, dtype=jnp.int32),
        "forced": jnp.full((P, R), -1, jnp.int32),
        "forbidden": jnp.zeros((P, R, C), bool),
        "sol": sol0,
        "total": total0,
        "valid": feasible0 & valid_parents,
    }
    # Capacity k: the queue never needs more entries than pops remain (see the loop).
    queue = _keep_best(_concatenate(roots, invalid), k)

    def pop(t, state):
        queue, out_parent, out_sol, out_valid = state
        node = jax.tree.map(lambda x: x[0], queue)  # the queue is kept sorted: the best is first
        out_parent = out_parent.at[t].set(jnp.where(node["valid"], node["parent"], -1))
        out_sol = out_sol.at[t].set(jnp.where(node["valid"], node["sol"], -1))
        out_valid = out_valid.at[t].set(node["valid"])

        # Murty's partition over the free rows in increasing row order: child r (for a free
        # row r) forces every row forced in the node and every free row before r to the node's
        # solution, and forbids the pair (r, sol[r]). (A forced row's column is its solution's.)
        free = node["forced"] < 0  # (R,)
        before = rows[None, :] < rows[:, None]  # [child r, row r'] = r' < r
        child_forced = jnp.where(before | ~free[None, :], node["sol"][None, :], -1)  # (R, R)
        newly = (rows[:, None, None] == rows[None, :, None]) & (cols[None, None, :] == node["sol"][None, :, None])
        child_forbidden = node["forbidden"][None] | newly  # (R, R, C)
        p = jnp.maximum(node["parent"], 0)
        on_forced = (child_forced[:, :, None] < 0) | (cols[None, None, :] == child_forced[:, :, None])
        allowed = finite[p][None] & ~child_forbidden & on_forced
        sols, totals, feasible = jax.vmap(_solve, in_axes=(None, 0, None))(work[p], allowed, work_offsets[p])
        children = {
            "parent": jnp.full((R,), node["parent"], jnp.int32),
            "forced": child_forced.astype(jnp.int32),
            "forbidden": child_forbidden,
            "sol": sols,
            "total": totals,
            "valid": node["valid"] & free & feasible,
        }
        # Drop the popped node, add its children, keep the best k. After pop t, only k − 1 − t
        # more pops happen, so an entry ranked k − 1 − t or beyond (0-based) can never be popped:
        # truncating the sorted queue to k entries loses nothing (k − 1 would do; k keeps one
        # shape for the initial queue and the loop).
        queue = dict(queue, valid=queue["valid"].at[0].set(False), total=queue["total"].at[0].set(jnp.inf))
        queue = _keep_best(_concatenate(queue, children), k)
        return queue, out_parent, out_sol, out_valid

    init = (queue, jnp.full((k,), -1, jnp.int32), jnp.full((k, R), -1, jnp.int32), jnp.zeros((k,), bool))
    _, parent, row_to_col, valid = jax.lax.fori_loop(0, k, pop, init)

    # The totals, gathered from the un-stopped cost and offsets (the envelope-theorem gradient).
    p = jnp.maximum(parent, 0)
    col = jnp.maximum(row_to_col, 0)
    picked = cost[p[:, None], rows[None, :], col]  # (k, R)
    total = offsets[p] + jnp.sum(jnp.where(valid[:, None], picked, 0.0), axis=1)
    total = jnp.where(valid, total, jnp.inf)
    # A final stable sort makes the order exact in the recomputed totals (the subproblem sums
    # can differ from these in the last bit).
    order = jnp.argsort(total, stable=True)
    return KBestAssignments(
        parent=parent[order],
        row_to_col=row_to_col[order],
        total_cost=total[order],
        valid=valid[order],
        num_solutions=jnp.sum(valid, dtype=jnp.int32),
    )

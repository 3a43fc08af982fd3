"""Two-dimensional assignment inside ``jit``, and global nearest neighbour (GNN) built on it.

:func:`linear_assignment` wraps optax's lax-only Hungarian solver
(``optax.assignment.hungarian_algorithm``, after scenic's ``hungarian_jax.py``) so that it accepts
forbidden pairs (``+inf``) and padding, and never feeds the solver an infinity or a NaN.
:class:`GNN` solves the augmented (tracks × (measurements + misses)) problem of Stone Soup's
``GNNWith2DAssignment`` on the shared log-weight matrix ``L`` (``_types``), maximising the sum
of log weights of one joint event.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import optax
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ._types import AbstractAssociator, Association


def linear_assignment(
    cost: Float[ArrayLike, "R C"],
    valid: Bool[ArrayLike, "#R #C"] | None = None,
) -> tuple[Int[Array, " R"], Float[Array, ""]]:
    r"""Minimum-cost assignment of rows to columns of a rectangular cost matrix with forbidden pairs.

    A pair ``(r, c)`` is *allowed* when ``cost[r, c]`` is finite and ``valid[r, c]`` is True;
    ``+inf`` (or NaN, or ``−inf``) marks a forbidden pair. The answer is, among matchings that use
    allowed pairs only (each row at most one column, each column at most one row):

    1. one of **maximum cardinality** (as many rows assigned as the allowed pairs permit), then
    2. of **minimum total cost** among those.

    When a complete assignment of ``min(R, C)`` allowed pairs exists this is exactly
    ``scipy.optimize.linear_sum_assignment``'s problem (same optimal cost); where it does not,
    SciPy raises "cost matrix is infeasible" and this function leaves the rows it cannot match
    unassigned (−1). Rows whose entries are all forbidden are never assigned.

    How: the allowed entries are shifted to ``[0, D]`` (``D`` their range) and every forbidden
    entry becomes the finite sentinel ``B = (n + 1)·D + 1``, ``n = min(R, C)``, in the working
    dtype. A complete matching with ``k`` sentinel pairs costs between ``k·B`` and
    ``k·B + (n − k)·D``, so one more sentinel pair always costs more than any saving on the
    allowed pairs: the solver's complete assignment of the shifted matrix uses the fewest
    sentinels (the maximum matching of allowed pairs) and, among those, the cheapest. The sentinel pairs are then dropped. The
    solver sees ``stop_gradient(cost)``; ``total_cost`` is summed from ``cost`` itself, so its
    gradient is that of the optimal value (the envelope theorem: ``∂ total / ∂ cost[r, c]`` is 1
    on the assigned pairs).

    **Arguments:**

    - ``cost``: ``(R, C)``, any real units (an integer matrix is cast to the default float
      dtype). Allowed entries should span less than ``finfo.max / (min(R, C) + 1)``.
    - ``valid``: optional boolean mask broadcastable to ``(R, C)`` (e.g. ``(R, 1)`` for padded
      rows, ``(1, C)`` for padded columns); False is the same as ``+inf``. Default: all True.

    **Returns:** ``(row_to_col, total_cost)``: ``row_to_col`` int32 ``(R,)``, the column assigned
    to each row or −1; ``total_cost`` ``()``, the sum of ``cost`` over the assigned pairs (0 when
    none), in ``cost``'s units and dtype.

    Jittable and vmappable (the solver is ``lax.scan`` over rows around ``lax.while_loop``s).

    Example (row 1 has no allowed pair and stays unassigned; row 0 can only take column 0):

    >>> import jax.numpy as jnp
    >>> inf = jnp.inf
    >>> row_to_col, total = linear_assignment(jnp.array([[1.0, inf], [inf, inf], [2.0, 5.0]]))
    >>> row_to_col.tolist(), float(total)
    ([0, -1, 1], 6.0)

    Solver: optax 0.2.8 ``optax.assignment.hungarian_algorithm`` (after scenic,
    Dehghani et al. 2022, "Scenic: a JAX library for computer vision research and beyond");
    the rectangular problem as stated by D. F. Crouse, "On implementing 2D rectangular
    assignment algorithms", IEEE Trans. Aerosp. Electron. Syst. 52(4), 2016.
    """
    cost = jnp.asarray(cost)
    if not jnp.issubdtype(cost.dtype, jnp.floating):
        cost = cost.astype(jnp.result_type(float))
    R, C = cost.shape
    allowed = jnp.isfinite(cost)
    if valid is not None:
        allowed = allowed & jnp.broadcast_to(jnp.asarray(valid, bool), (R, C))
    if R == 0 or C == 0:
        return jnp.full((R,), -1, jnp.int32), jnp.zeros((), cost.dtype)

    n = min(R, C)
    work = jax.lax.stop_gradient(cost)
    # Range of the allowed entries (0 when there are none): the sentinel is built from it so that
    # it cannot win against any set of allowed pairs, whatever the units of the costs.
    lo = jnp.min(jnp.where(allowed, work, jnp.inf))
    hi = jnp.max(jnp.where(allowed, work, -jnp.inf))
    any_allowed = jnp.any(allowed)
    lo = jnp.where(any_allowed, lo, 0.0)
    spread = jnp.where(any_allowed, hi - lo, 0.0)
    finfo = jnp.finfo(cost.dtype)
    # Clipped only so that no infinity reaches the solver if the allowed entries span nearly the
    # whole float range (then the lexicographic guarantee above no longer holds).
    sentinel = jnp.minimum((n + 1) * spread + 1.0, finfo.max / (4 * (n + 1)))
    shifted = jnp.where(allowed, work - lo, sentinel).astype(cost.dtype)

    rows, cols = optax.assignment.hungarian_algorithm(shifted)
    # Scatter the solver's min(R, C) pairs into a per-row table; any index the solver returns
    # out of range (it should not) is dropped rather than wrapped around.
    rows = jnp.where((rows >= 0) & (rows < R), rows, R)
    cols = jnp.where((cols >= 0) & (cols < C), cols, -1)
    row_to_col = jnp.full((R,), -1, jnp.int32).at[rows].set(cols.astype(jnp.int32), mode="drop")
    safe_col = jnp.clip(row_to_col, 0, C - 1)
    assigned = (row_to_col >= 0) & allowed[jnp.arange(R), safe_col]
    row_to_col = jnp.where(assigned, row_to_col, -1)
    picked = jnp.take_along_axis(cost, safe_col[:, None], axis=1)[:, 0]
    total_cost = jnp.sum(jnp.where(assigned, picked, 0.0))
    return row_to_col, total_cost


class GNN(AbstractAssociator):
    r"""Global nearest neighbour: the single most likely joint association event of a scan.

    Maximises ``Σ_t L[t, θ_t]`` over joint events ``θ`` (each valid track takes column 0, "not
    detected", or one measurement column; no measurement taken twice), by a 2-D assignment on
    the augmented ``(T, M + T)`` cost matrix of Stone Soup's ``GNNWith2DAssignment``
    (``stonesoup/dataassociator/neighbour.py``)::

        [ −L[:, 1:]  |  diag(−L[:, 0]) with +inf off the diagonal ]

    Column ``M + t`` is track ``t``'s own "missed" column, so every valid track with a finite
    missed weight can always be matched, and the minimum-cost complete assignment is the
    maximum-weight joint event. (Stone Soup sums linear probabilities; this sums log weights,
    i.e. maximises the product of the likelihood ratios, the event's posterior probability.)

    **Returns** an :class:`~jaxtrack.association.Association` with one-hot rows for valid tracks
    (column 0 when missed), zero rows for invalid tracks, ``clutter_probabilities`` ``1 − Σ_t β[t,
    j + 1]`` (1 for every measurement no track took, padded or not: the associator is not told
    which columns are padding), ``log_normalizer`` the best event's log weight ``Σ_t L[t, θ_t]``
    over valid tracks, ``residual`` 0, ``overflow`` False (no capacity), and ``ok`` False when
    that weight is not finite or a valid row of ``L`` holds a NaN or ``+inf`` (no probability: a
    ``+inf`` entry is forbidden to the solver like a NaN, so the event it picks means nothing;
    ``log_normalizer`` is then NaN). A valid track with no allowed option at all
    (``L[t, 0] = −inf`` and every measurement gated out or taken) is reported as missed, with
    ``log_normalizer = −inf`` and ``ok`` False: no joint event has positive probability.

    No options; jittable and vmappable. The best event is differentiable in ``L`` (the
    assignment itself is piecewise constant): ``∂ log_normalizer / ∂ L[t, θ_t] = 1``.
    """

    def __call__(
        self,
        log_weights: Float[Array, "T Mp1"],
        valid_tracks: Bool[Array, " T"] | None = None,
    ) -> Association:
        L = jnp.asarray(log_weights)
        T, Mp1 = L.shape
        M = Mp1 - 1
        valid = jnp.ones((T,), bool) if valid_tracks is None else jnp.asarray(valid_tracks, bool)

        eye = jnp.eye(T, dtype=bool)
        miss_block = jnp.where(eye, -L[:, :1], jnp.inf)
        cost = jnp.concatenate([-L[:, 1:], miss_block], axis=1)
        row_to_col, _ = linear_assignment(cost, valid[:, None])

        detected = (row_to_col >= 0) & (row_to_col < M)
        column = jnp.where(detected, row_to_col + 1, 0)  # missed or unassignable → column 0
        beta = jax.nn.one_hot(column, Mp1, dtype=L.dtype) * valid[:, None].astype(L.dtype)

        chosen = jnp.take_along_axis(L, column[:, None], axis=1)[:, 0]
        # An unassigned valid track has no allowed option: its event weight is zero (log −inf),
        # whatever L[t, 0] holds.
        chosen = jnp.where(row_to_col >= 0, chosen, -jnp.inf)
        log_normalizer = jnp.sum(jnp.where(valid, chosen, 0.0))
        # NaN and +inf (−inf is legal: gated out) in a valid row: the same rule as PDA/JPDA/BP.
        bad_input = jnp.any((jnp.isnan(L) | (L == jnp.inf)) & valid[:, None])
        log_normalizer = jnp.where(bad_input, jnp.nan, log_normalizer)
        ok = jnp.isfinite(log_normalizer)
        return Association(
            association_probabilities=beta,
            clutter_probabilities=1.0 - jnp.sum(beta[:, 1:], axis=0),
            log_normalizer=log_normalizer,
            residual=jnp.zeros((), L.dtype),
            ok=ok,
            overflow=jnp.zeros((), bool),
        )

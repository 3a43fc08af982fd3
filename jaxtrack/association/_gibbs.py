"""Gibbs sampling of good 2-D assignments over several cost matrices at once, with static shapes.

:func:`gibbs_assignments` is the randomised alternative to Murty's ranking
(:func:`~jaxtrack.association.k_best_assignments`) of Vo, Vo & Hoang (2017): instead of the ``k``
best assignments in order, it draws assignments from the distribution ``∝ exp(−cost)`` by
systematic-scan Gibbs sampling, keeps the distinct ones and returns the ``k`` cheapest of them in
the same :class:`~jaxtrack.association.KBestAssignments`. Its cost is linear in the number of
samples and rows (no ``R³`` subproblem per solution), so many more hypotheses are affordable.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._validation import InputError, as_key, is_concrete
from ._murty import KBestAssignments, _solve, check_count, check_problem


def _check_key(key) -> Array:
    """``key`` as ONE typed PRNG key of shape ``()``: :func:`~jaxtrack._validation.as_key` (a typed
    key, a legacy ``uint32`` ``(2,)`` key, wrapped, or an int seed), then one key, not a batch."""
    key = as_key(key)
    if not jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        key = jax.random.wrap_key_data(key)
    if key.shape != ():
        raise InputError(f"`key` must be ONE PRNG key (shape ()); got shape {key.shape} (vmap over a batch).")
    return key


def _chain(work, allowed, start, key, num_sweeps):
    """One chain on one ``(R, C)`` cost matrix: ``num_sweeps`` systematic scans over the rows from
    the injective assignment ``start`` ``(R,)``. **Returns** the state after each sweep
    ``(num_sweeps, R)`` int32. (:func:`_chains` for one chain.)"""
    return _chains(work[None], allowed[None], start[None], key[None], num_sweeps)[0]


_BLOCK = 8  # columns a block of the draws' two-level cumulative sums (_chains)


def _chains(work, allowed, start, keys, num_sweeps, shared=None):
    """``T`` independent chains at once, chain ``t`` on the ``(R, C)`` cost matrix ``work[t]``
    from the injective assignment ``start[t]`` with the key ``keys[t]``: ``num_sweeps``
    systematic scans over the rows. **Returns** the state after each sweep ``(T, num_sweeps, R)``
    int32.

    ``shared`` (static; default ``C``): only columns ``0..shared−1`` are shared between rows;
    column ``shared + q`` of row ``r`` is a column of its own (a compacted diagonal block, see
    :func:`gibbs_assignments`' ``private_columns``), never held by another row.

    Row ``r``'s full conditional given the other rows ``θ_{−r}`` (VVH17 Sec. IV-B; for the
    δ-GLMB it is ``η_r(j)`` of the joint prediction–update restricted to the measurements the
    other candidates leave free) is ``P(θ_r = c | θ_{−r}) ∝ exp(−cost[r, c])`` over the columns
    ``c`` with a finite cost that no other row holds. The row's own column is always among them,
    so the chain never leaves the injective, finite assignments.

    Why batched by hand rather than ``vmap`` of one chain: the weights ``exp(−(cost − min_row))``
    are taken once, not at every draw, the cumulative sums are two small matrix products (with the
    batching, 19 → 15 ms a δ-GLMB scan at H = 128; the R·num_sweeps sequential row steps remain,
    each costing in proportion to its T·C width), and
    the rare draw whose free weights all underflow (free columns > 700 nats above the row's
    cheapest) is redone in log space under a ``lax.cond`` on ANY chain, which a vmapped chain
    would turn into both branches every time."""
    T, R, C = work.shape
    shared = C if shared is None else shared
    cols = jnp.arange(C)
    is_shared = cols < shared
    # Row-wise shift by the cheapest finite entry: the weights are ≤ 1 and the best is 1.
    lo = jnp.min(jnp.where(allowed, work, jnp.inf), axis=-1, keepdims=True)
    weights = jnp.where(allowed, jnp.exp(-(work - jnp.where(jnp.isfinite(lo), lo, 0.0))), 0.0)
    tiny = jnp.finfo(weights.dtype).tiny
    # How many rows hold each shared column: a row's "taken by the others" is this minus its own
    # (0 on the private columns, which only their row can hold).
    held = (start[:, :, None] == cols[None, None]) & is_shared[None, None]
    counts0 = jnp.sum(held, axis=1, dtype=jnp.int32)  # (T, C)

    # Cumulative sums in two levels: within blocks of _BLOCK columns, then the blocks' totals, each
    # a product with a small triangular matrix: T·C·(b + C/b) multiply-adds instead of the T·C² of
    # one (C, C) triangular product. In a loop of dependent draws (XLA:CPU) at C = 64: 7.7 against
    # 15.5 µs a draw for T = 64 chains, 20.5 against 53.4 µs for T = 256; XLA's own cumsum is no
    # faster than the one product (15.0, 49.6 µs).
    b = min(_BLOCK, C)
    nb = -(-C // b)
    within_upper = jnp.triu(jnp.ones((b, b), weights.dtype))
    before_upper = jnp.triu(jnp.ones((nb, nb), weights.dtype), 1)  # block i: the totals of blocks < i

    def cumulative(w):
        wb = jnp.pad(w, ((0, 0), (0, nb * b - C))).reshape(T, nb, b) @ within_upper
        return (wb + (wb[:, :, -1] @ before_upper)[:, :, None]).reshape(T, nb * b)[:, :C]

    def draw(w, u):
        # Inverse-CDF draw with one uniform per row (cheaper than C Gumbels on the CPU): the first
        # column with a weight whose cumulative weight exceeds u·total. Asking for a weight keeps
        # the draw on a free column even where the sums' rounding makes them non-monotone; past
        # every sum (rounding again) the last free column.
        cum = cumulative(w)
        hit = (cum > u[:, None] * cum[:, -1:]) & (w > 0)
        last = C - 1 - jnp.argmax((w > 0)[:, ::-1], axis=-1)
        return jnp.where(jnp.any(hit, axis=-1), jnp.argmax(hit, axis=-1), last).astype(jnp.int32)

    def row(r, carry):
        theta, counts, u = carry
        own = theta[:, r]
        mine = (cols[None] == own[:, None]) & is_shared[None]
        free = allowed[:, r] & (((counts - mine) == 0) | ~is_shared[None])
        w = jnp.where(free, weights[:, r], 0.0)
        underflow = jnp.sum(w, axis=-1) < tiny  # only the own column can keep it from being 0

        def exact(_):
            logits = jnp.where(free, -work[:, r], -jnp.inf)
            return jnp.where(free, jnp.exp(logits - jnp.max(logits, axis=-1, keepdims=True)), 0.0)

        w = jax.lax.cond(jnp.any(underflow), exact, lambda _: w, None)
        c = draw(w, u[:, r])
        counts = counts - mine + ((cols[None] == c[:, None]) & is_shared[None])
        return theta.at[:, r].set(c), counts, u

    def sweep(carry, t):
        theta, counts = carry
        u = jax.vmap(lambda k: jax.random.uniform(jax.random.fold_in(k, t), (R,), work.dtype))(keys)
        theta, counts, _ = jax.lax.fori_loop(0, R, row, (theta, counts, u))
        return (theta, counts), theta

    _, states = jax.lax.scan(sweep, (start, counts0), jnp.arange(num_sweeps))
    return jnp.swapaxes(states, 0, 1)


def _check_private(private_columns, cost, R: int) -> int:
    """``private_columns`` as a static int ``Q ≥ 0`` with ``Q·R ≤ C``; for a concrete ``cost``, every
    entry of the last ``Q·R`` columns off its row's own column must be non-finite."""
    Q = private_columns
    C = cost.shape[-1]
    if isinstance(Q, bool) or not isinstance(Q, int) or Q < 0 or Q * R > C:
        raise InputError(f"`private_columns` must be a static int >= 0 with private_columns * rows <= columns "
                         f"({R} rows, {C} columns); got {private_columns!r}.")
    if Q and is_concrete(cost):
        blocks = np.asarray(cost)[..., C - Q * R:].reshape(cost.shape[:-1] + (Q, R))
        off = ~np.eye(R, dtype=bool)[:, None, :]  # (R, 1, R): row r, any block, column ≠ r
        if np.any(np.isfinite(blocks) & off):
            raise InputError(f"`private_columns` = {Q}: the last {Q}·{R} columns of `cost` must be {Q} diagonal "
                             f"blocks (+inf off the diagonal); a finite entry was found off it.")
    return Q


def _check_exponent(weight_exponent) -> float:
    """``weight_exponent`` as a finite Python float ``≥ 0`` (it shapes nothing, but a negative one
    would send the chains to the LIGHTEST parents)."""
    if isinstance(weight_exponent, bool) or not isinstance(weight_exponent, (int, float)) \
            or not math.isfinite(weight_exponent) or weight_exponent < 0:
        raise InputError(f"`weight_exponent` must be a finite Python float >= 0; got {weight_exponent!r}.")
    return float(weight_exponent)


def _allocate(offsets, feasible, alpha, T):
    """The parent of each of ``T`` chains: stratified over the shares ``∝ exp(−α·offsets)`` of the
    feasible parents (``(T,)`` int32). Chain ``j`` takes the first parent whose normalised
    cumulative share exceeds ``(j + ½)/T``, so parent ``p`` gets ``T·share_p`` chains rounded
    up or down. With no feasible parent every chain goes to parent 0 (its samples are dropped)."""
    lo = jnp.min(jnp.where(feasible, offsets, jnp.inf))
    share = jnp.where(feasible, jnp.exp(-alpha * (offsets - jnp.where(jnp.isfinite(lo), lo, 0.0))), 0.0)
    cum = jnp.cumsum(share)
    u = (jnp.arange(T, dtype=cum.dtype) + 0.5) / T * cum[-1]
    p = jnp.searchsorted(cum, u, side="right")  # how many cumulative shares are ≤ u
    return jnp.where(cum[-1] > 0, jnp.minimum(p, offsets.shape[0] - 1), 0).astype(jnp.int32)


def gibbs_assignments(
    cost: Float[ArrayLike, "P R C"] | Float[ArrayLike, "R C"],
    k: int,
    *,
    key: Array,
    num_chains: int,
    num_sweeps: int,
    offsets: Float[ArrayLike, " P"] | None = None,
    valid_parents: Bool[ArrayLike, " P"] | None = None,
    weight_exponent: float = 0.5,
    private_columns: int = 0,
) -> KBestAssignments:
    r"""Up to ``k`` low-cost complete assignments over ``P`` cost matrices, by Gibbs sampling.

    Solutions are as in :func:`~jaxtrack.association.k_best_assignments`: a pair ``(p, θ)`` of a
    valid parent and an assignment of EVERY row of ``cost[p]`` to a distinct column with a finite
    entry, costing ``offsets[p] + Σ_r cost[p, r, θ_r]``. This function returns the ``k`` cheapest
    DISTINCT solutions among those it visited, ascending; a drop-in for Murty's ranking with the
    same result type, but not guaranteed to be the ``k`` best (it is, once the samples cover them).

    **Algorithm** (Vo, Vo & Hoang 2017, "An efficient implementation of the generalized labeled
    multi-Bernoulli filter", IEEE TSP 65(8), Sec. IV-B, the Gibbs sampler of the joint
    prediction–update; VVH17 below. Section cited; equation numbers were not checked against the
    published PDF):

    1. Each valid parent's optimal assignment (the Hungarian solve that also starts Murty's
       queue) is a sample and the start of its chains, so the best solution of every parent is
       always found, and every chain starts from a feasible state. The ``P·num_chains`` chains
       are shared over the feasible valid parents in proportion to ``w_p^weight_exponent``
       (``w_p = exp(−offsets[p])``; Allocation below).
    2. Each chain runs ``num_sweeps`` systematic scans over the rows; row ``r`` is redrawn from its
       full conditional ``∝ exp(−cost[p, r, c])`` over the finite columns ``c`` that no other row
       holds (VVH17 Sec. IV-B). The target distribution is ``π_p(θ) ∝ exp(−Σ_r cost[p, r, θ_r])``
       on the injective ``θ`` — for the δ-GLMB's costs ``−log η``, the posterior hypothesis
       weights. The state after each sweep is a sample.
    3. The ``P (1 + num_chains·num_sweeps)`` samples are sorted lexicographically by
       ``(parent, θ)`` to keep each distinct solution once, then the ``k`` cheapest are returned.

    **Allocation:** the budget is ``T = P·num_chains`` chains a call, whatever the number of
    valid parents, and parent ``p`` gets about ``T·w_p^α / Σ_q w_q^α`` of them (``α =
    weight_exponent``), by deterministic stratified selection: chain ``j`` goes to the parent
    whose cumulative share first exceeds ``(j + ½)/T``. ``α = ½`` (the default) is VVH17's
    allocation for the joint prediction–update (the samples of prior hypothesis ``h`` ``∝ √w_h``;
    Vo's MATLAB ``jointglmb`` and the labeledRFS port allocate so); ``α = 0``
    gives every valid parent the same number. Sharing ONE budget matters when few of the ``P``
    parent slots are valid (a δ-GLMB's first scans: one prior hypothesis out of ``H``): a fixed
    ``num_chains`` per slot would leave that hypothesis ``num_chains`` chains and waste the rest.
    Measured on Vo & Vo's benchmark (benchmarks/labelled_reference.py): with 2 chains per slot
    the δ-GLMB confirmed the first targets a scan after the reference (+13 m OSPA at scan 2);
    sharing removes that lag at the same cost. A parent whose share is below one chain may get
    none; it still contributes its best solution (step 1), and the weights enter again through
    the final ranking by total cost.

    **Mixing:** the chain changes one row at a time, so it reaches every assignment only when
    such moves connect them: true when every row has a column of its own with a finite cost (the
    δ-GLMB's "missed" and "absent" columns, a PMBM's miss column), false for a square permutation
    problem (there every chain stays at its start).

    **Complexity:** ``P`` Hungarian solves of ``R × C`` (``O(R² C)`` each) plus
    ``P·num_chains·num_sweeps·R`` draws of ``O(C)``, plus one sort of ``P (1 + num_chains·
    num_sweeps)`` keys of length ``R + 1``; memory ``O(P·num_chains·num_sweeps·R)``.

    **Arguments:**

    - ``cost``: ``(P, R, C)`` or ``(R, C)`` (then ``P = 1``), ``R ≤ C``, in units of ``−log``
      weight (the sampler draws ``∝ exp(−cost)``, so the scale matters, unlike Murty's);
      ``+inf`` (any non-finite entry) marks a forbidden pair.
    - ``k``: static Python int ``≥ 1``, the most solutions returned.
    - ``key``: a PRNG key (``jax.random.key`` or a legacy ``jax.random.PRNGKey``) or an int seed,
      as everywhere in jaxtrack.
    - ``num_chains``: static int ``≥ 1``, chains per parent slot on average (``P·num_chains`` in
      all, shared as above); ``num_sweeps``: static int ``≥ 1``,
      sweeps per chain (each a sample).
    - ``offsets``: ``(P,)``, each parent's additive cost (e.g. ``−log`` of its weight); default 0.
      A parent with a non-finite offset has no solution.
    - ``valid_parents``: ``(P,)`` bool; False parents are left out. Default: all True.
    - ``weight_exponent``: Python float ``≥ 0``, ``α`` of the allocation ``∝ w_p^α``; default ½
      (VVH17).
    - ``private_columns``: static int ``Q ≥ 0``, a statement about ``cost``'s layout: its last
      ``Q·R`` columns are ``Q`` diagonal blocks (column ``C − Q·R + q·R + r`` is row ``r``'s own,
      every other row's entry there is ``+inf``), as the "missed" and "absent" blocks of VVH17's
      ``P × (M + 2P)`` cost (``Q = 2``) or a missed-detection block (``Q = 1``). The chains then
      redraw a row over its ``C − Q·R + Q`` possible columns, not all ``C`` (the same draws: the
      columns keep their order), and only the first ``C − Q·R`` can conflict. Default 0. A
      concrete ``cost`` that breaks the layout raises an :class:`~jaxtrack.InputError`.

    **Returns:** a :class:`~jaxtrack.association.KBestAssignments` with ``k`` rows, the distinct
    solutions found in ascending ``total_cost``, then invalid rows (parent −1, columns −1,
    ``+inf``). ``total_cost`` is differentiable in ``cost`` and ``offsets`` as Murty's.

    **Raises:** :class:`~jaxtrack.InputError` naming the argument (shapes, counts, key).

    Jittable (``k``, ``num_chains``, ``num_sweeps`` static) and vmappable over cost tensors and keys.

    Example (two rows, two shared columns and a miss column per row; the three best):

    >>> import jax, jax.numpy as jnp
    >>> inf = jnp.inf
    >>> cost = jnp.array([[0.0, 1.0, 2.0, inf], [1.0, 0.5, inf, 3.0]])
    >>> sol = gibbs_assignments(cost, 3, key=jax.random.key(0), num_chains=4, num_sweeps=4)
    >>> sol.row_to_col.tolist(), sol.total_cost.tolist()
    ([[0, 1], [1, 0], [2, 1]], [0.5, 2.0, 2.5])
    """
    cost, offsets, valid_parents = check_problem(cost, offsets, valid_parents)
    P, R, _ = cost.shape
    check_count("k", k)
    check_count("num_chains", num_chains)
    check_count("num_sweeps", num_sweeps)
    key = _check_key(key)
    alpha = _check_exponent(weight_exponent)
    C = cost.shape[-1]
    Q = _check_private(private_columns, cost, R)
    S0 = C - Q * R  # the shared columns

    # Sampling is discrete: it runs on stopped values; the gradient comes from the gather below.
    work = jax.lax.stop_gradient(cost)
    finite = jnp.isfinite(work)
    start, _, feasible = jax.vmap(_solve)(work, finite, jax.lax.stop_gradient(offsets))
    feasible = feasible & valid_parents
    # An infeasible parent keeps a dummy injective start; its sample is dropped below.
    start = jnp.where(feasible[:, None], start, jnp.arange(R, dtype=jnp.int32)[None]).astype(jnp.int32)
    T = P * num_chains
    chain_parent = _allocate(jax.lax.stop_gradient(offsets), feasible, alpha, T)
    rows = jnp.arange(R)
    if Q:  # each private block compacted to one column a row: (P, R, S0 + Q)
        own = S0 + jnp.arange(Q)[None, :] * R + rows[:, None]  # (R, Q): row r's private columns
        work_c = jnp.concatenate([work[..., :S0], jnp.take_along_axis(work, own[None], axis=2)], axis=2)
        start_c = jnp.where(start < S0, start, S0 + (start - S0) // R)
    else:
        work_c, start_c = work, start
    states = _chains(work_c[chain_parent], jnp.isfinite(work_c)[chain_parent], start_c[chain_parent],
                     jax.random.split(key, T), num_sweeps, S0)  # (T, num_sweeps, R)
    if Q:  # back to the full columns
        states = jnp.where(states < S0, states, S0 + (states - S0) * R + rows[None, None, :])
    theta = jnp.concatenate([start, states.reshape(T * num_sweeps, R)], axis=0)
    S = P + T * num_sweeps
    parent = jnp.concatenate([jnp.arange(P, dtype=jnp.int32), jnp.repeat(chain_parent, num_sweeps)])
    ok = feasible[parent]

    # Distinct solutions: one sort by (parent, θ) with θ packed losslessly into int32 words
    # (⌈log2 C⌉ bits a row: 5 keys instead of 21 at R = 20, C = 64; 2.3 → 0.6 ms for 2,176
    # samples); equal solutions end up adjacent, and an entry is kept when it differs from its
    # predecessor in the sorted order.
    bits = max(1, (C - 1).bit_length())
    per = 31 // bits  # rows a word
    words = -(-R // per)
    padded = jnp.pad(theta, ((0, 0), (0, words * per - R))).reshape(S, words, per)
    packed = jnp.sum(padded << (bits * jnp.arange(per, dtype=jnp.int32))[None, None, :], axis=-1, dtype=jnp.int32)
    keys_sorted = jax.lax.sort((parent, *packed.T, jnp.arange(S)), num_keys=1 + words)
    by_key = jnp.stack(keys_sorted[:-1], axis=1)  # (S, 1 + words)
    first = jnp.concatenate([jnp.ones((1,), bool), jnp.any(by_key[1:] != by_key[:-1], axis=1)])
    distinct = jnp.zeros((S,), bool).at[keys_sorted[-1]].set(first)
    keep = ok & distinct

    total = offsets[parent] + jnp.sum(cost[parent[:, None], rows[None, :], theta], axis=1)
    keep = keep & jnp.isfinite(jax.lax.stop_gradient(total))
    if k > S:  # fewer samples than asked: pad with invalid entries (static shapes)
        pad = k - S
        theta = jnp.concatenate([theta, jnp.zeros((pad, R), jnp.int32)])
        parent = jnp.concatenate([parent, jnp.zeros((pad,), jnp.int32)])
        total = jnp.concatenate([total, jnp.full((pad,), jnp.inf, total.dtype)])
        keep = jnp.concatenate([keep, jnp.zeros((pad,), bool)])
    total = jnp.where(keep, total, jnp.inf)
    order = jnp.argsort(jax.lax.stop_gradient(total), stable=True)[:k]
    valid = keep[order]
    return KBestAssignments(
        parent=jnp.where(valid, parent[order], -1),
        row_to_col=jnp.where(valid[:, None], theta[order], -1),
        total_cost=total[order],
        valid=valid,
        num_solutions=jnp.sum(valid, dtype=jnp.int32),
    )

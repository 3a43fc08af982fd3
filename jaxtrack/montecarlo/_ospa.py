"""OSPA and GOSPA distances between two finite sets of points, on padded sets inside ``jit``.

A set is a padded array and a mask: ``points`` ``(N, d)`` with ``valid`` ``(N,)``; padded rows
may hold anything (NaN included) and influence neither the value nor its gradient. A VALID point
with a NaN or infinite coordinate has no distance to anything: the metric is then NaN. Both metrics
solve one optimal assignment with optax's lax-only Hungarian solver
(``optax.assignment.hungarian_algorithm``) on a square cost matrix of static size
``S = max(N, K)``, so they compile once per padded shape and ``jax.vmap`` over runs and steps.

Conventions follow Stone Soup (``stonesoup.metricgenerator.ospametric``), which the tests use
as an oracle: GOSPA with ``α = 2`` reports its localisation, missed and false parts in the
p-th power, ``distance**p = localisation + missed + false`` (Stone Soup's
``GOSPAMetric.compute_gospa_metric``; García-Fernández's ``GOSPA.m``), and a pair at distance
``≥ c`` counts as one missed and one false point, not as an assignment.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._validation import InputError, is_concrete


class GOSPA(eqx.Module):
    """The GOSPA distance (``α = 2``) and its decomposition.

    **Fields** (all shape ``()``; under ``jax.vmap`` each gains the batch axes):

    - ``distance``: ``d_p^(c,2)(X, Y)``, in the units of the points (e.g. m).
    - ``localisation``: ``Σ_{(i,j)∈γ*} d(x_i, y_j)^p`` over the optimal assignment's pairs
      (each at distance ``< c``), units to the power ``p``.
    - ``missed``: ``(c^p/2)·num_missed``; ``false``: ``(c^p/2)·num_false`` (units to the ``p``).
      ``distance**p = localisation + missed + false``.
    - ``num_assigned``, ``num_missed``, ``num_false``: integer counts; ``num_missed = |X| −
      num_assigned``, ``num_false = |Y| − num_assigned``. A pair the solver matches at distance
      ``≥ c`` is counted as one missed and one false point (as Stone Soup does: it costs
      ``c^p``, the same as leaving both out).
    - ``assignment``: ``(N,)`` int, the estimate each true point is assigned to in ``γ*`` (−1
      when missed or padding): what track-level scores (switches, false tracks) are built on.
    """

    distance: Float[Array, ""]
    localisation: Float[Array, ""]
    missed: Float[Array, ""]
    false: Float[Array, ""]
    num_assigned: Int[Array, ""]
    num_missed: Int[Array, ""]
    num_false: Int[Array, ""]
    assignment: Int[Array, " N"]


class OSPA(eqx.Module):
    r"""The OSPA distance and its localisation and cardinality components.

    **Fields** (all shape ``()``, in the units of the points; under ``jax.vmap`` each gains the
    batch axes). With ``n = max(|X|, |Y|)``, ``m = min(|X|, |Y|)`` and ``π*`` the optimal
    permutation of Eq. (3) (Schuhmacher, Vo & Vo 2008):

    - ``distance``: $\bar d_p^{(c)}(X, Y) = \Big(\frac{1}{n}\big(\sum_{i≤m} d^{(c)}(x_i, y_{π^*(i)})^p +
      c^p (n − m)\big)\Big)^{1/p}$.
    - ``localisation``: $\big(\frac{1}{n} \sum_{i≤m} d^{(c)}(x_i, y_{π^*(i)})^p\big)^{1/p}$, with the cut-off
      distance $d^{(c)} = \min(d, c)$ (a pair at ``≥ c`` contributes ``c^p`` here).
    - ``cardinality``: $\big(c^p (n − m) / n\big)^{1/p}$.

    These are the paper's localisation and cardinality components, p-th ROOTS (unlike
    :class:`GOSPA`'s parts, which are p-th powers): ``distance**p = localisation**p +
    cardinality**p``. Stone Soup's ``OSPAMetric`` reports the distance only. All three are 0 when
    both sets are empty.
    """

    distance: Float[Array, ""]
    localisation: Float[Array, ""]
    cardinality: Float[Array, ""]


def _root(x, p):
    """``x^{1/p}`` for ``x ≥ 0``, with a finite (zero) gradient at ``x = 0`` (double ``where``:
    the derivative ``x^{1/p − 1}/p`` is infinite there for ``p > 1``); NaN stays NaN."""
    zero = x == 0
    safe = jnp.where(zero, 1.0, x)
    return jnp.where(zero, 0.0, safe ** (1.0 / p))


def _check(truth, truth_valid, estimates, estimates_valid, cutoff, order):
    """Shapes always; the values of ``cutoff`` and ``order``: ``InputError`` when concrete, an
    ``equinox.error_if`` naming the argument when traced."""
    truth = jnp.asarray(truth)
    estimates = jnp.asarray(estimates)
    truth_valid = jnp.asarray(truth_valid)
    estimates_valid = jnp.asarray(estimates_valid)
    if truth.ndim != 2:
        raise InputError(f"`truth` must have shape (N, d); got shape {truth.shape}.")
    if estimates.ndim != 2:
        raise InputError(f"`estimates` must have shape (K, d); got shape {estimates.shape}.")
    if estimates.shape[1] != truth.shape[1]:
        raise InputError(
            f"`estimates` {estimates.shape} and `truth` {truth.shape} must have the same last "
            f"dimension d (the points' dimension)."
        )
    for name, mask, points in (("truth_valid", truth_valid, truth), ("estimates_valid", estimates_valid, estimates)):
        if mask.shape != points.shape[:1]:
            raise InputError(f"`{name}` must have shape ({points.shape[0]},); got shape {mask.shape}.")
        if mask.dtype != jnp.bool_:
            raise InputError(f"`{name}` must be a boolean mask; got dtype {mask.dtype}.")
    dtype = jnp.result_type(truth, estimates)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    for name, value, ok, expected in (
        ("cutoff", cutoff, lambda v: (v > 0) & (v < np.inf), "a finite c > 0"),
        ("order", order, lambda v: (v >= 1) & (v < np.inf), "a finite p ≥ 1"),
    ):
        if is_concrete(value):
            v = np.asarray(value, dtype=np.float64)
            if v.shape != () or not bool(ok(v)):
                raise InputError(f"`{name}` must be {expected} (a scalar); got {value!r}.")
    # A traced cutoff/order that the concrete check would reject is a run-time error naming it.
    # Not a NaN metric (_validation.nan_where_traced): c and p are the caller's settings, the same
    # for every run of a batch, not a per-run failure that a `throw=False` caller reads per run;
    # a NaN distance in every run would only say "something is wrong", not what.
    # Concreteness of the caller's value, not of the converted array: under `jit`, `jnp.asarray`
    # of a Python float is a tracer too, and an `error_if` (a host callback) on an already checked
    # constant would make every program that scores GOSPA (the multi-target Monte Carlo's blocks)
    # ineligible for JAX's persistent compilation cache.
    c, p = jnp.asarray(cutoff, dtype), jnp.asarray(order, dtype)
    if not is_concrete(cutoff):
        c = eqx.error_if(c, ~((c > 0) & (c < jnp.inf)), "gospa/ospa: `cutoff` must be a finite c > 0.")
    if not is_concrete(order):
        p = eqx.error_if(p, ~((p >= 1) & (p < jnp.inf)), "gospa/ospa: `order` must be a finite p >= 1.")
    return truth.astype(dtype), truth_valid, estimates.astype(dtype), estimates_valid, c, p


def _assign(truth, truth_valid, estimates, estimates_valid, c, p, unmatched):
    """Solve the padded square assignment; return what both metrics need.

    The cost matrix is ``S × S``, ``S = max(N, K)``, rows truth, columns estimates (both padded
    to ``S`` with invalid rows):

    - valid–valid: ``min(d, c)^p``;
    - valid–padding (a point left out): ``unmatched`` (``c^p/2`` for GOSPA, ``c^p`` for OSPA);
    - padding–padding: 0.

    Every entry is finite (the solver is never given inf or NaN). **Returns:** ``(within, dp,
    num_truth, num_estimates, assignment)`` where ``within`` ``(S,)`` marks the solver's valid pairs at
    distance ``< c``, ``dp`` ``(S,)`` their ``d^p`` (0 elsewhere; all NaN when a valid point has a
    NaN or infinite coordinate, so that every metric built on it is NaN), and the ``(N,)``
    estimate index of each true point (−1: none).
    """
    n_truth, n_est = truth.shape[0], estimates.shape[0]
    size = max(n_truth, n_est)

    def pad(points, valid):
        # Garbage rows become 0 BEFORE any arithmetic, so NaN there reaches neither the value
        # nor (through the `where`) the gradient.
        points = jnp.where(valid[:, None], points, jnp.zeros((), points.dtype))
        extra = size - points.shape[0]
        return jnp.pad(points, ((0, extra), (0, 0))), jnp.pad(valid, (0, extra))

    x, xv = pad(truth, truth_valid)
    y, yv = pad(estimates, estimates_valid)
    # A valid point with a NaN (or infinite) coordinate: its distances are NaN (or inf − inf),
    # `dist < c` is False, and it would pass as a missed/false point at the finite c^p/2.
    # Padded rows are 0 here, so only valid points count.
    nonfinite_point = ~(jnp.all(jnp.isfinite(x)) & jnp.all(jnp.isfinite(y)))
    sq = jnp.sum((x[:, None, :] - y[None, :, :]) ** 2, axis=-1)  # (S, S)
    # Euclidean distance and its p-th power with finite gradients at coincident points.
    pos = sq > 0
    safe = jnp.where(pos, sq, 1.0)
    dist = jnp.where(pos, jnp.sqrt(safe), 0.0)
    dist_p = jnp.where(pos, safe ** (p / 2), 0.0)
    both = xv[:, None] & yv[None, :]
    within = both & (dist < c)  # strict, as Stone Soup's compute_cost_matrix (`distance < c`)
    cp = c**p
    cost = jnp.where(within, dist_p, cp)
    cost = jnp.where(both, cost, jnp.where(xv[:, None] ^ yv[None, :], unmatched, 0.0))
    # The solver only picks the permutation; values are recomputed from the differentiable
    # terms, so the gradient is that of the optimal value (envelope theorem). A NaN cutoff or a
    # NaN in a VALID row is replaced here only to keep the solver's loops well defined; the
    # metric computed below stays NaN.
    solver_cost = jax.lax.stop_gradient(cost)
    solver_cost = jnp.where(jnp.isfinite(solver_cost), solver_cost, 0.0)
    if size == 0:
        rows = cols = jnp.zeros((0,), jnp.int32)
    else:
        # (row, column) pairs of a full matching (for a square matrix optax returns the row of
        # each column, in column order).
        rows, cols = optax.assignment.hungarian_algorithm(solver_cost)
    matched = within[rows, cols]
    dp = jnp.where(matched, dist_p[rows, cols], 0.0)
    dp = jnp.where(nonfinite_point, jnp.nan, dp)
    # The estimate of each true point (rows index truth, columns estimates; padding is never
    # `within`, so padded columns never appear).
    assignment = jnp.full((size,), -1, jnp.int32).at[rows].set(
        jnp.where(matched, cols, -1).astype(jnp.int32)
    )[:n_truth]
    return matched, dp, jnp.sum(xv), jnp.sum(yv), assignment


def gospa(
    truth: Float[ArrayLike, "N d"],
    truth_valid: Bool[ArrayLike, " N"],
    estimates: Float[ArrayLike, "K d"],
    estimates_valid: Bool[ArrayLike, " K"],
    *,
    cutoff: float | Float[ArrayLike, ""],
    order: float | Float[ArrayLike, ""] = 2,
    alpha: float = 2,
) -> GOSPA:
    r"""The GOSPA distance between a true and an estimated set of points, with its parts.

    Rahmathullah, García-Fernández & Svensson (2017), Eq. (1), with ``α = 2``; for ``|X| ≤ |Y|``

    .. math::

        d_p^{(c,2)}(X, Y) = \Bigl(\min_{π∈Π_{|Y|}} \sum_{i=1}^{|X|} d^{(c)}(x_i, y_{π(i)})^p
                          + \tfrac{c^p}{2}(|Y| − |X|)\Bigr)^{1/p},

    ``d^{(c)} = min(d, c)``, ``d`` Euclidean. Proposition 1 writes it over assignment sets
    ``γ`` of pairs at distance ``< c``: ``(Σ_{(i,j)∈γ} d(x_i, y_j)^p + (c^p/2)(|X| + |Y| −
    2|γ|))^{1/p}``, i.e. localisation plus ``c^p/2`` per missed and per false point.

    **How.** One ``S × S`` assignment, ``S = max(N, K)`` (static): valid pairs cost
    ``min(d, c)^p``, a valid point against a padded slot ``c^p/2`` (Eq. (1)'s ``c^p/α`` per
    unassigned point), padding against padding 0. A pair at ``≥ c`` costs ``c^p``, exactly what
    leaving both points out costs, so the optimum over full matchings equals the minimum over
    ``γ`` in Proposition 1, and there are always enough padded slots (``S − |Y| ≥ |X| − |Y|``).
    The value, the parts and the counts are recomputed from the solver's permutation with
    pairs at ``≥ c`` counted as one missed and one false point, so they do not depend on how
    the solver breaks ties between such equal-cost choices (generic configurations have a
    unique optimal ``γ``; for exactly tied ``γ`` the split into parts, but not the distance,
    may follow the solver's choice, as it does in Stone Soup).

    Jittable and vmappable (over runs and steps); the solver sees ``stop_gradient`` of the
    costs, and the gradient is that of the optimal value (finite; at coincident points the
    ``d^p`` term has a zero gradient).

    **Arguments:**

    - ``truth``: ``X``, ``(N, d)`` (e.g. positions in m); ``truth_valid``: bool ``(N,)``, which
      rows are points. Invalid rows may hold anything, NaN included; a valid row with a NaN or
      infinite coordinate makes ``distance`` and ``localisation`` (hence the metric) NaN (the
      counts and ``assignment`` then treat that point as unassignable and mean nothing).
    - ``estimates``: ``Y``, ``(K, d)``, same units; ``estimates_valid``: bool ``(K,)``.
    - ``cutoff``: ``c > 0``, finite, in the units of the points.
    - ``order``: ``p ≥ 1``, finite (default 2).
    - ``alpha``: must be 2 (the only value whose parts split into missed and false points).

    **Returns:** a :class:`GOSPA` (distance, parts in the p-th power, counts).

    **Raises:** ``InputError`` naming ``alpha`` if it is not 2, ``cutoff``/``order`` outside
    their ranges (when concrete), ``estimates`` whose last dimension differs from ``truth``'s,
    or a mask of the wrong shape or not boolean. A traced ``cutoff``/``order`` out of range
    (under ``jit``/``vmap``/``grad``) raises at run time through ``equinox.error_if``, with a
    message naming it (``EquinoxRuntimeError`` or the runtime error ``jax.jit`` surfaces it as):
    they are settings shared by every run, so a NaN metric would hide which one is wrong.

    ```bibtex
    @inproceedings{rahmathullah2017gospa,
      author={Rahmathullah, Abu Sajana and Garc{\'i}a-Fern{\'a}ndez, {\'A}ngel F. and
              Svensson, Lennart},
      title={Generalized optimal sub-pattern assignment metric},
      booktitle={20th International Conference on Information Fusion (FUSION)},
      year={2017}, pages={1--8}}
    ```

    >>> import jax.numpy as jnp
    >>> from jaxtrack.montecarlo._ospa import gospa
    >>> x = jnp.array([[0.0, 0.0], [10.0, 0.0]]); y = jnp.array([[0.0, 1.0], [0.0, 0.0]])
    >>> r = gospa(x, jnp.array([True, True]), y, jnp.array([True, False]), cutoff=5.0)
    >>> float(r.localisation), float(r.missed), float(r.false), int(r.num_missed)
    (1.0, 12.5, 0.0, 1)
    """
    if not is_concrete(alpha) or float(alpha) != 2.0:
        raise InputError(f"`alpha` must be 2 (the only GOSPA α supported); got {alpha!r}.")
    truth, truth_valid, estimates, estimates_valid, c, p = _check(
        truth, truth_valid, estimates, estimates_valid, cutoff, order
    )
    half = c**p / 2
    matched, dp, n_truth, n_est, assignment = _assign(
        truth, truth_valid, estimates, estimates_valid, c, p, half
    )
    num_assigned = jnp.sum(matched)
    num_missed = n_truth - num_assigned
    num_false = n_est - num_assigned
    localisation = jnp.sum(dp)
    missed = half * num_missed
    false = half * num_false
    return GOSPA(
        distance=_root(localisation + missed + false, p),
        localisation=localisation,
        missed=missed,
        false=false,
        num_assigned=num_assigned,
        num_missed=num_missed,
        num_false=num_false,
        assignment=assignment,
    )


def ospa(
    truth: Float[ArrayLike, "N d"],
    truth_valid: Bool[ArrayLike, " N"],
    estimates: Float[ArrayLike, "K d"],
    estimates_valid: Bool[ArrayLike, " K"],
    *,
    cutoff: float | Float[ArrayLike, ""],
    order: float | Float[ArrayLike, ""] = 2,
) -> OSPA:
    r"""The OSPA distance between a true and an estimated set of points, with its components.

    Schuhmacher, Vo & Vo (2008), Eq. (3); for ``m = |X| ≤ |Y| = n``

    .. math::

        \bar d_p^{(c)}(X, Y) = \Bigl(\frac1n \Bigl(\min_{π∈Π_n} \sum_{i=1}^{m}
                               d^{(c)}(x_i, y_{π(i)})^p + c^p (n − m)\Bigr)\Bigr)^{1/p},

    ``d^{(c)} = min(d, c)``, ``d`` Euclidean, and ``\bar d = 0`` when both sets are empty (the
    paper's convention; Stone Soup's ``compute_OSPA_distance`` sets 0 there too, in a branch it
    cannot reach because it needs a timestamp from some state).

    **How.** Stone Soup's square matrix (``compute_cost_matrix(complete=True)``): an ``S × S``
    assignment, ``S = max(N, K)``, valid pairs ``min(d, c)^p``, a valid point against a padded
    slot ``c^p``, padding against padding 0. Its optimum is the bracket above. The permutation
    minimises the sum of ``d^(c)``'s p-th POWERS, as Eq. (3) does; Stone Soup 1.9.1 minimises
    the sum of ``d^(c)`` and then takes the p-th powers, which for ``p ≠ 1`` can give a larger
    value than Eq. (3) (the tests compare with it at ``p = 1`` and with an exact SciPy solution
    at ``p = 2``). The value depends only on the optimal cost, not on the solver's tie-breaking.

    Jittable and vmappable; gradients as :func:`gospa`.

    **Arguments:** as :func:`gospa` (``truth``, ``truth_valid``, ``estimates``,
    ``estimates_valid``, ``cutoff`` ``c > 0``, ``order`` ``p ≥ 1`` finite, default 2).

    **Returns:** an :class:`OSPA` (distance, localisation and cardinality components, p-th
    roots, in the units of the points). A valid point with a NaN or infinite coordinate makes
    ``distance`` and ``localisation`` NaN (``cardinality`` depends on the counts only).

    **Raises:** ``InputError`` as :func:`gospa` (without ``alpha``); a traced ``cutoff``/``order``
    out of range raises at run time as in :func:`gospa`.

    ```bibtex
    @article{schuhmacher2008ospa,
      author={Schuhmacher, Dominic and Vo, Ba-Tuong and Vo, Ba-Ngu},
      title={A Consistent Metric for Performance Evaluation of Multi-Object Filters},
      journal={IEEE Transactions on Signal Processing},
      year={2008}, volume={56}, number={8}, pages={3447--3457}}
    ```

    >>> import jax.numpy as jnp
    >>> from jaxtrack.montecarlo._ospa import ospa
    >>> x = jnp.array([[0.0, 0.0], [10.0, 0.0]]); y = jnp.array([[0.0, 1.0]])
    >>> r = ospa(x, jnp.array([True, True]), y, jnp.array([True]), cutoff=5.0, order=1)
    >>> float(r.distance), float(r.localisation), float(r.cardinality)
    (3.0, 0.5, 2.5)
    """
    truth, truth_valid, estimates, estimates_valid, c, p = _check(
        truth, truth_valid, estimates, estimates_valid, cutoff, order
    )
    cp = c**p
    matched, dp, n_truth, n_est, _ = _assign(truth, truth_valid, estimates, estimates_valid, c, p, cp)
    n = jnp.maximum(n_truth, n_est)
    m = jnp.minimum(n_truth, n_est)
    # The optimum pairs min(|X|, |Y|) valid points (a cut-off pair, c^p, is cheaper than two
    # points left out, 2c^p); those of them at ≥ c enter the localisation sum at c^p.
    loc_sum = jnp.sum(dp) + cp * (m - jnp.sum(matched))
    card_sum = cp * (n - m)
    inv_n = jnp.where(n > 0, 1.0 / jnp.maximum(n, 1), 0.0)  # both empty: everything is 0
    return OSPA(
        distance=_root((loc_sum + card_sum) * inv_n, p),
        localisation=_root(loc_sum * inv_n, p),
        cardinality=_root(card_sum * inv_n, p),
    )

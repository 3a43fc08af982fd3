"""Murty's k-best assignments (``k_best_assignments``) against independent references.

Oracles: brute-force enumeration of every complete assignment (``itertools.permutations``) of
every valid parent, and ``scipy.optimize.linear_sum_assignment`` for ``k = 1``. Random cases come
from ``np.random.default_rng(seed)``. Few compilations: the small random problems of every size
(``R ≤ 3``, ``C ≤ 5``, ``P ≤ 3``) are embedded, with the same solutions, in one padded
``(3, 3, 7)`` shape (see ``_embed``) and run as one vmapped batch; a few true shapes check the
unpadded code paths.
"""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize

from jaxtrack import InputError
from jaxtrack.association import KBestAssignments, k_best_assignments

_kbest = jax.jit(jax.vmap(k_best_assignments, in_axes=(0, None, 0, 0)), static_argnums=1)  # batched
_kbest_2d = jax.jit(jax.vmap(k_best_assignments, in_axes=(0, None)), static_argnums=1)  # (R, C) inputs
PADDED = (3, 3, 7)  # (P, R, C) of the embedded problems
K = 10
PAD_COLS = 5  # columns 5, 6 of the padded shape belong to the dummy rows


def _brute_force(cost, offsets, valid_parents):
    """Every solution ``(total, parent, columns)`` of the valid parents, ascending."""
    _, R, C = cost.shape
    out = []
    for p in np.flatnonzero(valid_parents):
        for cols in itertools.permutations(range(C), R):
            entries = cost[p, np.arange(R), list(cols)]
            if np.all(np.isfinite(entries)):
                out.append((offsets[p] + entries.sum(), int(p), cols))
    return sorted(out, key=lambda s: s[0])


def _check_against_brute_force(res, cost, offsets, valid_parents, k, rows=None, tol=1e-12):
    """One result (numpy fields) against the brute-force ranking of the real problem.

    ``rows``: how many leading rows of the result are the real problem's (the rest are dummy
    rows of the embedding, checked by the caller).
    """
    P, R, C = cost.shape
    ref = _brute_force(cost, offsets, valid_parents)
    n = min(k, len(ref))
    assert int(res.num_solutions) == n
    assert res.valid.tolist() == [True] * n + [False] * (k - n)
    assert np.all(res.parent[n:] == -1) and np.all(res.row_to_col[n:] == -1)
    assert np.all(res.total_cost[n:] == np.inf)
    totals = res.total_cost[:n]
    assert np.all(np.diff(totals) >= 0.0)
    np.testing.assert_allclose(totals, [s[0] for s in ref[:n]], rtol=0, atol=tol)
    got = set()
    for i in range(n):
        p, cols = int(res.parent[i]), tuple(int(c) for c in res.row_to_col[i, :R])
        assert 0 <= p < P and valid_parents[p]
        assert len(set(cols)) == R and all(0 <= c < C for c in cols)  # a complete assignment
        entries = cost[p, np.arange(R), list(cols)]
        assert np.all(np.isfinite(entries))  # of allowed pairs
        assert abs(offsets[p] + entries.sum() - totals[i]) <= tol  # its own cost
        got.add((p, cols))
    assert len(got) == n  # each solution once
    # The same set up to ties at the k-th cost: everything strictly cheaper than the k-th is in.
    ref_set = {(p, cols) for _, p, cols in ref}
    assert got <= ref_set
    if n:
        kth = totals[-1]
        assert {(p, cols) for t, p, cols in ref if t < kth - 1e-9} <= got
    return len(ref)


def _embed(cost, offsets, valid_parents):
    """A (P ≤ 3, R ≤ 3, C ≤ 5) problem in the padded (3, 3, 7) shape, with the same solutions.

    Extra columns are +inf for the real rows; each extra row r ≥ R (a dummy) may only take its
    own column ``5 + r − R`` at cost 0; extra parents are invalid and hold finite, attractive
    garbage (−50) that must never be used.
    """
    P, R, C = cost.shape
    out = np.full(PADDED, -50.0)
    out[:P] = np.inf
    out[:P, :R, :C] = cost
    for j, r in enumerate(range(R, PADDED[1])):
        out[:P, r, PAD_COLS + j] = 0.0
    off = np.full(PADDED[0], -50.0)
    off[:P] = offsets
    valid = np.zeros(PADDED[0], bool)
    valid[:P] = valid_parents
    return out, off, valid


def _random_problem(rng, kind):
    R = int(rng.integers(1, 4))
    C = int(rng.integers(R, 6))
    P = int(rng.choice([1, 3]))
    if kind == "integer":  # values 0..2: many ties, many equal totals
        cost = rng.integers(0, 3, (P, R, C)).astype(float)
        offsets = rng.integers(0, 2, P).astype(float)
    else:
        cost = rng.uniform(-5.0, 10.0, (P, R, C))
        offsets = rng.uniform(0.0, 6.0, P)
    cost = np.where(rng.random((P, R, C)) < 0.2, np.inf, cost)  # ~20% forbidden pairs
    if rng.random() < 0.05:  # a row with no allowed pair in any parent: no solution at all
        cost[:, rng.integers(R)] = np.inf
    valid = rng.random(P) < 0.8 if P > 1 else np.ones(1, bool)
    return cost, offsets, valid


def _numpy(res, b):
    return jax.tree.map(lambda x: np.asarray(x[b]), res)


@pytest.mark.parametrize("kind", ["uniform", "integer"])
def test_k_best_equals_brute_force_embedded(kind):
    rng = np.random.default_rng(20261201 if kind == "uniform" else 20261202)
    problems = [_random_problem(rng, kind) for _ in range(150)]
    padded = [_embed(*pr) for pr in problems]
    cost, offsets, valid = (jnp.asarray(np.stack(x)) for x in zip(*padded))
    res = _kbest(cost, K, offsets, valid)
    assert isinstance(res, KBestAssignments) and res.row_to_col.shape == (150, K, PADDED[1])
    counts = []
    for b, (cost, offsets, valid) in enumerate(problems):
        r = _numpy(res, b)
        counts.append(_check_against_brute_force(r, cost, offsets, valid, K))
        R = cost.shape[1]
        n = int(r.num_solutions)
        # The dummy rows sit on their own columns.
        for j, row in enumerate(range(R, PADDED[1])):
            assert np.all(r.row_to_col[:n, row] == PAD_COLS + j)
    counts = np.array(counts)
    # Every regime is exercised: no solution, fewer than k, more than k.
    assert np.sum(counts == 0) >= 5 and np.sum((counts > 0) & (counts < K)) >= 20 and np.sum(counts > K) >= 20


# (1, 3) and (3, 2, 2): k above the number of solutions; (3, 3, 4) with k = 3: the queue (up to
# P − 1 + R = 5 entries after the first pop) is truncated to k, so its capacity is exercised.
@pytest.mark.parametrize("shape, k, fewer_than_k", [((1, 3), 4, True), ((3, 2, 2), 8, True), ((3, 3, 4), 3, False)])
def test_k_best_equals_brute_force_true_shapes(shape, k, fewer_than_k):
    rng = np.random.default_rng(20261203 + len(shape) + k)
    n = 20
    cost = np.where(rng.random((n,) + shape) < 0.2, np.inf, rng.uniform(-5.0, 10.0, (n,) + shape))
    if len(shape) == 2:  # an (R, C) input: P = 1, no offsets
        res = _kbest_2d(jnp.asarray(cost), k)
        cost, offsets, valid = cost[:, None], np.zeros((n, 1)), np.ones((n, 1), bool)
    else:
        offsets = rng.uniform(0.0, 6.0, (n, shape[0]))
        valid = rng.random((n, shape[0])) < 0.8
        res = _kbest(jnp.asarray(cost), k, jnp.asarray(offsets), jnp.asarray(valid))
    counts = [_check_against_brute_force(_numpy(res, b), cost[b], offsets[b], valid[b], k) for b in range(n)]
    assert (min(counts) < k) == fewer_than_k  # some cases have fewer solutions than k, or none


@pytest.mark.parametrize("shape", [(4, 4), (3, 5)])
def test_k_equals_one_is_scipy(shape):
    rng = np.random.default_rng(20261204 + shape[1])
    cost = rng.uniform(-5.0, 10.0, (30,) + shape)
    cost[::3, 0, 0] = np.inf  # still feasible: SciPy accepts it
    res = _kbest_2d(jnp.asarray(cost), 1)
    for b in range(len(cost)):
        rows, cols = scipy.optimize.linear_sum_assignment(cost[b])
        assert bool(res.valid[b, 0]) and int(res.parent[b, 0]) == 0
        assert abs(float(res.total_cost[b, 0]) - cost[b][rows, cols].sum()) <= 1e-12
        assert np.asarray(res.row_to_col[b, 0]).tolist() == cols.tolist()  # continuous costs: unique


def test_infeasible_and_all_ties():
    inf = np.inf
    infeasible = np.zeros(PADDED)
    infeasible[:, 1, :] = inf  # a row of all +inf in every parent: no solution at all
    no_parent = np.zeros(PADDED)  # feasible, but no valid parent
    ties = np.zeros(PADDED)  # every complete assignment of every parent costs 0
    one_col = np.full(PADDED, inf)
    one_col[:, :, 0] = 1.0  # three rows, one usable column
    cost = np.stack([infeasible, no_parent, ties, one_col])
    offsets = np.zeros((4, 3))
    valid = np.array([[True] * 3, [False] * 3, [True] * 3, [True] * 3])
    res = _kbest(jnp.asarray(cost), K, jnp.asarray(offsets), jnp.asarray(valid))
    for b in (0, 1, 3):
        r = _numpy(res, b)
        assert int(r.num_solutions) == 0 and not r.valid.any()
        assert np.all(r.parent == -1) and np.all(r.row_to_col == -1) and np.all(r.total_cost == inf)
    r = _numpy(res, 2)  # 3 × 210 tied solutions: k distinct ones, each costing 0
    assert int(r.num_solutions) == K and np.all(r.total_cost == 0.0)
    assert len({(int(p), tuple(c)) for p, c in zip(r.parent, r.row_to_col.tolist())}) == K
    assert all(len(set(c)) == 3 for c in r.row_to_col.tolist())


def _weighted_total(cost, offsets, valid, weights):
    res = k_best_assignments(cost, K, offsets, valid)
    return jnp.sum(jnp.where(res.valid, res.total_cost, 0.0) * weights)


_grad = jax.jit(jax.grad(_weighted_total, argnums=(0, 1)))


def test_gradient_is_the_chosen_pairs():
    rng = np.random.default_rng(20261206)
    cost = np.where(rng.random(PADDED) < 0.2, np.inf, rng.uniform(0.0, 10.0, PADDED))
    offsets, valid = rng.uniform(0.0, 3.0, 3), np.array([True, True, False])
    # Tiled to the batch of the test above, so its compiled program is reused.
    tiled = [jnp.asarray(np.stack([x] * 4)) for x in (cost, offsets, valid)]
    res = _numpy(_kbest(tiled[0], K, *tiled[1:]), 0)
    assert int(res.num_solutions) == K
    first = np.zeros(K)
    first[0] = 1.0
    for weights in (first, np.ones(K)):  # total_cost[0], then the sum of the valid totals
        args = (jnp.asarray(x) for x in (cost, offsets, valid, weights))
        g_cost, g_off = map(np.asarray, _grad(*args))
        expected_cost, expected_off = np.zeros(PADDED), np.zeros(3)
        for i in np.flatnonzero(weights):
            p = res.parent[i]
            expected_cost[p, np.arange(3), res.row_to_col[i]] += 1.0
            expected_off[p] += 1.0
        np.testing.assert_array_equal(g_cost, expected_cost)  # no NaN from the +inf entries
        np.testing.assert_array_equal(g_off, expected_off)


def test_input_errors():
    with pytest.raises(InputError, match="`cost`.*R=3 > C=2"):
        k_best_assignments(np.zeros((3, 2)), 2)
    with pytest.raises(InputError, match="`cost`"):
        k_best_assignments(np.zeros(4), 2)
    for k in (0, -1, 2.0, True):
        with pytest.raises(InputError, match="`k`"):
            k_best_assignments(np.zeros((2, 2, 3)), k)
    with pytest.raises(InputError, match="`offsets`"):
        k_best_assignments(np.zeros((2, 2, 3)), 2, offsets=np.zeros(3))
    with pytest.raises(InputError, match="`offsets`"):
        k_best_assignments(np.zeros((2, 3)), 2, offsets=np.zeros(()))
    with pytest.raises(InputError, match="`valid_parents`"):
        k_best_assignments(np.zeros((2, 2, 3)), 2, valid_parents=np.ones((2, 1), bool))

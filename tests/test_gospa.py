"""OSPA and GOSPA on padded sets (jaxtrack.montecarlo._ospa) against Stone Soup 1.9.1.

Every jitted function is compiled once (module level, vmapped over a batch of BATCH random set
pairs of one padded shape; cutoff and order are traced arguments, so p = 1 and p = 2 share the
compilation). Stone Soup is the oracle: ``GOSPAMetric.compute_gospa_metric`` reports distance,
localisation, missed and false with the parts in the p-th power and ``missed = (c^p/2)·count``,
exactly our convention, so the parts are compared as they stand and the counts are read back as
``missed / (c^p/2)`` (it reports no counts). ``OSPAMetric.compute_OSPA_distance`` is compared at
p = 1; at p = 2 it minimises Σ min(d, c) rather than Σ min(d, c)^p (Eq. (3) of Schuhmacher et al.),
so there the oracle is SciPy's ``linear_sum_assignment`` on Eq. (3)'s matrix and Stone Soup is
only an upper bound. Stone Soup cannot evaluate two empty sets (it needs a timestamp from some
state): there the expected value is 0.
"""

import datetime

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

import jaxtrack  # noqa: F401  (float64)
from jaxtrack._validation import InputError
from jaxtrack.montecarlo._ospa import GOSPA, OSPA, gospa, ospa

stonesoup_ospa = pytest.importorskip("stonesoup.metricgenerator.ospametric")
from stonesoup.types.state import State, StateVector  # noqa: E402

BATCH = 256
SIZE = 6
DIM = 2
CUTOFF = 3.0
BOX = 10.0  # points uniform in [0, BOX]²: many pairs farther apart than the cutoff
T0 = datetime.datetime(2024, 1, 1)
ATOL = 1e-12  # absolute, on values of order c^p = 9 (p = 2) or 3 (p = 1)


def _all(truth, truth_valid, estimates, estimates_valid, cutoff, order):
    """GOSPA, OSPA and ∂(GOSPA distance²)/∂estimates of one set pair: one program, one compile."""

    def sq_distance(est):
        g = gospa(truth, truth_valid, est, estimates_valid, cutoff=cutoff, order=order)
        return g.distance**2, g

    (_, g), grad = jax.value_and_grad(sq_distance, has_aux=True)(estimates)
    return g, ospa(truth, truth_valid, estimates, estimates_valid, cutoff=cutoff, order=order), grad


_metrics = jax.jit(jax.vmap(_all, in_axes=(0, 0, 0, 0, None, None)))


def _run(cases, cutoff=CUTOFF, order=2.0):
    """(GOSPA, OSPA, gradient) of a batch of cases; cutoff and order are traced (no recompile)."""
    return _metrics(*cases, jnp.asarray(cutoff), jnp.asarray(order))


def _random_set(rng, n, size, garbage):
    """``n`` valid points at random slots of ``size`` rows; the other rows hold ``garbage``."""
    points = np.full((size, DIM), garbage)
    valid = np.zeros(size, bool)
    slots = rng.permutation(size)[:n]
    points[slots] = rng.uniform(0.0, BOX, (n, DIM))
    valid[slots] = True
    return points, valid


def _cases(seed, num=BATCH, size=SIZE):
    """``num`` set pairs with 0..SIZE points each; the first ones are the special cases."""
    rng = np.random.default_rng(seed)
    t = np.zeros((num, size, DIM)); tv = np.zeros((num, size), bool)
    e = np.zeros((num, size, DIM)); ev = np.zeros((num, size), bool)
    for b in range(num):
        garbage = np.nan if b % 2 else (-1e200 if b % 4 == 0 else 7.0)
        n, k = rng.integers(0, SIZE + 1, 2)
        if b == 0:
            n = k = 0  # both empty
        elif b in (1, 2):
            n, k = (0, 4) if b == 1 else (5, 0)  # one empty
        t[b], tv[b] = _random_set(rng, n, size, garbage)
        e[b], ev[b] = _random_set(rng, k, size, garbage)
    # Every pair farther apart than the cutoff (assignments at ≥ c would be missed + false).
    t[3], tv[3] = np.full((size, DIM), np.nan), np.arange(size) < 3
    t[3, :3] = [[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]]
    e[3], ev[3] = np.full((size, DIM), np.nan), np.arange(size) < 2
    e[3, :2] = [[5.0, 5.0], [10.0, 10.0]]
    # A pair at exactly the cutoff (3-4-5: distance 5 with c = 5 below is not "< c"), and ties:
    # two truths equidistant from one estimate.
    t[4], tv[4] = np.zeros((size, DIM)), np.arange(size) < 3
    t[4, :3] = [[0.0, 0.0], [2.0, 0.0], [20.0, 0.0]]
    e[4], ev[4] = np.zeros((size, DIM)), np.arange(size) < 2
    e[4, :2] = [[1.0, 0.0], [20.0, CUTOFF]]
    return jnp.asarray(t), jnp.asarray(tv), jnp.asarray(e), jnp.asarray(ev)


def _states(points, valid):
    return [State(StateVector(x), timestamp=T0) for x in np.asarray(points)[np.asarray(valid)]]


def _ospa_eq3(truth, estimates, c, p):
    """Eq. (3) of Schuhmacher et al. (2008), transcribed: SciPy on the complete matrix."""
    n = max(len(truth), len(estimates))
    if n == 0:
        return 0.0
    cost = np.full((n, n), c**p)
    if len(truth) and len(estimates):
        d = np.linalg.norm(truth[:, None, :] - estimates[None, :, :], axis=-1)
        cost[: len(truth), : len(estimates)] = np.minimum(d, c) ** p
    rows, cols = linear_sum_assignment(cost)
    return (cost[rows, cols].sum() / n) ** (1 / p)


CASES = _cases(0)


@pytest.fixture(scope="module")
def results():
    return {p: _run(CASES, order=p) for p in (1.0, 2.0)}


@pytest.mark.parametrize("p", [1.0, 2.0])
def test_gospa_matches_stone_soup(results, p):
    g, _, _ = results[p]
    metric = stonesoup_ospa.GOSPAMetric(c=CUTOFF, p=p)
    half = CUTOFF**p / 2
    t, tv, e, ev = (np.asarray(a) for a in CASES)
    for b in range(BATCH):
        truth, est = _states(t[b], tv[b]), _states(e[b], ev[b])
        if not truth and not est:
            want = dict(distance=0.0, localisation=0.0, missed=0.0, false=0.0)
            assigned = 0
        else:
            value, truth_to_est = metric.compute_gospa_metric(est, truth)
            want = value.value
            assigned = int(np.sum(np.asarray(truth_to_est) != -1)) if truth and est else 0
            if truth and est:  # the same optimal pairs (generic cases: a unique optimum)
                est_rank = np.where(ev[b], np.cumsum(ev[b]) - 1, -1)
                ours = np.asarray(g.assignment[b])[tv[b]]
                ours = np.where(ours >= 0, est_rank[np.maximum(ours, 0)], -1)
                np.testing.assert_array_equal(ours, np.asarray(truth_to_est).ravel(), err_msg=f"case {b}")
        for part in ("distance", "localisation", "missed", "false"):
            np.testing.assert_allclose(getattr(g, part)[b], want[part], rtol=0, atol=ATOL, err_msg=f"{part}, case {b}")
        assert int(g.num_missed[b]) == round(want["missed"] / half), b
        assert int(g.num_false[b]) == round(want["false"] / half), b
        assert int(g.num_assigned[b]) == assigned, b
        assert int(g.num_assigned[b]) + int(g.num_missed[b]) == tv[b].sum()
        assert int(g.num_assigned[b]) + int(g.num_false[b]) == ev[b].sum()
    # The special cases are what they claim to be.
    assert float(g.distance[0]) == 0.0
    assert int(g.num_assigned[3]) == 0 and int(g.num_missed[3]) == 3 and int(g.num_false[3]) == 2
    assert int(g.num_assigned[4]) == 1 and int(g.num_missed[4]) == 2 and int(g.num_false[4]) == 1  # d == c


@pytest.mark.parametrize("p", [1.0, 2.0])
def test_ospa_matches_eq3_and_stone_soup(results, p):
    _, o, _ = results[p]
    metric = stonesoup_ospa.OSPAMetric(c=CUTOFF, p=p)
    t, tv, e, ev = (np.asarray(a) for a in CASES)
    for b in range(BATCH):
        truth, est = t[b][tv[b]], e[b][ev[b]]
        want = _ospa_eq3(truth, est, CUTOFF, p)
        np.testing.assert_allclose(o.distance[b], want, rtol=0, atol=ATOL, err_msg=f"case {b}")
        if len(truth) or len(est):
            ss = metric.compute_OSPA_distance(_states(est, np.ones(len(est), bool)),
                                              _states(truth, np.ones(len(truth), bool))).value
            if p == 1.0:
                np.testing.assert_allclose(o.distance[b], ss, rtol=0, atol=ATOL, err_msg=f"case {b}")
            else:  # Stone Soup's p = 2 assignment minimises Σ min(d, c): never below Eq. (3)
                assert float(o.distance[b]) <= ss + ATOL, b
        n, m = max(len(truth), len(est)), min(len(truth), len(est))
        card = (CUTOFF**p * (n - m) / n) ** (1 / p) if n else 0.0
        np.testing.assert_allclose(o.cardinality[b], card, rtol=0, atol=ATOL)
        np.testing.assert_allclose(o.localisation[b] ** p + o.cardinality[b] ** p, o.distance[b] ** p,
                                   rtol=0, atol=ATOL)


def test_padding_invariance_and_garbage():
    """Padded to 6 and to 9 (the extra rows NaN, the valid rows moved to other slots): same values."""
    g6, o6, _ = _run(CASES)
    t, tv, e, ev = (np.asarray(a) for a in CASES)
    rng = np.random.default_rng(1)
    wide = [np.full((BATCH, 9, DIM), np.nan), np.zeros((BATCH, 9), bool),
            np.full((BATCH, 9, DIM), np.nan), np.zeros((BATCH, 9), bool)]
    slot_of = {}
    for b in range(BATCH):
        for i, (points, valid, wp, wv) in enumerate(((t, tv, wide[0], wide[1]), (e, ev, wide[2], wide[3]))):
            slots = np.sort(rng.permutation(9)[: SIZE])  # the same order, new slots among 9
            wp[b, slots], wv[b, slots] = points[b], valid[b]
            slot_of[b, i] = slots
    g9, o9, grad9 = _run(tuple(jnp.asarray(a) for a in wide))
    # The assignment names the same estimates in their new slots, for the truths in theirs.
    for b in range(BATCH):
        a6 = np.asarray(g6.assignment[b])
        a9 = np.asarray(g9.assignment[b])[slot_of[b, 0]]
        np.testing.assert_array_equal(np.where(a6 >= 0, slot_of[b, 1][np.maximum(a6, 0)], -1), a9)
    for a, b in ((g6, g9), (o6, o9)):
        for name, x in vars(a).items():
            if name == "assignment":
                continue
            y = getattr(b, name)
            if jnp.issubdtype(x.dtype, jnp.integer):
                np.testing.assert_array_equal(x, y, err_msg=name)
            else:
                assert np.all(np.isfinite(x)), name
                np.testing.assert_allclose(x, y, rtol=0, atol=ATOL, err_msg=name)
    # Garbage (NaN, ±1e200, 7.0) in padded rows reaches neither the value nor the gradient.
    grad6 = np.asarray(_run(CASES)[2])
    assert np.all(np.isfinite(grad6)) and np.all(grad6[~ev] == 0.0)
    assert np.all(np.isfinite(grad9)) and np.all(np.asarray(grad9)[~wide[3]] == 0.0)
    np.testing.assert_allclose(np.asarray(grad9)[wide[3]], grad6[ev], rtol=0, atol=ATOL)


def test_permutation_and_symmetry(results):
    """Reordering the rows (valid and padded together) of either set changes nothing; swapping
    the sets swaps missed and false."""
    g, o, _ = results[2.0]
    t, tv, e, ev = (np.asarray(a) for a in CASES)
    rng = np.random.default_rng(2)
    pt = np.stack([rng.permutation(SIZE) for _ in range(BATCH)])
    pe = np.stack([rng.permutation(SIZE) for _ in range(BATCH)])
    take = lambda a, idx: np.take_along_axis(a, idx[..., None] if a.ndim == 3 else idx, axis=1)  # noqa: E731
    perm = tuple(jnp.asarray(a) for a in (take(t, pt), take(tv, pt), take(e, pe), take(ev, pe)))
    gp, op, _ = _run(perm)
    gs, os_, _ = _run((CASES[2], CASES[3], CASES[0], CASES[1]))
    for name in ("distance", "localisation", "missed", "false", "num_assigned", "num_missed", "num_false"):
        np.testing.assert_allclose(getattr(gp, name), getattr(g, name), rtol=0, atol=ATOL, err_msg=name)
    for name in ("distance", "localisation", "cardinality"):
        np.testing.assert_allclose(getattr(op, name), getattr(o, name), rtol=0, atol=ATOL, err_msg=name)
        np.testing.assert_allclose(getattr(os_, name), getattr(o, name), rtol=0, atol=ATOL, err_msg=name)
    np.testing.assert_allclose(gs.distance, g.distance, rtol=0, atol=ATOL)
    np.testing.assert_array_equal(gs.num_missed, g.num_false)
    np.testing.assert_array_equal(gs.num_false, g.num_missed)
    np.testing.assert_allclose(gs.missed, g.false, rtol=0, atol=ATOL)


@pytest.mark.parametrize("p", [1.0, 2.0])
def test_gradient_matches_central_differences(p):
    """∂ distance² / ∂ estimates against central differences on a generic configuration (two
    pairs inside the cutoff, one truth missed, one estimate false)."""
    t = np.full((SIZE, DIM), np.nan); tv = np.arange(SIZE) < 3
    t[:3] = [[0.0, 0.0], [4.0, 1.0], [9.0, 9.0]]
    e = np.full((SIZE, DIM), np.nan); ev = np.arange(SIZE) < 3
    e[:3] = [[0.7, -0.4], [3.1, 1.9], [0.0, 6.0]]
    h = 1e-6
    steps = [(i, j, s) for i in range(3) for j in range(DIM) for s in (h, -h)]
    batch = [np.repeat(a[None], BATCH, axis=0) for a in (t, tv, e, ev)]
    for row, (i, j, s) in enumerate(steps):
        batch[2][row, i, j] += s
    batch = tuple(jnp.asarray(a) for a in batch)
    g, _, grad = _run(batch, order=p)
    values = np.asarray(g.distance) ** 2
    fd = np.zeros((SIZE, DIM))
    for row in range(0, len(steps), 2):
        i, j, _ = steps[row]
        fd[i, j] = (values[row] - values[row + 1]) / (2 * h)
    grad = np.asarray(grad)[len(steps)]  # the unperturbed case
    assert np.all(np.isfinite(grad)) and np.all(grad[3:] == 0.0)
    np.testing.assert_allclose(grad[:3], fd[:3], rtol=1e-6)
    assert np.all(np.abs(grad[:2]) > 0.1)  # the assigned estimates move the value
    assert np.all(grad[2] == 0.0)  # the false one (beyond c from every truth) does not


def test_traced_bad_cutoff_raises():
    """A traced cutoff/order out of range is a run-time error naming it (equinox.error_if),
    not a NaN metric (tests/test_silent_answers.py has the eager and unbatched cases)."""
    with pytest.raises(Exception, match="`cutoff`"):
        jax.block_until_ready(_run(CASES, cutoff=-1.0))
    with pytest.raises(Exception, match="`order`"):
        jax.block_until_ready(_run(CASES, order=0.5))


def test_input_errors_name_the_argument():
    x, xv = jnp.zeros((3, 2)), jnp.ones(3, bool)
    with pytest.raises(InputError, match="`alpha`"):
        gospa(x, xv, x, xv, cutoff=1.0, alpha=1)
    for fn in (gospa, ospa):
        for cutoff in (0.0, -2.0, np.inf):
            with pytest.raises(InputError, match="`cutoff`"):
                fn(x, xv, x, xv, cutoff=cutoff)
        with pytest.raises(InputError, match="`order`"):
            fn(x, xv, x, xv, cutoff=1.0, order=0.5)
        with pytest.raises(InputError, match="`estimates`.*last dimension"):
            fn(x, xv, jnp.zeros((3, 3)), xv, cutoff=1.0)
        with pytest.raises(InputError, match="`truth_valid`"):
            fn(x, jnp.ones(2, bool), x, xv, cutoff=1.0)
        with pytest.raises(InputError, match="`estimates_valid`.*boolean"):
            fn(x, xv, x, jnp.ones(3), cutoff=1.0)


def test_zero_capacity_sets():
    """Arrays with no rows at all (static N = K = 0, no assignment to solve)."""
    empty = (jnp.zeros((0, DIM)), jnp.zeros(0, bool))
    g, o, grad = jax.jit(_all)(*empty, *empty, 1.0, 2.0)
    assert isinstance(g, GOSPA) and isinstance(o, OSPA) and grad.shape == (0, DIM)
    assert float(g.distance) == 0.0 and float(o.distance) == 0.0 and int(g.num_assigned) == 0

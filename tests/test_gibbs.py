"""The Gibbs sampler of Vo, Vo & Hoang 2017 (Sec. IV-B) as a ranked-assignment strategy:
:func:`jaxtrack.association.gibbs_assignments` against Murty's k best and against the exact
distribution ``∝ exp(−cost)`` by enumeration, and the δ-GLMB with ``GibbsSampling`` against the
exact enumeration of tests/_glmb_oracle.py.

Compiled shapes are shared: module-level jitted functions with static counts, one GLMB fixture.
"""

import itertools
import math

import _glmb_oracle as oracle
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats
from test_glmb import (
    _compare,
    _draw_scan,
    _existence_error,
    _hypotheses,
    _kwargs,
    _model,
    _prior,
    _prior_state,
    _random_case,
    _scan,
    _with,
)

from jaxtrack import InputError
from jaxtrack.association import gibbs_assignments, k_best_assignments
from jaxtrack.association._gibbs import _allocate, _chain
from jaxtrack.filters import KalmanFilter
from jaxtrack.multitarget import GLMB, LMB, GibbsSampling, MurtyRanking

INF = math.inf


def _problem(rng, P, R, A, *, forbid=0.2):
    """``P`` random ``R × (A + 2R)`` cost matrices in the δ-GLMB's layout: ``A`` shared columns
    (a fraction ``forbid`` forbidden), a "missed" and an "absent" diagonal block; costs in
    ``[0, 3]`` (``−log`` weights: a flat enough distribution for the sampler to move)."""
    meas = rng.uniform(0.0, 3.0, (P, R, A))
    meas[rng.uniform(size=meas.shape) < forbid] = INF
    eye = np.eye(R, dtype=bool)
    miss = np.where(eye, rng.uniform(0.0, 3.0, (P, R, 1)), INF)
    absent = np.where(eye, rng.uniform(0.0, 3.0, (P, R, 1)), INF)
    return np.concatenate([meas, miss, absent], axis=-1), rng.uniform(0.0, 1.0, P)


@jax.jit
def _gibbs_small(cost, offsets, key):
    return gibbs_assignments(cost, 12, key=key, num_chains=16, num_sweeps=32, offsets=offsets)


@jax.jit
def _murty_small(cost, offsets):
    return k_best_assignments(cost, 12, offsets=offsets)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_sampled_set_contains_murtys_k_best(seed):
    # 2 parents × 3 rows × (3 shared + 6 diagonal columns): about 2·80 solutions; 2·(1 + 16·32)
    # = 1026 samples. The 12 cheapest visited must be exactly Murty's 12 best.
    rng = np.random.default_rng(seed)
    cost, offsets = _problem(rng, 2, 3, 3)
    g = jax.tree.map(np.asarray, _gibbs_small(cost, offsets, jax.random.key(seed)))
    m = jax.tree.map(np.asarray, _murty_small(cost, offsets))
    assert g.valid.all() and m.valid.all() and int(g.num_solutions) == 12
    assert np.all(np.diff(g.total_cost) >= 0.0)  # ascending
    assert np.max(np.abs(g.total_cost - m.total_cost)) <= 1e-12
    assert {(int(p), tuple(t)) for p, t in zip(g.parent, g.row_to_col)} == \
        {(int(p), tuple(t)) for p, t in zip(m.parent, m.row_to_col)}
    # Each a distinct, injective, finite solution whose total is its cost.
    keys = {(int(p), tuple(t)) for p, t in zip(g.parent, g.row_to_col)}
    assert len(keys) == 12
    for p, t, c in zip(g.parent, g.row_to_col, g.total_cost):
        assert len(set(t)) == len(t)
        assert abs(offsets[p] + sum(cost[p, r, t[r]] for r in range(3)) - c) <= 1e-12


def _enumerate(cost):
    """Every injective finite assignment of one ``(R, C)`` matrix and its probability ``∝ exp(−cost)``."""
    R, C = cost.shape
    sols = [t for t in itertools.product(range(C), repeat=R)
            if len(set(t)) == R and all(np.isfinite(cost[r, t[r]]) for r in range(R))]
    logw = np.array([-sum(cost[r, t[r]] for r in range(R)) for t in sols])
    w = np.exp(logw - logw.max())
    return sols, w / w.sum()


N_CHAINS, N_SWEEPS = 4000, 12


@jax.jit
def _final_states(cost, start, key):
    keys = jax.random.split(key, N_CHAINS)
    states = jax.vmap(_chain, in_axes=(None, None, None, 0, None))(cost, jnp.isfinite(cost), start, keys, N_SWEEPS)
    return states[:, -1]


@pytest.mark.parametrize("seed", [10, 11])
def test_chain_samples_the_exact_distribution(seed):
    # One 3 × (3 + 3 + 3) problem (≈ 60 injective assignments), 4000 independent chains from the
    # all-"missed" start, 12 sweeps each; their final states are iid draws from the chain's law
    # after 12 sweeps. Pearson's χ² against the enumerated exp(−cost), bins with an expected
    # count below 5 pooled, must stay below the χ²(dof) 0.9999 quantile (a correct sampler fails
    # with probability ≤ 1e-4 plus the 12-sweep burn-in bias, invisible at this sample size);
    # and every single assignment's frequency within 4.5 binomial standard deviations.
    rng = np.random.default_rng(seed)
    cost, _ = _problem(rng, 1, 3, 3, forbid=0.3)
    cost = cost[0]
    sols, prob = _enumerate(cost)
    final = np.asarray(_final_states(cost, jnp.array([3, 4, 5], jnp.int32), jax.random.key(seed)))
    index = {t: i for i, t in enumerate(sols)}
    seen = [tuple(int(c) for c in row) for row in final]
    assert all(t in index for t in seen), "a sampled state is not an injective finite assignment"
    counts = np.bincount([index[t] for t in seen], minlength=len(sols))
    expected = N_CHAINS * prob
    big = expected >= 5.0
    obs = np.append(counts[big], counts[~big].sum())
    exp = np.append(expected[big], expected[~big].sum())
    if exp[-1] == 0.0:
        obs, exp = obs[:-1], exp[:-1]
    chi2 = float(np.sum((obs - exp) ** 2 / exp))
    bound = float(stats.chi2.ppf(0.9999, len(obs) - 1))
    assert chi2 < bound, (chi2, bound, len(obs))
    sd = np.sqrt(N_CHAINS * prob * (1.0 - prob))
    assert np.all(np.abs(counts - expected) <= 4.5 * sd + 1.0), np.max(np.abs(counts - expected) / sd)


def test_chains_are_shared_in_proportion_to_a_power_of_the_parent_weight():
    # w = (4, 1, [invalid], 1, [infeasible: +inf offset]): √w shares 2:1:0:1:0 of T = 8 chains,
    # equal shares (α = 0) 1:1:0:1:0 of T = 9; an offset shift changes nothing (only ratios
    # count), and with no feasible parent all chains fall on parent 0 (dropped by the caller).
    offsets = -np.log(np.array([4.0, 1.0, 1.0, 1.0, 1.0])) + 700.0
    feasible = np.array([True, True, False, True, False])
    counts = lambda alpha, T, o=offsets, f=feasible: np.bincount(
        np.asarray(_allocate(jnp.asarray(o), jnp.asarray(f), alpha, T)), minlength=5).tolist()
    assert counts(0.5, 8) == [4, 2, 0, 2, 0]
    assert counts(0.0, 9) == [3, 3, 0, 3, 0]
    assert counts(1.0, 12) == [8, 2, 0, 2, 0]
    assert counts(0.5, 8, o=np.where(feasible, offsets, np.inf)) == [4, 2, 0, 2, 0]
    assert counts(0.5, 4, f=np.zeros(5, bool)) == [4, 0, 0, 0, 0]
    # Through the sampler: every sample of a 3-parent problem whose only valid parent is the last
    # one is that parent's (3·4 chains of 2 sweeps: up to 1 + 24 distinct solutions of it).
    rng = np.random.default_rng(9)
    cost, offs = _problem(rng, 3, 3, 3)
    sol = gibbs_assignments(cost, 40, key=jax.random.key(1), num_chains=4, num_sweeps=2, offsets=offs,
                            valid_parents=np.array([False, False, True]))
    assert np.all(np.asarray(sol.parent)[np.asarray(sol.valid)] == 2) and int(sol.num_solutions) > 1 + 4 * 2  # more than 4 chains of 2 sweeps could give
    with pytest.raises(InputError, match="weight_exponent"):
        gibbs_assignments(cost, 4, key=jax.random.key(1), num_chains=1, num_sweeps=1, weight_exponent=-1.0)
    with pytest.raises(InputError, match="weight_exponent"):
        GibbsSampling(2, 2, weight_exponent=float("nan"))


@jax.jit
def _first_draws(cost, start, key):
    keys = jax.random.split(key, N_CHAINS)
    return jax.vmap(_chain, in_axes=(None, None, None, 0, None))(cost, jnp.isfinite(cost), start, keys, 1)[:, 0]


def test_a_draw_whose_free_weights_underflow_is_still_exact():
    # Row 0's cheapest column (0) is held by row 1 and every other column of row 0 costs 800 nats
    # more, so its free weights exp(−(cost − row min)) underflow to 0: the sampler must redo the
    # draw in log space. Row 0's first draw (the first of the sweep, given θ_{−0} = (0, 5)) is
    # then ∝ exp(−cost[0, c]) over its free columns; χ² at the 0.9999 quantile. Without the
    # log-space path every draw lands on a forbidden column.
    rng = np.random.default_rng(3)
    cost, _ = _problem(rng, 1, 3, 3, forbid=0.0)
    cost = cost[0]
    cost[0, 0], cost[1, 0] = 0.0, 0.5
    cost[0, 1:] += 800.0
    row0 = np.asarray(_first_draws(cost, jnp.array([3, 0, 5], jnp.int32), jax.random.key(4)))[:, 0]
    free = [c for c in range(cost.shape[1]) if np.isfinite(cost[0, c]) and c not in (0, 5)]
    assert set(row0.tolist()) <= set(free), sorted(set(row0.tolist()))
    logw = -cost[0, free]
    prob = np.exp(logw - logw.max()) / np.exp(logw - logw.max()).sum()
    counts = np.array([np.sum(row0 == c) for c in free])
    chi2 = float(np.sum((counts - N_CHAINS * prob) ** 2 / (N_CHAINS * prob)))
    assert chi2 < float(stats.chi2.ppf(0.9999, len(free) - 1)), (chi2, counts, N_CHAINS * prob)


# ------------------------------------------------------------------------------------------------ δ-GLMB
H_GIBBS = 64


@pytest.fixture(scope="module")
def glmb_gibbs():
    case, _ = _random_case(0)
    return GLMB(KalmanFilter(), _model(), max_hypotheses=H_GIBBS, ranking=GibbsSampling(64, 32, seed=3),
                **_kwargs(case))


@eqx.filter_jit
def _step(f, state, z, v):
    return f.step(state, z, v)


# Cases with at most H = 64 enumerated hypotheses, none of normalised weight below 3e-3 (found by
# enumeration over seeds): the samples (64 chains of 32 sweeps per prior hypothesis slot, shared over the few valid ones) then cover them all, and
# the δ-GLMB is exact, as with Murty. A hypothesis of weight 1e-8 would almost never be drawn:
# Gibbs finds what carries weight, not the whole tail.
@pytest.mark.parametrize("seed,one_birth,m1,m2", [(78, True, 2, 2), (34, True, 1, 2)])
def test_glmb_with_gibbs_equals_the_enumeration(glmb_gibbs, seed, one_birth, m1, m2):
    case, rng = _random_case(seed, one_birth=one_birth)
    scans = [_draw_scan(rng, case, m1), _draw_scan(rng, case, m2)]
    exact = oracle.glmb_run(case, scans)
    assert len(exact[-1]) <= H_GIBBS and min(w for e in exact for w, _ in e) > 3e-3
    f = _with(glmb_gibbs, case)
    state = f.init()
    for k, pts in enumerate(scans):
        state, info = _step(f, state, *_scan(pts))
        assert bool(info.ok)
        errs = _compare(_hypotheses(state), exact[k])
        assert max(errs) <= 1e-10, (k, errs)
        assert _existence_error(state, exact[k]) <= 1e-10


def test_glmb_with_gibbs_from_prior_hypotheses_equals_the_enumeration(glmb_gibbs):
    # Three prior rows (parents) at once, scan index 5 (the key stream's fold_in); 36 enumerated
    # hypotheses, the lightest of weight 1.7e-3.
    case, rng = _random_case(15, one_birth=True)
    prior = _prior(rng)
    assert len(prior) == 3
    pts = _draw_scan(rng, case, 1)
    exact = oracle.glmb_run(case, [pts], prior=prior, first_step=5)[0]
    assert len(exact) <= H_GIBBS and min(w for w, _ in exact) > 1e-3
    f = _with(glmb_gibbs, case)
    state, info = _step(f, _prior_state(f, prior, 5), *_scan(pts))
    errs = _compare(_hypotheses(state), exact)
    assert bool(info.ok) and max(errs) <= 1e-10, errs


# ------------------------------------------------------------------------------------------------ API
def test_private_columns_give_the_same_draws():
    """``private_columns=2`` on a cost in the δ-GLMB's layout (two diagonal blocks) compacts each
    row to its ``A + 2`` possible columns; the columns keep their order, so with the same key the
    chains draw the same columns as on the full matrix (every draw, not only the law), and the
    result is the same. A finite entry off a block's diagonal is an error naming the argument."""
    rng = np.random.default_rng(5)
    P, R, A = 3, 5, 4
    cost, offsets = _problem(rng, P, R, A)
    key = jax.random.key(3)
    run = jax.jit(lambda c, o, q: gibbs_assignments(c, 40, key=key, num_chains=8, num_sweeps=6, offsets=o,
                                                    private_columns=q), static_argnums=2)
    full, compact = run(cost, offsets, 0), run(cost, offsets, 2)
    assert int(full.num_solutions) > 20
    for a, b in zip(jax.tree.leaves(full), jax.tree.leaves(compact)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # The chains themselves, draw by draw (the visited set above hides repeats).
    from jaxtrack.association._gibbs import _chains

    finite = np.isfinite(cost)
    start = np.stack([np.asarray(jax.vmap(lambda c: k_best_assignments(c, 1).row_to_col[0])(cost[:, None]))[p]
                      for p in range(P)])
    own = A + np.arange(2)[None, :] * R + np.arange(R)[:, None]
    cost_c = np.concatenate([cost[..., :A], np.take_along_axis(cost, own[None], axis=2)], axis=2)
    start_c = np.where(start < A, start, A + (start - A) // R)
    keys = jax.random.split(key, P)
    s_full = np.asarray(_chains(jnp.asarray(cost), jnp.asarray(finite), jnp.asarray(start), keys, 6))
    s_c = np.asarray(_chains(jnp.asarray(cost_c), jnp.isfinite(cost_c), jnp.asarray(start_c), keys, 6, A))
    np.testing.assert_array_equal(s_full, np.where(s_c < A, s_c, A + (s_c - A) * R + np.arange(R)))
    assert len(np.unique(s_full.reshape(-1, R), axis=0)) > 5
    bad = cost.copy()
    bad[0, 1, A] = 0.5  # row 1 in row 0's "missed" column
    for q, match in [(2, "diagonal"), (-1, "private_columns"), (3, "private_columns"), (True, "private_columns")]:
        with pytest.raises(InputError, match=match):
            gibbs_assignments(bad if q == 2 else cost, 4, key=key, num_chains=2, num_sweeps=2, private_columns=q)


def test_errors_name_the_argument():
    cost = np.zeros((2, 4))
    key = jax.random.key(0)
    good = {"key": key, "num_chains": 2, "num_sweeps": 2}
    for kwargs, match in [
        (dict(good, num_chains=0), "num_chains"), (dict(good, num_chains=2.5), "num_chains"),
        (dict(good, num_sweeps=0), "num_sweeps"), (dict(good, num_sweeps=True), "num_sweeps"),
        (dict(good, key=0.5), "key"), (dict(good, key=jnp.zeros(2)), "key"),
        (dict(good, key=jax.random.split(key, 3)), "key"),
        (dict(good, offsets=np.zeros(2)), "offsets"), (dict(good, valid_parents=np.ones(3, bool)), "valid_parents"),
    ]:
        with pytest.raises(InputError, match=match):
            gibbs_assignments(cost, 2, **kwargs)
    with pytest.raises(InputError, match="`k`"):
        gibbs_assignments(cost, 0, **good)
    with pytest.raises(InputError, match="cost"):
        gibbs_assignments(np.zeros(4), 2, **good)
    with pytest.raises(InputError, match="cost"):
        gibbs_assignments(np.zeros((3, 2)), 2, **good)
    for args, match in [((0, 4), "num_chains"), ((4, -1), "num_sweeps")]:
        with pytest.raises(InputError, match=match):
            GibbsSampling(*args)
    with pytest.raises(InputError, match="seed"):
        GibbsSampling(2, 2, seed=0.5)
    case, _ = _random_case(0)
    with pytest.raises(InputError, match="ranking"):
        LMB(KalmanFilter(), _model(), max_hypotheses=4, ranking="gibbs", **_kwargs(case))


def test_jits_vmaps_and_is_reproducible():
    rng = np.random.default_rng(5)
    problems = [_problem(rng, 2, 3, 3) for _ in range(3)]
    cost = np.stack([c for c, _ in problems])
    offsets = np.stack([o for _, o in problems])
    keys = jax.random.split(jax.random.key(7), 3)
    batch = jax.vmap(_gibbs_small)(cost, offsets, keys)
    for i in range(3):  # the same samples; the sums may differ in the last bit (reduction order)
        one = _gibbs_small(cost[i], offsets[i], keys[i])
        for name in ("parent", "row_to_col", "valid", "num_solutions"):
            np.testing.assert_array_equal(np.asarray(getattr(one, name)), np.asarray(getattr(batch, name)[i]))
        np.testing.assert_allclose(np.asarray(one.total_cost), np.asarray(batch.total_cost[i]), rtol=0, atol=1e-14)
    # The same key gives the same answer; a legacy uint32 key is accepted; eager equals jitted.
    eager = gibbs_assignments(cost[0], 12, key=keys[0], num_chains=16, num_sweeps=32, offsets=offsets[0])
    again = _gibbs_small(cost[0], offsets[0], keys[0])
    np.testing.assert_array_equal(np.asarray(eager.row_to_col), np.asarray(again.row_to_col))
    np.testing.assert_array_equal(np.asarray(eager.total_cost), np.asarray(again.total_cost))
    legacy = gibbs_assignments(cost[0], 3, key=jax.random.PRNGKey(1), num_chains=1, num_sweeps=1)
    assert int(legacy.num_solutions) >= 1
    # More asked than sampled: padded with invalid rows; an invalid parent gives nothing.
    few = gibbs_assignments(cost[0], 40, key=keys[0], num_chains=1, num_sweeps=2, offsets=offsets[0],
                            valid_parents=np.array([True, False]))
    # (Both chains go to the one valid parent: at most 1 + 2·2 distinct samples.)
    assert few.valid.shape == (40,) and int(few.num_solutions) <= 5
    assert np.all(np.asarray(few.parent)[np.asarray(few.valid)] == 0)
    assert np.all(np.isinf(np.asarray(few.total_cost)[~np.asarray(few.valid)]))
    # The default ranking is Murty's.
    case, _ = _random_case(0)
    assert isinstance(GLMB(KalmanFilter(), _model(), max_hypotheses=4, **_kwargs(case)).ranking, MurtyRanking)


def test_glmb_seed_is_a_vmappable_leaf():
    # A batch of seeds through jax.vmap equals the seeds one at a time; with one sample per prior
    # hypothesis (1 chain × 1 sweep) and H = 4 the seeds find different hypotheses.
    case, rng = _random_case(1, one_birth=True)
    f = GLMB(KalmanFilter(), _model(), max_hypotheses=4, ranking=GibbsSampling(1, 1, seed=0), **_kwargs(case))
    z, v = _scan(_draw_scan(rng, case, 3))

    def two_scans(seed):
        g = eqx.tree_at(lambda g: g.ranking.seed, f, seed)
        s, _ = g.step(g.init(), z, v)
        return g.step(s, z, v)[0].log_weights

    seeds = jnp.arange(3)
    batch = np.asarray(jax.jit(jax.vmap(two_scans))(seeds))
    one = np.stack([np.asarray(jax.jit(two_scans)(s)) for s in seeds])
    np.testing.assert_allclose(batch, one, rtol=0, atol=1e-14)
    assert not np.array_equal(one[0], one[1]) or not np.array_equal(one[1], one[2])

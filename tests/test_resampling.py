"""Resampling: the four index schemes against FilterPy bit for bit, their statistics over many
keys, and the gradients of the differentiable variants.

FilterPy draws its uniforms with ``random`` imported into ``filterpy.monte_carlo.resampling``;
the reference calls replace that name for the call with a function that hands out our uniforms.
Its ``residual_resample`` computes the residual as ``weights − num_copies`` (rlabbe/filterpy#290,
biased); the reference is its source with that one line corrected to ``N·weights − num_copies``.

Compilations are shared: one jitted program computes all four index functions for a batch of
weight vectors (one compile per particle count), one computes every strategy over many keys.
"""

from __future__ import annotations

import inspect
import math
from functools import partial

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from filterpy.monte_carlo import resampling as filterpy_resampling
from jax import Array

from jaxtrack import InputError
from jaxtrack.filters._resampling import (
    AbstractResamplingScheme,
    Multinomial,
    Residual,
    SoftResampling,
    StopGradientResampling,
    Stratified,
    Systematic,
    effective_sample_size,
    multinomial_indices,
    residual_indices,
    stratified_indices,
    systematic_indices,
)

# ------------------------------------------------------------------------------------------------
# FilterPy with our uniforms
# ------------------------------------------------------------------------------------------------


def _residual_with_fix():
    source = inspect.getsource(filterpy_resampling.residual_resample)
    buggy = "residual = weights - num_copies"
    assert source.count(buggy) == 1, "FilterPy's residual_resample changed: re-read rlabbe/filterpy#290"
    namespace = dict(vars(filterpy_resampling))
    exec(source.replace(buggy, "residual = N*np.asarray(weights) - num_copies"), namespace)
    return namespace["residual_resample"]


FILTERPY = {
    "systematic": filterpy_resampling.systematic_resample,
    "stratified": filterpy_resampling.stratified_resample,
    "multinomial": filterpy_resampling.multinomial_resample,
    "residual": _residual_with_fix(),
}


def filterpy(name: str, weights: np.ndarray, u) -> np.ndarray | None:
    """FilterPy's resampling of ``weights`` with the uniforms ``u``; None where it raises IndexError."""
    fn = FILTERPY[name]
    namespace = fn.__globals__
    saved = namespace["random"]
    # Each function calls `random()` (systematic) or `random(size)` once; the first `size` of ours.
    namespace["random"] = lambda size=None: float(u) if size is None else np.asarray(u)[:size].copy()
    try:
        with np.errstate(all="ignore"):  # residual: 0/0 when every copy is deterministic (unused)
            return np.asarray(fn(weights.copy()))
    except IndexError:  # systematic/stratified have no round-off guard
        return None
    finally:
        namespace["random"] = saved


# ------------------------------------------------------------------------------------------------
# Weight vectors and uniforms (with positions placed exactly on cumulative-sum boundaries)
# ------------------------------------------------------------------------------------------------


def _nudge(start: float, position, target: float) -> float | None:
    """A uniform in [0, 1) within a few ulps of ``start`` whose ``position(u)`` is exactly ``target``."""
    for step in range(-6, 7):
        u = start + step * np.spacing(start) if start > 0 else step * 5e-324
        if 0.0 <= u < 1.0 and position(u) == target:
            return float(u)
    return None


def _weights(rng: np.random.Generator, n: int, kind: str) -> np.ndarray:
    if kind == "one":
        w = np.zeros(n)
        w[rng.integers(n)] = 1.0
        return w
    if kind == "equal":
        return np.full(n, 1.0 / n)
    if kind == "heavy":  # log-normal weights, spanning many orders of magnitude
        w = np.exp(rng.normal(0.0, 4.0, n))
    else:
        w = rng.random(n) ** rng.uniform(0.5, 4.0)
    if kind == "zeros":
        w[rng.random(n) < 0.4] = 0.0
        w[-1] = 0.0 if rng.random() < 0.5 else w[-1]  # trailing zeros half the time
        w[rng.integers(n)] += 0.1  # at least one positive
    return w / w.sum()


def _uniforms(rng: np.random.Generator, w: np.ndarray, ties: bool):
    """Uniforms for systematic ``()``, stratified, multinomial and residual ``(N,)``.

    With ``ties``, some positions land exactly on a value of FilterPy's cumulative sum, where a
    position one ulp away (a reciprocal instead of a division, a cumulative sum summed in another
    order) selects another particle.
    """
    n = len(w)
    u_sys, u_str, u_mul, u_res = rng.random(), rng.random(n), rng.random(n), rng.random(n)
    if not ties:
        return u_sys, u_str, u_mul, u_res
    c = np.cumsum(w)
    inner = [j for j in range(n) if 0.0 < c[j] < 1.0]
    if inner:
        j = inner[rng.integers(len(inner))]
        i = min(int(np.floor(n * c[j])), n - 1)
        found = _nudge(n * c[j] - i, lambda v: (v + np.arange(n))[i] / n, c[j])
        u_sys = found if found is not None else u_sys
        # Stratified: the stratum holding c_j gets a position on it (16 of them at most).
        for j in inner[:: max(1, len(inner) // 16)]:
            i = min(int(np.floor(n * c[j])), n - 1)
            found = _nudge(n * c[j] - i, lambda v, i=i: (v + i) / n, c[j])
            u_str[i] = found if found is not None else u_str[i]
        picks = rng.integers(len(inner), size=n)
        u_mul = np.where(rng.random(n) < 0.5, c[np.asarray(inner)[picks]], u_mul)
    r = n * w - np.floor(n * w)
    if r.sum() > 0:
        cr = np.cumsum(r / sum(r))
        inner = np.flatnonzero((cr > 0) & (cr < 1))
        if inner.size:
            u_res = np.where(rng.random(n) < 0.5, cr[inner[rng.integers(inner.size, size=n)]], u_res)
    return u_sys, u_str, u_mul, u_res


def _has_tie(name: str, w: np.ndarray, u) -> bool:
    """Whether a position (in FilterPy's arithmetic) equals a value of the cumulative sum it is
    compared with: there, one ulp decides the ancestor."""
    n = len(w)
    if name in ("systematic", "stratified"):
        return bool(np.isin((u + np.arange(n)) / n, np.cumsum(w)).any())
    if name == "multinomial":
        return bool(np.isin(u, np.cumsum(w)).any())
    r = n * w - np.floor(n * w)
    return bool(r.sum() > 0 and np.isin(u, np.cumsum(r / sum(r))).any())


def _cases(seed: int, n: int, count: int):
    rng = np.random.default_rng(seed)
    kinds = ["random", "heavy", "zeros", "one", "equal"]
    weights, uniforms = [], []
    for k in range(count):
        w = _weights(rng, n, kinds[k % len(kinds)] if k >= 5 else kinds[k])
        weights.append(w)
        uniforms.append(_uniforms(rng, w, ties=k % 2 == 1))
    u_sys, u_str, u_mul, u_res = (np.asarray(x) for x in zip(*uniforms))
    return np.asarray(weights), (u_sys, u_str, u_mul, u_res)


@jax.jit
def _all_indices(weights, u_sys, u_str, u_mul, u_res):
    def one(w, a, b, c, d):
        return {
            "systematic": systematic_indices(w, a),
            "stratified": stratified_indices(w, b),
            "multinomial": multinomial_indices(w, c),
            "residual": residual_indices(w, d),
        }

    return jax.vmap(one)(weights, u_sys, u_str, u_mul, u_res)


# (particle count, vectors): 246 weight vectors in all, half of them with ties. Each size is one
# compilation (about 1 s), so the sizes are few and every other call reuses the N = 7 batch.
SIZES = [(1, 6), (7, 190), (1000, 50)]
BATCH = dict(SIZES)


def indices_of(weights, u_sys, u_str, u_mul, u_res) -> dict[str, np.ndarray]:
    """:func:`_all_indices` padded to the batch size compiled for this particle count."""
    count, n = weights.shape
    pad = BATCH[n] - count
    args = [np.concatenate([x, np.repeat(x[:1], pad, axis=0)])
            for x in (weights, u_sys, u_str, u_mul, u_res)]
    return {name: np.asarray(v)[:count] for name, v in _all_indices(*args).items()}


NAMES = ["systematic", "stratified", "multinomial", "residual"]


@pytest.fixture(scope="module")
def filterpy_comparison():
    """Per scheme: (vectors compared, vectors with a tie, vectors where FilterPy raised
    IndexError, mismatches)."""
    compared = {name: 0 for name in NAMES}
    ties = {name: 0 for name in NAMES}
    raised = {name: [] for name in NAMES}
    mismatches = {name: [] for name in NAMES}
    for seed, (n, count) in enumerate(SIZES):
        weights, uniforms = _cases(seed, n, count)
        ours = indices_of(weights, *uniforms)
        for name, u in zip(NAMES, uniforms):
            for b in range(count):
                got = ours[name][b]
                # Every scheme, every vector: in range, and never a particle without weight.
                assert got.dtype == np.int32 and got.min() >= 0 and got.max() <= n - 1, (name, n, b)
                assert np.all(weights[b][got] > 0), (name, n, b)
                want = filterpy(name, weights[b], u[b])
                if want is None:
                    raised[name].append((n, b))
                    continue
                compared[name] += 1
                ties[name] += _has_tie(name, weights[b], u[b])
                if not np.array_equal(got, want):
                    mismatches[name].append((n, b))
    return compared, ties, raised, mismatches


@pytest.mark.parametrize("name", NAMES)
def test_bit_for_bit_with_filterpy(filterpy_comparison, name):
    compared, ties, raised, mismatches = filterpy_comparison
    assert compared[name] >= 200
    assert ties[name] >= 50, ties  # the comparison does reach the last bit
    assert not mismatches[name], f"{name}: (N, vector) differing from FilterPy: {mismatches[name][:10]}"
    # FilterPy's guard (multinomial, residual) means it never runs past the end there.
    if name in ("multinomial", "residual"):
        assert not raised[name]


def test_filterpys_residual_is_biased_and_ours_is_not():
    # rlabbe/filterpy#290: with the residual `weights − num_copies`, particle 3 of this vector is
    # never drawn; it is owed 7 × 0.05 = 0.35 copies on average (3 + 2 + 1 copies are
    # deterministic, the seventh is drawn from the residuals (0.5, 0.1, 0.05, 0.35)).
    w = np.array([0.5, 0.3, 0.15, 0.05, 0.0, 0.0, 0.0])
    num = BATCH[7]
    u = np.random.default_rng(3).random((num, 7))
    original = filterpy_resampling.residual_resample
    namespace = original.__globals__
    saved = namespace["random"]
    theirs = []
    try:
        for row in u:
            namespace["random"] = lambda size, row=row: row[:size].copy()
            with np.errstate(all="ignore"):
                theirs.append(np.bincount(original(w), minlength=7))
    finally:
        namespace["random"] = saved
    ours = indices_of(np.tile(w, (num, 1)), u[:, 0], u, u, u)["residual"]
    ours = (ours[..., None] == np.arange(7)).sum(axis=1)
    assert np.sum(np.stack(theirs)[:, 3]) == 0
    assert np.all(ours[:, :3] >= [3, 2, 1])
    assert abs(ours[:, 3].mean() - 0.35) < 5 * np.sqrt(0.35 * 0.65 / num)


def test_round_off_gap_and_position_one_go_to_the_last_particle_with_weight():
    # Weights with a trailing zero whose sum rounds below 1, and a uniform in the gap above it.
    rng = np.random.default_rng(11)
    while True:
        w = np.r_[rng.random(6), 0.0]
        w /= w.sum()
        if np.cumsum(w)[-1] < 1.0:
            break
    gap = np.nextafter(np.cumsum(w)[-1], 1.0)
    u = np.full(7, gap)
    # FilterPy's guard (cumsum[-1] = 1) hands the gap to particle 6, which has no weight.
    assert filterpy("multinomial", w, u)[0] == 6
    # FilterPy's systematic loop has no guard: a position at 1.0 ((u + N − 1)/N rounds up to 1
    # for u = the largest double below 1) runs past the end.
    top = np.nextafter(1.0, 0.0)
    exact = np.array([0.5, 0.25, 0.125, 0.0625, 0.03125, 0.03125, 0.0])
    assert (top + 6) / 7 == 1.0 and filterpy("systematic", exact, top) is None
    got = indices_of(np.stack([w, exact]), np.array([0.5, top]), np.full((2, 7), 0.5),
                     np.stack([u, u]), np.stack([u, u]))
    assert np.all(got["multinomial"][0] == 5)
    assert got["systematic"][1, -1] == 5


# ------------------------------------------------------------------------------------------------
# Strategies: statistics over many keys (one compilation for all four)
# ------------------------------------------------------------------------------------------------

STAT_WEIGHTS = np.array([0.31, 0.2, 0.15, 0.12, 0.1, 0.07, 0.05, 0.0])
with np.errstate(divide="ignore"):
    STAT_LOG_WEIGHTS = np.log(STAT_WEIGHTS)  # the last is −inf: a zero weight
NUM_KEYS = 4000
SCHEMES = [Systematic(), Stratified(), Multinomial(), Residual()]


@pytest.fixture(scope="module")
def draws():
    """Ancestor indices ``(K, 4, N)`` of the four strategies for ``K`` keys (jit of vmap)."""

    @jax.jit
    def run(keys, log_weights):
        def one(key):
            out = [scheme(key, log_weights) for scheme in SCHEMES]
            return jnp.stack([i for i, _ in out]), jnp.stack([lw for _, lw in out])

        return jax.vmap(one)(keys)

    keys = jax.random.split(jax.random.key(7), NUM_KEYS)
    indices, new_log_weights = run(keys, jnp.asarray(STAT_LOG_WEIGHTS))
    return np.asarray(indices), np.asarray(new_log_weights)


def test_indices_in_range_and_weights_uniform(draws):
    indices, new_log_weights = draws
    n = STAT_WEIGHTS.size
    assert indices.dtype == np.int32 and indices.min() >= 0 and indices.max() <= n - 1
    assert np.all(STAT_WEIGHTS[indices] > 0)  # the zero-weight particle is never drawn
    assert np.all(new_log_weights == -math.log(n))
    # Systematic and stratified indices come out sorted.
    assert np.all(np.diff(indices[:, :2], axis=-1) >= 0)


def test_expected_copies_are_n_w(draws):
    indices, _ = draws
    n = STAT_WEIGHTS.size
    copies = (indices[..., None] == np.arange(n)).sum(axis=-2)  # (K, 4, N)
    expected = n * STAT_WEIGHTS
    # Bound: 5 standard errors of the multinomial count, whose variance N w (1 − w) bounds the
    # per-particle variance of the other three (Douc, Cappé & Moulines 2005; for systematic the
    # count is floor or ceil of N w, variance frac(N w)(1 − frac(N w)) ≤ N w (1 − w)).
    bound = 5.0 * np.sqrt(n * STAT_WEIGHTS * (1 - STAT_WEIGHTS) / NUM_KEYS) + 1e-12
    error = np.abs(copies.mean(axis=0) - expected)
    assert np.all(error <= bound), (error / np.maximum(bound, 1e-12)).round(2)
    low, high = np.floor(expected), np.ceil(expected)
    assert np.all((copies[:, 0] >= low) & (copies[:, 0] <= high))  # systematic: floor or ceil
    assert np.all((copies[:, 1] >= low - 1) & (copies[:, 1] <= high + 1))  # stratified
    assert np.all(copies[:, 3] >= low)  # residual: the deterministic copies
    # Multinomial really is the noisiest (sanity of the bound's premise).
    var = copies.var(axis=0).sum(axis=-1)
    assert var[2] > max(var[0], var[1], var[3])


def test_effective_sample_size():
    ess = jax.jit(jax.vmap(effective_sample_size))
    w = np.array([0.5, 0.3, 0.15, 0.05])
    # Scale-free (±1000: beyond exp's range) and the two extremes: equal weights, one weight.
    lw = np.stack([np.log(w), np.log(w) + 1e3, np.log(w) - 1e3, np.zeros(4), [0.0, -np.inf, -np.inf, -np.inf]])
    got = np.asarray(ess(lw))
    np.testing.assert_allclose(got, [1 / np.sum(w**2)] * 3 + [4.0, 1.0], rtol=1e-12)


# ------------------------------------------------------------------------------------------------
# Differentiable variants
# ------------------------------------------------------------------------------------------------


class GivenUniform(AbstractResamplingScheme):
    """Systematic resampling with the uniform given, so that an expectation over it is a sum."""

    u: Array

    def uniforms(self, key, num_particles, dtype):
        return self.u

    def indices(self, weights, u):
        return systematic_indices(weights, u)


def _pieces(*cumulative_sums, n: int):
    """Midpoints and lengths of the intervals of ``u`` on which systematic indices are constant:
    a position ``(u + i)/N`` crosses ``C_j`` at ``u = frac(N C_j)``."""
    edges = np.unique(np.concatenate([np.mod(n * c, 1.0) for c in cumulative_sums] + [[0.0, 1.0]]))
    return (edges[:-1] + edges[1:]) / 2, np.diff(edges)


N_GRAD = 7
ALPHA = 0.5
_rng = np.random.default_rng(2)
GRAD_LOG_WEIGHTS = _rng.normal(0.0, 1.0, N_GRAD)
PHI = _rng.normal(0.0, 1.0, N_GRAD)  # a per-particle quantity, e.g. a next-step likelihood
GRAD_KEY = jax.random.key(5)


@pytest.fixture(scope="module")
def gradients():
    """Everything the gradient tests read, from one compiled program.

    - ``forward``: per scheme (systematic, multinomial): stop-gradient and plain resampling
      outputs and the Jacobian of the stop-gradient new log weights; soft at α = 1 against multinomial.
    - ``pieces``: per interval of the systematic uniform on which the indices are constant, the
      gradients of ``Σ_i exp(new_i) φ_{a_i}`` (stop-gradient, plain, soft α = 0.5, soft α = 0),
      of ``logsumexp(lw) + logsumexp(new)`` (stop-gradient), and the soft estimate's value.
    """
    key, phi = GRAD_KEY, jnp.asarray(PHI)
    w = np.asarray(jax.nn.softmax(GRAD_LOG_WEIGHTS))
    mids, lengths = _pieces(np.cumsum(w), np.cumsum(ALPHA * w + (1 - ALPHA) / N_GRAD), n=N_GRAD)

    def estimate(resampling, lw):
        indices, new = resampling(key, lw)
        return jnp.sum(jnp.exp(new) * phi[indices])

    def per_uniform(lw, u):
        given = GivenUniform(u)
        schemes = (StopGradientResampling(given), given, SoftResampling(given, ALPHA), SoftResampling(given, 0.0))
        grads = [jax.grad(partial(estimate, r))(lw) for r in schemes]
        with_normaliser = jax.grad(
            lambda lw: jax.nn.logsumexp(lw) + jax.nn.logsumexp(StopGradientResampling(given)(key, lw)[1])
        )(lw)
        return jnp.stack([*grads, with_normaliser]), estimate(SoftResampling(given, ALPHA), lw)

    @jax.jit
    def run(lw, mids):
        forward = []
        for scheme in (Systematic(), Multinomial()):  # sorted and unsorted indices
            jac = jax.jacrev(lambda lw, scheme=scheme: StopGradientResampling(scheme)(key, lw)[1])(lw)
            forward.append((StopGradientResampling(scheme)(key, lw), scheme(key, lw), jac))
        soft = SoftResampling(Multinomial(), 1.0)
        soft_jac = jax.jacrev(lambda lw: soft(key, lw)[1])(lw)
        forward.append((soft(key, lw), Multinomial()(key, lw), soft_jac))
        return forward, jax.vmap(per_uniform, in_axes=(None, 0))(lw, mids)

    out = run(jnp.asarray(GRAD_LOG_WEIGHTS), jnp.asarray(mids))
    forward, (grads, soft_values) = jax.tree.map(np.asarray, out)
    return forward, lengths, grads, soft_values


def test_stop_gradient_forward_unchanged_and_jacobian_exact(gradients):
    forward = gradients[0]
    w = np.asarray(jax.nn.softmax(GRAD_LOG_WEIGHTS))
    for (indices, new), (base_indices, base_new), jac in forward[:2]:
        assert np.array_equal(indices, base_indices) and np.array_equal(new, base_new)
        assert np.all(new == -math.log(N_GRAD))
        # d new_i / d lw = e_{a_i} − w: the ancestor's normalised log weight.
        np.testing.assert_allclose(jac, np.eye(N_GRAD)[indices] - w[None, :], rtol=0, atol=1e-15)


def test_score_identity_exact_by_quadrature_over_the_systematic_uniform(gradients):
    """``E_u[∇ Σ_i exp(new_i) φ_{a_i}] = ∇ Σ_j w_j φ_j``, the expectation over the systematic
    uniform computed exactly (the indices are constant between known breakpoints).

    With ``φ = exp(ℓ)`` (next-step likelihoods) this is the predictive likelihood; adding the
    dropped normaliser, ``∇[logsumexp(lw) + logsumexp(new)]`` averages to ``∇ logsumexp(lw)``.
    Plain resampling has gradient zero; soft resampling keeps the value unbiased, has biased
    gradients for 0 < α < 1, and exact ones at α = 0.
    """
    _, lengths, grads, soft_values = gradients
    w = np.asarray(jax.nn.softmax(GRAD_LOG_WEIGHTS))
    expected = np.einsum("k,k...->...", lengths, grads)
    truth = w * (PHI - np.sum(w * PHI))  # ∂/∂lw_j Σ softmax(lw) φ = w_j (φ_j − Σ w φ)
    assert np.max(np.abs(truth)) > 0.05
    np.testing.assert_allclose(expected[0], truth, rtol=0, atol=1e-13)  # stop-gradient: unbiased
    assert np.all(grads[:, 1] == 0.0)  # plain resampling: no gradient at all
    assert np.max(np.abs(expected[2] - truth)) > 1e-3  # soft, α = 0.5: biased gradient
    np.testing.assert_allclose(expected[3], truth, rtol=0, atol=1e-13)  # soft, α = 0: unbiased
    np.testing.assert_allclose(expected[4], w, rtol=0, atol=1e-13)  # ∇ logsumexp(lw)
    # SoftResampling resampling is properly weighted: the value is unbiased.
    np.testing.assert_allclose(lengths @ soft_values, np.sum(w * PHI), rtol=0, atol=1e-13)


def test_soft_at_alpha_one_is_the_scheme_and_has_no_gradient(gradients):
    (indices, new), (ref_indices, ref_new), jac = gradients[0][2]
    assert np.array_equal(indices, ref_indices)
    np.testing.assert_allclose(new, ref_new, rtol=0, atol=1e-15)
    assert np.all(jac == 0.0)


# ------------------------------------------------------------------------------------------------
# Input errors
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: systematic_indices(np.full((2, 2), 0.25), 0.5), "`weights` must have shape"),
        (lambda: stratified_indices(np.full(4, 0.25), np.full(3, 0.5)), "`u` must have shape"),
        (lambda: multinomial_indices(np.array([0.5, 0.6]), np.full(2, 0.5)), "normalised"),
        (lambda: residual_indices(np.array([1.5, -0.5]), np.full(2, 0.5)), "non-negative"),
        (lambda: systematic_indices(np.full(4, 0.25), 1.0), r"\[0, 1\)"),
        (lambda: Systematic()(jax.random.key(0), np.full(3, -np.inf)), "at least one finite"),
        (lambda: SoftResampling(Systematic(), 1.5), "`alpha`"),
        (lambda: StopGradientResampling(SoftResampling(Systematic(), 0.5)), "index scheme"),
    ],
)
def test_input_errors_name_the_argument(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_strategies_are_pytrees_with_array_leaves():
    # alpha is a leaf: a new value does not recompile.
    leaves = jax.tree.leaves(SoftResampling(Systematic(), 0.3))
    assert leaves == [0.3]
    assert eqx.tree_equal(Systematic(), Systematic())

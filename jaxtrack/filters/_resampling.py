r"""Resampling for particle filters: four ancestor-index schemes and two differentiable
variants (when to resample is the particle filter's ``ess_threshold``).

Two layers:

- **Pure index functions** of normalised weights ``(N,)`` and explicit uniforms:
  :func:`systematic_indices`, :func:`stratified_indices`, :func:`multinomial_indices`,
  :func:`residual_indices`. They return the ancestor indices ``(N,)`` int32 and, on CPU,
  reproduce FilterPy's ``filterpy.monte_carlo.{systematic,stratified,multinomial}_resample``
  bit for bit when given the uniforms FilterPy draws (and ``residual_resample`` with the fix of
  its residual, see :func:`residual_indices`).
- **Strategy objects** (equinox Modules) for a particle filter. Every one is called the same way,

  ``indices, new_log_weights = resampling(key, log_weights)``,

  with ``log_weights`` ``(N,)`` (normalised or not) and returns the ancestor indices ``(N,)``
  int32 and the log weights of the resampled particles ``(N,)``, *relative to the input's total
  mass*: the input's normaliser ``logsumexp(log_weights)`` is dropped, so a filter that
  accumulates a log-likelihood adds ``logsumexp(log_weights)`` before calling (or computes each
  increment self-normalised, ``logsumexp(lw + ℓ) − logsumexp(lw)``, which works for all of
  them). :class:`Systematic`, :class:`Stratified`, :class:`Multinomial`, :class:`Residual` and
  :class:`StopGradientResampling` return exactly ``−log N`` in the forward pass;
  :class:`SoftResampling` returns importance weights whose exponentials sum to 1 in expectation only.

Static shapes throughout (``N`` is the static length of the weights), so every strategy runs
under ``jit``, ``vmap`` (over keys or runs) and ``grad``.
"""

from __future__ import annotations

import abc
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, ArrayLike, Float, Int, PRNGKeyArray

from .._validation import InputError, as_key, check_shape, is_concrete

# ------------------------------------------------------------------------------------------------
# Arithmetic that rounds as NumPy does
# ------------------------------------------------------------------------------------------------


def _sequential_cumsum(x: Array) -> Array:
    def step(total, xi):
        total = total + xi
        return total, total

    return lax.scan(step, jnp.zeros((), x.dtype), x, unroll=8)[1]


def _cumsum(x: Array) -> Array:
    """Running sum ``x_0, x_0 + x_1, …``.

    XLA's cumsum on CPU is a reduce-window that the compiler rewrites into a tree, which rounds
    differently from NumPy's left-to-right ``np.cumsum`` (and so FilterPy's). On CPU an explicit
    left-to-right scan is used instead: bit-identical to NumPy, and measured faster there
    (N = 1000: 9 µs against 39 µs). On GPU/TPU the parallel prefix sum is kept; there an index
    can differ from the CPU one only when a position lies within a few ulps of a boundary of the
    cumulative sum.
    """
    return lax.platform_dependent(x, cpu=_sequential_cumsum, default=lambda y: jnp.cumsum(y))


def _divide(a: Array, b) -> Array:
    """``a / b`` elementwise, rounded as an IEEE division (as NumPy rounds it).

    XLA rewrites a division by a broadcast (``(u + i) / N``, ``r / Σr``) into a multiplication
    by the reciprocal, which rounds differently in about one case in three. The divisor goes
    through an optimization barrier, so the compiler cannot see that it is a broadcast; it is
    first tied to ``a`` (``0·a + b``, exact for finite ``a``) so that under ``vmap`` it carries the
    batch axis too, rather than being broadcast over it after the barrier.
    """
    b = jnp.zeros((), a.dtype) * a + jnp.asarray(b, a.dtype)
    return a / lax.optimization_barrier(b)


def _search(cumulative: Array, positions: Array, side: str, positive: Array) -> Array:
    """Ancestor of each position: ``side="left"``: first ``j`` with ``c_j ≥ v`` (FilterPy's
    ``np.searchsorted`` in ``multinomial_resample``/``residual_resample``); ``side="right"``:
    first ``j`` with ``c_j > v`` (the ``while positions[i] < cumulative_sum[j]`` loop of
    ``systematic_resample``/``stratified_resample``)."""
    n = cumulative.shape[0]
    # The last particle with positive weight (N − 1 if none).
    last = n - 1 - jnp.argmax(positive[::-1])
    # Guard against round-off, as FilterPy does with `cumulative_sum[-1] = 1.`: a normalised sum
    # can round to just below 1, and a uniform above it would have no ancestor (index N). The
    # sum is set to exactly 1 from the last positive weight on, not only at the last entry, so a
    # uniform in that gap goes to the last particle *with weight*: FilterPy's guard gives it to
    # particle N − 1 even when that particle has zero weight (its systematic and stratified
    # versions have no guard and raise IndexError there). Clipping at 1 keeps the array sorted
    # when a partial sum rounds above 1.
    cumulative = jnp.where(jnp.arange(n) >= last, 1.0, jnp.minimum(cumulative, 1.0)).astype(cumulative.dtype)
    indices = jnp.searchsorted(cumulative, positions, side=side)
    # A systematic or stratified position can itself round to 1.0 ((u + N − 1)/N with u within
    # N ulps of 1) and then passes every entry; it belongs to the last particle with weight.
    return jnp.where(indices >= n, last, indices).astype(jnp.int32)


# ------------------------------------------------------------------------------------------------
# Pure index functions
# ------------------------------------------------------------------------------------------------


def _check_inputs(weights, u, u_shape) -> tuple[Array, Array]:
    """Shapes always; values (finite, non-negative, summing to 1; uniforms in [0, 1)) when concrete."""
    weights = jnp.asarray(weights)
    if not jnp.issubdtype(weights.dtype, jnp.floating):
        weights = weights.astype(float)
    check_shape("weights", weights, [(None,)])
    if weights.shape[0] == 0:
        raise InputError("`weights` must hold at least one particle; got shape (0,).")
    u = jnp.asarray(u, weights.dtype)
    n = weights.shape[0]
    check_shape("u", u, [tuple(n if s == "N" else s for s in u_shape)])
    if is_concrete(weights):
        w = np.asarray(weights)
        tol = math.sqrt(np.finfo(w.dtype).eps)
        if not np.all(np.isfinite(w)) or np.any(w < 0) or abs(float(np.sum(w)) - 1.0) > tol:
            raise InputError(
                f"`weights` must be finite, non-negative and sum to 1 (normalised); got min "
                f"{float(np.min(w)):.3g}, sum {float(np.sum(w)):.17g}. Normalise log weights with "
                f"exp(lw - logsumexp(lw))."
            )
    if is_concrete(u):
        v = np.asarray(u)
        if not np.all((v >= 0) & (v < 1)):
            raise InputError(f"`u` must hold uniforms in [0, 1); got values in [{v.min()!r}, {v.max()!r}].")
    return weights, u


def systematic_indices(weights: ArrayLike, u: ArrayLike) -> Int[Array, " N"]:
    r"""Systematic resampling: one uniform, ``N`` evenly spaced positions.

    Positions ``p_i = (u + i)/N``, ``i = 0…N−1``; ancestor ``a_i`` is the first ``j`` with
    ``p_i < C_j``, ``C`` the cumulative sum of the weights. Particle ``j`` gets ``⌊N w_j⌋`` or
    ``⌈N w_j⌉`` copies, ``N w_j`` in expectation. Indices come out sorted.

    Bit for bit FilterPy's ``systematic_resample`` on CPU, when ``u`` is the ``random()`` it
    draws; where FilterPy's unguarded loop runs past the end (a position at or above a sum that
    rounded below 1) it raises IndexError, and this returns the last particle with weight.

    **Arguments:**

    - ``weights``: normalised weights ``(N,)`` (non-negative, summing to 1).
    - ``u``: one uniform in ``[0, 1)``, shape ``()``.

    **Returns:** the ancestor indices ``(N,)`` int32, in ``[0, N−1]``.

    **Raises:** :class:`~jaxtrack.InputError` for wrong shapes, or (when concrete) weights that
    are negative, non-finite or not normalised, or ``u`` outside ``[0, 1)``.

    ??? cite "Reference"

        ```bibtex
        @article{kitagawa1996,
          author  = {Kitagawa, Genshiro},
          title   = {Monte {C}arlo Filter and Smoother for Non-{G}aussian Nonlinear State Space Models},
          journal = {Journal of Computational and Graphical Statistics},
          volume  = {5}, number = {1}, pages = {1--25}, year = {1996},
        }
        ```

    >>> import jax.numpy as jnp
    >>> systematic_indices(jnp.array([0.5, 0.25, 0.25, 0.0]), 0.5).tolist()
    [0, 0, 1, 2]
    """
    weights, u = _check_inputs(weights, u, ())
    n = weights.shape[0]
    w = lax.stop_gradient(weights)
    positions = _divide(lax.stop_gradient(u) + jnp.arange(n, dtype=w.dtype), n)
    return _search(_cumsum(w), positions, "right", w > 0)


def stratified_indices(weights: ArrayLike, u: ArrayLike) -> Int[Array, " N"]:
    r"""Stratified resampling: one uniform in each of ``N`` equal strata.

    Positions ``p_i = (u_i + i)/N``; ancestor ``a_i`` is the first ``j`` with ``p_i < C_j``.
    ``N w_j`` copies of particle ``j`` in expectation, with a variance never above the
    multinomial one (Douc, Cappé & Moulines 2005); indices come out sorted.

    Bit for bit FilterPy's ``stratified_resample`` on CPU, when ``u`` is the ``random(N)`` it
    draws (where FilterPy raises IndexError, as in :func:`systematic_indices`, this returns the
    last particle with weight).

    **Arguments:**

    - ``weights``: normalised weights ``(N,)``.
    - ``u``: uniforms in ``[0, 1)``, shape ``(N,)``, one per stratum.

    **Returns:** the ancestor indices ``(N,)`` int32.

    **Raises:** as :func:`systematic_indices`.

    ??? cite "Reference"

        ```bibtex
        @inproceedings{douc2005,
          author    = {Douc, Randal and Capp{\'e}, Olivier and Moulines, Eric},
          title     = {Comparison of Resampling Schemes for Particle Filtering},
          booktitle = {Proc. 4th Int. Symp. Image and Signal Processing and Analysis (ISPA)},
          pages     = {64--69}, year = {2005},
        }
        ```
    """
    weights, u = _check_inputs(weights, u, ("N",))
    n = weights.shape[0]
    w = lax.stop_gradient(weights)
    positions = _divide(lax.stop_gradient(u) + jnp.arange(n, dtype=w.dtype), n)
    return _search(_cumsum(w), positions, "right", w > 0)


def multinomial_indices(weights: ArrayLike, u: ArrayLike) -> Int[Array, " N"]:
    r"""Multinomial resampling: ``N`` independent draws by inversion of the cumulative sum.

    Ancestor ``a_i`` is the first ``j`` with ``C_j ≥ u_i``. The uniforms need not be sorted and
    are not sorted here: FilterPy's ``multinomial_resample`` returns
    ``np.searchsorted(cumsum, random(N))`` on unsorted uniforms, so the indices come out in the
    order of the uniforms, and so do these. Bit for bit FilterPy's ``multinomial_resample`` on
    CPU given its ``random(N)``, except that a uniform in the round-off gap above a sum that
    rounded below 1 goes to the last particle with weight rather than to particle ``N − 1``
    (see the guard in the source). As in FilterPy, ``u_i = 0`` exactly selects particle 0 even
    when leading weights are zero; the strategy objects draw from ``(0, 1)`` to exclude it.

    **Arguments:**

    - ``weights``: normalised weights ``(N,)``.
    - ``u``: uniforms in ``[0, 1)``, shape ``(N,)``, sorted or not.

    **Returns:** the ancestor indices ``(N,)`` int32, in the order of ``u``.

    **Raises:** as :func:`systematic_indices`.
    """
    weights, u = _check_inputs(weights, u, ("N",))
    w = lax.stop_gradient(weights)
    return _search(_cumsum(w), lax.stop_gradient(u), "left", w > 0)


def residual_indices(weights: ArrayLike, u: ArrayLike) -> Int[Array, " N"]:
    r"""Residual resampling: ``⌊N w_j⌋`` copies of each particle, the rest drawn multinomially.

    With ``k_j = ⌊N w_j⌋`` and ``K = Σ k_j``, positions ``0…K−1`` hold the deterministic copies in
    particle order (``k_0`` zeros, then ``k_1`` ones, …), and positions ``K…N−1`` the ``R = N − K``
    multinomial draws from the residual weights ``r_j = (N w_j − k_j)/Σ r`` made with the first
    ``R`` uniforms, ``u_0 … u_{R−1}``, in their order (the rest of ``u`` is unused). The order
    and every rounding step (the residual normalised by its left-to-right sum, FilterPy's
    Python ``sum``) follow FilterPy's ``residual_resample``.

    FilterPy's own ``residual_resample`` (1.4.5 and later, still open as rlabbe/filterpy#290)
    computes the residual as ``weights − num_copies`` instead of ``N·weights − num_copies``:
    its residual weights are negative wherever a copy was made, and its resampling is biased
    (for ``w = (0.5, 0.3, 0.15, 0.05)`` it never draws the last two particles, which should get
    0.6 and 0.2 copies on average). This function is bit for bit that function with the
    residual corrected (the tests patch that one line of FilterPy's source), with the guard
    difference described in :func:`multinomial_indices`.

    **Arguments:**

    - ``weights``: normalised weights ``(N,)``.
    - ``u``: uniforms in ``[0, 1)``, shape ``(N,)``; only the first ``N − K`` are used.

    **Returns:** the ancestor indices ``(N,)`` int32.

    **Raises:** as :func:`systematic_indices`.

    ??? cite "Reference"

        ```bibtex
        @article{liu1998,
          author  = {Liu, Jun S. and Chen, Rong},
          title   = {Sequential {M}onte {C}arlo Methods for Dynamic Systems},
          journal = {Journal of the American Statistical Association},
          volume  = {93}, number = {443}, pages = {1032--1044}, year = {1998},
        }
        ```
    """
    weights, u = _check_inputs(weights, u, ("N",))
    n = weights.shape[0]
    w = lax.stop_gradient(weights)
    u = lax.stop_gradient(u)
    scaled = n * w
    copies = jnp.floor(scaled)
    counts = jnp.cumsum(copies.astype(jnp.int32))  # integer sums: exact in any order
    num_copied = counts[-1]
    slot = jnp.arange(n, dtype=jnp.int32)
    deterministic = jnp.searchsorted(counts, slot, side="right")
    residual = scaled - copies
    # Normalised by the left-to-right total, as FilterPy's `residual /= sum(residual)`. When every
    # copy is deterministic the total is 0 and the residual NaN, but then no slot reads it.
    residual = _divide(residual, _cumsum(residual)[-1])
    draws = _search(_cumsum(residual), u[jnp.maximum(slot - num_copied, 0)], "left", residual > 0)
    return jnp.where(slot < num_copied, deterministic, draws).astype(jnp.int32)


# ------------------------------------------------------------------------------------------------
# Strategy objects
# ------------------------------------------------------------------------------------------------


def _normalise(log_weights: Array) -> Array:
    return log_weights - jax.nn.logsumexp(log_weights)


def _check_log_weights(log_weights) -> Array:
    log_weights = jnp.asarray(log_weights)
    if not jnp.issubdtype(log_weights.dtype, jnp.floating):
        log_weights = log_weights.astype(float)
    check_shape("log_weights", log_weights, [(None,)])
    if log_weights.shape[0] == 0:
        raise InputError("`log_weights` must hold at least one particle; got shape (0,).")
    if is_concrete(log_weights):
        lw = np.asarray(log_weights)
        if np.any(np.isnan(lw)) or np.any(lw == np.inf) or not np.any(np.isfinite(lw)):
            raise InputError(
                "`log_weights` must be below +inf, not NaN, with at least one finite entry "
                f"(−inf is a zero weight); got {np.count_nonzero(np.isnan(lw))} NaN, "
                f"{np.count_nonzero(lw == np.inf)} +inf, {np.count_nonzero(np.isfinite(lw))} finite."
            )
    return log_weights


def _uniforms(key, shape, dtype) -> Array:
    # Uniforms in (0, 1): minval = the smallest normal number only turns an exact 0 into it
    # (every other value is ≥ 2⁻⁵² and unchanged), so a multinomial or residual draw can never
    # tie with the zero cumulative sum of leading zero weights and pick a zero-weight particle.
    return jax.random.uniform(key, shape, dtype, minval=jnp.finfo(dtype).tiny, maxval=1.0)


def effective_sample_size(log_weights: ArrayLike) -> Float[Array, ""]:
    r"""Kish's effective sample size ``(Σ w)² / Σ w²`` of (unnormalised) log weights.

    Computed as ``exp(2 logsumexp(lw) − logsumexp(2 lw))``, stable for any scale of the log
    weights. Between 1 (one particle holds all the weight) and ``N`` (equal weights);
    NaN when every weight is zero.

    **Arguments:** ``log_weights``: ``(N,)``, normalised or not. **Returns:** a scalar.
    """
    log_weights = _check_log_weights(log_weights)
    return jnp.exp(2.0 * jax.nn.logsumexp(log_weights) - jax.nn.logsumexp(2.0 * log_weights))


class AbstractResampling(eqx.Module):
    """How a particle filter resamples: ``indices, new_log_weights = resampling(key, log_weights)``.

    A strategy object, as :class:`~jaxtrack.filters.AbstractCovarianceStrategy` is for batches.

    **Arguments of the call:**

    - ``key``: a JAX PRNG key (the uniforms are drawn from it) or an int seed.
    - ``log_weights``: ``(N,)``, normalised or not (the normaliser is dropped); at least one
      must be finite.

    **Returns:** ``(indices, new_log_weights)``: ancestor indices ``(N,)`` int32 in
    ``[0, N−1]`` (gather the particles with ``particles[indices]``) and the log weights ``(N,)``
    of the resampled particles relative to the input's total mass (see the module docstring).
    """

    @abc.abstractmethod
    def __call__(
        self, key: PRNGKeyArray, log_weights: Float[Array, " N"]
    ) -> tuple[Int[Array, " N"], Float[Array, " N"]]:
        """Resample: ``(indices, new_log_weights)``."""


class AbstractResamplingScheme(AbstractResampling):
    """An unbiased ancestor-index scheme: ``E[copies of j] = N w_j``, new weights ``1/N``.

    Defines how many uniforms it needs (:meth:`uniforms`) and how they become indices
    (:meth:`indices`, a pure function of normalised weights and uniforms). The call normalises
    the log weights (logsumexp), draws the uniforms from the key and returns ``−log N`` for every
    particle. No gradient reaches the input through the indices or the new weights: wrap the
    scheme in :class:`StopGradientResampling` or :class:`SoftResampling` for gradients.
    """

    @abc.abstractmethod
    def uniforms(self, key: PRNGKeyArray, num_particles: int, dtype) -> Array:
        """The uniforms in ``(0, 1)`` this scheme consumes for ``num_particles`` particles."""

    @abc.abstractmethod
    def indices(self, weights: Float[Array, " N"], u: Array) -> Int[Array, " N"]:
        """Ancestor indices ``(N,)`` of normalised ``weights`` for the uniforms ``u``."""

    def __call__(self, key, log_weights):
        log_weights = _check_log_weights(log_weights)
        n = log_weights.shape[0]
        weights = jnp.exp(_normalise(lax.stop_gradient(log_weights)))
        indices = self.indices(weights, self.uniforms(as_key(key), n, log_weights.dtype))
        return indices, jnp.full((n,), -math.log(n), log_weights.dtype)


class Systematic(AbstractResamplingScheme):
    """Systematic resampling (one uniform): :func:`systematic_indices`. The usual default: in
    practice the lowest variance of the four, though not provably below stratified (Douc,
    Cappé & Moulines 2005)."""

    def uniforms(self, key, num_particles, dtype):
        return _uniforms(key, (), dtype)

    def indices(self, weights, u):
        return systematic_indices(weights, u)


class Stratified(AbstractResamplingScheme):
    """Stratified resampling (``N`` uniforms, one per stratum): :func:`stratified_indices`."""

    def uniforms(self, key, num_particles, dtype):
        return _uniforms(key, (num_particles,), dtype)

    def indices(self, weights, u):
        return stratified_indices(weights, u)


class Multinomial(AbstractResamplingScheme):
    """Multinomial resampling (``N`` i.i.d. draws): :func:`multinomial_indices`. The highest
    variance of the four; the reference against which the others are compared."""

    def uniforms(self, key, num_particles, dtype):
        return _uniforms(key, (num_particles,), dtype)

    def indices(self, weights, u):
        return multinomial_indices(weights, u)


class Residual(AbstractResamplingScheme):
    """Residual resampling (``⌊N w⌋`` copies, the rest multinomial): :func:`residual_indices`."""

    def uniforms(self, key, num_particles, dtype):
        return _uniforms(key, (num_particles,), dtype)

    def indices(self, weights, u):
        return residual_indices(weights, u)


class StopGradientResampling(AbstractResampling):
    r"""Stop-gradient resampling (Ścibior & Wood 2021): the forward pass is unchanged, the score
    flows through the weights.

    Resamples with ``scheme`` and sets the new log weight of particle ``i`` (ancestor ``a_i``)
    to ``v_{a_i} − stop_gradient(v_{a_i}) − log N``, ``v = lw − logsumexp(lw)``: exactly
    ``−log N`` in value, with the derivative of the ancestor's normalised log weight,
    ``∂ new_i / ∂ lw = e_{a_i} − w``. For any per-particle quantity ``φ`` the resampled
    estimate ``Σ_i exp(new_i) φ_{a_i}`` then has, given the particles before resampling, the
    expected gradient of ``Σ_j w_j φ_j`` (the tests check this identity exactly, by quadrature
    over the systematic uniform), where plain resampling has gradient zero.

    **Bias and variance.** The forward pass and its law are those of ``scheme``. Through a whole
    filter, differentiating the log-likelihood estimate gives the Fisher-identity score
    estimator on the particle genealogy (Poyiadjis, Doucet & Singh 2011, their O(N) estimator):
    consistent as N → ∞ but not unbiased for ``∇ log p(y)`` at finite ``N`` (the log of an
    unbiased estimate is biased), and its variance grows with the number of steps through path
    degeneracy (quadratically in time for that estimator). No hyperparameter. For the
    likelihood itself (not its log), Ścibior & Wood state that the gradient of ``Ẑ`` is an
    unbiased estimator of ``∇Z``.

    **Arguments:** ``scheme``: the unbiased index scheme (:class:`Systematic`, …).

    ??? cite "Reference"

        ```bibtex
        @article{scibior2021,
          author  = {{\'S}cibior, Adam and Wood, Frank},
          title   = {Differentiable Particle Filtering without Modifying the Forward Pass},
          journal = {arXiv preprint arXiv:2106.10314},
          year    = {2021},
        }
        @article{poyiadjis2011,
          author  = {Poyiadjis, George and Doucet, Arnaud and Singh, Sumeetpal S.},
          title   = {Particle Approximations of the Score and Observed Information Matrix in
                     State Space Models with Application to Parameter Estimation},
          journal = {Biometrika}, volume = {98}, number = {1}, pages = {65--80}, year = {2011},
        }
        ```
    """

    scheme: AbstractResamplingScheme

    def __check_init__(self):
        if not isinstance(self.scheme, AbstractResamplingScheme):
            raise InputError(
                f"`scheme` must be an index scheme (Systematic(), Stratified(), Multinomial() or "
                f"Residual()); got {self.scheme!r}."
            )

    def __call__(self, key, log_weights):
        log_weights = _check_log_weights(log_weights)
        indices, uniform = self.scheme(key, log_weights)
        ancestors = _normalise(log_weights)[indices]
        return indices, ancestors - lax.stop_gradient(ancestors) + uniform


class SoftResampling(AbstractResampling):
    r"""SoftResampling resampling (Karkus, Hsu & Lee 2018): resample from a mixture with the uniform
    distribution and keep importance weights, so gradients flow through the new weights.

    With ``q = α w + (1 − α)/N`` (``w`` the normalised weights), ancestors are drawn from ``q``
    by ``scheme`` and the new log weights are ``log(w_{a_i} / q_{a_i}) − log N``: properly
    weighted (``E[Σ_i exp(new_i) φ_{a_i}] = Σ_j w_j φ_j``), so their exponentials sum to 1 in
    expectation, not exactly. ``α = 1`` is ``scheme`` itself (weights ``1/N``, zero gradient);
    ``α = 0`` draws ancestors uniformly and keeps the weights ``w_{a_i}``.

    **Bias and variance.** The forward pass changes: the estimates stay unbiased, but their
    variance is above that of ``scheme`` (importance weights no longer equal, less
    concentration on heavy particles), more so as ``α`` decreases. The gradient flows through
    ``w_{a}/q_{a}`` but not through the draw of the ancestors, whose law depends on the
    parameters through ``q`` for ``α > 0``: it is biased for ``0 < α ≤ 1`` (the ignored term
    vanishes only at ``α = 0``, where ``q`` does not depend on the weights and the gradient of
    the estimate is unbiased), and its variance grows as ``α`` → 0 with the spread of the
    importance weights. ``α`` trades resampling's variance reduction against gradient bias.

    **Arguments:**

    - ``scheme``: the unbiased index scheme that draws from ``q``.
    - ``alpha``: ``α`` in ``[0, 1]`` (an array leaf).

    ??? cite "Reference"

        ```bibtex
        @inproceedings{karkus2018,
          author    = {Karkus, Peter and Hsu, David and Lee, Wee Sun},
          title     = {Particle Filter Networks with Application to Visual Localization},
          booktitle = {Proceedings of the 2nd Conference on Robot Learning (CoRL)},
          series    = {PMLR}, volume = {87}, pages = {169--178}, year = {2018},
        }
        ```
    """

    scheme: AbstractResamplingScheme
    alpha: float | Float[Array, ""] = 0.5

    def __check_init__(self):
        if not isinstance(self.scheme, AbstractResamplingScheme):
            raise InputError(
                f"`scheme` must be an index scheme (Systematic(), Stratified(), Multinomial() or "
                f"Residual()); got {self.scheme!r}."
            )
        if is_concrete(self.alpha) and not 0.0 <= float(self.alpha) <= 1.0:
            raise InputError(f"`alpha` must be in [0, 1]; got {self.alpha}.")

    def __call__(self, key, log_weights):
        log_weights = _check_log_weights(log_weights)
        n = log_weights.shape[0]
        dtype = log_weights.dtype
        log_w = _normalise(log_weights)
        alpha = jnp.asarray(self.alpha, dtype)
        # log q = log(α w + (1 − α)/N), stable for weights of any scale; log 0 = −inf at the ends.
        log_q = jnp.logaddexp(jnp.log(alpha) + log_w, jnp.log1p(-alpha) - math.log(n))
        # q sums to 1 up to rounding, which the schemes' guard absorbs; at α = 1 it is bit for bit
        # the weights `scheme` itself resamples.
        q = jnp.exp(lax.stop_gradient(log_q))
        indices = self.scheme.indices(q, self.scheme.uniforms(as_key(key), n, dtype))
        return indices, log_w[indices] - log_q[indices] - math.log(n)

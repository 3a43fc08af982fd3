"""Particle filters: sequential importance resampling in the shape of every other filter.

A :class:`ParticleFilter` is an :class:`~jaxtrack.filters.AbstractFilter` with its own state
(:class:`ParticleState`: the particles, their log-weights and a PRNG key besides the fields every
filter state has), so :func:`~jaxtrack.filters.run_filter` scans it, ``jax.vmap`` batches it and
:mod:`jaxtrack.montecarlo` scores it exactly as it does a Kalman filter. Two strategy objects say
*how*: the proposal (:class:`Bootstrap`, :class:`LocallyOptimal`) and the resampling scheme
(:mod:`jaxtrack.filters._resampling`: ``Systematic()``, ``Stratified()``, …, and the
differentiable wrappers ``StopGradientResampling``, ``SoftResampling``).

The particle filter is not Gaussian: it works through :meth:`ParticleFilter.step` only. The
Gaussian ``predict``/``update`` pair of :class:`~jaxtrack.filters.AbstractFilter` raises
``InputError`` (see :meth:`ParticleFilter.predict`).
"""

from __future__ import annotations

import abc
import math
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.special import logsumexp
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray

from .._validation import InputError, as_key
from ..models import AbstractStateSpaceModel
from ._base import AbstractFilter, FirstStep, StepOutput
from ._linalg import cholesky, cholesky_and_inverse, matmul
from ._resampling import AbstractResampling, Systematic, effective_sample_size
from ._updates import Conditioned, gaussian_log_likelihood, masked_noise, symmetrize


class ParticleState(eqx.Module):
    """The state of a :class:`ParticleFilter` after measurement ``k − 1`` (one trajectory).

    **Fields** (``N`` particles, ``n`` states):

    - ``mean`` ``(n,)``, ``cov`` ``(n, n)``: the weighted moments of the filtered particles
      (before any resampling of the step); before the first step, the model's prior.
    - ``log_likelihood`` ``()``: the sum of the per-step increments ``log Σ_i w̄_i p(z_k | ·)``:
      the log of the standard unbiased estimate of ``p(z_{0:k-1})``.
    - ``step`` ``()`` int: the index ``k`` of the next measurement; ``ok`` ``()`` bool: False once
      the moments or the log-likelihood became non-finite.
    - ``particles`` ``(N, n)``: the particles, in the state's units; ``log_weights`` ``(N,)``: their
      normalised log-weights (``logsumexp = 0``; after a ``SoftResampling`` resampling, 0 in expectation only).
    - ``key``: the PRNG key the next step splits (a run is replayable from the key :meth:`init` got).

    The fields :func:`~jaxtrack.filters.run_filter` and :mod:`jaxtrack.montecarlo` read from a
    :class:`~jaxtrack.filters.FilterState` (``mean``, ``cov``, ``log_likelihood``, ``step``,
    ``ok``) mean the same here.
    """

    mean: Float[Array, " n"]
    cov: Float[Array, "n n"]
    log_likelihood: Float[Array, ""]
    step: Int[Array, ""]
    ok: Bool[Array, ""]
    particles: Float[Array, "N n"]
    log_weights: Float[Array, " N"]
    key: PRNGKeyArray


def weighted_moments(points: Array, log_weights: Array) -> tuple[Array, Array]:
    """Mean and covariance of ``points`` ``(N, d)`` under the weights ``softmax(log_weights)``.

    **Returns:** ``(mean (d,), cov (d, d))``; ``cov = Σ_i w_i (x_i − x̄)(x_i − x̄)ᵀ`` (no
    small-sample correction: the moments of the weighted empirical measure).
    """
    w = jax.nn.softmax(log_weights)
    mean = w @ points
    centred = points - mean[None, :]
    # The product is symmetric in exact arithmetic; keep it so for the Cholesky factorisations
    # downstream (NEES, NIS, the next step's S).
    return mean, symmetrize((centred * w[:, None]).T @ centred)


def noise_factor(cov: Array, jitter: float | None = None) -> Array:
    """A factor ``L`` (``L Lᵀ ≈ cov``) of a positive *semi*definite ``cov``, with finite gradients.

    ``L = chol(cov + δ I)`` with ``δ = jitter · max_i cov_ii`` (``jitter`` default
    ``100 · eps`` of the dtype, 2.2e-14 in float64): a singular plant noise (noise on the velocity
    only, a rank-deficient ``G q Gᵀ``) gets an extra spread of ``√δ`` in its null directions,
    about 1.5e-7 of its largest standard deviation. ``cov = 0`` exactly gives ``L = 0`` exactly
    (a deterministic transition), with the Cholesky factorisation of ``I`` in its place so the
    unused branch keeps its gradients finite (the double-``where`` form). The jitter's scale is a
    constant of the factorisation (no gradient flows through it). Chosen over the
    eigendecomposition: ``eigh``'s derivative divides by eigenvalue gaps, which are zero for
    every kinematic ``Q₁ ⊗ I``, and Cholesky factors of ``d ≤ 4`` are written out
    (:func:`~jaxtrack.filters._linalg.cholesky`), which batches cheaply.

    **Arguments:** ``cov``: ``(d, d)``; ``jitter``: relative, dimensionless (None: ``100 · eps``).

    **Returns:** ``L``, lower triangular ``(d, d)``, in the square root of ``cov``'s units.
    """
    d = cov.shape[-1]
    jitter = 100.0 * jnp.finfo(cov.dtype).eps if jitter is None else jitter
    scale = jax.lax.stop_gradient(jnp.max(jnp.diagonal(cov)))
    zero = scale == 0  # NaN compares unequal: a NaN covariance gives a NaN factor, not 0
    eye = jnp.eye(d, dtype=cov.dtype)
    safe = jnp.where(zero, eye, symmetrize(cov) + (jitter * scale) * eye)
    return jnp.where(zero, 0.0, cholesky(safe))


def _log_densities(residuals: Array, R: Array, observed: Array) -> Array:
    """``log N(r_i; 0, R)`` over the observed components, for every row of ``residuals`` ``(N, m)``.

    Missing components are decoupled as :func:`~jaxtrack.filters._updates.masked_noise` does
    (identity block, residual 0), so they add nothing; a fully missing step gives 0 for every
    particle. The factorisation is shared by all particles.
    """
    chol, chol_inv = cholesky_and_inverse(symmetrize(masked_noise(R, observed)))
    num = jnp.sum(observed.astype(R.dtype))
    # The filters' own Gaussian log-density, one factorisation for all particles.
    return jax.vmap(gaussian_log_likelihood, in_axes=(0, None, None, None))(residuals, chol, num, chol_inv)


def _residuals(model, points: Array, z: Array, observed: Array, k) -> Array:
    """``z − h(x_i)`` per particle (angles wrapped by ``model.residual``), 0 where missing."""
    r = jax.vmap(lambda x: model.residual(z, model.measurement(x, k)))(points)
    return jnp.where(observed[None, :], r, 0.0)


class StepInputs(NamedTuple):
    """What a proposal sees of the step besides the particles (one trajectory).

    ``z`` ``(m,)`` (0 where missing), ``observed`` ``(m,)`` bool, ``k`` the step index, ``move``
    ``()`` bool (False at step 0 with ``first_step="update"``: no transition, the particles stay),
    ``jitter`` the relative jitter of :func:`noise_factor` (None: the dtype's default).
    """

    z: Array
    observed: Array
    k: Array
    move: Array
    jitter: float | None


class Proposed(NamedTuple):
    """What a proposal returns for one step (``N`` particles, ``n`` states, ``m`` components).

    - ``particles`` ``(N, n)``: the new particles ``x_k^i ~ q(· | x_{k-1}^i, z_k)``.
    - ``log_increment`` ``(N,)``: ``log [p(z_k | x_k^i) p(x_k^i | x_{k-1}^i) / q(x_k^i | ·)]``; the
      filter's new log-weights are the old ones plus these, normalised.
    - ``predicted_mean`` ``(n,)``, ``predicted_cov`` ``(n, n)``: ``x̂_{k/k-1}``, ``P_{k/k-1}``.
    - ``residuals`` ``(N, m)``: ``z − ẑ_i`` whose average under the predicted weights is the
      innovation; ``residual_cov`` ``(m, m)``: what ``S`` has besides their weighted covariance
      and ``R`` (0 for :class:`Bootstrap`, ``H Q Hᵀ`` for :class:`LocallyOptimal`), 0 where missing.
    """

    particles: Array
    log_increment: Array
    predicted_mean: Array
    predicted_cov: Array
    residuals: Array
    residual_cov: Array


class AbstractProposal(eqx.Module):
    """How a :class:`ParticleFilter` moves its particles: a strategy object (``proposal=``)."""

    def check_model(self, model: AbstractStateSpaceModel) -> None:
        """Raise ``InputError`` if this proposal cannot run on ``model`` (trace-time)."""

    @abc.abstractmethod
    def propose(self, model, particles: Array, log_weights: Array, key: PRNGKeyArray,
                inputs: StepInputs) -> Proposed:
        """Draw the step's particles from ``particles`` (weights ``log_weights``): a :class:`Proposed`."""


class Bootstrap(AbstractProposal):
    r"""The transition prior as proposal (Gordon, Salmond & Smith 1993): ``q = p(x_k | x_{k-1})``.

    .. math::

        x_k^i = f_k(x_{k-1}^i) + L_Q ε^i,\ ε^i \sim N(0, I),\qquad
        \log \tilde w_k^i = \log w_{k-1}^i + \log N(z_k; h_k(x_k^i), R_k)

    with ``L_Q`` from :func:`noise_factor` (Cholesky of ``Q + δ I``; exact 0 for ``Q = 0``). The
    draw is a reparametrisation, so ``jax.grad`` of the log-likelihood flows through the
    particles into ``f`` and ``Q``. Predicted moments: the weighted moments of the moved
    particles; the innovation is ``z − Σ_i w_{k-1}^i h(x_k^i)``.

    ??? cite "Reference"

        ```bibtex
        @article{gordon1993novel,
          title={Novel approach to nonlinear/non-Gaussian {B}ayesian state estimation},
          author={Gordon, Neil J. and Salmond, David J. and Smith, Adrian F. M.},
          journal={IEE Proceedings F (Radar and Signal Processing)}, volume={140}, number={2},
          pages={107--113}, year={1993}}
        ```
    """

    def propose(self, model, particles, log_weights, key, inputs):
        z, observed, k, move, jitter = inputs
        eps = jax.random.normal(key, particles.shape, particles.dtype)
        L = noise_factor(model.process_noise_cov(k), jitter)
        moved = jax.vmap(lambda x: model.transition(x, k))(particles) + eps @ L.T
        points = jnp.where(move, moved, particles)
        residuals = _residuals(model, points, z, observed, k)
        log_inc = _log_densities(residuals, model.measurement_noise_cov(k), observed)
        mean, cov = weighted_moments(points, log_weights)
        m = z.shape[-1]
        return Proposed(points, log_inc, mean, cov, residuals, jnp.zeros((m, m), particles.dtype))


class LocallyOptimal(AbstractProposal):
    r"""The locally optimal proposal ``q = p(x_k | x_{k-1}, z_k)`` for linear-Gaussian measurements.

    For ``z_k = H_k x_k + v_k`` (Doucet, Godsill & Andrieu 2000, §II.D), with ``f_i = f_k(x_{k-1}^i)``:

    .. math::

        S = H Q Hᵀ + R,\quad K = Q Hᵀ S^{-1},\quad Σ = Q − K S Kᵀ,\qquad
        x_k^i = f_i + K (z_k − H f_i) + L_Σ ε^i,

        \log \tilde w_k^i = \log w_{k-1}^i + \log N(z_k;\ H f_i,\ S)

    The weight does not depend on the draw, so its variance is the least any proposal of
    ``x_k`` alone can give. The dynamics ``f`` may be nonlinear. Predicted moments are those of
    the mixture ``Σ_i w_{k-1}^i N(f_i, Q)`` (the moved particles follow the posterior, not the
    prediction): ``x̂ = Σ w f_i``, ``P = Σ w (f_i − x̂)(f_i − x̂)ᵀ + Q``; the innovation is
    ``z − H x̂`` and ``S = H P Hᵀ + R``.

    Requires a model exposing ``measurement_matrix(k)`` (a
    :class:`~jaxtrack.models.LinearGaussianModel`); ``InputError`` otherwise.

    ??? cite "Reference"

        ```bibtex
        @article{doucet2000sequential,
          title={On sequential {M}onte {C}arlo sampling methods for {B}ayesian filtering},
          author={Doucet, Arnaud and Godsill, Simon and Andrieu, Christophe},
          journal={Statistics and Computing}, volume={10}, number={3}, pages={197--208}, year={2000}}
        ```
    """

    def check_model(self, model):
        if not callable(getattr(model, "measurement_matrix", None)):
            raise InputError(
                f"`proposal=LocallyOptimal()` needs a linear-Gaussian measurement z = H x + v, from a "
                f"model with `measurement_matrix(k)` (a LinearGaussianModel); got {type(model).__name__}. "
                f"Use proposal=Bootstrap() for a nonlinear measurement model."
            )

    def propose(self, model, particles, log_weights, key, inputs):
        z, observed, k, move, jitter = inputs
        dtype = particles.dtype
        fx = jax.vmap(lambda x: model.transition(x, k))(particles)
        fx = jnp.where(move, fx, particles)
        # No transition (step 0 with first_step="update"): Q = 0, so K = 0, Σ = 0 and the
        # particles stay where they are, weighted by N(z; H x, R).
        Q = jnp.where(move, model.process_noise_cov(k), 0.0)
        H = jnp.where(observed[:, None], model.measurement_matrix(k), 0.0)
        R = masked_noise(model.measurement_noise_cov(k), observed)
        QHt = matmul(Q, H.T)
        HQHt = symmetrize(matmul(H, QHt))
        chol, chol_inv = cholesky_and_inverse(symmetrize(HQHt + R))
        A = matmul(QHt, chol_inv.T)  # Q Hᵀ L⁻ᵀ: K = A L⁻¹, K S Kᵀ = A Aᵀ
        gain = matmul(A, chol_inv)
        L = noise_factor(symmetrize(Q - matmul(A, A.T)), jitter)
        residuals = _residuals(model, fx, z, observed, k)  # z − H f_i
        eps = jax.random.normal(key, particles.shape, dtype)
        points = fx + residuals @ gain.T + eps @ L.T
        num = jnp.sum(observed.astype(dtype))
        log_inc = jax.vmap(gaussian_log_likelihood, in_axes=(0, None, None, None))(residuals, chol, num, chol_inv)
        mean, spread = weighted_moments(fx, log_weights)
        return Proposed(points, log_inc, mean, symmetrize(spread + Q), residuals, HQHt)


_GAUSSIAN_ONLY = (
    "ParticleFilter.{name} is not available: a particle filter carries particles, not a Gaussian "
    "N(mean, cov), so it has no Gaussian {name}. It works through `step` (and `init`), which "
    "run_filter, run_filter_batch and monte_carlo call; it cannot be a member of an "
    "InteractingMultipleModel or any other wrapper that calls predict/update directly."
)


class Regularization(eqx.Module):
    r"""Gaussian-kernel jitter after each resampling: the (post-)regularised particle filter.

    Musso, Oudjane & Le Gland (2001), Sec. 12.2.2: after resampling, every particle moves by
    ``h · L ε_i``, ``ε_i ~ N(0, I)``, with ``L Lᵀ`` the weighted covariance of the particles before
    the resampling (the filtered covariance) and the bandwidth that minimises the mean integrated
    squared error of a Gaussian kernel density for a Gaussian target (their eq. 12.6):

    .. math::

        h = \mathrm{scale} \cdot A\, N^{-1/(n+4)},\qquad A = \bigl(4 / (n + 2)\bigr)^{1/(n+4)}.

    Why: with little or no process noise (a constant-velocity target with ``Q = 0``, static
    parameters) resampling only copies particles and nothing spreads them again, so after a few
    resamplings the cloud collapses to a few points (sample impoverishment) and the filter stops
    learning from the data. The jitter keeps the cloud's spread. The price: the filtered
    distribution is smoothed by the kernel (covariance inflated by ``h² P`` at each resampling,
    small for large ``N``), and ``exp(Σ ℓ̂_k)`` is no longer exactly unbiased.

    **Arguments:** ``scale``: a multiple of the optimal bandwidth (``> 0``; 1 = Musso et al.'s).

    ??? cite "Reference"

        ```bibtex
        @incollection{musso2001improving,
          title={Improving Regularized Particle Filters}, author={Musso, Christian and Oudjane, Nadia
                 and Le Gland, Fran{\c{c}}ois}, booktitle={Sequential {M}onte {C}arlo Methods in Practice},
          pages={247--271}, publisher={Springer}, year={2001}}
        ```
    """

    scale: float = eqx.field(static=True, default=1.0)

    def __check_init__(self):
        if not (isinstance(self.scale, (int, float)) and not isinstance(self.scale, bool)
                and math.isfinite(self.scale) and self.scale > 0):
            raise InputError(f"`scale` must be a positive float; got {self.scale!r}.")

    def bandwidth(self, num_states: int, num_particles: int) -> float:
        """``h`` for ``n`` states and ``N`` particles (dimensionless)."""
        n = num_states
        return self.scale * (4.0 / (n + 2)) ** (1.0 / (n + 4)) * num_particles ** (-1.0 / (n + 4))

    def move(self, key: PRNGKeyArray, particles: Array, cov: Array, jitter: float | None = None) -> Array:
        """``particles + h · ε L_covᵀ`` (``particles`` ``(N, n)``, ``cov`` ``(n, n)`` in state units²)."""
        N, n = particles.shape
        eps = jax.random.normal(key, particles.shape, particles.dtype)
        return particles + self.bandwidth(n, N) * eps @ noise_factor(cov, jitter).T


class ParticleFilter(AbstractFilter):
    r"""Sequential importance resampling particle filter (bootstrap by default).

    Each step moves the ``N`` particles with the proposal, reweights them and resamples when
    the effective sample size falls below ``ess_threshold · N``:

    .. math::

        x_k^i \sim q(· \mid x_{k-1}^i, z_k),\qquad
        \tilde w_k^i = w_{k-1}^i\, \frac{p(z_k \mid x_k^i)\, p(x_k^i \mid x_{k-1}^i)}{q(x_k^i \mid x_{k-1}^i, z_k)},

        \hat\ell_k = \log \textstyle\sum_i \tilde w_k^i,\qquad w_k^i = \tilde w_k^i / e^{\hat\ell_k},
        \qquad \mathrm{ESS} = 1 / \textstyle\sum_i (w_k^i)^2

    with normalised ``w_{k-1}`` (uniform after a resampling). ``exp(Σ_k ℓ̂_k)`` is the standard
    unbiased estimate of ``p(z_{0:T-1})`` (Del Moral 2004, Prop. 7.4.1): the filter's
    ``log_likelihood`` is its log (biased low by Jensen, consistent as ``N → ∞``).

    What one :meth:`step` reports (:class:`~jaxtrack.filters.StepOutput`): predicted moments
    from the proposal (:class:`Bootstrap`: the weighted moments of the moved particles); in the
    :class:`~jaxtrack.filters.Conditioned`, the weighted mean and covariance of the filtered
    particles (before resampling), the innovation ``z − Σ_i w_{k-1}^i h(x_k^i)``, ``S`` = the
    weighted covariance of ``h(x_k^i)`` + ``R`` (missing components decoupled as
    :func:`~jaxtrack.filters._updates.masked_noise` does), the step's ``ℓ̂_k``, and a zero gain
    (a particle filter has none; ``gain`` is kept for the common result shape).

    Missing components (``observed`` False) drop out of the likelihood; a fully missing step
    moves the particles and leaves the weights unchanged (its ``ℓ̂_k`` is 0 and it never
    resamples). ``first_step="update"``: no transition into step 0; ``"predict"``: the prior is
    one transition before the first measurement (as in
    :meth:`~jaxtrack.filters.AbstractFilter.step`).

    **Arguments:**

    - ``num_particles``: ``N`` (a static size: changing it recompiles).
    - ``proposal``: :class:`Bootstrap` (default) or :class:`LocallyOptimal`.
    - ``resampling``: a resampling scheme, ``Systematic()`` (default), ``Stratified()``,
      ``Multinomial()``, ``Residual()``, or a differentiable wrapper (``StopGradientResampling(scheme)``
      for unbiased score estimates, Ścibior & Wood 2021; ``SoftResampling(scheme, alpha)``).
    - ``ess_threshold``: resample when ``ESS < ess_threshold · N``; ``1`` resamples at every step
      that has a measurement, ``0`` never. In ``[0, 1]``.
    - ``key``: the PRNG key of :meth:`init` (default ``jax.random.key(0)``, made when the filter
      is, not at import); a run is a pure function of it. :func:`~jaxtrack.filters.run_filter_batch`
      gives run ``i`` ``fold_in(key, i)``; :func:`~jaxtrack.montecarlo.monte_carlo` derives each
      run's from that run's own key (``needs_key``), so runs never share particles.
    - ``jitter``: relative jitter of the noise factors (:func:`noise_factor`); None: ``100 · eps``.
    - ``regularization``: None, or a :class:`Regularization` (the regularised particle filter:
      kernel jitter after each resampling, for models with little or no process noise).

    **Raises:** ``InputError`` for a bad argument, or (at run time) a proposal the model cannot
    take (:class:`LocallyOptimal` on a nonlinear measurement).

    Example::

        pf = ParticleFilter(1000, key=jax.random.key(1))
        result = run_filter(pf, model, zs)          # one lax.scan of pf.step
        result.filtered_mean.shape, result.log_likelihood   # (T, n), the log of p̂(z)

        state = pf.init(model)                      # manual stepping: the filter holds a key
        step = eqx.filter_jit(pf.step)              # array, so jit it with filter_jit (jax.jit
        state, out = step(model, state, zs[0])      # would try to hash it)

    ??? cite "Reference"

        ```bibtex
        @book{delmoral2004feynman,
          title={Feynman-{K}ac Formulae: Genealogical and Interacting Particle Systems with
                 Applications}, author={Del Moral, Pierre}, publisher={Springer}, year={2004}}
        ```
    """

    needs_key: ClassVar[bool] = True

    num_particles: int = eqx.field(static=True)
    proposal: AbstractProposal
    resampling: AbstractResampling
    ess_threshold: float = eqx.field(static=True)
    key: PRNGKeyArray
    jitter: float | None = eqx.field(static=True)
    regularization: Regularization | None

    def __init__(
        self,
        num_particles: int,
        proposal: AbstractProposal = Bootstrap(),
        resampling: AbstractResampling = Systematic(),
        ess_threshold: float = 0.5,
        key: PRNGKeyArray | int | None = None,
        *,
        jitter: float | None = None,
        regularization: Regularization | None = None,
    ):
        if isinstance(num_particles, bool) or not isinstance(num_particles, int) or num_particles < 1:
            raise InputError(f"`num_particles` must be a positive int; got {num_particles!r}.")
        if not isinstance(proposal, AbstractProposal):
            raise InputError(f"`proposal` must be Bootstrap() or LocallyOptimal(); got {proposal!r}.")
        if not isinstance(resampling, AbstractResampling):
            raise InputError(
                f"`resampling` must be a resampling scheme (Systematic(), Stratified(), Multinomial(), "
                f"Residual(), StopGradientResampling(...), SoftResampling(...)); got {resampling!r}."
            )
        try:
            threshold = float(ess_threshold)
        except (TypeError, ValueError):
            threshold = math.nan
        if not 0.0 <= threshold <= 1.0:
            raise InputError(f"`ess_threshold` must be a number in [0, 1]; got {ess_threshold!r}.")
        if jitter is not None and not (isinstance(jitter, (int, float)) and 0 <= jitter < 1):
            raise InputError(f"`jitter` must be None or a float in [0, 1); got {jitter!r}.")
        self.num_particles = num_particles
        self.proposal = proposal
        self.resampling = resampling
        self.ess_threshold = threshold
        self.key = jax.random.key(0) if key is None else as_key(key)
        if regularization is not None and not isinstance(regularization, Regularization):
            raise InputError(f"`regularization` must be None or Regularization(...); got {regularization!r}.")
        self.jitter = None if jitter is None else float(jitter)
        self.regularization = regularization

    def check_model(self, model):
        self.proposal.check_model(model)

    def predict(self, model, mean, cov, k):
        """Not available: raises ``InputError`` (the particle filter works through :meth:`step`).

        A Gaussian predict would be another filter's (the sigma-point or linearised one), so
        ``N(mean, cov)`` in, ``N(mean, cov)`` out would silently stop being a particle filter;
        the base class's contract for these two methods is Gaussian, so they refuse.
        """
        raise InputError(_GAUSSIAN_ONLY.format(name="predict"))

    def update(self, model, mean, cov, z, observed, k):
        """Not available: raises ``InputError`` (see :meth:`predict`)."""
        raise InputError(_GAUSSIAN_ONLY.format(name="update"))

    def init(self, model: AbstractStateSpaceModel, key: PRNGKeyArray | int | None = None) -> ParticleState:
        """``N`` particles drawn from the prior ``N(initial_mean, initial_cov)``, uniform weights.

        **Arguments:** ``model``: the state-space model; ``key``: the run's PRNG key (None: the
        filter's ``key``). **Returns:** a :class:`ParticleState` with the prior as ``mean``/``cov``.
        """
        key = self.key if key is None else as_key(key)
        key, draw = jax.random.split(key)
        m0, P0 = model.initial_mean, model.initial_cov
        eps = jax.random.normal(draw, (self.num_particles, m0.shape[-1]), m0.dtype)
        particles = m0[None, :] + eps @ noise_factor(P0, self.jitter).T
        log_weights = jnp.full((self.num_particles,), -math.log(self.num_particles), m0.dtype)
        return ParticleState(m0, P0, jnp.zeros((), m0.dtype), jnp.zeros((), jnp.int32), jnp.ones((), bool),
                             particles, log_weights, key)

    def step(
        self,
        model: AbstractStateSpaceModel,
        state: ParticleState,
        z: ArrayLike,
        observed: ArrayLike | None = None,
        *,
        first_step: FirstStep = "update",
    ) -> tuple[ParticleState, StepOutput]:
        """One propose + reweight (+ resample): the step :func:`~jaxtrack.filters.run_filter` scans.

        **Arguments:** as :meth:`~jaxtrack.filters.AbstractFilter.step`, with ``state`` a
        :class:`ParticleState`.

        **Returns:** ``(new_state, StepOutput)`` (see the class docstring for what it holds).
        """
        k = state.step
        dtype = state.mean.dtype
        z = jnp.asarray(z, dtype)
        observed = jnp.ones(z.shape, bool) if observed is None else jnp.asarray(observed)
        z = jnp.where(observed, z, 0.0)
        key, propose_key, resample_key = jax.random.split(state.key, 3)
        move = jnp.ones((), bool) if first_step == "predict" else k != 0
        inputs = StepInputs(z, observed, k, move, self.jitter)
        prop = self.proposal.propose(model, state.particles, state.log_weights, propose_key, inputs)

        # Reweight: ℓ̂_k = log Σ_i w_{k-1}^i w̃^i. The previous weights sum to 1 (after SoftResampling resampling:
        # to 1 in expectation, which is what keeps exp(ℓ̂) unbiased), so this is the step's increment.
        joint = state.log_weights + prop.log_increment
        step_ll = logsumexp(joint)
        log_weights = joint - step_ll
        mean, cov = weighted_moments(prop.particles, log_weights)

        # Innovation moments under the predicted weights; missing components decoupled.
        w_pred = jax.nn.softmax(state.log_weights)
        innovation = w_pred @ prop.residuals
        centred = prop.residuals - innovation[None, :]
        S = (centred * w_pred[:, None]).T @ centred + prop.residual_cov
        S = symmetrize(S + masked_noise(model.measurement_noise_cov(k), observed))

        particles = prop.particles
        if self.ess_threshold > 0:
            # A step without measurements brings no information: never resample there.
            resample = jnp.any(observed)
            if self.ess_threshold < 1:
                ess = effective_sample_size(log_weights)
                resample = resample & (ess < self.ess_threshold * self.num_particles)

            def resampled(operands):
                points, lw = operands
                ancestors, new_lw = self.resampling(resample_key, lw)
                points = jnp.take(points, ancestors, axis=0)
                if self.regularization is not None:
                    # A key apart from the resampling's (fold_in: the streams without it are unchanged).
                    points = self.regularization.move(jax.random.fold_in(resample_key, 1), points, cov, self.jitter)
                return points, new_lw.astype(lw.dtype)

            particles, log_weights = jax.lax.cond(resample, resampled, lambda ops: ops, (particles, log_weights))

        ll = state.log_likelihood + step_ll
        finite = jnp.all(jnp.isfinite(mean)) & jnp.all(jnp.isfinite(cov)) & jnp.isfinite(ll)
        post = Conditioned(mean, cov, jnp.where(observed, innovation, 0.0), S, step_ll,
                           jnp.zeros((mean.shape[-1], z.shape[-1]), dtype))
        new_state = ParticleState(mean, cov, ll, k + 1, state.ok & finite, particles, log_weights, key)
        return new_state, StepOutput(prop.predicted_mean, prop.predicted_cov, post)

r"""The Gaussian-mixture CPHD filter (Vo, Vo & Cantoni 2007) on the GM-PHD's fixed component budget.

The CPHD filter propagates, besides the intensity ``v_k(x) = Σ_i w_i N(x; m_i, P_i)`` of the
GM-PHD (:mod:`._phd`), the cardinality distribution ``p_k(n)``, ``n = 0..N_max``. Notation and
recursion of B.-T. Vo, B.-N. Vo & A. Cantoni (2007), "Analytic implementations of the cardinalized
probability hypothesis density filter", IEEE Trans. Signal Process. 55(7), 3553-3567, with no
spawning, constant ``P_S`` and ``P_D``, and Poisson clutter (rate ``λ``, spatial density ``c(z)``):

1. **predict**: the intensity exactly as the GM-PHD's (``P_S w``, the filter's moments, the
   birth mixture appended); the cardinality as the convolution of the birth cardinality
   ``p_Γ`` with the binomial thinning of ``p_{k-1}``:
   ``p_{k|k-1}(n) = Σ_j p_Γ(n − j) Σ_{l≥j} C(l, j) P_S^j (1 − P_S)^{l−j} p_{k-1}(l)``;
2. **update** on one padded scan ``Z`` (``M`` valid measurements), with
   ``Λ_z = P_D Σ_i w_i q_i(z) / c(z)``, ``q_i(z) = N(z; ẑ_i, S_i)``, ``N_{k|k-1} = Σ_i w_i`` and the
   elementary symmetric functions ``e_j`` of ``Ξ = {Λ_z}``:

   .. math::

       Υ^u[Z](n) = \sum_{j=0}^{\min(M, n−u)} λ^{M−j} P^n_{j+u} (1 − P_D)^{n−j−u} N_{k|k-1}^{−(j+u)} e_j(Ξ)

   (``P^n_i = n!/(n−i)!``; Poisson clutter gives ``(M − j)! p_K(M − j) = e^{−λ} λ^{M−j}``, whose
   ``e^{−λ}`` cancels in every ratio below). Then ``p_k(n) = Υ^0[Z](n) p_{k|k-1}(n) / ⟨Υ^0[Z], p_{k|k-1}⟩``,
   the missed weights ``(1 − P_D) w_i ⟨Υ^1[Z], p⟩/⟨Υ^0[Z], p⟩`` and the detection weights
   ``P_D w_i q_i(z)/c(z) · ⟨Υ^1[Z∖{z}], p⟩/⟨Υ^0[Z], p⟩``, in the GM-PHD's slot layout;
3. **reduce** with the GM-PHD's Table II reduction into ``J_max`` slots (leftovers counted).

Everything runs in log space (``gammaln`` for the factorials, a log-space Vieta recursion for
``e_j`` with padded entries at ``−inf``, log-sum-exp for the sums), so ``N_max ≈ 100`` and
``M ≈ 50`` stay finite; a non-finite update sets ``ok`` False rather than passing NaN on quietly.
The predicted cardinality mass above ``N_max`` is counted per scan (``truncated_mass``) and
warned about on the host, never dropped in silence.
"""

from __future__ import annotations

import math
import warnings
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import gammainc, gammaln
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._validation import InputError, is_concrete
from ..filters._base import AbstractFilter
from ..models._base import AbstractStateSpaceModel
from ._phd import (
    GMPHDMixture,
    _common_fields,
    AbstractGaussianMixtureFilter,
    _initial_mixture_checked,
    _initial_mixture,
    _pair_likelihoods,
    _predict_intensity,
    _scalar,
    _updated_layout,
)
from ._base import Estimates, check_scans, scan_method, scan_ok, warn_capacity
from ._mixture import (
    AbstractMixtureReduction,
    GaussianMixture,
    VoMaReduction,
    legacy_mixture,
    legacy_reduction,
    reject_unknown,
)
from ._scenario import CapacityWarning, _positive_int


# ------------------------------------------------------------------------------ log-space helpers
def _log(x):
    """``log x`` for ``x >= 0`` (``−inf`` at 0) with a finite gradient at 0 (double ``where``)."""
    pos = x > 0
    return jnp.where(pos, jnp.log(jnp.where(pos, x, 1.0)), -jnp.inf)


def _log_pow(k, x):
    """``log(x**k)`` for integer ``k`` and ``x >= 0``, with ``0**0 = 1`` (``λ = 0``, ``P_D = 1``)."""
    pos = x > 0
    return jnp.where(k == 0, 0.0, jnp.where(pos, k * jnp.log(jnp.where(pos, x, 1.0)), -jnp.inf))


def _poisson_pmf(mu, N: int):
    """``(Poisson(μ) pmf at n = 0..N, P(Poisson(μ) > N))``: the pmf in log space (``μ = 0`` gives
    ``δ_0``) and the tail as ``P(N + 1, μ)``, the regularised lower incomplete gamma function."""
    n = jnp.arange(N + 1)
    return jnp.exp(_log_pow(n, mu) - mu - gammaln(n + 1.0)), gammainc(N + 1.0, mu)


def _lse(x, axis=-1):
    """Log-sum-exp that returns ``−inf`` (not NaN, nor a NaN gradient) when every entry is ``−inf``."""
    m = jnp.max(x, axis=axis, keepdims=True)
    m = jax.lax.stop_gradient(jnp.where(jnp.isfinite(m), m, 0.0))
    s = jnp.sum(jnp.exp(x - m), axis=axis)
    return _log(s) + jnp.squeeze(m, axis)


def _log_esf(log_x):
    """``log e_j(x)``, ``j = 0..M``, of ``x = exp(log_x)`` ``(M,)`` by the Vieta recursion
    ``e_j ← e_j + x_i e_{j−1}`` in log space; an entry at ``−inf`` (padding) leaves ``e`` unchanged."""
    M = log_x.shape[0]
    init = jnp.full((M + 1,), -jnp.inf, log_x.dtype).at[0].set(0.0)

    def body(e, lx):
        shifted = jnp.concatenate([jnp.full((1,), -jnp.inf, e.dtype), e[:-1]]) + lx
        return _lse(jnp.stack([e, shifted]), axis=0), None

    e, _ = jax.lax.scan(body, init, log_x)
    return e


# ------------------------------------------------------------------------------ state and result
class CPHDState(eqx.Module):
    """The GM-CPHD filter's state.

    **Fields:** ``mixture``: the intensity, a :class:`GMPHDMixture` (``J_max`` slots);
    ``cardinality_pmf`` ``(N_max + 1,)``: ``p_k(n)``, ``n = 0..N_max``; ``truncated_mass`` ``()``:
    predicted cardinality mass above ``N_max``, summed over the scans so far; ``ok`` ``()`` bool:
    False once an update was not finite.
    """

    mixture: GMPHDMixture
    cardinality_pmf: Float[Array, " N1"]
    truncated_mass: Float[Array, ""]
    ok: Bool[Array, ""]

    @property
    def mean_cardinality(self) -> Float[Array, ""]:
        """``Σ_n n p_k(n)``, the expected number of targets."""
        return jnp.sum(jnp.arange(self.cardinality_pmf.shape[0]) * self.cardinality_pmf)

    @property
    def map_cardinality(self) -> Int[Array, ""]:
        """``argmax_n p_k(n)``, the estimated number of targets."""
        return jnp.argmax(self.cardinality_pmf).astype(jnp.int32)


class GMCPHDStepInfo(NamedTuple):
    """What one :meth:`GMCPHD.step` computed besides the new state.

    ``predicted_pmf`` ``(N_max + 1,)``: ``p_{k|k-1}`` truncated at ``N_max`` (it sums to
    ``1 − truncated_mass``); ``truncated_mass`` ``()``: this scan's predicted mass above ``N_max``;
    ``updated_intensity_mass`` ``()``: ``Σ w`` before reduction (equal to the updated cardinality's
    mean); ``num_dropped``, ``dropped_weight``, ``num_pruned``: as :class:`GMPHDStepInfo`'s;
    ``ok`` ``()``: this update was finite.
    """

    predicted_pmf: Float[Array, " N1"]
    truncated_mass: Float[Array, ""]
    updated_intensity_mass: Float[Array, ""]
    num_dropped: Int[Array, ""]
    dropped_weight: Float[Array, ""]
    num_pruned: Int[Array, ""]
    ok: Bool[Array, ""]


class CPHDResult(eqx.Module):
    """A GM-CPHD run over ``T`` scans.

    **Fields** (``J`` = capacity, ``E`` = ``max_estimates``, ``N1 = N_max + 1``): ``weights``
    ``(T, J)``, ``means`` ``(T, J, n)``, ``covs`` ``(T, J, n, n)``, ``active`` ``(T, J)``: the reduced
    intensity after each scan; ``cardinality_pmf`` ``(T, N1)``; ``mean_cardinality`` ``(T,)``;
    ``map_cardinality`` ``(T,)`` int; ``intensity_mass`` ``(T,)``: ``Σ w`` after reduction;
    ``updated_intensity_mass`` ``(T,)``: before it; ``truncated_mass`` ``(T,)``: predicted
    cardinality mass above ``N_max`` per scan; ``estimates`` ``(T, E, n)``, ``estimate_mask``
    ``(T, E)``, ``num_estimates`` ``(T,)`` (MAP cardinality, see :meth:`GMCPHD.estimates`);
    ``num_dropped`` ``(T,)``, ``dropped_weight`` ``(T,)``: left over per scan for want of slots;
    ``ok`` ``(T,)``: the scan's update was finite; ``overflow`` ``()``: some scan left components
    over; ``truncated`` ``()``: some scan's ``truncated_mass`` exceeded ``truncation_tolerance``;
    ``final``: the last :class:`CPHDState`.
    """

    weights: Float[Array, "T J"]
    means: Float[Array, "T J n"]
    covs: Float[Array, "T J n n"]
    active: Bool[Array, "T J"]
    cardinality_pmf: Float[Array, "T N1"]
    mean_cardinality: Float[Array, " T"]
    map_cardinality: Int[Array, " T"]
    intensity_mass: Float[Array, " T"]
    updated_intensity_mass: Float[Array, " T"]
    truncated_mass: Float[Array, " T"]
    estimates: Float[Array, "T E n"]
    estimate_mask: Bool[Array, "T E"]
    num_estimates: Int[Array, " T"]
    num_dropped: Int[Array, " T"]
    dropped_weight: Float[Array, " T"]
    ok: Bool[Array, " T"]
    overflow: Bool[Array, ""]
    truncated: Bool[Array, ""]
    final: CPHDState

    @property
    def scan_overflow(self) -> Bool[Array, " T"]:
        """Per scan: True where the reduction left components over for want of slots."""
        return self.num_dropped > 0


# ------------------------------------------------------------------------------ the filter
class GMCPHD(AbstractGaussianMixtureFilter):
    r"""The GM-CPHD filter of Vo, Vo & Cantoni (2007) with fixed budgets ``J_max`` (components) and
    ``N_max`` (cardinality).

    **Arguments** (those shared with :class:`GMPHD` mean the same there: ``filter``, ``model``,
    ``prob_survival``, ``prob_detect``, ``birth``, ``capacity``, ``reduction`` (Table II's
    :class:`~jaxtrack.multitarget.VoMaReduction` only: Stone Soup's conventions are the GM-PHD's),
    ``gate``, ``max_estimates``):

    - ``max_cardinality``: ``N_max``, the largest number of targets the cardinality pmf holds (static).
    - ``clutter_rate``: ``λ``, the Poisson mean number of clutter points per scan, ``>= 0``;
      with ``clutter_volume``: ``V``, the clutter region's measure (the clutter points' density
      over measurement space is ``c(z) = 1/V``), or ``clutter_density``: ``κ = λ/V`` as every
      multi-target method takes it (needs ``λ > 0``; :mod:`._clutter` gives the vocabulary).
      ``clutter_spatial_density`` (Stone Soup's name of ``κ``) is refused for one release: up to
      jaxtrack 0.1.0 the GM-CPHD read it as ``c = 1/V``, and taking it as ``κ`` now would change a
      result without a word.
    - ``birth_cardinality``: ``p_Γ(n)``, ``n = 0..L−1`` with ``L <= N_max + 1``, summing to 1 with
      mean ``Σ birth.weights`` (an i.i.d. cluster birth); default: Poisson with mean
      ``Σ birth.weights`` (its mass above ``N_max`` counts as truncated at every scan).
    - ``truncation_tolerance``: the predicted mass above ``N_max`` per scan beyond which
      :func:`run_cphd` warns (default 1e-9).
    - ``initial``: the intensity before the first scan (a :class:`~jaxtrack.multitarget.GaussianMixture`),
      as :class:`GMPHD`'s, taken as a Poisson RFS (cardinality Poisson with mean
      ``Σ initial.weights``; see :meth:`init`); default None: no target before the first births.
    - Deprecated (one release): ``birth_*``, ``initial_*``, ``prune_threshold``, ``merge_threshold``.

    The estimated number of targets
    is the MAP of the cardinality pmf; the estimates are the means of that many heaviest components.

    ``P_S``, ``P_D``, ``λ``, ``c``, the birth mixture and cardinality are array leaves: changing
    them does not recompile :func:`run_cphd`, and ``jax.grad`` passes through them wherever the
    reduction's prune and merge decisions do not flip.

    **Raises:** :class:`~jaxtrack.InputError` naming the argument (as :class:`GMPHD`, and a
    ``max_cardinality`` below 1, a negative ``clutter_rate``, a non-positive clutter volume, both or
    neither clutter density, a ``birth_cardinality`` that is not a pmf or whose mean is not
    ``Σ birth_weights``).

    Example (as :class:`GMPHD`'s, with the clutter as a rate over a region of 200 m × 200 m)::

        cphd = GMCPHD(KalmanFilter(), model, prob_survival=0.99, prob_detect=0.9,
                      clutter_rate=10.0, clutter_volume=200.0**2,
                      birth=GaussianMixture([0.1], [m_b], [P_b]), capacity=50, max_cardinality=30)
        result = run_cphd(cphd, scans.measurements, scans.valid)
        result.cardinality_pmf      # (T, 31)
        result.estimates[k][result.estimate_mask[k]]        # scan k's MAP-many target states

    ??? cite "Reference"

        ```bibtex
        @article{vo2007cphd,
          author  = {Vo, Ba-Tuong and Vo, Ba-Ngu and Cantoni, Antonio},
          title   = {Analytic Implementations of the Cardinalized Probability Hypothesis Density Filter},
          journal = {IEEE Transactions on Signal Processing},
          volume  = {55}, number = {7}, pages = {3553--3567}, year = {2007}}
        ```
    """

    filter: AbstractFilter
    model: AbstractStateSpaceModel
    prob_survival: Float[Array, ""]
    prob_detect: Float[Array, ""]
    clutter_rate: Float[Array, ""]
    clutter_pdf: Float[Array, ""]
    birth: GaussianMixture
    birth_cardinality: Float[Array, " N1"]
    birth_tail: Float[Array, ""]
    initial: GaussianMixture | None
    reduction: AbstractMixtureReduction
    truncation_tolerance: Float[Array, ""]
    gate: Float[Array, ""]
    capacity: int = eqx.field(static=True)
    max_cardinality: int = eqx.field(static=True)
    max_estimates: int = eqx.field(static=True)
    labelled: ClassVar[bool] = False

    def __init__(
        self,
        filter: AbstractFilter,
        model: AbstractStateSpaceModel,
        *,
        prob_survival: ArrayLike,
        prob_detect: ArrayLike,
        clutter_rate: ArrayLike,
        birth: GaussianMixture | None = None,
        capacity: int,
        max_cardinality: int,
        clutter_volume: ArrayLike | None = None,
        clutter_density: ArrayLike | None = None,
        clutter_spatial_density: ArrayLike | None = None,
        birth_cardinality: ArrayLike | None = None,
        reduction: VoMaReduction | None = None,
        truncation_tolerance: ArrayLike = 1e-9,
        gate: ArrayLike = math.inf,
        max_estimates: int | None = None,
        initial: GaussianMixture | None = None,
        **deprecated,
    ):
        n = model.state_dim if isinstance(model, AbstractStateSpaceModel) else 0
        birth = legacy_mixture("birth", deprecated, birth, n, required=True)
        initial = legacy_mixture("initial", deprecated, initial, n, required=False)
        reduction = legacy_reduction(deprecated, reduction, allow_string=False)
        reject_unknown("GMCPHD", deprecated)
        if reduction.stonesoup_update:
            raise InputError("`reduction` must be a VoMaReduction for the GM-CPHD (Stone Soup's conventions are "
                             "its GM-PHD's).")
        fields = _common_fields(
            filter, model, prob_survival=prob_survival, prob_detect=prob_detect, birth=birth, capacity=capacity,
            reduction=reduction, gate=gate, max_estimates=max_estimates,
        )
        for name, value in fields.items():  # no extraction threshold: the CPHD extracts by MAP cardinality
            setattr(self, name, value)
        N = self.max_cardinality = _positive_int("max_cardinality", max_cardinality)  # N_max
        self.clutter_rate = _scalar("clutter_rate", clutter_rate, low=0.0)
        if clutter_spatial_density is not None:
            raise InputError(
                "GMCPHD: `clutter_spatial_density` was read as c = 1/V up to jaxtrack 0.1.0; jaxtrack now uses Stone Soup's "
                "meaning everywhere (κ = λ/V, points per unit volume per scan), so it is refused for one release "
                "rather than silently reread: pass `clutter_volume=V` (c = 1/V) or `clutter_density=κ`.")
        if (clutter_volume is None) == (clutter_density is None):
            raise InputError("GMCPHD: give `clutter_rate` with exactly one of `clutter_volume` (V, c = 1/V) and "
                             "`clutter_density` (κ = λ/V).")
        if clutter_density is not None:
            kappa = _scalar("clutter_density", clutter_density, low=0.0, open_low=True)
            if is_concrete(self.clutter_rate) and not float(self.clutter_rate) > 0.0:
                raise InputError("`clutter_density` needs `clutter_rate` > 0 (c = κ/λ); give `clutter_volume`.")
            self.clutter_pdf = kappa / self.clutter_rate
        else:
            self.clutter_pdf = 1.0 / _scalar("clutter_volume", clutter_volume, low=0.0, open_low=True)
        self.truncation_tolerance = _scalar("truncation_tolerance", truncation_tolerance, low=0.0)
        mu = jnp.sum(self.birth_weights)
        if birth_cardinality is None:
            self.birth_cardinality, self.birth_tail = _poisson_pmf(mu, N)
        else:
            pg = jnp.asarray(birth_cardinality, float)
            if pg.ndim != 1 or not 1 <= pg.shape[0] <= N + 1:
                raise InputError(f"`birth_cardinality` must have shape (L,) with 1 <= L <= N_max + 1 = {N + 1}; "
                                 f"got {pg.shape}.")
            if is_concrete(pg):
                p = np.asarray(pg)
                if not (np.all(np.isfinite(p)) and np.all(p >= 0.0) and abs(p.sum() - 1.0) <= 1e-9):
                    raise InputError(f"`birth_cardinality` must be a pmf (>= 0, summing to 1); got {p}.")
                if is_concrete(mu) and abs(float(p @ np.arange(p.shape[0])) - float(mu)) > 1e-9 * max(1.0, float(mu)):
                    raise InputError(f"`birth_cardinality` has mean {float(p @ np.arange(p.shape[0]))}; the birth "
                                     f"intensity's mass Σ birth_weights is {float(mu)} (they must agree).")
            self.birth_cardinality = jnp.zeros((N + 1,), pg.dtype).at[: pg.shape[0]].set(pg)
            self.birth_tail = jnp.zeros((), pg.dtype)
        self.initial = _initial_mixture_checked(initial, model.state_dim, self.capacity, "capacity")

    # ------------------------------------------------------------------------------------------
    def init(self) -> CPHDState:
        """The state before the first scan. Without ``initial_*``: no target for sure
        (``p_0 = δ_0``, empty mixture; births enter in the first predict). With them: a Poisson
        RFS, the intensity ``initial_*`` and ``p_0`` Poisson with mean ``μ_0 = Σ initial_weights``
        (the i.i.d. cluster form of a Poisson RFS; its mass above ``N_max``, ``P(N_max + 1, μ_0)``,
        is removed, the pmf renormalised, and the mass counted in ``truncated_mass``)."""
        N, dtype = self.max_cardinality, self.birth_means.dtype
        mixture = _initial_mixture(self)
        if self.initial_weights.shape[0] == 0:
            pmf, tail = jnp.zeros((N + 1,), dtype).at[0].set(1.0), jnp.zeros((), dtype)
        else:
            pmf, tail = _poisson_pmf(jnp.sum(self.initial_weights).astype(dtype), N)
            pmf = pmf / jnp.sum(pmf)
        return CPHDState(mixture, pmf, tail, jnp.ones((), bool))

    def predict(self, state: CPHDState):
        """Prediction: the intensity as :meth:`GMPHD.predict` (same tuple, ``J_max + B`` rows) and
        :meth:`predict_cardinality`. **Returns:** ``(predicted, predicted_pmf, truncated_mass)``."""
        return (_predict_intensity(self, state.mixture), *self.predict_cardinality(state.cardinality_pmf))

    def predict_cardinality(self, pmf):
        r"""``p_{k|k-1}(n) = Σ_j p_Γ(n − j) Σ_{l≥j} C(l, j) P_S^j (1 − P_S)^{l−j} p(l)``, ``n <= N_max``.

        **Returns:** ``(predicted, truncated_mass)``: ``(N_max + 1,)`` and the mass the full
        convolution puts above ``N_max`` (plus the birth pmf's own tail beyond ``N_max``).
        """
        N = self.max_cardinality
        j = jnp.arange(N + 1)[:, None]
        l = jnp.arange(N + 1)[None, :]
        d = jnp.maximum(l - j, 0)
        log_binom = gammaln(l + 1.0) - gammaln(j + 1.0) - gammaln(d + 1.0)
        log_t = log_binom + _log_pow(j, self.prob_survival) + _log_pow(d, 1.0 - self.prob_survival)
        # Binomial thinning: each of l targets survives independently with P_S.
        survivors = jnp.where(l >= j, jnp.exp(jnp.where(l >= j, log_t, 0.0)), 0.0) @ pmf
        full = jnp.convolve(survivors, self.birth_cardinality)  # (2N + 1,): targets = survivors + births
        truncated = jnp.sum(full[N + 1:]) + self.birth_tail * jnp.sum(survivors)
        return full[: N + 1], truncated

    def update(self, predicted, predicted_pmf, measurements, valid, k):
        r"""The CPHD update of the intensity and the cardinality on one padded scan (module docstring).

        **Arguments:** ``predicted``: :meth:`GMPHD.predict`'s tuple (``J_max + B`` rows);
        ``predicted_pmf`` ``(N_max + 1,)``; ``measurements`` ``(M, m)``, ``valid`` ``(M,)``; ``k``: the step.

        **Returns:** ``(weights, means, covs, active, pmf, ok)``: the GM-PHD's ``(1 + M)·J`` slot
        layout, the updated pmf ``(N_max + 1,)`` and whether everything came out finite.
        """
        w, m, P, active, _ = predicted
        loglik, pair, cond = _pair_likelihoods(self, m, P, active, measurements, valid, k)
        pd, lam, c = self.prob_detect, self.clutter_rate, self.clutter_pdf
        w = jnp.where(active, w, 0.0)
        log_w = _log(w)
        mass = jnp.sum(w)  # N_{k|k-1} = ⟨1, v⟩
        log_mass = _log(mass)
        log_mass = jnp.where(jnp.isfinite(log_mass), log_mass, 0.0)  # no components: every term has j + u = 0 or e_j = 0
        # log Λ_z = log(P_D Σ_i w_i q_i(z) / c); padding and gated-out pairs are −inf already.
        log_lam_z = jnp.where(valid, jnp.log(pd) + _lse(log_w[:, None] + loglik, axis=0) - jnp.log(c), -jnp.inf)
        M = log_lam_z.shape[0]
        num = jnp.sum(valid).astype(jnp.int32)
        log_e = _log_esf(log_lam_z)  # (M + 1,)
        # e_j(Ξ ∖ {Λ_z}) for each z: the recursion again with that entry removed (O(M²) each).
        log_e_loo = jax.vmap(lambda z: _log_esf(jnp.where(jnp.arange(M) == z, -jnp.inf, log_lam_z)))(jnp.arange(M))
        n = jnp.arange(self.max_cardinality + 1)[:, None]
        jj = jnp.arange(M + 1)[None, :]

        def log_upsilon(log_e_, size, u):
            ju = jj + u
            feasible = (jj <= size) & (ju <= n)
            t = (_log_pow(size - jj, lam) + gammaln(n + 1.0) - gammaln(jnp.maximum(n - ju, 0) + 1.0)
                 + _log_pow(n - ju, 1.0 - pd) - ju * log_mass + log_e_[None, :])
            return _lse(jnp.where(feasible, t, -jnp.inf), axis=1)  # (N_max + 1,)

        log_p = _log(predicted_pmf)
        log_joint = log_upsilon(log_e, num, 0) + log_p  # log Υ^0[Z](n) p_{k|k-1}(n)
        log_norm = _lse(log_joint)  # log ⟨Υ^0[Z], p⟩: −inf when no hypothesis explains Z (ok False)
        pmf = jnp.exp(log_joint - log_norm)
        log_r_miss = _lse(log_upsilon(log_e, num, 1) + log_p) - log_norm
        log_r_det = _lse(jax.vmap(lambda le: log_upsilon(le, num - 1, 1))(log_e_loo) + log_p[None, :], axis=1) - log_norm
        w_miss = jnp.where(active, (1.0 - pd) * w * jnp.exp(log_r_miss), 0.0)
        log_det = jnp.log(pd) + log_w[:, None] + loglik - jnp.log(c) + log_r_det[None, :]
        w_det = jnp.where(pair, jnp.exp(jnp.where(pair, log_det, -jnp.inf)), 0.0)
        weights, means, covs, out_active = _updated_layout(w_miss, active, w_det, pair, m, P, cond)
        ok = jnp.isfinite(log_norm) & jnp.all(jnp.isfinite(pmf)) & jnp.all(jnp.isfinite(weights))
        return weights, means, covs, out_active, pmf, ok

    def step(self, state: CPHDState, measurements, valid) -> tuple[CPHDState, GMCPHDStepInfo]:
        """One scan: :meth:`predict`, :meth:`update`, the GM-PHD's reduction (:meth:`GMPHD.reduce`).

        **Arguments:** ``state``: the :class:`CPHDState` after scan ``k − 1`` (or :meth:`init`);
        ``measurements`` ``(M, m)`` in the sensor's units (padding may be NaN); ``valid`` ``(M,)`` bool.
        """
        mixture = state.mixture
        dtype = mixture.weights.dtype
        measurements = jnp.asarray(measurements, dtype)
        valid = jnp.asarray(valid, bool)
        predicted, predicted_pmf, truncated = self.predict(state)
        w, m, P, active, pmf, ok = self.update(predicted, predicted_pmf, measurements, valid, mixture.step)
        ok = ok & scan_ok(measurements, valid)
        updated_mass = jnp.sum(jnp.where(active, w, 0.0))
        w, m, P, active, n_drop, w_drop, n_pruned = self.reduction(w, m, P, active, self.capacity,
                                                                   self.birth_means[0], self.birth_covs[0])
        new_mixture = GMPHDMixture(w, m, P, active, mixture.step + 1, mixture.num_dropped + n_drop,
                                   mixture.dropped_weight + w_drop, mixture.num_unreported)
        new = CPHDState(new_mixture, pmf, state.truncated_mass + truncated, state.ok & ok)
        new = eqx.tree_at(lambda s: s.mixture.num_unreported, new, mixture.num_unreported + self._unreported(new))
        return new, GMCPHDStepInfo(predicted_pmf, truncated, updated_mass, n_drop, w_drop, n_pruned, ok)

    def estimates(self, state: CPHDState) -> Estimates:
        """The reported targets (:meth:`_extract`): :class:`~jaxtrack.multitarget.Estimates`, ``ids``
        the row index (−1 where masked; the GM-CPHD has no labels)."""
        states, mask, _ = self._extract(state)
        return Estimates(states, mask, jnp.where(mask, jnp.arange(self.max_estimates, dtype=jnp.int32), -1))

    def capacity_events(self, state: CPHDState) -> Int[Array, ""]:
        """Components the reduction left over for want of slots, plus estimates beyond the
        ``max_estimates`` slots (not reported), summed over the scans so far."""
        return state.mixture.num_dropped + state.mixture.num_unreported

    def _unreported(self, state: CPHDState) -> Int[Array, ""]:
        """Targets of the MAP cardinality (at most the active components) beyond ``max_estimates``."""
        n = jnp.minimum(state.map_cardinality, jnp.sum(state.mixture.active))
        return jnp.maximum(n - self.max_estimates, 0).astype(jnp.int32)

    def capacity_message(self, events: int) -> str:
        return (f"the GM-CPHD's budgets were too small: {events} components left over by the reduction "
                f"(capacity {self.capacity}) or estimates beyond max_estimates={self.max_estimates} (not "
                "reported); raise `capacity` or `max_estimates`")

    def _extract(self, state: CPHDState):
        r"""Multi-target state extraction: ``n̂ = argmax_n p_k(n)`` (MAP cardinality), then the
        means of the ``n̂`` heaviest components (fewer if fewer are active), padded to ``max_estimates``.

        **Returns:** ``(states, mask, n̂)``: ``(E, n)``, ``(E,)`` bool and ``()`` int.
        """
        mixture = state.mixture
        n_hat = state.map_cardinality
        w = jnp.where(mixture.active, mixture.weights, -jnp.inf)
        order = jnp.argsort(-w, stable=True)
        E = self.max_estimates
        src = order[jnp.minimum(jnp.arange(E), order.shape[0] - 1)]
        mask = (jnp.arange(E) < n_hat) & mixture.active[src]
        states = jnp.where(mask[:, None], mixture.means[src], 0.0)
        return states, mask, n_hat


def _record_cphd(cphd, state, info):
    states, mask, count = cphd._extract(state)
    mix = state.mixture
    return (mix.weights, mix.means, mix.covs, mix.active, state.cardinality_pmf, state.mean_cardinality,
            state.map_cardinality, mix.cardinality, info.updated_intensity_mass, info.truncated_mass,
            states, mask, count, info.num_dropped, info.dropped_weight, info.ok)


def _run_cphd(cphd, measurements, valid):
    final, outs = scan_method(cphd, measurements, valid, _record_cphd)
    truncated = jnp.any(outs[9] > cphd.truncation_tolerance)
    return CPHDResult(*outs, final.mixture.overflow, truncated, final)


def run_cphd(cphd: GMCPHD, measurements: ArrayLike, valid: ArrayLike, *, warn: bool = True) -> CPHDResult:
    """Run a GM-CPHD filter over ``T`` scans: one jitted ``lax.scan`` of :meth:`GMCPHD.step`.

    **Arguments:** ``cphd``: the :class:`GMCPHD`; ``measurements`` ``(T, M, m)`` padded scans in
    the sensor's units (padding may be NaN), ``valid`` boolean ``(T, M)``; ``warn``: on the host
    (concrete results only), a :class:`CapacityWarning` when the reduction left components over or
    the predicted cardinality put more than ``truncation_tolerance`` above ``N_max`` in some scan,
    and a ``RuntimeWarning`` when an update was not finite.

    **Returns:** a :class:`CPHDResult`.

    **Raises:** :class:`~jaxtrack.InputError` naming ``cphd``, ``measurements`` or ``valid``.
    """
    if not isinstance(cphd, GMCPHD):
        raise InputError(f"`cphd` must be a GMCPHD; got {type(cphd).__name__}.")
    measurements, valid = check_scans(measurements, valid, cphd.model.meas_dim)
    result = _run_cphd(cphd, measurements, valid)
    if warn:
        warn_capacity(cphd, cphd.capacity_events(result.final))
        if is_concrete(result.truncated) and bool(result.truncated):
            warnings.warn(
                f"the GM-CPHD's cardinality budget (max_cardinality = {cphd.max_cardinality}) was too small: "
                f"up to {float(jnp.max(result.truncated_mass)):.3g} of the predicted cardinality mass per scan lay "
                "above it (reported in `truncated_mass`); raise `max_cardinality`.",
                CapacityWarning,
                stacklevel=2,
            )
        if is_concrete(result.ok) and not bool(jnp.all(result.ok)):
            bad = np.flatnonzero(~np.asarray(result.ok))
            warnings.warn(f"the GM-CPHD update was not finite at scans {bad.tolist()} (see `ok`).", RuntimeWarning,
                          stacklevel=2)
    return result

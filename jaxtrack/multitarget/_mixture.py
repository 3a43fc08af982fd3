r"""Gaussian mixtures as the random-finite-set filters take them, and how a mixture is reduced.

- :class:`GaussianMixture`: weights, means and covariances of ``B`` components, checked once — a
  birth intensity ``γ(x) = Σ_b w_b N(x; m_b, P_b)`` or a time-0 intensity, for the GM-PHD,
  GM-CPHD, PMB and PMBM filters alike.
- The **mixture-reduction strategy** every Gaussian-mixture filter applies to its intensity (the
  GM-PHD/GM-CPHD after each update, the PMB/PMBM Poisson part after each prediction):
  :class:`VoMaReduction` (Vo & Ma 2006, Table II: prune ``w ≤ T``; each pass the heaviest
  remaining component absorbs every one within squared Mahalanobis distance ``U``, measured with
  the candidate's covariance) and :class:`StoneSoupReduction` (Stone Soup's ``PHDUpdater`` +
  ``GaussianMixtureReducer`` conventions, for comparisons with it: the differences are listed on
  the class). The numerics are in :mod:`._reduction`.

Both strategies are Modules whose thresholds are array leaves (no recompilation when they change).
"""

from __future__ import annotations

import warnings
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError, is_concrete


class GaussianMixture(eqx.Module):
    r"""A Gaussian mixture ``Σ_b w_b N(x; m_b, P_b)`` of ``B`` components: an intensity (PHD).

    **Arguments and fields:**

    - ``weights`` ``(B,)``: finite, ``>= 0``; for an intensity, the expected number of targets
      each component holds (a birth intensity: expected births per scan).
    - ``means`` ``(B, n)``: in the state's units and layout (``model.state_layout``).
    - ``covs`` ``(B, n, n)``: symmetric positive definite, in the state's units squared.

    A single component may be given unbatched: ``GaussianMixture(0.1, m, P)`` with ``m`` ``(n,)``
    and ``P`` ``(n, n)``.

    **Raises:** :class:`~jaxtrack.InputError` naming ``weights``, ``means`` or ``covs`` (shape, a
    negative or non-finite weight, a covariance that is not symmetric positive definite; values
    are checked when concrete).

    Example (the Williams 2015 birth intensity)::

        birth = GaussianMixture([0.005], [[100.0, 100.0, 0.0, 0.0]], [np.diag([150.0**2, 150.0**2, 1.0, 1.0])])
    """

    weights: Float[Array, " B"]
    means: Float[Array, "B n"]
    covs: Float[Array, "B n n"]

    def __init__(self, weights: ArrayLike, means: ArrayLike, covs: ArrayLike):
        w, m, c = (jnp.asarray(a, float) for a in (weights, means, covs))
        if w.ndim == 0 and m.ndim == 1 and c.ndim == 2:  # one component, unbatched
            w, m, c = w[None], m[None], c[None]
        if w.ndim != 1 or w.shape[0] < 1:
            raise InputError(f"`weights` must have shape (B,) with B >= 1; got {w.shape}.")
        B = w.shape[0]
        if m.ndim != 2 or m.shape[0] != B:
            raise InputError(f"`means` must have shape ({B}, n) (one row per weight); got {m.shape}.")
        n = m.shape[1]
        if c.shape != (B, n, n):
            raise InputError(f"`covs` must have shape ({B}, {n}, {n}); got {c.shape}.")
        if is_concrete(w) and not (np.all(np.asarray(w) >= 0.0) and np.all(np.isfinite(np.asarray(w)))):
            raise InputError(f"`weights` must be finite and >= 0; got {np.asarray(w)}.")
        if is_concrete(m) and not np.all(np.isfinite(np.asarray(m))):
            raise InputError("`means` must be finite.")
        if is_concrete(c):
            cc = np.asarray(c)
            if not np.all(np.isfinite(cc)) or not np.allclose(cc, np.swapaxes(cc, -1, -2), rtol=1e-8, atol=0.0):
                raise InputError("`covs` must be finite and symmetric.")
            if np.any(np.linalg.eigvalsh(cc) <= 0.0):
                raise InputError("`covs` must be positive definite.")
        self.weights, self.means, self.covs = w, m, c

    @property
    def num_components(self) -> int:
        """``B``."""
        return self.weights.shape[0]

    @property
    def state_dim(self) -> int:
        """``n``."""
        return self.means.shape[1]

    @property
    def mass(self) -> Float[Array, ""]:
        """``Σ_b w_b``: the expected number of targets of the intensity."""
        return jnp.sum(self.weights)


def empty_mixture(n: int) -> tuple[Array, Array, Array]:
    """No component: ``(weights (0,), means (0, n), covs (0, n, n))``."""
    return jnp.zeros((0,)), jnp.zeros((0, n)), jnp.zeros((0, n, n))


def check_mixture(name: str, mixture, n: int, *, optional: bool = False) -> GaussianMixture | None:
    """``mixture`` as a :class:`GaussianMixture` of ``n``-state components, or
    :class:`~jaxtrack.InputError` naming ``name``."""
    if mixture is None and optional:
        return None
    if not isinstance(mixture, GaussianMixture):
        raise InputError(f"`{name}` must be a GaussianMixture(weights, means, covs); got {type(mixture).__name__}.")
    if mixture.state_dim != n:
        raise InputError(f"`{name}` has {mixture.state_dim}-state components; the model has {n} states.")
    return mixture


# ------------------------------------------------------------------------------------------------
# Reduction strategies.


def _threshold(name, value):
    x = jnp.asarray(value, float)
    if x.shape != ():
        raise InputError(f"`{name}` must be a scalar; got shape {x.shape}.")
    if is_concrete(x) and not (np.isfinite(float(x)) and float(x) >= 0.0):
        raise InputError(f"`{name}` must be finite and >= 0; got {float(x)}.")
    return x


class AbstractMixtureReduction(eqx.Module):
    """How a Gaussian-mixture filter prunes and merges its intensity into its ``capacity`` slots.

    ``prune_threshold`` (``T``) and ``merge_threshold`` (``U``, a squared Mahalanobis distance) are
    array leaves. ``stonesoup_update`` declares whether the GM-PHD update follows Stone Soup's
    conventions as well (no missed term for births, ``P_S`` on detected births, a zero weight
    raised to machine epsilon), so that the filter asks the strategy, not its type.
    """

    prune_threshold: Float[Array, ""]
    merge_threshold: Float[Array, ""]
    stonesoup_update: ClassVar[bool]

    def __call__(self, weights, means, covs, active, capacity: int, free_mean, free_cov):
        """Reduce ``(weights (K,), means (K, n), covs (K, n, n), active (K,))`` into ``capacity``
        slots (free slots hold ``free_mean``, ``free_cov``).

        **Returns:** ``(weights, means, covs, active, num_dropped, dropped_weight, num_pruned)``, the
        first four with ``capacity`` rows; what did not fit is counted, never stored.
        """
        from ._reduction import reduce_mixture

        return reduce_mixture(self.stonesoup_update, self.prune_threshold, self.merge_threshold, capacity,
                              free_mean, free_cov, weights, means, covs, active)


class VoMaReduction(AbstractMixtureReduction):
    r"""Vo & Ma (2006), Table II: with ``I = {i : w_i > T}``, each pass (at most ``J_max``) takes
    ``j = argmax_{i∈I} w_i``, ``L = {i ∈ I : (m_i − m_j)ᵀ P_i⁻¹ (m_i − m_j) ≤ U}`` and emits
    ``w̃ = Σ_L w_i``, ``m̃ = Σ_L w_i m_i / w̃``, ``P̃ = Σ_L w_i (P_i + (m̃ − m_i)(m̃ − m_i)ᵀ) / w̃``,
    then ``I ← I \ L``. What remains after ``J_max`` passes is counted (a capacity event).

    **Arguments:** ``prune_threshold``: ``T`` (default 1e-5); ``merge_threshold``: ``U``, a squared
    Mahalanobis distance (default 4, Vo & Ma's value).
    """

    stonesoup_update: ClassVar[bool] = False

    def __init__(self, prune_threshold: ArrayLike = 1e-5, merge_threshold: ArrayLike = 4.0):
        self.prune_threshold = _threshold("prune_threshold", prune_threshold)
        self.merge_threshold = _threshold("merge_threshold", merge_threshold)


class StoneSoupReduction(AbstractMixtureReduction):
    r"""Stone Soup's ``PHDUpdater`` + ``GaussianMixtureReducer``
    (``stonesoup/updater/pointprocess.py``, ``stonesoup/mixturereducer/gaussianmixture.py``), for a
    like-for-like comparison. It differs from Vo & Ma's Tables I–II in five places: an undetected
    birth component is dropped; a detected birth's weight is multiplied by ``P_S`` too; pruned
    weight (``w < T``) is spread evenly over the kept components; merging is pairwise against the
    running merged component, candidates in ascending weight order, with ``d < U``, the merged
    weight capped at 1 after every pair; a zero updated weight becomes machine epsilon. Not
    reproduced: the truncation to ``max_number_components`` (the budget here is the filter's
    ``capacity``, what exceeds it counted).

    **Arguments:** ``prune_threshold``: ``T`` (default 1e-5); ``merge_threshold``: ``U`` (default 4).
    """

    stonesoup_update: ClassVar[bool] = True

    def __init__(self, prune_threshold: ArrayLike = 1e-5, merge_threshold: ArrayLike = 4.0):
        self.prune_threshold = _threshold("prune_threshold", prune_threshold)
        self.merge_threshold = _threshold("merge_threshold", merge_threshold)


# ------------------------------------------------------------------------------------------------
# The former keyword arguments, for one release.

_REMOVED_IN = "0.3"


def legacy_mixture(kind: str, legacy: dict, given, n: int, *, required: bool):
    """``given`` (a :class:`GaussianMixture` or None), or one built from the deprecated
    ``{kind}_weights/means/covs`` keywords popped from ``legacy`` (with a ``DeprecationWarning``)."""
    keys = [f"{kind}_weights", f"{kind}_means", f"{kind}_covs"]
    old = [legacy.pop(k, None) for k in keys]
    if all(v is None for v in old):
        if given is None and required:
            raise InputError(f"`{kind}` is required: a GaussianMixture(weights, means, covs).")
        return check_mixture(kind, given, n, optional=not required)
    if given is not None:
        raise InputError(f"give `{kind}` or the deprecated `{kind}_weights/means/covs`, not both.")
    if old[0] is None or old[1] is None or old[2] is None:
        missing = [k for k, v in zip(keys, old) if v is None]
        raise InputError(f"`{missing[0]}` is missing: give `{kind}=GaussianMixture(weights, means, covs)`.")
    warnings.warn(f"`{kind}_weights`, `{kind}_means`, `{kind}_covs` are deprecated: pass "
                  f"`{kind}=GaussianMixture(weights, means, covs)`; they will be removed in jaxtrack {_REMOVED_IN}.",
                  DeprecationWarning, stacklevel=4)
    try:
        mixture = GaussianMixture(*old)
    except InputError as e:  # name the keyword the caller wrote
        raise InputError(str(e).replace("`weights`", f"`{keys[0]}`").replace("`means`", f"`{keys[1]}`")
                         .replace("`covs`", f"`{keys[2]}`")) from None
    return check_mixture(kind, mixture, n)


def legacy_reduction(legacy: dict, given, *, prefix: str = "", allow_string: bool = True):
    """``given`` (an :class:`AbstractMixtureReduction` or None: the default), or one built from the
    deprecated ``{prefix}prune_threshold``/``{prefix}merge_threshold`` keywords (and a ``"vo-ma"`` /
    ``"stonesoup"`` string for ``reduction``), with a ``DeprecationWarning``."""
    name = f"{prefix}reduction"
    thresholds = {k: legacy.pop(f"{prefix}{k}") for k in ("prune_threshold", "merge_threshold")
                  if f"{prefix}{k}" in legacy}
    kind = "vo-ma"
    if isinstance(given, str):
        if not allow_string or given not in ("vo-ma", "stonesoup"):
            raise InputError(f"`{name}` must be VoMaReduction(...) or StoneSoupReduction(...); got {given!r}.")
        kind, given = given, None
        thresholds.setdefault("_string", True)
    if given is not None:
        if thresholds:
            raise InputError(f"give `{name}` or the deprecated `{prefix}prune_threshold`/`{prefix}merge_threshold`, "
                             "not both.")
        if not isinstance(given, AbstractMixtureReduction):
            raise InputError(f"`{name}` must be VoMaReduction(...) or StoneSoupReduction(...); got "
                             f"{type(given).__name__}.")
        return given
    if not thresholds:
        return VoMaReduction()
    thresholds.pop("_string", None)
    new = "StoneSoupReduction" if kind == "stonesoup" else "VoMaReduction"
    warnings.warn(f"`{prefix}prune_threshold`, `{prefix}merge_threshold` and a string `reduction` are deprecated: "
                  f"pass `{name}={new}(prune_threshold, merge_threshold)`; they will be removed in jaxtrack "
                  f"{_REMOVED_IN}.", DeprecationWarning, stacklevel=4)
    try:
        return (StoneSoupReduction if kind == "stonesoup" else VoMaReduction)(**thresholds)
    except InputError as e:
        raise InputError(str(e).replace("`prune_threshold`", f"`{prefix}prune_threshold`")
                         .replace("`merge_threshold`", f"`{prefix}merge_threshold`")) from None


def reject_unknown(cls: str, legacy: dict) -> None:
    if legacy:
        raise InputError(f"{cls} got unexpected keyword arguments {sorted(legacy)}.")


def log_normalise(log_w: Array, mask: Array) -> tuple[Array, Array]:
    """``(log Σ_mask exp(log_w), log_w − that)`` over the rows where ``mask`` is True (``−inf``
    elsewhere): the normalisation of ranked hypotheses' log weights (PMBM, δ-GLMB), stable when the
    largest is far from 0 and 0 (not NaN) when no row is in ``mask``."""
    top = jnp.max(jnp.where(mask, log_w, -jnp.inf))
    top_safe = jnp.where(jnp.isfinite(top), top, 0.0)
    log_total = top_safe + jnp.log(jnp.sum(jnp.where(mask, jnp.exp(log_w - top_safe), 0.0)))
    return log_total, jnp.where(mask, log_w - log_total, -jnp.inf)

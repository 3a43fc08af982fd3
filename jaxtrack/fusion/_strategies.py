"""Fusion rules as strategy objects: one base, :class:`AbstractFusionRule`, and one class per rule
of :mod:`jaxtrack.fusion._rules` (the formulas live there; these hold their settings)."""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError
from ._rules import (
    DEFAULT_ITERATIONS,
    Criterion,
    FusedEstimate,
    _as_weight,
    _check_criterion,
    _check_iterations,
    bar_shalom_campo,
    covariance_intersection,
    ellipsoidal_intersection,
    independent_fusion,
    split_covariance_intersection,
)

# --------------------------------------------------------------------------------------------
# Strategy objects


class AbstractFusionRule(eqx.Module):
    """A track-to-track fusion rule: two estimates of one state → one :class:`FusedEstimate`.

    Concrete rules are final classes with their options as fields; the track-fusion run takes
    one as its ``rule``. Every rule acts on ONE pair (no batch axis); batches come from
    ``jax.vmap``.

    ``needs_cross_cov`` (class-level flag): True for rules that need the cross-covariance of
    the two estimates' errors (:class:`BarShalomCampo`); the others ignore it.
    """

    needs_cross_cov: ClassVar[bool] = False

    @abc.abstractmethod
    def fuse(
        self,
        mean1: Float[ArrayLike, " n"],
        cov1: Float[ArrayLike, "n n"],
        mean2: Float[ArrayLike, " n"],
        cov2: Float[ArrayLike, "n n"],
        *,
        cross_cov: Float[ArrayLike, "n n"] | None = None,
        independent_cov1: Float[ArrayLike, "n n"] | None = None,
        independent_cov2: Float[ArrayLike, "n n"] | None = None,
    ) -> FusedEstimate:
        """Fuse two estimates of the same state.

        **Arguments:**

        - ``mean1``, ``mean2``: ``(n,)``; ``cov1``, ``cov2``: ``(n, n)``, symmetric positive
          definite, in the state's units (squared).
        - ``cross_cov``: ``P_{12} = E[e_1 e_2ᵀ]``, ``(n, n)``, when known (used by
          :class:`BarShalomCampo`, required there).
        - ``independent_cov1``, ``independent_cov2``: the independent parts of ``cov1``,
          ``cov2``, ``(n, n)`` (used by :class:`SplitCovarianceIntersection`; None means 0).

        **Returns:** a :class:`FusedEstimate`.
        """


def _weight_field(omega):
    return None if omega is None else _as_weight(omega)


class _WeightedRule(AbstractFusionRule):
    """The fields and checks of the two rules with a weight ``ω`` (given, or optimal by ``criterion``)."""

    omega: Float[Array, ""] | None
    criterion: str = eqx.field(static=True)
    iterations: int = eqx.field(static=True)

    def __init__(self, omega: Float[ArrayLike, ""] | None = None, *, criterion: Criterion = "trace",
                 iterations: int = DEFAULT_ITERATIONS):
        _check_criterion(criterion)
        _check_iterations(iterations)
        self.omega = _weight_field(omega)
        self.criterion = criterion
        self.iterations = iterations


class CovarianceIntersection(_WeightedRule):
    """Covariance intersection (:func:`covariance_intersection`) as a fusion strategy.

    **Arguments:**

    - ``omega``: the weight ``ω ∈ [0, 1]`` of the first estimate (an array leaf: differentiable,
      and a concrete value outside ``[0, 1]`` raises ``InputError``), or None (default) for the
      optimal weight.
    - ``criterion``: ``"trace"`` (default) or ``"det"``: what the optimal weight minimises.
    - ``iterations``: bisection halvings of the optimal weight (default 64).
    """

    def fuse(self, mean1, cov1, mean2, cov2, *, cross_cov=None, independent_cov1=None, independent_cov2=None):
        return covariance_intersection(mean1, cov1, mean2, cov2, self.omega, criterion=self.criterion,
                                       iterations=self.iterations)


class SplitCovarianceIntersection(_WeightedRule):
    """Split covariance intersection (:func:`split_covariance_intersection`) as a fusion strategy.

    Reads the independent parts from ``fuse``'s ``independent_cov1``/``independent_cov2`` (the
    track-fusion run passes each local filter's part driven by its own measurement noise).

    **Arguments:** ``omega``, ``criterion``, ``iterations`` as for :class:`CovarianceIntersection`.
    """

    def fuse(self, mean1, cov1, mean2, cov2, *, cross_cov=None, independent_cov1=None, independent_cov2=None):
        return split_covariance_intersection(mean1, cov1, independent_cov1, mean2, cov2, independent_cov2,
                                             self.omega, criterion=self.criterion, iterations=self.iterations)


class EllipsoidalIntersection(AbstractFusionRule):
    """Ellipsoidal intersection (:func:`ellipsoidal_intersection`) as a fusion strategy.

    **Arguments:** ``zeta``: ``ζ`` of Sijs & Lazar's eq. (16c) (default: ``√ε`` of the dtype).
    """

    zeta: float | None = eqx.field(static=True, default=None)

    def fuse(self, mean1, cov1, mean2, cov2, *, cross_cov=None, independent_cov1=None, independent_cov2=None):
        return ellipsoidal_intersection(mean1, cov1, mean2, cov2, zeta=self.zeta)


class BarShalomCampo(AbstractFusionRule):
    """Bar-Shalom–Campo fusion (:func:`bar_shalom_campo`) as a fusion strategy; needs ``cross_cov``."""

    needs_cross_cov: ClassVar[bool] = True

    def fuse(self, mean1, cov1, mean2, cov2, *, cross_cov=None, independent_cov1=None, independent_cov2=None):
        if cross_cov is None:
            raise InputError("BarShalomCampo needs `cross_cov`, the cross-covariance of the two estimates' errors.")
        return bar_shalom_campo(mean1, cov1, mean2, cov2, cross_cov)


class IndependentFusion(AbstractFusionRule):
    """Independent (naive) fusion (:func:`independent_fusion`) as a fusion strategy."""

    def fuse(self, mean1, cov1, mean2, cov2, *, cross_cov=None, independent_cov1=None, independent_cov2=None):
        return independent_fusion(mean1, cov1, mean2, cov2)

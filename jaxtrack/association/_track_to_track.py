"""Track-to-track association: which track of one tracker and which of another follow the same target.

The test statistic is Bar-Shalom's track-to-track association test (Bar-Shalom 1981; Bar-Shalom,
Willett & Tian 2011, *Tracking and Data Fusion*, the track-to-track association chapter): for a
track ``i`` of tracker 1 and a track ``j`` of tracker 2, with ``Δ = x̂_1i − x̂_2j``, the hypothesis
"same target" is accepted when

.. math::

    d^2_{ij} = Δᵀ (P_{1i} + P_{2j})^{-1} Δ \\le γ,

``γ`` a χ² quantile with ``n`` degrees of freedom (``d²`` is χ²(n) under the hypothesis when
the two errors are independent; with the common process noise they are positively correlated,
the covariance of ``Δ`` is ``P_1 + P_2 − P_12 − P_21``, smaller, so the test is conservative:
it accepts at least as often as its nominal probability). The tracks are then paired by the
2-D assignment that minimises ``Σ d²`` over the accepted pairs (the global nearest-neighbour
track association), solved inside ``jit`` by :func:`~jaxtrack.association.linear_assignment`.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._validation import InputError, check_shape
from ._assignment import linear_assignment


class TrackToTrackAssignment(eqx.Module):
    """The pairing of two trackers' tracks (:func:`track_to_track_assignment`).

    **Fields** (``N_1``, ``N_2`` track slots):

    - ``pair`` ``(N_1,)`` int32: the slot of tracker 2 paired with slot ``i`` of tracker 1, or −1
      (masked, gated out, or no partner left).
    - ``distance_sq`` ``(N_1, N_2)``: ``d²_ij`` (dimensionless), ``+inf`` where either slot is masked.
    - ``total_cost`` ``()``: ``Σ d²`` over the pairs (0 when there are none).
    """

    pair: Int[Array, " N1"]
    distance_sq: Float[Array, "N1 N2"]
    total_cost: Float[Array, ""]


def check_gate(gate) -> float:
    """``gate`` as a Python float, or :class:`~jaxtrack.InputError` unless it is a concrete number > 0
    (``inf``: no gate)."""
    if isinstance(gate, bool) or not isinstance(gate, (int, float)) or math.isnan(gate) or not gate > 0:
        raise InputError(f"`gate` must be a positive number (a χ² threshold on d², inf for no gate); got {gate!r}.")
    return float(gate)


def track_to_track_assignment(
    means1: Float[ArrayLike, "N1 n"],
    covs1: Float[ArrayLike, "N1 n n"],
    mask1: Bool[ArrayLike, " N1"],
    means2: Float[ArrayLike, "N2 n"],
    covs2: Float[ArrayLike, "N2 n n"],
    mask2: Bool[ArrayLike, " N2"],
    gate: float,
) -> TrackToTrackAssignment:
    r"""Pair the tracks of two trackers by the 2-D assignment on Bar-Shalom's statistical distance.

    .. math::

        d^2_{ij} = (x̂_{1i} − x̂_{2j})ᵀ (P_{1i} + P_{2j})^{-1} (x̂_{1i} − x̂_{2j})

    (Bar-Shalom 1981; Bar-Shalom, Willett & Tian 2011, the track-to-track association test, with
    the cross-covariance taken as 0: the module docstring says why that is conservative). Pairs
    with ``d² > gate`` or a masked slot are forbidden; among the matchings of allowed pairs the
    one with the most pairs and, among those, the least ``Σ d²`` is returned
    (:func:`~jaxtrack.association.linear_assignment`). Static shapes: ``N_1``, ``N_2`` slots, the
    masks say which hold a track; jittable, vmappable.

    **Arguments:**

    - ``means1`` ``(N_1, n)``, ``covs1`` ``(N_1, n, n)``: tracker 1's track estimates in the state's
      units (and squared); ``mask1`` ``(N_1,)`` bool: the slots that hold a track. Masked slots
      must still hold a finite positive definite covariance (a tracker's empty slots do): they
      are solved and discarded, so that gradients stay finite.
    - ``means2`` ``(N_2, n)``, ``covs2`` ``(N_2, n, n)``, ``mask2`` ``(N_2,)``: tracker 2's.
    - ``gate``: ``γ``, the threshold on ``d²`` (dimensionless, > 0; ``scipy.stats.chi2.ppf(P, n)``
      for a test of size ``1 − P``, or ``inf`` for no gate; a static Python number).

    **Returns:** a :class:`TrackToTrackAssignment`.

    **Raises:** :class:`~jaxtrack.InputError` naming the argument for shapes that do not fit
    (``(N, n)``, ``(N, n, n)``, ``(N,)``, the same ``n`` on both sides) or a ``gate`` that is not
    a positive number.

    References: Y. Bar-Shalom, "On the track-to-track correlation problem", IEEE Trans. Automatic
    Control 26(2), 571–572, 1981; Y. Bar-Shalom, P. K. Willett and X. Tian, *Tracking and Data
    Fusion: A Handbook of Algorithms*, YBS Publishing, 2011.
    """
    gate = check_gate(gate)
    x1, P1, x2, P2 = (jnp.asarray(a) for a in (means1, covs1, means2, covs2))
    dtype = jnp.result_type(x1, P1, x2, P2, float)
    x1, P1, x2, P2 = (a.astype(dtype) for a in (x1, P1, x2, P2))
    check_shape("means1", x1, [(None, None)])
    N1, n = x1.shape
    check_shape("covs1", P1, [(N1, n, n)])
    check_shape("means2", x2, [(None, n)])
    N2 = x2.shape[0]
    check_shape("covs2", P2, [(N2, n, n)])
    m1, m2 = jnp.asarray(mask1, bool), jnp.asarray(mask2, bool)
    check_shape("mask1", m1, [(N1,)])
    check_shape("mask2", m2, [(N2,)])

    def distance_sq(xa, Pa, xb, Pb):
        delta = xa - xb
        # Cholesky of the sum: d² = |L⁻¹ Δ|², no explicit inverse.
        L = jnp.linalg.cholesky(Pa + Pb)
        w = jax.scipy.linalg.solve_triangular(L, delta, lower=True)
        return jnp.sum(w * w)

    d2 = jax.vmap(lambda xa, Pa: jax.vmap(lambda xb, Pb: distance_sq(xa, Pa, xb, Pb))(x2, P2))(x1, P1)
    both = m1[:, None] & m2[None, :]
    d2 = jnp.where(both, d2, jnp.inf)
    # A NaN distance (a covariance sum that is not positive definite) is forbidden, never paired.
    allowed = both & (d2 <= gate)
    pair, total = linear_assignment(d2, allowed)
    return TrackToTrackAssignment(pair, d2, total)

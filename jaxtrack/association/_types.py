"""What every association method takes and returns.

One input, one output, so trackers take the method as a strategy object (``../DESIGN``: "every
association method returns the same thing").

**The input** is a log-weight matrix ``L`` of shape ``(T, 1 + M)`` for ``T`` tracks (padded to a
capacity) and ``M`` measurements (padded to ``max_measurements``):

- column 0: the log weight of "track ``t`` is not detected in this scan", ``log(1 − P_D·P_G)``
  for PDA/JPDA (Bar-Shalom & Tse 1975; Stone Soup's ``PDAHypothesiser``), or
  ``log(1 − r·P_D·P_G)`` for a track with existence probability ``r`` (JIPDA);
- column ``j ≥ 1``: the log likelihood ratio of "measurement ``j − 1`` is track ``t``'s" against
  "it is clutter", ``log(P_D · N(z_j; ẑ_t, S_t) / λ)`` with ``λ`` the clutter spatial density
  (``log(r · P_D · N / λ)`` with existence ``r``);
- ``−inf`` where measurement ``j − 1`` is outside track ``t``'s gate or is padding.

This is the layout of Stone Soup's ``JPDAwithLBP`` likelihood matrix and of pyehm, so both serve
as oracles as they stand. Padded tracks are given by ``valid_tracks`` (False rows), not by the
values in their rows.

**The output** is an :class:`Association`: the marginal association probabilities
``β[t, j] = P(track t ↔ column j | scan)`` in ``L``'s shape (valid rows sum to 1, column 0 the
missed-detection probability; invalid rows are 0).
"""

from __future__ import annotations

import abc

import equinox as eqx
from jaxtyping import Array, Bool, Float


class Association(eqx.Module):
    """Marginal association probabilities of one scan (every association method's result).

    **Fields:**

    - ``association_probabilities``: ``β``, ``(T, 1 + M)``; ``β[t, 0]`` the probability that
      track ``t`` was not detected, ``β[t, j]`` that measurement ``j − 1`` is track ``t``'s.
      Rows of valid tracks sum to 1; rows of invalid (padded) tracks are 0. GNN gives one-hot rows.
    - ``clutter_probabilities``: ``(M,)``, the probability that measurement ``j`` is clutter
      (``1 − Σ_t β[t, j + 1]``). A column no track can take (outside every gate, or padding)
      gets 1: the method is not told which columns are padding, so mask with the scan's
      validity where it matters.
    - ``log_normalizer``: ``()``, ``log Σ_θ Π_t L[t, θ_t]`` over the joint events ``θ`` the method
      sums over (the scan's log likelihood ratio against "all clutter, no detection" for JPDA;
      the best event's log weight for GNN; BP's Bethe estimate).
    - ``residual``: ``()``, the largest change of a message in the last iteration (iterative
      methods; 0 for exact ones), so a caller can see whether a fixed iteration count converged.
    - ``ok``: ``()`` bool; False when the method could not answer within its static capacity
      (``overflow``), the result is not finite, or a valid track's row of ``L`` holds a NaN or
      ``+inf`` (``−inf`` is legal: gated out).
    - ``overflow``: ``()`` bool; True exactly when a static capacity was exceeded (JPDA's
      cluster caps ``max_cluster_tracks``, ``max_cluster_measurements``, ``max_large_clusters``),
      so that the marginals of the clusters beyond it are wrong (``ok`` is then False too).
      Distinct from a non-finite result. Always False for methods with no capacity (GNN, PDA,
      LoopyBP, and JPDA on a problem small enough to solve in one piece).
    """

    association_probabilities: Float[Array, "T Mp1"]
    clutter_probabilities: Float[Array, " M"]
    log_normalizer: Float[Array, ""]
    residual: Float[Array, ""]
    ok: Bool[Array, ""]
    overflow: Bool[Array, ""]


class AbstractAssociator(eqx.Module):
    """A data-association method: ``(L, valid_tracks) → Association``.

    Concrete methods (GNN, PDA, exact JPDA, loopy BP) are final classes with their options
    (iteration counts, capacities) as fields; trackers take one as their ``association=`` strategy.
    Every method acts on ONE scan (no batch axis); batches come from ``jax.vmap``.
    """

    @abc.abstractmethod
    def __call__(
        self,
        log_weights: Float[Array, "T Mp1"],
        valid_tracks: Bool[Array, " T"] | None = None,
    ) -> Association:
        """Associate one scan.

        **Arguments:**

        - ``log_weights``: ``L``, ``(T, 1 + M)``, as in :mod:`jaxtrack.association` (column 0
          missed detection, ``−inf`` outside the gate and for padded measurements).
        - ``valid_tracks``: optional boolean ``(T,)``; False rows are padding (default: all valid).

        **Returns:** an :class:`Association`.
        """

"""How the labelled filters (:mod:`._glmb`) generate their posterior hypotheses from the joint
prediction–update's cost tensor: a strategy object, as the projection is. :class:`MurtyRanking`
(the ``K`` best, exactly; the default) and :class:`GibbsSampling` (Vo, Vo & Hoang 2017 Sec. IV-B,
VVH17 below)."""

from __future__ import annotations

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .._validation import InputError
from ..association._gibbs import _check_exponent, gibbs_assignments
from ..association._murty import KBestAssignments, check_count, k_best_assignments

__all__ = ["AbstractLabelledRanking", "GibbsSampling", "MurtyRanking"]



class AbstractLabelledRanking(eqx.Module):
    """How a labelled filter generates its posterior hypotheses from the joint prediction–update's
    cost tensor (module docstring): :class:`MurtyRanking` (the ``K`` best, exactly) or
    :class:`GibbsSampling` (the ``K`` best of the distinct hypotheses a Gibbs sampler visits).
    ``hypotheses(cost, K, offsets, valid_parents, step)`` → a
    :class:`~jaxtrack.association.KBestAssignments` with ``K`` rows, ascending cost."""

    @abc.abstractmethod
    def hypotheses(self, cost: Float[Array, "R P C"], num: int, offsets: Float[Array, " R"],
                   valid_parents: Bool[Array, " R"], step: Int[Array, ""]) -> KBestAssignments:
        """Up to ``num`` posterior hypotheses: ``cost`` ``(R, P, A + 2P)`` (``−log η``),
        ``offsets`` ``(R,)`` (``−log w_h``), ``step`` the scan index."""


class MurtyRanking(AbstractLabelledRanking):
    """The ``K`` best posterior hypotheses over all prior ones, in order: Murty's ranked
    assignment with one shared queue (:func:`~jaxtrack.association.k_best_assignments`; VVH17
    Sec. IV-A). Exact; costs ``O(K·P³·(A + 2P))`` per scan. The default."""

    def hypotheses(self, cost, num, offsets, valid_parents, step):
        return k_best_assignments(cost, num, offsets=offsets, valid_parents=valid_parents)


class GibbsSampling(AbstractLabelledRanking):
    """The ``K`` cheapest distinct posterior hypotheses visited by the Gibbs sampler of VVH17
    Sec. IV-B (:func:`~jaxtrack.association.gibbs_assignments`): every prior hypothesis gives its
    best posterior hypothesis, and ``R·num_chains`` chains of ``num_sweeps`` systematic scans over
    the ``P`` candidates are shared over the prior hypotheses in proportion to ``w_h^α``
    (``α = weight_exponent``; ½, VVH17's ``√w_h``, by default), each candidate redrawn from
    ``η_i(·)`` over the choices the other candidates leave free. Not exact (the ``K`` best only
    once the samples cover them); costs ``O(R·num_chains·num_sweeps·P·(A + 2))`` per scan (a
    candidate is redrawn over the ``A`` measurement columns and its own "missed" and "absent",
    ``private_columns=2``) plus ``R`` Hungarian solves, so a large ``max_hypotheses`` is
    affordable.

    **Arguments:** ``num_chains``, ``num_sweeps``: static ints ``≥ 1`` (``R·(1 + num_chains·
    num_sweeps)`` samples a scan, ``R`` the prior hypothesis slots); ``seed``: int, the PRNG seed;
    ``weight_exponent``: static float ``≥ 0``, the allocation's ``α`` (0: every prior hypothesis
    the same number of chains). Scan ``k`` draws with ``fold_in(key(seed), k)``, so a run is
    reproducible and the same under ``jax.vmap`` (each run of a batch its own measurements, the
    same key stream; ``seed`` is an array leaf, so a batch of seeds can be vmapped too).

    Sharing one budget over the prior hypotheses, rather than ``num_chains`` per slot, is what
    keeps the first scans right: at scan 0 there is one prior hypothesis of ``H``, and with
    per-slot chains it got 17 samples (``GibbsSampling(2, 8)``) where the labeledRFS port draws
    1000; the filter then confirmed Vo & Vo's first targets a scan late (+13 m OSPA at scan 2,
    benchmarks/measured/labelled_reference.txt).

    The LMB has ONE prior hypothesis, so give it ``num_chains·num_sweeps ≥ max_hypotheses``:
    ``GibbsSampling(32, 16)`` at ``H = 256`` matches Murty's LMB (13.3 m OSPA on Vo & Vo's
    benchmark, ``benchmarks/glmb.py``) in 1.0 s against 2.9 s.
    """

    num_chains: int = eqx.field(static=True)
    num_sweeps: int = eqx.field(static=True)
    seed: Int[Array, ""]
    weight_exponent: float = eqx.field(static=True)

    def __init__(self, num_chains: int, num_sweeps: int, seed=0, weight_exponent: float = 0.5):
        self.num_chains = check_count("num_chains", num_chains)
        self.num_sweeps = check_count("num_sweeps", num_sweeps)
        seed_ = jnp.asarray(seed)
        if seed_.shape != () or not jnp.issubdtype(seed_.dtype, jnp.integer):
            raise InputError(f"`seed` must be an integer scalar; got {seed!r}.")
        self.seed = seed_
        self.weight_exponent = _check_exponent(weight_exponent)

    def hypotheses(self, cost, num, offsets, valid_parents, step):
        key = jax.random.fold_in(jax.random.key(self.seed), step)
        # The cost's "missed" and "absent" blocks are diagonal: a chain redraws a candidate over
        # the A measurement columns and its own two, not all A + 2P.
        return gibbs_assignments(cost, num, key=key, num_chains=self.num_chains, num_sweeps=self.num_sweeps,
                                 offsets=offsets, valid_parents=valid_parents,
                                 weight_exponent=self.weight_exponent, private_columns=2)

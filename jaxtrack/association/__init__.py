"""Data association: gating, likelihood-ratio matrices, assignment, PDA/JPDA marginals.

Pure functions of arrays for ONE scan (batches come from ``jax.vmap``); no track table here
(trackers live in :mod:`jaxtrack.multitarget`). Every method takes the same log-weight matrix
``L`` ``(T, 1 + M)`` (column 0: missed detection; ``−inf`` outside the gate) and returns the same
:class:`Association` (marginal association probabilities), so a tracker takes the method as a
strategy object:

- ``_types``: :class:`Association`, :class:`AbstractAssociator` (the input and output conventions);
- ``_gating``: :func:`gate_threshold` (χ² gates), :func:`measurement_likelihoods` (any filter's
  update on every measurement of a scan), :func:`log_likelihood_ratios` (the matrix ``L``);
- ``_assignment``: :func:`linear_assignment` (2-D assignment) and :class:`GNN`;
- ``_track_to_track``: :func:`track_to_track_assignment` (two trackers' tracks paired on
  Bar-Shalom's statistical distance, for track-to-track fusion) and :class:`TrackToTrackAssignment`;
- ``_murty``: :func:`k_best_assignments` (Murty's k best assignments over several cost matrices);
- ``_gibbs``: :func:`gibbs_assignments` (good assignments over several cost matrices by Gibbs
  sampling, Vo, Vo & Hoang 2017: Murty's result type at a cost linear in the samples);
- ``_jpda``: :class:`PDA`, :class:`JPDA` (exact marginals), :class:`LoopyBP` (belief propagation);
- ``_pda_update``: :func:`pda_update`, the PDA/JPDA mixture collapse of the conditioned moments.
"""

from ._types import (
    AbstractAssociator as AbstractAssociator,
    Association as Association,
)
from ._gating import (
    gate_threshold as gate_threshold,
    log_likelihood_ratios as log_likelihood_ratios,
    measurement_likelihoods as measurement_likelihoods,
)
from ._assignment import (
    GNN as GNN,
    linear_assignment as linear_assignment,
)
from ._track_to_track import (
    TrackToTrackAssignment as TrackToTrackAssignment,
    track_to_track_assignment as track_to_track_assignment,
)
from ._murty import (
    KBestAssignments as KBestAssignments,
    k_best_assignments as k_best_assignments,
)
from ._gibbs import gibbs_assignments as gibbs_assignments
from ._jpda import (
    JPDA as JPDA,
    PDA as PDA,
    LoopyBP as LoopyBP,
)
from ._pda_update import pda_update as pda_update

__all__ = [
    "AbstractAssociator",
    "Association",
    "gate_threshold",
    "log_likelihood_ratios",
    "measurement_likelihoods",
    "GNN",
    "linear_assignment",
    "track_to_track_assignment",
    "TrackToTrackAssignment",
    "KBestAssignments",
    "k_best_assignments",
    "gibbs_assignments",
    "JPDA",
    "PDA",
    "LoopyBP",
    "pda_update",
]

"""The crossing-targets scenario and the three trackers of the multi-target study.

The scenario is the library's :func:`jaxtrack.multitarget.crossing_targets` at its defaults:
4 targets at 20 m/s on lines through a point 5 km in front of a range–bearing radar
(σ_r = 10 m, σ_φ = 2 mrad), crossing near scan 50 of 100 (births staggered over the first 20
scans, deaths over the last 20), ``P_D`` = 0.9 and Poisson clutter of 10 points per scan,
uniform over the sector ``r ∈ [0, 10 km]``, ``φ ∈ [−45°, 45°]``.

The trackers (:func:`trackers`) share everything but the association and the track logic:
EKF prediction and update on the scenario's own model, a 99.9% χ² gate, one-point initiation
(an iterated EKF update of a broad prior, 3 km and 30 m/s standard deviations, on the
measurement) and a table of :data:`CAPACITY` slots.

- ``"gnn"``: :class:`~jaxtrack.association.GNN`, M-of-N confirmation :data:`CONFIRM_HITS` of
  :data:`CONFIRM_WINDOW`, deletion after :data:`DELETE_AFTER_MISSES` misses in a row;
- ``"jpda"``: :class:`~jaxtrack.association.JPDA` with the same logic;
- ``"jipda"``: JPDA with :class:`~jaxtrack.multitarget.IntegratedExistence` (``P_S`` = 0.99):
  also confirmed at existence :data:`CONFIRM_EXISTENCE`, deleted below
  :data:`DELETE_EXISTENCE`, a new track starting at existence :data:`JIPDA_INITIAL_EXISTENCE`.

**Why these settings** (measured on this scenario, study key, 32–64 runs; the study's docstring
in :mod:`.rows` has the table):

- *Every measurement no track claims starts a tentative track*, so with 10 clutter points per
  scan about 23 slots are in use on average and up to 42 at the peak (3-of-4 logic, 64 runs).
  A 24-slot table refused about 3,200 births per 32 runs; :data:`CAPACITY` = 48 refuses none
  (the study checks it: row MT7).
- *3-of-4 confirmation* rather than 2-of-3: with 2-of-3 two clutter points that happen to fall
  in one gate confirm a track, and GNN and JPDA confirmed ≈ 38 false tracks per run (mean GOSPA
  69 and 73 m at 24 slots); with 3-of-4 they confirm 0.2 and 1.9 and the GOSPA is 21 and 25 m.
  A true target (``P_D`` = 0.9) is confirmed within its first four scans with probability 0.97.
- *JIPDA's initial existence 0.02* rather than the initiator's default 0.5: the prior that an
  unclaimed measurement is a new target is about (4 births / 100 scans) / 10 clutter points =
  0.004; at 0.5 two hits lift a clutter track past the 0.9 confirmation threshold, and JIPDA
  confirmed 8.8 false tracks per run (mean GOSPA 32 m); at 0.1, 2.2 (22 m); at 0.02, 0.5 (20 m).
"""

from __future__ import annotations

import numpy as np

from ...association import GNN, JPDA
from ...filters import ExtendedKalmanFilter, IteratedExtendedKalmanFilter
from ...multitarget import (
    IntegratedExistence,
    OnePointInitiator,
    Scenario,
    Tracker,
    TrackManagement,
    crossing_targets,
)

CENTRE_RANGE = 5_000.0  # m, the crossing point's range (crossing_targets' default)
PRIOR_STD = (3_000.0, 3_000.0, 30.0, 30.0)  # m, m, m/s, m/s: the one-point initiator's prior
INITIATOR_ITERATIONS = 8  # iterated-EKF steps of the initiating update (a far-away prior mean)
PROB_DETECT = 0.9
PROB_GATE = 0.999
CAPACITY = 48
CONFIRM_HITS = 3
CONFIRM_WINDOW = 4
DELETE_AFTER_MISSES = 3
PROB_SURVIVAL = 0.99
CONFIRM_EXISTENCE = 0.9
DELETE_EXISTENCE = 0.05
JIPDA_INITIAL_EXISTENCE = 0.02
CUTOFF = 100.0  # m, GOSPA's c
ORDER = 2.0  # GOSPA's p

TRACKERS = ("gnn", "jpda", "jipda")
LABELS = {"gnn": "GNN", "jpda": "JPDA", "jipda": "JIPDA"}


def scenario() -> Scenario:
    """The study's scenario: :func:`jaxtrack.multitarget.crossing_targets` at its defaults."""
    return crossing_targets(centre_range=CENTRE_RANGE)


def initiator(existence: float = 0.5) -> OnePointInitiator:
    """The one-point initiator: an iterated EKF update of ``N([R, 0, 0, 0], diag(PRIOR_STD²))``."""
    return OnePointInitiator(
        prior_mean=[CENTRE_RANGE, 0.0, 0.0, 0.0],
        prior_cov=np.diag(np.square(PRIOR_STD)),
        filter=IteratedExtendedKalmanFilter(num_iterations=INITIATOR_ITERATIONS),
        existence=existence,
    )


def trackers(scen: Scenario | None = None, capacity: int = CAPACITY) -> dict[str, Tracker]:
    """The three trackers, keyed by :data:`TRACKERS`, on ``scen``'s model (default :func:`scenario`)."""
    scen = scenario() if scen is None else scen
    logic = TrackManagement(CONFIRM_HITS, CONFIRM_WINDOW, DELETE_AFTER_MISSES)
    existence_logic = TrackManagement(CONFIRM_HITS, CONFIRM_WINDOW, DELETE_AFTER_MISSES,
                                      confirm_existence=CONFIRM_EXISTENCE, delete_existence=DELETE_EXISTENCE)
    common = dict(prob_detect=PROB_DETECT, clutter_density=scen.clutter_density, prob_gate=PROB_GATE,
                  capacity=capacity)
    ekf = ExtendedKalmanFilter()
    return {
        "gnn": Tracker(ekf, scen.model, GNN(), initiator(), management=logic, **common),
        "jpda": Tracker(ekf, scen.model, JPDA(), initiator(), management=logic, **common),
        "jipda": Tracker(ekf, scen.model, JPDA(), initiator(JIPDA_INITIAL_EXISTENCE), management=existence_logic,
                         existence=IntegratedExistence(PROB_SURVIVAL), **common),
    }

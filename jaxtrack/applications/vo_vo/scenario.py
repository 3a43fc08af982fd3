"""The labelled-RFS study's scenario and filters: Vo & Vo's linear benchmark
(:func:`jaxtrack.multitarget.vo_vo_linear`) with the δ-GLMB (:class:`~jaxtrack.multitarget.GLMB`)
and the LMB (:class:`~jaxtrack.multitarget.LMB`) filters, Kalman filter per component.

Budgets (static): ``N`` = :data:`MAX_TRACKS` track slots per hypothesis, ``H`` =
:data:`MAX_HYPOTHESES` hypotheses (Murty's ranked assignment over all prior hypotheses at once),
:data:`ASSIGNMENT_MEASUREMENTS` gated measurement columns, a Mahalanobis gate of :data:`GATE`.
Measured on 8 runs (benchmarks/glmb.py): H = 32, N = 16 run 5.3 s (δ-GLMB) and 2.9 s (LMB) a run
on this repository's 2-core CPU; H = 64, N = 24 cost 6x more for 0.7 m less mean OSPA. The LMB
prunes labels at ``r`` ≤ :data:`LMB_EXISTENCE_THRESHOLD` (the toolbox's track threshold): at the
library's 1e-5 lingering birth labels filled the 16 slots (18 capacity events in 8 runs).
"""

from __future__ import annotations

from ...filters import KalmanFilter
from ...multitarget import GLMB, LMB, Scenario, VoVoLinearSettings, vo_vo_linear

MAX_TRACKS = 16
MAX_HYPOTHESES = 32
ASSIGNMENT_MEASUREMENTS = 24
GATE = 4.0
LMB_EXISTENCE_THRESHOLD = 1e-3

METHODS = ("glmb", "lmb")
LABELS = {"glmb": "δ-GLMB", "lmb": "LMB"}


def scenario(num_steps: int | None = None) -> tuple[Scenario, VoVoLinearSettings]:
    """The benchmark (:func:`jaxtrack.multitarget.vo_vo_linear`), all 100 scans or the first
    ``num_steps`` (short tests)."""
    return vo_vo_linear() if num_steps is None else vo_vo_linear(num_steps=num_steps)


def methods(scen: Scenario | None = None, settings: VoVoLinearSettings | None = None, *,
            max_hypotheses: int = MAX_HYPOTHESES, max_tracks: int = MAX_TRACKS) -> dict:
    """The two filters, keyed by :data:`METHODS`, with the benchmark's settings."""
    if scen is None or settings is None:
        scen, settings = scenario()
    s = settings
    common = dict(prob_survival=s.prob_survival, prob_detect=s.prob_detect, clutter_density=s.clutter_density,
                  birth=s.birth, max_tracks=max_tracks, max_hypotheses=max_hypotheses, gate=GATE,
                  assignment_measurements=ASSIGNMENT_MEASUREMENTS)
    return {
        "glmb": GLMB(KalmanFilter(), scen.model, **common),
        "lmb": LMB(KalmanFilter(), scen.model, existence_threshold=LMB_EXISTENCE_THRESHOLD, **common),
    }

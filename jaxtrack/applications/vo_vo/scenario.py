"""The labelled-RFS study's scenario and filters: Vo & Vo's linear benchmark
(:func:`jaxtrack.multitarget.vo_vo_linear`) with the δ-GLMB (:class:`~jaxtrack.multitarget.GLMB`)
and the LMB (:class:`~jaxtrack.multitarget.LMB`) filters, Kalman filter per component.

Budgets (static): ``N`` = :data:`MAX_TRACKS` track slots per hypothesis, ``H`` =
:data:`MAX_HYPOTHESES` hypotheses per filter, :data:`ASSIGNMENT_MEASUREMENTS` gated measurement
columns, a Mahalanobis gate of :data:`GATE`. Both filters draw their hypotheses by Gibbs sampling
(:data:`GLMB_RANKING`, :data:`LMB_RANKING`; Vo, Vo & Hoang 2017 Sec. IV-B): the δ-GLMB 128 of them,
its chains shared over the prior hypotheses by √w, the LMB 256 from 64 chains of 16 sweeps.
Against the labeledRFS port on the same 100 runs (benchmarks/labelled_reference.py,
benchmarks/measured/labelled_reference.txt, one core each): the δ-GLMB's time-averaged OSPA is
+0.48 ± 0.20 m above the port's (1.4 s a run; +0.81 ± 0.22 m before equal hypotheses merged at 1e-9
of the slot's scale), +0.17 ± 0.18 m at H = 256 (2.2 s) and 0.45 ± 0.14 m
BELOW it at H = 512 (8.4 s; closer to the truth than the port, whose 1,000 samples are a budget
too; 17 scans in 100 runs had gated measurements beyond the 24 columns). The LMB keeps
:data:`LMB_COMPONENTS` Gaussian components a label (the port's ``L_max``) and is +0.05 ± 0.05 m
from the port, 98 of 100 scans within 2 SE (cardinality 99/100), at 0.6 s a run; with one Gaussian
a label (moment matched) it was +0.49 ± 0.17 m, 87/100. (The H = 512 figures are of the sampler
before its private columns and of the earlier merge.) The LMB prunes labels at
``r`` ≤ :data:`LMB_EXISTENCE_THRESHOLD` (the toolbox's track threshold): at the library's 1e-5
lingering birth labels filled the 16 slots (18 capacity events in 8 runs).
"""

from __future__ import annotations

from ...filters import KalmanFilter
from ...multitarget import GLMB, LMB, GibbsSampling, Scenario, VoVoLinearSettings, vo_vo_linear

MAX_TRACKS = 16
MAX_HYPOTHESES = {"glmb": 128, "lmb": 256}
# Two chains of eight sweeps per prior hypothesis slot: 256 chains a scan, shared over the prior
# hypotheses in proportion to √w (VVH17; GibbsSampling's docstring), 2,304 samples in all. The LMB
# has one prior hypothesis: its 64 chains of 16 sweeps (1,025 samples) match the port's 1,000.
GLMB_RANKING = GibbsSampling(num_chains=2, num_sweeps=8)
LMB_RANKING = GibbsSampling(num_chains=64, num_sweeps=16)
ASSIGNMENT_MEASUREMENTS = 24
GATE = 4.0
LMB_EXISTENCE_THRESHOLD = 1e-3
# Gaussian components each LMB label keeps (LMBProjection; the port's L_max = 10, pruned below
# 1e-5 and merged within a squared Mahalanobis distance of 4, VoMaReduction's defaults).
LMB_COMPONENTS = 10

METHODS = ("glmb", "lmb")
LABELS = {"glmb": "δ-GLMB", "lmb": "LMB"}


def scenario(num_steps: int | None = None) -> tuple[Scenario, VoVoLinearSettings]:
    """The benchmark (:func:`jaxtrack.multitarget.vo_vo_linear`), all 100 scans or the first
    ``num_steps`` (short tests)."""
    return vo_vo_linear() if num_steps is None else vo_vo_linear(num_steps=num_steps)


def methods(scen: Scenario | None = None, settings: VoVoLinearSettings | None = None, *,
            max_hypotheses: int | None = None, max_tracks: int = MAX_TRACKS) -> dict:
    """The two filters, keyed by :data:`METHODS`, with the benchmark's settings;
    ``max_hypotheses`` (an int) replaces both filters' :data:`MAX_HYPOTHESES` (short tests)."""
    if scen is None or settings is None:
        scen, settings = scenario()
    s = settings
    H = MAX_HYPOTHESES if max_hypotheses is None else dict.fromkeys(METHODS, max_hypotheses)
    common = dict(prob_survival=s.prob_survival, prob_detect=s.prob_detect, clutter_density=s.clutter_density,
                  birth=s.birth, max_tracks=max_tracks, gate=GATE, assignment_measurements=ASSIGNMENT_MEASUREMENTS)
    return {
        "glmb": GLMB(KalmanFilter(), scen.model, max_hypotheses=H["glmb"], ranking=GLMB_RANKING, **common),
        "lmb": LMB(KalmanFilter(), scen.model, max_hypotheses=H["lmb"], existence_threshold=LMB_EXISTENCE_THRESHOLD,
                   ranking=LMB_RANKING, max_components=LMB_COMPONENTS, **common),
    }

"""The labelled-RFS study's scenario and filters: Vo & Vo's linear benchmark
(:func:`jaxtrack.multitarget.vo_vo_linear`) with the δ-GLMB (:class:`~jaxtrack.multitarget.GLMB`)
and the LMB (:class:`~jaxtrack.multitarget.LMB`) filters, Kalman filter per component.

Budgets (static): ``N`` = :data:`MAX_TRACKS` track slots per hypothesis, ``H`` =
:data:`MAX_HYPOTHESES` hypotheses per filter, :data:`ASSIGNMENT_MEASUREMENTS` gated measurement
columns, a Mahalanobis gate of :data:`GATE`. The δ-GLMB draws its 128 hypotheses by Gibbs sampling
(:data:`GLMB_RANKING`, Vo, Vo & Hoang 2017 Sec. IV-B), the LMB ranks its 32 with Murty's
algorithm. Measured on 8 runs (benchmarks/glmb.py, benchmarks/measured/glmb_gibbs.txt, 2-core
CPU): the δ-GLMB with Murty at H = 32 ran 4.1 s a run at a mean OSPA of 18.5 m (its truncation
loses targets: rows.py), with Gibbs at H = 128 3.1 s at 14.75 m (H = 512: 13.3 m at 16.8 s); the
LMB with Murty at H = 32 2.9 s at 13.4 m. The LMB
prunes labels at ``r`` ≤ :data:`LMB_EXISTENCE_THRESHOLD` (the toolbox's track threshold): at the
library's 1e-5 lingering birth labels filled the 16 slots (18 capacity events in 8 runs).
"""

from __future__ import annotations

from ...filters import KalmanFilter
from ...multitarget import GLMB, LMB, GibbsSampling, MurtyRanking, Scenario, VoVoLinearSettings, vo_vo_linear

MAX_TRACKS = 16
MAX_HYPOTHESES = {"glmb": 128, "lmb": 32}
# Two chains of eight sweeps per prior hypothesis slot: 256 chains a scan, shared over the prior
# hypotheses in proportion to √w (VVH17; GibbsSampling's docstring), 2,304 samples in all.
GLMB_RANKING = GibbsSampling(num_chains=2, num_sweeps=8)
LMB_RANKING = MurtyRanking()
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
                   ranking=LMB_RANKING,
                   **common),
    }

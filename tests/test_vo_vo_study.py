"""The labelled-RFS study (Vo & Vo's linear benchmark with the δ-GLMB and LMB filters).

The filters' steps are held to an exact enumeration in tests/test_glmb.py, and a short
``vo_vo_linear`` run and Monte Carlo run there; here: the study's filters are what it says, and
(``--runslow``) a short study gives its rows. The whole study runs in ``jaxtrack reproduce
labelled`` (``make run``).
"""

from __future__ import annotations

import numpy as np
import pytest

from jaxtrack.applications import vo_vo
from jaxtrack.applications.vo_vo.scenario import (
    ASSIGNMENT_MEASUREMENTS,
    GATE,
    LMB_EXISTENCE_THRESHOLD,
    MAX_HYPOTHESES,
    MAX_TRACKS,
)
from jaxtrack.multitarget import GLMB, LMB, DeltaGLMB, GibbsSampling, LMBProjection


def test_the_filters_are_what_the_study_says():
    scen, settings = vo_vo.scenario()
    m = vo_vo.methods(scen, settings)
    assert tuple(m) == vo_vo.METHODS == ("glmb", "lmb")
    assert isinstance(m["glmb"], GLMB) and isinstance(m["glmb"].projection, DeltaGLMB)
    assert isinstance(m["lmb"], LMB) and isinstance(m["lmb"].projection, LMBProjection)
    assert MAX_HYPOTHESES == {"glmb": 128, "lmb": 256}
    assert isinstance(m["glmb"].ranking, GibbsSampling)
    assert (m["glmb"].ranking.num_chains, m["glmb"].ranking.num_sweeps) == (2, 8)
    assert isinstance(m["lmb"].ranking, GibbsSampling)
    assert (m["lmb"].ranking.num_chains, m["lmb"].ranking.num_sweeps) == (64, 16)
    for name, f in m.items():
        assert (f.max_tracks, f.max_hypotheses, f.assignment_measurements) == (MAX_TRACKS, MAX_HYPOTHESES[name],
                                                                              ASSIGNMENT_MEASUREMENTS)
        assert float(f.gate) == GATE and float(f.prob_detect) == 0.98 and float(f.prob_survival) == 0.99
        assert float(f.clutter_density) == pytest.approx(66 / 2000**2)
    assert float(m["lmb"].existence_threshold) == LMB_EXISTENCE_THRESHOLD
    assert (scen.num_steps, scen.max_targets, float(scen.clutter_rate)) == (100, 12, 66.0)
    assert (settings.ospa_cutoff, settings.ospa_order) == (100.0, 1.0)


@pytest.mark.slow
def test_a_short_study_gives_every_row():
    study = vo_vo.run_study(2, num_steps=20, max_hypotheses=8, max_tracks=8)
    rows = vo_vo.paper_rows(study)
    assert [r.id for r in rows] == ["V1", "V2", "V3", "V4", "V5", "V6", "V7"]
    assert all(np.isfinite(r.value) for r in rows)
    assert rows[-1].value == 0.0  # no capacity event, overflow or failed scan

"""The Williams (2015) study: GM-PHD, GM-CPHD, PMB, PMBM and the JPDA tracker on `williams15()`.

At 2 runs (the notebook's small size: the same compiled blocks) the rows' margins, calibrated at
100 runs, are too tight to hold, so the fast tests check what holds at any size (no capacity
event, the rows' layout, the RMS GOSPA from its parts) and the 2-run means against the 100-run
values; the 100-run rows run with --runslow (and in `jaxtrack reproduce williams15`).
"""

from __future__ import annotations

import numpy as np
import pytest

from jaxtrack.applications import williams15 as w15
from jaxtrack.applications.williams15 import scenario as sc
from jaxtrack.association import JPDA
from jaxtrack.multitarget import GMCPHD, GMPHD, PMB, PMBM, Tracker

RUNS = 2


@pytest.fixture(scope="module")
def study():
    return w15.run_study(RUNS)


def test_methods_are_what_the_study_says():
    scen, settings = w15.scenario()
    m = w15.methods(scen, settings)
    assert tuple(m) == w15.METHODS == ("phd", "cphd", "pmb", "pmbm", "jpda")
    assert isinstance(m["phd"], GMPHD) and isinstance(m["cphd"], GMCPHD) and isinstance(m["jpda"], Tracker)
    assert isinstance(m["pmb"], PMB) and isinstance(m["pmb"].associator, JPDA) and isinstance(m["pmbm"], PMBM)
    assert (m["pmbm"].max_hypotheses, m["pmbm"].max_tracks) == (sc.PMBM_HYPOTHESES, sc.MAX_TRACKS)
    for name in ("pmb", "pmbm"):
        f = m[name]
        assert float(f.gate) ** 2 == pytest.approx(20.0) and float(f.existence_threshold) == 1e-5
        assert float(f.estimation_threshold) == 0.4 and float(f.initial_weights[0]) == 3.0
    assert (scen.num_steps, scen.max_targets, float(scen.clutter_rate)) == (81, 4, 10.0)
    assert float(settings.clutter_density) == pytest.approx(10 / 300**2)
    assert (settings.gospa_cutoff, settings.gospa_order, settings.num_runs) == (10.0, 2.0, 100)


def test_rows_and_rms(study):
    rows = w15.paper_rows(study)
    assert [r.id for r in rows] == ["W1", "W2", "W3", "W4", "W5", "W6", "W6", "W6", "W7"]
    assert all(r.source == "claim" and r.bound == "at_most" for r in rows)
    assert rows[-1].ok and rows[-1].value == 0  # no overflowed scan, no capacity event in any method
    for name in w15.METHODS:
        r = study.results[name]
        rms = study.rms_gospa(name)
        # E[d²] ≥ E[d]²: the RMS is at least the mean, scan by scan
        assert np.all(rms >= np.asarray(r.gospa) - 1e-9)
        assert np.all(np.isfinite(rms))

"""The Williams (2015) study: GM-PHD, GM-CPHD, PMB, PMBM and the JPDA tracker on `williams15()`.

The fast test checks the methods' settings; the study itself runs at its small size in the
notebook (notebooks/williams15_rfs.ipynb, 2 runs, through tests/test_notebooks.py: one more
2-run study here would cost about a minute of the suite) and at its full size (100 runs, every
row) with --runslow and in `jaxtrack reproduce williams15`.
"""

from __future__ import annotations

import numpy as np
import pytest

from jaxtrack.applications import williams15 as w15
from jaxtrack.applications.williams15.scenario import MAX_TRACKS, PMBM_HYPOTHESES
from jaxtrack.association import JPDA
from jaxtrack.multitarget import GMCPHD, GMPHD, PMB, PMBM, Tracker



@pytest.fixture(scope="module")
def study():
    return w15.run_study(w15.DEFAULT_RUNS)


def test_methods_are_what_the_study_says():
    scen, settings = w15.scenario()
    m = w15.methods(scen, settings)
    assert tuple(m) == w15.METHODS == ("phd", "cphd", "pmb", "pmbm", "jpda")
    assert isinstance(m["phd"], GMPHD) and isinstance(m["cphd"], GMCPHD) and isinstance(m["jpda"], Tracker)
    assert isinstance(m["pmb"], PMB) and isinstance(m["pmb"].associator, JPDA) and isinstance(m["pmbm"], PMBM)
    assert (m["pmbm"].max_hypotheses, m["pmbm"].max_tracks) == (PMBM_HYPOTHESES, MAX_TRACKS)
    for name in ("pmb", "pmbm"):
        f = m[name]
        assert float(f.gate) ** 2 == pytest.approx(20.0) and float(f.existence_threshold) == 1e-5
        assert float(f.estimation_threshold) == 0.4
    for name in ("phd", "cphd", "pmb", "pmbm"):  # the same time-0 intensity for every RFS filter
        assert float(m[name].initial_weights[0]) == 3.0 and m[name].initial_weights.shape == (1,)
    assert (scen.num_steps, scen.max_targets, float(scen.clutter_rate)) == (81, 4, 10.0)
    assert float(settings.clutter_density) == pytest.approx(10 / 300**2)
    assert (settings.gospa_cutoff, settings.gospa_order, settings.num_runs) == (10.0, 2.0, 100)


@pytest.mark.slow
def test_rows_and_rms(study):
    rows = w15.paper_rows(study)
    assert [r.id for r in rows] == ["W1", "W2", "W3", "W4", "W5", "W6", "W6", "W6", "W7"]
    assert all(r.source == "claim" and r.bound == "at_most" for r in rows)
    assert all(r.ok for r in rows), [(r.id, r.quantity, r.value) for r in rows if not r.ok]
    for name in w15.METHODS:
        r = study.results[name]
        rms = study.rms_gospa(name)
        # E[d²] ≥ E[d]²: the RMS is at least the mean, scan by scan
        assert np.all(rms >= np.asarray(r.gospa) - 1e-9)
        assert np.all(np.isfinite(rms))

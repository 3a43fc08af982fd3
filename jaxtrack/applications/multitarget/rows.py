"""The multi-target study's claims as rows, and :func:`reproduce`.

Our own use of the library's standard scenario (not a paper's): each row states a claim with
the margin the study commits to (``bound="at_most"``/``"at_least"``, the reference column
holding the bound; ``source="claim"``), so that ``jaxtrack reproduce multitarget`` fails if a
change to the library breaks it.

The GOSPA claims use the upper end of the 95% interval. :func:`multitarget_monte_carlo` gives the
interval per scan; the time average of the per-scan upper ends is an upper 95% bound of the
time-averaged GOSPA that is conservative (a standard deviation of a sum is at most the sum of
the standard deviations), so no per-run data is needed.
"""

from __future__ import annotations

import numpy as np

from .._report import PaperRow, write_figures
from .figures import figure_gospa, figure_track_counts
from .montecarlo import DEFAULT_RUNS, MultiTargetStudy, run_study
from .scenario import LABELS, TRACKERS

GOSPA_MARGIN = 35.0  # m: every tracker's time-averaged GOSPA, upper 95%, at most this
CROSSING_SCANS = (40, 61)  # scans around the crossing (scan 50), stop exclusive
CROSSING_MARGIN = 35.0  # m: every tracker's per-scan GOSPA upper 95% over the crossing, at most this
COUNT_SCAN = 50
COUNT_MARGIN = 0.25  # |mean confirmed tracks − alive targets| at scan 50, every tracker, at most this
FALSE_TRACK_RATIO = 0.5  # JIPDA's false tracks per run at most half of JPDA's


def upper_mean_gospa(result) -> float:
    """A conservative upper 95% bound of the time-averaged GOSPA: the mean of the per-scan upper ends."""
    return float(np.mean(np.asarray(result.gospa_interval)[:, 1]))


def paper_rows(study: MultiTargetStudy | None = None, num_runs: int = DEFAULT_RUNS) -> list[PaperRow]:
    """The study's claims, measured on ``study`` (run with ``num_runs`` if not given)."""
    study = run_study(num_runs) if study is None else study
    res = study.results
    rows = []
    for i, name in enumerate(TRACKERS):
        r = res[name]
        rows.append(PaperRow(f"MT{i + 1}", f"{LABELS[name]} time-avg GOSPA [m], upper 95% (mean {r.mean_gospa():.1f} m)",
                             GOSPA_MARGIN, upper_mean_gospa(r), 0.0, "at_most", source="claim"))
    a, b = CROSSING_SCANS
    worst = max(float(np.max(np.asarray(res[n].gospa_interval)[a:b, 1])) for n in TRACKERS)
    rows.append(PaperRow("MT4", f"max over trackers and scans {a}–{b - 1} (crossing) of GOSPA upper 95% [m]",
                         CROSSING_MARGIN, worst, 0.0, "at_most", source="claim"))
    gap = max(abs(float(res[n].num_tracks[COUNT_SCAN]) - float(res[n].num_targets[COUNT_SCAN])) for n in TRACKERS)
    rows.append(PaperRow("MT5", f"max over trackers |mean confirmed tracks − alive targets| at scan {COUNT_SCAN}",
                         COUNT_MARGIN, gap, 0.0, "at_most", source="claim"))
    fj, fp = float(res["jipda"].scores.num_false), float(res["jpda"].scores.num_false)
    rows.append(PaperRow("MT6", f"JIPDA/JPDA false tracks per run ({fj:.2f} / {fp:.2f})",
                         FALSE_TRACK_RATIO, fj / fp if fp > 0 else float("nan"), 0.0, "at_most", source="claim"))
    refused = sum(res[n].scans_overflowed + res[n].capacity_events for n in TRACKERS)
    rows.append(PaperRow("MT7", "scans overflowed + track births refused, all trackers and runs",
                         0.0, float(refused), 0.0, "at_most", source="claim"))
    return rows


def reproduce(out_dir, num_runs: int = DEFAULT_RUNS) -> tuple[list[PaperRow], list[str]]:
    """Compute every row of :func:`paper_rows` and write the study's figures as PNG into ``out_dir``.

    **Arguments:** ``out_dir``: the output directory (created if missing); ``num_runs``: Monte
    Carlo runs (default ``DEFAULT_RUNS`` = 32).

    **Returns:** ``(rows, figure_paths)``.
    """
    study = run_study(num_runs)
    rows = paper_rows(study)
    figures = write_figures(out_dir, [
        ("gospa.png", lambda: figure_gospa(study)),
        ("track_counts.png", lambda: figure_track_counts(study)),
    ], dpi=110)
    return rows, figures

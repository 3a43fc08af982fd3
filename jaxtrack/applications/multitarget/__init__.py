"""Study: four crossing targets in clutter tracked by GNN, JPDA and JIPDA.

The library's standard multi-target scenario (:func:`jaxtrack.multitarget.crossing_targets`:
4 targets crossing 5 km in front of a range–bearing radar, ``P_D`` = 0.9, 10 clutter points
per scan, 100 scans), tracked by three :class:`~jaxtrack.multitarget.Tracker` instances that
differ only in the association (GNN, JPDA) and the track logic (M-of-N, or integrated
existence for JIPDA). The study assembles library parts:

- :mod:`.scenario` — the scenario and the trackers (:func:`trackers`), with why each setting
  (table capacity, 3-of-4 confirmation, JIPDA's initial existence) was chosen;
- :mod:`.montecarlo` — :func:`jaxtrack.multitarget.multitarget_monte_carlo` of every tracker on
  the same runs (:func:`run_study`), and one run's tracks (:func:`example_run`);
- :mod:`.figures`, :mod:`.rows` — figures, :func:`paper_rows` (the claims with their stated
  margins) and :func:`reproduce`.
"""

from .scenario import (
    CAPACITY as CAPACITY,
    LABELS as LABELS,
    TRACKERS as TRACKERS,
    initiator as initiator,
    scenario as scenario,
    trackers as trackers,
)
from .montecarlo import (
    DEFAULT_RUNS as DEFAULT_RUNS,
    MultiTargetStudy as MultiTargetStudy,
    example_run as example_run,
    run_study as run_study,
)
from .figures import (
    figure_gospa as figure_gospa,
    figure_run as figure_run,
    figure_track_counts as figure_track_counts,
)
from .rows import paper_rows as paper_rows, reproduce as reproduce

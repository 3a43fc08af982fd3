"""Study: the Williams (2015) coalescence scenario with the random-finite-set filters and the
JPDA tracker.

The scenario of García-Fernández's PMBM MATLAB reference (:func:`jaxtrack.multitarget.williams15`:
4 targets, 81 steps, ``P_D`` = 0.9, 10 clutter points per scan over 300 m × 300 m, the truth
fixed over 100 runs), filtered by GM-PHD, GM-CPHD, PMB, PMBM and the JPDA tracker, scored by
GOSPA (c = 10 m, p = 2, α = 2) with its localisation, missed and false parts. The study
assembles library parts:

- :mod:`.scenario` — the scenario and the five methods (:func:`methods`), with their settings;
- :mod:`.montecarlo` — :func:`jaxtrack.multitarget.multitarget_monte_carlo` of every method on the
  same runs (:func:`run_study`);
- :mod:`.figures`, :mod:`.rows` — the figure, :func:`paper_rows` (claims with margins) and
  :func:`reproduce`.
"""

from .scenario import (
    LABELS as LABELS,
    METHODS as METHODS,
    methods as methods,
    scenario as scenario,
)
from .montecarlo import (
    DEFAULT_RUNS as DEFAULT_RUNS,
    Williams15Study as Williams15Study,
    run_study as run_study,
)
from .figures import figure_gospa as figure_gospa
from .rows import paper_rows as paper_rows, reproduce as reproduce

"""Study: Vo & Vo's linear benchmark with the labelled random-finite-set filters (δ-GLMB, LMB).

The benchmark of B.-T. Vo & B.-N. Vo (2013) and Vo, Vo & Phung (2014)
(:func:`jaxtrack.multitarget.vo_vo_linear`: 12 tracks, at most 10 at once, born at five times and
two dying, 100 scans, ``P_D`` = 0.98, 66 clutter points a scan over 2 km × 2 km, an LMB birth of
four labels), filtered by :class:`~jaxtrack.multitarget.GLMB` and
:class:`~jaxtrack.multitarget.LMB` and scored by GOSPA with the toolbox's OSPA cut-off and order
(c = 100 m, p = 1, α = 2) and by the labelled estimates' track scores (switches, breaks). The
study assembles library parts:

- :mod:`.scenario` — the scenario and the two filters (:func:`methods`) with their budgets;
- :mod:`.montecarlo` — :func:`jaxtrack.multitarget.multitarget_monte_carlo` of both filters on
  the same runs (:func:`run_study`);
- :mod:`.figures`, :mod:`.rows` — the figure, :func:`paper_rows` (claims with margins) and
  :func:`reproduce`.
"""

from .figures import figure_study as figure_study
from .montecarlo import (
    DEFAULT_RUNS as DEFAULT_RUNS,
)
from .montecarlo import (
    VoVoStudy as VoVoStudy,
)
from .montecarlo import (
    run_study as run_study,
)
from .rows import paper_rows as paper_rows
from .rows import reproduce as reproduce
from .scenario import (
    LABELS as LABELS,
)
from .scenario import (
    METHODS as METHODS,
)
from .scenario import (
    methods as methods,
)
from .scenario import (
    scenario as scenario,
)

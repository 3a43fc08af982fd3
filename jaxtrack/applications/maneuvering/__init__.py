"""Study: a maneuvering target tracked by CV-only, CT-only and IMM filters (issue 20).

Our own documented scenario (not a paper's), in :mod:`.scenario`: constant-velocity legs and two
coordinated turns seen by a range–bearing radar. The study assembles library parts:

- :mod:`.scenario` — the truth, the filter models, the IMM parametrisation
  (:class:`ImmParameters`, :func:`build_imm`);
- :mod:`.montecarlo` — :func:`jaxtrack.montecarlo.monte_carlo` of every filter (mode
  probabilities streamed), the paired per-run errors on
  :func:`jaxtrack.montecarlo.monte_carlo_map` (IMM smoother included), and the learned IMM
  (:func:`jaxtrack.learning.fit_imm`, after Brandenburger, Hoffmann & Charlish 2023);
- :mod:`.figures`, :mod:`.rows` — figures, :func:`paper_rows` (the headline claims with their
  stated margins) and :func:`reproduce`.
"""

from .montecarlo import (
    DEFAULT_RUNS as DEFAULT_RUNS,
    ESTIMATORS as ESTIMATORS,
    ManeuveringStudy as ManeuveringStudy,
    learn_imm as learn_imm,
    run_study as run_study,
    training_measurements as training_measurements,
)
from .scenario import (
    DESIGN as DESIGN,
    START as START,
    ImmParameters as ImmParameters,
    build_imm as build_imm,
    ct_model as ct_model,
    cv_model as cv_model,
    truth_model as truth_model,
    turn_rates as turn_rates,
    turn_steps as turn_steps,
)
from .figures import (
    figure_estimators as figure_estimators,
    figure_learning as figure_learning,
    figure_mode_probabilities as figure_mode_probabilities,
    figure_rmse_nees as figure_rmse_nees,
    figure_scenario as figure_scenario,
)
from .rows import paper_rows as paper_rows, reproduce as reproduce

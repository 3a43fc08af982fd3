"""The maneuvering study's headline numbers as rows, and :func:`reproduce`.

This is our own scenario, not a paper's: each row states a claim with the margin the study
commits to (``bound="at_most"``/``"at_least"``, the reference column holding the bound;
``source="claim"``), so that ``jaxtrack reproduce maneuvering`` fails if a change to the
library breaks the claim. Ratios are paired over the same runs, with 95% delta-method bounds
(:func:`jaxtrack.montecarlo.time_averaged_rmse_ratio`); the upper bound is what is compared.
"""

from __future__ import annotations

import numpy as np

from ...montecarlo import time_averaged_rmse_ratio
from .._report import PaperRow, write_figures
from .figures import (
    figure_estimators,
    figure_learning,
    figure_mode_probabilities,
    figure_rmse_nees,
    figure_scenario,
)
from .montecarlo import DEFAULT_RUNS, FIT_ITERATIONS, NUM_TRAINING_TRACKS, ManeuveringStudy, learn_imm, run_study
from .scenario import TURNS

RATIO_MARGIN = 0.9  # the IMM is ≥ 10% better than either single model (upper 95% bound)
SMOOTHER_MARGIN = 0.8  # the IMM smoother is ≥ 20% better than the IMM filter
LEARNED_MARGIN = 1.05  # the learned IMM is within 5% (or better) of the designed one
ANEES_TOLERANCE = 0.25  # the IMM's ANEES within 25% of 1 (IMMs are not exactly consistent)


def _late_turn_and_leg_steps(num_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Steps in the second half of each turn, and leg steps ≥ 20 s after a turn ended."""
    k = np.arange(num_steps)
    late = np.zeros(num_steps, bool)
    legs = np.ones(num_steps, bool)
    for start, stop, _ in TURNS:
        late |= (k >= (start + stop) // 2) & (k < stop)
        legs &= ~((k >= start) & (k < stop + 20))
    return late, legs


def paper_rows(study: ManeuveringStudy | None = None, num_runs: int = DEFAULT_RUNS) -> list[PaperRow]:
    """The study's claims, measured on ``study`` (run with ``num_runs`` if not given)."""
    study = run_study(num_runs) if study is None else study
    e = study.squared_position_error
    rows = []
    for ref, name in (("cv", "CV-only"), ("ct", "CT-only")):
        iv = time_averaged_rmse_ratio(e["imm"], e[ref])
        rows.append(PaperRow("M1" if ref == "cv" else "M2",
                             f"IMM/{name} time-avg pos. RMSE, upper 95% (ratio {iv.value:.3f})",
                             RATIO_MARGIN, iv.upper, 0.0, "at_most", source="claim"))
    imm = study.results["imm"]
    lo, hi = (float(b) for b in imm.anees_bounds)
    rows.append(PaperRow("M3", f"IMM ANEES, x y vx vy (95% χ² bounds [{lo:.3f}, {hi:.3f}])",
                         1.0, float(imm.anees), ANEES_TOLERANCE, source="claim"))
    iv = time_averaged_rmse_ratio(e["imm_smoother"], e["imm"])
    rows.append(PaperRow("M4", f"IMM smoother/filter time-avg pos. RMSE, upper 95% (ratio {iv.value:.3f})",
                         SMOOTHER_MARGIN, iv.upper, 0.0, "at_most", source="claim"))
    iv = time_averaged_rmse_ratio(e["imm_learned"], e["imm"])
    rows.append(PaperRow("M5", f"learned/designed IMM time-avg pos. RMSE, upper 95% (ratio {iv.value:.3f})",
                         LEARNED_MARGIN, iv.upper, 0.0, "at_most", source="claim"))
    T = imm.mode_probs.shape[0]
    late, legs = _late_turn_and_leg_steps(T)
    mu_turn = np.asarray(imm.mode_probs)[:, 1]
    rows.append(PaperRow("M6", "IMM turn-mode probability, mean over the turns' second halves",
                         0.7, float(mu_turn[late].mean()), 0.0, "at_least", source="claim"))
    rows.append(PaperRow("M7", "IMM turn-mode probability, mean over legs ≥ 20 s after a turn",
                         0.35, float(mu_turn[legs].mean()), 0.0, "at_most", source="claim"))
    return rows


def reproduce(out_dir, num_runs: int = DEFAULT_RUNS, num_tracks: int = NUM_TRAINING_TRACKS,
              fit_iterations: int = FIT_ITERATIONS) -> tuple[list[PaperRow], list[str]]:
    """Compute every row of :func:`paper_rows` and write the study's figures as PNG into ``out_dir``.

    **Arguments:** ``out_dir``: the output directory (created if missing); ``num_runs``: Monte
    Carlo runs (default ``DEFAULT_RUNS`` = 2000); ``num_tracks``, ``fit_iterations``: the
    learned IMM's training tracks and Adam steps (:func:`~.montecarlo.learn_imm`).

    **Returns:** ``(rows, figure_paths)``.
    """
    study = run_study(num_runs, fit=learn_imm(num_tracks, fit_iterations))
    rows = paper_rows(study)
    figures = write_figures(out_dir, [
        ("scenario.png", figure_scenario),
        ("rmse_nees.png", lambda: figure_rmse_nees(study)),
        ("mode_probabilities.png", lambda: figure_mode_probabilities(study)),
        ("estimators_rmse.png", lambda: figure_estimators(study)),
        ("learning.png", lambda: figure_learning(study)),
    ], dpi=110)
    return rows, figures

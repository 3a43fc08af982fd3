"""The maneuvering study's Monte Carlo: CV-only, CT-only, IMM, IMM smoother and learned IMM.

Two passes over the same runs (run ``i`` from ``fold_in(key, i)`` in both, so they pair up):

1. :func:`jaxtrack.montecarlo.monte_carlo` for every filter: per-step RMSE, NEES and (IMM)
   mode probabilities, streamed; the filters are scored on the kinematic state
   ``[x, y, vx, vy]`` (``filter_components``), so the 5-state turn model and the IMM's common
   state compare with the 4-state truth.
2. :func:`jaxtrack.montecarlo.monte_carlo_map` of :func:`_one_run`: each run's squared position
   error per step for every estimator (the IMM smoother needs the whole run), kept per run for
   the paired confidence intervals of :func:`jaxtrack.montecarlo.time_averaged_rmse_ratio`.

The learned IMM is fitted by :func:`jaxtrack.learning.fit_imm` on ``NUM_TRAINING_TRACKS``
recorded tracks drawn from other keys than the evaluation runs (measurements only), starting
from :data:`~.scenario.START`.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ...filters import ExtendedKalmanFilter, imm_smoother, run_filter, run_imm
from ...learning import IMMFit, fit_imm
from ...montecarlo import MonteCarloResult, monte_carlo, monte_carlo_map, simulate
from .scenario import DESIGN, KINEMATIC, NUM_STEPS, START, build_imm, ct_model, cv_model, truth_model

DEFAULT_RUNS = 2000
NUM_TRAINING_TRACKS = 10
FIT_ITERATIONS = 150
FIT_LEARNING_RATE = 0.05
EVALUATION_KEY = 20
TRAINING_KEY = 21
ESTIMATORS = ("cv", "ct", "imm", "imm_smoother", "imm_learned")


@dataclasses.dataclass(frozen=True)
class ManeuveringStudy:
    """What :func:`run_study` returns.

    - ``results``: :class:`~jaxtrack.montecarlo.MonteCarloResult` per filter (``"cv"``, ``"ct"``,
      ``"imm"``, ``"imm_learned"``), scored on ``[x, y, vx, vy]``.
    - ``squared_position_error``: per estimator of :data:`ESTIMATORS`, ``(M, T)`` NumPy arrays
      of ``‖p − p̂‖²`` (m²), run ``i`` the same run in every array and in ``results``.
    - ``smoothed_mode_probs`` ``(T, 2)``: the IMM smoother's mode probabilities averaged over runs.
    - ``fit``: the :class:`~jaxtrack.learning.IMMFit` of the learned IMM.
    """

    results: dict
    squared_position_error: dict
    smoothed_mode_probs: np.ndarray
    fit: IMMFit

    @property
    def num_runs(self) -> int:
        return int(self.squared_position_error["imm"].shape[0])


def training_measurements(num_tracks: int = NUM_TRAINING_TRACKS, num_steps: int = NUM_STEPS) -> jax.Array:
    """``(R, T, 2)`` recorded range–bearing tracks for learning (independent of the evaluation runs)."""
    truth, key = truth_model(num_steps), jax.random.key(TRAINING_KEY)
    return jnp.stack([simulate(truth, jax.random.fold_in(key, r), num_steps).measurements
                      for r in range(num_tracks)])


# One optimiser object: fit_imm's loop takes it as a static argument (hashed by identity), so a
# new optax.adam per call would compile the whole fit again (10.9 s of a 16.5 s second call).
_FIT_OPTIMIZER = optax.adam(FIT_LEARNING_RATE)


def learn_imm(num_tracks: int = NUM_TRAINING_TRACKS, num_iterations: int = FIT_ITERATIONS) -> IMMFit:
    """Fit :class:`~.scenario.ImmParameters` from :data:`~.scenario.START` to recorded tracks."""
    return fit_imm(build_imm, START, training_measurements(num_tracks), num_iterations=num_iterations,
                   optimizer=_FIT_OPTIMIZER)


def _one_run(key, args):
    """Run ``key``'s squared position error ``(5, T)`` of the :data:`ESTIMATORS`, its smoothed
    mode probabilities ``(T, 2)`` and whether every estimator stayed finite."""
    truth, cv, ct, imm, learned = args
    run = simulate(truth, key, truth.num_steps)
    z, pos = run.measurements, run.states[:, :2]

    def sq(mean):
        return jnp.sum((pos - mean[:, :2]) ** 2, axis=-1)

    ekf = ExtendedKalmanFilter()
    a = run_filter(ekf, cv, z, save="mean", throw=False)
    b = run_filter(ekf, ct, z, save="mean", throw=False)
    smooth = imm_smoother(imm, z, throw=False)
    c = run_imm(learned, z, throw=False)
    errors = jnp.stack([sq(a.filtered_mean), sq(b.filtered_mean), sq(smooth.filtered.filtered_mean),
                        sq(smooth.smoothed_mean), sq(c.filtered_mean)])
    ok = a.ok & b.ok & smooth.ok & c.ok
    return errors, smooth.smoothed_mode_probs, ok


def run_study(num_runs: int = DEFAULT_RUNS, *, fit: IMMFit | None = None, progress: bool = False) -> ManeuveringStudy:
    """All Monte Carlo results of the study on ``num_runs`` runs (``fit`` reuses a learned IMM)."""
    fit = learn_imm() if fit is None else fit
    truth, key = truth_model(), jax.random.key(EVALUATION_KEY)
    imm, learned = build_imm(DESIGN), fit.imm
    ekf = ExtendedKalmanFilter()
    kw = dict(progress=progress, filter_components=KINEMATIC)
    results = {
        "cv": monte_carlo(truth, key, num_runs, filter=ekf, filter_model=cv_model(), progress=progress),
        "ct": monte_carlo(truth, key, num_runs, filter=ekf, filter_model=ct_model(), **kw),
        "imm": monte_carlo(truth, key, num_runs, filter=imm, **kw),
        "imm_learned": monte_carlo(truth, key, num_runs, filter=learned, **kw),
    }
    errors, modes, ok = monte_carlo_map(_one_run, key, num_runs, args=(truth, cv_model(), ct_model(), imm, learned),
                                        reduce="stack", block_size=256, progress=progress)
    if not np.all(ok):
        raise FloatingPointError(f"maneuvering study: {int(np.sum(~np.asarray(ok)))} runs went non-finite.")
    errors = np.asarray(errors)
    per = {name: errors[:, j] for j, name in enumerate(ESTIMATORS)}
    return ManeuveringStudy(results, per, np.asarray(modes).mean(axis=0), fit)

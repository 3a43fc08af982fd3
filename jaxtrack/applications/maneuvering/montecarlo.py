"""The maneuvering study's Monte Carlo: CV-only, CT-only, IMM, IMM smoother and learned IMM.

One pass over the runs (run ``i`` from ``fold_in(key, i)``):
:func:`jaxtrack.montecarlo.monte_carlo_map` of :func:`_one_run` filters each run once with every
estimator (the IMM smoother's forward pass is the IMM filter) and keeps, per run and step, each
filter's error on the kinematic state ``[x, y, vx, vy]`` (:data:`~.scenario.KINEMATIC`: the
5-state turn model and the IMM's common state compare with the 4-state truth), NEES, NIS and
(IMM) mode probabilities, and every estimator's squared position error.
:func:`jaxtrack.montecarlo.summarize_runs` turns the former into the filters'
:class:`~jaxtrack.montecarlo.MonteCarloResult` (the statistics :func:`~jaxtrack.montecarlo.monte_carlo`
streams, same formulas and bounds); the latter are kept per run for the paired confidence
intervals of :func:`jaxtrack.montecarlo.time_averaged_rmse_ratio`. (Until this was one pass, every
filter ran twice: ``monte_carlo`` per filter, then the paired errors; about half the study's time.)

The learned IMM is fitted by :func:`jaxtrack.learning.fit_imm` on ``NUM_TRAINING_TRACKS``
recorded tracks drawn from other keys than the evaluation runs (measurements only), starting
from :data:`~.scenario.START`.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ...filters import ExtendedKalmanFilter, imm_smoother, run_filter, run_imm
from ...filters._linalg import marginal_cov
from ...learning import IMMFit, fit_imm
from ...montecarlo import monte_carlo_map, normalized_squared_error, simulate, summarize_runs
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


FILTERS = ("cv", "ct", "imm", "imm_learned")  # the estimators with a MonteCarloResult


class _FilterRun(NamedTuple):
    """One run of one filter, per step: error on :data:`~.scenario.KINEMATIC` ``(T, 4)``, NEES,
    NIS and its degrees of freedom ``(T,)`` (0 for an IMM), mode probabilities ``(T, K)``."""

    error: jax.Array
    nees: jax.Array
    nis: jax.Array
    nis_dof: jax.Array
    mode_probs: jax.Array


def _scored(x, mean, cov):
    """Error and NEES on the kinematic components, per step (the filter's marginal covariance)."""
    error = x - mean[:, KINEMATIC]
    return error, jax.vmap(normalized_squared_error)(error, marginal_cov(cov, KINEMATIC))


def _ekf_run(x, res) -> _FilterRun:
    error, nees = _scored(x, res.filtered_mean, res.filtered_cov)
    nis = jax.vmap(normalized_squared_error)(res.innovation, res.innovation_cov)
    return _FilterRun(error, nees, nis, res.num_observed.astype(nees.dtype), jnp.zeros((nees.shape[0], 0), nees.dtype))


def _imm_run(x, res) -> _FilterRun:
    error, nees = _scored(x, res.filtered_mean, res.filtered_cov)
    zero = jnp.zeros_like(nees)  # an IMM has no single innovation: NIS not scored, as in monte_carlo
    return _FilterRun(error, nees, zero, zero, res.mode_probs)


def _one_run(key, args):
    """Run ``key`` through every estimator once: ``(squared position errors (5, T) of the
    ESTIMATORS, {filter: _FilterRun}, smoothed mode probabilities (T, 2), ok)``."""
    truth, cv, ct, imm, learned = args
    run = simulate(truth, key, truth.num_steps)
    z, x = run.measurements, run.states

    def sq(mean):
        return jnp.sum((x[:, :2] - mean[:, :2]) ** 2, axis=-1)

    ekf = ExtendedKalmanFilter()
    a = run_filter(ekf, cv, z, throw=False)
    b = run_filter(ekf, ct, z, throw=False)
    smooth = imm_smoother(imm, z, throw=False)
    c = run_imm(learned, z, throw=False)
    errors = jnp.stack([sq(a.filtered_mean), sq(b.filtered_mean), sq(smooth.filtered.filtered_mean),
                        sq(smooth.smoothed_mean), sq(c.filtered_mean)])
    filters = {"cv": _ekf_run(x, a), "ct": _ekf_run(x, b), "imm": _imm_run(x, smooth.filtered),
               "imm_learned": _imm_run(x, c)}
    ok = a.ok & b.ok & smooth.ok & c.ok
    return errors, filters, smooth.smoothed_mode_probs, ok


def run_study(num_runs: int = DEFAULT_RUNS, *, fit: IMMFit | None = None, progress: bool = False) -> ManeuveringStudy:
    """All Monte Carlo results of the study on ``num_runs`` runs (``fit`` reuses a learned IMM)."""
    fit = learn_imm() if fit is None else fit
    truth, key = truth_model(), jax.random.key(EVALUATION_KEY)
    imm, learned = build_imm(DESIGN), fit.imm
    cv, ct = cv_model(), ct_model()
    errors, filters, modes, ok = monte_carlo_map(_one_run, key, num_runs, args=(truth, cv, ct, imm, learned),
                                                 reduce="stack", block_size=256, progress=progress)
    if not np.all(ok):
        raise FloatingPointError(f"maneuvering study: {int(np.sum(~np.asarray(ok)))} runs went non-finite.")
    ekf = ExtendedKalmanFilter()
    estimator = {"cv": (ekf, cv), "ct": (ekf, ct), "imm": (imm, None), "imm_learned": (learned, None)}
    results = {}
    for name in FILTERS:
        r = filters[name]
        results[name] = summarize_runs(
            r.error, r.nees, nis=r.nis, nis_dof=r.nis_dof, mode_probs=r.mode_probs if r.mode_probs.shape[-1] else None,
            components=None if name == "cv" else KINEMATIC, key=key, filter=estimator[name][0],
            filter_model=estimator[name][1])
    errors = np.asarray(errors)
    per = {name: errors[:, j] for j, name in enumerate(ESTIMATORS)}
    return ManeuveringStudy(results, per, np.asarray(modes).mean(axis=0), fit)

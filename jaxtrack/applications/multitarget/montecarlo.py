"""The multi-target study's Monte Carlo: each tracker through
:func:`jaxtrack.multitarget.multitarget_monte_carlo` on the same runs (run ``i`` is
``simulate_scenario(scenario, fold_in(key, i))`` for every tracker), and one run's tracks."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from ...multitarget import MultiTargetTrajectory, MultiTargetMonteCarloResult, run_tracker, simulate_scenario, \
    multitarget_monte_carlo
from .scenario import CUTOFF, ORDER, TRACKERS, scenario, trackers

DEFAULT_RUNS = 32
BLOCK_SIZE = 32
EVALUATION_KEY = 30


@dataclasses.dataclass(frozen=True)
class MultiTargetStudy:
    """What :func:`run_study` returns: ``results``, a
    :class:`~jaxtrack.multitarget.MultiTargetMonteCarloResult` per tracker of
    :data:`~.scenario.TRACKERS`, all on the same runs."""

    results: dict[str, MultiTargetMonteCarloResult]

    @property
    def num_runs(self) -> int:
        return self.results[TRACKERS[0]].num_runs

    @property
    def num_scans(self) -> int:
        return int(np.shape(self.results[TRACKERS[0]].gospa)[0])


def run_study(num_runs: int = DEFAULT_RUNS, *, block_size: int = BLOCK_SIZE, progress: bool = False,
              capacity: int | None = None) -> MultiTargetStudy:
    """Every tracker's Monte Carlo on ``num_runs`` runs of :func:`~.scenario.scenario` (GOSPA with
    ``c`` = :data:`~.scenario.CUTOFF`, ``p`` = :data:`~.scenario.ORDER`)."""
    scen = scenario()
    trk = trackers(scen) if capacity is None else trackers(scen, capacity)
    key = jax.random.key(EVALUATION_KEY)
    results = {name: multitarget_monte_carlo(trk[name], scen, key, num_runs, cutoff=CUTOFF, order=ORDER,
                                         block_size=block_size, progress=progress)
               for name in TRACKERS}
    return MultiTargetStudy(results)


def example_run(run: int = 0) -> tuple[MultiTargetTrajectory, dict]:
    """Run ``run`` of the study (its truth and scans) and each tracker's
    :class:`~jaxtrack.multitarget.TrackerResult` on it."""
    scen = scenario()
    truth = simulate_scenario(scen, jax.random.fold_in(jax.random.key(EVALUATION_KEY), run))
    tracks = {name: run_tracker(t, truth.scans.measurements, truth.scans.valid)
              for name, t in trackers(scen).items()}
    return truth, tracks

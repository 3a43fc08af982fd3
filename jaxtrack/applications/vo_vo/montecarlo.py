"""The labelled-RFS study's Monte Carlo: both filters through
:func:`jaxtrack.multitarget.multitarget_monte_carlo` on the same runs (run ``i`` is
``simulate_scenario(scenario, fold_in(key, i))``: the truth is fixed, detections and clutter are
redrawn), scored by GOSPA with the toolbox's OSPA cut-off and order (``c = 100`` m, ``p = 1``,
``α = 2``)."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from ...multitarget import MultiTargetMonteCarloResult, multitarget_monte_carlo
from .scenario import MAX_TRACKS, METHODS, methods, scenario

DEFAULT_RUNS = 20
# One run a block: a vmapped block of labelled-filter runs costs more per run than one run (a
# batch's per-scan arrays leave the cache, and a Murty loop steps until the batch's longest is
# done): the δ-GLMB 3.6 s a run in a batch of 100 against 3.1 s alone; at H = 256, 8.7 s against
# 4.2 s (benchmarks/labelled_reference.py, one core).
BLOCK_SIZE = 1
EVALUATION_KEY = 13


@dataclasses.dataclass(frozen=True)
class VoVoStudy:
    """What :func:`run_study` returns: ``results``, a
    :class:`~jaxtrack.multitarget.MultiTargetMonteCarloResult` per method of :data:`~.scenario.METHODS`."""

    results: dict[str, MultiTargetMonteCarloResult]

    @property
    def num_runs(self) -> int:
        return self.results[METHODS[0]].num_runs

    def cardinality_error(self, name: str) -> np.ndarray:
        """Per scan, the mean number of estimates minus the mean number of alive targets."""
        r = self.results[name]
        return np.asarray(r.num_tracks) - np.asarray(r.num_targets)


def run_study(num_runs: int = DEFAULT_RUNS, *, num_steps: int | None = None, progress: bool = False,
              max_hypotheses: int | None = None, max_tracks: int = MAX_TRACKS) -> VoVoStudy:
    """Both filters' Monte Carlo on ``num_runs`` runs (the first ``num_steps`` scans if given)."""
    scen, settings = scenario(num_steps)
    meth = methods(scen, settings, max_hypotheses=max_hypotheses, max_tracks=max_tracks)
    key = jax.random.key(EVALUATION_KEY)
    results = {name: multitarget_monte_carlo(meth[name], scen, key, num_runs, cutoff=settings.ospa_cutoff,
                                             order=settings.ospa_order, block_size=BLOCK_SIZE, progress=progress)
               for name in METHODS}
    return VoVoStudy(results)

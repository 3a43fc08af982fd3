"""The Williams (2015) study's Monte Carlo: every method through
:func:`jaxtrack.multitarget.multitarget_monte_carlo` on the same runs (run ``i`` is
``simulate_scenario(scenario, fold_in(key, i))`` for every method: the truth is fixed, the
detections and clutter are redrawn)."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from ...multitarget import MultiTargetMonteCarloResult, multitarget_monte_carlo
from .scenario import METHODS, PMBM_HYPOTHESES, methods, scenario

DEFAULT_RUNS = 100  # the reference's Nmc
BLOCK_SIZE = 25
EVALUATION_KEY = 15


@dataclasses.dataclass(frozen=True)
class Williams15Study:
    """What :func:`run_study` returns: ``results``, a
    :class:`~jaxtrack.multitarget.MultiTargetMonteCarloResult` per method of :data:`~.scenario.METHODS`."""

    results: dict[str, MultiTargetMonteCarloResult]

    @property
    def num_runs(self) -> int:
        return self.results[METHODS[0]].num_runs

    def rms_gospa(self, name: str) -> np.ndarray:
        """The RMS GOSPA per scan, ``sqrt(E[d²])`` (the reference's ``rms_gospa_t``): with p = 2
        the mean squared distance is the sum of the mean parts."""
        r = self.results[name]
        return np.sqrt(np.asarray(r.localisation) + np.asarray(r.missed) + np.asarray(r.false))


def run_study(num_runs: int = DEFAULT_RUNS, *, block_size: int = BLOCK_SIZE, progress: bool = False,
              names=METHODS, pmbm_hypotheses: int = PMBM_HYPOTHESES) -> Williams15Study:
    """Every method's Monte Carlo on ``num_runs`` runs (GOSPA with the reference's ``c`` and ``p``)."""
    scen, settings = scenario()
    meth = methods(scen, settings, pmbm_hypotheses)
    key = jax.random.key(EVALUATION_KEY)
    results = {name: multitarget_monte_carlo(meth[name], scen, key, num_runs, cutoff=settings.gospa_cutoff,
                                         order=settings.gospa_order, block_size=min(block_size, num_runs),
                                         progress=progress)
               for name in names}
    return Williams15Study(results)

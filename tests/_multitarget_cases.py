"""The five multi-target families on one small scenario, for the contract tests.

A 12-scan cut of the Williams (2015) scenario (its fixed truth, 10 clutter points a scan over
300 m × 300 m, ``P_D`` 0.9) and the five methods of the Williams study at small budgets, so that
each family compiles in seconds. ``tests/data/multitarget_contract.npz`` holds what these runs gave
before the multi-target layer was refactored onto one contract (commit 0847afe, written by
``python tests/_multitarget_cases.py``): ``tests/test_multitarget_contract.py`` holds the new code
to it bit for bit.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

REFERENCE = Path(__file__).resolve().parent / "data" / "multitarget_contract.npz"
SCANS = 12
MC_RUNS = 3
MC_KEY = 5
RUN_KEY = 11
CUTOFF = 10.0


def scenario():
    from jaxtrack.multitarget import Scenario, williams15

    full, settings = williams15(9, max_measurements=24)
    death = np.minimum(np.asarray(full.death_step), SCANS)
    scen = Scenario(full.model, None, np.asarray(full.birth_step), death, detection_probability=0.9,
                    clutter_rate=float(full.clutter_rate), clutter_region=np.asarray(full.clutter_region),
                    max_measurements=24, num_steps=SCANS, truth_states=np.asarray(full.truth_states[:SCANS]))
    return scen, settings


def methods(scen, s):
    """The five methods (the constructors' current form; the reference was written with their
    pre-contract keywords, ``birth_weights=…``, which build the same filters)."""
    from jaxtrack.association import JPDA
    from jaxtrack.filters import KalmanFilter
    from jaxtrack.multitarget import GMCPHD, GMPHD, PMB, PMBM, OnePointInitiator, Tracker, TrackManagement

    kf = KalmanFilter()
    common = dict(prob_survival=s.prob_survival, prob_detect=s.prob_detect, birth=s.birth, initial=s.initial)
    mb = dict(clutter_density=s.clutter_density, max_tracks=24, gate=math.sqrt(20.0))
    initiator = OnePointInitiator(prior_mean=np.asarray(s.birth_means[0]), prior_cov=np.asarray(s.birth_covs[0]))
    return {
        "phd": GMPHD(kf, scen.model, clutter_density=s.clutter_density, capacity=24, **common),
        "cphd": GMCPHD(kf, scen.model, clutter_rate=s.clutter_rate,
                       clutter_density=s.clutter_density, capacity=24,
                       max_cardinality=12, **common),
        "pmb": PMB(kf, scen.model, associator=JPDA(max_cluster_tracks=6, max_large_clusters=2), **common, **mb),
        "pmbm": PMBM(kf, scen.model, max_hypotheses=4, assignment_rows=8, assignment_tracks=12, **common, **mb),
        "jpda": Tracker(kf, scen.model, JPDA(), initiator, prob_detect=s.prob_detect,
                        clutter_density=s.clutter_density, prob_gate=0.999, capacity=16,
                        management=TrackManagement(3, 4, 3)),
    }


def _fields(obj, prefix=""):
    """A result's array fields by name (``final.``-prefixed for the last state), as NumPy."""
    import dataclasses

    import jax

    out = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if value is None or isinstance(value, (int, float, str, bool)):
            continue
        if dataclasses.is_dataclass(value):
            out.update(_fields(value, prefix + f.name + "."))
        elif isinstance(value, tuple) and hasattr(value, "_fields"):
            for name, leaf in zip(value._fields, value):
                if leaf is not None:
                    out[prefix + f.name + "." + name] = np.asarray(leaf)
        else:
            leaves = jax.tree.leaves(value)
            if len(leaves) == 1:
                out[prefix + f.name] = np.asarray(leaves[0])
    return out


def old_outputs() -> dict:
    """Every family's run and Monte Carlo through the pre-contract entry points (as at 0847afe,
    with the constructors' keywords of then)."""
    import warnings

    from jaxtrack.multitarget import run_cphd, run_phd, run_pmbm, run_tracker, simulate_scenario, tracker_monte_carlo

    scen, settings = scenario()
    all_methods = methods(scen, settings)
    truth = simulate_scenario(scen, RUN_KEY)
    z, v = truth.scans.measurements, truth.scans.valid
    runs = {"phd": run_phd, "cphd": run_cphd, "pmb": run_pmbm, "pmbm": run_pmbm, "jpda": run_tracker}
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, method in all_methods.items():
            for key, value in _fields(runs[name](method, z, v, warn=False)).items():
                out[f"{name}/run/{key}"] = value
            mc = tracker_monte_carlo(method, scen, MC_KEY, MC_RUNS, cutoff=CUTOFF, block_size=MC_RUNS)
            for key, value in _fields(mc).items():
                out[f"{name}/mc/{key}"] = value
            out[f"{name}/mc/births_dropped"] = np.asarray(mc.births_dropped)
    return out


if __name__ == "__main__":
    import os

    os.environ.setdefault("JAX_DISABLE_MOST_OPTIMIZATIONS", "1")  # as the suite compiles (tests/conftest.py)
    import jax

    jax.config.update("jax_enable_x64", True)
    arrays = old_outputs()
    REFERENCE.parent.mkdir(exist_ok=True)
    np.savez_compressed(REFERENCE, **arrays)
    print(f"wrote {len(arrays)} arrays to {REFERENCE}")


def new_style(kwargs: dict) -> dict:
    """Constructor keywords in the tests' flat form (``birth_weights=…``, ``prune_threshold=…``,
    ``reduction="stonesoup"``, ``poisson_*``) as the constructors take them now (``birth=``,
    ``initial=`` GaussianMixtures, ``reduction=``/``poisson_reduction=`` strategies)."""
    from jaxtrack.multitarget import GaussianMixture, StoneSoupReduction, VoMaReduction

    kw = dict(kwargs)
    for kind in ("birth", "initial"):
        parts = [kw.pop(f"{kind}_{p}", None) for p in ("weights", "means", "covs")]
        if any(p is not None for p in parts):
            kw[kind] = GaussianMixture(*parts)
    for prefix, key in (("", "reduction"), ("poisson_", "poisson_reduction")):
        thresholds = {t: kw.pop(f"{prefix}{t}") for t in ("prune_threshold", "merge_threshold") if f"{prefix}{t}" in kw}
        kind = kw.pop(key, None) if isinstance(kw.get(key), str) else None
        if thresholds or kind is not None:
            kw[key] = (StoneSoupReduction if kind == "stonesoup" else VoMaReduction)(**thresholds)
    return kw

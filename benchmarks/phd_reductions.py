"""GM-PHD accuracy by reduction: Table II (``"vo-ma"``, the default) against Stone Soup's (``"stonesoup"``).

The question (a user's report: on a plain crossing scenario the default scored a mean GOSPA of
21.6 m against Stone Soup's 16.4 m, with capacity warnings): which of the differences between
the two (``jaxtrack/multitarget/_phd.py``'s module docstring) costs the accuracy, and which
should be the default?

Scenarios (each GM-PHD with ``P_S`` 0.99, ``P_D`` 0.9, the scenario's clutter density, pruning
``T`` = 1e-5, merging ``U`` = 4, ``capacity`` 100, ``max_estimates`` 24 (asserted: no scan
extracts more), extraction above weight 0.5):

- **crossing**: :func:`jaxtrack.multitarget.crossing_targets` at its defaults (4 targets, 100
  scans, range-bearing radar, 10 clutter points a scan) and the GM-PHD of
  ``benchmarks/phd_batch.py`` (EKF, one birth component: weight 0.05, mean at the crossing
  point, standard deviations 1 km and 40 m/s); GOSPA ``c`` = 100 m;
- **Williams**: :func:`jaxtrack.multitarget.williams15` and the Williams study's GM-PHD
  (:mod:`jaxtrack.applications.williams15.scenario`: Kalman filter, birth weight 0.005 at
  (100, 100) m with standard deviations 150 m and 1 m/s, time-0 intensity 3 on the same
  Gaussian); GOSPA ``c`` = 10 m, as the reference;
- **sparse**: a low-clutter linear scenario: ``benchmarks/rfs.py``'s 5 targets (2-D CV, ``q`` =
  0.3 m²/s³, positions measured with ``R`` = 0.75 m²·I, 3 born at scans 20, 40, 60, one dies
  at 70) over 100 scans with 1 clutter point a scan over 200 m × 200 m; a Kalman GM-PHD with one
  birth component (weight 0.05, mean 0, standard deviations 80 m and 2 m/s); GOSPA ``c`` = 10 m.

For each scenario, ``--runs`` Monte Carlo runs (run ``i`` from ``fold_in(key 0, i)``, as
:func:`~jaxtrack.multitarget.multitarget_monte_carlo` draws them) are filtered by these variants,
all on the same runs (paired):

- ``vo-ma``: Table I update + Table II reduction (the default); ``stonesoup``: Stone Soup's
  update and reduction; ``vo-ma, capacity 200``;
- ``vo-ma update + stonesoup reduction`` and ``stonesoup update + vo-ma reduction``: the two
  halves swapped (a ``GMPHD`` subclass whose ``reduce`` runs the other reduction);
- ``vo-ma without undetected births``: Table I's update with the birth components' missed
  term removed (what Stone Soup's update does besides applying ``P_S`` to detected births), Table
  II's reduction;
- ``vo-ma, distance in the seed's P_j``: Table I's update, Table II's reduction with the merging
  distance ``(m_i − m_j)ᵀ P_j⁻¹ (m_i − m_j)`` in the seed's covariance instead of the candidate's;
- ``vo-ma, one estimate per component``: extraction of ``min(round(w), 1)`` copies.

Printed per variant: the mean GOSPA over runs and scans with its 95% interval over runs
(``mean ± 1.96 s/√R`` of the runs' time-averaged GOSPA), its difference from ``vo-ma`` with the
paired interval, GOSPA's parts (localisation, missed, false; m², means over scans), the mean
number of estimates a scan, the capacity events (components left over for want of slots, over
all runs and scans) and the mean position standard deviation of the extracted components
(``sqrt`` of the mean position variance, m: a component that absorbed a broad one is wide).
Then :func:`~jaxtrack.multitarget.multitarget_monte_carlo` itself for ``vo-ma`` and ``stonesoup``
(its ``mean_gospa()`` and ``capacity_events``, which must equal the paired figures).

Measured (``benchmarks/measured/phd_reductions.txt``, 100 runs a scenario): the difference is the
update's missed-detection term of the birth components, not the reduction. Table I keeps
``(1 − P_D) w_b`` of every birth Gaussian; Table II measures a candidate's distance to the seed in
the candidate's own covariance, so that broad component lies within ``U`` of the heaviest target
component and is merged into it, which widens it by about ``(1 − P_D) w_b P_b / w̃`` (crossing:
extracted components' position σ 46 m against 5.6 m). The wide component then gathers clutter
(the capacity events; capacity 200 removes them and changes nothing else) and localises worse.
With that term dropped Table II is at least as good as Stone Soup's reduction everywhere
(crossing 36.52 against 36.57 m, sparse 3.98 against 3.99 m, Williams 4.13 against 4.56 m);
Stone Soup's merged-weight cap (one estimate for targets that coalesce) costs +0.47 m in the
Williams scenario. Measuring the distance in the seed's covariance instead also removes most of
it (crossing 35.79, sparse 4.00, Williams 4.30 m).

Usage::

    PYTHONPATH=. python benchmarks/phd_reductions.py               # 100 runs a scenario, ~26 min on 2 shared cores
    PYTHONPATH=. python benchmarks/phd_reductions.py --runs 8 --out /dev/null
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import warnings

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jaxtrack.applications.williams15.scenario import scenario as williams_scenario  # noqa: E402
from jaxtrack.filters import KalmanFilter  # noqa: E402
from jaxtrack.filters._linalg import cholesky_and_inverse  # noqa: E402
from jaxtrack.models import constant_velocity  # noqa: E402
from jaxtrack.montecarlo import monte_carlo_map  # noqa: E402
from jaxtrack.multitarget import (  # noqa: E402
    GMPHD, AbstractMixtureReduction, CapacityWarning, GaussianMixture, Scenario, StoneSoupReduction, VoMaReduction,
    crossing_targets, multitarget_monte_carlo)
from jaxtrack.multitarget._evaluation import _positions, score_tracks  # noqa: E402
from jaxtrack.multitarget._phd import _run_phd  # noqa: E402
from jaxtrack.multitarget._reduction import reduce_mixture  # noqa: E402
from jaxtrack.multitarget._scenario import _simulate_one  # noqa: E402

from phd_batch import Out, _where, crossing_phd  # noqa: E402

MAX_ESTIMATES = 24
BASE = "vo-ma"


def reduction(name):
    """The library's strategy for ``"vo-ma"`` or ``"stonesoup"`` (thresholds 1e-5 and 4)."""
    return (StoneSoupReduction if name == "stonesoup" else VoMaReduction)(1e-5, 4.0)


class SwappedReduction(AbstractMixtureReduction):
    """The update conventions of one reduction with the pruning and merging of the other: a
    strategy whose ``stonesoup_update`` is ``update_stonesoup`` and whose numerics are the other's."""

    update_stonesoup: bool = eqx.field(static=True)

    def __init__(self, update_stonesoup: bool):
        self.prune_threshold, self.merge_threshold = jnp.asarray(1e-5), jnp.asarray(4.0)
        self.update_stonesoup = update_stonesoup

    @property
    def stonesoup_update(self):
        return self.update_stonesoup

    def __call__(self, weights, means, covs, active, capacity, free_mean, free_cov):
        return reduce_mixture(not self.update_stonesoup, self.prune_threshold, self.merge_threshold, capacity,
                              free_mean, free_cov, weights, means, covs, active)


class SeedCovarianceMerge(AbstractMixtureReduction):
    """Table II with the merging distance in the seed's covariance, ``(m_i − m_j)ᵀ P_j⁻¹ (m_i − m_j)
    ≤ U``, instead of the candidate's ``P_i`` (the same pruning, passes, moments and budget; fixed
    passes, slower than the library's while loop, the same values otherwise)."""

    stonesoup_update = False

    def __init__(self):
        self.prune_threshold, self.merge_threshold = jnp.asarray(1e-5), jnp.asarray(4.0)

    def __call__(self, weights, means, covs, active, capacity, free_mean, free_cov):
        keep = active & (weights > self.prune_threshold)
        J, n = capacity, means.shape[1]
        _, chol_inv = jax.vmap(cholesky_and_inverse)(covs)
        prec = jnp.einsum("kji,kjl->kil", chol_inv, chol_inv)

        def one_pass(slot, carry):
            remaining, (w_o, m_o, P_o, a_o) = carry
            has = jnp.any(remaining)
            j = jnp.argmax(jnp.where(remaining, weights, -jnp.inf))
            d = means - means[j][None, :]
            L = remaining & (jnp.einsum("ki,il,kl->k", d, prec[j], d) <= self.merge_threshold)
            wl = jnp.where(L, weights, 0.0)
            wsum = jnp.sum(wl)
            safe = jnp.where(wsum > 0.0, wsum, 1.0)
            mean = jnp.sum(wl[:, None] * means, axis=0) / safe
            dm = mean[None, :] - means
            cov = jnp.sum(wl[:, None, None] * (covs + dm[:, :, None] * dm[:, None, :]), axis=0) / safe
            return remaining & ~L, (w_o.at[slot].set(jnp.where(has, wsum, 0.0)),
                                    m_o.at[slot].set(jnp.where(has, mean, free_mean)),
                                    P_o.at[slot].set(jnp.where(has, cov, free_cov)), a_o.at[slot].set(has))

        empty = (jnp.zeros((J,)), jnp.zeros((J, n)), jnp.zeros((J, n, n)), jnp.zeros((J,), bool))
        remaining, out = jax.lax.fori_loop(0, J, one_pass, (keep, empty))
        return (*out, jnp.sum(remaining).astype(jnp.int32), jnp.sum(jnp.where(remaining, weights, 0.0)),
                jnp.sum(active & ~keep).astype(jnp.int32))


class OneEstimatePerComponent(GMPHD):
    """Extraction of at most one copy of each component above the threshold (a benchmark-only
    variant of Table III; :meth:`GMPHD._extract` is what the runs record)."""

    def _extract(self, mixture):
        return GMPHD._extract(self, eqx.tree_at(lambda x: x.weights, mixture, jnp.minimum(mixture.weights, 1.0)))


def variants(make):
    """``make(cls, reduction strategy, capacity, **options)`` -> a GM-PHD; the module docstring's variants."""
    return {
        "vo-ma": make(GMPHD, reduction("vo-ma"), 100),
        "stonesoup": make(GMPHD, reduction("stonesoup"), 100),
        "vo-ma, capacity 200": make(GMPHD, reduction("vo-ma"), 200),
        "vo-ma update + stonesoup reduction": make(GMPHD, SwappedReduction(update_stonesoup=False), 100),
        "stonesoup update + vo-ma reduction": make(GMPHD, SwappedReduction(update_stonesoup=True), 100),
        "vo-ma without undetected births": make(GMPHD, reduction("vo-ma"), 100, undetected_births=False),
        "vo-ma, distance in the seed's P_j": make(GMPHD, SeedCovarianceMerge(), 100),
        "vo-ma, one estimate per component": make(OneEstimatePerComponent, reduction("vo-ma"), 100),
    }


def _one_run(key, args):
    methods, scen, idx, cutoff = args
    truth = _simulate_one(scen, key)
    z, v = truth.scans.measurements, truth.scans.valid
    out = {}
    for name, f in methods.items():
        r = _run_phd(f, z, v)
        g, _ = score_tracks(truth.states[..., idx], truth.alive, r.estimates[..., idx], r.estimate_mask,
                            jnp.broadcast_to(jnp.arange(r.estimate_mask.shape[1], dtype=jnp.int32),
                                             r.estimate_mask.shape), cutoff=cutoff)
        extracted = r.active & (r.weights > f.extraction_threshold)
        pos_var = jnp.mean(jnp.diagonal(r.covs, axis1=-2, axis2=-1)[..., idx], axis=-1)
        d = jnp.mean(g.distance)
        out[name] = {"gospa": d, "gospa_sq": d**2, "loc": jnp.mean(g.localisation), "missed": jnp.mean(g.missed),
                     "false": jnp.mean(g.false), "estimates": jnp.mean(r.num_estimates),
                     "overfull": jnp.sum(r.num_estimates > f.max_estimates), "events": jnp.sum(r.num_dropped),
                     "pos_var_sum": jnp.sum(jnp.where(extracted, pos_var, 0.0)), "extracted": jnp.sum(extracted)}
    for name in methods:
        diff = out[name]["gospa"] - out[BASE]["gospa"]
        out[name]["diff"], out[name]["diff_sq"] = diff, diff**2
    return out


def compare(label, scen, methods, cutoff, runs, out):
    idx = np.asarray(_positions(scen.model.state_layout, "model"))
    t0 = time.perf_counter()
    s = monte_carlo_map(_one_run, 0, runs, args=(methods, scen, idx, cutoff), block_size=32)
    R = runs
    out(f"\n{label}: {R} runs, GOSPA c = {cutoff:g} m, p = 2 ({time.perf_counter() - t0:.0f} s)")
    out(f"  {'variant':<38}{'mean GOSPA [m]':>18}{'− vo-ma [m]':>17}{'loc':>8}{'missed':>8}{'false':>8}"
        f"{'est/scan':>9}{'cap. events':>12}{'σ_pos [m]':>10}")
    rows = {}
    for name in methods:
        x = {k: float(np.sum(v)) for k, v in s[name].items()}
        mean, dmean = x["gospa"] / R, x["diff"] / R
        half = 1.959963984540054 * np.sqrt(max(x["gospa_sq"] / R - mean**2, 0.0) / (R - 1))
        dhalf = 1.959963984540054 * np.sqrt(max(x["diff_sq"] / R - dmean**2, 0.0) / (R - 1))
        sigma = np.sqrt(x["pos_var_sum"] / max(x["extracted"], 1.0))
        assert x["overfull"] == 0, f"{name}: {x['overfull']} scans extracted more than max_estimates"
        rows[name] = {"gospa": mean, "half": half, "diff": dmean, "diff_half": dhalf, "events": int(x["events"]),
                      "sigma": sigma}
        diff = "" if name == BASE else f"{dmean:+8.2f} ± {dhalf:5.2f}"
        out(f"  {name:<38}{mean:9.2f} ± {half:5.2f}{diff:>17}{x['loc'] / R:8.1f}{x['missed'] / R:8.1f}"
            f"{x['false'] / R:8.1f}{x['estimates'] / R:9.2f}{int(x['events']):12d}{sigma:10.1f}")
    for name in ("vo-ma", "stonesoup"):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            r = multitarget_monte_carlo(methods[name], scen, 0, R, cutoff=cutoff, block_size=32)
        warned = any(issubclass(w.category, CapacityWarning) for w in caught)
        assert abs(r.mean_gospa() - rows[name]["gospa"]) <= 1e-9 * max(1.0, rows[name]["gospa"]), (
            r.mean_gospa(), rows[name]["gospa"])
        assert r.capacity_events == rows[name]["events"], (r.capacity_events, rows[name]["events"])
        out(f"  multitarget_monte_carlo({name}): mean_gospa() {r.mean_gospa():.2f} m, capacity events "
            f"{r.capacity_events}{' (CapacityWarning)' if warned else ''}")
    return rows


def sparse_scenario():
    targets = np.array([[-60.0, -40.0, 1.0, 1.2], [50.0, 30.0, -1.1, 0.2], [0.0, 60.0, 0.5, -1.3],
                        [-20.0, -70.0, 0.8, 0.9], [30.0, -50.0, -0.6, 1.0]])  # [x, y, vx, vy]
    model = constant_velocity(1.0, dim=2, accel_psd=0.3, measurement_std=float(np.sqrt(0.75)),
                              initial_mean=np.zeros(4), initial_cov=np.diag([80.0, 80.0, 2.0, 2.0]) ** 2)
    T = 100
    return Scenario(model, targets, [0, 0, 20, 40, 60], [T, 70, T, T, T], detection_probability=0.9,
                    clutter_rate=1.0, clutter_region=[[-100.0, 100.0]] * 2, max_measurements=16, num_steps=T)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100, help="Monte Carlo runs a scenario (default 100)")
    ap.add_argument("--scenarios", nargs="+", default=["crossing", "williams", "sparse"])
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "measured", "phd_reductions.txt"),
                    help="also write the output here (default benchmarks/measured/phd_reductions.txt)")
    a = ap.parse_args(argv)
    out = Out(a.out)
    out(f"# {time.strftime('%Y-%m-%d')} python {' '.join(sys.argv)}")
    out(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}, float64; "
        f"jaxtrack from {_where(os.path.dirname(reduce_mixture.__code__.co_filename))}")
    out("# GOSPA parts (loc, missed, false) in m², means over runs and scans; σ_pos: the extracted components' "
        "position standard deviation")
    common = dict(max_estimates=MAX_ESTIMATES)
    for which in a.scenarios:
        if which == "crossing":
            scen = crossing_targets()

            def make(cls, strategy, capacity, scen=scen, **options):
                return crossing_phd(scen, strategy, capacity, MAX_ESTIMATES, cls, **options)

            compare("crossing (crossing_targets(), EKF GM-PHD)", scen, variants(make), 100.0, a.runs, out)
        elif which == "williams":
            scen, s = williams_scenario()

            def make(cls, strategy, capacity, scen=scen, s=s, **options):
                return cls(KalmanFilter(), scen.model, prob_survival=s.prob_survival, prob_detect=s.prob_detect,
                           clutter_density=s.clutter_density, birth=s.birth, initial=s.initial,
                           capacity=capacity, reduction=strategy, **common, **options)

            compare("Williams (2015) (williams15(9), the study's Kalman GM-PHD)", scen, variants(make),
                    s.gospa_cutoff, a.runs, out)
        elif which == "sparse":
            scen = sparse_scenario()

            def make(cls, strategy, capacity, scen=scen, **options):
                m = scen.model
                return cls(KalmanFilter(), m, prob_survival=0.99, prob_detect=0.9, clutter_density=scen.clutter_density,
                           birth=GaussianMixture([0.05], [m.initial_mean], [m.initial_cov]),
                           capacity=capacity, reduction=strategy, **common, **options)

            compare("sparse (5 targets, 1 clutter point a scan, Kalman GM-PHD)", scen, variants(make), 10.0,
                    a.runs, out)
        else:
            sys.exit(f"unknown scenario {which!r}")


if __name__ == "__main__":
    main()

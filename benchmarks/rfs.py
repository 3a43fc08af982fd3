"""GM-PHD and GM-CPHD per scan: jaxtrack's ``run_phd`` / ``run_cphd`` against Stone Soup's GM-PHD.

The scenario: a 2-D constant-velocity model in Stone Soup's state order ``[x, vx, y, vy]``
(``ConstantVelocity(q = 0.3 m²/s³)`` per axis, τ = 1 s), positions measured with
``R = 0.75 m²·I``; five targets in a 200 m × 200 m square centred at the origin, two alive from
the first scan, three born at scans ``T/5``, ``2T/5``, ``3T/5`` (one of the first two dies at
``0.7 T``), detected with ``P_D = 0.9``, and ``Poisson(10)`` clutter points per scan uniform over
the square; ``--scans`` scans (default 50). jaxtrack simulates it (``Scenario`` and
``simulate_scenarios``: run ``i`` from ``jax.random.fold_in(key, i)``); every scan is padded to
the largest scan of the whole draw (``max_measurements``, with a validity mask).

The filter on both sides is the GM-PHD with ``P_S = 0.99``, ``P_D = 0.9``, clutter density
``κ = 10 / (200 m)²``, one birth component (weight 0.25, mean 0, standard deviations 80 m and
2 m/s), no gate, pruning below ``T = 1e-5`` and merging within a squared Mahalanobis distance
``U = 4`` (Vo & Ma's values): Stone Soup's ``GaussianMixtureHypothesiser`` over a
``DistanceHypothesiser(KalmanPredictor, KalmanUpdater, Mahalanobis(), include_all=True)``,
``PHDUpdater`` and ``GaussianMixtureReducer``, the birth component joining the reduced mixture
at each scan (as ``tests/test_gm_phd.py`` sets it up); jaxtrack's ``GMPHD(KalmanFilter(), ...,
reduction=StoneSoupReduction(...), capacity=--capacity)``, which reproduces Stone Soup's updater and reducer.

Timed:

- **jaxtrack GM-PHD**, one run: ``jax.jit(run_phd)`` on run 0 over all scans; returns every
  scan's reduced mixture (weights, means, covariances, active slots) and estimates. A batch:
  ``jax.jit(jax.vmap(run_phd))`` over ``--runs`` runs (default 64), per scan per run =
  wall / (runs × scans). Compilation (``lower().compile()``) is reported separately and a
  warm-up call precedes the clock; each time is the best of ``--repeats``.
- **Stone Soup GM-PHD** on run 0: a Python loop over the scans (hypothesise, update, reduce);
  its ``Detection`` and birth objects are built before the clock, each scan is timed on its own,
  per scan is the mean over the scans of the best of ``--ss-repeats`` passes (median printed
  too). With ``--ss-scans`` below ``--scans`` it runs (and is checked on) the first scans only.
- **jaxtrack GM-CPHD** (``run_cphd``, Vo, Vo & Cantoni 2007; Stone Soup has none): the same
  model, ``P_S``, ``P_D``, births and thresholds, clutter rate 10 and spatial density
  ``1 / (200 m)²``, ``max_cardinality`` 30, Vo & Ma's reduction (``"vo-ma"``, the only one it
  has); one run and a batch of the first ``--cphd-runs`` runs (default 16: it takes ~20 ms a
  scan), timed as the GM-PHD. Its cost is compared with jaxtrack's GM-PHD with the same
  ``"vo-ma"`` reduction (also timed, same batch) and with the ``"stonesoup"`` one.

Each round times every jaxtrack program, then (in the first ``--ss-repeats`` rounds) Stone Soup,
so that load drifts hit all alike.

Equal work (asserted before any timing): on the timed run, scan by scan, Stone Soup's reduced
mixture has as many components as jaxtrack's, and after matching them (an assignment on weight
and mean) the weights and means agree within 1e-9 and the covariances within 1e-9 relative to
``1 + |P|``; run 0 of the batch equals the single run (1e-9); no run of any jaxtrack filter left a
component over for want of slots (``overflow``), and the CPHD's cardinality was not truncated.

jaxtrack pays for padding that Stone Soup does not: each scan updates ``capacity + 1`` component
slots on ``max_measurements`` measurement slots, ``(1 + M)·(J + 1)`` updated slots (the counts of
live components and measurements are printed next to the padded sizes).

Where jaxtrack's GM-PHD scan goes (one run, ``J = 128``, ``M = 27``: 3612 updated slots, ~70
kept after pruning): ~0.3 ms predict, update and the sort of the slots; the rest is Stone Soup's
sequential merging, a ``while_loop`` over the merges actually made (before it, fixed loops over
every slot and candidate took 175 ms a scan). A vmapped batch costs about as much per run as
one run: ``vmap`` steps the runs' loops side by side until the longest is done. The ``"vo-ma"``
reduction (the GM-CPHD's) still runs ``J`` fixed vectorised passes over all the updated slots.

Needs Stone Soup (the ``bench`` extra). Usage::

    python benchmarks/rfs.py                 # 50 scans, batch of 64 runs (GM-CPHD 16), ~9 min on 2 cores
    python benchmarks/rfs.py --quick         # a smoke test (10 scans, 4 runs, GM-CPHD one run)
    python benchmarks/rfs.py --json out.json
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import time

import jax
import numpy as np

import jaxtrack
from jaxtrack.filters import KalmanFilter
from jaxtrack.models import LinearGaussianModel
from jaxtrack.multitarget import (
    GMCPHD,
    GMPHD,
    GaussianMixture,
    StoneSoupReduction,
    VoMaReduction,
    Scenario,
    run_cphd,
    run_phd,
    simulate_scenarios,
)

Q, R_VAR = 0.3, 0.75  # m²/s³, m²
HALF_WIDTH = 100.0  # m: the square is [-100, 100]²
AREA = (2 * HALF_WIDTH) ** 2
P_S, P_D, CLUTTER_RATE = 0.99, 0.9, 10.0
KAPPA = CLUTTER_RATE / AREA
BIRTH_W = 0.25
BIRTH_M = np.zeros(4)
BIRTH_P = np.diag([80.0, 2.0, 80.0, 2.0]) ** 2
PRUNE, MERGE = 1e-5, 4.0
MAX_CARDINALITY = 30
TARGETS = np.array([[-60.0, 1.0, -40.0, 1.2], [50.0, -1.1, 30.0, 0.2], [0.0, 0.5, 60.0, -1.3],
                    [-20.0, 0.8, -70.0, 0.9], [30.0, -0.6, -50.0, 1.0]])  # [x, vx, y, vy]
TOL = 1e-9


def stonesoup_models():
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )

    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(Q), ConstantVelocity(Q)])
    measurement = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=R_VAR * np.eye(2))
    return transition, measurement


def make_model():
    """jaxtrack's model with Stone Soup's own matrices (so that both filter the same model)."""
    transition, measurement = stonesoup_models()
    tau = datetime.timedelta(seconds=1)
    return LinearGaussianModel(transition.matrix(time_interval=tau), transition.covar(time_interval=tau),
                               measurement.matrix(), measurement.covar(), BIRTH_M, BIRTH_P)


def draw_scans(model, num_runs, num_scans, seed=0):
    """``(z (R, T, M, 2), valid (R, T, M), live targets per scan (R, T))``, padded to the largest scan."""
    births = [0, 0, num_scans // 5, 2 * num_scans // 5, 3 * num_scans // 5]
    deaths = [num_scans, max(int(0.7 * num_scans), 1), num_scans, num_scans, num_scans]
    slots = len(TARGETS) + int(np.ceil(CLUTTER_RATE + 8 * np.sqrt(CLUTTER_RATE))) + 8
    scenario = Scenario(model, TARGETS, births, deaths, detection_probability=P_D, clutter_rate=CLUTTER_RATE,
                        clutter_region=[[-HALF_WIDTH, HALF_WIDTH]] * 2, max_measurements=slots,
                        num_steps=num_scans)
    traj = simulate_scenarios(scenario, jax.random.key(seed), num_runs)
    valid = np.asarray(traj.scans.valid)
    if bool(np.any(np.asarray(traj.overflow))):
        raise AssertionError("a scan overflowed max_measurements")
    m = int(valid.sum(-1).max())  # the scenario packs the valid rows first
    z = np.asarray(traj.scans.measurements)[:, :, :m].copy()
    z[~valid[:, :, :m]] = np.nan
    return z, valid[:, :, :m], np.asarray(traj.alive).sum(-1)


def make_phd(model, capacity, reduction):
    strategy = (StoneSoupReduction if reduction == "stonesoup" else VoMaReduction)(PRUNE, MERGE)
    return GMPHD(KalmanFilter(), model, prob_survival=P_S, prob_detect=P_D, clutter_density=KAPPA,
                 birth=GaussianMixture([BIRTH_W], [BIRTH_M], [BIRTH_P]), capacity=capacity, reduction=strategy)


def make_cphd(model, capacity):
    return GMCPHD(KalmanFilter(), model, prob_survival=P_S, prob_detect=P_D, clutter_rate=CLUTTER_RATE,
                  clutter_volume=AREA, birth=GaussianMixture([BIRTH_W], [BIRTH_M], [BIRTH_P]),
                  capacity=capacity, max_cardinality=MAX_CARDINALITY, reduction=VoMaReduction(PRUNE, MERGE))


def timed(fn) -> float:
    t = time.perf_counter()
    jax.block_until_ready(fn())
    return time.perf_counter() - t


def compiled_pair(run, filt, z, valid, runs):
    """``(one run, batch, compile seconds of each)``: ``jit(run)`` on run 0, ``jit(vmap(run))`` on
    the first ``runs`` (no batch for none)."""
    def one(zz, vv):
        return run(filt, zz, vv, warn=False)

    out = {}
    t = time.perf_counter()
    single = jax.jit(one).lower(z[0], valid[0]).compile()
    out["one run"] = time.perf_counter() - t
    if runs == 0:
        return single, None, out
    t = time.perf_counter()
    batch = jax.jit(jax.vmap(one)).lower(z[:runs], valid[:runs]).compile()
    out["batch"] = time.perf_counter() - t
    return single, batch, out


# ---------------------------------------------------------------------------------------------
# Stone Soup


def stonesoup_inputs(z, valid):
    """The filter's parts, and per scan (time, detections, birth component), built before the clock."""
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.gaussianmixture import GaussianMixtureHypothesiser
    from stonesoup.measures import Mahalanobis
    from stonesoup.mixturereducer.gaussianmixture import GaussianMixtureReducer
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import TaggedWeightedGaussianState
    from stonesoup.updater.kalman import KalmanUpdater
    from stonesoup.updater.pointprocess import PHDUpdater

    transition, measurement = stonesoup_models()
    kalman = KalmanUpdater(measurement)
    base = DistanceHypothesiser(KalmanPredictor(transition), kalman, Mahalanobis(), missed_distance=3,
                                include_all=True)
    hypothesiser = GaussianMixtureHypothesiser(base, order_by_detection=True)
    updater = PHDUpdater(kalman, clutter_spatial_density=KAPPA, prob_detection=P_D, prob_survival=P_S)
    reducer = GaussianMixtureReducer(prune_threshold=PRUNE, merge_threshold=MERGE)
    t0 = datetime.datetime(2026, 1, 1)
    scans = []
    for k in range(z.shape[0]):
        t = t0 + datetime.timedelta(seconds=k)
        birth = TaggedWeightedGaussianState(state_vector=BIRTH_M, covar=BIRTH_P, weight=BIRTH_W,
                                            tag=TaggedWeightedGaussianState.BIRTH, timestamp=t)
        scans.append((t, [Detection(zj, timestamp=t, measurement_model=measurement) for zj in z[k][valid[k]]],
                       birth))
    return (hypothesiser, updater, reducer), scans


def stonesoup_run(parts, scans):
    """One pass: ``(seconds per scan (T,), [(weights, means, covs) per scan])``."""
    hypothesiser, updater, reducer = parts
    reduced, seconds, history = [], [], []
    for t, detections, birth in scans:
        start = time.perf_counter()
        hypotheses = hypothesiser.hypothesise(reduced + [birth], detections, t, order_by_detection=True)
        reduced = list(reducer.reduce(list(updater.update(hypotheses))))
        seconds.append(time.perf_counter() - start)
        history.append((np.array([float(c.weight) for c in reduced]),
                        np.array([np.asarray(c.state_vector, float).ravel() for c in reduced]).reshape(-1, 4),
                        np.array([np.asarray(c.covar, float) for c in reduced]).reshape(-1, 4, 4)))
    return np.asarray(seconds), history


def compare(result, history):
    """Largest |Δ| of weights, means and covariances (relative to 1 + |P|) over the scans of
    ``history``, after matching Stone Soup's components to jaxtrack's; the counts must agree."""
    from scipy.optimize import linear_sum_assignment

    worst = {"weight": 0.0, "mean": 0.0, "cov": 0.0}
    for k, (w_ss, m_ss, P_ss) in enumerate(history):
        act = np.asarray(result.active[k])
        w, m, P = (np.asarray(a[k])[act] for a in (result.weights, result.means, result.covs))
        if w.shape != w_ss.shape:
            raise AssertionError(f"scan {k}: jaxtrack {w.shape[0]} components, Stone Soup {w_ss.shape[0]}")
        cost = np.abs(w[:, None] - w_ss[None, :]) + np.abs(m[:, None, :] - m_ss[None, :, :]).sum(-1)
        _, cols = linear_sum_assignment(cost)
        worst["weight"] = max(worst["weight"], float(np.max(np.abs(w - w_ss[cols]), initial=0.0)))
        worst["mean"] = max(worst["mean"], float(np.max(np.abs(m - m_ss[cols]), initial=0.0)))
        worst["cov"] = max(worst["cov"], float(np.max(np.abs(P - P_ss[cols]) / (1.0 + np.abs(P_ss[cols])),
                                                      initial=0.0)))
    return worst


def batch_vs_single(single, batch):
    """Largest |Δ| between run 0 of the batch and the single run (weights, means, covariances)."""
    return max(float(np.max(np.abs(np.asarray(getattr(batch, f)[0]) - np.asarray(getattr(single, f))),
                            initial=0.0)) for f in ("weights", "means", "covs"))


# ---------------------------------------------------------------------------------------------


def bench(num_scans, num_runs, cphd_runs, ss_scans, capacity, repeats, ss_repeats, vo_ma=True, seed=0) -> dict:
    model = make_model()
    t = time.perf_counter()
    z, valid, live = draw_scans(model, num_runs, num_scans, seed)
    draw_s = time.perf_counter() - t
    zj, vj = jax.device_put(z), jax.device_put(valid)
    cphd_runs = min(cphd_runs, num_runs)
    filters = {"GM-PHD stonesoup": (run_phd, make_phd(model, capacity, "stonesoup"), num_runs)}
    if vo_ma:
        filters["GM-PHD vo-ma"] = (run_phd, make_phd(model, capacity, "vo-ma"), cphd_runs)
    filters["GM-CPHD"] = (run_cphd, make_cphd(model, capacity), cphd_runs)
    programs, compile_s, outputs = {}, {}, {}
    for name, (run, filt, runs) in filters.items():
        zb, vb = zj[:runs], vj[:runs]
        single, batch, compile_s[name] = compiled_pair(run, filt, zj, vj, runs)
        programs[name] = {"one": lambda c=single: c(zj[0], vj[0])}
        if batch is not None:
            programs[name]["batch"] = lambda c=batch, zb=zb, vb=vb: c(zb, vb)
        outputs[name] = {k: jax.block_until_ready(fn()) for k, fn in programs[name].items()}  # warm-up; checked
        print(f"  compiled {name}: " + ", ".join(f"{k} {v:.1f} s" for k, v in compile_s[name].items()), flush=True)

    # Checks, before any timing.
    for name, out in outputs.items():
        for r in out.values():
            if bool(np.any(np.asarray(r.overflow))):
                raise AssertionError(f"{name}: capacity {capacity} too small (components left over); raise --capacity")
            if name == "GM-CPHD" and (bool(np.any(np.asarray(r.truncated))) or not bool(np.all(np.asarray(r.ok)))):
                raise AssertionError("GM-CPHD: cardinality truncated or an update not finite")
        if "batch" in out and (d := batch_vs_single(out["one"], out["batch"])) > TOL:
            raise AssertionError(f"{name}: batch run 0 differs from the single run by {d:.1e}")
    ss_scans = min(ss_scans, num_scans)
    parts, ss_inputs = stonesoup_inputs(z[0, :ss_scans], valid[0, :ss_scans])
    seconds, history = stonesoup_run(parts, ss_inputs)  # its warm-up, and the run checked
    worst = compare(outputs["GM-PHD stonesoup"]["one"], history)
    if max(worst.values()) > TOL:
        raise AssertionError(f"jaxtrack and Stone Soup differ: {worst}")
    print(f"  equal work: {ss_scans} scans, max |Δ| weight {worst['weight']:.1e}, mean {worst['mean']:.1e} m, "
          f"covariance {worst['cov']:.1e} (relative)", flush=True)

    best = {name: {k: np.inf for k in fns} for name, fns in programs.items()}
    ss_best = seconds if ss_repeats < 1 else np.full(ss_scans, np.inf)
    for r in range(max(repeats, ss_repeats)):  # interleaved rounds
        if r < repeats:
            for name, fns in programs.items():
                for k, fn in fns.items():
                    best[name][k] = min(best[name][k], timed(fn))
        if r < ss_repeats:
            ss_best = np.minimum(ss_best, stonesoup_run(parts, ss_inputs)[0])
    ss_scan = float(np.mean(ss_best))
    per_scan = {}
    for name, b in best.items():
        runs = filters[name][2]
        per_scan[name] = {"one_run_wall_s": b["one"], "one_run_s": b["one"] / num_scans, "batch_runs": runs}
        if "batch" in b:
            per_scan[name].update(batch_wall_s=b["batch"], batch_per_run_s=b["batch"] / (runs * num_scans))
    ratio = {}  # numerator / denominator per scan, one run and batch
    for key, num, den in (("speed_up", "Stone Soup", "GM-PHD stonesoup"),
                          ("stone_soup_phd_over_cphd", "Stone Soup", "GM-CPHD"),
                          ("cphd_over_phd_stonesoup", "GM-CPHD", "GM-PHD stonesoup"),
                          ("cphd_over_phd_vo_ma", "GM-CPHD", "GM-PHD vo-ma")):
        if den not in per_scan:
            continue
        ratio[key] = {}
        for k in ("one_run_s", "batch_per_run_s"):
            top = ss_scan if num == "Stone Soup" else per_scan[num].get(k)
            if top is not None and k in per_scan[den]:
                ratio[key][k.removesuffix("_s")] = top / per_scan[den][k]
    one, many = outputs["GM-PHD stonesoup"]["one"], outputs["GM-PHD stonesoup"].get("batch")
    counts = valid.sum(-1)
    return {
        "scans": num_scans, "runs": num_runs, "cphd_runs": cphd_runs, "stone_soup_scans": ss_scans,
        "capacity": capacity, "max_measurements": int(z.shape[2]),
        "mean_measurements_per_scan": float(counts.mean()), "mean_live_targets": float(live.mean()),
        "live_components_run0_mean_max": [float(np.asarray(one.active).sum(-1).mean()),
                                          int(np.asarray(one.active).sum(-1).max())],
        "live_components_batch_max": int(np.asarray((many or one).active).sum(-1).max()),
        "updated_slots_per_scan": int((1 + z.shape[2]) * (capacity + 1)),
        "draw_s": draw_s, "compile_s": compile_s, "per_scan": per_scan,
        "stone_soup_per_scan_mean_s": ss_scan, "stone_soup_per_scan_median_s": float(np.median(ss_best)),
        "stone_soup_per_scan_max_s": float(np.max(ss_best)),
        "max_abs_difference": worst, "ratios": ratio,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="10 scans, 4 runs, 2 repeats; GM-CPHD one run only, no vo-ma GM-PHD (a smoke test)")
    parser.add_argument("--scans", type=int, default=None, help="T (default 50)")
    parser.add_argument("--runs", type=int, default=None, help="runs in the vmapped batch (default 64)")
    parser.add_argument("--cphd-runs", type=int, default=None,
                        help="runs in the GM-CPHD's and vo-ma GM-PHD's batch, the first ones (default 16; 0: one run only)")
    parser.add_argument("--ss-scans", type=int, default=None, help="scans Stone Soup runs, the first ones (default T)")
    parser.add_argument("--capacity", type=int, default=128, help="jaxtrack mixture slots J_max (default 128)")
    parser.add_argument("--repeats", type=int, default=None, help="timed rounds for jaxtrack (default 5)")
    parser.add_argument("--ss-repeats", type=int, default=None, help="timed passes for Stone Soup (default 3)")
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    args = parser.parse_args()
    scans, runs, cphd_runs, repeats, ss_repeats = (10, 4, 0, 2, 1) if args.quick else (50, 64, 16, 5, 3)
    scans, runs = args.scans or scans, args.runs or runs
    cphd_runs = args.cphd_runs if args.cphd_runs is not None else cphd_runs
    repeats = args.repeats or repeats
    ss_repeats = args.ss_repeats if args.ss_repeats is not None else ss_repeats
    ss_scans = min(args.ss_scans or scans, scans)
    machine = {"cores": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
               "jax": jax.__version__, "jaxtrack": getattr(jaxtrack, "__version__", "dev"),
               "backend": jax.default_backend(), "dtype": "float64"}
    try:
        import stonesoup
        machine["stonesoup"] = stonesoup.__version__
    except ImportError:
        sys.exit("needs Stone Soup: pip install -e '.[bench]'")
    print(f"GM-PHD / GM-CPHD, 2-D CV, {len(TARGETS)} targets with births, P_D {P_D}, {CLUTTER_RATE:g} clutter/scan "
          f"over {2 * HALF_WIDTH:.0f} m × {2 * HALF_WIDTH:.0f} m, {scans} scans, prune {PRUNE:g}, merge {MERGE:g}; "
          f"float64, {machine['cores']} cores ({machine['backend']}), jax {machine['jax']}, "
          f"Stone Soup {machine['stonesoup']}, best of {repeats} (Stone Soup {max(ss_repeats, 1)})")
    print(f"platform: {machine['platform']}, python {machine['python']}")
    print(f"command: python {' '.join(sys.argv)}")
    load_before = os.getloadavg()[0]
    print(f"load average before: {load_before:.2f}")
    row = bench(scans, runs, cphd_runs, ss_scans, args.capacity, repeats, ss_repeats, vo_ma=not args.quick)
    row["load_average_before_after"] = [load_before, os.getloadavg()[0]]

    ps, T, S, ss = row["per_scan"], row["scans"], row["stone_soup_scans"], row["stone_soup_per_scan_mean_s"]
    print(f"\n  {'per scan, excluding compilation':48s}{'runs × scans':>14s}{'wall':>12s}{'per scan':>12s}"
          f"{'Stone Soup /':>14s}")
    for name, label in (("GM-PHD stonesoup", "jaxtrack GM-PHD (reduction=stonesoup)"),
                        ("GM-PHD vo-ma", "jaxtrack GM-PHD (reduction=vo-ma)"), ("GM-CPHD", "jaxtrack GM-CPHD")):
        if name not in ps:
            continue
        v, R = ps[name], ps[name]["batch_runs"]
        print(f"  {label + ', one run':48s}{f'1 × {T}':>14s}{v['one_run_wall_s'] * 1e3:9.1f} ms"
              f"{v['one_run_s'] * 1e3:9.3f} ms{ss / v['one_run_s']:13.1f}×")
        if "batch_per_run_s" in v:
            print(f"  {label + f', vmap batch of {R}':48s}{f'{R} × {T}':>14s}{v['batch_wall_s'] * 1e3:9.1f} ms"
                  f"{v['batch_per_run_s'] * 1e3:9.3f} ms{ss / v['batch_per_run_s']:13.1f}×")
    print(f"  {'Stone Soup GM-PHD':48s}{f'1 × {S}':>14s}{ss * S * 1e3:9.1f} ms{ss * 1e3:9.3f} ms"
          f"   (median {row['stone_soup_per_scan_median_s'] * 1e3:.2f} ms, max {row['stone_soup_per_scan_max_s'] * 1e3:.2f} ms)")
    if S < T:
        print(f"  (Stone Soup ran the first {S} of the {T} scans; its time is per scan over those)")
    print("\n  compilation (once, not in the times above): " + "; ".join(
        f"{name} " + " / ".join(f"{k} {v:.1f} s" for k, v in c.items()) for name, c in row["compile_s"].items()))
    print(f"  padding (jaxtrack pays for it): capacity {row['capacity']} component slots (live after reduction, "
          f"run 0: mean {row['live_components_run0_mean_max'][0]:.1f}, max {row['live_components_run0_mean_max'][1]}; "
          f"batch max {row['live_components_batch_max']}), max_measurements {row['max_measurements']} "
          f"(measurements per scan: mean {row['mean_measurements_per_scan']:.1f}): "
          f"{row['updated_slots_per_scan']} updated slots per scan")
    w = row["max_abs_difference"]
    print(f"  equal work, run 0, {S} scans: the same number of components every scan, max |Δ| weight "
          f"{w['weight']:.1e}, mean {w['mean']:.1e} m, covariance {w['cov']:.1e} (relative to 1 + |P|); "
          f"no overflow in any run (capacity {row['capacity']})")
    r = row["ratios"]
    hits = {k: v >= 100 for k, v in r["speed_up"].items()}
    met = "met" if all(hits.values()) else ("not met" if not any(hits.values()) else
                                            "met for the " + ", ".join(k.replace("_", " ") for k, h in hits.items() if h) + " only")
    print(f"\n  Stone Soup / jaxtrack GM-PHD per scan: one run {r['speed_up']['one_run']:.1f}×"
          + (f", batch of {row['runs']} {r['speed_up']['batch_per_run']:.1f}× per run" if "batch_per_run" in r["speed_up"]
             else "") + f" — target >= 100x: {met}")
    for key, what in (("one_run", "one run"), ("batch_per_run", f"batch of {row['cphd_runs']}")):
        if key not in r["stone_soup_phd_over_cphd"]:
            continue
        vs_vo = (f"{r['cphd_over_phd_vo_ma'][key]:.2f}× jaxtrack's GM-PHD with the same reduction (vo-ma), "
                 if key in r.get("cphd_over_phd_vo_ma", {}) else "")
        print(f"  GM-CPHD per scan, {what}: {vs_vo}{r['cphd_over_phd_stonesoup'][key]:.1f}× its GM-PHD "
              f"(stonesoup); Stone Soup's GM-PHD / jaxtrack's GM-CPHD {r['stone_soup_phd_over_cphd'][key]:.1f}×")
    print(f"\nload average after: {os.getloadavg()[0]:.2f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"machine": machine, "command": "python " + " ".join(sys.argv), "rows": [row]}, f, indent=2)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

"""JPDA multi-target tracking, per scan: jaxtrack's ``Tracker(JPDA())`` against Stone Soup's JPDA tracker.

The scenario is the linear one of ``tests/test_multitarget_tracker.py`` with more clutter: a 2-D
constant-velocity model (``[x, y, vx, vy]``, τ = 1 s, white-acceleration ``q = 0.05`` m²/s³,
position measured with σ = 1 m), four targets crossing near the centre of a 200 m × 200 m region
for 100 scans, detected with ``P_D = 0.9``, and ``Poisson(--clutter)`` clutter points per scan
(default 10) uniform over the region. Every run's scans are drawn once with NumPy (truth,
detections, clutter; detections first in target order, then clutter) and padded to the largest
scan of the whole draw (``max_measurements``, with a validity mask).

The tracker on both sides is the configuration the test checks jaxtrack against: Stone Soup's
``MultiTargetMixtureTracker`` with ``JPDA(PDAHypothesiser(KalmanPredictor, KalmanUpdater,
clutter_spatial_density=λ/area, prob_detect=0.9, prob_gate=0.99, include_all=False))``, a
``SinglePointInitiator`` on the broad prior (every unclaimed detection starts a track) and an
``UpdateTimeStepsDeleter(3)``; jaxtrack's ``Tracker(KalmanFilter(), model, JPDA(),
OnePointInitiator(prior), prob_detect, clutter_density, prob_gate=0.99, capacity=--capacity,
management=TrackManagement(1, 1, 3))``.

Timed:

- **jaxtrack**: ``jax.jit(jax.vmap(run_tracker))`` over blocks of ``--block`` runs (default 16)
  × 100 scans, the blocks one after another, ``--runs`` runs in all (the scans drawn with NumPy,
  not ``multitarget_monte_carlo``, so that Stone Soup gets the very same detections). A call returns
  every scan's track means, statuses and ids ``(B, T, N, ·)`` and the refused births; the
  association matrices and covariances are not returned (XLA drops them). Blocks, because the
  time per scan grows with the batch on a 2-core CPU (measured: 2.5 ms per scan with 16 runs a
  call, 3.5 ms with 64, 8.3 ms with 256). Compilation (``lower().compile()``) is reported
  separately and a warm-up call precedes the clock; the time is the best of ``--repeats`` passes
  over all runs, and per scan is wall / (runs × scans).
- **Stone Soup**: the same tracker on the first ``--ss-runs`` runs (the same detections as
  jaxtrack's first runs), a Python loop over scans per run; its ``Detection`` objects are built
  before the clock starts, and each scan (``next(tracker)`` plus a copy of the set of tracks it
  yields) is timed on its own; per scan is the mean (median and max printed too). Two data
  associators, both exact JPDA with the same marginals: ``JPDA``, the one the test checks
  against, which enumerates joint events over all tracks at once (``itertools.product`` of every
  track's gated hypotheses, so its cost grows with the product of the gate counts), and
  ``JPDAwithEHM`` (Efficient Hypothesis Management on the clusters, Maskell et al. 2004), Stone
  Soup's fast exact JPDA.

Equal work: on every Stone Soup run, every track of every scan is matched to jaxtrack's by the
detection it was born at (as in the test), the sets of tracks must agree scan by scan, and the
largest absolute difference of the track means is printed (asserted < 1e-6 m).

jaxtrack pays for padding that Stone Soup does not: every scan is ``capacity`` track slots ×
``max_measurements`` measurement slots whatever is alive or measured (the live-track and
measurement counts are printed next to the padded sizes), and its exact JPDA runs on the
clusters of the gating graph with static caps (every track the root of a small cluster, plus
the two largest clusters of up to 8 tracks). Stone Soup pays for Python objects per hypothesis.

Needs Stone Soup (the ``bench`` extra). Usage::

    python benchmarks/multitarget.py                 # 1000 runs × 100 scans, Stone Soup on 3 (~15 min)
    python benchmarks/multitarget.py --runs 256      # what benchmarks/measured/multitarget.txt ran
    python benchmarks/multitarget.py --runs 64       # a quick look
    python benchmarks/multitarget.py --json out.json
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

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from peers import peak_rss_mb  # noqa: E402

import jaxtrack  # noqa: E402
from jaxtrack.association import JPDA  # noqa: E402
from jaxtrack.filters import KalmanFilter  # noqa: E402
from jaxtrack.models import constant_velocity  # noqa: E402
from jaxtrack.multitarget import OnePointInitiator, Tracker, TrackManagement, run_tracker  # noqa: E402

Q, SIGMA, P_D, P_G = 0.05, 1.0, 0.9, 0.99  # m²/s³, m, -, -
REGION = np.array([[0.0, 200.0], [0.0, 200.0]])  # m
AREA = float(np.prod(REGION[:, 1] - REGION[:, 0]))
NUM_STEPS = 100
DELETE_AFTER = 3  # scans without a hit
PRIOR_MEAN = np.array([100.0, 100.0, 0.0, 0.0])
PRIOR_COV = np.diag([1e4, 1e4, 4.0, 4.0])
TARGETS = np.array([[40.0, 40.0, 1.2, 1.2], [40.0, 160.0, 1.2, -1.2], [160.0, 40.0, -1.2, 1.2],
                    [100.0, 30.0, 0.0, 1.4]])


def draw_scans(num_runs, num_steps, clutter_rate, seed=0):
    """``(z (R, T, M, 2), valid (R, T, M))``: detections then clutter, NaN-padded to the largest scan."""
    rng = np.random.default_rng(seed)
    F = np.kron(np.array([[1.0, 1.0], [0.0, 1.0]]), np.eye(2))
    LQ = np.linalg.cholesky(np.kron(Q * np.array([[1 / 3, 1 / 2], [1 / 2, 1.0]]), np.eye(2)))
    num_targets = len(TARGETS)
    x = np.broadcast_to(TARGETS, (num_runs, num_targets, 4)).copy()
    counts = rng.poisson(clutter_rate, (num_runs, num_steps))
    c_max = int(counts.max())
    cand = np.empty((num_runs, num_steps, num_targets + c_max, 2))
    ok = np.zeros(cand.shape[:3], bool)
    for k in range(num_steps):
        cand[:, k, :num_targets] = x[..., :2] + SIGMA * rng.standard_normal((num_runs, num_targets, 2))
        ok[:, k, :num_targets] = rng.uniform(size=(num_runs, num_targets)) < P_D
        cand[:, k, num_targets:] = REGION[:, 0] + (REGION[:, 1] - REGION[:, 0]) * rng.uniform(
            size=(num_runs, c_max, 2))
        ok[:, k, num_targets:] = np.arange(c_max) < counts[:, k, None]
        x = x @ F.T + rng.standard_normal(x.shape) @ LQ.T
    # Pack each scan's valid rows to the front (stable: detections in target order, then clutter).
    order = np.argsort(~ok, axis=-1, kind="stable")
    z = np.take_along_axis(cand, order[..., None], axis=2)
    valid = np.take_along_axis(ok, order, axis=2)
    max_meas = int(valid.sum(-1).max())
    z, valid = z[:, :, :max_meas], valid[:, :, :max_meas]
    z[~valid] = np.nan
    return z, valid


def make_tracker(clutter_rate, capacity):
    model = constant_velocity(1.0, dim=2, accel_psd=Q, measurement_std=SIGMA,
                              initial_mean=PRIOR_MEAN, initial_cov=PRIOR_COV)
    return Tracker(KalmanFilter(), model, JPDA(), OnePointInitiator(PRIOR_MEAN, PRIOR_COV),
                   prob_detect=P_D, clutter_density=clutter_rate / AREA, prob_gate=P_G, capacity=capacity,
                   management=TrackManagement(1, 1, DELETE_AFTER))


def jaxtrack_job(tracker):
    """``jit(vmap(run_tracker))``: every scan's track means, statuses, ids, and the refused births."""
    def one(z, valid):
        r = run_tracker(tracker, z, valid, warn=False)
        return r.mean, r.status, r.track_id, r.final.num_dropped_births

    return jax.jit(jax.vmap(one))


# ---------------------------------------------------------------------------------------------
# Stone Soup


def stonesoup_inputs(z, valid, clutter_rate):
    """The tracker's parts and each run's detections per scan (built before the clock)."""
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.types.detection import Detection

    meas_model = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=SIGMA**2 * np.eye(2))
    t0 = datetime.datetime(2026, 1, 1)
    times = [t0 + datetime.timedelta(seconds=k) for k in range(z.shape[1])]
    runs = [[(times[k], {Detection(z_run[k, j][:, None], timestamp=times[k], measurement_model=meas_model,
                                    metadata={"index": (k, j)}) for j in np.flatnonzero(v_run[k])})
             for k in range(z.shape[1])] for z_run, v_run in zip(z, valid, strict=True)]
    return meas_model, t0, runs


def stonesoup_tracker(meas_model, t0, scans, clutter_rate, associator="JPDA"):
    from stonesoup.dataassociator import probability
    from stonesoup.deleter.time import UpdateTimeStepsDeleter
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.initiator.simple import SinglePointInitiator
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.tracker.simple import MultiTargetMixtureTracker
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import KalmanUpdater

    perm = [0, 2, 1, 3]  # Stone Soup orders [x, vx, y, vy]
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(Q), ConstantVelocity(Q)])
    predictor = KalmanPredictor(transition)
    updater = KalmanUpdater(meas_model)
    hypothesiser = PDAHypothesiser(predictor, updater, clutter_spatial_density=clutter_rate / AREA,
                                   prob_detect=P_D, prob_gate=P_G, include_all=False)
    prior = GaussianState(PRIOR_MEAN[perm][:, None], PRIOR_COV[np.ix_(perm, perm)], timestamp=t0)

    class Reader:
        def __iter__(self):
            return iter(scans)

    return MultiTargetMixtureTracker(
        initiator=SinglePointInitiator(prior, meas_model), deleter=UpdateTimeStepsDeleter(DELETE_AFTER),
        detector=Reader(), data_associator=getattr(probability, associator)(hypothesiser), updater=updater)


def stonesoup_run(meas_model, t0, scans, clutter_rate, associator):
    """One run: the tracks alive after each scan (timed, per scan), then their means per scan.

    Returns ``(seconds per scan (T,), {(birth scan, birth detection): {scan: mean [x, y, vx, vy]}})``.
    """
    tracker = iter(stonesoup_tracker(meas_model, t0, scans, clutter_rate, associator))
    alive, seconds = [], []
    for _ in scans:
        t = time.perf_counter()
        _, tracks = next(tracker)
        alive.append(set(tracks))
        seconds.append(time.perf_counter() - t)
    inverse = np.argsort([0, 2, 1, 3])
    history = {}
    for k, tracks in enumerate(alive):
        stamp = scans[k][0]
        for track in tracks:
            key = track.states[0].hypothesis.measurement.metadata["index"]
            state = next(s for s in reversed(track.states) if s.timestamp == stamp)
            history.setdefault(key, {})[k] = np.asarray(state.state_vector, float).ravel()[inverse]
    return np.asarray(seconds), history


def jaxtrack_history(mean, status, ids, z, valid):
    """One jaxtrack run in the same form: tracks keyed by the detection they were born at."""
    births, tracks = {}, {}
    for k in range(mean.shape[0]):
        for s in np.flatnonzero(status[k] > 0):
            tid = int(ids[k, s])
            births.setdefault(tid, k)
            tracks.setdefault(tid, {})[k] = mean[k, s]
    out = {}
    for tid, k in births.items():
        # The initiated position is the KF update of the broad prior on its detection: nearest to it.
        m0 = tracks[tid][k][:2]
        j = int(np.argmin(np.where(valid[k], np.linalg.norm(np.nan_to_num(z[k]) - m0, axis=1), np.inf)))
        out[(k, j)] = tracks[tid]
    return out


def compare(ours, theirs):
    """Max |Δ mean| over every track and scan; the track sets must be equal."""
    if set(ours) != set(theirs):
        raise AssertionError(f"different tracks: {len(set(ours) - set(theirs))} only in jaxtrack, "
                             f"{len(set(theirs) - set(ours))} only in Stone Soup")
    worst = 0.0
    for key, steps in theirs.items():
        if set(ours[key]) != set(steps):
            raise AssertionError(f"track born at {key} lives in different scans")
        for k, m in steps.items():
            worst = max(worst, float(np.max(np.abs(ours[key][k] - m))))
    return worst, len(theirs)


# ---------------------------------------------------------------------------------------------


def bench(num_runs, ss_runs, clutter_rate, capacity, block, repeats, associators, seed=0) -> dict:
    t = time.perf_counter()
    z, valid = draw_scans(num_runs, NUM_STEPS, clutter_rate, seed)
    draw_s = time.perf_counter() - t
    max_meas = z.shape[2]
    block = min(block, num_runs)
    if num_runs % block:
        raise SystemExit(f"--runs ({num_runs}) must be a multiple of --block ({block})")
    tracker = make_tracker(clutter_rate, capacity)
    job = jaxtrack_job(tracker)
    blocks = [(jax.device_put(z[i:i + block]), jax.device_put(valid[i:i + block]))
              for i in range(0, num_runs, block)]
    t = time.perf_counter()
    compiled = job.lower(*blocks[0]).compile()
    compile_s = time.perf_counter() - t
    jax.block_until_ready(compiled(*blocks[0]))  # warm-up

    def all_runs():
        return [jax.block_until_ready(compiled(*b)) for b in blocks]

    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        out = all_runs()
        best = min(best, time.perf_counter() - t)
    mean, status, ids, dropped = (np.concatenate([np.asarray(o[i]) for o in out]) for i in range(4))
    live = (status > 0).sum(-1)  # (R, T)
    if dropped.any():
        raise AssertionError(f"capacity {capacity} too small: births refused in {int((dropped > 0).sum())} runs")
    print(f"  jaxtrack: {num_runs} runs in {best:.1f} s (best of {repeats}), compilation {compile_s:.1f} s", flush=True)

    ss_runs = min(ss_runs, num_runs)
    meas_model, t0, ss_scans = stonesoup_inputs(z[:ss_runs], valid[:ss_runs], clutter_rate)
    ss = {}
    for name in associators:
        per_scan, worst, num_tracks = [], 0.0, 0
        for i in range(ss_runs):
            seconds, theirs = stonesoup_run(meas_model, t0, ss_scans[i], clutter_rate, name)
            per_scan.append(seconds)
            d, n = compare(jaxtrack_history(mean[i], status[i], ids[i], z[i], valid[i]), theirs)
            worst, num_tracks = max(worst, d), num_tracks + n
            print(f"  Stone Soup {name} run {i}: {seconds.sum():.1f} s, {n} tracks, "
                  f"max |Δ mean| vs jaxtrack {d:.1e} m", flush=True)
        assert worst < 1e-6, worst
        per_scan = np.concatenate(per_scan)
        ss[name] = {"total_s": float(per_scan.sum()), "per_scan_mean_s": float(per_scan.mean()),
                    "per_scan_median_s": float(np.median(per_scan)), "per_scan_max_s": float(per_scan.max()),
                    "max_abs_mean_difference_m": worst, "tracks_compared": num_tracks}

    jt_scan = best / (num_runs * NUM_STEPS)
    counts = valid.sum(-1)
    return {
        "runs": num_runs, "scans": NUM_STEPS, "block": block, "stone_soup_runs": ss_runs,
        "clutter_rate": clutter_rate, "capacity": capacity, "max_measurements": max_meas,
        "mean_measurements_per_scan": float(counts.mean()),
        "mean_live_tracks": float(live.mean()), "max_live_tracks": int(live.max()),
        "draw_s": draw_s, "compile_s": compile_s, "jaxtrack_s": best, "jaxtrack_per_scan_s": jt_scan,
        "stone_soup": ss, "speed_up": {k: v["per_scan_mean_s"] / jt_scan for k, v in ss.items()},
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1000, help="jaxtrack runs (default 1000)")
    parser.add_argument("--ss-runs", type=int, default=3, help="Stone Soup runs, the first ones (default 3)")
    parser.add_argument("--clutter", type=float, default=10.0, help="clutter points per scan (default 10)")
    parser.add_argument("--capacity", type=int, default=64, help="jaxtrack track slots (default 64)")
    parser.add_argument("--block", type=int, default=16,
                        help="runs per jaxtrack call (jit(vmap) over a block; default 16)")
    parser.add_argument("--stonesoup", nargs="+", default=["JPDA", "JPDAwithEHM"],
                        help="Stone Soup associators to time (default JPDA JPDAwithEHM)")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    args = parser.parse_args()
    machine = {"cores": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
               "jax": jax.__version__, "jaxtrack": getattr(jaxtrack, "__version__", "dev"), "dtype": "float64"}
    try:
        import stonesoup
        machine["stonesoup"] = stonesoup.__version__
    except ImportError:
        sys.exit("needs Stone Soup: pip install -e '.[bench]'")
    print(f"JPDA tracker, 2-D CV, {len(TARGETS)} targets, P_D {P_D}, {args.clutter:g} clutter/scan over "
          f"{REGION[0, 1]:.0f} m × {REGION[1, 1]:.0f} m, {NUM_STEPS} scans; float64, {machine['cores']} cores, "
          f"jax {machine['jax']}, Stone Soup {machine['stonesoup']}, best of {args.repeats}")
    print(f"command: python {' '.join(sys.argv)}")
    load_before = os.getloadavg()[0]
    print(f"load average before: {load_before:.2f}")
    row = bench(args.runs, args.ss_runs, args.clutter, args.capacity, args.block, args.repeats, args.stonesoup)
    row["load_average_before_after"] = [load_before, os.getloadavg()[0]]
    R, S = row["runs"], row["stone_soup_runs"]
    print(f"\n  {'per scan, excluding compilation':40s}{'runs × scans':>14s}{'wall':>10s}{'mean':>12s}"
          f"{'median':>12s}{'max':>12s}{'jaxtrack ×':>12s}")
    jt_name = f"jaxtrack jit(vmap(run_tracker)), {row['block']}/call"
    print(f"  {jt_name:40s}{f'{R} × {NUM_STEPS}':>14s}"
          f"{row['jaxtrack_s']:9.1f} s{row['jaxtrack_per_scan_s'] * 1e3:9.2f} ms")
    for name, v in row["stone_soup"].items():
        print(f"  {'Stone Soup ' + name:40s}{f'{S} × {NUM_STEPS}':>14s}{v['total_s']:9.1f} s"
              f"{v['per_scan_mean_s'] * 1e3:9.2f} ms{v['per_scan_median_s'] * 1e3:9.2f} ms"
              f"{v['per_scan_max_s'] * 1e3:9.1f} ms{row['speed_up'][name]:11.0f}×")
    print(f"\n  jaxtrack: compilation (once) {row['compile_s']:.1f} s, not in the times above; "
          f"scans drawn with NumPy in {row['draw_s']:.1f} s (not timed)")
    print(f"  padding (jaxtrack pays for it): capacity {row['capacity']} track slots (live tracks per scan: mean "
          f"{row['mean_live_tracks']:.1f}, max {row['max_live_tracks']}), max_measurements {row['max_measurements']} "
          f"(measurements per scan: mean {row['mean_measurements_per_scan']:.1f})")
    for name, v in row["stone_soup"].items():
        print(f"  equal work, Stone Soup {name}: {v['tracks_compared']} tracks on {S} runs, the same tracks "
              f"every scan, max |Δ track mean| {v['max_abs_mean_difference_m']:.1e} m")
    for name in row["stone_soup"]:
        med = row["stone_soup"][name]["per_scan_median_s"] / row["jaxtrack_per_scan_s"]
        print(f"  jaxtrack / Stone Soup {name} speed-up per scan: {row['speed_up'][name]:.0f}× "
              f"(on Stone Soup's median scan: {med:.0f}×)")
    print(f"\npeak RSS of this process: {peak_rss_mb():.0f} MB; load average after: {os.getloadavg()[0]:.2f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"machine": machine, "command": "python " + " ".join(sys.argv), "rows": [row],
                       "peak_rss_mb": peak_rss_mb()}, f, indent=2)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

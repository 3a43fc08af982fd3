"""Throughput of jaxtrack's batched Kalman filter and Monte Carlo harness against FilterPy.

Same model and same simulated data for every contender, measured in one run; prints filter
steps per second and the ratio of jaxtrack to FilterPy (only ratios from one run mean anything
on a shared machine). Times exclude compilation (each jitted function is run once first).
``benchmarks/peers.py`` is the full comparison (simdkalman, dynamax, EKF, several sizes).

    python benchmarks/monte_carlo_throughput.py [--runs 10000] [--steps 200] [--json]

Requires the `test` extra (FilterPy).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time

import jax
import numpy as np

import jaxtrack  # noqa: F401  (float64)
from jaxtrack.cli._demo import demo_models
from jaxtrack.filters import KalmanFilter, run_filter_batch
from jaxtrack.montecarlo import monte_carlo, simulate


def _best_of(fn, repeats=3):
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return best


def bench(num_runs: int, num_steps: int, filterpy_runs: int = 20) -> dict:
    model, _ = demo_models()
    keys = jax.random.split(jax.random.key(0), num_runs)
    data = jax.vmap(lambda k: simulate(model, k, num_steps))(keys)
    zs = data.measurements

    def batched(covariance):
        return lambda: run_filter_batch(KalmanFilter(), model, zs, save="mean", throw=False,
                                        covariance=covariance).filtered_mean

    jax.block_until_ready(batched("auto")())
    t_filter = _best_of(batched("auto"))
    jax.block_until_ready(batched("per_run")())
    t_filter_per_run = _best_of(batched("per_run"))

    def mc():
        return monte_carlo(model, jax.random.key(1), num_runs, num_steps=num_steps, progress=False).anees

    mc()
    t_mc = _best_of(mc, repeats=2)

    from filterpy.kalman import KalmanFilter as FPKalmanFilter

    zs_np = np.asarray(zs[:filterpy_runs])
    t0 = time.perf_counter()
    for z_run in zs_np:
        kf = FPKalmanFilter(dim_x=4, dim_z=2)
        kf.F, kf.Q = np.asarray(model.F), np.asarray(model.Q)
        kf.H, kf.R = np.asarray(model.H), np.asarray(model.R)
        kf.x, kf.P = np.asarray(model.initial_mean).copy(), np.asarray(model.initial_cov).copy()
        for k, z in enumerate(z_run):
            if k:
                kf.predict()
            kf.update(z)
    t_fp = (time.perf_counter() - t0) * num_runs / filterpy_runs

    total = num_runs * num_steps
    rows = {
        "runs": num_runs,
        "steps": num_steps,
        "cores": os.cpu_count(),
        "jaxtrack_filter_steps_per_s": total / t_filter,
        "jaxtrack_filter_per_run_path_steps_per_s": total / t_filter_per_run,
        "jaxtrack_monte_carlo_steps_per_s": total / t_mc,
        "filterpy_steps_per_s": total / t_fp,
        "filter_vs_filterpy": t_fp / t_filter,
        "monte_carlo_vs_filterpy_filter_only": t_fp / t_mc,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10_000)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    row = bench(args.runs, args.steps)
    if args.json:
        print(json.dumps(row, indent=2))
        return
    print(f"4-state constant velocity, {row['runs']} runs x {row['steps']} steps, float64, {row['cores']} cores")
    print(f"  jaxtrack batch (shared cov.) {row['jaxtrack_filter_steps_per_s'] / 1e6:8.2f} M steps/s   "
          f"{row['filter_vs_filterpy']:8.0f}x FilterPy")
    print(f"  jaxtrack batch (per-run cov.){row['jaxtrack_filter_per_run_path_steps_per_s'] / 1e6:8.2f} M steps/s")
    print(f"  jaxtrack full Monte Carlo    {row['jaxtrack_monte_carlo_steps_per_s'] / 1e6:8.2f} M steps/s   "
          f"{row['monte_carlo_vs_filterpy_filter_only']:8.0f}x FilterPy (filter only)")
    print(f"  FilterPy (loop, extrapolated){row['filterpy_steps_per_s'] / 1e6:8.3f} M steps/s")
    print(f"  peak RSS {row['peak_rss_mb']:.0f} MB")


if __name__ == "__main__":
    main()

"""PCRLB cost per step as a multiple of a covariance pass (issue 21), measured in one run.

The model is a 4-state 2-D constant-velocity target (1 s sampling, q = 0.5 m²/s³) observed by a
range–bearing sensor (5 m, 0.01 rad) at (−500, 300) m, ``T`` steps. The reference "covariance
pass" is ``run_filter(ExtendedKalmanFilter(), model, z)`` on one simulated run (predict + update
of mean and covariance, the Jacobians at the estimate). Contenders:

- ``pcrlb_along(model, truth)``: the bound linearised along one truth (Stone Soup's PCRB);
- ``pcrlb(model, key, R)`` for R true trajectories: simulation of each truth, its Jacobians and
  measurement information, the Monte Carlo sums, then one recursion — reported as the cost of one
  run (÷ R) against the covariance pass, and in total;
- for reference, the Kalman filter on the linear position-sensor model against ``pcrlb(…, 1)``.

Each time is the best of ``--repeats`` calls after compilation (results blocked on). No timed
tests: this script prints numbers, nothing asserts them.

Usage::

    python benchmarks/pcrlb.py [--steps 200] [--runs 1 256 2048] [--repeats 5]
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

import jaxtrack  # noqa: F401  (float64)
from jaxtrack.bounds import pcrlb, pcrlb_along
from jaxtrack.filters import ExtendedKalmanFilter, KalmanFilter, run_filter
from jaxtrack.models import ConstantVelocity, RangeBearing, TrackingModel, constant_velocity
from jaxtrack.montecarlo import simulate


def best_time(fn, repeats: int) -> float:
    jax.block_until_ready(fn())  # compile
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return best


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--runs", type=int, nargs="+", default=[1, 256, 2048])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    T = args.steps
    P0 = np.diag([100.0, 100.0, 4.0, 4.0])
    m0 = np.array([100.0, 200.0, 5.0, -3.0])
    model = TrackingModel(ConstantVelocity(1.0, noise_intensity=0.5, dim=2),
                          RangeBearing(noise_std=(5.0, 0.01), sensor_position=(-500.0, 300.0)), m0, P0)
    key = jax.random.key(0)
    run = simulate(model, key, T)

    t_ekf = best_time(lambda: run_filter(ExtendedKalmanFilter(), model, run.measurements).filtered_cov,
                      args.repeats)
    rows = [("EKF covariance pass (reference)", t_ekf, 1)]
    rows.append(("pcrlb_along (one truth)", best_time(lambda: pcrlb_along(model, run.states).bound,
                                                      args.repeats), 1))
    for R in args.runs:
        rows.append((f"pcrlb, {R} truths", best_time(lambda R=R: pcrlb(model, key, R, T).bound, args.repeats), R))

    print(f"range-bearing CV model, T = {T} steps, {jax.devices()[0].platform}")
    print(f"{'':36s} {'total ms':>10s} {'µs/step/run':>12s} {'× EKF pass per run':>20s}")
    for name, t, R in rows:
        print(f"{name:36s} {1e3 * t:10.3f} {1e6 * t / (T * R):12.3f} {t / R / t_ekf:20.2f}")

    linear = constant_velocity(np.asarray(1.0), accel_psd=0.5, measurement_std=5.0, initial_mean=m0,
                               initial_cov=P0)
    z = simulate(linear, key, T).measurements
    t_kf = best_time(lambda: run_filter(KalmanFilter(), linear, z).filtered_cov, args.repeats)
    t_lin = best_time(lambda: pcrlb(linear, key, 1, T).bound, args.repeats)
    print(f"linear CV model: KF covariance pass {1e3 * t_kf:.3f} ms, pcrlb(1 truth) {1e3 * t_lin:.3f} ms, "
          f"ratio {t_lin / t_kf:.2f}")


if __name__ == "__main__":
    main()

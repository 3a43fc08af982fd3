"""Bearings-only TMA: the particle filter's RMSE against the PCRLB and the mean per-truth bound, as
the particle count grows (issue 34's "PF terminal RMSE / PCRLB ≤ 1.1 on the geometry where the EKF
is inefficient").

The job: the bearings-only study's geometry (``--geometry``, default R3, where the study's EKF is
8.6× the PCRLB at 960 s), ``--runs`` truths drawn from the bound's prior (σ 250 m, 0.5 m/s around
the nominal truth), and on the same truths (the study's own functions,
:func:`jaxtrack.applications.bearings_tma.bounds.bound_comparison`):

- the PCRLB ``E[J]⁻¹`` (Tichavský et al. 1998; :func:`jaxtrack.bounds.pcrlb`, the study's bound);
- the mean per-truth bound ``E[J(x)⁻¹]``
  (:func:`~jaxtrack.applications.bearings_tma.bounds.mean_per_truth_bound`);
- the study's EKF and its regularised particle filter
  (:func:`~jaxtrack.applications.bearings_tma.bounds.particle_filter`) with each of ``--particles``.

Printed: position RMSE (m) at 240, 480, 720 and 960 s and the ratios. The particle filter
approximates the MMSE estimator, whose mean squared error no estimator beats on these truths; as
it converges with N, its RMSE shows where the MMSE lies relative to the two bounds. Without plant
noise the averaged information of different truths is better conditioned than any one truth's
(Jensen), so the PCRLB can lie far below what any estimator reaches.

Usage::

    python benchmarks/pf_vs_bounds.py                           # R3, 500 runs, N = 1e3, 1e4, 5e4
    python benchmarks/pf_vs_bounds.py --geometry R1 --runs 200 --particles 1000 10000
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import jax
import numpy as np

import jaxtrack  # noqa: F401  (float64)
from jaxtrack.applications.bearings_tma import bounds as tb

TIMES = (240.0, 480.0, 720.0, 960.0)  # s


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--geometry", default="R3", choices=("R1", "R2", "R3"))
    ap.add_argument("--runs", type=int, default=500)
    ap.add_argument("--particles", type=int, nargs="+", default=[1000, 10_000, 50_000])
    a = ap.parse_args(argv)
    # The key of the study's extra table for this geometry (rows._extra_bounds).
    key = dict(zip(("R1", "R2", "R3"), jax.random.split(jax.random.key(21), 3)))[a.geometry]
    print(f"bearings-only TMA, geometry {a.geometry}, {a.runs} truths from the prior, float64, "
          f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}")
    truth = np.asarray(tb.mean_per_truth_bound(a.geometry, key, a.runs))
    for n in a.particles:
        t0 = time.perf_counter()
        c = tb.bound_comparison(a.geometry, key, a.runs, particles=n)
        wall = time.perf_counter() - t0
        times = np.asarray(c.times)
        print(f"\nN = {n} particles ({wall:.0f} s with the EKF, PLKF and bound)")
        print(f"  {'t [s]':>6} {'PCRLB':>8} {'per-truth':>10} {'EKF':>8} {'PF':>8} {'± 2 s.e.':>9} "
              f"{'EKF/PCRLB':>10} {'PF/PCRLB':>9} {'PF/per-truth':>13}")
        for tt in TIMES:
            k = int(np.argmin(np.abs(times - tt)))
            crb, pt = np.sqrt(float(c.position_bound[k])), np.sqrt(float(truth[k]))
            ekf, pf = np.sqrt(float(c.ekf_mse[k])), np.sqrt(float(c.pf_mse[k]))
            se = float(c.pf_se_mean[k]) / (2.0 * pf)  # s.e. of the RMSE by the delta method
            print(f"  {tt:6.0f} {crb:8.1f} {pt:10.1f} {ekf:8.1f} {pf:8.1f} {2 * se:9.1f} "
                  f"{ekf / crb:10.2f} {pf / crb:9.2f} {pf / pt:13.2f}")


if __name__ == "__main__":
    main()

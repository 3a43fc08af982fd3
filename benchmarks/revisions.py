"""jaxtrack against an earlier revision of itself, in one process: is any job slower?

The earlier revision (default ``c1ffaca``, before the one-core refactor) is extracted with
``git archive`` into a temporary folder as the package ``jaxtrack_old`` (jaxtrack imports itself
only relatively, so both versions load side by side) and both run the 4-state, 10,000 × 200
jobs of ``benchmarks/peers.py`` on the same simulated data, interleaved, best of ``--repeats``
(compilation excluded). Prints M filter steps per second and new/old ratios, and checks that the
two revisions compute the same numbers.

Usage::

    python benchmarks/revisions.py                 # old = c1ffaca
    python benchmarks/revisions.py --old HEAD~3 --json revisions.json
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxtrack  # noqa: E402
from peers import linear_model, race, range_bearing_class, range_bearing_model, simulate_batch  # noqa: E402


def load_old(rev: str, folder: str):
    """``git archive REV jaxtrack`` into ``folder/jaxtrack_old`` and import it."""
    root = subprocess.run(["git", "rev-parse", "--show-toplevel"], cwd=HERE, capture_output=True, text=True,
                          check=True).stdout.strip()
    tar = subprocess.run(["git", "archive", rev, "jaxtrack"], cwd=root, capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", folder], input=tar, check=True)
    os.rename(os.path.join(folder, "jaxtrack"), os.path.join(folder, "jaxtrack_old"))
    sys.path.insert(0, folder)
    return importlib.import_module("jaxtrack_old")


def range_bearing(lib):
    """peers.py's range-bearing model, built on ``lib``'s model base class."""
    return range_bearing_model(range_bearing_class(lib.models.AbstractStateSpaceModel))


def jobs(lib, zs, obs, zs_rb, runs, steps):
    """The 4-state 10k × 200 jobs of peers.py for one revision: name -> zero-argument callable."""
    model = linear_model(4)  # built with the new package; rebuild with lib's own classes
    model = lib.models.constant_velocity(1.0, dim=2, accel_psd=0.5, measurement_std=10.0,
                                          initial_cov=model.initial_cov)
    kf, ekf = lib.filters.KalmanFilter(), lib.filters.ExtendedKalmanFilter()
    rb = range_bearing(lib)
    batch = lib.filters.run_filter_batch
    mc = lib.montecarlo.monte_carlo
    return {
        "shared schedule, means": lambda: batch(kf, model, zs, save="mean", throw=False).filtered_mean,
        "shared schedule, loglik": lambda: batch(kf, model, zs, save="final", throw=False).log_likelihood,
        "per-run path, means": lambda: batch(kf, model, zs, save="mean", throw=False,
                                             covariance="per_run").filtered_mean,
        "per-run path, loglik": lambda: batch(kf, model, zs, save="final", throw=False,
                                              covariance="per_run").log_likelihood,
        "per-run masks, loglik": lambda: batch(kf, model, zs, mask=obs, save="final", throw=False).log_likelihood,
        "EKF range-bearing, means": lambda: batch(ekf, rb, zs_rb, save="mean", throw=False).filtered_mean,
        "monte_carlo": lambda: mc(model, jax.random.key(1), runs, num_steps=steps, progress=False).nees,
        "monte_carlo per-run path": lambda: mc(model, jax.random.key(1), runs, num_steps=steps, progress=False,
                                               covariance="per_run").nees,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", default="c1ffaca", help="the earlier revision (git rev)")
    parser.add_argument("--runs", type=int, default=10_000)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--json", metavar="PATH")
    parser.add_argument("--only", nargs="*", help="run only the jobs whose names contain one of these words")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        old = load_old(args.old, folder)
        runs, steps = args.runs, args.steps
        zs = simulate_batch(linear_model(4), runs, steps).measurements
        obs = jnp.asarray(np.random.default_rng(1).random((runs, steps)) >= 0.1)
        zs_rb = simulate_batch(range_bearing(jaxtrack), runs, steps).measurements
        new_jobs = jobs(jaxtrack, zs, obs, zs_rb, runs, steps)
        old_jobs = jobs(old, zs, obs, zs_rb, runs, steps)
        print(f"jaxtrack (working tree) vs {args.old}: 4 states, {runs} runs × {steps} steps, float64, "
              f"best of {args.repeats}, M steps/s")
        print(f"{'job':<28} {'new':>8} {'old':>8} {'new/old':>8}  max |new − old|")
        report = {"old": args.old, "runs": runs, "steps": steps, "jobs": {}}
        total = runs * steps
        for name in new_jobs:
            if args.only and not any(w in name for w in args.only):
                continue
            diff = float(np.max(np.abs(np.asarray(new_jobs[name]()) - np.asarray(old_jobs[name]()))))
            times = race({"new": (new_jobs[name], 1.0), "old": (old_jobs[name], 1.0)}, args.repeats)
            new, oldr = total / times["new"] / 1e6, total / times["old"] / 1e6
            report["jobs"][name] = {"new": new, "old": oldr, "ratio": new / oldr, "max_abs_difference": diff}
            print(f"{name:<28} {new:8.2f} {oldr:8.2f} {new / oldr:8.3f}  {diff:.1e}", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=2)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

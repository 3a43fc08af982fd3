"""Sequential against parallel-in-time Kalman filter and RTS smoother on CPU (``scan=`` of run_filter).

The job: one trajectory of a 2-D constant-velocity model (``n = 4`` states, ``m = 2`` position
measurements, τ = 1 s, q = 0.5 m²/s³, σ = 3 m, float64) of T = 100, 1,000, 10,000 and 100,000
steps, simulated once per T. jaxtrack's :func:`run_filter` and :func:`rts_smoother` run with
``scan=Sequential()`` (one ``lax.scan``) and ``scan=ParallelInTime()`` (Särkkä &
García-Fernández 2021, associative scans); each is wrapped in ``jax.jit`` and compiled once,
ahead of time (compilation reported separately), and timed as the best of ``--repeats`` calls
after a warm-up. dynamax's ``lgssm_filter`` (sequential) and ``parallel_lgssm_filter``
(``jax.lax.associative_scan``) run on the same model and data when dynamax imports, compiled and
timed the same way; the parallel one only up to ``--dynamax-parallel-max-steps`` (default 1,000):
with jax 0.10.2 on this 2-core machine it compiled in 40 s at T = 10,000 and then did not return
within 3 minutes (every thread waiting on a futex, no CPU time used), standalone as well.
Agreement is asserted: jaxtrack parallel = sequential to 1e-10 relative to scale (filtered,
smoothed moments, log-likelihood); dynamax's filtered moments = jaxtrack's to
1e-8 (its ``psd_solve`` adds 1e-9·I to every innovation covariance, hence not closer) and its
sequential log-likelihood to 1e-10. The log-likelihood of dynamax's *parallel* filter is only
printed (relative to jaxtrack's): it drifts from its own sequential one as T grows.

This is the measurement behind ``AutoScan``'s CPU rule (always sequential). The GPU threshold
of ``AutoScan`` is not measured: run this script on a GPU machine to measure it.

Usage::

    python benchmarks/parallel_kalman.py                  # T = 100 … 100,000, best of 5
    python benchmarks/parallel_kalman.py --quick          # T = 100, 1,000: a smoke test
    python benchmarks/parallel_kalman.py --steps 1000 10000 --repeats 3 --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxtrack
from jaxtrack.filters import KalmanFilter, ParallelInTime, Sequential, rts_smoother, run_filter
from jaxtrack.models import constant_velocity

TAU, ACCEL_PSD, SIGMA = 1.0, 0.5, 3.0  # s, m²/s³, m
SCANS = {"sequential": Sequential(), "parallel": ParallelInTime()}


def make_model():
    prior_cov = jnp.diag(jnp.array([100.0, 100.0, 10.0, 10.0]))  # m², m²/s²
    return constant_velocity(TAU, dim=2, accel_psd=ACCEL_PSD, measurement_std=SIGMA,
                             initial_mean=jnp.array([0.0, 0.0, 10.0, -5.0]), initial_cov=prior_cov)


def simulate(model, num_steps: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    F, H = np.asarray(model.F), np.asarray(model.H)
    w = rng.standard_normal((num_steps, 4)) @ np.linalg.cholesky(np.asarray(model.Q)).T
    v = SIGMA * rng.standard_normal((num_steps, 2))
    x = np.asarray(model.initial_mean) + np.sqrt(np.diag(np.asarray(model.initial_cov))) * rng.standard_normal(4)
    zs = np.empty((num_steps, 2))
    for k in range(num_steps):
        if k:
            x = F @ x + w[k]
        zs[k] = H @ x + v[k]
    return zs


def compiled(fn, *args):
    t = time.perf_counter()
    c = jax.jit(fn).lower(*args).compile()
    return c, time.perf_counter() - t


def best_of(fn, args, repeats: int) -> float:
    jax.block_until_ready(fn(*args))  # warm-up
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - t)
    return best


def rel(a, b) -> float:
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), np.finfo(float).tiny))


def dynamax_functions():
    try:
        from dynamax.linear_gaussian_ssm import (
            ParamsLGSSM, ParamsLGSSMDynamics, ParamsLGSSMEmissions, ParamsLGSSMInitial, lgssm_filter,
            parallel_lgssm_filter,
        )
    except Exception as error:  # noqa: BLE001  (optional peer: any import failure skips it)
        print(f"dynamax not benchmarked: {type(error).__name__}: {error}")
        return None

    def params(model):
        n, m = model.state_dim, model.meas_dim
        return ParamsLGSSM(
            ParamsLGSSMInitial(model.initial_mean, model.initial_cov),
            ParamsLGSSMDynamics(model.F, jnp.zeros(n), jnp.zeros((n, 0)), model.Q),
            ParamsLGSSMEmissions(model.H, jnp.zeros(m), jnp.zeros((m, 0)), model.R),
        )

    return params, {"dynamax lgssm_filter": lgssm_filter, "dynamax parallel_lgssm_filter": parallel_lgssm_filter}


def bench(num_steps: int, repeats: int, dynamax, dynamax_parallel_max_steps: int) -> dict:
    model = make_model()
    zs = jnp.asarray(simulate(model, num_steps))
    row = {"T": num_steps, "time_s": {}, "compile_s": {}, "max_rel_difference": {}}
    out = {}
    for name, scan in SCANS.items():
        filt, c1 = compiled(lambda z, s=scan: run_filter(KalmanFilter(), model, z, scan=s, throw=False), zs)
        smooth, c2 = compiled(lambda z, s=scan: rts_smoother(model, z, scan=s, throw=False), zs)
        row["compile_s"][f"{name} filter"], row["compile_s"][f"{name} smoother"] = c1, c2
        row["time_s"][f"{name} filter"] = best_of(filt, (zs,), repeats)
        row["time_s"][f"{name} smoother"] = best_of(smooth, (zs,), repeats)
        out[name] = smooth(zs)
    seq, par = out["sequential"], out["parallel"]
    for field in ("filtered_mean", "filtered_cov", "log_likelihood"):
        row["max_rel_difference"][f"parallel {field}"] = rel(getattr(par.filtered, field), getattr(seq.filtered, field))
    for field in ("smoothed_mean", "smoothed_cov"):
        row["max_rel_difference"][f"parallel {field}"] = rel(getattr(par, field), getattr(seq, field))
    assert all(v <= 1e-10 for v in row["max_rel_difference"].values()), row["max_rel_difference"]
    if dynamax is not None:
        params, functions = dynamax
        p = params(model)
        for name, fn in functions.items():
            if "parallel" in name and num_steps > dynamax_parallel_max_steps:
                continue
            c, row["compile_s"][name] = compiled(fn, p, zs)
            row["time_s"][name] = best_of(c, (p, zs), repeats)
            post = c(p, zs)
            diffs = {
                "filtered_mean": rel(post.filtered_means, seq.filtered.filtered_mean),
                "filtered_cov": rel(post.filtered_covariances, seq.filtered.filtered_cov),
                "log_likelihood": rel(post.marginal_loglik, seq.filtered.log_likelihood),
            }
            assert diffs["filtered_mean"] <= 1e-8 and diffs["filtered_cov"] <= 1e-8, (name, diffs)
            if "parallel" not in name:  # see the module docstring for the parallel one
                assert diffs["log_likelihood"] <= 1e-10, (name, diffs)
            for field, d in diffs.items():
                row["max_rel_difference"][f"{name} {field}"] = d
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="T = 100, 1,000 (a smoke test)")
    parser.add_argument("--steps", type=int, nargs="+", default=None, help="the T values (default 100 … 100,000)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--no-dynamax", action="store_true", help="skip dynamax")
    parser.add_argument("--dynamax-parallel-max-steps", type=int, default=1000,
                        help="largest T for dynamax's parallel_lgssm_filter (default 1,000; see above)")
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    args = parser.parse_args()
    steps = args.steps or ([100, 1000] if args.quick else [100, 1000, 10_000, 100_000])
    machine = {"cores": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
               "jax": jax.__version__, "backend": jax.default_backend(),
               "jaxtrack": getattr(jaxtrack, "__version__", "dev"), "dtype": "float64"}
    print(f"Kalman filter and RTS smoother, 2-D constant velocity (n = 4, m = 2), float64, "
          f"{machine['cores']} cores, {machine['backend']}, jax {machine['jax']}, best of {args.repeats}")
    print(f"machine: {machine['platform']}, python {machine['python']}")
    print(f"command: python {' '.join(sys.argv)}")
    load_before = os.getloadavg()[0]
    print(f"load average before: {load_before:.2f}")
    dynamax = None if args.no_dynamax else dynamax_functions()
    rows = []
    for num_steps in steps:
        rows.append(bench(num_steps, args.repeats, dynamax, args.dynamax_parallel_max_steps))
        print(f"  T = {num_steps} done", flush=True)
    names = list(dict.fromkeys(name for r in rows for name in r["time_s"]))
    width = max(len(n) for n in names) + 2

    def cell(row, key, name, fmt):
        return fmt(row[key][name]) if name in row[key] else f"{'—':>14s}"

    print(f"\n  wall time per call (compiled once; best of {args.repeats})")
    print("  " + " " * width + "".join(f"{'T = ' + format(r['T'], ','):>14s}" for r in rows))
    for name in names:
        print(f"  {name:{width}s}" + "".join(cell(r, "time_s", name, lambda v: f"{v * 1e3:11.2f} ms") for r in rows))
    print("\n  parallel / sequential (jaxtrack)")
    for what in ("filter", "smoother"):
        ratios = [r["time_s"][f"parallel {what}"] / r["time_s"][f"sequential {what}"] for r in rows]
        print(f"  {what:{width}s}" + "".join(f"{x:13.2f}×" for x in ratios))
    print("\n  compilation (once per T)")
    for name in names:
        print(f"  {name:{width}s}" + "".join(cell(r, "compile_s", name, lambda v: f"{v:12.2f} s") for r in rows))
    print("\n  largest relative difference (to jaxtrack sequential, over the T run)")
    for key in dict.fromkeys(k for r in rows for k in r["max_rel_difference"]):
        print(f"  {key:50s}{max(r['max_rel_difference'].get(key, 0.0) for r in rows):10.1e}")
    load_after = os.getloadavg()[0]
    print(f"\nload average after: {load_after:.2f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"machine": machine, "command": "python " + " ".join(sys.argv),
                       "load_average_before_after": [load_before, load_after], "rows": rows}, f, indent=2)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

"""Nonlinear filters, per run: jaxtrack's UKF and iterated EKF against FilterPy and dynamax.

The model is the 4-state range–bearing model of ``peers.py`` (2-D constant velocity
``[x, y, vx, vy]``, 1 s sampling, a radar at the origin measuring range (5 m) and bearing
(0.01 rad)), built from the library's components (``TrackingModel`` of a ``LinearTransition``
and a ``RangeBearing`` sensor). Every contender gets the same simulated data in one process; each
time is the best of ``--repeats`` interleaved rounds, after compilation. Rates are filter steps
per second (runs × steps / wall time).

Two jobs per filter:

1. **filter**: the filtered means of every step of every run, from the same measurements.
   jaxtrack: ``run_filter_batch(filter, model, zs, save="mean")``; dynamax:
   ``jit(vmap(unscented_kalman_filter))`` / ``extended_kalman_filter(..., num_iter)``; FilterPy:
   its ``UnscentedKalmanFilter`` with ``MerweScaledSigmaPoints``, and for the iterated EKF its
   ``ExtendedKalmanFilter.predict`` with the Gauss–Newton iterations written in numpy (FilterPy
   has no iterated update), a Python loop per run timed on a subset and scaled.
2. **Monte Carlo**: simulate, filter and score (RMSE and NEES per step). jaxtrack:
   ``monte_carlo(..., filter=...)`` (per-run covariance, streaming); dynamax: ``vmap`` of
   ``NonlinearGaussianSSM.sample`` and the filter, metrics in ``jnp``; FilterPy: numpy simulation,
   the filter loop and the metrics per run, on a subset, scaled.

Agreement: the UKF means agree with FilterPy's to rounding, and with dynamax's to its diagonal
boost (``psd_solve`` adds 1e-9·I to every innovation covariance, 1e-5 of the bearing variance
here, so its means differ by ~1e-4 m). dynamax's
``num_iter`` is not the Gauss–Newton iterated EKF: it re-conditions the posterior on the same
measurement ``num_iter`` times (``_condition_on`` in ``inference_ekf``), so its means differ from
jaxtrack's and FilterPy-loop's, which agree; the timing compares the same amount of work
(``num_iter`` linearisations and gains per step).

``--model radar`` runs the README's 3-D radar instead (6 states: ``CoordinatedTurn`` in 3-D at
0.026 rad/s, ``RangeAzimuthElevation`` on a 20 m mast, compass azimuth, yawed by −0.35 rad; every
step detected, as dynamax has no missing data), against dynamax only (FilterPy's side is written
for the range–bearing model).

Needs the ``bench`` extra. Usage::

    python benchmarks/nonlinear.py                 # 10,000 runs × 200 steps (~10 min on 2 cores)
    python benchmarks/nonlinear.py --quick         # 1,000 × 50, a smoke test
    python benchmarks/nonlinear.py --model radar --runs 4096 --steps 100
    python benchmarks/nonlinear.py --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from peers import linear_model, peak_rss_mb, print_table, race  # noqa: E402

import jaxtrack  # noqa: E402
from jaxtrack.filters import (  # noqa: E402
    IteratedExtendedKalmanFilter,
    UnscentedKalmanFilter,
    run_filter_batch,
)
from jaxtrack.models import (  # noqa: E402
    CoordinatedTurn,
    LinearTransition,
    RangeAzimuthElevation,
    RangeBearing,
    TrackingModel,
    sensor_rotation,
)
from jaxtrack.montecarlo import monte_carlo, simulate  # noqa: E402

# The UKF's (α, β, κ): FilterPy's usual Merwe setting (α < 1, β = 2 for Gaussians).
UKF_PARAMS = (0.5, 2.0, 0.0)
IEKF_ITERATIONS = 3


def model():
    """The 4-state range–bearing model (the same numbers as ``peers.range_bearing_model``)."""
    cv = linear_model(4)
    return TrackingModel(
        LinearTransition(cv.F, cv.Q),
        RangeBearing(noise_std=jnp.asarray([5.0, 0.01])),
        initial_mean=jnp.asarray([3000.0, 2000.0, -10.0, 5.0]),
        initial_cov=jnp.diag(jnp.asarray([50.0, 50.0, 5.0, 5.0]) ** 2),
    )


def radar_model():
    """The README's 3-D radar (6 states ``[x, y, z, vx, vy, vz]``; range 15 m, angles 2 mrad)."""
    radar = RangeAzimuthElevation(noise_std=jnp.asarray([15.0, 2e-3, 2e-3]),
                                  sensor_position=jnp.asarray([0.0, 0.0, 20.0]),
                                  world_to_sensor_rotation=sensor_rotation(yaw=-0.35), azimuth="compass")
    motion = CoordinatedTurn(1.0, turn_rate=0.026, noise_intensity=0.05, dim=3)
    return TrackingModel(motion, radar, initial_mean=jnp.asarray([8e3, 12e3, 3e3, -150.0, 0.0, 0.0]),
                         initial_cov=jnp.diag(jnp.asarray([200.0, 200, 100, 20, 20, 5]) ** 2))


MODELS = {"range-bearing": model, "radar": radar_model}


def simulate_batch(m, num_runs, num_steps, seed=0):
    keys = jax.random.split(jax.random.key(seed), num_runs)
    return jax.block_until_ready(jax.jit(jax.vmap(lambda k: simulate(m, k, num_steps)))(keys))


# ---------------------------------------------------------------------------------------------
# numpy pieces a FilterPy user writes


def _np_model(m):
    F = np.asarray(m.transition_model.F)
    Q = np.asarray(m.transition_model.Q)
    R = np.asarray(m.measurement_noise_cov(0))
    return F, Q, R, np.asarray(m.initial_mean), np.asarray(m.initial_cov)


def hx(x):
    return np.array([np.hypot(x[0], x[1]), np.arctan2(x[1], x[0])])


def h_jac(x):
    r2 = x[0] ** 2 + x[1] ** 2
    r = np.sqrt(r2)
    return np.array([[x[0] / r, x[1] / r, 0.0, 0.0], [-x[1] / r2, x[0] / r2, 0.0, 0.0]])


def residual(a, b):
    d = np.asarray(a, float) - b
    d[1] = (d[1] + np.pi) % (2 * np.pi) - np.pi
    return d


def filterpy_ukf(m, zs, truth=None):
    """FilterPy's UKF over runs; with ``truth``, also the per-step NEES (the Monte Carlo job)."""
    from filterpy.kalman import MerweScaledSigmaPoints
    from filterpy.kalman import UnscentedKalmanFilter as FPUKF

    F, Q, R, m0, P0 = _np_model(m)
    alpha, beta, kappa = UKF_PARAMS
    out = np.empty(zs.shape[:2] + (4,))
    nees = np.empty(zs.shape[:2])
    for i, z_run in enumerate(zs):
        f = FPUKF(dim_x=4, dim_z=2, dt=1.0, hx=hx, fx=lambda x, dt: F @ x,
                  points=MerweScaledSigmaPoints(4, alpha, beta, kappa), residual_z=residual)
        f.Q, f.R, f.x, f.P = Q, R, m0.copy(), P0.copy()
        for k, z in enumerate(z_run):
            if k:
                f.predict()
            # FilterPy's update reuses the sigma points of predict (drawn before Q was added,
            # and never drawn before the first update); draw them from the predicted moments,
            # as jaxtrack, dynamax and Stone Soup do.
            f.sigmas_f = f.points_fn.sigma_points(f.x, f.P)
            f.update(z)
            out[i, k] = f.x
            if truth is not None:
                e = truth[i, k] - f.x
                nees[i, k] = e @ np.linalg.solve(f.P, e)
    return out if truth is None else (out, nees)


def filterpy_iekf(m, zs, truth=None, iterations=IEKF_ITERATIONS):
    """FilterPy's EKF prediction with the Gauss–Newton iterated update in numpy."""
    from filterpy.kalman import ExtendedKalmanFilter as FPEKF

    F, Q, R, m0, P0 = _np_model(m)
    out = np.empty(zs.shape[:2] + (4,))
    nees = np.empty(zs.shape[:2])
    eye = np.eye(4)
    for i, z_run in enumerate(zs):
        f = FPEKF(dim_x=4, dim_z=2)
        f.F, f.Q, f.R, f.x, f.P = F, Q, R, m0.copy(), P0.copy()
        for k, z in enumerate(z_run):
            if k:
                f.predict()
            x_pred, P = f.x.copy(), f.P
            xi = x_pred.copy()
            for _ in range(iterations):
                H = h_jac(xi)
                S = H @ P @ H.T + R
                W = P @ H.T @ np.linalg.inv(S)
                xi = x_pred + W @ (residual(z, hx(xi)) - H @ (x_pred - xi))
            IWH = eye - W @ H
            f.x, f.P = xi, IWH @ P @ IWH.T + W @ R @ W.T
            out[i, k] = f.x
            if truth is not None:
                e = truth[i, k] - f.x
                nees[i, k] = e @ np.linalg.solve(f.P, e)
    return out if truth is None else (out, nees)


# ---------------------------------------------------------------------------------------------
# dynamax


def dynamax_pieces(m, kind):
    from dynamax.nonlinear_gaussian_ssm import (
        ParamsNLGSSM,
        UKFHyperParams,
        extended_kalman_filter,
        unscented_kalman_filter,
    )

    Q, R = m.process_noise_cov(0), m.measurement_noise_cov(0)
    params = ParamsNLGSSM(m.initial_mean, m.initial_cov, lambda x: m.transition(x, 0), Q,
                          lambda x: m.measurement(x, 0), R)
    if kind == "ukf":
        hyper = UKFHyperParams(*UKF_PARAMS)
        filt = lambda ys: unscented_kalman_filter(  # noqa: E731
            params, ys, hyper, output_fields=["filtered_means", "filtered_covariances"])
    else:
        filt = lambda ys: extended_kalman_filter(  # noqa: E731
            params, ys, num_iter=IEKF_ITERATIONS, output_fields=["filtered_means", "filtered_covariances"])
    return params, filt


def dynamax_filter_job(m, kind):
    _, filt = dynamax_pieces(m, kind)
    return jax.jit(jax.vmap(lambda ys: filt(ys).filtered_means))


def dynamax_monte_carlo_job(m, kind, num_runs, num_steps):
    """Simulate with ``NonlinearGaussianSSM.sample``, filter, RMSE and NEES in ``jnp``."""
    from dynamax.nonlinear_gaussian_ssm import NonlinearGaussianSSM

    params, filt = dynamax_pieces(m, kind)
    ssm = NonlinearGaussianSSM(m.state_dim, m.meas_dim)

    @jax.jit
    def job(key):
        def one(k):
            states, ys = ssm.sample(params, k, num_steps)
            post = filt(ys)
            err = states - post.filtered_means
            nees = jnp.einsum("ti,tij,tj->t", err, jnp.linalg.inv(post.filtered_covariances), err)
            return err, nees

        err, nees = jax.vmap(one)(jax.random.split(key, num_runs))
        return jnp.sqrt(jnp.mean(err**2, axis=0)), jnp.mean(nees, axis=0)

    return job


# ---------------------------------------------------------------------------------------------
# Jobs


def jaxtrack_filter(kind):
    alpha, beta, kappa = UKF_PARAMS
    if kind == "ukf":
        return UnscentedKalmanFilter(alpha=alpha, beta=beta, kappa=kappa)
    return IteratedExtendedKalmanFilter(num_iterations=IEKF_ITERATIONS)


def bench(kind, num_runs, num_steps, repeats, fp_runs, model_name="range-bearing") -> dict:
    m = MODELS[model_name]()
    if model_name != "range-bearing":
        fp_runs = 0  # FilterPy's hx, Jacobian and residual here are the range-bearing model's
    traj = simulate_batch(m, num_runs, num_steps)
    zs, truth = traj.measurements, traj.states
    zs_np, truth_np = np.asarray(zs), np.asarray(truth)
    filt = jaxtrack_filter(kind)
    fp = filterpy_ukf if kind == "ukf" else filterpy_iekf
    dx = dynamax_filter_job(m, kind)
    dx_mc = dynamax_monte_carlo_job(m, kind, num_runs, num_steps)
    fp_runs = min(fp_runs, num_runs)

    ref = np.asarray(run_filter_batch(filt, m, zs[:5], save="mean").filtered_mean)
    agree = {"dynamax": float(np.max(np.abs(np.asarray(dx(zs)[:5]) - ref) / (1.0 + np.abs(ref))))}
    if fp_runs:
        agree["FilterPy"] = float(np.max(np.abs(fp(m, zs_np[:5]) - ref) / (1.0 + np.abs(ref))))

    filter_job = {
        "jaxtrack": (lambda: run_filter_batch(filt, m, zs, save="mean", throw=False).filtered_mean, 1.0),
        "dynamax": (lambda: dx(zs), 1.0),
    }
    mc_job = {
        "jaxtrack monte_carlo": (lambda: monte_carlo(m, jax.random.key(1), num_runs, num_steps=num_steps,
                                                     filter=filt, progress=False).nees, 1.0),
        "dynamax": (lambda: dx_mc(jax.random.key(1)), 1.0),
    }
    if fp_runs:
        filter_job["FilterPy"] = (lambda: fp(m, zs_np[:fp_runs]), num_runs / fp_runs)
        mc_job["FilterPy"] = (lambda: fp(m, zs_np[:fp_runs], truth_np[:fp_runs])[1], num_runs / fp_runs)
    total = num_runs * num_steps
    rates = {}
    for job, contenders in (("filter", filter_job), ("monte_carlo", mc_job)):
        times = race(contenders, repeats)
        rates[job] = {k: total / t for k, t in times.items()}
    return {"filter": kind, "model": model_name, "runs": num_runs, "steps": num_steps, "steps_per_s": rates,
            "max_rel_mean_difference_first_5_runs": agree}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1,000 runs × 50 steps (a smoke test)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    parser.add_argument("--model", choices=sorted(MODELS), default="range-bearing")
    parser.add_argument("--filters", default="ukf,iekf", help="comma-separated: ukf, iekf")
    parser.add_argument("--runs", type=int, help="override the number of runs")
    parser.add_argument("--steps", type=int, help="override the number of steps")
    args = parser.parse_args()
    runs, steps, fp_runs = (1000, 50, 5) if args.quick else (10_000, 200, 20)
    runs, steps = args.runs or runs, args.steps or steps
    machine = {"cores": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
               "jax": jax.__version__, "jaxtrack": getattr(jaxtrack, "__version__", "dev"), "dtype": "float64"}
    print(f"nonlinear filters vs peers, float64, {machine['cores']} cores, jax {machine['jax']}, "
          f"best of {args.repeats}")
    print(f"command: python {' '.join(sys.argv)}")
    report = {"machine": machine, "command": "python " + " ".join(sys.argv), "rows": []}
    names = {"ukf": f"UKF (α, β, κ) = {UKF_PARAMS}", "iekf": f"iterated EKF, {IEKF_ITERATIONS} iterations"}
    for kind in args.filters.split(","):
        row = bench(kind, runs, steps, args.repeats, fp_runs, args.model)
        report["rows"].append(row)
        for job, rates in row["steps_per_s"].items():
            ours = [k for k in rates if k.startswith("jaxtrack")]
            print_table(f"{names[kind]}, {args.model}, {runs} runs × {steps} steps — {job}", rates, ours)
        print("  max relative |Δ mean| vs jaxtrack (5 runs): "
              + ", ".join(f"{k} {v:.1e}" for k, v in row["max_rel_mean_difference_first_5_runs"].items()))
    print(f"\npeak RSS of this process: {peak_rss_mb():.0f} MB")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=2)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

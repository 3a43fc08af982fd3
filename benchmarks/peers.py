"""Batched Kalman filtering and Monte Carlo throughput: jaxtrack against FilterPy, simdkalman, dynamax.

Every contender gets the same simulated data in one process, and the table reports filter steps
per second (runs × steps / wall time) and the ratio of each jaxtrack path to each peer. On a
shared machine only ratios measured in the same run mean anything; each time is the best of
``--repeats`` rounds, and the rounds interleave the contenders so that load drifts hit all alike.
Times exclude compilation (every jitted function runs once first).

What is measured:

1. **Linear Kalman filter** at several (runs × steps × states) points. Two jobs: *means*, the
   filtered mean of every step of every run, and *loglik*, each run's log-likelihood (what
   parameter estimation and model comparison need; no per-step output). Two scenarios:

   - *shared schedule*: every run sees every measurement, so the covariances are the same in
     all runs. jaxtrack picks its shared-covariance path by itself (``run_filter_batch``); the
     "per-run path" row forces the general path (``covariance="per_run"``), which is ``vmap`` of
     the single-run scan (JAX then keeps the data-free covariance unbatched by itself, and so it
     does for dynamax's ``jit(vmap(lgssm_filter))``).
   - *per-run masks* (log-likelihood job): each run misses 10% of its measurement steps at
     random, so every run has its own covariances. jaxtrack runs its general path (chosen
     automatically by the per-run mask), FilterPy skips the update, simdkalman gets NaN, and
     dynamax, which has no missing-data support, gets R = 10¹²·I on those steps (a per-run,
     per-step R: the same per-run covariance work).

   FilterPy computes the means in both jobs (and the log-likelihood from its own ``y`` and
   ``S`` in the second); simdkalman always returns means and log-likelihoods together.

2. **Extended Kalman filter** on a range-bearing model (2-D constant velocity, sensor at the
   origin), against FilterPy's EKF and dynamax's ``extended_kalman_filter``.
3. **A full Monte Carlo study**: simulate truth and measurements, filter, and accumulate RMSE
   and NEES (jaxtrack: ``monte_carlo``, streaming, nothing stored per run), against the same job
   written with dynamax (``vmap`` of ``LinearGaussianSSM.sample``, ``vmap`` of ``lgssm_filter``,
   metrics in ``jnp``).
4. **Memory**: a 10⁶-run × 200-step ``monte_carlo`` of the 4-state model in a fresh process;
   its peak resident set size is printed.

FilterPy is a Python loop per run: it is timed on a subset of runs and scaled. simdkalman is
timed on a subset of runs too (it vectorises across runs, so its cost is linear in runs).

Needs the ``bench`` extra::

    pip install -e ".[bench]"

Usage::

    python benchmarks/peers.py                       # full table (~10 minutes on 2 cores)
    python benchmarks/peers.py --quick               # small sizes, a smoke test
    python benchmarks/peers.py --json peers.json     # also write the table as JSON
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import jaxtrack
from jaxtrack.filters import ExtendedKalmanFilter, KalmanFilter, run_filter_batch
from jaxtrack.models import AbstractStateSpaceModel, constant_acceleration, constant_velocity
from jaxtrack.montecarlo import monte_carlo, simulate

MISSING_FRACTION = 0.1
HUGE_R = 1e12


# ---------------------------------------------------------------------------------------------
# Models


def linear_model(n: int):
    """4: 2-D constant velocity; 6: 3-D constant velocity; 9: 3-D constant acceleration.

    1 s sampling, position measurements with 10 m noise.
    """
    if n in (4, 6):
        dim = n // 2
        prior = jnp.diag(jnp.asarray([100.0] * dim + [10.0] * dim) ** 2)
        return constant_velocity(1.0, dim=dim, accel_psd=0.5, measurement_std=10.0, initial_cov=prior)
    if n == 9:
        prior = jnp.diag(jnp.asarray([100.0] * 3 + [10.0] * 3 + [1.0] * 3) ** 2)
        return constant_acceleration(1.0, dim=3, jerk_psd=0.05, measurement_std=10.0, initial_cov=prior)
    raise ValueError(f"no benchmark model with {n} states")


def range_bearing_class(base):
    """The range-bearing model class on ``base`` (a version's ``AbstractStateSpaceModel``; the
    revision benchmark builds it on an earlier jaxtrack too)."""

    class RangeBearing(base):
        """2-D constant velocity ``[x, y, vx, vy]`` seen by a sensor at the origin: ``z = (r, θ)``."""

        F: jax.Array
        Q: jax.Array
        R: jax.Array
        initial_mean: jax.Array
        initial_cov: jax.Array
        angle_components: tuple[int, ...] = eqx.field(static=True)

        @property
        def num_steps(self):
            return None

        def transition(self, x, k):
            return self.F @ x

        def transition_jacobian(self, x, k):
            return self.F

        def measurement(self, x, k):
            return jnp.stack([jnp.hypot(x[0], x[1]), jnp.arctan2(x[1], x[0])])

        def measurement_jacobian(self, x, k):
            r2 = x[0] ** 2 + x[1] ** 2
            r = jnp.sqrt(r2)
            zero = jnp.zeros_like(r)
            return jnp.stack([
                jnp.stack([x[0] / r, x[1] / r, zero, zero]),
                jnp.stack([-x[1] / r2, x[0] / r2, zero, zero]),
            ])

        def process_noise_cov(self, k):
            return self.Q

        def measurement_noise_cov(self, k):
            return self.R

    return RangeBearing


RangeBearing = range_bearing_class(AbstractStateSpaceModel)


def range_bearing_model(cls=RangeBearing):
    cv = linear_model(4)
    return cls(
        F=cv.F, Q=cv.Q, R=jnp.diag(jnp.asarray([5.0, 0.01]) ** 2),
        initial_mean=jnp.asarray([3000.0, 2000.0, -10.0, 5.0]),
        initial_cov=jnp.diag(jnp.asarray([50.0, 50.0, 5.0, 5.0]) ** 2),
        angle_components=(1,),
    )


def simulate_batch(model, num_runs, num_steps, seed=0):
    keys = jax.random.split(jax.random.key(seed), num_runs)
    traj = jax.jit(jax.vmap(lambda k: simulate(model, k, num_steps)))(keys)
    return jax.block_until_ready(traj)


# ---------------------------------------------------------------------------------------------
# Timing


def timed(fn):
    t0 = time.perf_counter()
    jax.block_until_ready(fn())
    return time.perf_counter() - t0


def race(contenders: dict, repeats: int) -> dict:
    """Best wall time of each contender over ``repeats`` interleaved rounds (after a warm-up).

    ``contenders`` maps a name to ``(fn, scale)``: ``fn()`` runs the job (or a subset of it) and
    ``scale`` multiplies its time up to the full job.
    """
    for fn, _ in contenders.values():
        jax.block_until_ready(fn())
    best = {name: np.inf for name in contenders}
    for _ in range(repeats):
        for name, (fn, scale) in contenders.items():
            best[name] = min(best[name], timed(fn) * scale)
    return best


# ---------------------------------------------------------------------------------------------
# Peers: linear Kalman filter


def dynamax_params(model, R=None):
    from dynamax.linear_gaussian_ssm import ParamsLGSSM
    from dynamax.linear_gaussian_ssm.models import (
        ParamsLGSSMDynamics,
        ParamsLGSSMEmissions,
        ParamsLGSSMInitial,
    )

    n, m = model.state_dim, model.meas_dim
    return ParamsLGSSM(
        initial=ParamsLGSSMInitial(mean=model.initial_mean, cov=model.initial_cov),
        dynamics=ParamsLGSSMDynamics(weights=model.F, bias=jnp.zeros(n), input_weights=jnp.zeros((n, 0)), cov=model.Q),
        emissions=ParamsLGSSMEmissions(weights=model.H, bias=jnp.zeros(m), input_weights=jnp.zeros((m, 0)),
                                       cov=model.R if R is None else R),
    )


def dynamax_kf(model, job):
    """``jit(vmap(lgssm_filter))``; ``job`` "means" returns the filtered means, "loglik" the
    marginal log-likelihoods (XLA then drops the unused histories)."""
    from dynamax.linear_gaussian_ssm import lgssm_filter

    params = dynamax_params(model)

    @jax.jit
    def run(zs):
        post = jax.vmap(lambda y: lgssm_filter(params, y))(zs)
        return post.filtered_means if job == "means" else post.marginal_loglik

    return run


def dynamax_kf_masked(model, job):
    """dynamax has no missing data: a missing step gets R = 10¹²·I (per run and step)."""
    from dynamax.linear_gaussian_ssm import lgssm_filter

    m = model.meas_dim

    @jax.jit
    def run(zs, observed):
        def one(y, obs):
            R = jnp.where(obs[:, None, None], model.R, HUGE_R * jnp.eye(m))
            post = lgssm_filter(dynamax_params(model, R), y)
            return post.filtered_means if job == "means" else post.marginal_loglik

        return jax.vmap(one)(zs, observed)

    return run


def filterpy_kf(model, zs, observed=None, loglik=False):
    """FilterPy's ``predict(); update(z)`` loop per run; the log-likelihood, when asked for, is
    accumulated from FilterPy's own ``y`` and ``S`` (cheaper than its ``log_likelihood``)."""
    from filterpy.kalman import KalmanFilter as FPKalmanFilter

    F, Q, H, R = (np.asarray(a) for a in (model.F, model.Q, model.H, model.R))
    x0, P0 = np.asarray(model.initial_mean), np.asarray(model.initial_cov)
    n, m = F.shape[0], H.shape[0]
    out = np.empty(zs.shape[:2] + (n,))
    lls = np.zeros(zs.shape[0])
    for i, z_run in enumerate(zs):
        kf = FPKalmanFilter(dim_x=n, dim_z=m)
        kf.F, kf.Q, kf.H, kf.R = F, Q, H, R
        kf.x, kf.P = x0.copy(), P0.copy()
        for k, z in enumerate(z_run):
            if k:
                kf.predict()
            seen = observed is None or observed[i, k]
            kf.update(z if seen else None)
            out[i, k] = kf.x
            if loglik and seen:
                _, logdet = np.linalg.slogdet(kf.S)
                lls[i] -= 0.5 * (kf.y @ np.linalg.solve(kf.S, kf.y) + logdet + m * np.log(2 * np.pi))
    return lls if loglik else out


def simdkalman_kf(model, zs):
    import simdkalman

    kf = simdkalman.KalmanFilter(*(np.asarray(a) for a in (model.F, model.Q, model.H, model.R)))
    res = kf.compute(zs, 0, initial_value=np.asarray(model.initial_mean),
                     initial_covariance=np.asarray(model.initial_cov), smoothed=False, filtered=True,
                     covariances=False, observations=False, log_likelihood=True)
    return res.filtered.states.mean, res.log_likelihood


# ---------------------------------------------------------------------------------------------
# Sections


def bench_linear(num_runs, num_steps, n, repeats, fp_runs, sk_runs) -> dict:
    """Two jobs on a shared schedule ("means": every filtered mean; "loglik": each run's
    log-likelihood) and the log-likelihood job with per-run masks."""
    model = linear_model(n)
    m = model.meas_dim
    zs = simulate_batch(model, num_runs, num_steps).measurements
    zs_np = np.asarray(zs)
    observed = np.random.default_rng(1).random((num_runs, num_steps)) >= MISSING_FRACTION
    zs_nan = np.where(observed[..., None], zs_np, np.nan)
    obs_j = jnp.asarray(observed)
    kf = KalmanFilter()
    fp_runs, sk_runs = min(fp_runs, num_runs), min(sk_runs, num_runs)
    fp_scale, sk_scale = num_runs / fp_runs, num_runs / sk_runs

    def jt(save, field, **kw):
        return lambda: getattr(run_filter_batch(kf, model, zs, save=save, throw=False, **kw), field)

    races = {}
    for job, save, field in (("means", "mean", "filtered_mean"), ("loglik", "final", "log_likelihood")):
        dx = dynamax_kf(model, job)
        races[f"shared schedule, {job}"] = {
            "jaxtrack": (jt(save, field), 1.0),
            "jaxtrack per-run path": (jt(save, field, covariance="per_run"), 1.0),
            "dynamax": (lambda dx=dx: dx(zs), 1.0),
            "simdkalman": (lambda: simdkalman_kf(model, zs_np[:sk_runs]), sk_scale),
            "FilterPy": (lambda job=job: filterpy_kf(model, zs_np[:fp_runs], loglik=job == "loglik"), fp_scale),
        }
    dx_masked = dynamax_kf_masked(model, "loglik")
    races["per-run masks, loglik"] = {
        "jaxtrack": (jt("final", "log_likelihood", mask=obs_j), 1.0),
        "dynamax": (lambda: dx_masked(zs, obs_j), 1.0),
        "simdkalman": (lambda: simdkalman_kf(model, zs_nan[:sk_runs]), sk_scale),
        "FilterPy": (lambda: filterpy_kf(model, zs_np[:fp_runs], observed, loglik=True), fp_scale),
    }
    # The contenders compute the same estimates (checked on a few runs before timing).
    few = slice(0, 5)
    ref = run_filter_batch(kf, model, zs[few])
    ref_masked = run_filter_batch(kf, model, zs[few], mask=obs_j[few])
    ll_const = 0.5 * m * np.log(2 * np.pi) * num_steps  # simdkalman leaves out this constant
    agree = {
        "means: dynamax": np.abs(np.asarray(dynamax_kf(model, "means")(zs[few])) - ref.filtered_mean).max(),
        "means: simdkalman": np.abs(simdkalman_kf(model, zs_np[few])[0] - ref.filtered_mean).max(),
        "means: FilterPy": np.abs(filterpy_kf(model, zs_np[few]) - ref.filtered_mean).max(),
        "loglik: dynamax": np.abs(np.asarray(dynamax_kf(model, "loglik")(zs[few])) - ref.log_likelihood).max(),
        "loglik: simdkalman": np.abs(simdkalman_kf(model, zs_np[few])[1] - ll_const - ref.log_likelihood).max(),
        "loglik: FilterPy": np.abs(filterpy_kf(model, zs_np[few], loglik=True) - ref.log_likelihood).max(),
        "masked loglik: FilterPy": np.abs(filterpy_kf(model, zs_np[few], observed[few], loglik=True)
                                          - ref_masked.log_likelihood).max(),
        "masked means: simdkalman": np.abs(simdkalman_kf(model, zs_nan[few])[0] - ref_masked.filtered_mean).max(),
    }
    total = num_runs * num_steps
    out = {"runs": num_runs, "steps": num_steps, "states": n, "measurements": m,
           "max_abs_difference_vs_jaxtrack": {k: float(v) for k, v in agree.items()}, "steps_per_s": {}}
    for name, contenders in races.items():
        times = race(contenders, repeats)
        out["steps_per_s"][name] = {k: total / t for k, t in times.items()}
    return out


def bench_ekf(num_runs, num_steps, repeats, fp_runs) -> dict:
    from dynamax.nonlinear_gaussian_ssm import ParamsNLGSSM, extended_kalman_filter
    from filterpy.kalman import ExtendedKalmanFilter as FPExtendedKalmanFilter

    model = range_bearing_model()
    zs = simulate_batch(model, num_runs, num_steps).measurements
    zs_np = np.asarray(zs)
    ekf = ExtendedKalmanFilter()
    params = ParamsNLGSSM(model.initial_mean, model.initial_cov, lambda x: model.F @ x, model.Q,
                          lambda x: model.measurement(x, 0), model.R)

    @jax.jit
    def dx(zs):
        return jax.vmap(lambda y: extended_kalman_filter(params, y, output_fields=["filtered_means"]).filtered_means)(zs)

    F, Q, R = (np.asarray(a) for a in (model.F, model.Q, model.R))

    def hx(x):
        return np.array([np.hypot(x[0], x[1]), np.arctan2(x[1], x[0])])

    def h_jac(x):
        r2 = x[0] ** 2 + x[1] ** 2
        r = np.sqrt(r2)
        return np.array([[x[0] / r, x[1] / r, 0.0, 0.0], [-x[1] / r2, x[0] / r2, 0.0, 0.0]])

    def residual(a, b):
        d = a - b
        d[1] = (d[1] + np.pi) % (2 * np.pi) - np.pi
        return d

    def filterpy(zs):
        out = np.empty(zs.shape[:2] + (4,))
        for i, z_run in enumerate(zs):
            f = FPExtendedKalmanFilter(dim_x=4, dim_z=2)
            f.F, f.Q, f.R = F, Q, R
            f.x, f.P = np.asarray(model.initial_mean).copy(), np.asarray(model.initial_cov).copy()
            for k, z in enumerate(z_run):
                if k:
                    f.predict()
                f.update(z, h_jac, hx, residual=residual)
                out[i, k] = f.x
        return out

    fp_runs = min(fp_runs, num_runs)
    ref = np.asarray(run_filter_batch(ekf, model, zs[:5], save="mean").filtered_mean)
    agree = {
        "FilterPy": float(np.abs(filterpy(zs_np[:5]) - ref).max()),
        "dynamax": float(np.abs(np.asarray(dx(zs)[:5]) - ref).max()),
    }
    contenders = {
        "jaxtrack": (lambda: run_filter_batch(ekf, model, zs, save="mean", throw=False).filtered_mean, 1.0),
        "dynamax": (lambda: dx(zs), 1.0),
        "FilterPy": (lambda: filterpy(zs_np[:fp_runs]), num_runs / fp_runs),
    }
    times = race(contenders, repeats)
    total = num_runs * num_steps
    return {"runs": num_runs, "steps": num_steps, "states": 4, "measurements": 2,
            "max_abs_mean_difference": agree, "steps_per_s": {k: total / t for k, t in times.items()}}


def dynamax_monte_carlo_job(model, num_runs, num_steps):
    """The full Monte Carlo job as a dynamax user writes it: ``vmap`` of ``LinearGaussianSSM.sample``
    and ``lgssm_filter``, RMSE, mean error and NEES in ``jnp``. Returns ``job(key)``."""
    from dynamax.linear_gaussian_ssm import LinearGaussianSSM, lgssm_filter

    params = dynamax_params(model)
    ssm = LinearGaussianSSM(model.state_dim, model.meas_dim)

    @jax.jit
    def job(key):
        def one(k):
            states, ys = ssm.sample(params, k, num_steps)
            post = lgssm_filter(params, ys)
            err = states - post.filtered_means
            nees = jnp.einsum("ti,tij,tj->t", err, jnp.linalg.inv(post.filtered_covariances), err)
            return err, nees

        err, nees = jax.vmap(one)(jax.random.split(key, num_runs))
        return jnp.sqrt(jnp.mean(err**2, axis=0)), jnp.mean(err, axis=0), jnp.mean(nees, axis=0), jnp.std(nees, axis=0)

    return job


def bench_monte_carlo(num_runs, num_steps, repeats) -> dict:
    model = linear_model(4)
    dynamax_job = dynamax_monte_carlo_job(model, num_runs, num_steps)

    def jt(**kw):
        return lambda: monte_carlo(model, jax.random.key(1), num_runs, num_steps=num_steps, progress=False, **kw).nees

    contenders = {
        "jaxtrack monte_carlo": (jt(), 1.0),
        "jaxtrack monte_carlo per-run path": (jt(covariance="per_run"), 1.0),
        "dynamax job": (lambda: dynamax_job(jax.random.key(1)), 1.0),
    }
    times = race(contenders, repeats)
    total = num_runs * num_steps
    return {"runs": num_runs, "steps": num_steps, "states": 4, "steps_per_s": {k: total / t for k, t in times.items()}}


_MEMORY_CHILD = """
import sys, time, jax
sys.path.insert(0, {here!r})
from peers import linear_model, peak_rss_mb
from jaxtrack.montecarlo import monte_carlo
model = linear_model(4)
float(monte_carlo(model, jax.random.key(1), 4096, num_steps={steps}, progress=False).anees)  # compile
t0 = time.perf_counter()
res = monte_carlo(model, jax.random.key(0), {runs}, num_steps={steps}, chunk_size=100_000, progress=False)
float(res.anees)
print(time.perf_counter() - t0, peak_rss_mb(), float(res.anees))
"""


def peak_rss_mb() -> float:
    """Peak resident set size of this process in MB: ``VmHWM`` (reset by ``exec``, unlike
    ``ru_maxrss``, which a child started from a large parent inherits), else ``ru_maxrss``."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def bench_memory(num_runs, num_steps) -> dict:
    """A long ``monte_carlo`` in a fresh process, so that its peak RSS is its own (time after
    compilation, which a smaller run of the same block size does first)."""
    code = _MEMORY_CHILD.format(here=os.path.dirname(os.path.abspath(__file__)), runs=num_runs, steps=num_steps)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    seconds, rss_mb, anees = (float(v) for v in out.stdout.split()[-3:])
    return {"runs": num_runs, "steps": num_steps, "seconds": seconds, "steps_per_s": num_runs * num_steps / seconds,
            "peak_rss_mb": rss_mb, "anees": anees}


# ---------------------------------------------------------------------------------------------
# Report


def _fmt_rate(r):
    return f"{r / 1e6:9.3f}" if r < 1e6 else f"{r / 1e6:9.2f}"


def print_table(title, rates: dict, ours: list[str]):
    """One row per contender: steps per second, then how many times faster each jaxtrack path is."""
    print(f"\n{title}")
    print(f"  {'':36s}{'M steps/s':>10s}" + "".join(f"{o + ' ×':>30s}" for o in ours))
    for name, rate in rates.items():
        cells = "" if name in ours else "".join(f"{rates[o] / rate:30.1f}" for o in ours)
        print(f"  {name:36s}{_fmt_rate(rate)} {cells}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes (a smoke test)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    parser.add_argument("--memory-runs", type=int, default=1_000_000, help="runs of the memory check (0: skip)")
    args = parser.parse_args()

    if args.quick:
        points = [(1000, 50, 4), (1000, 50, 6), (1000, 50, 9)]
        ekf_point, mc_point, memory_runs, fp_runs, sk_runs = (1000, 50), (1000, 50), min(args.memory_runs, 10_000), 5, 200
    else:
        points = [(10_000, 200, 4), (10_000, 200, 6), (10_000, 200, 9), (1_000, 1_000, 4)]
        ekf_point, mc_point, memory_runs, fp_runs, sk_runs = (10_000, 200), (10_000, 200), args.memory_runs, 20, 1000
    machine = {
        "cores": os.cpu_count(),
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "jaxtrack": getattr(jaxtrack, "__version__", "dev"),
        "dtype": "float64",
    }
    print(f"jaxtrack vs peers, float64, {machine['cores']} cores, jax {machine['jax']}, best of {args.repeats}")
    print(f"command: python {' '.join(sys.argv)}")
    report = {"machine": machine, "command": "python " + " ".join(sys.argv), "linear": [], "ekf": None,
              "monte_carlo": None, "memory": None}

    for runs, steps, n in points:
        row = bench_linear(runs, steps, n, args.repeats, fp_runs, sk_runs)
        report["linear"].append(row)
        label = f"Kalman filter, {runs} runs × {steps} steps, {n} states, {row['measurements']} measurements"
        for name, rates in row["steps_per_s"].items():
            ours = [k for k in rates if k.startswith("jaxtrack")]
            print_table(f"{label} — {name}", rates, ours)
        print("  max |difference| vs jaxtrack: "
              + ", ".join(f"{k} {v:.1e}" for k, v in row["max_abs_difference_vs_jaxtrack"].items()))

    row = bench_ekf(*ekf_point, args.repeats, fp_runs)
    report["ekf"] = row
    print_table(f"EKF, range-bearing, {row['runs']} runs × {row['steps']} steps", row["steps_per_s"], ["jaxtrack"])
    print("  max |Δ mean| vs jaxtrack: " + ", ".join(f"{k} {v:.1e}" for k, v in row["max_abs_mean_difference"].items()))

    row = bench_monte_carlo(*mc_point, args.repeats)
    report["monte_carlo"] = row
    print_table(f"Full Monte Carlo (simulate, filter, RMSE/NEES), {row['runs']} runs × {row['steps']} steps, 4 states",
                row["steps_per_s"], ["jaxtrack monte_carlo", "jaxtrack monte_carlo per-run path"])

    if memory_runs:
        row = bench_memory(memory_runs, mc_point[1])
        report["memory"] = row
        print(f"\nMemory: monte_carlo {row['runs']} runs × {row['steps']} steps (fresh process): "
              f"{row['seconds']:.1f} s, {row['steps_per_s'] / 1e6:.2f} M steps/s, peak RSS {row['peak_rss_mb']:.0f} MB")
    print(f"\npeak RSS of this process: {peak_rss_mb():.0f} MB")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=2)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

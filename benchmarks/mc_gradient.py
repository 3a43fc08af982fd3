"""Cost of a Monte Carlo gradient: ``jax.grad`` through :func:`jaxtrack.montecarlo.differentiable_monte_carlo`
as a multiple of the forward Monte Carlo (target ≤ 4×), and the process's peak RSS.

The objective is the time-averaged position MSE of a Kalman filter (constant velocity, 2-D) whose
process-noise intensity ``q`` is the parameter (truth fixed, filter mismatched in R); the same
key for both (common random numbers). Both are measured in this run after compilation (each
jitted function runs once first; best of ``--repeats``); the ratio is the number to read, the
absolute times depend on the machine. ``--filter ekf`` uses the per-run covariance path.

    python benchmarks/mc_gradient.py [--runs 100000] [--steps 200] [--filter kf|ekf] [--json]

Peak RSS (``ru_maxrss``) is that of this whole process, JAX runtime and compilations included;
run one configuration per process to read it for that configuration.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxtrack  # noqa: F401  (float64)
from jaxtrack.filters import ExtendedKalmanFilter, KalmanFilter
from jaxtrack.models import constant_velocity
from jaxtrack.montecarlo import differentiable_monte_carlo, monte_carlo

P0 = jnp.diag(jnp.array([100.0, 100.0, 25.0, 25.0]))


def _models(log_q):
    truth = constant_velocity(1.0, accel_psd=1.0, measurement_std=10.0, initial_cov=P0)
    fm = constant_velocity(1.0, accel_psd=jnp.exp(log_q), measurement_std=15.0, initial_cov=P0)
    return truth, fm


def _peak_rss_mb() -> float:
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / 2**20 if sys.platform == "darwin" else rss / 1024  # bytes on macOS, KiB on Linux


def _best_of(fn, repeats):
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return best


def bench(num_runs: int, num_steps: int, filter_name: str = "kf", repeats: int = 2, block_size=None) -> dict:
    filt = KalmanFilter() if filter_name == "kf" else ExtendedKalmanFilter()
    key = jax.random.key(0)

    def objective(log_q):
        truth, fm = _models(log_q)
        res = differentiable_monte_carlo(truth, key, num_runs, num_steps=num_steps, filter=filt, filter_model=fm,
                                         block_size=block_size)
        return jnp.mean(jnp.sum(res.mse[:, :2], axis=-1))

    forward = jax.jit(objective)
    gradient = jax.jit(jax.grad(objective))
    x = jnp.asarray(0.0)
    t0 = time.perf_counter()
    jax.block_until_ready(forward(x))
    compile_forward = time.perf_counter() - t0
    t0 = time.perf_counter()
    jax.block_until_ready(gradient(x))
    compile_grad = time.perf_counter() - t0
    t_fwd = _best_of(lambda: forward(x), repeats)
    t_grad = _best_of(lambda: gradient(x), repeats)
    # The host-driven harness on the same problem (forward only), for reference.
    truth, fm = _models(x)
    monte_carlo(truth, key, num_runs, num_steps=num_steps, filter=filt, filter_model=fm, progress=False)
    t_mc = _best_of(lambda: monte_carlo(truth, key, num_runs, num_steps=num_steps, filter=filt, filter_model=fm,
                                        progress=False).anees, repeats)
    return {
        "runs": num_runs, "steps": num_steps, "filter": filter_name,
        "forward_s": t_fwd, "gradient_s": t_grad, "ratio": t_grad / t_fwd,
        "monte_carlo_s": t_mc, "ratio_vs_monte_carlo": t_grad / t_mc,
        "first_call_forward_s": compile_forward, "first_call_gradient_s": compile_grad,
        "peak_rss_mb": _peak_rss_mb(), "gradient": float(gradient(x)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100_000)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--filter", choices=("kf", "ekf"), default="kf")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--block-size", type=int, default=None)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    r = bench(args.runs, args.steps, args.filter, args.repeats, args.block_size)
    if args.json:
        print(json.dumps(r))
        return
    print(f"Monte Carlo gradient, {r['runs']} runs x {r['steps']} steps, {r['filter'].upper()} "
          f"(device: {jax.devices()[0].platform})")
    print(f"  forward (differentiable_monte_carlo, jitted) : {r['forward_s']:.3f} s")
    print(f"  forward (monte_carlo, host-driven blocks)    : {r['monte_carlo_s']:.3f} s")
    print(f"  gradient (jax.grad, checkpointed blocks)     : {r['gradient_s']:.3f} s")
    print(f"  gradient / forward                           : {r['ratio']:.2f}x  (target <= 4x)")
    print(f"  gradient / monte_carlo                       : {r['ratio_vs_monte_carlo']:.2f}x")
    print(f"  peak RSS of this process                     : {r['peak_rss_mb']:.0f} MB")


if __name__ == "__main__":
    main()

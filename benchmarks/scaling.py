"""Monte Carlo speed-up from sharding the runs over CPU devices (``monte_carlo(..., mesh=...)``).

Each device count runs in a fresh process (the CPU is split into devices when JAX starts), on
the same study and key; the statistics are checked identical across device counts, and the
table prints steps per second and the speed-up over one device. Two jobs:

- *shared covariance*: the 4-state constant-velocity Kalman filter (only means per run);
- *per-run covariance*: the same model through the EKF (a covariance per run).

Usage::

    python benchmarks/scaling.py                    # 1 and 2 devices (this machine has 2 cores)
    python benchmarks/scaling.py --devices 1 2 4    # any counts
    python benchmarks/scaling.py --quick --json scaling.json
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

CHILD = r"""
import json, sys, time
import jax
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_num_cpu_devices", {devices})
import jax.numpy as jnp, numpy as np
from jaxtrack.filters import ExtendedKalmanFilter, KalmanFilter
from jaxtrack.models import constant_velocity
from jaxtrack.montecarlo import monte_carlo, run_mesh

model = constant_velocity(1.0, dim=2, accel_psd=0.5, measurement_std=10.0,
                          initial_cov=jnp.diag(jnp.asarray([100.0, 100.0, 10.0, 10.0]) ** 2))
mesh = run_mesh()
out = {{}}
for name, filt, runs in (("shared covariance", KalmanFilter(), {shared_runs}),
                         ("per-run covariance", ExtendedKalmanFilter(), {per_run_runs})):
    job = lambda: monte_carlo(model, jax.random.key(0), runs, num_steps={steps}, filter=filt,
                              mesh=mesh, progress=False, chunk_size=10**9)
    job()  # compile
    best = float("inf")
    for _ in range({repeats}):
        t0 = time.perf_counter()
        res = job()
        best = min(best, time.perf_counter() - t0)
    out[name] = {{"runs": runs, "seconds": best, "steps_per_s": runs * {steps} / best,
                  "anees": float(res.anees), "mse_sum": float(np.sum(res.mse))}}
print(json.dumps(out))
"""


def run_child(devices, args):
    code = CHILD.format(devices=devices, shared_runs=args.shared_runs, per_run_runs=args.per_run_runs,
                        steps=args.steps, repeats=args.repeats)
    env = dict(os.environ)
    env.pop("XLA_FLAGS", None)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--devices", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--shared-runs", type=int, default=200_000)
    parser.add_argument("--per-run-runs", type=int, default=20_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="small sizes (a smoke test)")
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    args = parser.parse_args()
    if args.quick:
        args.shared_runs, args.per_run_runs, args.steps, args.repeats = 16_384, 2_048, 50, 1

    results = {d: run_child(d, args) for d in args.devices}
    base = results[args.devices[0]]
    print(f"Monte Carlo sharded over CPU devices, {os.cpu_count()} cores, {args.steps} steps, best of {args.repeats}")
    print(f"command: python {' '.join(sys.argv)}")
    for job in base:
        print(f"\n{job} ({base[job]['runs']} runs)")
        print(f"  {'devices':>8s} {'M steps/s':>10s} {'speed-up':>9s}  identical statistics")
        for d, res in results.items():
            r = res[job]
            same = (r["anees"], r["mse_sum"]) == (base[job]["anees"], base[job]["mse_sum"])
            print(f"  {d:8d} {r['steps_per_s'] / 1e6:10.2f} {r['steps_per_s'] / base[job]['steps_per_s']:9.2f}  "
                  f"{'yes' if same else 'NO'}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"cores": os.cpu_count(), "command": "python " + " ".join(sys.argv),
                       "results": {str(d): r for d, r in results.items()}}, f, indent=2)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

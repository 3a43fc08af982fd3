"""What bounds the every-mean and full Monte Carlo jobs on this machine, measured against dynamax.

Two jobs of ``benchmarks/peers.py`` do work that no implementation can skip:

- **every filtered mean** returns a fresh ``(runs, steps, n)`` float64 array, so it cannot run
  faster than writing such an array (the page faults of a fresh 64 MB buffer included);
- **the full Monte Carlo** simulates, so it cannot run faster than drawing its standard
  normals: ``n + m`` per run and step (6 for the 4-state model), by jaxtrack's own generator
  (:func:`jaxtrack.montecarlo._noise.step_normals`, Threefry-2x32 + inverse error function, the
  quality of ``jax.random.normal``) or by ``jax.random.normal`` in one call.

The script times those floors and the dynamax jobs of ``peers.py`` in one run and prints each
floor as a multiple of dynamax: the largest ratio to dynamax any implementation of the job can
reach here. Usage::

    python benchmarks/floors.py [--runs 10000 --steps 200 --repeats 5] [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import os

import jax
import jax.numpy as jnp

import jaxtrack  # noqa: F401  (float64)
from jaxtrack.filters import KalmanFilter, run_filter_batch
from jaxtrack.montecarlo import monte_carlo
from jaxtrack.montecarlo._noise import step_normals

from peers import dynamax_kf, dynamax_monte_carlo_job, linear_model, race, simulate_batch


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10_000)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--json", metavar="PATH")
    args = parser.parse_args()
    runs, steps = args.runs, args.steps
    model = linear_model(4)
    n, m = model.state_dim, model.meas_dim
    zs = simulate_batch(model, runs, steps).measurements
    dx_means = dynamax_kf(model, "means")

    @jax.jit
    def write_means(scale):
        # The cheapest fresh (runs, steps, n) array: one multiply per entry.
        return jnp.full((runs, steps, n), 1.0) * scale

    words = jax.random.key_data(jax.random.split(jax.random.key(0), runs))

    @jax.jit
    def jaxtrack_normals(words):
        # The draws monte_carlo makes, step by step (summed so that nothing is stored).
        def body(total, k):
            return total + jnp.sum(step_normals(words, k, n + m, jnp.float64)), None

        return jax.lax.scan(body, 0.0, jnp.arange(steps))[0]

    @jax.jit
    def jax_normals(key):
        return jnp.sum(jax.random.normal(key, (runs, steps, n + m)))

    dynamax_mc = dynamax_monte_carlo_job(model, runs, steps)

    contenders = {
        "dynamax every mean": (lambda: dx_means(zs), 1.0),
        "jaxtrack every mean": (
            lambda: run_filter_batch(KalmanFilter(), model, zs, save="mean", throw=False).filtered_mean, 1.0),
        "floor: write a fresh (runs, steps, n) array": (lambda: write_means(2.0), 1.0),
        "dynamax full Monte Carlo job": (lambda: dynamax_mc(jax.random.key(1)), 1.0),
        "jaxtrack monte_carlo": (
            lambda: monte_carlo(model, jax.random.key(1), runs, num_steps=steps, progress=False).nees, 1.0),
        "floor: jaxtrack's normals (n+m per step)": (lambda: jaxtrack_normals(words), 1.0),
        "floor: jax.random.normal, one call": (lambda: jax_normals(jax.random.key(2)), 1.0),
    }
    times = race(contenders, args.repeats)
    rate = {k: runs * steps / t for k, t in times.items()}
    print(f"floors, float64, {os.cpu_count()} cores, {runs} runs × {steps} steps, 4 states, best of {args.repeats}")
    print(f"  {'':46s}{'M steps/s':>10s}{'× dynamax':>12s}")
    groups = (("dynamax every mean", ("jaxtrack every mean", "floor: write a fresh (runs, steps, n) array")),
              ("dynamax full Monte Carlo job", ("jaxtrack monte_carlo", "floor: jaxtrack's normals (n+m per step)",
                                                "floor: jax.random.normal, one call")))
    for ref, others in groups:
        print(f"  {ref:46s}{rate[ref] / 1e6:10.2f}")
        for name in others:
            print(f"  {name:46s}{rate[name] / 1e6:10.2f}{rate[name] / rate[ref]:12.1f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"cores": os.cpu_count(), "runs": runs, "steps": steps, "steps_per_s": rate}, f, indent=2)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

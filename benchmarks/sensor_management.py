"""Sensor management: the gradient design against the myopic brute-force manager, jaxtrack's and Stone Soup's.

Five 2-D constant-velocity targets (different priors and manoeuvre noise, tests/_sensor_management_cases.py),
one position sensor (σ = 10 m) that looks at one target per scan, 40 scans of 1 s. The cost is
``J = Σ_k Σ_i tr(P_i[pos, pos])`` (m²), the same for all three. It prints each schedule's ``J``,
the wall time of each method (median of ``--repeats`` calls after a first, compiling one, whose
time is printed apart), and the ratios, all from the same run:

- jaxtrack ``relaxed_sensor_schedule`` (300 Adam steps on softmax look weights, annealed, then
  rounding and single-scan local search),
- jaxtrack ``greedy_sensor_schedule`` (jitted brute force, scan by scan),
- Stone Soup's ``BruteForceSensorManager`` with a sensor whose action picks the target and a
  position-trace reward (built from Stone Soup's base classes in the cases module), run for the 40
  scans with its own ``KalmanPredictor``/``KalmanUpdater``,
- and, as a reference, the design's local search started from the greedy schedule (what the
  gradient stage adds over the search alone).

    python benchmarks/sensor_management.py [--targets 5] [--scans 40] [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
# This checkout's jaxtrack (a script's folder, not the working directory, heads sys.path), and the
# scenario helpers shared with the tests.
sys.path[:0] = [ROOT, os.path.join(ROOT, "tests")]

import jax  # noqa: E402
import numpy as np  # noqa: E402

import jaxtrack  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from jaxtrack.design import greedy_sensor_schedule, relaxed_sensor_schedule, schedule_cost  # noqa: E402
from jaxtrack.design._sensor_management import _polish  # noqa: E402

from _sensor_management_cases import numpy_costs, scenario, stonesoup_schedule  # noqa: E402


def timed(fn, repeats):
    t0 = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, first, statistics.median(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", type=int, default=5)
    parser.add_argument("--scans", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    load_before = os.getloadavg()[0]
    sc = scenario(args.targets, args.scans, seed=11)
    problem = sc.problem()
    relaxed, t_relaxed_first, t_relaxed = timed(lambda: relaxed_sensor_schedule(problem), args.repeats)
    (greedy, greedy_cost), t_greedy_first, t_greedy = timed(lambda: greedy_sensor_schedule(problem), args.repeats)
    stonesoup, t_ss_first, t_ss = timed(lambda: stonesoup_schedule(sc), args.repeats)
    ss_cost = float(schedule_cost(problem, stonesoup[:, 0]))

    # Reference: the design's own local search started from the greedy schedule instead of the
    # rounded relaxation (how much does the gradient stage add?).
    def greedy_polished():
        g, _ = greedy_sensor_schedule(problem)
        out = _polish(problem, jnp.asarray(g.reshape(1, -1, 1), jnp.int32), jnp.asarray(10_000, jnp.int32),
                      jnp.asarray(1e-12))
        return np.asarray(out[0])[0, :, 0], float(np.asarray(out[1])[0]), int(np.asarray(out[2])[0])

    (gp_schedule, gp_cost, gp_moves), t_gp_first, t_gp = timed(greedy_polished, args.repeats)
    # NumPy check of every cost printed (independent recursion).
    check = numpy_costs(problem, np.stack([relaxed.schedule, greedy, stonesoup[:, 0], gp_schedule])[:, :, None])
    worst = float(np.max(np.abs(check - [relaxed.cost, greedy_cost, ss_cost, gp_cost]) / check))

    import stonesoup as ss_pkg
    print(f"sensor management: {args.targets} CV targets, 1 sensor (σ = {sc.noise_std[0]:g} m), "
          f"{args.scans} scans of {sc.tau:g} s; J = Σ_k Σ_i tr(P_pos) in m²")
    print(f"jaxtrack {jaxtrack.__version__}, jax {jax.__version__}, stonesoup {ss_pkg.__version__}, "
          f"python {platform.python_version()}, {os.cpu_count()} cores, float64; "
          f"wall time median of {args.repeats} after a first call")
    print(f"jaxtrack from {os.path.relpath(os.path.dirname(jaxtrack.__file__), ROOT)}/ of this checkout; "
          f"load average (1 min) before {load_before:.2f}, after {os.getloadavg()[0]:.2f}")
    print("command: python benchmarks/sensor_management.py" + "".join(f" {a}" for a in sys.argv[1:]))
    print()
    print(f"  {'method':<44} {'J (m²)':>12} {'vs greedy':>10} {'median':>10} {'first call':>11}")
    rows = [
        ("jaxtrack relaxed_sensor_schedule (gradient)", relaxed.cost, t_relaxed, t_relaxed_first),
        ("jaxtrack greedy_sensor_schedule", greedy_cost, t_greedy, t_greedy_first),
        ("Stone Soup BruteForceSensorManager", ss_cost, t_ss, t_ss_first),
        ("reference: greedy + the design's local search", gp_cost, t_gp, t_gp_first),
    ]
    for name, J, t, first in rows:
        print(f"  {name:<44} {J:>12.2f} {J / greedy_cost:>10.4f} {t * 1e3:>8.2f} ms {first:>9.3f} s")
    print()
    print(f"  gradient design: {len(relaxed.history)} Adam steps, relaxed J {relaxed.relaxed_cost:.2f}, rounded J "
          f"{relaxed.rounded_cost:.2f}, {relaxed.moves} local-search moves; smallest largest weight "
          f"{relaxed.weights.max(axis=-1).min():.3f}")
    print(f"  gradient J / greedy J = {relaxed.cost / greedy_cost:.4f} "
          f"({100 * (1 - relaxed.cost / greedy_cost):.2f}% lower)")
    print(f"  greedy schedule identical to Stone Soup's: {bool(np.array_equal(greedy, stonesoup[:, 0]))}")
    print(f"  greedy + local search: {gp_moves} moves, J / greedy J = {gp_cost / greedy_cost:.4f}; gradient J / "
          f"(greedy + local search) J = {relaxed.cost / gp_cost:.4f}")
    print(f"  time ratios: Stone Soup / jaxtrack greedy = {t_ss / t_greedy:.0f}x; jaxtrack gradient / Stone Soup = "
          f"{t_relaxed / t_ss:.1f}x; jaxtrack gradient / jaxtrack greedy = {t_relaxed / t_greedy:.0f}x")
    print(f"  first calls (compilation + one run): gradient {t_relaxed_first:.2f} s, greedy {t_greedy_first:.2f} s")
    print(f"  largest relative difference from the NumPy recursion over the four J: {worst:.1e}")


if __name__ == "__main__":
    main()

"""Sensor management: the gradient design against the myopic brute-force manager, jaxtrack's and Stone Soup's.

Two scenarios of 2-D constant-velocity targets (different priors and manoeuvre noise,
tests/_sensor_management_cases.py), 40 scans of 1 s, each position sensor looking at one target
per scan: ``one``: five targets, one sensor (σ = 10 m); ``three``: eight targets, three sensors
(σ = 5, 15, 40 m; Stone Soup's brute force enumerates 512 joint looks per scan). The cost is
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

Stone Soup's ``OptimizeBruteSensorManager`` and ``OptimizeBasinHoppingSensorManager`` are not run:
they optimise over continuous ranges (``generator.min``/``max``, ``action_from_value``) with SciPy,
which does not fit a choice among target indices (on an integer grid ``brute`` would be the same
``N^S`` enumeration as ``BruteForceSensorManager``; basin hopping's steps are continuous).

    python benchmarks/sensor_management.py [--scenario one|three|all] [--repeats 5]
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


SCENARIOS = {
    # (targets, scans, sensor σ in m, seed)
    "one": (5, 40, (10.0,), 11),
    # Three sensors of different accuracy: Stone Soup's brute force enumerates 8³ = 512 joint looks
    # per scan in Python; the design's search has 7020 exchanges and 40·512 joint-look changes.
    "three": (8, 40, (5.0, 15.0, 40.0), 3),
}


def run(label, args):
    targets, scans, noise_std, seed = SCENARIOS[label]
    load_before = os.getloadavg()[0]
    sc = scenario(targets, scans, seed=seed, noise_std=noise_std)
    problem = sc.problem()
    S = sc.num_sensors
    relaxed, t_relaxed_first, t_relaxed = timed(lambda: relaxed_sensor_schedule(problem), args.repeats)
    (greedy, greedy_cost), t_greedy_first, t_greedy = timed(lambda: greedy_sensor_schedule(problem), args.repeats)
    stonesoup, t_ss_first, t_ss = timed(lambda: stonesoup_schedule(sc), args.repeats)
    ss_cost = float(schedule_cost(problem, stonesoup.reshape(problem.schedule_shape())))

    # Reference: the design's own local search started from the greedy schedule instead of the
    # rounded relaxation (how much does the gradient stage add?).
    def greedy_polished():
        g, _ = greedy_sensor_schedule(problem)
        out = _polish(problem, jnp.asarray(g.reshape(1, scans, S), jnp.int32), jnp.asarray(10_000, jnp.int32),
                      jnp.asarray(1e-12))
        return np.asarray(out[0])[0], float(np.asarray(out[1])[0]), int(np.asarray(out[2])[0])

    (gp_schedule, gp_cost, gp_moves), t_gp_first, t_gp = timed(greedy_polished, args.repeats)
    # NumPy check of every cost printed (independent recursion).
    check = numpy_costs(problem, np.stack([relaxed.schedule.reshape(scans, S), greedy.reshape(scans, S),
                                           stonesoup, gp_schedule]))
    worst = float(np.max(np.abs(check - [relaxed.cost, greedy_cost, ss_cost, gp_cost]) / check))

    sigmas = ", ".join(f"{s:g}" for s in sc.noise_std)
    print(f"scenario {label!r}: {targets} CV targets, {S} sensor{'s' if S > 1 else ''} (σ = {sigmas} m), "
          f"{scans} scans of {sc.tau:g} s; {targets}^{S} = {targets ** S} joint looks per scan; "
          "J = Σ_k Σ_i tr(P_pos) in m²")
    print(f"load average (1 min) before {load_before:.2f}, after {os.getloadavg()[0]:.2f}")
    print()
    print(f"  {'method':<44} {'J (m²)':>12} {'vs greedy':>10} {'median':>12} {'first call':>11}")
    rows = [
        ("jaxtrack relaxed_sensor_schedule (gradient)", relaxed.cost, t_relaxed, t_relaxed_first),
        ("jaxtrack greedy_sensor_schedule", greedy_cost, t_greedy, t_greedy_first),
        ("Stone Soup BruteForceSensorManager", ss_cost, t_ss, t_ss_first),
        ("reference: greedy + the design's local search", gp_cost, t_gp, t_gp_first),
    ]
    for name, J, t, first in rows:
        print(f"  {name:<44} {J:>12.2f} {J / greedy_cost:>10.4f} {t * 1e3:>10.2f} ms {first:>9.3f} s")
    print()
    print(f"  gradient design: {len(relaxed.history)} Adam steps, {len(relaxed.start_costs)} starts, relaxed J "
          f"{relaxed.relaxed_cost:.2f}, rounded J {relaxed.rounded_cost:.2f}, {relaxed.moves} local-search moves; "
          f"smallest largest weight {relaxed.weights.max(axis=-1).min():.3f}")
    print(f"  gradient J / greedy J = {relaxed.cost / greedy_cost:.4f} "
          f"({100 * (1 - relaxed.cost / greedy_cost):.2f}% lower); gradient J / Stone Soup J = "
          f"{relaxed.cost / ss_cost:.4f}")
    print(f"  greedy schedule identical to Stone Soup's: "
          f"{bool(np.array_equal(greedy.reshape(scans, S), stonesoup))}")
    print(f"  greedy + local search: {gp_moves} moves, J / greedy J = {gp_cost / greedy_cost:.4f}; gradient J / "
          f"(greedy + local search) J = {relaxed.cost / gp_cost:.4f}")
    print(f"  time ratios: Stone Soup / jaxtrack greedy = {t_ss / t_greedy:.0f}x; Stone Soup / jaxtrack gradient = "
          f"{t_ss / t_relaxed:.2f}x (the goal: ≥ 10x at J ≤ Stone Soup's); jaxtrack gradient / jaxtrack greedy = "
          f"{t_relaxed / t_greedy:.0f}x")
    print(f"  first calls (compilation + one run): gradient {t_relaxed_first:.2f} s, greedy {t_greedy_first:.2f} s, "
          f"Stone Soup {t_ss_first:.2f} s")
    print(f"  largest relative difference from the NumPy recursion over the four J: {worst:.1e}")
    print()


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", choices=[*SCENARIOS, "all"], default="all")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    import stonesoup as ss_pkg
    print(f"jaxtrack {jaxtrack.__version__}, jax {jax.__version__}, stonesoup {ss_pkg.__version__}, "
          f"python {platform.python_version()}, {os.cpu_count()} cores (shared), float64; "
          f"wall time median of {args.repeats} after a first call")
    print(f"jaxtrack from {os.path.relpath(os.path.dirname(jaxtrack.__file__), ROOT)}/ of this checkout")
    print("command: python benchmarks/sensor_management.py" + "".join(f" {a}" for a in sys.argv[1:]))
    print()
    for label in SCENARIOS if args.scenario == "all" else [args.scenario]:
        run(label, args)


if __name__ == "__main__":
    main()

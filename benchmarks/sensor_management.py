"""Sensor management: the gradient design against the myopic brute-force manager, jaxtrack's and Stone Soup's.

Three scenarios of 2-D constant-velocity targets (different priors and manoeuvre noise,
tests/_sensor_management_cases.py), 40 scans of 1 s, each position sensor looking at one target
per scan: ``one``: five targets, one sensor (σ = 10 m); ``three``: eight targets, three sensors
(σ = 5, 15, 40 m; Stone Soup's brute force enumerates 512 joint looks per scan); ``four``: eight
targets, four sensors (σ = 5, 15, 40, 25 m; 4096 joint looks per scan: the default design and the
greedy + exact search reference are not run there, about a minute a call, and Stone Soup is timed
once). The cost is
``J = Σ_k Σ_i tr(P_i[pos, pos])`` (m²), the same for all three. It prints each schedule's ``J``,
the wall time of each method (median of ``--repeats`` calls after a first, compiling one, whose
time is printed apart), and the ratios, all from the same run:

- jaxtrack ``relaxed_sensor_schedule`` (300 Adam steps on softmax look weights, annealed, then
  rounding and single-scan local search), with its defaults (4 starts, every exchange priced per
  iteration) and in its fast setting (``exchanges=32, starts=1``: screened exchanges, one start),
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
from jaxtrack.design import (  # noqa: E402
    greedy_sensor_schedule,
    relaxed_sensor_schedule,
    schedule_cost,
    simulate_sensor_schedule,
)
from jaxtrack.montecarlo import gospa  # noqa: E402
from jaxtrack.design._sensor_management import _polish  # noqa: E402

from _sensor_management_cases import numpy_costs, scenario, stonesoup_schedule  # noqa: E402


def timed(fn, repeats):
    """``(out, first call s, median s of repeats)``; with ``repeats = 0`` the first call is the median."""
    t0 = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t0
    times = [] if repeats else [first]
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
    # A fourth sensor: 8⁴ = 4096 joint looks per scan for the brute force, 2⁴ = 16 subsets per
    # target and scan for the design's single-move table.
    "four": (8, 40, (5.0, 15.0, 40.0, 25.0), 5),
}
SLOW = {"four"}
# The design's fast setting: screened exchanges, one start.
FAST = {"exchanges": 32, "starts": 1}


def run(label, args):
    targets, scans, noise_std, seed = SCENARIOS[label]
    load_before = os.getloadavg()[0]
    sc = scenario(targets, scans, seed=seed, noise_std=noise_std)
    problem = sc.problem()
    S = sc.num_sensors
    slow = label in SLOW  # the exact searches take about a minute a call here: not run
    rows = []  # (name, J, median s, first call s, schedule (T, S))

    def add(name, fn, repeats=args.repeats):
        (schedule, J), first, median = timed(fn, repeats)
        rows.append((name, J, median, first, np.asarray(schedule).reshape(scans, S)))
        return schedule, J

    def design(**kw):
        d = relaxed_sensor_schedule(problem, **kw)
        designs[kw.get("exchanges")] = d
        return d.schedule, d.cost

    designs = {}
    if not slow:
        add("jaxtrack relaxed_sensor_schedule (gradient)", design)
    add(f"  the same, exchanges={FAST['exchanges']}, starts={FAST['starts']}", lambda: design(**FAST))
    greedy, greedy_cost = add("jaxtrack greedy_sensor_schedule", lambda: greedy_sensor_schedule(problem))

    def stone_soup():
        schedule = stonesoup_schedule(sc)
        return schedule, float(schedule_cost(problem, schedule.reshape(problem.schedule_shape())))

    # Stone Soup compiles nothing: where one call takes minutes, that call is the measurement.
    stonesoup, ss_cost = add("Stone Soup BruteForceSensorManager", stone_soup, 0 if slow else args.repeats)

    # Reference: the design's own local search started from the greedy schedule instead of the
    # rounded relaxation (how much does the gradient stage add?).
    def greedy_polished():
        g, _ = greedy_sensor_schedule(problem)
        out = _polish(problem, jnp.asarray(g.reshape(1, scans, S), jnp.int32), jnp.asarray(10_000, jnp.int32),
                      jnp.asarray(1e-12))
        greedy_polished.moves = int(np.asarray(out[2])[0])
        return np.asarray(out[0])[0], float(np.asarray(out[1])[0])

    if not slow:
        add("reference: greedy + the design's local search", greedy_polished)
    # NumPy check of every cost printed (independent recursion).
    check = numpy_costs(problem, np.stack([r[4] for r in rows]))
    worst = float(np.max(np.abs(check - [r[1] for r in rows]) / check))

    sigmas = ", ".join(f"{s:g}" for s in sc.noise_std)
    print(f"scenario {label!r}: {targets} CV targets, {S} sensor{'s' if S > 1 else ''} (σ = {sigmas} m), "
          f"{scans} scans of {sc.tau:g} s; {targets}^{S} = {targets ** S} joint looks per scan; "
          "J = Σ_k Σ_i tr(P_pos) in m²")
    print(f"load average (1 min) before {load_before:.2f}, after {os.getloadavg()[0]:.2f}")
    if slow:
        print("  not run here: the default design (exact search, 4 starts) and greedy + exact search, about a minute "
              "a call; Stone Soup timed once (no compilation)")
    print()
    print(f"  {'method':<44} {'J (m²)':>12} {'vs greedy':>10} {'median':>12} {'first call':>11}")
    for name, J, t, first, _ in rows:
        print(f"  {name:<44} {J:>12.2f} {J / greedy_cost:>10.4f} {t * 1e3:>10.2f} ms {first:>9.3f} s")
    print()
    t_ss = rows[[r[0] for r in rows].index("Stone Soup BruteForceSensorManager")][2]
    t_greedy = rows[[r[0] for r in rows].index("jaxtrack greedy_sensor_schedule")][2]
    for exchanges, d in designs.items():
        name = "default" if exchanges is None else f"exchanges={exchanges}, starts={FAST['starts']}"
        t = rows[0 if exchanges is None else (0 if slow else 1)][2]
        print(f"  gradient design ({name}): {len(d.history)} Adam steps, {len(d.start_costs)} starts, relaxed J "
              f"{d.relaxed_cost:.2f}, rounded J {d.rounded_cost:.2f}, {d.moves} local-search moves; smallest largest "
              f"weight {d.weights.max(axis=-1).min():.3f}; J / greedy J = {d.cost / greedy_cost:.4f} "
              f"({100 * (1 - d.cost / greedy_cost):.2f}% lower), J / Stone Soup J = {d.cost / ss_cost:.4f}; "
              f"Stone Soup time / its time = {t_ss / t:.2f}x (the goal: ≥ 10x at J ≤ Stone Soup's)")
    print(f"  greedy schedule identical to Stone Soup's: {bool(np.array_equal(greedy.reshape(scans, S), stonesoup))}"
          f"; Stone Soup / jaxtrack greedy time = {t_ss / t_greedy:.0f}x")
    if not slow:
        gp = rows[-1]
        print(f"  greedy + local search: {greedy_polished.moves} moves, J / greedy J = {gp[1] / greedy_cost:.4f}")
    print("  first calls (compilation + one run): " + ", ".join(f"{r[0].strip()} {r[3]:.2f} s" for r in rows))
    print(f"  largest relative difference from the NumPy recursion over the J above: {worst:.1e}")
    if args.runs:
        gospa_table(problem, rows, args)
    print()


@jax.jit
def _per_scan_gospa(truth, estimates, cutoff):
    valid = jnp.ones(truth.shape[-2], bool)
    one = lambda t, e: gospa(t, valid, e, valid, cutoff=cutoff, order=2).distance  # noqa: E731
    return jax.vmap(jax.vmap(one))(truth, estimates)


def gospa_table(problem, rows, args):
    """Each schedule's tracking accuracy: ``--runs`` Monte Carlo runs of the targets and the looks'
    measurements (:func:`jaxtrack.design.simulate_sensor_schedule`, the same key for every schedule:
    common random numbers), each target's Kalman filter, and GOSPA (p = 2, α = 2, cut-off
    ``--cutoff``) per scan. With the cut-off beyond every error, E[Σ_k GOSPA_k²] = J."""
    key = jax.random.key(args.seed)
    per_run = {}
    for name, J, _, _, schedule in rows:
        sim = simulate_sensor_schedule(problem, schedule.reshape(problem.schedule_shape()), key, args.runs)
        g = np.asarray(_per_scan_gospa(sim.truth, sim.estimates, args.cutoff))  # (R, T)
        per_run[name] = (g.mean(axis=1), (g**2).sum(axis=1), J)
    ss = per_run["Stone Soup BruteForceSensorManager"][0]
    print(f"  tracking accuracy, {args.runs} Monte Carlo runs (same draws for every schedule), GOSPA p = 2, "
          f"c = {args.cutoff:g} m, no missed or false targets:")
    print(f"  {'method':<44} {'mean GOSPA (m)':>16} {'Σ_k GOSPA² / J':>15} {'− Stone Soup (m)':>24}")
    for name, (mean_g, sq, J) in per_run.items():
        se = mean_g.std(ddof=1) / np.sqrt(mean_g.size)
        d = mean_g - ss
        se_d = d.std(ddof=1) / np.sqrt(d.size) if np.any(d) else 0.0
        print(f"  {name:<44} {mean_g.mean():>9.4f} ± {se:6.4f} {sq.mean() / J:>15.4f} "
              f"{d.mean():>+13.4f} ± {se_d:6.4f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", choices=[*SCENARIOS, "all"], default="all")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--runs", type=int, default=2000,
                        help="Monte Carlo runs per schedule for the mean GOSPA (0: skip)")
    parser.add_argument("--cutoff", type=float, default=100.0, help="GOSPA cut-off c, m")
    parser.add_argument("--seed", type=int, default=0, help="the Monte Carlo's key")
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

"""Per-scan time of the Williams (2015) study's filters (GM-PHD, GM-CPHD, PMB, PMBM at several budgets).

The job: one run of :func:`jaxtrack.multitarget.williams15` (81 scans, up to 40 measurements per
padded scan), filtered by the study's GM-PHD, GM-CPHD and PMB and by its PMBM at several
global-hypothesis budgets ``H`` (``--hypotheses``, default 16, 64 and 200: the study's value, and the MATLAB reference's
``Nhyp_max = 200``), each jitted once (compilation reported separately), timed as the best of
``--repeats`` runs; and a vmapped batch of ``--runs`` runs (the Monte Carlo's shape) for the
study's budget. Printed: milliseconds per scan, the largest number of global hypotheses held and
the largest ranked-assignment size a scan needed.

No peer runs here: Stone Soup has no PMBM, and the reference is MATLAB (not installed on this
machine; its papers report GOSPA, not per-scan time), so the MATLAB figure is not compared.

Usage::

    python benchmarks/pmbm.py                       # H = 16, 64, 200; a batch of 8 runs at H = 16
    python benchmarks/pmbm.py --quick               # H = 4 only, batch of 2, one repeat
    python benchmarks/pmbm.py --hypotheses 16 200
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import numpy as np  # noqa: E402

from jaxtrack.applications.williams15.scenario import (  # noqa: E402
    ASSIGNMENT_ROWS, ASSIGNMENT_TRACKS, PMBM_HYPOTHESES, methods, scenario,
)
from jaxtrack.multitarget import PMBM, run_cphd, run_phd, simulate_scenario, simulate_scenarios  # noqa: E402
from jaxtrack.multitarget._multibernoulli import _run  # noqa: E402


def _time(fn, *args, repeats):
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - t0)
    return first - best, best, out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hypotheses", type=int, nargs="+", default=[16, 64, 200])
    ap.add_argument("--runs", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    if a.quick:
        a.hypotheses, a.runs, a.repeats = [4], 2, 1
    scen, settings = scenario()
    base = methods(scen, settings)
    truth = simulate_scenario(scen, 1)
    z, v = truth.scans.measurements, truth.scans.valid
    T = z.shape[0]
    print(f"jaxtrack PMBM/PMB on the Williams (2015) scenario: {T} scans, {z.shape[1]} measurement slots, "
          f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}")
    print(f"{'filter':<22}{'compile [s]':>12}{'ms/scan':>10}{'max hyps':>10}{'max rows':>10}{'max tracks':>12}")
    # The study's intensity filters first (their reduction, Table II, is a while loop over the
    # merges made: jaxtrack/multitarget/_reduction.py).
    for name, runner, f in (("GM-PHD", run_phd, base["phd"]), ("GM-CPHD", run_cphd, base["cphd"])):
        comp, best, _ = _time(eqx.filter_jit(lambda f, z, v, runner=runner: runner(f, z, v, warn=False)), f, z, v,
                              repeats=a.repeats)
        print(f"{name:<22}{comp:>12.1f}{best / T * 1e3:>10.2f}{'-':>10}{'-':>10}{'-':>12}")
    run = eqx.filter_jit(_run)
    contenders = [("PMB (exact JPDA)", base["pmb"])]
    for H in a.hypotheses:
        pmbm = methods(scen, settings, pmbm_hypotheses=H)["pmbm"]
        contenders.append((f"PMBM H={H}", pmbm))
    for name, f in contenders:
        comp, best, r = _time(run, f, z, v, repeats=a.repeats)
        print(f"{name:<22}{comp:>12.1f}{best / T * 1e3:>10.2f}{int(np.max(r.num_hypotheses)):>10}"
              f"{int(np.max(r.assignment_rows)):>10}{int(np.max(r.assignment_tracks)):>12}")
    H = PMBM_HYPOTHESES if not a.quick else a.hypotheses[0]
    pmbm = methods(scen, settings, pmbm_hypotheses=H)["pmbm"]
    assert isinstance(pmbm, PMBM) and (pmbm.assignment_rows, pmbm.assignment_tracks) == (ASSIGNMENT_ROWS, ASSIGNMENT_TRACKS)
    batch = simulate_scenarios(scen, 2, a.runs)
    vrun = eqx.filter_jit(jax.vmap(_run, in_axes=(None, 0, 0)))
    comp, best, _ = _time(vrun, pmbm, batch.scans.measurements, batch.scans.valid, repeats=a.repeats)
    print(f"batch of {a.runs} runs, PMBM H={H}: compile {comp:.1f} s, {best / (T * a.runs) * 1e3:.2f} ms per scan per run")


if __name__ == "__main__":
    main()

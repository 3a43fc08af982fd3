"""Every benchmark script runs: each of benchmarks/*.py at the smallest sizes its own options allow.

The benchmarks print speed ratios against peer libraries and no other test runs them, so an API
change could break one unnoticed (jpda_vs_pyehm.py raised a TypeError at run time for weeks).
Each script runs here as a fresh ``python benchmarks/NAME.py ...`` from the repository root, on
the CPU, with this checkout's jaxtrack first on ``PYTHONPATH`` and the suite's environment
otherwise (tests/conftest.py: its compilation cache, its XLA optimisation level); it must exit 0
and print the line its results hang on (a ratio, a speed-up, an agreement check). A script whose
peer library is not installed is skipped, naming it. Scripts that write files are pointed into
``tmp_path``: nothing is written to benchmarks/measured/. Slow: ``pytest --runslow
tests/test_benchmarks_smoke.py`` (part of ``make test-slow``) took 6:44 on 2 cores shared with
other jobs (load 6 to 8), cold or warm compilation cache alike (2026-12-07; the longest:
sensor_management 28-77 s, maneuvering_study 50-55 s, phd_batch 43-58 s, pmbm 42-46 s,
phd_reductions 31-50 s; each test prints its script's wall time under ``-s``).
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
BENCHMARKS = ROOT / "benchmarks"
TIMEOUT_S = 600

# name -> (arguments, peer modules it needs, pattern its output must contain). "{tmp}" in an
# argument is the test's tmp_path. The sizes are the smallest the script's options allow (one
# repeat, a few runs and steps, one scenario or filter where it has a choice).
SCRIPTS: dict[str, tuple[list[str], tuple[str, ...], str]] = {
    "cli_startup": (["--repeats", "1"], (), r"--help under 1 s: (yes|NO)"),
    "design_methods": (["--g", "1", "--repeats", "1"], (),
                       r"gradient design (converges|does NOT converge) in under 1 s \([\d.]+ s"),
    "first_call": (["--entry", "run_filter_kf", "--out", "{tmp}", "--timeout", "300"], (),
                   r"run_filter_kf: [^\n]*\d"),
    "floors": (["--runs", "64", "--steps", "10", "--repeats", "1"], ("dynamax",),
               r"jaxtrack monte_carlo\s+[\d.]+\s+[\d.]+\n"),
    "glmb": (["--runs", "2", "--hypotheses", "4", "--tracks", "8", "--repeats", "1", "--filters", "GLMB"], (),
             r"GLMB  compile one [^\n]* per run \| mean OSPA +[\d.]+ m"),
    "gospa": (["--pairs", "16", "--ss-pairs", "4", "--repeats", "1"], ("stonesoup",),
              r"jaxtrack/Stone Soup speed-up: \d+×"),
    "imm": (["--quick", "--repeats", "1", "--fp-runs", "1"], ("filterpy",),
            r"scores: time-averaged position RMSE [\d.]+ m"),
    "jpda_vs_pyehm": (["--batch", "4", "--repeats", "1"], ("pyehm",),
                      r"every scan's marginals equal EHM2's to [\d.e+-]+, [\d.e+-]+, [\d.e+-]+"),
    # The reference (the labeledRFS port) needs its own venv and checkout: only jaxtrack's stages here.
    "labelled_reference": (["--stage", "export,ours", "--runs", "2", "--workdir", "{tmp}", "--filters", "glmb",
                            "--glmb-hypotheses", "4"], (), r"ours glmb: batch of 2: [\d.]+ s"),
    "maneuvering_study": (["--runs", "2", "--repeats", "1"], (),
                          r"old / new +: first call [\d.]+x, warm [\d.]+x"),
    "mc_gradient": (["--runs", "16", "--steps", "10", "--repeats", "1"], (), r"gradient / forward +: [\d.]+x"),
    "monte_carlo_throughput": (["--runs", "20", "--steps", "10"], ("filterpy",), r"M steps/s +\d+x FilterPy\n"),
    "multitarget": (["--runs", "2", "--ss-runs", "1", "--block", "2", "--repeats", "1", "--stonesoup", "JPDA",
                     "--clutter", "1"],
                    ("stonesoup",), r"jaxtrack / Stone Soup JPDA speed-up per scan: \d+×"),
    "nonlinear": (["--runs", "8", "--steps", "10", "--repeats", "1", "--filters", "ukf"], ("filterpy", "dynamax"),
                  r"max relative \|Δ mean\| vs jaxtrack \(5 runs\): dynamax [\d.e+-]+, FilterPy [\d.e+-]+"),
    "parallel_kalman": (["--steps", "16", "--repeats", "1"], ("dynamax",),
                        r"parallel / sequential \(jaxtrack\)\n +filter +[\d.]+×"),
    "particle": (["--particles", "200", "--steps", "20", "--runs", "2", "--ss-steps", "5", "--repeats", "1"],
                 ("filterpy", "stonesoup"), r"jaxtrack / Stone Soup: +one run +[\d.]+×"),
    "pcrlb": (["--steps", "10", "--runs", "2", "--repeats", "1"], (),
              r"linear CV model: KF covariance pass [\d.]+ ms, pcrlb\(1 truth\) [\d.]+ ms, ratio [\d.]+"),
    "peers": (["--quick", "--repeats", "1", "--memory-runs", "0"], ("filterpy", "dynamax", "simdkalman"),
              r"Full Monte Carlo"),
    "pf_vs_bounds": (["--geometry", "R1", "--runs", "4", "--particles", "100"], (),
                     r"N = 100 particles [^\n]*\n[^\n]*PF/per-truth\n +\d+ +[\d.]+"),
    "phd_batch": (["--quick", "--repeats", "1", "--out", "{tmp}/phd_batch.txt"], (), r"crossing GM-PHD vo-ma"),
    "phd_reductions": (["--runs", "2", "--scenarios", "sparse", "--out", "{tmp}/phd_reductions.txt"], (),
                       r"sparse [^\n]*: 2 runs[^\n]*\n[^\n]*\n +vo-ma +[\d.]+ ±"),
    "pmbm": (["--quick"], (), r"batch of 2 runs, PMBM H=4: compile [\d.]+ s, [\d.]+ ms per scan per run"),
    "readme_table": (["benchmarks/measured/peers.json"], (), r"\| job \| states \|"),
    "revisions": (["--runs", "16", "--steps", "10", "--repeats", "1", "--only", "EKF"], (),
                  r"EKF range-bearing, means +[\d.]+ +[\d.]+ +[\d.]+"),
    "rfs": (["--quick", "--scans", "5", "--runs", "2", "--repeats", "1", "--ss-repeats", "1"], ("stonesoup",),
            r"Stone Soup / jaxtrack GM-PHD per scan: one run [\d.]+×"),
    "scaling": (["--devices", "1", "2", "--steps", "5", "--shared-runs", "64", "--per-run-runs", "16",
                 "--repeats", "1"], (), r"shared covariance \(64 runs\)\n[^\n]*\n +1 [^\n]*yes\n +2 [^\n]*yes"),
    "sensitivity_cost": (["--steps", "10", "--repeats", "1", "--sizes", "2"], (),
                         r"n =  2: adjoint gradient is [\d.]+x faster than reverse mode"),
    "sensor_management": (["--scenario", "one", "--repeats", "0", "--runs", "50"], ("stonesoup",),
                          r"greedy schedule identical to Stone Soup's: (True|False)"),
}


def _scripts() -> list[str]:
    """The runnable scripts of benchmarks/ (private helpers, ``_*.py``, left out)."""
    return sorted(p.stem for p in BENCHMARKS.glob("*.py") if not p.name.startswith("_"))


def test_every_script_is_listed():
    """A new benchmark script gets its smoke run here (or the listing fails)."""
    assert _scripts() == sorted(SCRIPTS)


def _env() -> dict:
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    # This checkout's jaxtrack, whatever the venv has installed (an editable install elsewhere).
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    return env


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SCRIPTS))
def test_benchmark_runs(name, tmp_path):
    args, peers, expected = SCRIPTS[name]
    missing = [m for m in peers if importlib.util.find_spec(m) is None]
    if missing:
        pytest.skip(f"benchmarks/{name}.py needs {', '.join(missing)} (not installed; pip install -e '.[bench]')")
    measured = {p.name: p.stat().st_mtime_ns for p in (BENCHMARKS / "measured").iterdir()}
    cmd = [sys.executable, str(BENCHMARKS / f"{name}.py"), *(a.replace("{tmp}", str(tmp_path)) for a in args)]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=TIMEOUT_S)
    wall = time.perf_counter() - t0
    print(f"benchmarks/{name}.py: {wall:.1f} s")
    out = proc.stdout
    tail = f"\n--- stdout ---\n{out[-3000:]}\n--- stderr ---\n{proc.stderr[-3000:]}"
    if name == "cli_startup":
        # Its exit status is its verdict on the 1 s target (a measurement on a busy machine), not a crash.
        assert proc.returncode == (0 if "--help under 1 s: yes" in out else 1), tail
    else:
        assert proc.returncode == 0, tail
    assert re.search(expected, out), f"no match for {expected!r}{tail}"
    assert "Traceback" not in proc.stderr, tail
    after = {p.name: p.stat().st_mtime_ns for p in (BENCHMARKS / "measured").iterdir()}
    assert after == measured, "the script wrote into benchmarks/measured/"

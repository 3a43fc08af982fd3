"""The maneuvering study's Monte Carlo, one pass against the former two (issue 35).

Until 32e5e95 ``maneuvering.run_study`` filtered every run twice: ``monte_carlo`` once per
filter (CV, CT, IMM, learned IMM: the streamed statistics), then ``monte_carlo_map`` for the
paired per-run errors and the IMM smoother. It now filters each run once
(``monte_carlo_map`` + :func:`jaxtrack.montecarlo.summarize_runs`). Both revisions run here in one
process on the same learned IMM (``benchmarks/revisions.py``'s ``load_old``), first call (with
compilation) and best of ``--repeats`` warm calls, and the results are checked to agree.

Usage::

    python benchmarks/maneuvering_study.py [--runs 2000] [--old 32e5e95]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import jax  # noqa: E402
import numpy as np  # noqa: E402

import jaxtrack  # noqa: E402, F401  (float64)
from jaxtrack.applications import maneuvering  # noqa: E402
from jaxtrack.applications.maneuvering.scenario import NUM_STEPS  # noqa: E402
from revisions import load_old  # noqa: E402


def timed(fn, repeats):
    t = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return out, first, best


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=maneuvering.DEFAULT_RUNS)
    parser.add_argument("--old", default="32e5e95")
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args(argv)
    fit = maneuvering.learn_imm(5, 80)
    with tempfile.TemporaryDirectory() as folder:
        old_lib = load_old(args.old, folder)
        from jaxtrack_old.applications import maneuvering as old  # noqa: PLC0415
        old_fit = old.learn_imm(5, 80)
        new_study, new_first, new_best = timed(lambda: maneuvering.run_study(args.runs, fit=fit), args.repeats)
        old_study, old_first, old_best = timed(lambda: old.run_study(args.runs, fit=old_fit), args.repeats)
    worst = 0.0
    for name in ("cv", "ct", "imm", "imm_learned"):
        for field in ("mse", "nees", "anees"):
            a, b = np.asarray(getattr(new_study.results[name], field)), np.asarray(getattr(old_study.results[name], field))
            worst = max(worst, float(np.max(np.abs(a - b) / np.abs(b))))
    print(f"maneuvering study, {args.runs} runs x {NUM_STEPS} steps, jax {jax.__version__}, "
          f"{os.cpu_count()} cores (old: {args.old}, {old_lib.__name__})")
    print(f"  one pass  (now)   : first call {new_first:6.1f} s, warm {new_best:6.1f} s")
    print(f"  two passes (old)  : first call {old_first:6.1f} s, warm {old_best:6.1f} s")
    print(f"  old / new         : first call {old_first / new_first:.2f}x, warm {old_best / new_best:.2f}x")
    print(f"  results agree     : max relative difference of mse, nees, anees {worst:.1e}")


if __name__ == "__main__":
    main()

"""Where a compiled job's time goes, fusion by fusion: XLA's per-kernel trace joined to its HLO.

On CPU a vmapped step is a few dozen loop fusions per step; a slow step is usually one fusion
that XLA made expensive (a cheap producer fused into every element of a consumer that reuses
it, a reduction run as a kernel of its own, a transcendental that is not vectorised), which
neither the Python code nor a wall-clock time shows. This prints, for one call of a job after
its warm-up, each fusion's total time over the call, how often it ran and the shape it writes,
and keeps the optimised HLO (``--dump``) to read what a fusion computes.

Usage (needs the ``bench`` extra for the benchmark models)::

    python tools/xla_profile.py                          # the README radar UKF, run_filter_batch
    python tools/xla_profile.py --model range-bearing --runs 10000 --steps 200
    python tools/xla_profile.py --filter ekf --top 40 --dump .cache/hlo

Then ``grep "  %<fusion name> = " <dump>/*after_optimizations.txt`` names the fusion's
computation (``calls=%…``), whose body is the element-wise program. XLA's flags must be set
before JAX starts, so this runs as a script (it sets ``XLA_FLAGS`` itself).
"""

from __future__ import annotations

import argparse
import collections
import gzip
import json
import os
import re
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def fusion_times(fn, trace_dir, dump_dir=None):
    """Profile one call of ``fn`` (already warmed up) and sum the trace's events by name.

    **Arguments:** ``fn``: a zero-argument callable returning JAX arrays; ``trace_dir``: an
    empty folder for the trace; ``dump_dir``: the ``--xla_dump_to`` folder, if any, to read each
    fusion's output shape from.

    **Returns:** ``[(name, total ms, count, shape or "")]``, longest first.
    """
    import jax

    with jax.profiler.trace(str(trace_dir), create_perfetto_trace=True):
        jax.block_until_ready(fn())
    trace = sorted(Path(trace_dir).glob("**/*.trace.json.gz"))[-1]
    events = json.load(gzip.open(trace))
    events = events["traceEvents"] if isinstance(events, dict) else events
    total, count = collections.Counter(), collections.Counter()
    for e in events:
        if e.get("ph") == "X":
            total[e["name"]] += e.get("dur", 0)
            count[e["name"]] += 1
    hlo = ""
    if dump_dir is not None:
        hlo = "".join(p.read_text() for p in Path(dump_dir).glob("*after_optimizations.txt"))
    rows = []
    for name, us in total.most_common():
        shape = re.search(r"  %" + re.escape(name) + r" = (\S+) ", hlo) if hlo else None
        rows.append((name, us / 1e3, count[name], shape.group(1) if shape else ""))
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", choices=("radar", "range-bearing"), default="radar")
    parser.add_argument("--filter", choices=("ukf", "ekf"), default="ukf")
    parser.add_argument("--runs", type=int, default=4096)
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--top", type=int, default=25, help="fusions to print")
    parser.add_argument("--dump", metavar="FOLDER", help="keep the optimised HLO here")
    args = parser.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="xla_profile_"))
    dump = Path(args.dump) if args.dump else work / "hlo"
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_enable_xprof_traceme=true"
                               f" --xla_dump_to={dump} --xla_dump_hlo_as_text").strip()
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import jax
    import nonlinear  # the benchmark's models: the README radar and the 4-state range-bearing

    from jaxtrack.filters import ExtendedKalmanFilter, run_filter_batch

    model = nonlinear.MODELS[args.model]()
    zs = nonlinear.simulate_batch(model, args.runs, args.steps).measurements
    filt = nonlinear.jaxtrack_filter("ukf") if args.filter == "ukf" else ExtendedKalmanFilter()

    def job():
        return run_filter_batch(filt, model, zs, save="mean", throw=False).filtered_mean

    jax.block_until_ready(job())
    rows = fusion_times(job, work / "trace", dump)
    kernels = [r for r in rows if "fusion" in r[0] or r[0].startswith(("wrapped", "copy"))]
    whole = sum(r[1] for r in kernels)
    print(f"{args.filter.upper()} {args.model}, run_filter_batch {args.runs} x {args.steps}: "
          f"{whole:.1f} ms in {len(kernels)} kernels (one call)")
    print(f"{'ms':>8} {'share':>6} {'calls':>6}  fusion / shape written")
    for name, ms, n, shape in kernels[:args.top]:
        print(f"{ms:8.1f} {100 * ms / whole:5.1f}% {n:6d}  {name}  {shape}")
    print(f"optimised HLO: {dump}")


if __name__ == "__main__":
    main()

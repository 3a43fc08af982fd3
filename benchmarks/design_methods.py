"""Wall time of each sampling-design method on Ho's 50-sample problem (issue: sampling-period design).

The Sec. III-E plant (1/s², σ = 100 ft, 1 g or 10 g), J = P_T(1,1). Each method is timed after a
first (compiling) call, best of ``--repeats``; it runs on ONE CPU core (XLA's thread pool is
limited to one thread below; pin the process too, e.g. ``taskset -c 0``, for a clean number):

- Newton for the uniform τ with J = 1000 ft² (III-A, 50 samples),
- Ho's rule (segment sensitivities of the 50-sample scheme, remove 10),
- the gradient design of 40 samples in five segments (optax, 300 Adam steps), alone and with
  rounding and the 1-exchange local search,
- the per-step design of 50 periods (optax, 400 steps),
- the exhaustive integer search (62,871 schemes), the yardstick.

It prints seconds, J, and the Adam step at which the gradient design first came within 0.1% of
its final value (its convergence).

    taskset -c 0 python benchmarks/design_methods.py [--g 1 10] [--repeats 3] [--json]
"""

from __future__ import annotations

import os

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from jaxtrack import design  # noqa: E402
from jaxtrack.applications import ho_sensitivity as ho  # noqa: E402


def _time(fn, repeats):
    out = fn()  # compile
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def bench(g: float, repeats: int) -> dict:
    problem = ho.segment_problem(g)
    res = {"g": g}
    t, r = _time(lambda: ho.newton_example(), repeats) if g == 1.0 else (np.nan, None)
    if r is not None:
        res["newton"] = {"seconds": t, "tau": float(r.taus[-1]), "iterations": len(r.taus) - 1}
    t, counts = _time(lambda: design.ho_reduction(problem, ho.UNIFORM, 10), repeats)
    res["ho_rule"] = {"seconds": t, "counts": counts, "J": problem.cost(counts)}
    t, rel = _time(lambda: design.relaxed_segment_design(problem, 40, hi=20), repeats)
    conv = int(np.argmax(np.abs(rel.history - rel.cost) <= 1e-3 * rel.cost))
    res["gradient_relaxed"] = {"seconds": t, "J": rel.cost, "steps_to_0.1pct": conv, "steps": len(rel.history)}

    def full():
        r = design.relaxed_segment_design(problem, 40, hi=20)
        return design.local_search(problem, design.round_counts(r.counts, 40, 1, 20), hi=20)

    t, (counts, J) = _time(full, repeats)
    res["gradient_rounded_local_search"] = {"seconds": t, "counts": counts, "J": J}
    t, ps = _time(lambda: ho.per_step_example(g), repeats)
    res["per_step"] = {"seconds": t, "J": ps.cost}
    t, (counts, J, n) = _time(lambda: design.exhaustive_counts(problem, 40, hi=20), 1)
    res["exhaustive"] = {"seconds": t, "counts": counts, "J": J, "schemes": n}
    return res


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--g", type=float, nargs="+", default=[1.0, 10.0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    rows = [bench(g, args.repeats) for g in args.g]
    if args.json:
        print(json.dumps(rows, indent=2, default=str))
        return
    print(f"design methods, wall time after compilation, 1 XLA thread ({os.cpu_count()} cores on the machine)")
    for r in rows:
        print(f"\n{r['g']:g} g")
        for name, v in r.items():
            if name == "g":
                continue
            extra = ", ".join(f"{k}={v[k]}" for k in v if k != "seconds")
            print(f"  {name:<32} {v['seconds']:>8.3f} s   {extra}")
        print(f"  gradient design {'converges' if r['gradient_relaxed']['seconds'] < 1.0 else 'does NOT converge'} "
              f"in under 1 s ({r['gradient_relaxed']['seconds']:.3f} s, within 0.1% after "
              f"{r['gradient_relaxed']['steps_to_0.1pct']} of {r['gradient_relaxed']['steps']} Adam steps)")


if __name__ == "__main__":
    main()

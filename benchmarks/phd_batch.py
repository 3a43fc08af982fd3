"""GM-PHD and GM-CPHD per run: one compiled run against a vmapped batch of runs (a Monte Carlo block).

The question (a user's report: a GM-PHD Monte Carlo cost ~25× its single compiled run per run):
what does a run cost inside ``jax.jit(jax.vmap(run))``, as :func:`~jaxtrack.multitarget.tracker_monte_carlo`
runs it through ``monte_carlo_map``, compared with the same run compiled alone?

The filters (float64, CPU):

- **crossing, GM-PHD**: :func:`jaxtrack.multitarget.crossing_targets` at its defaults (4 targets
  crossing 5 km in front of a range-bearing radar, 100 scans, ``P_D`` 0.9, 10 clutter points a
  scan, 48 measurement slots) filtered by ``GMPHD(ExtendedKalmanFilter(), ...)`` with ``P_S``
  0.99, ``P_D`` 0.9, the scenario's clutter density, one birth component (weight 0.05, the
  scenario model's prior: mean at the crossing point, standard deviations 1 km and 40 m/s),
  ``capacity`` 100, ``T`` = 1e-5, ``U`` = 4, each reduction (``"vo-ma"``, ``"stonesoup"``);
- **Williams, GM-PHD / GM-CPHD**: the Williams (2015) study's filters
  (:mod:`jaxtrack.applications.williams15.scenario`: Kalman filter, ``capacity`` 100, 81 scans,
  40 measurement slots; the GM-CPHD with Table II's reduction).

Timed, for each filter, on the same ``--runs`` simulated runs (run ``i`` from ``fold_in(key 1, i)``):

- **one run**: ``jax.jit(run)`` called on each run in turn (what ``run_phd`` compiles); per run;
- **batch, side by side** (*before*): ``jax.jit(jax.vmap(run))`` over all runs with the
  reduction's ``while_loop`` s vmapped as JAX does by default (``_reduction._BATCHED =
  "side-by-side"``: what every platform ran before the commit that adds this file); per run;
- **batch, in turn** (*after*): the same with the default, ``_BATCHED = "platform"``: on CPU
  the batching rule of the merging runs the members one after another (``lax.map``), each its own
  ``while_loop`` (``_reduction._in_turn_on_cpu``); per run.

``run`` is ``_run_phd`` / ``_run_cphd`` (``run_phd`` / ``run_cphd`` without their host-side
checks): every scan's reduced mixture and estimates. Each variant is compiled once (``lower().compile()``,
after ``jax.clear_caches()`` so that no traced form is reused; compile times printed), called once
before the clock, then timed in ``--repeats`` interleaved rounds (one run, before, after, in
turn, so that load drifts hit all alike); printed: the medians of wall time
(``time.perf_counter``) and CPU time of the process (``time.process_time``, all threads) per run.
Values: the batch's outputs against the one-run outputs (largest absolute difference; the
merging alone is bit for bit in turn, ``tests/test_gm_phd.py``; the Kalman/EKF steps may round
differently batched).

``--mc`` adds where a Monte Carlo run goes: the per-run function ``tracker_monte_carlo`` vmaps
(``_one_run``: simulate, filter, score with GOSPA, ``c`` = 100 m) on the crossing GM-PHD
(vo-ma), batched over ``--runs`` runs, with ``max_estimates`` = ``capacity`` (100, the default)
and 24, and its scoring alone (``score_tracks`` on the filter's estimates): GOSPA solves one
``S × S`` assignment a scan, ``S = max(N, max_estimates)``.

Measured (``benchmarks/measured/phd_batch.txt``, 2 shared cores, CPU time per run, batch / one
run): side by side the GM-PHD cost 1.88× (crossing, vo-ma), 1.36× (crossing, stonesoup), 1.86×
(Williams) and the GM-CPHD 1.98×; in turn 1.07×, 1.07×, 1.07× and 1.52×. What the GM-CPHD keeps
is outside the reduction: its leave-one-out elementary symmetric functions (``_cphd._log_esf``, a
``scan`` whose step stacks two rows and log-sum-exps them) cost about 3× batched. And a Monte
Carlo run of the crossing GM-PHD is mostly its scoring when ``max_estimates`` is left at
``capacity``: 783 of 1010 ms with 100 estimate slots (GOSPA's assignment is cubic in them), 7.5 of
176 ms with 24.

Usage::

    PYTHONPATH=. python benchmarks/phd_batch.py          # 16 runs, 5 rounds, writes benchmarks/measured/phd_batch.txt
    PYTHONPATH=. python benchmarks/phd_batch.py --mc     # and the Monte Carlo breakdown
    PYTHONPATH=. python benchmarks/phd_batch.py --quick --out /dev/null

(``PYTHONPATH=.``: a script's folder, not the working directory, heads ``sys.path``, so without it
an installed jaxtrack elsewhere would be imported; the header prints which one ran.)
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxtrack.multitarget._reduction as reduction_module  # noqa: E402
from jaxtrack.applications.williams15.scenario import methods as williams_methods  # noqa: E402
from jaxtrack.applications.williams15.scenario import scenario as williams_scenario  # noqa: E402
from jaxtrack.filters import ExtendedKalmanFilter  # noqa: E402
from jaxtrack.multitarget import (  # noqa: E402
    GMPHD, GaussianMixture, StoneSoupReduction, VoMaReduction, crossing_targets, simulate_scenarios)
from jaxtrack.multitarget._cphd import _run_cphd  # noqa: E402
from jaxtrack.multitarget._evaluation import _one_run, _positions, score_tracks  # noqa: E402
from jaxtrack.multitarget._phd import _run_phd  # noqa: E402

CROSSING_CAPACITY = 100
CROSSING_BIRTH_WEIGHT = 0.05
CUTOFF = 100.0  # m, GOSPA's c on the crossing scenario (the crossing-targets study's)


def _where(path: str) -> str:
    """Which jaxtrack ran: the checkout's own (relative), or another installation, without a
    machine path in the measured file."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    path = os.path.abspath(path)
    return os.path.relpath(path, root) if path.startswith(root + os.sep) else "an installed jaxtrack outside the checkout"


def crossing_phd(scen, reduction="vo-ma", capacity=CROSSING_CAPACITY, max_estimates=None, cls=GMPHD, filter=None,
                 **options):
    """The crossing scenario's GM-PHD (module docstring); ``cls`` a :class:`GMPHD` subclass,
    ``reduction`` ``"vo-ma"``/``"stonesoup"`` or a strategy object."""
    model = scen.model
    if isinstance(reduction, str):
        reduction = (StoneSoupReduction if reduction == "stonesoup" else VoMaReduction)(1e-5, 4.0)
    return cls(filter or ExtendedKalmanFilter(), model, prob_survival=0.99, prob_detect=0.9,
               clutter_density=scen.clutter_density,
               birth=GaussianMixture([CROSSING_BIRTH_WEIGHT], [model.initial_mean], [model.initial_cov]),
               capacity=capacity, reduction=reduction, max_estimates=max_estimates, **options)


class Out:
    """Print to stdout and to a file."""

    def __init__(self, path):
        self.f = open(path, "w") if path else None

    def __call__(self, *parts):
        line = " ".join(str(p) for p in parts)
        print(line, flush=True)
        if self.f:
            self.f.write(line + "\n")
            self.f.flush()


def _clock(fn):
    c0, t0 = time.process_time(), time.perf_counter()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def _compile(fn, *args, form="platform"):
    reduction_module._BATCHED = form
    jax.clear_caches()
    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    reduction_module._BATCHED = "platform"
    return compiled, time.perf_counter() - t0


def _max_diff(batched, singles):
    worst = 0.0
    for i, one in enumerate(singles):
        for a, b in zip(jax.tree.leaves(batched), jax.tree.leaves(one)):
            a, b = np.asarray(a[i]), np.asarray(b)
            if a.dtype.kind == "f":
                worst = max(worst, float(np.max(np.abs(a - b), initial=0.0)))
            elif not np.array_equal(a, b):
                return float("inf")
    return worst


def bench_filter(name, f, runner, z, v, repeats, out):
    R = z.shape[0]
    run = lambda z, v: runner(f, z, v)  # noqa: E731
    one, c_one = _compile(run, z[0], v[0])
    before, c_before = _compile(jax.vmap(run), z, v, form="side-by-side")
    after, c_after = _compile(jax.vmap(run), z, v)
    singles = [jax.block_until_ready(one(z[i], v[i])) for i in range(R)]
    d_before, d_after = _max_diff(before(z, v), singles), _max_diff(after(z, v), singles)
    jax.block_until_ready((before(z, v), after(z, v)))
    times = {"one": [], "before": [], "after": []}
    for _ in range(repeats):
        times["one"].append(_clock(lambda: [jax.block_until_ready(one(z[i], v[i])) for i in range(R)]))
        times["before"].append(_clock(lambda: jax.block_until_ready(before(z, v))))
        times["after"].append(_clock(lambda: jax.block_until_ready(after(z, v))))
    med = {k: np.median(np.asarray(t), axis=0) / R for k, t in times.items()}  # (wall, cpu) per run
    out(f"  {name:<34}{'one run':<22}{med['one'][0] * 1e3:10.1f}{med['one'][1] * 1e3:10.1f}{'':>16}"
        f"  compile {c_one:.1f} s")
    for k, label, d, c in (("before", "batch, side by side", d_before, c_before),
                           ("after", "batch, in turn", d_after, c_after)):
        ratio = med[k] / med["one"]
        out(f"  {'':<34}{label:<22}{med[k][0] * 1e3:10.1f}{med[k][1] * 1e3:10.1f}{ratio[0]:7.2f}×{ratio[1]:7.2f}×"
            f"  compile {c:.1f} s, max |batch − one| {d:.1e}")
    return {k: v.tolist() for k, v in med.items()} | {"diff_before": d_before, "diff_after": d_after}


def bench_mc(scen, R, repeats, out):
    """The per-run function of ``tracker_monte_carlo`` batched, by ``max_estimates``, and its scoring alone."""
    idx = np.asarray(_positions(scen.model.state_layout, "model"))
    keys = jax.vmap(lambda i: jax.random.fold_in(jax.random.key(0), i))(jnp.arange(R))
    out(f"\n  tracker_monte_carlo's per-run function (simulate, filter, score; GOSPA c = {CUTOFF:g} m), crossing "
        f"GM-PHD vo-ma, vmap batch of {R}, per run:")
    out(f"  {'max_estimates':<16}{'what':<26}{'wall ms':>10}{'CPU ms':>10}")
    for E in (CROSSING_CAPACITY, 24):
        f = crossing_phd(scen, max_estimates=E)
        args = (f, scen, idx, idx, CUTOFF, 2.0)
        whole = jax.jit(jax.vmap(lambda k: _one_run(k, args)["gospa"])).lower(keys).compile()
        traj = simulate_scenarios(scen, 0, R)
        est = jax.jit(jax.vmap(lambda z, v: _run_phd(f, z, v)))(traj.scans.measurements, traj.scans.valid)

        def score(states, alive, e, mask):
            ids = jnp.broadcast_to(jnp.arange(mask.shape[-1], dtype=jnp.int32), mask.shape)
            return score_tracks(states[..., idx], alive, e[..., idx], mask, ids, cutoff=CUTOFF)[0].distance

        sargs = (traj.states, traj.alive, est.estimates, est.estimate_mask)
        scoring = jax.jit(jax.vmap(score)).lower(*sargs).compile()
        jax.block_until_ready((whole(keys), scoring(*sargs)))
        t = {"whole": [], "score": []}
        for _ in range(repeats):
            t["whole"].append(_clock(lambda: jax.block_until_ready(whole(keys))))
            t["score"].append(_clock(lambda: jax.block_until_ready(scoring(*sargs))))
        for k, label in (("whole", "simulate + filter + score"), ("score", "score alone")):
            w, c = np.median(np.asarray(t[k]), axis=0) / R
            out(f"  {E:<16}{label:<26}{w * 1e3:10.1f}{c * 1e3:10.1f}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=16, help="runs in the batch (default 16)")
    ap.add_argument("--repeats", type=int, default=5, help="interleaved timed rounds (default 5; medians)")
    ap.add_argument("--mc", action="store_true", help="also the Monte Carlo breakdown (scoring by max_estimates)")
    ap.add_argument("--quick", action="store_true", help="4 runs, 2 rounds, the crossing GM-PHD (vo-ma) only")
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "measured", "phd_batch.txt"),
                    help="also write the output here (default benchmarks/measured/phd_batch.txt)")
    a = ap.parse_args(argv)
    if a.quick:
        a.runs, a.repeats = 4, 2
    if not hasattr(reduction_module, "_in_turn_on_cpu"):
        sys.exit(f"{reduction_module.__file__} has no batched form to compare: run with PYTHONPATH=. from a checkout "
                 "that has it")
    out = Out(a.out)
    out(f"# {time.strftime('%Y-%m-%d')} python {' '.join(sys.argv)}")
    out(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}, "
        f"backend {jax.default_backend()}, float64; load average before {os.getloadavg()[0]:.2f}")
    out(f"# jaxtrack from {_where(reduction_module.__file__)}")
    out(f"# medians of {a.repeats} interleaved rounds; per run over a batch of {a.runs} runs; "
        "ratios: batch per run / one run (wall, CPU)")
    out(f"\n  {'filter':<34}{'how':<22}{'wall ms':>10}{'CPU ms':>10}{'ratio wall, CPU':>16}")
    cross = crossing_targets()
    traj = simulate_scenarios(cross, 1, a.runs)
    zc, vc = traj.scans.measurements, traj.scans.valid
    rows = {}
    todo = [("crossing GM-PHD vo-ma", crossing_phd(cross, "vo-ma"), _run_phd, zc, vc)]
    if not a.quick:
        wscen, wset = williams_scenario()
        wm = williams_methods(wscen, wset)
        wt = simulate_scenarios(wscen, 1, a.runs)
        zw, vw = wt.scans.measurements, wt.scans.valid
        todo += [("crossing GM-PHD stonesoup", crossing_phd(cross, "stonesoup"), _run_phd, zc, vc),
                 ("Williams GM-PHD vo-ma", wm["phd"], _run_phd, zw, vw),
                 ("Williams GM-CPHD", wm["cphd"], _run_cphd, zw, vw)]
    for name, f, runner, z, v in todo:
        rows[name] = bench_filter(name, f, runner, z, v, a.repeats, out)
    if a.mc:
        bench_mc(cross, a.runs, a.repeats, out)
    out(f"\n# load average after {os.getloadavg()[0]:.2f}")
    return rows


if __name__ == "__main__":
    main()

"""δ-GLMB and LMB on Vo & Vo's linear benchmark: one run, and a vmapped batch of runs.

The scenario is :func:`jaxtrack.multitarget.vo_vo_linear` (100 scans, 12 noise-free tracks, at
most 10 at once, ``P_D = 0.98``, ``Poisson(66)`` clutter over ``[−1000, 1000]²`` m, LMB birth of
four labels with ``r_B = 0.03``), run ``i`` drawn from ``jax.random.fold_in(key, i)``. The filters:
``GLMB`` and ``LMB`` with a Kalman filter, the settings of :class:`VoVoLinearSettings`, a
Mahalanobis gate of ``--gate`` (default 4), ``--tracks`` slots, ``--hypotheses`` ranked
hypotheses, ``--columns`` gated measurement columns and the LMB's ``--existence-threshold``
(default 1e-5, the library's); the hypotheses come from ``--ranking murty`` (``MurtyRanking()``,
the default) or ``--ranking gibbs`` (``GibbsSampling(--chains, --sweeps, seed=--gibbs-seed)``:
``H·chains`` chains of ``sweeps`` samples shared over the prior hypotheses by ``√w``, plus each
one's best).

Timed (after a warm-up call; compilation reported separately; best of ``--repeats``):

- one run: ``jax.jit`` of the scan (:func:`~jaxtrack.multitarget._base.scan_method`) on run 0;
- a batch: ``jax.jit(jax.vmap(...))`` over ``--runs`` runs (default 8); per run = wall / runs.

Also printed: the mean OSPA (``c = 100`` m, ``p = 1``, the toolbox's) and GOSPA (``c = 100`` m,
``p = 1``, ``α = 2``) over scans and runs, the mean absolute cardinality error, and the capacity
events and scans not ``ok`` (both must be 0).

Measured (2026-12-07, this repository's shared 2-core CPU machine, 8 runs, gate 4, ``A = 24``):

| filter | ``H``, ``N`` | one run | batch of 8, per run | mean OSPA | mean GOSPA | mean abs. cardinality error |
|---|---|---|---|---|---|---|
| GLMB | 32, 16 | 5.3 s | 9.4 s | 18.5 m | 105.1 m | 0.77 |
| LMB | 32, 16 | 2.9 s | 6.7 s | 13.4 m | 82.9 m | 0.24 (18 capacity events: ``N`` too small) |
| GLMB | 64, 24 | 30.7 s | 37.7 s | 17.8 m | 102.1 m | 0.69 |
| LMB | 64, 24 | 19.6 s | 34.9 s | 13.3 m | 82.6 m | 0.24 |

Gibbs sampling as the δ-GLMB's hypothesis generation (``--ranking gibbs``; measured 2026-12-07
13:02-13:44 UTC on the same shared 2-core CPU machine, jax 0.10.2, 8 runs, gate 4, ``A = 24``,
``N = 16``; another session's benchmark held one core at about 13:02-13:12, so the first Gibbs rows
are pessimistic; the Murty row was rerun in the same window, and OSPA, GOSPA and the cardinality
error are deterministic, equal in both runs):

| filter, ranking | ``H`` | chains × sweeps | one run | batch of 8, per run | mean OSPA | mean GOSPA | mean abs. cardinality error |
|---|---|---|---|---|---|---|---|
| GLMB, Murty | 32 | – | 4.0 s (4.1 s rerun) | 6.6 s (5.5 s rerun) | 18.50 m | 105.11 m | 0.766 |
| LMB, Murty | 32 | – | 3.1 s | 6.6 s | 13.37 m | 82.91 m | 0.244 (18 capacity events) |
| GLMB, Gibbs | 128 | 2 × 8 | 3.5 s (3.1 s rerun) | 4.1 s (3.4 s rerun) | 14.75 m | 88.50 m | 0.381 |
| GLMB, Gibbs | 256 | 2 × 8 | 8.0 s | 8.8 s | 14.53 m | 87.58 m | 0.360 |
| GLMB, Gibbs | 256 | 4 × 8 | 10.0 s | 11.3 s | 14.42 m | 87.95 m | 0.367 |
| GLMB, Gibbs | 512 | 2 × 8 | 16.8 s | 15.0 s | 13.34 m | 82.54 m | 0.253 (10 capacity events) |
| GLMB, Gibbs | 512 | 1 × 4 | 10.7 s | 10.4 s | 13.99 m | 84.84 m | 0.302 (14 capacity events) |
| LMB, Murty (rerun 13:41) | 32 | – | 2.9 s | 5.0 s | 13.37 m | 82.91 m | 0.244 (18 capacity events) |
| LMB, Gibbs | 128 | 2 × 8 | 0.12 s | 0.08 s | 16.63 m | 94.70 m | 0.515 |
| LMB, Gibbs | 128 | 16 × 16 | 0.55 s | 0.31 s | 13.88 m | 85.53 m | 0.297 |
| LMB, Gibbs | 256 | 32 × 16 | 1.0 s | 0.54 s | 13.32 m | 82.95 m | 0.250 (1 capacity event) |
| LMB, Gibbs | 512 | 64 × 16 | 1.2 s | 1.4 s | 13.23 m | 82.51 m | 0.234 (3 capacity events) |

Since 2026-12-07 21:00 the chains are one budget of ``H·chains`` shared over the prior hypotheses by
``√w`` (not ``chains`` per slot), so the Gibbs rows above are of the earlier sampler. Rerun on the
same 8 runs at 23:45 (benchmarks/measured/glmb_gibbs.txt, end; the sampler then drew each candidate
over its ``A + 2`` possible columns, ``private_columns=2``):

| filter, ranking | ``H`` | chains × sweeps | one run | batch of 8, per run | mean OSPA | mean GOSPA | mean abs. cardinality error |
|---|---|---|---|---|---|---|---|
| GLMB, Gibbs | 128 | 2 × 8 | 1.59 s | 2.07 s | 16.32 m | 95.98 m | 0.549 |
| GLMB, Gibbs | 256 | 1 × 8 | 2.70 s | 3.23 s | 14.25 m | 87.27 m | 0.346 |
| GLMB, Gibbs | 512 | 1 × 4 | 5.73 s | 5.51 s | 12.79 m | 80.76 m | 0.215 (1 capacity event) |
| LMB, Gibbs, 1 component | 256 | 64 × 16 | 0.48 s | 0.60 s | 13.23 m | 82.51 m | 0.234 (3 capacity events) |
| LMB, Gibbs, 10 components | 256 | 64 × 16 | 0.58 s | 0.72 s | 12.80 m | 80.34 m | 0.205 (6 capacity events) |

(The LMB's capacity events are lingering birth labels at the library's existence threshold 1e-5;
the study prunes at 1e-3 and has none.) GLMB 128, 2 × 8 is worse than the per-slot sampler on these
8 runs (16.32 against 14.75 m) and better on the study's 100 runs against the labeledRFS port (OSPA
14.78 against 16.23 m, benchmarks/measured/labelled_reference.txt).

Gibbs at ``H = 128`` is faster than Murty at ``H = 32`` (no ``P³`` subproblems, a batch no longer
waits for the slowest run's ``while_loop``) and closes most of the gap to the LMB (OSPA 18.5 →
14.8 m, cardinality error 0.77 → 0.38). Only ``H = 512`` matches the LMB (13.3 m), at 4× Murty's
time: there most of a scan is no longer the ranking but what grows with ``H`` around it (one
scan at ``H = 512``: 0.19 s, of which sampling 2 × 8 ≈ 0.09 s, likelihoods of all ``H·P``
candidates on all ``M`` slots, Hungarian starts and updates ≈ 0.07 s, the projection's
``O(H²)`` merge of equal hypotheses ≈ 0.04 s). More samples per hypothesis (4 × 8 instead of
2 × 8 at ``H = 256``) buy almost nothing; more hypotheses do.

The LMB has ONE prior hypothesis, so its samples per scan are ``1 + chains·sweeps`` in all: with
2 × 8 it sees at most 17 hypotheses and loses accuracy (16.6 m); with ``chains·sweeps ≥ H`` it
matches Murty's LMB at a fraction of its time (``H = 256``, 32 × 16: 13.3 m in 1.0 s against
13.4 m in 2.9 s; the rest of its scan is small, one row of ``N`` slots).

A vmapped batch costs more per run than one run here: the runs' Murty loops (``while_loop``) step
side by side until the longest is done, on two cores. Murty's cost grows as ``H·P³·(A + 2P)``
with ``P = N + B`` candidate rows (empty slots included), hence the jump from ``N = 16`` to 24.
The δ-GLMB's larger error comes from its truncation: a target missed in its first scans survives
only in low-weight hypotheses, which a small ``H`` drops, and the birth (position σ = 10 m) cannot
start it again once it has moved away; the LMB keeps such labels with a small ``r``.

Usage::

    python benchmarks/glmb.py [--runs 8] [--hypotheses 32] [--tracks 16] [--columns 24] [--gate 4]
        [--ranking murty|gibbs] [--chains 4] [--sweeps 8] [--gibbs-seed 0] [--components 1] [--filters GLMB LMB]
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxtrack.multitarget as mt
from jaxtrack.filters import KalmanFilter
from jaxtrack.montecarlo import gospa, ospa
from jaxtrack.multitarget._base import _record_estimates, scan_method


def _filters(scen, st, args):
    ranking = (mt.MurtyRanking() if args.ranking == "murty"
               else mt.GibbsSampling(args.chains, args.sweeps, seed=args.gibbs_seed))
    kw = {"prob_survival": st.prob_survival, "prob_detect": st.prob_detect, "clutter_density": st.clutter_density,
          "birth": st.birth, "max_tracks": args.tracks, "max_hypotheses": args.hypotheses, "gate": args.gate,
          "assignment_measurements": args.columns, "existence_threshold": args.existence_threshold,
          "ranking": ranking}
    out = {}
    if "GLMB" in args.filters:
        out["GLMB"] = mt.GLMB(KalmanFilter(), scen.model, **kw)
    if "LMB" in args.filters:
        out["LMB"] = mt.LMB(KalmanFilter(), scen.model, max_components=args.components, **kw)
    return out


def _best(fn, repeats):
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t)
    return best


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=int, default=8)
    p.add_argument("--hypotheses", type=int, default=32)
    p.add_argument("--tracks", type=int, default=16)
    p.add_argument("--columns", type=int, default=24)
    p.add_argument("--gate", type=float, default=4.0)
    p.add_argument("--existence-threshold", type=float, default=1e-5)
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--ranking", choices=("murty", "gibbs"), default="murty")
    p.add_argument("--chains", type=int, default=4, help="Gibbs: chains per prior hypothesis slot (H·chains in all, shared by sqrt(w))")
    p.add_argument("--sweeps", type=int, default=8, help="Gibbs: sweeps per chain (each a sample)")
    p.add_argument("--gibbs-seed", type=int, default=0)
    p.add_argument("--components", type=int, default=1, help="LMB: Gaussian components a label (1: moment matched)")
    p.add_argument("--filters", nargs="+", choices=("GLMB", "LMB"), default=["GLMB", "LMB"])
    args = p.parse_args()
    scen, st = mt.vo_vo_linear(0)
    trajs = mt.simulate_scenarios(scen, args.seed, args.runs)
    z, v = trajs.scans.measurements, trajs.scans.valid
    truth, alive = trajs.states[..., :2], trajs.alive
    print(f"vo_vo_linear: {scen.num_steps} scans, {args.runs} runs, M = {scen.max_measurements} slots; "
          f"H = {args.hypotheses}, N = {args.tracks}, A = {args.columns}, gate {args.gate}; ranking {args.ranking}"
          + (f" ({args.chains} chains x {args.sweeps} sweeps per prior hypothesis slot)" if args.ranking == "gibbs" else "")
          + (f"; LMB {args.components} components a label" if "LMB" in args.filters else "")
          + f"; device {jax.devices()[0]}")
    for name, f in _filters(scen, st, args).items():
        one = jax.jit(lambda zz, vv, f=f: scan_method(f, zz, vv, _record_estimates)[1])
        batch = jax.jit(jax.vmap(lambda zz, vv, f=f: scan_method(f, zz, vv, _record_estimates)[1]))
        t = time.perf_counter()
        one.lower(z[0], v[0]).compile()
        c1 = time.perf_counter() - t
        t = time.perf_counter()
        batch.lower(z, v).compile()
        c8 = time.perf_counter() - t
        jax.block_until_ready(one(z[0], v[0]))
        out = jax.block_until_ready(batch(z, v))
        t1 = _best(lambda one=one: one(z[0], v[0]), args.repeats)
        t8 = _best(lambda batch=batch: batch(z, v), args.repeats)
        est, ok, events = out
        pos = est.states[..., :2]
        def one_ospa(a, b, c, d):
            return ospa(a, b, c, d, cutoff=st.ospa_cutoff, order=st.ospa_order).distance

        o = jax.vmap(jax.vmap(one_ospa))(truth, alive, pos, est.mask)
        g = jax.vmap(jax.vmap(lambda a, b, c, d: gospa(a, b, c, d, cutoff=100.0, order=1.0).distance))(
            truth, alive, pos, est.mask)
        card = np.abs(np.asarray(est.mask.sum(-1)) - np.asarray(alive.sum(-1)))
        print(f"{name:5s} compile one {c1:6.1f} s, batch {c8:6.1f} s | one run {t1:7.3f} s | batch of {args.runs}: "
              f"{t8:7.3f} s = {t8 / args.runs:7.3f} s per run | mean OSPA {float(jnp.mean(o)):6.2f} m, "
              f"GOSPA {float(jnp.mean(g)):6.2f} m, |card err| {card.mean():.3f}, capacity events "
              f"{int(events[:, -1].sum())}, scans not ok {int((~ok).sum())}")


if __name__ == "__main__":
    main()

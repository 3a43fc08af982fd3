"""δ-GLMB and LMB on Vo & Vo's linear benchmark: one run, and a vmapped batch of runs.

The scenario is :func:`jaxtrack.multitarget.vo_vo_linear` (100 scans, 12 noise-free tracks, at
most 10 at once, ``P_D = 0.98``, ``Poisson(66)`` clutter over ``[−1000, 1000]²`` m, LMB birth of
four labels with ``r_B = 0.03``), run ``i`` drawn from ``jax.random.fold_in(key, i)``. The filters:
``GLMB`` and ``LMB`` with a Kalman filter, the settings of :class:`VoVoLinearSettings`, a
Mahalanobis gate of ``--gate`` (default 4), ``--tracks`` slots, ``--hypotheses`` ranked
hypotheses, ``--columns`` gated measurement columns and the LMB's ``--existence-threshold``
(default 1e-5, the library's).

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

A vmapped batch costs more per run than one run here: the runs' Murty loops (``while_loop``) step
side by side until the longest is done, on two cores. Murty's cost grows as ``H·P³·(A + 2P)``
with ``P = N + B`` candidate rows (empty slots included), hence the jump from ``N = 16`` to 24.
The δ-GLMB's larger error comes from its truncation: a target missed in its first scans survives
only in low-weight hypotheses, which a small ``H`` drops, and the birth (position σ = 10 m) cannot
start it again once it has moved away; the LMB keeps such labels with a small ``r``.

Usage::

    python benchmarks/glmb.py [--runs 8] [--hypotheses 32] [--tracks 16] [--columns 24] [--gate 4]
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
    kw = {"prob_survival": st.prob_survival, "prob_detect": st.prob_detect, "clutter_density": st.clutter_density,
          "birth": st.birth, "max_tracks": args.tracks, "max_hypotheses": args.hypotheses, "gate": args.gate,
          "assignment_measurements": args.columns, "existence_threshold": args.existence_threshold}
    return {"GLMB": mt.GLMB(KalmanFilter(), scen.model, **kw), "LMB": mt.LMB(KalmanFilter(), scen.model, **kw)}


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
    args = p.parse_args()
    scen, st = mt.vo_vo_linear(0)
    trajs = mt.simulate_scenarios(scen, args.seed, args.runs)
    z, v = trajs.scans.measurements, trajs.scans.valid
    truth, alive = trajs.states[..., :2], trajs.alive
    print(f"vo_vo_linear: {scen.num_steps} scans, {args.runs} runs, M = {scen.max_measurements} slots; "
          f"H = {args.hypotheses}, N = {args.tracks}, A = {args.columns}, gate {args.gate}; device {jax.devices()[0]}")
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

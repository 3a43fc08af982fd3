"""Exact JPDA marginals per scan: jaxtrack's ``JPDA()`` against pyehm's EHM2 (C++).

The scans are built the way a tracker builds them (seeded NumPy): ``T`` predicted measurements
uniform in a square region, each with its own innovation covariance ``S_t`` (eigenvalues in
[2, 8]); each target detected with ``P_D = 0.9`` (the detection drawn from ``N(ẑ_t, S_t)``),
uniform clutter filling the scan up to ``M`` measurements (density ``λ`` = clutter count / area);
a χ² gate at ``P_G = 0.99``; ``L[t, 0] = log(1 − P_D P_G)``, ``L[t, j] = log(P_D N(z_j; ẑ_t,
S_t) / λ)`` inside the gate, ``−inf`` outside. The region's size sets the sparsity: each track
gates about two measurements in the sparse cases (``5×20``, ``8×80``); the dense case gates every
pair (no gate), which pyehm's EHM2 pays for exponentially.

Timed, interleaved, medians over ``--repeats`` rounds (each round cycles over the same scans):

- **jaxtrack single**: ``jax.jit(JPDA())`` on one scan (a device array made before the clock),
  ``block_until_ready`` on the result: the wall time of the call, dispatch included;
- **jaxtrack batched**: ``jax.jit(jax.vmap(JPDA()))`` on ``--batch`` scans in one call, per scan;
- **pyehm EHM2**: ``EHM2().run(validation, likelihood)`` per scan, with its int32 validation
  matrix and float64 likelihood matrix (``exp L``, 0 outside the gate) built before the clock;
- **dispatch floors**: a jitted function with the same five outputs that does almost nothing,
  once under XLA's 1000-flop line (run inline on the caller's thread) and once above it (handed
  to a worker thread, as every real JPDA call is): what any jitted call of this shape costs here.

Before timing, every scan's jaxtrack marginals are checked against EHM2's (≤ 1e-10) and the
single and batched calls against each other.

On a machine whose other cores are busy, a jitted call's hand-offs between threads (the call
runs on XLA's worker thread, and the thunks of one program on its pool) wait for those cores;
``--cpu N`` pins the whole process (jaxtrack's threads and pyehm alike) to core ``N`` before
JAX starts its threads, which measures the work without that wait. Usage::

    python benchmarks/jpda_vs_pyehm.py [--batch 256 --repeats 7 --cpu 1 --out benchmarks/measured/jpda_vs_pyehm.txt]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from scipy.stats import chi2  # noqa: E402

from jaxtrack.association import JPDA, Association  # noqa: E402

PROB_DETECT, PROB_GATE = 0.9, 0.99

# (name, tracks, measurements, region side, gate every pair)
CASES = [
    ("5x20 sparse", 5, 20, 40.0, False),
    ("8x80 sparse", 8, 80, 80.0, False),
    ("5x20 dense (no gate)", 5, 20, 40.0, True),
]


def make_scan(rng, T, M, side, dense=False):
    """One scan's ``L`` ``(T, 1 + M)`` as a tracker makes it (see the module docstring)."""
    centres = rng.uniform(0.0, side, (T, 2))
    S = np.empty((T, 2, 2))
    for t in range(T):
        a, b = rng.uniform(2.0, 8.0, 2)
        r = rng.uniform(-0.5, 0.5) * np.sqrt(a * b)
        S[t] = [[a, r], [r, b]]
    detected = rng.random(T) < PROB_DETECT
    dets = [centres[t] + np.linalg.cholesky(S[t]) @ rng.normal(size=2) for t in range(T) if detected[t]][:M]
    n_clutter = M - len(dets)
    z = np.array(dets + list(rng.uniform(0.0, side, (n_clutter, 2)))).reshape(M, 2)[rng.permutation(M)]
    density = max(n_clutter, 1) / side**2
    L = np.full((T, 1 + M), -np.inf)
    L[:, 0] = np.log1p(-PROB_DETECT * PROB_GATE)
    threshold = chi2.ppf(PROB_GATE, 2)
    for t in range(T):
        nu = z - centres[t]
        d2 = np.einsum("mi,ij,mj->m", nu, np.linalg.inv(S[t]), nu)
        loglik = -0.5 * (d2 + np.log(np.linalg.det(2 * np.pi * S[t])))
        inside = np.ones(M, bool) if dense else d2 <= threshold
        L[t, 1:][inside] = np.log(PROB_DETECT) + loglik[inside] - np.log(density)
    return L


def _floors():
    """Jitted functions with ``JPDA``'s six outputs that do (almost) nothing: under and over
    the 1000 flops below which XLA's CPU client runs a call inline."""

    def cheap(L):
        return Association(L * 2.0, L[0, 1:], L[0, 0], L[-1, 0], L[0, 0] > 0, L[0, 0] < 0)

    def over(L):
        x = L
        for _ in range(1000 // L.size + 2):
            x = x * 0.999 + 0.5  # fused into one loop: about as cheap, counted as > 1000 flops
        return Association(x, L[0, 1:], L[0, 0], L[-1, 0], L[0, 0] > 0, L[0, 0] < 0)

    return jax.jit(cheap), jax.jit(over)


def _loop(fn, items):
    """Seconds per item of ``fn`` over ``items`` (each result blocked on)."""
    t0 = time.perf_counter()
    for x in items:
        jax.block_until_ready(fn(x))
    return (time.perf_counter() - t0) / len(items)


def run_case(name, T, M, side, dense, *, batch, repeats, seed):
    rng = np.random.default_rng(seed)
    Ls = np.stack([make_scan(rng, T, M, side, dense) for _ in range(batch)])
    gated = np.isfinite(Ls[:, :, 1:])
    shared = (gated.sum(axis=1) >= 2).sum(axis=1)
    single = jax.jit(JPDA())
    batched = jax.jit(jax.vmap(JPDA()))
    cheap, over = _floors()
    scans = [jax.device_put(L) for L in Ls]
    stack = jax.device_put(Ls)
    from pyehm.core import EHM2

    ehm = EHM2()
    ehm_in = [(np.isfinite(L).astype(np.int32), np.where(np.isfinite(L), np.exp(L), 0.0)) for L in Ls]

    # Checks (and warm-up): every scan against EHM2, single against batched.
    got = jax.block_until_ready(batched(stack))
    assert bool(np.all(got.ok)), name
    one = single(scans[0])
    assert np.abs(np.asarray(one.association_probabilities) - np.asarray(got.association_probabilities[0])).max() <= 1e-12
    t0 = time.perf_counter()
    expect = ehm.run(*ehm_in[0])
    per_ehm = time.perf_counter() - t0
    # EHM2 on the dense case costs ~0.2 s per scan: compare and time it on a few scans only.
    n_ehm = batch if per_ehm < 2e-3 else max(2, int(0.3 / max(per_ehm, 1e-9)))
    worst = 0.0
    for i in range(n_ehm):
        expect = ehm.run(*ehm_in[i])
        worst = max(worst, np.abs(np.asarray(got.association_probabilities[i]) - expect).max())
    assert worst <= 1e-10, (name, worst)
    for f in (cheap, over):
        jax.block_until_ready(f(scans[0]))

    timings = {k: [] for k in ("single", "batched", "ehm2", "floor inline", "floor worker")}
    for _ in range(repeats):
        timings["single"].append(_loop(single, scans))
        timings["batched"].append(_loop(batched, [stack]) / batch)
        timings["ehm2"].append(_loop(lambda a: ehm.run(*a), ehm_in[:n_ehm]))
        timings["floor inline"].append(_loop(cheap, scans))
        timings["floor worker"].append(_loop(over, scans))
    med = {k: float(np.median(v)) * 1e6 for k, v in timings.items()}
    return dict(name=name, worst=worst, n_ehm=n_ehm, shared_mean=shared.mean(), shared_max=shared.max(),
                gated_per_track=gated.sum(axis=2).mean(), **med)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, default=256, help="scans per case (and per vmapped call)")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None, help="also append the table to this file")
    ap.add_argument("--cpu", type=int, default=None, help="pin the process to this core")
    ap.add_argument("--sync-dispatch", action="store_true",
                    help="run every jitted call on the caller's thread (jax_cpu_enable_async_dispatch=False)")
    a = ap.parse_args(argv)
    if a.sync_dispatch:
        jax.config.update("jax_cpu_enable_async_dispatch", False)
    if a.cpu is not None:
        os.sched_setaffinity(0, {a.cpu})  # before JAX's first computation starts its threads
    load = os.getloadavg()[0]
    import jaxtrack

    # Which checkout's jaxtrack ran, relative to this script's repository (no machine paths in
    # the measured files).
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    where = os.path.relpath(os.path.dirname(os.path.dirname(os.path.abspath(jaxtrack.__file__))), root)
    where = "this checkout" if where == "." else where
    rows = [run_case(*case, batch=a.batch, repeats=a.repeats, seed=a.seed + i) for i, case in enumerate(CASES)]
    lines = [
        (f"jpda_vs_pyehm: float64, {os.cpu_count()} cores ({platform.processor() or platform.machine()}), "
         f"load {load:.1f} before the run, {a.batch} scans per case, median of {a.repeats} interleaved rounds"
         + (f", pinned to core {a.cpu}" if a.cpu is not None else ", not pinned")
         + (", synchronous dispatch (jax_cpu_enable_async_dispatch=False)" if a.sync_dispatch else "")
         + f"; jaxtrack from {where}"),
        "µs per scan; ratios = jaxtrack / EHM2 (below 1: jaxtrack faster); floors: a jitted call with JPDA's five",
        "outputs doing nothing, inline (< 1000 flops) and on XLA's worker thread (>= 1000 flops, as a real JPDA call)",
        (f"{'case':24s}{'gated/trk':>10s}{'shared':>9s}{'single':>9s}{'batched':>9s}{'EHM2':>11s}"
         f"{'single/EHM2':>13s}{'batch/EHM2':>12s}{'floor in':>10s}{'floor wk':>10s}"),
    ]
    for r in rows:
        lines.append(
            f"{r['name']:24s}{r['gated_per_track']:10.2f}{r['shared_mean']:5.1f}/{r['shared_max']:<3d}"
            f"{r['single']:9.1f}{r['batched']:9.2f}{r['ehm2']:11.1f}{r['single'] / r['ehm2']:13.3g}"
            f"{r['batched'] / r['ehm2']:12.3g}{r['floor inline']:10.1f}{r['floor worker']:10.1f}"
        )
    lines.append("every scan's marginals equal EHM2's to " + ", ".join(f"{r['worst']:.1e}" for r in rows)
                 + f" (EHM2 timed and compared on {', '.join(str(r['n_ehm']) for r in rows)} scans)")
    text = "\n".join(lines)
    print(text)
    if a.out:
        with open(a.out, "a") as f:
            f.write(text + "\n\n")
        print(f"appended to {a.out}")


if __name__ == "__main__":
    main()

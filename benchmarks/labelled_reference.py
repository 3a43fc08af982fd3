"""Issue 49: jaxtrack's δ-GLMB and LMB against an independent reference, the labeledRFS Python
port (linh-gist/labeledRFS, MIT; its ``jointglmb_gms_python``, a port of Vo & Vo's MATLAB
``jointglmb/gms``, and ``jointlmb_gms_python``), on Vo & Vo's linear benchmark.

Steps (``--stage all``, or a comma-separated list of ``export``, ``ours``, ``reference``, ``compare`` to redo a part):

1. ``export``: ``--runs`` runs (default 100) of :func:`jaxtrack.multitarget.vo_vo_linear`, run
   ``i`` simulated from ``jax.random.fold_in(jax.random.key(13), i)`` exactly as the labelled study
   (jaxtrack/applications/vo_vo) draws it; the truth, every run's measurement sets and the model's
   numbers go to ``WORKDIR/runs.npz``.
2. ``ours``: the study's two filters (:func:`jaxtrack.applications.vo_vo.methods`: δ-GLMB with
   ``GibbsSampling(2, 8)`` at ``H = 128``, LMB with ``GibbsSampling(64, 16)`` at ``H = 256``, ``N = 16``, gate 4,
   ``A = 24``) over the runs as one ``jit(vmap)`` batch (timed after an ahead-of-time compile:
   per run = wall / runs) and over one run (run 0, ``jit``, best of 2 after a warm-up call; the
   study itself runs one run a block); every scan's estimates go to ``WORKDIR/ours.npz``.
3. ``reference``: benchmarks/_labeledrfs_driver.py under the reference's interpreter
   (``--reference-python``, or the environment variable ``LABELEDRFS_PYTHON``; numpy < 2) and
   checkout (``--labeledrfs``, or ``LABELEDRFS_DIR``) on the same measurement sets;
   ``WORKDIR/reference_glmb.npz``, ``reference_lmb.npz``. It resumes: runs already in that file are skipped (``--stage
   reference`` again after an interruption).
4. ``compare``: per filter, OSPA (``c = 100`` m, ``p = 1``, the study's; jaxtrack's
   :func:`~jaxtrack.montecarlo.ospa` for both filters' estimated positions against the truth) and
   the cardinality per scan; per scan the paired difference of the run means (ours − reference;
   the same measurement sets) and its standard error over runs, the fraction of scans with
   ``|difference| ≤ 2 SE`` against its binomial expectation, the time-averaged difference with
   its SE (per-run time averages, paired), and the time per run of both and their ratio. Written
   to ``--out`` (default benchmarks/measured/labelled_reference.txt) with a figure (.png) next to
   it.

Usage::

    LABELEDRFS_PYTHON=/path/to/venv/bin/python python benchmarks/labelled_reference.py \\
        --labeledrfs /path/to/labeledRFS [--runs 100] [--workdir DIR] [--stage all]
        [--reference-runs-lmb N] [--lmb-birth fixed|adaptive]
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
FILTERS = ("glmb", "lmb")
NAMES = {"glmb": "δ-GLMB", "lmb": "LMB"}
DIFFERENCES = """
How the filters differ (same model numbers; settings of each left at its own defaults):
- δ-GLMB, reference: H_upd = 1000 Gibbs samples a scan (the port's gibbswrap_jointpredupdt_custom, first
  sample all-missed), shared over the prior hypotheses in proportion to sqrt(w); H_max = 1000 kept,
  pruned below 1e-15; gate chi2(2) with P_G = 1 - 1e-7 (NIS < 32.2, 5.7 sigma); no cap on tracks.
  jaxtrack (the study's): H = 128 hypotheses, GibbsSampling(2 chains x 8 sweeps per prior hypothesis slot, 256 chains
  shared over the prior hypotheses in proportion to sqrt(w), as the reference shares its samples),
  gate NIS < 16 (4 sigma), at most A = 24 gated measurement columns, N = 16 track slots.
  Estimator of both: the MAP cardinality, then the heaviest hypothesis of that cardinality, its tracks'
  means (the reference's per-scan value, recorded as each scan ends; its end-of-run output, whose
  recursive estimator rewrites earlier scans along the latest association histories, is shown apart).
- LMB, reference: one joint assignment of all tracks a scan, 1000 Gibbs samples; each track a Gaussian
  mixture (pruned below 1e-5, merged within 4, at most 10 components), its estimate the heaviest
  component's mean; tracks pruned at r <= 1e-3, at most 100. Birth: {lmb_birth} ("fixed": the port's
  adaptive measurement-driven birth, Reuter et al. 2014 eq. 75, replaced by the scenario's four-label
  birth, as in Vo's MATLAB jointlmb and jaxtrack). jaxtrack (the study's): the 256 best distinct of
  GibbsSampling(64 chains x 16 sweeps), 1,025 samples; each track a Gaussian mixture (pruned below 1e-5,
  merged within 4, at most 10 components: LMB_COMPONENTS; --lmb-components 1 gives one moment-matched
  Gaussian), its estimate the heaviest component's mean; r <= 1e-3 pruned, N = 16 slots, same gate and A.
- Both use P_S, P_D, lambda_c, the clutter region, F, Q, H, R and the birth of vo_vo_linear (the driver
  prints the table of the port's defaults and the values set).
"""


# --------------------------------------------------------------------------- export / ours (jaxtrack)

def _study(glmb_hypotheses: int | None = None, gate: float | None = None, gibbs: str | None = None,
           lmb_gibbs: str | None = None, lmb_hypotheses: int | None = None, lmb_components: int | None = None):
    import importlib

    study = importlib.import_module("jaxtrack.applications.vo_vo.scenario")
    montecarlo = importlib.import_module("jaxtrack.applications.vo_vo.montecarlo")
    if gate is not None:  # the study's filters with another Mahalanobis gate (read when they are built)
        study.GATE = gate
    if gibbs is not None:  # the δ-GLMB's Gibbs sampler with other chains (per prior hypothesis slot) × sweeps
        from jaxtrack.multitarget import GibbsSampling

        chains, sweeps, *alpha = gibbs.split("x")
        study.GLMB_RANKING = GibbsSampling(int(chains), int(sweeps), seed=study.GLMB_RANKING.seed,
                                           weight_exponent=float(alpha[0]) if alpha else 0.5)
    if lmb_gibbs is not None:  # the LMB's hypotheses by Gibbs sampling (one prior hypothesis: all chains its)
        from jaxtrack.multitarget import GibbsSampling

        chains, sweeps = (int(x) for x in lmb_gibbs.split("x"))
        study.LMB_RANKING = GibbsSampling(chains, sweeps, seed=0)
    if lmb_hypotheses is not None:
        study.MAX_HYPOTHESES = dict(study.MAX_HYPOTHESES, lmb=lmb_hypotheses)
    if lmb_components is not None:  # the Gaussian components each LMB label keeps
        study.LMB_COMPONENTS = lmb_components
    scen, settings = study.scenario()
    meth = study.methods(scen, settings)
    if glmb_hypotheses is not None:  # the study's δ-GLMB at another hypothesis budget
        meth["glmb"] = study.methods(scen, settings, max_hypotheses=glmb_hypotheses)["glmb"]
    return scen, settings, meth, montecarlo.EVALUATION_KEY


def export(runs: int, workdir: str) -> str:
    import jax

    scen, st, _, key_int = _study()
    key = jax.random.key(key_int)
    traj = jax.jit(jax.vmap(lambda i: scen.sample(jax.random.fold_in(key, i))))(np.arange(runs))
    m = scen.model
    region = np.asarray(scen.clutter_region, float)
    path = os.path.join(workdir, "runs.npz")
    np.savez(
        path,
        z=np.asarray(traj.scans.measurements, float), valid=np.asarray(traj.scans.valid, bool),
        overflow=np.asarray(traj.scans.overflow), truth=np.asarray(traj.states[0, ..., :2], float),
        alive=np.asarray(traj.alive[0], bool), truth_all_equal=np.all(np.asarray(traj.states) == np.asarray(traj.states[:1])),
        F=np.asarray(m.F, float), Q=np.asarray(m.Q, float), H=np.asarray(m.H, float), R=np.asarray(m.R, float),
        prob_survival=float(st.prob_survival), prob_detect=float(st.prob_detect),
        clutter_rate=float(st.clutter_rate), clutter_density=float(st.clutter_density), clutter_region=region,
        birth_weights=np.asarray(st.birth_weights, float), birth_means=np.asarray(st.birth_means, float),
        birth_covs=np.asarray(st.birth_covs, float), key=key_int,
    )
    print(f"exported {runs} runs to {path}: measurements a scan mean {np.asarray(traj.scans.valid).sum(-1).mean():.1f}, "
          f"max {np.asarray(traj.scans.valid).sum(-1).max()} of {scen.max_measurements} slots, "
          f"overflowed scans {int(np.asarray(traj.scans.overflow).sum())}", flush=True)
    return path


def ours(workdir: str, runs: int | None = None, repeats: int = 2, glmb_hypotheses: int | None = None,
         filters=FILTERS, tag: str = "", gate: float | None = None, gibbs: str | None = None,
         lmb_gibbs: str | None = None, lmb_hypotheses: int | None = None, lmb_components: int | None = None) -> str:
    import jax

    from jaxtrack.multitarget._base import _record_estimates, scan_method

    _, _, meth, _ = _study(glmb_hypotheses, gate, gibbs, lmb_gibbs, lmb_hypotheses, lmb_components)
    d = np.load(os.path.join(workdir, "runs.npz"))
    z, v = jax.numpy.asarray(d["z"][:runs]), jax.numpy.asarray(d["valid"][:runs])
    R = z.shape[0]
    rk = meth["glmb"].ranking
    lrk = meth["lmb"].ranking
    out = {"glmb_hypotheses": meth["glmb"].max_hypotheses, "gate": float(meth["glmb"].gate),
           "glmb_ranking": f"{type(rk).__name__}({getattr(rk, 'num_chains', '')}, {getattr(rk, 'num_sweeps', '')}"
                           + (f", weight_exponent={rk.weight_exponent}" if hasattr(rk, "weight_exponent") else "") + ")",
           "lmb_hypotheses": meth["lmb"].max_hypotheses, "lmb_components": meth["lmb"].projection.max_components,
           "lmb_ranking": f"{type(lrk).__name__}({getattr(lrk, 'num_chains', '')}, {getattr(lrk, 'num_sweeps', '')})"}
    for name in filters:
        f = meth[name]
        run = lambda zz, vv, f=f: scan_method(f, zz, vv, _record_estimates)[1]
        batch = jax.jit(jax.vmap(run))
        one = jax.jit(run)
        t = time.perf_counter()
        cb = batch.lower(z, v).compile()
        compile_batch = time.perf_counter() - t
        t, c = time.perf_counter(), time.process_time()
        est, ok, events = jax.block_until_ready(cb(z, v))
        wall_batch, cpu_batch = time.perf_counter() - t, time.process_time() - c
        t = time.perf_counter()
        c1 = one.lower(z[0], v[0]).compile()
        compile_one = time.perf_counter() - t
        jax.block_until_ready(c1(z[0], v[0]))
        best = best_cpu = np.inf
        for _ in range(repeats):
            t, c = time.perf_counter(), time.process_time()
            jax.block_until_ready(c1(z[0], v[0]))
            best, best_cpu = min(best, time.perf_counter() - t), min(best_cpu, time.process_time() - c)
        out[f"{name}_pos"] = np.asarray(est.states[..., :2], float)
        out[f"{name}_mask"] = np.asarray(est.mask, bool)
        out[f"{name}_ok"] = np.asarray(ok, bool)
        out[f"{name}_events"] = np.asarray(events[:, -1])
        out[f"{name}_batch_seconds"] = wall_batch
        out[f"{name}_one_seconds"] = best
        out[f"{name}_batch_cpu_seconds"] = cpu_batch
        out[f"{name}_one_cpu_seconds"] = best_cpu
        out[f"{name}_batch_finished_at"] = time.time()
        out[f"{name}_compile_batch"] = compile_batch
        out[f"{name}_compile_one"] = compile_one
        print(f"ours {name}: batch of {R}: {wall_batch:.1f} s ({wall_batch / R:.3f} s a run; CPU {cpu_batch / R:.3f} s a run; "
              f"compile {compile_batch:.1f} s); one run {best:.3f} s (CPU {best_cpu:.3f} s; best of {repeats}; compile {compile_one:.1f} s); capacity events "
              f"{int(out[f'{name}_events'].sum())}, scans not ok {int((~out[f'{name}_ok']).sum())}", flush=True)
    path = os.path.join(workdir, f"ours{tag}.npz")
    np.savez(path, **out)
    return path


# --------------------------------------------------------------------------- reference (subprocess)

def reference_command(args, name: str, runs: int) -> list[str]:
    """The driver's command for one filter (its own output file, ``WORKDIR/reference_NAME.npz``, so
    the two filters may run as two processes)."""
    return [args.reference_python, os.path.join(HERE, "_labeledrfs_driver.py"), "--labeledrfs", args.labeledrfs,
            "--input", os.path.join(args.workdir, "runs.npz"),
            "--output", os.path.join(args.workdir, f"reference_{name}.npz"),
            "--runs", str(runs), "--filters", name, "--lmb-birth", args.lmb_birth, "--seed", str(args.reference_seed)]


def reference(args) -> None:
    """The reference's runs, one filter after the other, one process (one core) at a time."""
    env = dict(os.environ, MPLBACKEND="Agg")
    env.pop("PYTHONPATH", None)
    n = {"glmb": args.runs, "lmb": args.runs if args.reference_runs_lmb is None else args.reference_runs_lmb}
    for name in FILTERS:
        cmd = reference_command(args, name, n[name])
        print("reference:", " ".join(shlex.quote(c) for c in cmd), flush=True)
        with open(os.path.join(args.workdir, f"reference_{name}.log"), "a") as log:
            subprocess.run(cmd, env=env, check=True, stdout=log, stderr=subprocess.STDOUT)


# --------------------------------------------------------------------------- compare

def _ospa_card(truth, alive, pos, mask):
    """Per run and scan: OSPA (c = 100, p = 1) and the number of estimates."""
    import jax

    from jaxtrack.montecarlo import ospa

    f = jax.jit(jax.vmap(jax.vmap(lambda a, b, c, d: ospa(a, b, c, d, cutoff=100.0, order=1.0).distance,
                                  in_axes=(0, 0, 0, 0)), in_axes=(None, None, 0, 0)))
    return np.asarray(f(truth, alive, pos, mask)), mask.sum(-1).astype(float)


def _paired(a, b):
    """Per scan: mean difference a − b over runs and its SE; the time-averaged difference and SE."""
    d = a - b
    n = d.shape[0]
    mean = d.mean(0)
    se = d.std(0, ddof=1) / np.sqrt(n)
    td = d.mean(1)
    return mean, se, td.mean(), td.std(ddof=1) / np.sqrt(n)


def _binomial_low(n, p, alpha=0.01):
    """The largest k with P(X < k) <= alpha for X ~ Bin(n, p): fewer than k scans within 2 SE would be
    unusual (one-sided, level alpha) if the filters were equal and the scans independent."""
    from math import comb

    cdf, k = 0.0, 0
    for j in range(n + 1):
        cdf += comb(n, j) * p**j * (1 - p) ** (n - j)
        if cdf > alpha:
            return j
        k = j
    return k


def _versions():
    import jax

    import jaxtrack
    return f"jaxtrack {getattr(jaxtrack, '__version__', '?')}, jax {jax.__version__}, numpy {np.__version__}, python {platform.python_version()}"


def _git(args, path):
    try:
        return subprocess.run(["git", *args], cwd=path, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"


def compare(args) -> str:
    d = np.load(os.path.join(args.workdir, "runs.npz"))
    o = np.load(os.path.join(args.workdir, f"ours{args.tag}.npz"))
    filters = [name for name in FILTERS if f"{name}_pos" in o.files]
    refs = {name: os.path.join(args.workdir, f"reference_{name}.npz") for name in FILTERS}
    truth, alive = d["truth"], d["alive"]
    T = d["valid"].shape[1]
    R = o[f"{filters[0]}_pos"].shape[0]  # the runs of jaxtrack's batch
    lines = []
    say = lambda s="": (print(s), lines.append(s))
    ref_commit = _git(["rev-parse", "--short=7", "HEAD"], args.labeledrfs) if args.labeledrfs else "?"
    def shown(a):  # no machine paths in the measured file
        if not os.path.isabs(a):
            return a
        rel = os.path.relpath(a, REPO)
        return rel if not rel.startswith("..") else "<" + os.path.basename(a.rstrip("/")) + ">"

    cmd = "python benchmarks/labelled_reference.py " + " ".join(shown(a) for a in sys.argv[1:])
    say("# Issue 49: jaxtrack's δ-GLMB and LMB against the labeledRFS Python port on Vo & Vo's linear benchmark")
    say(f"date {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC; machine {platform.machine()}, "
        f"{os.cpu_count()} CPUs ({platform.processor() or platform.platform()}); {_versions()}; jaxtrack commit "
        f"{_git(['rev-parse', '--short=7', 'HEAD'], REPO)}")
    say(f"reference: linh-gist/labeledRFS commit {args.reference_commit or ref_commit} (jointglmb_gms_python, "
        f"jointlmb_gms_python), run by benchmarks/_labeledrfs_driver.py under its own venv (numpy < 2); "
        f"LMB birth {args.lmb_birth}")
    say(f"command: {cmd} (paths to the reference given by --labeledrfs/--reference-python or LABELEDRFS_DIR/LABELEDRFS_PYTHON)")
    say(f"runs: {d['valid'].shape[0]} exported, {R} in jaxtrack's batch, of vo_vo_linear, key fold_in(key({int(d['key'])}), i); {T} scans; OSPA c = 100 m, p = 1; "
        f"SE = paired standard error over runs (same measurement sets)")
    say()
    logs = {}
    for name in FILTERS:  # the driver's parameter table and the port's filter settings
        path = os.path.join(args.workdir, f"reference_{name}.log")
        if os.path.exists(path):
            with open(path) as fh:
                logs[name] = fh.read().splitlines()
    keep = False
    for line in logs.get("glmb", []):
        if line.startswith("[glmb] model"):
            keep = True
            say("The model, as the driver set it (printed by benchmarks/_labeledrfs_driver.py):")
            continue
        if line.startswith("numpy ") and keep:
            break  # the first table (a resumed driver prints it again)
        if keep:
            say("  " + line)
    for lines_ in logs.values():
        for line in dict.fromkeys(x for x in lines_ if "filter settings" in x):
            say(line)
    say()
    if "glmb" in filters and "glmb_hypotheses" in o.files:
        say(f"jaxtrack's δ-GLMB keeps H = {int(o['glmb_hypotheses'])} hypotheses (the study: 128)"
            + (f"; both filters gate at {float(o['gate']):.3g} σ (the study: 4)" if "gate" in o.files else "")
            + (f"; ranking {o['glmb_ranking']} (the study: GibbsSampling(2, 8))" if "glmb_ranking" in o.files else ""))
    if "lmb" in filters and "lmb_hypotheses" in o.files:
        say(f"jaxtrack's LMB keeps H = {int(o['lmb_hypotheses'])} hypotheses, ranking {o['lmb_ranking']}"
            + (f", {int(o['lmb_components'])} Gaussian components a label" if "lmb_components" in o.files else "")
            + " (the study: 256, GibbsSampling(64, 16), 10 components)")
    stats = {}
    for name in filters:
        r = np.load(refs[name]) if os.path.exists(refs[name]) else {}
        done = (r[f"{name}_done"] if f"{name}_done" in r else np.zeros(d["valid"].shape[0], bool))[:R]
        n = int(done.sum())
        if n < 2:
            say(f"{NAMES[name]}: {n} reference runs, nothing to compare")
            continue
        idx = np.flatnonzero(done)
        op, oc = _ospa_card(truth, alive, o[f"{name}_pos"][idx], o[f"{name}_mask"][idx])
        rpos = r[f"{name}_pos"][idx]
        rmask = ~np.isnan(rpos[..., 0])
        rp, rc = _ospa_card(truth, alive, np.nan_to_num(rpos), rmask)
        assert np.allclose(rc, r[f"{name}_card"][idx]), "reference cardinality vs stored positions"
        ntrue = alive.sum(-1)
        from scipy.stats import t as student_t

        p_within = float(2 * student_t.cdf(2.0, n - 1) - 1)  # P(|t_{n-1}| <= 2): equal filters, normal differences
        low = _binomial_low(T, p_within)
        say(f"## {NAMES[name]}: {n} runs (ours: all {R} in the batch; compared on the {n} the reference ran)")
        for label, a, b in (("OSPA [m]", op, rp), ("cardinality", oc, rc)):
            mean, se, tmean, tse = _paired(a, b)
            within = np.abs(mean) <= 2 * se
            # scans where both are identical over all runs have SE 0: counted as within
            frac = within.mean()
            worst = np.argsort(-np.abs(mean) / np.maximum(se, 1e-12))[:5]
            say(f"{label}: mean ours {a.mean():.3f}, reference {b.mean():.3f}; time-averaged difference (ours − ref) "
                f"{tmean:+.3f} ± {tse:.3f} (SE), {tmean / tse if tse > 0 else 0:+.1f} SE")
            say(f"  scans with |difference| ≤ 2 SE: {int(within.sum())}/{T} = {frac:.2f} (equal filters: about "
                f"{p_within * T:.0f} expected, P(|t_{n - 1}| ≤ 2) = {p_within:.3f}; fewer than {low} has probability "
                f"≤ 1% under Bin({T}, {p_within:.3f}) if scans were independent — they are not, the runs are shared)")
            tiny = ~within & (np.abs(mean) < 0.01)
            say(f"  scans outside: {np.flatnonzero(~within).tolist()}" + (
                f" (of them {int(tiny.sum())} with |difference| < 0.01: {np.flatnonzero(tiny).tolist()}, an SE near 0 "
                "where both filters agree on almost every run)" if tiny.any() else ""))
            say(f"  largest |difference|/SE at scans (0-indexed) {worst.tolist()}: differences "
                f"{np.round(mean[worst], 3).tolist()}, SE {np.round(se[worst], 3).tolist()}")
            stats[(name, label)] = (a.mean(0), b.mean(0), mean, se)
        bias_o, bias_r = (oc - ntrue).mean(), (rc - ntrue).mean()
        say(f"cardinality bias (estimates − true): ours {bias_o:+.3f}, reference {bias_r:+.3f}; "
            f"mean |bias| per scan: ours {np.abs(oc.mean(0) - ntrue).mean():.3f}, reference {np.abs(rc.mean(0) - ntrue).mean():.3f}")
        if name == "glmb" and "glmb_final_card" in r:
            fpos = r["glmb_final_pos"][idx]
            fp, fc = _ospa_card(truth, alive, np.nan_to_num(fpos), ~np.isnan(fpos[..., 0]))
            mean, se, tmean, tse = _paired(op, fp)
            say(f"  (the reference's end-of-run δ-GLMB estimates, its recursive estimator's rewritten histories, not "
                f"online: OSPA {fp.mean():.3f} m, cardinality {fc.mean():.3f}; ours − it: OSPA {tmean:+.3f} ± {tse:.3f})")
        secs = r[f"{name}_seconds"][idx]
        cpu = r[f"{name}_cpu_seconds"][idx] if f"{name}_cpu_seconds" in r else np.full(n, np.nan)
        cpu = cpu[~np.isnan(cpu)]
        ob, o1 = float(o[f"{name}_batch_seconds"]) / R, float(o[f"{name}_one_seconds"])
        obc, o1c = float(o[f"{name}_batch_cpu_seconds"]) / R, float(o[f"{name}_one_cpu_seconds"])
        say(f"time a run, wall: reference {secs.mean():.2f} s (median {np.median(secs):.2f}, min {secs.min():.2f}, "
            f"max {secs.max():.2f}; {n} runs, one process); ours {ob:.3f} s in a batch of {R} "
            f"({float(o[f'{name}_batch_seconds']):.1f} s wall), {o1:.3f} s one run (run 0, best of 2)")
        if cpu.size:
            say(f"time a run, process CPU: reference {cpu.mean():.2f} s (median {np.median(cpu):.2f}, min "
                f"{cpu.min():.2f}; {cpu.size} runs); ours {obc:.3f} s in the batch, {o1c:.3f} s one run")
        say(f"speed ratio (reference / ours), wall: {secs.mean() / ob:.1f}x per run in the batch, "
            f"{secs.mean() / o1:.1f}x one run; with the reference's fastest run: {secs.min() / ob:.1f}x, "
            f"{secs.min() / o1:.1f}x" + (f"; process CPU: {cpu.mean() / obc:.1f}x in the batch, {cpu.mean() / o1c:.1f}x "
                                         "one run" if cpu.size else "") + "; issue 49 asks ≥ 100x in a batch")
        say(f"ours: capacity events {int(o[f'{name}_events'].sum())}, scans not ok {int((~o[f'{name}_ok']).sum())}")
        say()
    for line in DIFFERENCES.format(lmb_birth=args.lmb_birth).strip().splitlines():
        say(line)
    out = args.out
    os.makedirs(os.path.dirname(out), exist_ok=True)
    with open(out, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    try:
        _figure(stats, alive.sum(-1), os.path.splitext(out)[0] + ".png")
    except (ImportError, OSError, ValueError) as e:  # the figure is optional
        print("figure not written:", e)
    return out


def _figure(stats, ntrue, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 7), constrained_layout=True, sharex=True)
    for j, name in enumerate(FILTERS):
        for i, label in enumerate(("OSPA [m]", "cardinality")):
            if (name, label) not in stats:
                continue
            a, b, mean, se = stats[(name, label)]
            ax = axes[i, j]
            k = np.arange(1, len(a) + 1)
            ax.plot(k, a, color="C0", lw=1.2, label="jaxtrack")
            ax.plot(k, b, color="C1", lw=1.2, label="labeledRFS port")
            ax.fill_between(k, b + mean - 2 * se, b + mean + 2 * se, color="C0", alpha=0.2,
                            label="jaxtrack ± 2 SE of the paired difference")
            if label == "cardinality":
                ax.step(k, ntrue, where="mid", color="k", lw=1, label="true")
            ax.set(title=f"{NAMES[name]}: mean {label}", xlabel="scan")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
    fig.savefig(path, dpi=100)
    print("figure:", path)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=int, default=100)
    p.add_argument("--workdir", default=None, help="work folder (default: a new temporary folder)")
    p.add_argument("--stage", default="all",
                   help="all, or a comma-separated list of export, ours, reference, compare")
    p.add_argument("--reference-python", default=os.environ.get("LABELEDRFS_PYTHON"),
                   help="the reference's interpreter (numpy < 2); default $LABELEDRFS_PYTHON")
    p.add_argument("--labeledrfs", default=os.environ.get("LABELEDRFS_DIR"),
                   help="the labeledRFS checkout; default $LABELEDRFS_DIR")
    p.add_argument("--reference-commit", default=None, help="the checkout's commit if it is not a git work tree")
    p.add_argument("--ours-runs", type=int, default=None,
                   help="jaxtrack's batch: the first OURS_RUNS runs (default --runs)")
    p.add_argument("--reference-runs-lmb", type=int, default=None, help="reference LMB runs (default --runs)")
    p.add_argument("--reference-seed", type=int, default=0)
    p.add_argument("--lmb-birth", choices=("fixed", "adaptive"), default="fixed")
    p.add_argument("--glmb-hypotheses", type=int, default=None,
                   help="jaxtrack's δ-GLMB hypothesis budget H (default the study's, 128)")
    p.add_argument("--filters", default="glmb,lmb", help="jaxtrack's filters to run in --stage ours")
    p.add_argument("--gibbs", default=None, help="the δ-GLMB's Gibbs sampler, CHAINSxSWEEPS[xALPHA] (chains per prior hypothesis slot, shared by w^ALPHA, default 0.5) "
                   "(default the study's, 2x8)")
    p.add_argument("--lmb-gibbs", default=None, help="the LMB's hypotheses by GibbsSampling(CHAINS, SWEEPS), given "
                   "as CHAINSxSWEEPS (default the study's: 64x16)")
    p.add_argument("--lmb-hypotheses", type=int, default=None, help="jaxtrack's LMB hypothesis budget (default the study's, 256)")
    p.add_argument("--lmb-components", type=int, default=None,
                   help="the Gaussian components each of jaxtrack's LMB labels keeps (default the study's)")
    p.add_argument("--gate", type=float, default=None,
                   help="jaxtrack's Mahalanobis gate in σ (default the study's, 4; the port's is sqrt(32.24) = 5.68)")
    p.add_argument("--tag", default="", help="suffix of jaxtrack's result file (ours{TAG}.npz) and of --out's default")
    p.add_argument("--out", default=None, help="default benchmarks/measured/labelled_reference{TAG}.txt")
    args = p.parse_args()
    args.out = args.out or os.path.join(HERE, "measured", f"labelled_reference{args.tag}.txt")
    stages = {"export", "ours", "reference", "compare"} if args.stage == "all" else set(args.stage.split(","))
    if not stages <= {"export", "ours", "reference", "compare"}:
        p.error(f"--stage: unknown {sorted(stages - {'export', 'ours', 'reference', 'compare'})}")
    if "reference" in stages and not (args.reference_python and args.labeledrfs):
        p.error("the reference needs --reference-python and --labeledrfs (or LABELEDRFS_PYTHON, LABELEDRFS_DIR)")
    args.workdir = args.workdir or tempfile.mkdtemp(prefix="labelled_reference_")
    os.makedirs(args.workdir, exist_ok=True)
    print("workdir:", args.workdir, flush=True)
    if "export" in stages:
        export(args.runs, args.workdir)
    if "ours" in stages:
        ours(args.workdir, args.ours_runs, glmb_hypotheses=args.glmb_hypotheses,
             filters=[f for f in args.filters.split(",") if f], tag=args.tag, gate=args.gate,
             gibbs=args.gibbs, lmb_gibbs=args.lmb_gibbs, lmb_hypotheses=args.lmb_hypotheses,
             lmb_components=args.lmb_components)
    if "reference" in stages:
        reference(args)
    if "compare" in stages:
        compare(args)


if __name__ == "__main__":
    main()

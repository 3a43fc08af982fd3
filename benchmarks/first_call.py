"""First-call time (JAX tracing + XLA compilation + run) of jaxtrack's main entry points, one fresh process each.

A user's first call of an entry point pays for tracing, lowering and compiling everything it
jits; this script measures that, at the sizes the README shows. For each library entry the parent
starts ``python benchmarks/first_call.py --child NAME`` with JAX's persistent compilation cache
off (``JAX_COMPILATION_CACHE_DIR`` removed from the environment, ``JAXTRACK_CACHE_DIR=off``), so
every compilation is cold. The child times, on the wall clock:

- ``setup``: ``import jax``, ``import jaxtrack`` and building the inputs (models, simulated data);
- ``first call``: the entry's first call, ``jax.block_until_ready`` on its outputs included;
- ``second call``: the same call again in the same process (what is left once compiled).

Of the first call, ``compile`` sums JAX's ``/jax/core/compile/backend_compile_duration`` events
(XLA) and ``trace+lower`` its ``jaxpr_trace_duration`` and ``jaxpr_to_mlir_module_duration``
events (``jax.monitoring.register_event_duration_secs_listener``); the rest is running the code
and Python overhead; ``first CPU`` is the process's CPU time over the first call (every thread).
Targets: no entry's first call above 15 s on 2 cores, nor above 10 s of CPU (issue 48). The
``multitarget_*``, ``*_step`` and ``run_multitarget_phd`` entries run the Williams (2015) study's
methods on its scenario: a Monte Carlo's first block of 64 runs, one jitted step, one run.

The ``reproduce_<study>`` entries (and ``reproduce_all``) are measured differently: the command
``jaxtrack reproduce STUDY --json --out TMP`` runs twice, each in a fresh process, with
``JAXTRACK_CACHE_DIR`` set to one new temporary folder (the CLI's persistent compilation cache):
the first run is cold, the second warm. Target: ``reproduce_all`` warm ≤ 60 % of cold.

Results go to ``--out`` (default ``benchmarks/measured``) as ``first_call.txt`` (the printed
table) and ``first_call.json``; rows already there for other entries are kept (each row has its
date), so ``--entry reproduce_all`` adds its row to an earlier run's. One run, noisy machine;
nothing asserts these numbers. Run one benchmark process at a time.

Usage::

    python benchmarks/first_call.py                      # every entry
    python benchmarks/first_call.py --skip-reproduce     # the library entries only
    python benchmarks/first_call.py --entry pcrlb --entry run_imm
    python benchmarks/first_call.py --list
"""

from __future__ import annotations

import argparse
import datetime
import importlib.metadata
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
TRACE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration")
TARGET_FIRST_S, TARGET_WARM_RATIO = 15.0, 0.60
TARGET_FIRST_CPU_S = 10.0  # issue 48: every README-sized first call <= 10 s of CPU
ENTRIES = {}  # name -> setup function returning the zero-argument call to time


def entry(fn):
    ENTRIES[fn.__name__] = fn
    return fn


# ---------------------------------------------------------------- the entries (run in the child only)
jax = jnp = np = jt = None  # bound by _child_imports(): the parent stays free of JAX


def _child_imports():
    global jax, jnp, np, jt
    import jax
    import jax.numpy as jnp
    import numpy as np
    import jaxtrack as jt  # float64; subpackages load on first use


def _quickstart():
    return jt.models.constant_velocity(1.0, dim=2, accel_psd=0.5, measurement_std=10.0,
                                       initial_cov=jnp.diag(jnp.array([100.0, 100.0, 10.0, 10.0]) ** 2))


def _radar_model():
    m = jt.models
    radar = m.RangeAzimuthElevation(noise_std=jnp.array([15.0, 2e-3, 2e-3]),
                                    sensor_position=jnp.array([0.0, 0.0, 20.0]),
                                    world_to_sensor_rotation=m.sensor_rotation(yaw=-0.35), azimuth="compass")
    motion = m.CoordinatedTurn(turn_rate=0.026, sample_period=1.0, noise_intensity=0.05, dim=3)
    return m.TrackingModel(motion, radar, initial_mean=jnp.array([8e3, 12e3, 3e3, -150.0, 0.0, 0.0]),
                           initial_cov=jnp.diag(jnp.array([200.0, 200, 100, 20, 20, 5]) ** 2))


def _imm_example():
    """(truth, IMM members, Markov matrix) of the README's maneuvering example (200 steps)."""
    m, ekf = jt.models, jt.filters.ExtendedKalmanFilter
    radar = m.RangeBearing(jnp.array([20.0, 2e-3]))
    x0, P0 = jnp.array([-12e3, 4e3, 150.0, 0.0]), jnp.diag(jnp.array([100.0, 100, 20, 20]) ** 2)
    omega = jnp.where((jnp.arange(200) // 40) % 2 == 1, 0.06, 0.0)
    truth = m.TrackingModel(m.CoordinatedTurn(1.0, turn_rate=omega, noise_intensity=0.1), radar, x0, P0)
    cv = m.TrackingModel(m.ConstantVelocity(1.0, noise_intensity=1.0), radar, x0, P0)
    ct = m.TrackingModel(m.NearlyConstantTurn(1.0, noise_intensity=0.1, turn_rate_intensity=1e-4), radar,
                         jnp.append(x0, 0.0),
                         jnp.diag(jnp.append(jnp.diag(P0), 0.05**2)))
    return truth, [(ekf(), cv), (ekf(), ct)], jnp.array([[0.95, 0.05], [0.05, 0.95]])


def _learning_case(name, seed=0, T=200):
    """A case of tests/_learning_cases.py (Q = Σ θ_i Q_i, R = θ_last): (F, H, Qs, a0, P0, z (T, 1))."""
    F, H = np.array([[1.0, 1.0], [0.0, 1.0]]), np.array([[1.0, 0.0]])
    if name == "constant_velocity":  # white-noise acceleration of PSD θ₀, dt = 1 s
        Qs, theta, P0 = [np.array([[1 / 3, 1 / 2], [1 / 2, 1.0]])], [0.3, 4.0], np.diag([25.0, 4.0])
    else:  # local linear trend
        Qs, theta, P0 = [np.diag([1.0, 0.0]), np.diag([0.0, 1.0])], [1.0, 0.1, 2.0], np.diag([10.0, 1.0])
    rng, Q = np.random.default_rng(seed), sum(t * Qi for t, Qi in zip(theta, Qs))
    x, zs = rng.multivariate_normal(np.zeros(2), P0), []
    for _ in range(T):
        zs.append(H @ x + rng.multivariate_normal(np.zeros(1), theta[-1] * np.eye(1)))
        x = F @ x + rng.multivariate_normal(np.zeros(2), Q, method="eigh")
    return F, H, np.stack(Qs), np.zeros(2), P0, np.array(zs)


def _position_mse(res):
    return jnp.mean(jnp.sum(res.mse[:, :2], axis=-1))  # time-averaged position MSE, m²


@entry
def run_filter_kf():
    model = _quickstart()
    z = jt.montecarlo.simulate(model, jax.random.key(0), num_steps=100).measurements
    return lambda: jt.filters.run_filter(jt.filters.KalmanFilter(), model, z)


def _radar_filter(filter_name):
    model, filt = _radar_model(), getattr(jt.filters, filter_name)()
    run = jt.montecarlo.simulate(model, jax.random.key(0), 100, detection_probability=0.7)
    return lambda: jt.filters.run_filter(filt, model, run.measurements, mask=run.detected)


ENTRIES["run_filter_ekf"] = lambda: _radar_filter("ExtendedKalmanFilter")
ENTRIES["run_filter_ukf"] = lambda: _radar_filter("UnscentedKalmanFilter")


@entry
def run_imm():
    truth, members, P = _imm_example()
    z = jt.montecarlo.simulate(truth, jax.random.key(0), 200).measurements
    imm = jt.filters.InteractingMultipleModel(members, P)
    return lambda: jt.filters.run_imm(imm, z)


@entry
def monte_carlo_kf():
    model = _quickstart()
    return lambda: jt.montecarlo.monte_carlo(model, jax.random.key(1), 10_000, num_steps=100, progress=False)


@entry
def monte_carlo_ekf():
    model, iekf = _radar_model(), jt.filters.IteratedExtendedKalmanFilter(num_iterations=3)
    return lambda: jt.montecarlo.monte_carlo(model, jax.random.key(1), 2_000, num_steps=100, filter=iekf,
                                             detection_probability=0.7, progress=False)


@entry
def monte_carlo_imm():
    truth, members, P = _imm_example()
    imm = jt.filters.InteractingMultipleModel(members, P)
    return lambda: jt.montecarlo.monte_carlo(truth, jax.random.key(1), 2_000, filter=imm,
                                             filter_components=(0, 1, 2, 3), progress=False)


@entry
def differentiable_monte_carlo_grad():
    truth, key = _quickstart(), jax.random.key(1)

    def objective(q):  # q: the filter's white-acceleration PSD (the truth's is 0.5)
        fm = jt.models.constant_velocity(1.0, dim=2, accel_psd=q, measurement_std=10.0, initial_cov=truth.initial_cov)
        return _position_mse(jt.montecarlo.differentiable_monte_carlo(
            truth, key, 1_000, num_steps=100, filter=jt.filters.KalmanFilter(), filter_model=fm))
    fn, q = jax.value_and_grad(objective), jnp.asarray(0.5)
    return lambda: fn(q)


@entry
def pcrlb():
    model = _radar_model()
    return lambda: jt.bounds.pcrlb(model, jax.random.key(0), 500, 100)


@entry
def learning_fit_cv():
    F, H, Qs, a0, P0, z = (jnp.asarray(a) for a in _learning_case("constant_velocity"))

    def build(p):  # tests/_learning_cases.py's _builder
        theta = p["theta"]()
        return jt.models.LinearGaussianModel(F, jnp.tensordot(theta[:-1], Qs, 1), H, theta[-1] * jnp.eye(1), a0, P0)
    params = {"theta": jt.learning.PositiveScalar.from_value(np.ones(2))}

    def call():
        res = jt.learning.fit(build, params, z)
        return res, res.standard_errors()
    return call


@entry
def learning_fit_calibration():
    from jaxtrack.applications.obem_registration import calibration, scenario
    S = calibration.yaw_only_scenario()
    scans = scenario.simulate_run(S, jax.random.key(3), True, True)
    return lambda: calibration.calibrate(scans, S)  # the fit and its standard errors


@entry
def fit_em():
    F, H, Qs, a0, P0, z = _learning_case("local_linear_trend")
    start = jt.models.LinearGaussianModel(F, Qs.sum(0), H, np.eye(1), a0, P0)  # θ = 1 everywhere
    return lambda: jt.learning.fit_em(start, z, num_iterations=50)


@entry
def fit_imm():
    import optax
    from jaxtrack.applications.maneuvering import montecarlo as study, scenario
    z = study.training_measurements(study.NUM_TRAINING_TRACKS)  # study.learn_imm's data and arguments
    adam = optax.adam(study.FIT_LEARNING_RATE)  # one object: fit_imm's jit is keyed on it (static)
    return lambda: jt.learning.fit_imm(scenario.build_imm, scenario.START, z, num_iterations=study.FIT_ITERATIONS,
                                       optimizer=adam)


@entry
def imm_mc_gradient():
    truth, members, P = _imm_example()
    key = jax.random.key(1)

    def objective(logits):
        imm = jt.filters.InteractingMultipleModel.from_logits(members, logits)
        return _position_mse(jt.montecarlo.differentiable_monte_carlo(truth, key, 200, filter=imm,
                                                                      filter_components=(0, 1, 2, 3)))
    fn, logits = jax.jit(jax.value_and_grad(objective)), jnp.log(P)
    return lambda: fn(logits)


@entry
def schedule_design():
    from jaxtrack.applications import ho_sensitivity as ho
    d, g, N, lo, hi = jt.design, 1.0, 40, 1, 20  # `jaxtrack design gradient` at its defaults
    problem = ho.segment_problem(g)
    plant = lambda t: jt.models.ho_plant(t, g=g)  # noqa: E731

    def call():  # the library calls of jaxtrack/cli/_design.py, method "gradient"
        relaxed = d.relaxed_segment_design(problem, N, lo=lo, hi=hi)
        counts, J = d.local_search(problem, d.round_counts(relaxed.counts, N, lo, hi), lo=lo, hi=hi)
        ps = d.per_step_design(plant, N, 5.0 - 5.0 / N, ho.POSITION, first_time=5.0 / N)
        return relaxed, J, jnp.asarray(ps.cost)
    return call


def child(name: str) -> dict:
    """Run entry ``name`` in this process; the row (times in s, or an error string)."""
    row, t0 = {"entry": name}, time.perf_counter()
    try:
        _child_imports()
        totals = {"compile": 0.0, "trace": 0.0}

        def listen(event, duration, **_):
            if event == COMPILE_EVENT:
                totals["compile"] += duration
            elif event in TRACE_EVENTS:
                totals["trace"] += duration
        jax.monitoring.register_event_duration_secs_listener(listen)
        call = ENTRIES[name]()
        row["setup_s"] = time.perf_counter() - t0
        for which in ("first", "second"):
            totals.update(compile=0.0, trace=0.0)
            t, c = time.perf_counter(), time.process_time()
            jax.block_until_ready(call())
            row[f"{which}_s"] = time.perf_counter() - t
            row[f"{which}_cpu_s"] = time.process_time() - c  # every thread of the process
            row[f"{which}_compile_s"], row[f"{which}_trace_s"] = totals["compile"], totals["trace"]
    except Exception as exc:  # reported in the table, not raised
        row["error"] = f"{type(exc).__name__}: {exc}"[:500]
    return row


# ---------------------------------------------------------------- the parent
def studies() -> list[str]:
    from jaxtrack.cli._reproduce import STUDIES  # no JAX import
    return [*STUDIES, "all"]


def _env(cache: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    env["JAXTRACK_CACHE_DIR"] = cache
    return env


def _tail(p) -> str:
    return " | ".join(p.stderr.strip().splitlines()[-3:])[:500]


def _williams(name):
    """One of the Williams (2015) study's methods, its scenario and one run's scans (the sizes of
    ``jaxtrack reproduce williams15`` and of the multi-target notebooks)."""
    from jaxtrack.applications import williams15 as w15
    scen, settings = w15.scenario()
    method = w15.methods(scen, settings)[name]
    truth = jt.multitarget.simulate_scenario(scen, 1)
    return method, scen, truth.scans


def _multitarget_mc(name):
    method, scen, _ = _williams(name)
    return lambda: jt.multitarget.multitarget_monte_carlo(method, scen, 3, 64, cutoff=10.0, block_size=64).gospa


def _multitarget_step(name):
    import equinox as eqx
    method, _, scans = _williams(name)
    step, state = eqx.filter_jit(method.step), method.init()
    return lambda: step(state, scans.measurements[0], scans.valid[0])


@entry
def multitarget_mc_jpda():
    """The JPDA tracker's Monte Carlo, first block of 64 runs × 81 scans (the Williams study's)."""
    return _multitarget_mc("jpda")


@entry
def multitarget_mc_phd():
    return _multitarget_mc("phd")


@entry
def multitarget_mc_pmbm():
    return _multitarget_mc("pmbm")


@entry
def jpda_tracker_step():
    """One jitted JPDA tracker step (``eqx.filter_jit(tracker.step)``) on a Williams scan."""
    return _multitarget_step("jpda")


@entry
def phd_step():
    return _multitarget_step("phd")


@entry
def run_multitarget_phd():
    method, _, scans = _williams("phd")
    return lambda: jt.multitarget.run_multitarget(method, scans.measurements, scans.valid, warn=False).estimates


def measure_library(name: str, timeout: float) -> dict:
    """One fresh child process for entry ``name``; its row, or an error row."""
    t = time.perf_counter()
    try:
        p = subprocess.run([sys.executable, __file__, "--child", name], capture_output=True, text=True,
                           timeout=timeout, env=_env("off"))
    except subprocess.TimeoutExpired:
        return {"entry": name, "error": f"timeout after {timeout:g} s"}
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith("{")]  # the child's row is its last JSON line
    row = json.loads(lines[-1]) if lines else {"entry": name, "error": f"exit {p.returncode}, no result: {_tail(p)}"}
    row["process_s"] = time.perf_counter() - t
    return row


def measure_reproduce(study: str, timeout: float) -> dict:
    """``jaxtrack reproduce STUDY`` cold then warm, sharing one fresh JAXTRACK_CACHE_DIR."""
    exe = shutil.which("jaxtrack", path=str(Path(sys.executable).parent))
    cmd = [exe] if exe else [sys.executable, "-m", "jaxtrack"]
    row = {"entry": f"reproduce_{study}"}
    with tempfile.TemporaryDirectory(prefix="jaxtrack-cache-") as cache, tempfile.TemporaryDirectory() as out:
        for which in ("cold", "warm"):
            t = time.perf_counter()
            try:
                p = subprocess.run([*cmd, "reproduce", study, "--json", "--out", out], capture_output=True,
                                   text=True, timeout=timeout, env=_env(cache))
            except subprocess.TimeoutExpired:
                row["error"] = f"{which} run: timeout after {timeout:g} s"
                return row
            row[f"{which}_s"], row[f"{which}_rc"] = time.perf_counter() - t, p.returncode
            if p.returncode not in (0, 1):  # 1: a row missed its tolerance, still timed
                row["error"] = f"{which} run exit {p.returncode}: {_tail(p)}"
    if "cold_s" in row and "warm_s" in row:
        row["warm_over_cold"] = row["warm_s"] / row["cold_s"]
    return row


def _f(row, key, fmt="{:.2f}"):
    return fmt.format(row[key]) if key in row else "–"


def format_report(header: list[str], rows: list[dict]) -> str:
    lib = [r for r in rows if not r["entry"].startswith("reproduce_")]
    rep = [r for r in rows if r["entry"].startswith("reproduce_")]
    out = list(header)
    if lib:
        out += ["", f"{'entry':<32} {'setup s':>8} {'first call s':>13} {'first CPU s':>12} {'XLA compile s':>14} "
                    f"{'trace+lower s':>14} {'second call s':>14} {'<= 15 s':>8} {'CPU <= 10 s':>12}"]
        for r in lib:
            ok = ("yes" if r["first_s"] <= TARGET_FIRST_S else "NO") if "first_s" in r else "–"
            cpu_ok = ("yes" if r["first_cpu_s"] <= TARGET_FIRST_CPU_S else "NO") if "first_cpu_s" in r else "–"
            out.append(f"{r['entry']:<32} {_f(r, 'setup_s'):>8} {_f(r, 'first_s'):>13} {_f(r, 'first_cpu_s'):>12} "
                       f"{_f(r, 'first_compile_s'):>14} {_f(r, 'first_trace_s'):>14} {_f(r, 'second_s', '{:.3f}'):>14} "
                       f"{ok:>8} {cpu_ok:>12}")
        slow = [r["entry"] for r in lib if r.get("first_s", 0.0) > TARGET_FIRST_S]
        if any("first_s" in r for r in lib):
            out.append(f"no first call above {TARGET_FIRST_S:g} s: {'yes' if not slow else 'NO'}"
                       + (f" ({', '.join(slow)})" if slow else ""))
    if rep:
        out += ["", f"{'entry':<32} {'cold s':>8} {'warm s':>8} {'warm/cold':>10} {'<= 60 %':>8}"]
        for r in rep:
            ok = ("yes" if r["warm_over_cold"] <= TARGET_WARM_RATIO else "NO") if (
                r["entry"] == "reproduce_all" and "warm_over_cold" in r) else "–"
            out.append(f"{r['entry']:<32} {_f(r, 'cold_s'):>8} {_f(r, 'warm_s'):>8} "
                       f"{_f(r, 'warm_over_cold', '{:.0%}'):>10} {ok:>8}")
    errors = [r for r in rows if "error" in r]
    out += ["", "errors:"] + [f"  {r['entry']}: {r['error']}" for r in errors] if errors else []
    return "\n".join(out)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--entry", action="append", metavar="NAME", help="run only this entry (repeatable)")
    parser.add_argument("--list", action="store_true", help="list the entries and exit")
    parser.add_argument("--skip-reproduce", action="store_true", help="leave out the reproduce_* entries")
    parser.add_argument("--out", default=str(HERE / "measured"), help="folder for first_call.txt / .json")
    parser.add_argument("--timeout", type=float, default=900.0, help="seconds per child process (default 900)")
    parser.add_argument("--child", metavar="NAME", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child)), flush=True)
        return 0
    names = [*ENTRIES, *(f"reproduce_{s}" for s in studies())]
    if args.list:
        print("\n".join(names))
        return 0
    chosen = args.entry or [n for n in names if not (args.skip_reproduce and n.startswith("reproduce_"))]
    if unknown := [n for n in chosen if n not in names]:
        parser.error(f"unknown entries {unknown}; see --list")
    date = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
    versions = {p: importlib.metadata.version(p) for p in ("jax", "jaxlib")}
    header = ["first-call time of jaxtrack entry points, one fresh process each, persistent cache off "
              "(reproduce_*: cold/warm with a fresh JAXTRACK_CACHE_DIR)",
              f"jax {versions['jax']}, jaxlib {versions['jaxlib']}, {os.cpu_count()} CPUs, {date}",
              f"command: python benchmarks/first_call.py {' '.join(sys.argv[1:])}".rstrip(),
              f"load average before: {os.getloadavg()[0]:.2f}"]
    print("\n".join(header), flush=True)
    rows = []
    for name in chosen:
        study = name.removeprefix("reproduce_")
        row = measure_reproduce(study, args.timeout) if name.startswith("reproduce_") else measure_library(
            name, args.timeout)
        row["date"] = date
        rows.append(row)
        print(f"  {name}: " + ", ".join(f"{k} {v:.2f}" for k, v in row.items() if isinstance(v, float))
              + (f"  ERROR {row['error']}" if "error" in row else ""), flush=True)
    header.append(f"load average after: {os.getloadavg()[0]:.2f}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "first_call.json"
    old = json.loads(path.read_text())["rows"] if path.exists() else []
    merged = {r["entry"]: r for r in old} | {r["entry"]: r for r in rows}  # rows of other entries are kept
    merged = [merged[n] for n in names if n in merged]
    report = format_report(header, merged)
    print("\n".join(report.splitlines()[len(header) - 1:]))  # the header's first lines are printed already
    path.write_text(json.dumps({"header": header, "versions": versions, "cpus": os.cpu_count(),
                                "target_first_call_s": TARGET_FIRST_S, "target_warm_over_cold": TARGET_WARM_RATIO,
                                "rows": merged}, indent=2) + "\n")
    (out / "first_call.txt").write_text(report + "\n")
    print(f"wrote {path} and {out / 'first_call.txt'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

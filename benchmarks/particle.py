"""Bootstrap particle filter throughput: jaxtrack's jitted (and vmapped) ``ParticleFilter`` against a
FilterPy-style NumPy loop and Stone Soup's ``ParticlePredictor``/``ParticleUpdater``.

The job: a bootstrap particle filter (transition prior as proposal, systematic resampling at
every step) on a 2-D constant-velocity model, state ``[x, y, vx, vy]`` (CWNA, ``q = 1 m²/s³``,
``dt = 1 s``), position measurements with ``σ = 10 m``, ``T = 100`` steps, ``N = 1,000``
particles (``--particles``), float64. Every filter gets the same simulated truth and the same
measurements; the prior sits one transition before the first measurement (``first_step="predict"``
in jaxtrack, a predict then an update at every step everywhere). The figure of merit is
**particle-steps per second**, ``N · T / wall time``.

Contenders:

1. **jaxtrack**: ``ParticleFilter(N, Bootstrap(), Systematic(), ess_threshold=1.0, key=key)`` run
   by ``run_filter`` (``save="mean"``). One run: ``jax.jit`` of a function of the key that builds
   the filter and runs it (compiled once, the compilation reported separately). A batch: the same
   function under ``jax.jit(jax.vmap(...))`` over ``--runs`` keys (R = 64 by default), counted as
   ``R · N · T`` particle-steps.
2. **FilterPy**: FilterPy 2.0 has no particle-filter class, only the resampling functions in
   ``filterpy.monte_carlo``. The contender is therefore the hand-written NumPy loop of FilterPy's
   documentation (Labbe, *Kalman and Bayesian Filters in Python*, ch. 12): predict by
   ``F @ particles.T`` plus Gaussian noise, weights multiplied by the closed-form Gaussian
   likelihood and normalised, the weighted mean as estimate, ``filterpy.monte_carlo.systematic_resample``
   and ``resample_from_index``-style indexing (``particles[:] = particles[indexes]``, weights
   reset to ``1/N``). ``systematic_resample`` is a Python ``while`` loop over the particles.
3. **Stone Soup** (``stonesoup``): ``ParticlePredictor`` on a ``CombinedLinearGaussianTransitionModel``
   of two ``ConstantVelocity(q)`` and ``ParticleUpdater`` with a ``LinearGaussian`` measurement
   model and ``SystematicResampler`` (which resamples at every call), state order ``[x, vx, y, vy]``.
   It is a Python loop of object-heavy steps; with ``--ss-steps`` smaller than ``T`` it is timed on
   the first ``--ss-steps`` steps only and reported per particle-step (said so in the output).

4. **cuthbert** (the ``bench`` extra; skipped with a line saying so when it is not installed):
   ``cuthbert.smc.particle_filter.build_filter`` with the same prior, transition and Gaussian
   log-potential, ``cuthbertlib.resampling.systematic.resampling`` at every step (cuthbert
   resamples at the start of each step, before propagating), run by ``cuthbert.filter`` under
   ``jax.jit``; one run and the same ``jax.vmap`` batch as jaxtrack. Its estimate is the weighted
   mean of each step's particles. Its CPU inverse CDF is a Numba callback from inside the jitted
   program.

Each time is the best of ``--repeats`` interleaved rounds after a warm-up of every contender.
Agreement check (asserted): every filter's final position error is finite and its position RMSE
over the run is within a factor 2 of the Kalman filter's (``jaxtrack.filters.KalmanFilter`` via
``run_filter`` on the same measurements); for the batch, the mean RMSE over the R runs. Stone Soup
is checked on the steps it ran (against the Kalman RMSE of those steps).

Usage::

    python benchmarks/particle.py                    # N = 1,000, T = 100, R = 64
    python benchmarks/particle.py --quick            # a smoke test (fewer repeats, R = 8)
    python benchmarks/particle.py --particles 10000
    python benchmarks/particle.py --json out.json
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxtrack
from jaxtrack.filters import Bootstrap, KalmanFilter, ParticleFilter, Systematic, run_filter

DT = 1.0  # s
ACCEL_PSD = 1.0  # m²/s³
SIGMA = 10.0  # m
PRIOR_MEAN = np.array([0.0, 0.0, 10.0, 5.0])  # m, m, m/s, m/s
PRIOR_STD = np.array([20.0, 20.0, 5.0, 5.0])


def make_model():
    return jaxtrack.models.constant_velocity(
        DT, dim=2, accel_psd=ACCEL_PSD, measurement_std=SIGMA, initial_mean=PRIOR_MEAN,
        initial_cov=np.diag(PRIOR_STD**2))


def simulate(model, num_steps: int, seed: int = 0):
    """Truth ``(T, 4)`` and measurements ``(T, 2)``; the prior is one transition before step 0."""
    rng = np.random.default_rng(seed)
    F, Q, H, R = (np.asarray(a) for a in (model.F, model.Q, model.H, model.R))
    x = rng.multivariate_normal(PRIOR_MEAN, np.diag(PRIOR_STD**2))
    truth, zs = [], []
    for _ in range(num_steps):
        x = F @ x + rng.multivariate_normal(np.zeros(4), Q)
        truth.append(x)
        zs.append(H @ x + rng.multivariate_normal(np.zeros(2), R))
    return np.array(truth), np.array(zs)


def position_rmse(means, truth) -> float:
    return float(np.sqrt(np.mean(np.sum((np.asarray(means)[..., :2] - truth[..., :2]) ** 2, axis=-1))))


def final_error(means, truth) -> float:
    return float(np.linalg.norm(np.asarray(means)[-1, :2] - truth[-1, :2]))


# ------------------------------------------------------------------------------------------------
# FilterPy: the documentation's NumPy loop around filterpy.monte_carlo.systematic_resample
# ------------------------------------------------------------------------------------------------


def filterpy_pf(F, Q, zs, num_particles: int, seed: int = 1):
    from filterpy.monte_carlo import systematic_resample

    np.random.seed(seed)  # systematic_resample draws from the global NumPy generator
    n = F.shape[0]
    L = np.linalg.cholesky(Q + 1e-12 * np.max(np.diag(Q)) * np.eye(n))
    particles = PRIOR_MEAN + np.random.randn(num_particles, n) * PRIOR_STD
    weights = np.full(num_particles, 1.0 / num_particles)
    means = np.empty((len(zs), n))
    for k, z in enumerate(zs):
        # predict
        particles = (F @ particles.T).T + np.random.randn(num_particles, n) @ L.T
        # update: closed-form Gaussian likelihood of the position measurement
        r = particles[:, :2] - z
        weights *= np.exp(-0.5 * np.sum(r * r, axis=1) / SIGMA**2)
        weights += 1.0e-300  # avoid round-off to zero
        weights /= np.sum(weights)
        # estimate
        means[k] = np.average(particles, weights=weights, axis=0)
        # resample (every step), resample_from_index style
        indexes = systematic_resample(weights)
        particles[:] = particles[indexes]
        weights.resize(len(particles))
        weights.fill(1.0 / len(weights))
    return means


# ------------------------------------------------------------------------------------------------
# Stone Soup
# ------------------------------------------------------------------------------------------------

SS_ORDER = [0, 2, 1, 3]  # jaxtrack [x, y, vx, vy] -> Stone Soup [x, vx, y, vy]


def stone_soup_setup(zs, num_particles: int):
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
    from stonesoup.predictor.particle import ParticlePredictor
    from stonesoup.resampler.particle import SystematicResampler
    from stonesoup.types.detection import Detection
    from stonesoup.updater.particle import ParticleUpdater

    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(ACCEL_PSD), ConstantVelocity(ACCEL_PSD)])
    measurement = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=np.diag([SIGMA**2, SIGMA**2]))
    predictor = ParticlePredictor(transition)
    updater = ParticleUpdater(measurement, resampler=SystematicResampler())
    start = datetime.datetime(2024, 1, 1)
    detections = [Detection(np.asarray(z).reshape(2, 1), timestamp=start + datetime.timedelta(seconds=DT * (k + 1)),
                            measurement_model=measurement) for k, z in enumerate(zs)]
    return predictor, updater, detections, start


def stone_soup_pf(setup, num_particles: int, seed: int = 2):
    from stonesoup.types.array import StateVectors
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import ParticleState

    predictor, updater, detections, start = setup
    np.random.seed(seed)  # Stone Soup's noise and resampler draw from the global NumPy generator
    samples = PRIOR_MEAN[SS_ORDER] + np.random.randn(num_particles, 4) * PRIOR_STD[SS_ORDER]
    prior = ParticleState(StateVectors(samples.T), log_weight=np.full(num_particles, -np.log(num_particles)),
                          timestamp=start)
    means = np.empty((len(detections), 4))
    for k, det in enumerate(detections):
        prediction = predictor.predict(prior, timestamp=det.timestamp)
        posterior = updater.update(SingleHypothesis(prediction, det))
        means[k] = np.asarray(posterior.mean, dtype=float).ravel()[SS_ORDER]  # back to [x, y, vx, vy]
        prior = posterior
    return means


# ------------------------------------------------------------------------------------------------


def cuthbert_pf(model, zs, num_particles: int):
    """cuthbert's bootstrap particle filter on ``model`` (None when cuthbert is not installed):
    ``(one_run(key) -> (T, 4) means, compile seconds)``."""
    try:
        import cuthbert
        from cuthbert.smc import particle_filter
        from cuthbertlib.resampling import systematic
    except ImportError:
        return None
    F, Q, H, R = (jnp.asarray(a) for a in (model.F, model.Q, model.H, model.R))
    m0, chol_p0, chol_q = model.initial_mean, jnp.linalg.cholesky(model.initial_cov), jnp.linalg.cholesky(Q)
    r_inv = jnp.linalg.inv(R)

    def init_sample(key):
        return m0 + chol_p0 @ jax.random.normal(key, m0.shape, m0.dtype)

    def propagate(key, x, z):
        return F @ x + chol_q @ jax.random.normal(key, x.shape, x.dtype)

    def log_potential(x_prev, x, z):
        r = z - H @ x
        return -0.5 * r @ r_inv @ r

    pf = particle_filter.build_filter(init_sample, propagate, log_potential, num_particles, systematic.resampling)

    def one_run(key):
        k0, k1 = jax.random.split(key)
        states = cuthbert.filter(pf, zs, pf.init_prepare(key=k0), key=k1)
        w = jax.nn.softmax(states.log_weights, axis=-1)
        return jnp.einsum("tn,tnd->td", w, states.particles)[1:]  # entry 0 is the prior

    return one_run


def timed(fn) -> float:
    t = time.perf_counter()
    jax.block_until_ready(fn())
    return time.perf_counter() - t


def bench(num_particles: int, num_steps: int, num_runs: int, ss_particles: int, ss_steps: int, repeats: int) -> dict:
    model = make_model()
    truth, zs_np = simulate(model, num_steps)
    zs = jnp.asarray(zs_np)

    kf = run_filter(KalmanFilter(), model, zs, first_step="predict")
    kf_means = np.asarray(kf.filtered_mean)

    def one_run(key):
        pf = ParticleFilter(num_particles, Bootstrap(), Systematic(), ess_threshold=1.0, key=key)
        return run_filter(pf, model, zs, first_step="predict", save="mean", throw=False).filtered_mean

    key = jax.random.key(42)
    keys = jax.random.split(jax.random.key(7), num_runs)
    t = time.perf_counter()
    single = jax.jit(one_run).lower(key).compile()
    compile_s = time.perf_counter() - t
    t = time.perf_counter()
    batched = jax.jit(jax.vmap(one_run)).lower(keys).compile()
    compile_batch_s = time.perf_counter() - t

    F, Q = np.asarray(model.F), np.asarray(model.Q)
    ss_setup = stone_soup_setup(zs_np[:ss_steps], ss_particles)

    contenders = {
        "jaxtrack": (lambda: single(key), num_particles * num_steps),
        "jaxtrack batch": (lambda: batched(keys), num_runs * num_particles * num_steps),
        "FilterPy loop": (lambda: filterpy_pf(F, Q, zs_np, num_particles), num_particles * num_steps),
        "Stone Soup": (lambda: stone_soup_pf(ss_setup, ss_particles), ss_particles * ss_steps),
    }
    cb_run = cuthbert_pf(model, zs, num_particles)
    cb_compile = {}
    if cb_run is not None:
        t = time.perf_counter()
        cb_single = jax.jit(cb_run).lower(key).compile()
        cb_compile["one run"] = time.perf_counter() - t
        t = time.perf_counter()
        cb_batched = jax.jit(jax.vmap(cb_run)).lower(keys).compile()
        cb_compile["batch"] = time.perf_counter() - t
        contenders["cuthbert"] = (lambda: cb_single(key), num_particles * num_steps)
        contenders["cuthbert batch"] = (lambda: cb_batched(keys), num_runs * num_particles * num_steps)
    # Warm-up of every contender; these results are the ones checked.
    outputs = {name: np.asarray(jax.block_until_ready(fn())) for name, (fn, _) in contenders.items()}
    best = {name: np.inf for name in contenders}
    for _ in range(repeats):
        for name, (fn, _) in contenders.items():
            best[name] = min(best[name], timed(fn))
    rate = {name: contenders[name][1] / best[name] for name in contenders}

    kf_rmse = position_rmse(kf_means, truth)
    kf_rmse_ss = position_rmse(kf_means[:ss_steps], truth[:ss_steps])
    batch_rmses = [position_rmse(m, truth) for m in outputs["jaxtrack batch"]]
    check = {
        "Kalman filter": (kf_rmse, final_error(kf_means, truth), kf_rmse),
        "jaxtrack": (position_rmse(outputs["jaxtrack"], truth), final_error(outputs["jaxtrack"], truth), kf_rmse),
        "jaxtrack batch": (float(np.mean(batch_rmses)),
                           float(np.mean([final_error(m, truth) for m in outputs["jaxtrack batch"]])), kf_rmse),
        "FilterPy loop": (position_rmse(outputs["FilterPy loop"], truth),
                          final_error(outputs["FilterPy loop"], truth), kf_rmse),
        "Stone Soup": (position_rmse(outputs["Stone Soup"], truth[:ss_steps]),
                       final_error(outputs["Stone Soup"], truth[:ss_steps]), kf_rmse_ss),
    }
    if cb_run is not None:
        check["cuthbert"] = (position_rmse(outputs["cuthbert"], truth), final_error(outputs["cuthbert"], truth), kf_rmse)
        check["cuthbert batch"] = (float(np.mean([position_rmse(m, truth) for m in outputs["cuthbert batch"]])),
                                   float(np.mean([final_error(m, truth) for m in outputs["cuthbert batch"]])), kf_rmse)
    for name, (rmse, final, reference) in check.items():
        assert np.isfinite(final) and np.isfinite(rmse), (name, rmse, final)
        assert reference / 2 <= rmse <= 2 * reference, (name, rmse, reference)
    return {
        "particles": num_particles, "steps": num_steps, "runs": num_runs,
        "stone_soup_particles": ss_particles, "stone_soup_steps": ss_steps,
        "compile_s": compile_s, "compile_batch_s": compile_batch_s,
        "best_s": best, "particle_steps_per_s": rate,
        "speed_up_vs_filterpy": rate["jaxtrack"] / rate["FilterPy loop"],
        "speed_up_vs_stone_soup": rate["jaxtrack"] / rate["Stone Soup"],
        "batch_speed_up_vs_filterpy": rate["jaxtrack batch"] / rate["FilterPy loop"],
        "batch_speed_up_vs_stone_soup": rate["jaxtrack batch"] / rate["Stone Soup"],
        "cuthbert_compile_s": cb_compile,
        "speed_up_vs_cuthbert": rate["jaxtrack"] / rate["cuthbert"] if cb_run is not None else None,
        "batch_speed_up_vs_cuthbert": rate["jaxtrack batch"] / rate["cuthbert batch"] if cb_run is not None else None,
        "check": {name: {"position_rmse_m": v[0], "final_position_error_m": v[1], "kalman_rmse_m": v[2]}
                  for name, v in check.items()},
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="R = 8, Stone Soup on 20 steps, 2 repeats (a smoke test)")
    parser.add_argument("--particles", type=int, default=1000, help="N (default 1,000)")
    parser.add_argument("--steps", type=int, default=100, help="T (default 100)")
    parser.add_argument("--runs", type=int, default=None, help="R, runs in the vmapped batch (default 64)")
    parser.add_argument("--ss-steps", type=int, default=None, help="steps Stone Soup runs (default T)")
    parser.add_argument("--ss-particles", type=int, default=None, help="particles Stone Soup runs (default N)")
    parser.add_argument("--repeats", type=int, default=None, help="timed rounds (default 5)")
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    args = parser.parse_args()
    runs, ss_steps, repeats = (8, 20, 2) if args.quick else (64, args.steps, 5)
    runs = args.runs or runs
    ss_steps = min(args.ss_steps or ss_steps, args.steps)
    ss_particles = args.ss_particles or args.particles
    repeats = args.repeats or repeats
    machine = {"cores": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
               "jax": jax.__version__, "jaxtrack": getattr(jaxtrack, "__version__", "dev"),
               "backend": jax.default_backend(), "dtype": "float64"}
    print(f"Bootstrap particle filter, systematic resampling every step, 2-D constant velocity "
          f"(q = {ACCEL_PSD} m²/s³, dt = {DT} s, σ = {SIGMA} m), N = {args.particles}, T = {args.steps}, "
          f"float64, {machine['cores']} cores ({machine['backend']}), jax {machine['jax']}, best of {repeats}")
    print(f"platform: {machine['platform']}, python {machine['python']}")
    print(f"command: python {' '.join(sys.argv)}")
    load_before = os.getloadavg()[0]
    print(f"load average before: {load_before:.2f}")
    row = bench(args.particles, args.steps, runs, ss_particles, ss_steps, repeats)
    row["load_average_before_after"] = [load_before, os.getloadavg()[0]]

    rate, best = row["particle_steps_per_s"], row["best_s"]
    print(f"\n  {'':30s}{'N':>7s}{'T':>6s}{'runs':>6s}{'wall':>12s}{'particle-steps/s':>19s}")
    rows = (("jaxtrack (jit, one run)", "jaxtrack", args.particles, args.steps, 1),
            ("jaxtrack (jit ∘ vmap batch)", "jaxtrack batch", args.particles, args.steps, runs),
            ("FilterPy loop (NumPy)", "FilterPy loop", args.particles, args.steps, 1),
            ("Stone Soup", "Stone Soup", ss_particles, ss_steps, 1))
    if "cuthbert" in rate:
        rows += (("cuthbert (jit, one run)", "cuthbert", args.particles, args.steps, 1),
                 ("cuthbert (jit ∘ vmap batch)", "cuthbert batch", args.particles, args.steps, runs))
    for label, key, n, t, r in rows:
        print(f"  {label:30s}{n:7d}{t:6d}{r:6d}{best[key] * 1e3:9.2f} ms{rate[key]:19.3e}")
    if "cuthbert" not in rate:
        print("  cuthbert                      not installed (pip install -c requirements.lock -e '.[bench]'): not measured")
    if ss_steps < args.steps or ss_particles != args.particles:
        print(f"  (Stone Soup timed on {ss_particles} particles × {ss_steps} steps, reported per particle-step)")
    print(f"\n  jaxtrack compilation (once): one run {row['compile_s']:.2f} s, batch of {runs} "
          f"{row['compile_batch_s']:.2f} s")
    print(f"  jaxtrack / FilterPy loop:  one run {row['speed_up_vs_filterpy']:8.1f}×   "
          f"batch {row['batch_speed_up_vs_filterpy']:8.1f}×")
    print(f"  jaxtrack / Stone Soup:     one run {row['speed_up_vs_stone_soup']:8.1f}×   "
          f"batch {row['batch_speed_up_vs_stone_soup']:8.1f}×   (issue target ≥ 100×)")
    if row["speed_up_vs_cuthbert"] is not None:
        cc = row["cuthbert_compile_s"]
        print(f"  jaxtrack / cuthbert:       one run {row['speed_up_vs_cuthbert']:8.2f}×   "
              f"batch {row['batch_speed_up_vs_cuthbert']:8.2f}×   (issue target ≥ 1×; cuthbert compiles in "
              f"{cc['one run']:.2f} s / {cc['batch']:.2f} s)")
    print("\n  agreement (same truth and measurements; asserted: finite, RMSE within 2× of the Kalman filter's)")
    print(f"  {'':30s}{'position RMSE':>15s}{'final error':>13s}{'Kalman RMSE':>13s}")
    for name, v in row["check"].items():
        label = name + (" (mean of runs)" if name == "jaxtrack batch" else "")
        label += f" ({ss_steps} steps)" if name == "Stone Soup" and ss_steps < args.steps else ""
        print(f"  {label:30s}{v['position_rmse_m']:13.2f} m{v['final_position_error_m']:11.2f} m"
              f"{v['kalman_rmse_m']:11.2f} m")
    print(f"\nload average after: {os.getloadavg()[0]:.2f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"machine": machine, "command": "python " + " ".join(sys.argv), "rows": [row]}, f, indent=2)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

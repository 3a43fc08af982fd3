"""IMM Monte Carlo, per run: jaxtrack's ``InteractingMultipleModel`` against FilterPy's ``IMMEstimator``.

The scenario (linear members, so that FilterPy's ``IMMEstimator`` applies): a 2-D target
``[x, y, vx, vy]`` (jaxtrack's ordering), τ = 1 s, position measured with σ = 10 m
(``H = [I₂ 0]``). Three members, all linear Kalman filters with white-acceleration plant noise
``q`` on each axis: constant velocity, and coordinated turns with KNOWN turn rates +ω and −ω
(ω = 0.05 rad/s; a coordinated turn with known ω is linear, its ``F`` is
``CoordinatedTurn(ω, τ, q).transition_matrix``, BLK 2001 §11.7). Mode transitions
``p_ii = 0.95``, ``p_ij = 0.025``; uniform initial mode probabilities. The truth follows a turn
schedule (CV, +ω, CV, −ω, CV legs at 0/20/35/50/65 % of the run) as a
``LinearGaussianModel`` with per-step ``F_k = F(ω_k)`` (the fastest truth to simulate: one
``(4, 4)`` product per step) and the same ``q``; the prior is the filters' prior.

Every contender gets the same simulated data in one process; each time is the best of
``--repeats`` interleaved rounds, after compilation. Rates are IMM steps per second
(runs × steps / wall time). FilterPy is timed on a subset of runs (``--fp-runs``) and scaled.

Two jobs:

1. **filter**: the combined means and mode probabilities of every step of every run, from the
   same measurements. jaxtrack: ``jax.jit(jax.vmap(run_imm(imm, z).(mean, mode_probs)))``;
   FilterPy: ``IMMEstimator`` of three ``filterpy.kalman.KalmanFilter``, a Python loop per run
   (``update(z)``, record, ``predict()``; its constructor pushes ``mu`` through ``M`` once, so
   jaxtrack's ``initial_probs`` is ``mu @ M``, here uniform again; see ``tests/test_imm.py``).
   The means agree to rounding on the subset (printed; asserted < 1e-8 m).
2. **Monte Carlo**: simulate, filter and score: position squared error, NEES of the combined
   estimate and the mode probabilities, per step, summed over runs. jaxtrack:
   ``monte_carlo_map`` of one run (``simulate`` + ``run_imm`` + metrics, blocks of runs
   ``vmap``-ed and compiled once), and ``monte_carlo(truth, key, M, filter=imm)`` when the
   library's harness accepts an IMM; FilterPy: a numpy simulation, the filter loop and the
   metrics per run on the subset, scaled.

Needs the ``bench`` extra (FilterPy). Usage::

    python benchmarks/imm.py                 # 10,000 runs × 200 steps
    python benchmarks/imm.py --quick         # 1,000 × 50, a smoke test
    python benchmarks/imm.py --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from peers import peak_rss_mb, print_table, race  # noqa: E402

import jaxtrack  # noqa: E402
from jaxtrack.filters import InteractingMultipleModel, KalmanFilter, run_imm  # noqa: E402
from jaxtrack.models import ConstantVelocity, CoordinatedTurn, LinearGaussianModel  # noqa: E402
from jaxtrack.montecarlo import monte_carlo_map, normalized_squared_error, simulate  # noqa: E402

TAU = 1.0  # s
OMEGA = 0.05  # rad/s, the turn members' (known) turn rates ±ω and the truth's turns
Q_ACCEL = 0.5  # m²/s³, white-acceleration intensity per axis (truth and members)
SIGMA = 10.0  # m, position measurement noise
P_STAY = 0.95
TRANS = np.full((3, 3), (1.0 - P_STAY) / 2) + np.eye(3) * (P_STAY - (1.0 - P_STAY) / 2)
MU0 = np.full(3, 1.0 / 3.0)
H = np.hstack([np.eye(2), np.zeros((2, 2))])
R = SIGMA**2 * np.eye(2)
X0 = np.array([0.0, 0.0, 20.0, 0.0])
P0 = np.diag([100.0, 100.0, 10.0, 10.0]) ** 2
MEMBERS = ("CV", "CT +ω", "CT −ω")


def turn_schedule(num_steps: int) -> np.ndarray:
    """ω_k (rad/s), ``(T,)``: CV, +ω, CV, −ω, CV legs starting at 0, 20, 35, 50, 65 % of the run."""
    frac = np.arange(num_steps) / num_steps
    omega = np.zeros(num_steps)
    omega[(frac >= 0.20) & (frac < 0.35)] = OMEGA
    omega[(frac >= 0.50) & (frac < 0.65)] = -OMEGA
    return omega


def member_models():
    """CV, CT(+ω), CT(−ω) as ``LinearGaussianModel`` (F from the library's motion models)."""
    out = []
    for motion in (ConstantVelocity(TAU, noise_intensity=Q_ACCEL), CoordinatedTurn(TAU, turn_rate=OMEGA,
        noise_intensity=Q_ACCEL),
                   CoordinatedTurn(TAU, turn_rate=-OMEGA, noise_intensity=Q_ACCEL)):
        out.append(LinearGaussianModel(motion.transition_matrix(0), motion.noise_cov(0), H, R, X0, P0))
    return out


def make_imm():
    return InteractingMultipleModel([(KalmanFilter(), m) for m in member_models()], TRANS, MU0 @ TRANS)


def truth_model(num_steps: int) -> LinearGaussianModel:
    """The maneuvering truth: per-step ``F_k`` of ``CoordinatedTurn(turn_schedule)``."""
    ct = CoordinatedTurn(jnp.full(num_steps, TAU), turn_rate=jnp.asarray(turn_schedule(num_steps)),
                         noise_intensity=Q_ACCEL)
    F = jax.vmap(ct.transition_matrix)(jnp.arange(num_steps))
    return LinearGaussianModel(F, ct.noise_cov(0), H, R, X0, P0)


def simulate_batch(m, num_runs, num_steps, seed=0):
    keys = jax.random.split(jax.random.key(seed), num_runs)
    return jax.block_until_ready(jax.jit(jax.vmap(lambda k: simulate(m, k, num_steps)))(keys))


# ---------------------------------------------------------------------------------------------
# FilterPy: what a FilterPy user writes


def filterpy_imm(zs, truth=None):
    """FilterPy's ``IMMEstimator`` per run: combined means ``(R, T, 4)`` and mode probabilities
    ``(R, T, 3)``; with ``truth``, the per-step sums over runs of the position squared error,
    NEES and mode probabilities (the Monte Carlo job's metrics)."""
    from filterpy.kalman import IMMEstimator
    from filterpy.kalman import KalmanFilter as FPKalman

    models = [(np.asarray(m.F), np.asarray(m.Q)) for m in member_models()]
    runs, steps = zs.shape[:2]
    means = np.empty((runs, steps, 4))
    mus = np.empty((runs, steps, 3))
    sq_sum, nees_sum = np.zeros(steps), np.zeros(steps)
    for i, z_run in enumerate(zs):
        fs = []
        for F, Q in models:
            f = FPKalman(dim_x=4, dim_z=2)
            f.x, f.P, f.F, f.Q, f.H, f.R = X0.copy(), P0.copy(), F, Q, H, R
            fs.append(f)
        imm = IMMEstimator(fs, MU0.copy(), TRANS)
        for k, z in enumerate(z_run):
            imm.update(z)
            means[i, k] = imm.x
            mus[i, k] = imm.mu
            if truth is not None:
                e = truth[i, k] - imm.x  # NEES needs this step's combined covariance
                nees_sum[k] += e @ np.linalg.solve(imm.P, e)
            imm.predict()
        if truth is not None:
            sq_sum += np.sum((truth[i, :, :2] - means[i, :, :2]) ** 2, axis=-1)
    if truth is None:
        return means, mus
    return sq_sum, nees_sum, mus.sum(axis=0)


def numpy_truth(num_steps):
    """The truth's ``F_k`` ``(T, 4, 4)`` and the Cholesky factors of ``Q`` and ``P0`` as numpy
    arrays (built once, outside the timed FilterPy job)."""
    Fs = np.asarray(truth_model(num_steps).F)
    Q = np.asarray(ConstantVelocity(TAU, noise_intensity=Q_ACCEL).noise_cov(0))
    return Fs, np.linalg.cholesky(Q), np.linalg.cholesky(P0)


def filterpy_monte_carlo(num_runs, np_truth, seed=1):
    """numpy simulation of the truth (same model), FilterPy's IMM and the metrics, per run."""
    rng = np.random.default_rng(seed)
    Fs, Lq, Lp = np_truth
    num_steps = Fs.shape[0]
    truth = np.empty((num_runs, num_steps, 4))
    zs = np.empty((num_runs, num_steps, 2))
    for i in range(num_runs):
        x = X0 + Lp @ rng.standard_normal(4)  # first_step="update": the prior draw is x_0
        for k in range(num_steps):
            if k:
                x = Fs[k] @ x + Lq @ rng.standard_normal(4)
            truth[i, k] = x
            zs[i, k] = H @ x + SIGMA * rng.standard_normal(2)
    return filterpy_imm(zs, truth)


# ---------------------------------------------------------------------------------------------
# jaxtrack


def jaxtrack_filter_job(imm):
    """Combined means ``(R, T, 4)`` and mode probabilities ``(R, T, 3)`` of a batch of runs."""
    return jax.jit(jax.vmap(lambda z: (lambda r: (r.filtered_mean, r.mode_probs))(run_imm(imm, z, throw=False))))


def one_run(key, args):
    """One Monte Carlo run for ``monte_carlo_map``: simulate, run the IMM, score per step."""
    truth, imm = args
    traj = simulate(truth, key, truth.num_steps)
    res = run_imm(imm, traj.measurements, throw=False)
    err = traj.states - res.filtered_mean
    nees = jax.vmap(normalized_squared_error)(err, res.filtered_cov)
    return {"pos_sq": jnp.sum(err[:, :2] ** 2, axis=-1), "nees": nees, "mode_probs": res.mode_probs}


def monte_carlo_map_job(truth, imm, num_runs):
    return lambda: monte_carlo_map(one_run, jax.random.key(1), num_runs, args=(truth, imm))


def imm_monte_carlo_available() -> bool:
    """Whether ``jaxtrack.montecarlo.monte_carlo`` accepts an IMM as ``filter`` (issue 20)."""
    import inspect

    from jaxtrack.montecarlo import _run

    return "InteractingMultipleModel" in inspect.getsource(_run)


# ---------------------------------------------------------------------------------------------


def bench(num_runs, num_steps, repeats, fp_runs) -> dict:
    truth = truth_model(num_steps)
    imm = make_imm()
    traj = simulate_batch(truth, num_runs, num_steps)
    zs, zs_np = traj.measurements, np.asarray(traj.measurements)
    fp_runs = min(fp_runs, num_runs)
    scale = num_runs / fp_runs
    total = num_runs * num_steps
    jt = jaxtrack_filter_job(imm)
    np_truth = numpy_truth(num_steps)

    # Agreement on the FilterPy subset (and a sanity check that the modes switch).
    t0 = time.perf_counter()
    jt_mean, jt_mu = (np.asarray(a) for a in jt(zs[:fp_runs]))
    fp_mean, fp_mu = filterpy_imm(zs_np[:fp_runs])
    d_mean = float(np.max(np.abs(jt_mean - fp_mean)))
    d_mu = float(np.max(np.abs(jt_mu - fp_mu)))
    assert d_mean < 1e-8, f"jaxtrack and FilterPy IMM means differ by {d_mean} m"
    print(f"  agreement on {fp_runs} runs (warm-up {time.perf_counter() - t0:.1f} s): "
          f"max |Δ mean| {d_mean:.1e} m, max |Δ mode prob| {d_mu:.1e}")

    filter_job = {
        "jaxtrack jit(vmap(run_imm))": (lambda: jt(zs), 1.0),
        "FilterPy IMMEstimator": (lambda: filterpy_imm(zs_np[:fp_runs]), scale),
    }
    mc_job = {"jaxtrack monte_carlo_map": (monte_carlo_map_job(truth, imm, num_runs), 1.0)}
    if imm_monte_carlo_available():
        from jaxtrack.montecarlo import monte_carlo

        mc_job["jaxtrack monte_carlo"] = (lambda: monte_carlo(
            truth, jax.random.key(1), num_runs, num_steps=num_steps, filter=imm, progress=False).nees, 1.0)
    mc_job["FilterPy IMMEstimator"] = (lambda: filterpy_monte_carlo(fp_runs, np_truth), scale)

    rates = {}
    for job, contenders in (("filter", filter_job), ("monte_carlo", mc_job)):
        times = race(contenders, repeats)
        rates[job] = {k: total / t for k, t in times.items()}

    # Scores (from the full jaxtrack Monte Carlo and the FilterPy subset), as a sanity check.
    sums = monte_carlo_map_job(truth, imm, num_runs)()
    rmse = np.sqrt(np.asarray(sums["pos_sq"]) / num_runs)
    nees = np.asarray(sums["nees"]) / num_runs
    mu = np.asarray(sums["mode_probs"]) / num_runs
    fsq, fnees, fmu = filterpy_monte_carlo(fp_runs, np_truth)
    if imm_monte_carlo_available():
        # Same run keys (fold_in(key, i)) and draws as simulate: the same runs as the map job.
        from jaxtrack.montecarlo import monte_carlo

        res = monte_carlo(truth, jax.random.key(1), num_runs, num_steps=num_steps, filter=imm, progress=False)
        lib = {"monte_carlo_time_avg_position_rmse_m": float(np.sqrt(np.mean(np.asarray(res.rmse((0, 1))) ** 2))),
               "monte_carlo_anees_over_4": float(res.anees),
               "monte_carlo_max_abs_mode_prob_difference_vs_map": float(np.max(np.abs(np.asarray(res.mode_probs) - mu)))}
    else:
        lib = {}
    scores = {
        "jaxtrack_time_avg_position_rmse_m": float(np.sqrt(np.mean(rmse**2))),
        "jaxtrack_anees_over_4": float(np.mean(nees) / 4),
        "jaxtrack_mean_mode_probs_mid_turn": mu[int(0.3 * num_steps)].tolist(),
        "filterpy_subset_time_avg_position_rmse_m": float(np.sqrt(np.mean(fsq / fp_runs))),
        "filterpy_subset_anees_over_4": float(np.mean(fnees / fp_runs) / 4),
        **lib,
    }
    return {"runs": num_runs, "steps": num_steps, "filterpy_runs": fp_runs, "steps_per_s": rates,
            "max_abs_mean_difference_m": d_mean, "max_abs_mode_prob_difference": d_mu, "scores": scores,
            "imm_monte_carlo_available": imm_monte_carlo_available()}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1,000 runs × 50 steps (a smoke test)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--fp-runs", type=int, default=None, help="FilterPy subset (default 20; quick 5)")
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    args = parser.parse_args()
    runs, steps, fp_runs = (1000, 50, 5) if args.quick else (10_000, 200, 20)
    fp_runs = args.fp_runs or fp_runs
    machine = {"cores": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
               "jax": jax.__version__, "jaxtrack": getattr(jaxtrack, "__version__", "dev"), "dtype": "float64"}
    print(f"IMM (CV, CT ±{OMEGA} rad/s, KF members) vs FilterPy IMMEstimator, float64, "
          f"{machine['cores']} cores, jax {machine['jax']}, best of {args.repeats}")
    print(f"command: python {' '.join(sys.argv)}")
    # The machine may be shared: the load average says how much (jaxtrack uses every core).
    load_before = os.getloadavg()
    print(f"load average before: {load_before[0]:.2f}")
    row = bench(runs, steps, args.repeats, fp_runs)
    row["load_average_before_after"] = [load_before[0], os.getloadavg()[0]]
    for job, rates in row["steps_per_s"].items():
        ours = [k for k in rates if k.startswith("jaxtrack")]
        print_table(f"IMM, 3 members, {runs} runs × {steps} steps — {job} "
                    f"(FilterPy: {row['filterpy_runs']} runs, scaled)", rates, ours)
    s = row["scores"]
    print(f"\n  scores: time-averaged position RMSE {s['jaxtrack_time_avg_position_rmse_m']:.2f} m "
          f"(FilterPy subset {s['filterpy_subset_time_avg_position_rmse_m']:.2f} m), "
          f"ANEES/4 {s['jaxtrack_anees_over_4']:.3f} (FilterPy subset {s['filterpy_subset_anees_over_4']:.3f}), "
          f"mean mode probs at 30 % (+ω turn) {np.round(s['jaxtrack_mean_mode_probs_mid_turn'], 3).tolist()}")
    if "monte_carlo_anees_over_4" in s:
        print(f"  monte_carlo (same runs): RMSE {s['monte_carlo_time_avg_position_rmse_m']:.2f} m, "
              f"ANEES/4 {s['monte_carlo_anees_over_4']:.3f}, max |Δ mode prob| vs monte_carlo_map "
              f"{s['monte_carlo_max_abs_mode_prob_difference_vs_map']:.1e}")
    print(f"\npeak RSS of this process: {peak_rss_mb():.0f} MB; load average after: {os.getloadavg()[0]:.2f}")
    if args.json:
        report = {"machine": machine, "command": "python " + " ".join(sys.argv), "rows": [row],
                  "peak_rss_mb": peak_rss_mb()}
        with open(args.json, "w") as f:
            json.dump(report, f, indent=2)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

"""Offline sensor calibration by maximum likelihood (issue 22, application): the registration
study's 8 identifiable biases from one recorded track, with intervals, against the truth and
against the OBEM filter's final online estimate on the same tracks.

Scenario: the paper's (spec §4.1) with zero pitch and roll (``yaw_only_scenario``), where the 8
OBEM states are exactly the identifiable biases and the calibration model is correctly specified.
Tracks: run ``i`` is ``simulate_run(scenario, fold_in(key(2022), i))`` — the study's simulator, so
OBEM's estimates are those :func:`~jaxtrack.applications.obem_registration.run_squared_errors`
would form on the same track. All fits of a test run as one ``jit(vmap(...))``; one extra
noise-free track rides in the same batch (one compilation).

Acceptance (coverage): for **each** of the 8 bias components separately, the fraction of tracks
whose 95% interval covers the truth lies inside the exact binomial 99% band around 0.95
(``scipy.stats.binom.ppf([0.005, 0.995], n, 0.95)/n``). CI runs n = 40 tracks (band [0.85, 1]);
the issue's n = 200 (band [0.905, 0.985]) is ``@pytest.mark.slow``.

Measured (n = 200, this machine under load: compile 127–210 s, run 200–264 s): coverage
[0.97 0.96 0.965 0.925 0.96 0.965 0.945 0.935]; RMSE(MLE)/RMSE(OBEM final) per component
[1.05 1.46 1.27 1.06 1.82 1.56 1.53 1.01]; the MLE's log-likelihood exceeds that at OBEM's
estimate on every track (by ≥ 2.9 nats) and that at the truth (by ≥ 0.9).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from jaxtrack import InputError
from jaxtrack.applications.obem_registration import calibration as cal
from jaxtrack.applications.obem_registration import frames, montecarlo, scenario as sc
from jaxtrack.applications.obem_registration.estimators import prior_cov
from jaxtrack.filters import KalmanFilter, run_filter

SCENARIO = cal.yaw_only_scenario()
TRUTH = np.asarray(cal.calibration_truth(SCENARIO))
SCALE = jnp.asarray(cal.CALIBRATION_SCALE)
KEY = 2022
N_CI, N_FULL = 40, 200


def _one(scans):
    """Calibrate one track; OBEM's final estimate; the log-likelihood at truth and at OBEM's estimate."""
    res = cal.calibrate(scans, SCENARIO)
    obem = cal.obem_final_estimate(scans, SCENARIO)
    build, z = cal.likelihood_model(scans, SCENARIO)

    def ll(beta):
        return run_filter(KalmanFilter(), build({"bias": beta / SCALE}), z, throw=False).log_likelihood

    return res, obem, ll(obem), ll(jnp.asarray(TRUTH))


@functools.lru_cache(maxsize=None)
def _batch(n):
    """``n`` noisy tracks (keys fold_in(2022, i)) plus one noise-free track (last), fitted in one batch."""
    keys = jax.vmap(lambda i: jax.random.fold_in(jax.random.key(KEY), i))(jnp.arange(n))
    noisy = jax.vmap(lambda k: sc.simulate_run(SCENARIO, k, True, True))(keys)
    clean = sc.simulate_run(SCENARIO, jax.random.key(7), False, True)
    scans = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b[None]]), noisy, clean)
    out = jax.jit(jax.vmap(_one))(scans)
    return jax.tree_util.tree_map(np.asarray, out)


def _check_batch(n):
    res, obem, ll_obem, ll_truth = _batch(n)
    assert res.ok.all() and res.converged.all(), (res.ok, res.converged)

    # 1. Noise-free track: the fit recovers the truth (exact map, exact gain convention) far
    #    inside its standard error.
    err0 = (res.estimate[-1] - TRUTH) / res.standard_error[-1]
    assert np.max(np.abs(err0)) < 1e-3, err0

    est, se, lo, hi = (a[:n] for a in (res.estimate, res.standard_error, res.lower, res.upper))
    obem, ll, ll_obem, ll_truth = obem[:n], res.log_likelihood[:n], ll_obem[:n], ll_truth[:n]
    # Wald intervals at 95%.
    np.testing.assert_allclose(hi - est, 1.959963984540054 * se, rtol=1e-12)

    # 2. Coverage, per component, inside the exact binomial 99% band.
    covered = (lo <= TRUTH) & (TRUTH <= hi)
    cover = covered.mean(axis=0)
    band = stats.binom.ppf([0.005, 0.995], n, 0.95) / n
    pooled_band = stats.binom.ppf([0.005, 0.995], 8 * n, 0.95) / (8 * n)
    print(f"n = {n}: coverage per component {np.round(cover, 3)}, band {band}; pooled {covered.mean():.3f} "
          f"(band if independent {pooled_band})")
    assert np.all((band[0] <= cover) & (cover <= band[1])), (cover, band)

    # 3. It is the maximum: above the likelihood at OBEM's online estimate and at the truth.
    print(f"min ℓ(MLE) − ℓ(OBEM) = {np.min(ll - ll_obem):.2f}, min ℓ(MLE) − ℓ(truth) = {np.min(ll - ll_truth):.2f}")
    assert np.all(ll > ll_obem) and np.all(ll > ll_truth)

    # 4. RMSE against OBEM's final online estimate on the same tracks. Measured: n = 200,
    #    MLE/OBEM = 1.01–1.82; n = 40, 0.97–1.09. On tracks where Δr and k_r are nearly collinear
    #    (the MLE's σ(Δr2) ranges 22 m … 1.6 km) OBEM's prior P_0 (σ 1 km) shrinks and wins
    #    (ratio 1.03–1.92 on the half with the larger σ(Δr2)); on the other half they tie
    #    (0.88–1.03). The MLE's errors match its own SEs: std of (β̂ − β)/σ̂ = 0.90–1.07 (n = 200).
    rmse_mle = np.sqrt(np.mean((est - TRUTH) ** 2, axis=0))
    rmse_obem = np.sqrt(np.mean((obem - TRUTH) ** 2, axis=0))
    ratio = rmse_mle / rmse_obem
    t_std = np.std((est - TRUTH) / se, axis=0)
    print("RMSE MLE ", rmse_mle, "\nRMSE OBEM", rmse_obem, "\nratio    ", np.round(ratio, 3),
          "\nstd of standardised errors", np.round(t_std, 3))
    assert np.all((0.7 < ratio) & (ratio < 2.5)), ratio
    assert np.all((0.7 < t_std) & (t_std < 1.3)), t_std
    return res, obem


def test_calibration_coverage_and_rmse_ci():
    _check_batch(N_CI)


@pytest.mark.slow
def test_calibration_coverage_and_rmse_200():
    _check_batch(N_FULL)


def test_same_tracks_as_the_study_monte_carlo():
    # OBEM's estimate here is the study's own: run_squared_errors' elevation error on track 0.
    key = jax.random.fold_in(jax.random.key(KEY), 0)
    scans = sc.simulate_run(SCENARIO, key, True, True)
    obem = cal.obem_final_estimate(scans, SCENARIO)
    args = montecarlo.RunArgs(SCENARIO, prior_cov("aam"), prior_cov("obem"))
    sq = montecarlo.run_squared_errors(key, args)
    truth = frames.obem_truth(SCENARIO.offset_bias, SCENARIO.attitude_bias)
    np.testing.assert_allclose(sq.elevation[1, :, -1], (obem[jnp.array([3, 7])] - truth[jnp.array([3, 7])]) ** 2,
                               rtol=1e-10)


def test_likelihood_mean_is_the_exact_registration_map():
    scans = sc.simulate_scans(SCENARIO, jax.random.key(3))
    pr = jnp.array([[1.0, 0.5], [-0.7, 0.3]]) * frames.DEG
    build, z = cal.likelihood_model(scans, SCENARIO, pitch_roll=pr)
    beta = jnp.asarray(TRUTH) + jnp.array([50.0, 0.002, 0.3 * frames.DEG, -0.2 * frames.DEG] * 2)
    aam = jnp.concatenate([beta[:4], beta[4:], jnp.zeros(1), pr[0], jnp.zeros(1), pr[1]])
    ref = jax.vmap(frames.nonlinear_pseudo_measurement, in_axes=(None, 0, 0, 0, 0))(
        aam, scans.raw[0], scans.sites[0], scans.raw[1], scans.sites[1])
    np.testing.assert_allclose(build.mean(beta), ref, atol=1e-7)
    # Its Jacobian at β = 0 (no pitch/roll) is eq. (47)'s H_OBEM, which the linearised variant uses.
    build0, _ = cal.likelihood_model(scans, SCENARIO)
    jac = jax.jacfwd(build0.mean)(jnp.zeros(8))
    np.testing.assert_allclose(jac, build0.H, rtol=1e-9, atol=1e-6)
    # The likelihood is Σ log N(Z; h(β), R) (the unit state adds nothing).
    ll = run_filter(KalmanFilter(), build({"bias": beta / SCALE}), z).log_likelihood
    resid = z - build.mean(beta)
    direct = jnp.sum(jax.vmap(lambda r, R: jax.scipy.stats.multivariate_normal.logpdf(r, jnp.zeros(3), R))(resid, build.R))
    np.testing.assert_allclose(ll, direct, rtol=1e-12)


def test_truth_gain_convention():
    # r_m = (1 + k) r_t + Δr  ⇔  r_t = (1 − k') r_m − Δr' with k' = k/(1+k), Δr' = Δr/(1+k).
    t = np.asarray(cal.calibration_truth(SCENARIO))
    k, dr, r_t = 0.01, 300.0, 8.0e4
    r_m = (1 + k) * r_t + dr
    assert abs((1 - t[1]) * r_m - t[0] - r_t) < 1e-8
    np.testing.assert_allclose(t[[2, 6]], 0.0, atol=1e-15)  # Δθ − Δφ = 2° − 2°


def test_input_errors():
    scans = sc.simulate_scans(SCENARIO, jax.random.key(0))
    with pytest.raises(InputError, match="`scans`"):
        cal.calibrate(scans.raw, SCENARIO)
    with pytest.raises(InputError, match="`scenario`"):
        cal.calibrate(scans, None)
    with pytest.raises(InputError, match="`pitch_roll`"):
        cal.calibrate(scans, SCENARIO, pitch_roll=jnp.zeros(4))
    with pytest.raises(InputError, match="`level`"):
        cal.calibrate(scans, SCENARIO, level=1.5)
    with pytest.raises(InputError, match="`initial`"):
        cal.calibrate(scans, SCENARIO, initial=jnp.zeros(4))
    with pytest.raises(InputError, match="`scenario`"):
        cal.calibration_truth("paper")

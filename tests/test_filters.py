"""Filters against independent references: FilterPy, NumPy batch solutions, finite differences.

Every comparison is numerical; tolerances are stated per test. ``assert_close`` compares with
``rtol`` and an absolute tolerance scaled to the largest entry of the reference array.
"""

import re

import filterpy.kalman
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import (
    assert_close,
    dense_solution,
    joseph_covariances,
    model_arrays,
    observed_matrix,
    random_linear_model,
    simulate_linear,
)

from jaxtrack import InputError
from jaxtrack.filters import (
    ExtendedKalmanFilter,
    KalmanFilter,
    UnscentedKalmanFilter,
    rts_smoother,
    run_filter,
)
from jaxtrack.models import LinearGaussianModel, NonlinearGaussianModel

T = 12  # one length for most tests, so that compiled scans are reused
FIRST_STEPS = ["predict", "update"]


def make_case(seed, n, m, *, T=T, offset=False, first_step="update", per_step_measurement=False):
    rng = np.random.default_rng(seed)
    model = random_linear_model(rng, n, m, T, offset=offset, per_step_measurement=per_step_measurement)
    _, zs = simulate_linear(rng, model, T, first_step)
    return model, zs, rng


# ---------------------------------------------------------------------------------------------
# 1. Kalman filter against FilterPy
# ---------------------------------------------------------------------------------------------


def filterpy_run(model, zs, observed, first_step):
    """FilterPy's predict/update loop; per step, update with the observed rows of H, R and z only.

    ``observed`` is ``(T, m)``; a step with no observed component calls ``update(None)`` (FilterPy
    then copies the prior to the posterior). ``first_step="update"`` skips the first predict, so the
    filter starts from ``x, P`` = the prior at the first measurement.
    """
    T_, m = observed.shape
    a = model_arrays(model, T_)
    n = a.m0.shape[0]
    kf = filterpy.kalman.KalmanFilter(dim_x=n, dim_z=m)
    kf.x = a.m0.copy()
    kf.P = a.P0.copy()
    out = {k: [] for k in ("pm", "pc", "fm", "fc")}
    innov = np.zeros((T_, m))
    S = np.zeros((T_, m, m))
    ll = 0.0
    for k in range(T_):
        if k > 0 or first_step == "predict":
            kf.predict(F=a.F[k], Q=a.Q[k], u=a.b[k], B=np.eye(n))
        out["pm"].append(kf.x.copy())
        out["pc"].append(kf.P.copy())
        obs = observed[k]
        if obs.any():
            kf.update(zs[k][obs], R=a.R[k][np.ix_(obs, obs)], H=a.H[k][obs])
            ll += kf.log_likelihood
            innov[k, obs] = kf.y
            S[k][np.ix_(obs, obs)] = kf.S
        else:
            kf.update(None)
        out["fm"].append(kf.x.copy())
        out["fc"].append(kf.P.copy())
    return {k: np.array(v) for k, v in out.items()} | {"innov": innov, "S": S, "ll": ll}


def assert_matches_filterpy(res, ref, observed, rtol):
    assert_close(res.predicted_mean, ref["pm"], rtol, err_msg="predicted mean")
    assert_close(res.predicted_cov, ref["pc"], rtol, err_msg="predicted cov")
    assert_close(res.filtered_mean, ref["fm"], rtol, err_msg="filtered mean")
    assert_close(res.filtered_cov, ref["fc"], rtol, err_msg="filtered cov")
    assert_close(res.innovation, ref["innov"], rtol, err_msg="innovation")
    # S agrees on the observed block; jaxtrack puts the identity on the missing block.
    both = observed[:, :, None] & observed[:, None, :]
    eye_missing = np.einsum("ti,ij->tij", (~observed).astype(float), np.eye(observed.shape[1]))
    assert_close(res.innovation_cov, np.where(both, ref["S"], 0.0) + eye_missing, rtol)
    np.testing.assert_array_equal(res.num_observed, observed.sum(axis=1))
    np.testing.assert_allclose(float(res.log_likelihood), ref["ll"], rtol=rtol)
    assert bool(res.ok)


@pytest.mark.parametrize("first_step", FIRST_STEPS)
@pytest.mark.parametrize(("n", "m", "offset"), [(2, 1, False), (4, 2, True), (6, 3, False)])
def test_kalman_matches_filterpy_missing_steps(n, m, offset, first_step):
    """Per-step F, Q (nonuniform τ), whole steps missing: all moments and log-lik to 1e-10."""
    model, zs, rng = make_case(10 * n + m, n, m, offset=offset, first_step=first_step)
    mask = np.ones(T, bool)
    mask[[2, 3, 7]] = False  # includes two consecutive missing steps
    zs = np.where(mask[:, None], zs, 1e6)  # values at missing steps must be ignored
    res = run_filter(KalmanFilter(), model, zs, mask=mask, first_step=first_step)
    observed = observed_matrix(mask, T, m)
    ref = filterpy_run(model, zs, observed, first_step)
    assert_matches_filterpy(res, ref, observed, rtol=1e-10)
    # Missing steps: no update at all.
    np.testing.assert_array_equal(res.filtered_mean[~mask], res.predicted_mean[~mask])
    np.testing.assert_array_equal(res.innovation[~mask], 0.0)
    if first_step == "update":  # the prior sits at step 0
        np.testing.assert_array_equal(res.predicted_mean[0], model.initial_mean)
        np.testing.assert_array_equal(res.predicted_cov[0], model.initial_cov)


# ---------------------------------------------------------------------------------------------
# 2. Partially missing measurement vectors
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("first_step", FIRST_STEPS)
def test_partial_mask_matches_reduced_update(first_step):
    """A (T, m) mask equals updating with only the observed rows of H, R, z (FilterPy), 1e-10."""
    n, m = 6, 3
    model, zs, rng = make_case(63, n, m, first_step=first_step)
    observed = rng.random((T, m)) < 0.6
    observed[1] = False  # a whole step missing
    observed[4] = True  # a full step
    observed[5] = [True, False, False]
    observed[6] = [False, True, True]
    zs = np.where(observed, zs, np.nan)  # unobserved components may hold NaN
    res = run_filter(KalmanFilter(), model, zs, mask=observed, first_step=first_step)
    ref = filterpy_run(model, np.nan_to_num(zs), observed, first_step)
    assert_matches_filterpy(res, ref, observed, rtol=1e-10)


# ---------------------------------------------------------------------------------------------
# 3. EKF and UKF reduce to the KF on a linear model
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "other",
    [
        ExtendedKalmanFilter(),
        UnscentedKalmanFilter(),
        UnscentedKalmanFilter(alpha=0.5, beta=2.0, kappa=0.0),
    ],
    ids=["ekf", "ukf-cubature", "ukf-a0.5-b2"],
)
def test_ekf_ukf_reduce_to_kf_on_linear_model(other):
    """Filtered/predicted moments, innovations, S and log-lik equal the KF's to 1e-10."""
    n, m = 4, 2
    model, zs, rng = make_case(42, n, m, offset=True, first_step="predict")
    observed = rng.random((T, m)) < 0.7
    observed[3] = False
    kf = run_filter(KalmanFilter(), model, zs, mask=observed, first_step="predict")
    res = run_filter(other, model, zs, mask=observed, first_step="predict")
    for name in ("predicted_mean", "predicted_cov", "filtered_mean", "filtered_cov",
                 "innovation", "innovation_cov"):
        assert_close(getattr(res, name), getattr(kf, name), 1e-10, err_msg=name)
    np.testing.assert_allclose(float(res.log_likelihood), float(kf.log_likelihood), rtol=1e-10)
    assert bool(res.ok)


# ---------------------------------------------------------------------------------------------
# 4./5. RTS smoother and log-likelihood against the dense batch solution
# ---------------------------------------------------------------------------------------------

SMALL_T = 8


@pytest.fixture(scope="module")
def small_case():
    rng = np.random.default_rng(5)
    model = random_linear_model(rng, 3, 2, SMALL_T, offset=True)
    _, zs = simulate_linear(rng, model, SMALL_T, "predict")
    partial = np.ones((SMALL_T, 2), bool)
    partial[2] = False
    partial[5, 0] = False
    return model, zs, {"none": None, "steps": np.arange(SMALL_T) % 3 != 1, "partial": partial}


@pytest.mark.parametrize("mask_kind", ["none", "partial"])
@pytest.mark.parametrize("first_step", FIRST_STEPS)
def test_rts_smoother_matches_dense_solution(small_case, first_step, mask_kind):
    """Smoothed means and marginal covariances equal the batch conditional, 1e-8."""
    model, zs, masks = small_case
    mask = masks[mask_kind]
    dense = dense_solution(model, zs, mask, first_step)
    sm = rts_smoother(model, zs, mask=mask, first_step=first_step)
    assert_close(sm.smoothed_mean, dense.smoothed_mean, 1e-8)
    assert_close(sm.smoothed_cov, dense.smoothed_cov, 1e-8)
    # The last smoothed state is the last filtered one; smoothing shrinks every other covariance.
    np.testing.assert_array_equal(sm.smoothed_mean[-1], sm.filtered.filtered_mean[-1])
    shrink = np.linalg.eigvalsh(np.asarray(sm.filtered.filtered_cov - sm.smoothed_cov))
    assert shrink.min() > -1e-12
    assert np.trace(sm.smoothed_cov[0]) < np.trace(sm.filtered.filtered_cov[0]) - 1e-6


@pytest.mark.parametrize("mask_kind", ["none", "steps", "partial"])
@pytest.mark.parametrize("first_step", FIRST_STEPS)
def test_log_likelihood_equals_dense_marginal(small_case, first_step, mask_kind):
    """Σ_k log N(y_k; 0, S_k) = log N(z_obs; E z_obs, Cov z_obs) of the joint Gaussian, 1e-9."""
    model, zs, masks = small_case
    mask = masks[mask_kind]
    dense = dense_solution(model, zs, mask, first_step)
    res = run_filter(KalmanFilter(), model, zs, mask=mask, first_step=first_step)
    np.testing.assert_allclose(float(res.log_likelihood), dense.log_likelihood, rtol=1e-9)
    # The filtered final state is the batch conditional of the last state.
    assert_close(res.final_mean, dense.smoothed_mean[-1], 1e-8)
    assert_close(res.final_cov, dense.smoothed_cov[-1], 1e-8)


# ---------------------------------------------------------------------------------------------
# 6. Transformations: jit, vmap, grad, jacfwd
# ---------------------------------------------------------------------------------------------


def test_jit_of_run_filter_matches_eager():
    model, zs, _ = make_case(7, 4, 2)
    mask = np.ones(T, bool)
    mask[5] = False

    @jax.jit
    def f(model, zs):
        r = run_filter(KalmanFilter(), model, zs, mask=mask)
        return r.filtered_mean, r.filtered_cov, r.log_likelihood

    eager = run_filter(KalmanFilter(), model, zs, mask=mask)
    jm, jc, jll = f(model, jnp.asarray(zs))
    assert_close(jm, eager.filtered_mean, 1e-12)
    assert_close(jc, eager.filtered_cov, 1e-12)
    np.testing.assert_allclose(float(jll), float(eager.log_likelihood), rtol=1e-12)


def test_vmap_over_measurement_batches_matches_loop():
    model, _, rng = make_case(8, 4, 2)
    batch = np.stack([simulate_linear(rng, model, T, "update")[1] for _ in range(5)])
    masks = rng.random((5, T, 2)) < 0.8

    def run(z, mask):
        return run_filter(KalmanFilter(), model, z, mask=mask, throw=False)

    batched = jax.vmap(run)(batch, masks)
    for i in range(batch.shape[0]):
        single = run_filter(KalmanFilter(), model, batch[i], mask=masks[i])
        assert_close(batched.filtered_mean[i], single.filtered_mean, 1e-12)
        assert_close(batched.filtered_cov[i], single.filtered_cov, 1e-12)
        np.testing.assert_allclose(float(batched.log_likelihood[i]), float(single.log_likelihood), rtol=1e-12)
    assert batched.ok.shape == (5,) and bool(jnp.all(batched.ok))


GRAD_T = 8
GRAD_MASK = np.arange(GRAD_T) != 4  # one missing step on the way


def _cv_model(params):
    """Per-step CV model: F_k = [[1, τ_k], [0, 1]], Q_k = τ_k Q, H = [1, 0]."""
    tau = params["tau"]
    one, zero = jnp.ones_like(tau), jnp.zeros_like(tau)
    F = jnp.stack([jnp.stack([one, tau], -1), jnp.stack([zero, one], -1)], -2)
    Q = tau[:, None, None] * params["Q"][None]
    H = jnp.array([[1.0, 0.0]])
    return LinearGaussianModel(F, Q, H, params["R"], jnp.array([0.5, -0.2]), params["P0"])


@pytest.fixture(scope="module")
def grad_case():
    rng = np.random.default_rng(11)
    params = {
        "tau": rng.uniform(0.05, 0.3, GRAD_T),
        "Q": np.array([[0.3, 0.05], [0.05, 0.8]]),
        "R": np.array([[0.2]]),
        "P0": np.array([[1.5, 0.2], [0.2, 0.7]]),
    }
    model = _cv_model({k: jnp.asarray(v) for k, v in params.items()})
    _, zs = simulate_linear(rng, model, GRAD_T, "predict")
    return params, zs


def _objectives(zs, first_step):
    def loglik(params):
        return run_filter(KalmanFilter(), _cv_model(params), zs, mask=GRAD_MASK,
                          first_step=first_step).log_likelihood

    def final_trace(params):
        return jnp.trace(run_filter(KalmanFilter(), _cv_model(params), zs, mask=GRAD_MASK,
                                    first_step=first_step, save="final").final_cov)

    return {"loglik": loglik, "final_trace": final_trace}


def _directions(params, rng):
    """Unit perturbations of each τ_k and random symmetric directions for Q, R, P0."""
    out = []
    for k in range(params["tau"].shape[0]):
        d = {name: np.zeros_like(v) for name, v in params.items()}
        d["tau"][k] = 1.0
        out.append((f"tau[{k}]", d))
    for name in ("Q", "R", "P0"):
        d = {name2: np.zeros_like(v) for name2, v in params.items()}
        A = rng.standard_normal(params[name].shape)
        d[name] = 0.5 * (A + A.T)
        out.append((name, d))
    return out


@pytest.mark.parametrize(
    ("objective", "first_step"),
    [("loglik", "predict"), ("loglik", "update"), ("final_trace", "predict")],
)
def test_grad_matches_finite_differences(grad_case, objective, first_step):
    """jax.grad w.r.t. per-step τ, Q, R, P0 vs central differences (rel 1e-6, abs 1e-8).

    Gradient entries here are of order 1e-3 to 5. ``jax.jacfwd`` equals ``jax.grad`` to 1e-10.
    """
    params, zs = grad_case
    fn = _objectives(zs, first_step)[objective]
    jparams = {k: jnp.asarray(v) for k, v in params.items()}
    grad = jax.grad(fn)(jparams)
    h = 1e-5
    rng = np.random.default_rng(3)
    for name, d in _directions(params, rng):
        plus = {k: jnp.asarray(params[k] + h * d[k]) for k in params}
        minus = {k: jnp.asarray(params[k] - h * d[k]) for k in params}
        fd = (float(fn(plus)) - float(fn(minus))) / (2 * h)
        ad = sum(float(jnp.sum(grad[k] * d[k])) for k in params)
        assert ad == pytest.approx(fd, rel=1e-6, abs=1e-8), name
    if first_step == "update":
        # The prior sits at step 0, so τ_0 (the interval before it) does not enter at all.
        assert float(grad["tau"][0]) == 0.0
    else:
        assert abs(float(grad["tau"][0])) > 1e-6
    if objective == "loglik":  # forward mode: one more compilation, so only here
        fwd = jax.jacfwd(fn)(jparams)
        for k in params:
            assert_close(fwd[k], grad[k], 1e-10, err_msg=k)


# ---------------------------------------------------------------------------------------------
# 7. External gain
# ---------------------------------------------------------------------------------------------


def test_external_gain():
    """Optimal gains fed back reproduce the KF (1e-10); a suboptimal gain's P is the Joseph one."""
    n, m = 4, 2
    model, zs, _ = make_case(77, n, m, offset=True)
    mask = np.ones(T, bool)
    mask[6] = False
    opt = run_filter(KalmanFilter(), model, zs, mask=mask)
    a = model_arrays(model, T)
    # W_k = P_{k/k-1} H_kᵀ S_k⁻¹ from the first run's own output.
    W = np.stack([
        np.asarray(opt.predicted_cov[k]) @ a.H[k].T @ np.linalg.inv(np.asarray(opt.innovation_cov[k]))
        for k in range(T)
    ])
    fed = run_filter(KalmanFilter(gain=W), model, zs, mask=mask)
    assert_close(fed.filtered_cov, opt.filtered_cov, 1e-10)
    assert_close(fed.filtered_mean, opt.filtered_mean, 1e-10)
    np.testing.assert_allclose(float(fed.log_likelihood), float(opt.log_likelihood), rtol=1e-10)
    # Optimal gain also agrees with the Joseph recursion of the reference.
    _, opt_ref = joseph_covariances(model, W, T, mask)
    assert_close(opt.filtered_cov, opt_ref, 1e-10)

    W_sub = 0.5 * W[-1]  # constant, deliberately suboptimal
    sub = run_filter(KalmanFilter(gain=W_sub), model, zs, mask=mask)
    pred_ref, filt_ref = joseph_covariances(model, W_sub, T, mask)
    assert_close(sub.predicted_cov, pred_ref, 1e-10)
    assert_close(sub.filtered_cov, filt_ref, 1e-10)
    # The mean uses the supplied gain too: x⁺ = x + W y.
    k = 3
    np.testing.assert_allclose(
        sub.filtered_mean[k], sub.predicted_mean[k] + W_sub @ np.asarray(sub.innovation[k]), rtol=1e-12
    )
    # The optimal filter's covariance is smaller in the Loewner order at every step.
    excess = np.linalg.eigvalsh(np.asarray(sub.filtered_cov - opt.filtered_cov))
    assert excess.min() > -1e-10 * float(np.abs(opt.filtered_cov).max())
    assert np.trace(sub.final_cov) > np.trace(opt.final_cov) * (1 + 1e-3)


# ---------------------------------------------------------------------------------------------
# 8. Angle residuals
# ---------------------------------------------------------------------------------------------


def _static_transition(x, k):
    return x


def _bearing(x, k):
    return jnp.arctan2(x[1:2], x[0:1])


def _bearing_model(predicted_bearing):
    m0 = 10.0 * jnp.array([jnp.cos(predicted_bearing), jnp.sin(predicted_bearing)])
    return NonlinearGaussianModel(
        _static_transition, _bearing, 0.01 * jnp.eye(2), jnp.array([[1e-4]]), m0,
        0.01 * jnp.eye(2), angle_components=(0,),
    )


@pytest.mark.parametrize(("z", "pred"), [(3.1, -3.1), (-3.1, 3.1)])
def test_bearing_innovation_wraps(z, pred):
    """Measured ±3.1 rad, predicted ∓3.1 rad: the innovation is ±(6.2 − 2π) ≈ ∓0.083, not ±6.2."""
    expected = np.sign(z) * (6.2 - 2 * np.pi)
    model = _bearing_model(pred)
    ekf = run_filter(ExtendedKalmanFilter(), model, np.array([[z]]))
    assert float(ekf.innovation[0, 0]) == pytest.approx(expected, abs=1e-12)
    assert abs(expected) == pytest.approx(0.0832, abs=1e-4)
    # The update moves the bearing along the short arc through ±π, between prediction and z.
    post = float(np.arctan2(ekf.final_mean[1], ekf.final_mean[0]))
    assert abs(post) > 3.1
    # UKF: same residual, up to the small sigma-point offset of the predicted bearing.
    ukf = run_filter(UnscentedKalmanFilter(), model, np.array([[z]]))
    assert float(ukf.innovation[0, 0]) == pytest.approx(expected, abs=1e-3)
    assert abs(float(np.arctan2(ukf.final_mean[1], ukf.final_mean[0]))) > 3.1


# ---------------------------------------------------------------------------------------------
# 9. save="final"
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("first_step", FIRST_STEPS)
def test_save_final_matches_save_all(first_step):
    model, zs, rng = make_case(9, 4, 2)
    mask = rng.random((T, 2)) < 0.8
    full = run_filter(KalmanFilter(), model, zs, mask=mask, first_step=first_step)
    final = run_filter(KalmanFilter(), model, zs, mask=mask, first_step=first_step, save="final")
    for name in ("filtered_mean", "filtered_cov", "predicted_mean", "predicted_cov",
                 "innovation", "innovation_cov", "num_observed"):
        assert getattr(final, name) is None, name
    assert_close(final.final_mean, full.final_mean, 1e-13)
    assert_close(final.final_cov, full.final_cov, 1e-13)
    np.testing.assert_allclose(float(final.log_likelihood), float(full.log_likelihood), rtol=1e-13)
    np.testing.assert_array_equal(full.final_mean, full.filtered_mean[-1])
    np.testing.assert_array_equal(full.final_cov, full.filtered_cov[-1])


# ---------------------------------------------------------------------------------------------
# 10. NaN handling
# ---------------------------------------------------------------------------------------------


def _assert_same_result(a, b, rtol=1e-13):
    for name in ("filtered_mean", "filtered_cov", "predicted_mean", "predicted_cov",
                 "innovation", "innovation_cov", "num_observed"):
        assert_close(getattr(a, name), getattr(b, name), rtol, err_msg=name)
    np.testing.assert_allclose(float(a.log_likelihood), float(b.log_likelihood), rtol=rtol)


def test_nan_measurements():
    model, zs, _ = make_case(10, 4, 2)
    bad = zs.copy()
    bad[3, 1] = np.nan  # one component
    bad[8] = np.nan  # a whole step
    with pytest.raises(InputError, match="`measurements`"):
        run_filter(KalmanFilter(), model, bad)

    # nan_as_missing=True is the same as masking those entries out.
    mask = np.isfinite(bad)
    as_missing = run_filter(KalmanFilter(), model, bad, nan_as_missing=True)
    masked = run_filter(KalmanFilter(), model, zs, mask=mask)
    _assert_same_result(as_missing, masked)
    assert bool(as_missing.ok)
    assert float(as_missing.num_observed[3]) == 1.0 and float(as_missing.num_observed[8]) == 0.0
    # ... and it differs from the full-data run (the entries really were dropped).
    full = run_filter(KalmanFilter(), model, zs)
    assert float(jnp.max(jnp.abs(full.filtered_mean[8] - as_missing.filtered_mean[8]))) > 1e-6

    # NaN where the mask already says missing is accepted and ignored.
    accepted = run_filter(KalmanFilter(), model, bad, mask=mask)
    _assert_same_result(accepted, masked)
    assert bool(accepted.ok)


# ---------------------------------------------------------------------------------------------
# 11. Bad inputs
# ---------------------------------------------------------------------------------------------


def _raises(name, fn):
    with pytest.raises(InputError, match=re.escape(name)):
        fn()


def test_bad_inputs_name_the_argument():
    n, m = 2, 1
    F, Q, H, R = np.eye(n), 0.1 * np.eye(n), np.ones((m, n)), np.eye(m)
    m0, P0 = np.zeros(n), np.eye(n)
    model = LinearGaussianModel(F, Q, H, R, m0, P0)
    zs = np.zeros((5, m))
    kf = KalmanFilter()

    _raises("`measurements`", lambda: run_filter(kf, model, np.zeros((5, m + 1))))
    _raises("`measurements`", lambda: run_filter(kf, model, np.zeros((5, m, 1))))
    _raises("`mask`", lambda: run_filter(kf, model, zs, mask=np.ones(4, bool)))
    _raises("`mask`", lambda: run_filter(kf, model, zs, mask=np.ones((5, m + 1), bool)))
    _raises("`mask` must be boolean", lambda: run_filter(kf, model, zs, mask=np.ones(5)))
    _raises("`first_step`", lambda: run_filter(kf, model, zs, first_step="correct"))
    _raises("`save`", lambda: run_filter(kf, model, zs, save="none"))

    R2 = np.array([[1.0, 0.5], [0.0, 1.0]])  # non-symmetric
    _raises("`measurement_noise_cov`", lambda: LinearGaussianModel(F, Q, np.eye(2), R2, m0, P0))
    _raises("`initial_cov`", lambda: LinearGaussianModel(F, Q, H, R, m0, np.diag([1.0, -1e-3])))
    _raises("`initial_cov`", lambda: LinearGaussianModel(F, Q, H, R, m0, np.diag([1.0, 0.0])))
    _raises("`process_noise_cov`", lambda: LinearGaussianModel(F, -Q, H, R, m0, P0))
    _raises("`transition_matrix`", lambda: LinearGaussianModel(np.array([[1.0, np.inf], [0, 1]]), Q, H, R, m0, P0))
    _raises("`transition_matrix`", lambda: LinearGaussianModel(np.eye(3), Q, H, R, m0, P0))

    # Per-step arrays: their T must agree with each other and with the measurements.
    per_step = LinearGaussianModel(np.stack([F] * 4), Q, H, R, m0, P0)
    _raises("`measurements`", lambda: run_filter(kf, per_step, zs))
    _raises("disagree", lambda: LinearGaussianModel(np.stack([F] * 4), np.stack([Q] * 5), H, R, m0, P0))

    nonlinear = NonlinearGaussianModel(_static_transition, _bearing, Q, R, m0 + 1.0, P0)
    _raises("KalmanFilter needs a LinearGaussianModel", lambda: run_filter(kf, nonlinear, zs))
    _raises("`gain`", lambda: run_filter(KalmanFilter(gain=np.ones((n + 1, m))), model, zs))


# ---------------------------------------------------------------------------------------------
# 12. No recompilation
# ---------------------------------------------------------------------------------------------

_TRACES = {"count": 0}


class _CountingModel(LinearGaussianModel):
    """A LinearGaussianModel that counts how often its measurement matrix is traced."""

    def measurement_matrix(self, k):
        _TRACES["count"] += 1  # a Python side effect: runs only while JAX traces
        return super().measurement_matrix(k)


def test_new_values_do_not_recompile():
    n, m, T_ = 3, 2, 9
    rng = np.random.default_rng(12)

    def fresh_model(T_):
        base = random_linear_model(rng, n, m, T_, offset=True)
        return _CountingModel(base.F, base.Q, base.H, base.R, base.initial_mean, base.initial_cov,
                              transition_offset=base.b)

    def zs(T_):
        return rng.standard_normal((T_, m))

    run_filter(KalmanFilter(), fresh_model(T_), zs(T_))
    first = _TRACES["count"]
    assert first > 0
    # New values of every array, a mask instead of None, NaN-as-missing: no new trace.
    mask = rng.random((T_, m)) < 0.5
    z_nan = zs(T_)
    z_nan[2, 0] = np.nan
    for kwargs in ({}, {"mask": mask}, {"mask": mask[:, 0]}, {"nan_as_missing": True}):
        z = z_nan if kwargs.get("nan_as_missing") else zs(T_)
        r = run_filter(KalmanFilter(), fresh_model(T_), z, **kwargs)
        assert bool(r.ok)
    assert _TRACES["count"] == first
    # The counter does see a retrace: a different number of steps compiles again.
    run_filter(KalmanFilter(), fresh_model(T_ + 1), zs(T_ + 1))
    assert _TRACES["count"] > first

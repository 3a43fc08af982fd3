"""EM for LinearGaussianModel (jaxtrack.learning.fit_em) against dynamax's fit_em, and its invariants."""

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.filters import KalmanFilter, run_filter
from jaxtrack.models import LinearGaussianModel
from jaxtrack.learning import fit_em

N_STATE, N_MEAS, T = 2, 2, 100
F_TRUE = np.array([[0.9, 0.2], [-0.1, 0.8]])
Q_TRUE = np.array([[1.0, 0.3], [0.3, 0.5]])
H_TRUE = np.array([[1.0, 0.0], [0.5, 1.0]])
R_TRUE = np.array([[2.0, 0.4], [0.4, 1.0]])


def _simulate(seed, num_steps=T):
    rng = np.random.default_rng(seed)
    x = rng.multivariate_normal(np.zeros(N_STATE), np.eye(N_STATE))
    zs = []
    for k in range(num_steps):
        if k:
            x = F_TRUE @ x + rng.multivariate_normal(np.zeros(N_STATE), Q_TRUE)
        zs.append(H_TRUE @ x + rng.multivariate_normal(np.zeros(N_MEAS), R_TRUE))
    return np.array(zs)


# The starting point shared with dynamax: every parameter away from the truth.
START = dict(F=0.5 * np.eye(N_STATE), Q=2.0 * np.eye(N_STATE), H=H_TRUE + 0.3, R=3.0 * np.eye(N_MEAS),
             m0=np.zeros(N_STATE), P0=4.0 * np.eye(N_STATE))


def _start_model(s=START):
    return LinearGaussianModel(s["F"], s["Q"], s["H"], s["R"], s["m0"], s["P0"])


def _dynamax_fit(zs, num_iters):
    with warnings.catch_warnings():
        # dynamax imports tensorflow_probability's JAX substrate, which reads a deprecated
        # jax.core attribute (a DeprecationWarning, an error under the suite's filterwarnings).
        warnings.simplefilter("ignore", DeprecationWarning)
        from dynamax.linear_gaussian_ssm import LinearGaussianSSM

    # No biases, no inputs: the model x_k = F x_{k-1} + w, z_k = H x_k + v with the prior at
    # step 0 (jaxtrack's first_step="update"). LinearGaussianSSM.log_prior is 0 (flat), so its
    # M-step is the ML one; its history entry i is the log-likelihood before the i-th M-step.
    ssm = LinearGaussianSSM(N_STATE, N_MEAS, has_dynamics_bias=False, has_emissions_bias=False)
    s = {k: jnp.asarray(v) for k, v in START.items()}
    params, props = ssm.initialize(
        initial_mean=s["m0"], initial_covariance=s["P0"], dynamics_weights=s["F"],
        dynamics_covariance=s["Q"], emission_weights=s["H"], emission_covariance=s["R"])
    return ssm.fit_em(params, props, jnp.asarray(zs), num_iters=num_iters, verbose=False)


def _assert_monotone(history, final, what):
    h = np.append(np.asarray(history), float(final))
    inc = np.diff(h)
    # Round-off allowance: 1e-9 relative to |ℓ| (EM never decreases ℓ in exact arithmetic).
    tol = 1e-9 * np.abs(h[1:])
    assert np.all(inc >= -tol), f"{what}: log-likelihood decreased by {-inc.min():.3e} at {np.argmin(inc)}"
    return inc.min()


@pytest.fixture
def dynamax_without_diagonal_boost():
    """dynamax's psd_solve adds 1e-9·I before every Cholesky solve (its Kalman gain, smoother gain
    and M-step regressions); switched off, the two EMs do the same arithmetic up to round-off."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import dynamax.utils.utils as du

    saved = du.psd_solve.__defaults__
    du.psd_solve.__defaults__ = (0.0,)
    yield
    du.psd_solve.__defaults__ = saved


@pytest.fixture(scope="module")
def em_all_free():
    zs = _simulate(0)
    return zs, fit_em(_start_model(), zs, fixed=(), num_iterations=50)


def test_fit_em_equals_dynamax_over_50_iterations(em_all_free, dynamax_without_diagonal_boost):
    zs, fit = em_all_free
    params, lls = _dynamax_fit(zs, 50)
    assert fit.ok and int(fit.num_steps_taken) == 50
    assert fit.log_likelihood_history.shape == (50,)
    # Measured: max |Δℓ| 1.7e-13 nats over the 50 iterations (ℓ from −422 to −376).
    np.testing.assert_allclose(fit.log_likelihood_history, lls, rtol=0, atol=1e-8)
    m = fit.model
    for ours, theirs in [(m.F, params.dynamics.weights), (m.Q, params.dynamics.cov),
                         (m.H, params.emissions.weights), (m.R, params.emissions.cov),
                         (m.initial_mean, params.initial.mean), (m.initial_cov, params.initial.cov)]:
        # Measured: ≤ 2e-14.
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-6)
    # The EM actually moved: ℓ rose by > 40 nats.
    assert float(fit.log_likelihood) - float(fit.log_likelihood_history[0]) > 40.0


def test_fit_em_equals_dynamax_with_its_diagonal_boost(em_all_free):
    # With dynamax's default 1e-9·I boost the histories differ by that perturbation only:
    # measured max |Δℓ| 5.0e-8 nats, 1.3e-10 relative.
    zs, fit = em_all_free
    _, lls = _dynamax_fit(zs, 50)
    np.testing.assert_allclose(fit.log_likelihood_history, lls, rtol=1e-9)


def test_log_likelihood_never_decreases_and_final_is_the_fitted_models(em_all_free):
    zs, fit = em_all_free
    smallest = _assert_monotone(fit.log_likelihood_history, fit.log_likelihood, "all free")
    assert smallest > 0.0  # measured 0.033 nats at iteration 49
    ll = run_filter(KalmanFilter(), fit.model, zs).log_likelihood
    np.testing.assert_allclose(fit.log_likelihood, ll, rtol=1e-12)
    np.testing.assert_allclose(fit.log_likelihood_history[0],
                               run_filter(KalmanFilter(), _start_model(), zs).log_likelihood, rtol=1e-12)


def test_many_runs_sum_statistics(dynamax_without_diagonal_boost):
    zs = _simulate(1, 60)
    runs = np.stack([zs, _simulate(2, 60)])
    fit = fit_em(_start_model(), runs, fixed=(), num_iterations=1)
    params, lls = _dynamax_fit(runs, 1)
    np.testing.assert_allclose(fit.log_likelihood_history, lls, rtol=0, atol=1e-9)
    m = fit.model
    for ours, theirs in [(m.F, params.dynamics.weights), (m.Q, params.dynamics.cov),
                         (m.H, params.emissions.weights), (m.R, params.emissions.cov),
                         (m.initial_mean, params.initial.mean)]:
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-12)
    # dynamax 1.0.3 forms the prior covariance as (Σ_r E[x₀x₀ᵀ] − (Σ_r x̂₀)(Σ_r x̂₀)ᵀ)/N, which is
    # N·m₀m₀ᵀ short of the sample second moment; ours is Σ_r E[x₀x₀ᵀ]/N − m₀m₀ᵀ (the ML estimate:
    # mean smoothed covariance plus the runs' spread about m₀). They differ by exactly (N−1) m₀m₀ᵀ.
    m0 = np.asarray(m.initial_mean)
    np.testing.assert_allclose(np.asarray(m.initial_cov) - np.asarray(params.initial.cov),
                               (2 - 1) * np.outer(m0, m0), rtol=0, atol=1e-12)
    # Identical copies of one run: the same fit as that run, ℓ times the number of copies (the
    # same shapes as above, so no new compilation).
    one = fit_em(_start_model(), zs, fixed=(), num_iterations=1)
    two = fit_em(_start_model(), np.stack([zs, zs]), fixed=(), num_iterations=1)
    np.testing.assert_allclose(two.log_likelihood_history, 2 * one.log_likelihood_history, rtol=1e-12)
    np.testing.assert_allclose(two.log_likelihood, 2 * one.log_likelihood, rtol=1e-12)
    for name in ("F", "Q", "H", "R", "initial_mean", "initial_cov"):
        np.testing.assert_allclose(getattr(two.model, name), getattr(one.model, name), rtol=0, atol=1e-12)


def test_fixed_parameters_are_held_bit_for_bit():
    zs = _simulate(3, 80)
    model = _start_model()
    fixed = ("H", "R", "initial_mean")
    fit = fit_em(model, zs, fixed=fixed, num_iterations=20)
    assert fit.ok
    for name in fixed:
        assert np.array_equal(np.asarray(getattr(fit.model, name)), np.asarray(getattr(model, name)))
    for name in ("F", "Q", "initial_cov"):
        assert np.max(np.abs(np.asarray(getattr(fit.model, name)) - np.asarray(getattr(model, name)))) > 1e-2
    _assert_monotone(fit.log_likelihood_history, fit.log_likelihood, "fixed H, R, m0")
    # The default holds H (known from the sensor in tracking).
    default = fit_em(model, zs, num_iterations=2)
    assert np.array_equal(np.asarray(default.model.H), np.asarray(model.H))


def test_missing_trailing_steps_same_as_truncated_data():
    # Steps after the last measurement do not change the smoothed x₀, so with F, Q, H, R held
    # the two EMs (prior only) are the same problem, iteration by iteration.
    zs = _simulate(4, 60)
    mask = np.arange(60) < 45
    fixed = ("F", "Q", "H", "R")
    masked = fit_em(_start_model(), zs, mask=mask, fixed=fixed, num_iterations=10)
    cut = fit_em(_start_model(), zs[:45], fixed=fixed, num_iterations=10)
    np.testing.assert_allclose(masked.log_likelihood_history, cut.log_likelihood_history, rtol=1e-12)
    np.testing.assert_allclose(masked.model.initial_mean, cut.model.initial_mean, rtol=0, atol=1e-10)
    np.testing.assert_allclose(masked.model.initial_cov, cut.model.initial_cov, rtol=0, atol=1e-10)


def test_masks_keep_the_log_likelihood_monotone():
    # Whole missing steps and single missing components, two runs, every parameter free: the
    # latent-measurement M-step (missing components given the observed ones) must keep EM a
    # true EM, so ℓ (which the filter computes from the observed components only) never falls.
    rng = np.random.default_rng(5)
    runs = np.stack([_simulate(6, 80), _simulate(7, 80)])
    mask = rng.random(runs.shape) > 0.3
    mask[:, 10:15] = False
    runs = np.where(mask, runs, np.nan)  # missing entries may hold anything
    fit = fit_em(_start_model(), runs, mask=mask, fixed=(), num_iterations=30)
    assert fit.ok
    smallest = _assert_monotone(fit.log_likelihood_history, fit.log_likelihood, "component mask")
    assert smallest > 0.0
    ll = sum(run_filter(KalmanFilter(), fit.model, r, mask=mk).log_likelihood for r, mk in zip(runs, mask))
    np.testing.assert_allclose(fit.log_likelihood, ll, rtol=1e-12)


def test_first_step_predict():
    zs = _simulate(8, 50)
    model = _start_model()
    fit = fit_em(model, zs, fixed=("H",), num_iterations=10, first_step="predict")
    first = run_filter(KalmanFilter(), model, zs, first_step="predict").log_likelihood
    np.testing.assert_allclose(fit.log_likelihood_history[0], first, rtol=1e-12)
    last = run_filter(KalmanFilter(), fit.model, zs, first_step="predict").log_likelihood
    np.testing.assert_allclose(fit.log_likelihood, last, rtol=1e-12)
    _assert_monotone(fit.log_likelihood_history, fit.log_likelihood, "first_step=predict")


def test_input_errors():
    zs = _simulate(9, 10)
    model = _start_model()
    with pytest.raises(InputError, match="`fixed`"):
        fit_em(model, zs, fixed=("G",))
    with pytest.raises(InputError, match="`num_iterations`"):
        fit_em(model, zs, num_iterations=0)
    with pytest.raises(InputError, match="`first_step`"):
        fit_em(model, zs, first_step="later")
    with pytest.raises(InputError, match="`mask`"):
        fit_em(model, zs, mask=np.ones(10))
    with pytest.raises(InputError, match="`measurements`"):
        fit_em(model, np.where(np.arange(10)[:, None] == 3, np.nan, zs))
    per_step = LinearGaussianModel(np.broadcast_to(START["F"], (10, 2, 2)), START["Q"], START["H"],
                                   START["R"], START["m0"], START["P0"])
    with pytest.raises(InputError, match=r"`model`\.F varies per step"):
        fit_em(per_step, zs)
    angles = LinearGaussianModel(START["F"], START["Q"], START["H"], START["R"], START["m0"], START["P0"],
                                 angle_components=(1,))
    with pytest.raises(InputError, match="angle components"):
        fit_em(angles, zs)
    with pytest.raises(InputError, match="single step"):
        fit_em(model, zs[:1], fixed=("H",))


def _brute_force_em_step(s, zs, mask):
    """One EM step from the joint Gaussian of all states and all measurements (NumPy oracle).

    Stacks ``[x_0 … x_{T-1}, z_0 … z_{T-1}]`` as a linear map of independent ``x_0``, ``w_k``,
    ``v_k``, conditions on the observed components, and forms the Shumway–Stoffer M-step from
    the exact posterior second moments (missing components included as latent variables).
    """
    F, Q, H, R, m0, P0 = (np.asarray(s[k], float) for k in ("F", "Q", "H", "R", "m0", "P0"))
    Tn, n, m = zs.shape[0], F.shape[0], H.shape[0]
    dim_x, dim_e = Tn * n, n + (Tn - 1) * n + Tn * m
    A = np.zeros((dim_x + Tn * m, dim_e))
    mu = np.zeros(dim_x + Tn * m)
    Fk = np.eye(n)
    for k in range(Tn):
        mu[k * n:(k + 1) * n] = Fk @ m0
        A[k * n:(k + 1) * n, :n] = Fk
        for j in range(1, k + 1):  # x_k = F^k x_0 + Σ_j F^{k-j} w_j
            A[k * n:(k + 1) * n, n + (j - 1) * n:n + j * n] = np.linalg.matrix_power(F, k - j)
        Fk = F @ Fk
    for k in range(Tn):
        rows = slice(dim_x + k * m, dim_x + (k + 1) * m)
        A[rows] = H @ A[k * n:(k + 1) * n]
        A[rows, n + (Tn - 1) * n + k * m:n + (Tn - 1) * n + (k + 1) * m] = np.eye(m)
        mu[rows] = H @ mu[k * n:(k + 1) * n]
    D = np.zeros((dim_e, dim_e))
    D[:n, :n] = P0
    for j in range(Tn - 1):
        D[n + j * n:n + (j + 1) * n, n + j * n:n + (j + 1) * n] = Q
    for k in range(Tn):
        o = n + (Tn - 1) * n + k * m
        D[o:o + m, o:o + m] = R
    S = A @ D @ A.T
    o = dim_x + np.flatnonzero(mask.reshape(-1))
    gain = S[:, o] @ np.linalg.inv(S[np.ix_(o, o)])
    resid = zs.reshape(-1)[o - dim_x] - mu[o]
    mean = mu + gain @ resid
    cov = S - gain @ S[o, :]
    M = cov + np.outer(mean, mean)
    sign, logdet = np.linalg.slogdet(S[np.ix_(o, o)])
    ll = -0.5 * (resid @ np.linalg.solve(S[np.ix_(o, o)], resid) + logdet + len(o) * np.log(2 * np.pi))
    xs = lambda k: slice(k * n, (k + 1) * n)  # noqa: E731
    zk = lambda k: slice(dim_x + k * m, dim_x + (k + 1) * m)  # noqa: E731
    S00 = sum(M[xs(k), xs(k)] for k in range(Tn - 1))
    S10 = sum(M[xs(k + 1), xs(k)] for k in range(Tn - 1))
    S11 = sum(M[xs(k + 1), xs(k + 1)] for k in range(Tn - 1))
    F1 = S10 @ np.linalg.inv(S00)
    Q1 = (S11 - F1 @ S10.T - S10 @ F1.T + F1 @ S00 @ F1.T) / (Tn - 1)
    Sxx = sum(M[xs(k), xs(k)] for k in range(Tn))
    Szx = sum(M[zk(k), xs(k)] for k in range(Tn))
    Szz = sum(M[zk(k), zk(k)] for k in range(Tn))
    H1 = Szx @ np.linalg.inv(Sxx)
    R1 = (Szz - H1 @ Szx.T - Szx @ H1.T + H1 @ Sxx @ H1.T) / Tn
    return ll, dict(F=F1, Q=Q1, H=H1, R=R1, initial_mean=mean[xs(0)], initial_cov=cov[xs(0), xs(0)])


def test_one_em_step_equals_the_joint_gaussian_oracle_with_component_masks():
    # The exact E-step with missing components (general, correlated R): per-component and
    # whole-step gaps, every parameter free, against the brute-force joint Gaussian.
    zs = _simulate(10, 5)
    mask = np.array([[True, True], [True, False], [False, False], [False, True], [True, True]])
    # A correlated R: the missing components then depend on the observed ones (K ≠ 0).
    start = dict(START, R=np.array([[3.0, 1.2], [1.2, 2.0]]))
    fit = fit_em(_start_model(start), zs, mask=mask, fixed=(), num_iterations=1)
    ll, want = _brute_force_em_step(start, zs, mask)
    np.testing.assert_allclose(fit.log_likelihood_history[0], ll, rtol=1e-12)
    for name, value in want.items():
        np.testing.assert_allclose(getattr(fit.model, name), value, rtol=0, atol=1e-10, err_msg=name)


def test_stops_early_once_the_relative_change_is_below_tol(capsys):
    # Q and R free from a wrong start, F, H and the prior known: EM converges linearly, and with
    # tol = 1e-8 it stops long before the cap (measured: 69 M-steps; 97 at the default 1e-10),
    # at the first iterate whose log-likelihood moved by ≤ tol·|ℓ|.
    zs = _simulate(3, 100)
    start = LinearGaussianModel(F_TRUE, 2.0 * np.eye(N_STATE), H_TRUE, 3.0 * np.eye(N_MEAS), np.zeros(N_STATE),
                                np.eye(N_STATE))
    fixed = ("F", "H", "initial_mean", "initial_cov")
    cap, tol = 500, 1e-8
    fit = fit_em(start, zs, fixed=fixed, num_iterations=cap, tol=tol, progress=True)
    assert "fit_em" in capsys.readouterr().err  # the progress bar (tqdm, on stderr)
    steps = int(fit.num_steps_taken)
    assert fit.ok and bool(fit.converged)
    assert 2 <= steps < cap // 4, steps
    # ℓ of iterates 0 … steps: the history up to the stop, then the returned model's.
    ll = np.append(np.asarray(fit.log_likelihood_history[:steps]), float(fit.log_likelihood))
    assert abs(ll[-1] - ll[-2]) <= tol * abs(ll[-1])  # the criterion held at the stop …
    assert abs(ll[-2] - ll[-3]) > tol * abs(ll[-2])  # … and not one iterate earlier
    np.testing.assert_array_equal(fit.log_likelihood_history[steps:], float(fit.log_likelihood))
    # Stopping early is truncation: the same number of M-steps without a stopping rule gives
    # the same model bit for bit.
    cut = fit_em(start, zs, fixed=fixed, num_iterations=steps, tol=0.0)
    assert int(cut.num_steps_taken) == steps and not bool(cut.converged)
    for name in ("Q", "R"):
        np.testing.assert_array_equal(getattr(fit.model, name), getattr(cut.model, name))
    for bad in (-1e-3, float("nan"), "small"):
        with pytest.raises(InputError, match="`tol`"):
            fit_em(start, zs, tol=bad)

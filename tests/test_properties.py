"""Property-based tests of the filter invariants over random linear-Gaussian models (hypothesis).

Each property is checked on ``PROPERTY_EXAMPLES`` (default 200) drawn models: 1–9 states, 1–4
measurement components, 1–12 steps with nonuniform intervals τ (per-step ``F``, ``Q``, ``H``,
``R`` and a known input ``b``), no mask, whole-step masks or per-component masks, and a change of
units over 6 decades (``tests/_strategies.py`` describes the draw). The runs are derandomised and
use no example database, so CI sees the same 200 examples every time, in bounded time.

**Tolerances.** The drawn models are well conditioned in their own units (``P0``, ``Q_c``, ``R``
with condition numbers ≤ 100, ``‖A τ‖ ≲ 1.5``, ``T ≤ 12``, posterior covariances far from
singular), so float64 recursions agree with the exact answer to about ``T · n · cond · ε ≈ 1e-12``
relative to the size of each quantity, whatever the units the library is given: a diagonal change
of units commutes with every operation of a Kalman filter, so it does not change rounding errors
relative to each component's own scale. Comparisons are therefore made in the well-scaled units,
relative to the size of each quantity per step (``_strategies.assert_moments_close``), with
``RTOL = 1e-8`` against independent oracles and ``1e-9`` between two paths of the library that
should agree to rounding (masks against reduced rows, shared against per-run covariances): four
orders of magnitude of room for rounding, while an algebraic mistake (a wrong step index, a
missing component that leaks, a wrong unit) gives errors of order 1e-3 to 1.

Set ``JAXTRACK_PROPERTY_EXAMPLES`` to run more examples locally (e.g. 2000).
"""

from __future__ import annotations

import os

import numpy as np
import pytest
from _strategies import (
    SHAPES,
    OpaqueLinearModel,
    Spec,
    assert_array_close,
    assert_moments_close,
    assert_scalar_close,
    build_case,
    dense_oracle,
    reduced_row_filter,
    spd_margin,
    specs,
    unscale_cov,
    unscale_log_likelihood,
    unscale_mean,
    unscale_meas,
    unscale_meas_cov,
)
from helpers import dense_solution
from hypothesis import HealthCheck, Phase, example, given, settings
from hypothesis import strategies as st

from jaxtrack.filters import (
    ExtendedKalmanFilter,
    KalmanFilter,
    UnscentedKalmanFilter,
    rts_smoother,
    run_filter,
    run_filter_batch,
)
from jaxtrack.models import LinearGaussianModel

PROPERTY_EXAMPLES = int(os.environ.get("JAXTRACK_PROPERTY_EXAMPLES", "200"))

# Deterministic and bounded: the same examples on every run (derandomize, no database), no
# per-example deadline (the first example of each shape compiles the filters).
PROPERTY_SETTINGS = settings(
    max_examples=PROPERTY_EXAMPLES,
    derandomize=True,
    database=None,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)

RTOL = 1e-8  # against an independent oracle (see the module docstring)
RTOL_PATHS = 1e-9  # between two library paths that compute the same recursion
BATCH_RUNS = 3


def run_kf(case, filter=None, model=None):
    return run_filter(
        KalmanFilter() if filter is None else filter,
        case.model if model is None else model,
        case.zs_scaled[0],
        mask=case.mask,
        first_step=case.first_step,
    )


def assert_filter_matches(case, res, ref, rtol, what):
    """Filtered and predicted moments and the log-likelihood of ``res`` (scaled units) vs ``ref``."""
    assert bool(res.ok), f"{what}: ok is False"
    assert_moments_close(
        unscale_mean(case, res.filtered_mean), unscale_cov(case, res.filtered_cov),
        ref.filtered_mean, ref.filtered_cov, rtol, f"{what} filtered",
    )
    assert_moments_close(
        unscale_mean(case, res.predicted_mean), unscale_cov(case, res.predicted_cov),
        ref.predicted_mean, ref.predicted_cov, rtol, f"{what} predicted",
    )
    assert_scalar_close(
        unscale_log_likelihood(case, res.log_likelihood), ref.log_likelihood, rtol,
        scale=float(case.observed.sum()), what=f"{what} log-likelihood",
    )


def test_strategy_covers_the_issue_ranges():
    """The drawn ranges are those the issue asks for: states 1–9, measurements 1–4, T ≤ 12."""
    assert max(s.n_pad for s in SHAPES) == 9 and {s.m for s in SHAPES} == {1, 2, 3, 4}
    assert max(s.T for s in SHAPES) <= 12 and {s.first_step for s in SHAPES} == {"update", "predict"}
    case = build_case(Spec(shape=3, n=9, mask="component", scaled=True, seed=7))
    tau_ratio = case.arrays.Q[:, 0, 0].max() / case.arrays.Q[:, 0, 0].min()
    assert tau_ratio > 1.5  # nonuniform intervals
    decades = np.log10(np.concatenate([case.state_scale, case.meas_scale]))
    assert decades.min() >= -3 and decades.max() <= 3 and np.ptp(decades) >= 3


@pytest.mark.parametrize(
    "spec",
    [
        Spec(shape=0, n=2, mask="component", scaled=False, seed=1),
        Spec(shape=1, n=3, mask="step", scaled=False, seed=2),
        Spec(shape=3, n=9, mask="none", scaled=False, seed=3),
        Spec(shape=4, n=3, mask="component", scaled=False, seed=4),
    ],
)
def test_dense_oracle_agrees_with_helpers_dense_solution(spec):
    """The new oracle's smoothed marginals and likelihood equal the suite's existing one."""
    case = build_case(spec)
    a = case.arrays
    model = LinearGaussianModel(a.F, a.Q, a.H, a.R, a.m0, a.P0, transition_offset=a.b)
    old = dense_solution(model, case.zs[0], mask=case.mask, first_step=case.first_step)
    new = dense_oracle(a, case.zs[0], case.observed, case.first_step)
    np.testing.assert_allclose(new.smoothed_mean, old.smoothed_mean, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(new.smoothed_cov, old.smoothed_cov, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(new.log_likelihood, old.log_likelihood, rtol=1e-10)


# ---------------------------------------------------------------------------------------------
# 1. The Kalman filter equals batch Gaussian conditioning
# ---------------------------------------------------------------------------------------------


@PROPERTY_SETTINGS
@given(specs())
def test_kalman_filter_equals_dense_gaussian_conditioning(spec):
    """``x̂_{k/k}``, ``P_{k/k}``, ``x̂_{k/k-1}``, ``P_{k/k-1}`` and the log-likelihood equal the
    marginals of the joint Gaussian of all states conditioned on the observed measurements of
    steps ``≤ k`` (``< k``), computed by Schur complements in NumPy."""
    case = build_case(spec)
    res = run_kf(case)
    ref = dense_oracle(case.arrays, case.zs[0], case.observed, case.first_step)
    assert_filter_matches(case, res, ref, RTOL, "KF")


# ---------------------------------------------------------------------------------------------
# 2. P stays symmetric positive definite
# ---------------------------------------------------------------------------------------------


def assert_spd(P, what, *, exactly_symmetric=True):
    """Symmetric, positive diagonal, positive definite in its correlation form, and factorable by
    Cholesky in the units the library was given.

    ``exactly_symmetric``: ``P == Pᵀ`` bit for bit (what the filter promises for the covariances
    it symmetrises); otherwise the asymmetry may be rounding, ``1e-12 · √(P_ii P_jj)``.
    """
    P = np.asarray(P, np.float64)
    Pt = np.swapaxes(P, -1, -2)
    if exactly_symmetric:
        assert np.array_equal(P, Pt), f"{what}: not exactly symmetric"
    else:
        sd = np.sqrt(np.abs(np.diagonal(P, axis1=-2, axis2=-1)))
        assert np.all(np.abs(P - Pt) <= 1e-12 * sd[..., :, None] * sd[..., None, :]), f"{what}: not symmetric"
    margin = spd_margin(0.5 * (P + Pt))
    assert np.all(margin > 0), f"{what}: smallest correlation-form eigenvalue {margin.min():.3g}"
    np.linalg.cholesky(P)  # raises LinAlgError if not numerically positive definite (lower triangle)


@PROPERTY_SETTINGS
@given(specs(tight=st.booleans()))
def test_covariances_stay_symmetric_positive_definite(spec):
    """Filtered, predicted and smoothed covariances are SPD at every step; half of the examples
    have a measurement noise 10⁶ times smaller (``tight``), whose posteriors are close to singular
    in the measured directions. Filtered and smoothed ``P`` are exactly symmetric; the predicted
    ``P_{k/k-1} = F P Fᵀ + Q`` is symmetric to rounding only (see the xfail test below)."""
    case = build_case(spec)
    sm = rts_smoother(case.model, case.zs_scaled[0], mask=case.mask, first_step=case.first_step)
    res = sm.filtered
    assert bool(res.ok)
    assert_spd(res.filtered_cov, "filtered P")
    assert_spd(res.predicted_cov, "predicted P", exactly_symmetric=False)
    assert_spd(sm.smoothed_cov, "smoothed P")


@pytest.mark.xfail(
    strict=True,
    raises=AssertionError,
    reason="KalmanFilter/ExtendedKalmanFilter.predict (filters/_kalman.py::_predict_linearized) "
    "returns F P Fᵀ + Q without symmetrising it, so FilterResult.predicted_cov is symmetric only "
    "to rounding (e.g. Spec(shape=0, n=2, mask='none', scaled=False, seed=0)); the filtered, "
    "smoothed and UKF-predicted covariances are symmetrised exactly",
)
@settings(PROPERTY_SETTINGS, phases=[Phase.explicit])
@example(Spec(shape=0, n=2, mask="none", scaled=False, seed=0))
@given(specs())
def test_predicted_covariance_is_exactly_symmetric(spec):
    case = build_case(spec)
    P = np.asarray(run_kf(case).predicted_cov)
    assert np.array_equal(P, np.swapaxes(P, -1, -2)), "predicted P: not exactly symmetric"


# ---------------------------------------------------------------------------------------------
# 3. A per-component mask equals the reduced-row update
# ---------------------------------------------------------------------------------------------


@PROPERTY_SETTINGS
@given(specs(mask_kinds=("component",)))
def test_component_mask_equals_reduced_row_update(spec):
    """With a ``(T, m)`` mask (missing entries NaN), every step equals the update with only the
    observed rows of ``H``, ``R`` and ``z``; missing components have innovation 0 and identity
    rows/columns of ``S``, and ``num_observed`` counts the rest."""
    case = build_case(spec, nan_missing=True)
    res = run_kf(case)
    ref = reduced_row_filter(case.arrays, case.zs[0], case.observed, case.first_step)
    assert_filter_matches(case, res, ref, RTOL_PATHS, "masked KF")
    obs = case.observed
    innovation = np.asarray(res.innovation)
    assert np.all(innovation[~obs] == 0.0)
    assert_array_close(unscale_meas(case, innovation), ref.innovation, RTOL_PATHS, "innovation")
    S = np.asarray(res.innovation_cov)  # scaled units; the missing block is unit-free
    both = obs[:, :, None] & obs[:, None, :]
    eye = np.broadcast_to(np.eye(case.shape.m, dtype=bool), S.shape)
    missing = ~both & (~obs[:, :, None] | ~obs[:, None, :])
    assert np.all(S[missing & eye] == 1.0) and np.all(S[missing & ~eye] == 0.0)
    S_unscaled = unscale_meas_cov(case, S)
    for k in range(case.shape.T):
        rows = obs[k]
        if rows.any():
            assert_array_close(S_unscaled[k][np.ix_(rows, rows)], ref.innovation_cov[k][np.ix_(rows, rows)],
                               RTOL_PATHS, f"S at step {k}", matrix=True)
    np.testing.assert_array_equal(np.asarray(res.num_observed), obs.sum(axis=1))


# ---------------------------------------------------------------------------------------------
# 4. Shared and per-run covariance paths of run_filter_batch agree
# ---------------------------------------------------------------------------------------------


@PROPERTY_SETTINGS
@given(specs())
def test_shared_and_per_run_covariance_paths_agree(spec):
    """``run_filter_batch(covariance="shared")`` (one covariance pass, block-affine means) equals
    ``covariance="per_run"`` (vmap of the single-run scan) on every field, for 3 runs with one
    schedule (missing entries NaN)."""
    case = build_case(spec, runs=BATCH_RUNS, nan_missing=True)
    kw = dict(mask=case.mask, first_step=case.first_step)
    shared = run_filter_batch(KalmanFilter(), case.model, case.zs_scaled, covariance="shared", **kw)
    per_run = run_filter_batch(KalmanFilter(), case.model, case.zs_scaled, covariance="per_run", **kw)
    assert shared.shared_covariance and not per_run.shared_covariance
    assert np.all(np.asarray(shared.ok)) and np.all(np.asarray(per_run.ok))
    for b in range(BATCH_RUNS):
        for when in ("filtered", "predicted"):
            assert_moments_close(
                unscale_mean(case, getattr(shared, f"{when}_mean")[b]),
                unscale_cov(case, getattr(shared, f"{when}_cov")),
                unscale_mean(case, getattr(per_run, f"{when}_mean")[b]),
                unscale_cov(case, getattr(per_run, f"{when}_cov")[b]),
                RTOL_PATHS, f"run {b} {when}",
            )
        assert_array_close(unscale_meas(case, shared.innovation[b]), unscale_meas(case, per_run.innovation[b]),
                           RTOL_PATHS, f"run {b} innovation")
        assert_array_close(unscale_meas_cov(case, shared.innovation_cov),
                           unscale_meas_cov(case, per_run.innovation_cov[b]), RTOL_PATHS,
                           f"run {b} innovation_cov", matrix=True)
        np.testing.assert_array_equal(np.asarray(shared.num_observed), np.asarray(per_run.num_observed[b]))
        assert_moments_close(
            unscale_mean(case, shared.final_mean[b])[None], unscale_cov(case, shared.final_cov)[None],
            unscale_mean(case, per_run.final_mean[b])[None], unscale_cov(case, per_run.final_cov[b])[None],
            RTOL_PATHS, f"run {b} final",
        )
    assert_scalar_close(
        unscale_log_likelihood(case, shared.log_likelihood),
        unscale_log_likelihood(case, per_run.log_likelihood),
        RTOL_PATHS, scale=float(case.observed.sum()), what="log-likelihoods",
    )


# ---------------------------------------------------------------------------------------------
# 5. EKF and UKF equal the KF on linear models
# ---------------------------------------------------------------------------------------------


@PROPERTY_SETTINGS
@given(specs())
def test_ekf_and_ukf_equal_kalman_filter_on_linear_models(spec):
    """On a linear model seen only through ``f`` and ``h`` (:class:`OpaqueLinearModel`: the EKF
    gets its Jacobians from ``jax.jacfwd``, the UKF propagates sigma points), the EKF and the
    UKF (cubature weights) reproduce the Kalman filter: moments, innovations, ``S`` and the
    log-likelihood."""
    case = build_case(spec)
    kf = run_kf(case)
    opaque = OpaqueLinearModel.of(case.model)
    for name, flt in (("EKF", ExtendedKalmanFilter()), ("UKF", UnscentedKalmanFilter())):
        res = run_kf(case, flt, opaque)
        assert bool(res.ok), f"{name}: ok is False"
        for when in ("filtered", "predicted"):
            assert_moments_close(
                unscale_mean(case, getattr(res, f"{when}_mean")), unscale_cov(case, getattr(res, f"{when}_cov")),
                unscale_mean(case, getattr(kf, f"{when}_mean")), unscale_cov(case, getattr(kf, f"{when}_cov")),
                RTOL, f"{name} {when}",
            )
        assert_array_close(unscale_meas(case, res.innovation), unscale_meas(case, kf.innovation), RTOL,
                           f"{name} innovation")
        assert_array_close(unscale_meas_cov(case, res.innovation_cov), unscale_meas_cov(case, kf.innovation_cov),
                           RTOL, f"{name} innovation_cov", matrix=True)
        assert_scalar_close(unscale_log_likelihood(case, res.log_likelihood),
                            unscale_log_likelihood(case, kf.log_likelihood), RTOL,
                            scale=float(case.observed.sum()), what=f"{name} log-likelihood")


# ---------------------------------------------------------------------------------------------
# 6. The RTS smoother equals the dense smoothed marginals
# ---------------------------------------------------------------------------------------------


@PROPERTY_SETTINGS
@given(specs())
def test_rts_smoother_equals_dense_smoothed_marginals(spec):
    """``x̂_{k/T-1}``, ``P_{k/T-1}`` equal the marginals of all states conditioned on every
    observed measurement (Schur complements in NumPy)."""
    case = build_case(spec)
    sm = rts_smoother(case.model, case.zs_scaled[0], mask=case.mask, first_step=case.first_step)
    ref = dense_oracle(case.arrays, case.zs[0], case.observed, case.first_step)
    assert bool(sm.filtered.ok)
    assert sm.smoother_gain.shape == (case.shape.T - 1, case.shape.n_pad, case.shape.n_pad)
    assert_moments_close(
        unscale_mean(case, sm.smoothed_mean), unscale_cov(case, sm.smoothed_cov),
        ref.smoothed_mean, ref.smoothed_cov, RTOL, "smoothed",
    )

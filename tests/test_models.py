"""Tests for continuous→discrete conversion (Van Loan) and the standard kinematic models."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from jaxtrack import InputError
from jaxtrack.models import (
    LinearGaussianModel,
    constant_acceleration,
    constant_velocity,
    discretize,
    ho_plant,
    sample_times,
    segment_schedule,
    singer,
    van_loan,
)

TAUS = np.array([0.01, 0.1, 1.0, 7.0])


def _cv_continuous(dim, q):
    A = np.kron(np.array([[0.0, 1.0], [0.0, 0.0]]), np.eye(dim))
    Qc = np.kron(np.diag([0.0, q]), np.eye(dim))
    return A, Qc


def _ca_continuous(dim, q):
    A = np.kron(np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]), np.eye(dim))
    Qc = np.kron(np.diag([0.0, 0.0, q]), np.eye(dim))
    return A, Qc


def _singer_continuous(theta, sigma):
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0 / theta]])
    Qc = np.diag([0.0, 0.0, 2.0 * sigma**2 / theta])
    return A, Qc


def _singer_phi(tau, theta):
    e = np.exp(-tau / theta)
    return np.array(
        [
            [1.0, tau, theta**2 * (-1.0 + tau / theta + e)],
            [0.0, 1.0, theta * (1.0 - e)],
            [0.0, 0.0, e],
        ]
    )


def _assert_matches_closed_form(actual, desired, rtol=1e-12):
    """Nonzero entries to ``rtol``; structural zeros to 1e-15·max|desired| (expm's squarings leave
    rounding of order eps·‖Φ‖ where the exact result is zero)."""
    actual, desired = np.asarray(actual), np.asarray(desired)
    nz = desired != 0
    assert_allclose(actual[nz], desired[nz], rtol=rtol, atol=0)
    assert np.max(np.abs(actual[~nz]), initial=0.0) <= 1e-15 * np.max(np.abs(desired))


# ---------------------------------------------------------------------------------------------
# Van Loan against closed forms


@pytest.mark.parametrize("dim", [1, 3])
def test_van_loan_matches_closed_form_constant_velocity(dim):
    """Φ and Q_d of Van Loan equal the CWNA closed form q[[τ³/3, τ²/2],[τ²/2, τ]] ⊗ I to 1e-12."""
    q = 2.5
    Phi, Qd = discretize(*_cv_continuous(dim, q), TAUS)
    model = constant_velocity(
        TAUS, dim=dim, accel_psd=q, measurement_std=1.0, initial_cov=np.eye(2 * dim)
    )
    assert Phi.shape == Qd.shape == (len(TAUS), 2 * dim, 2 * dim)
    for k, tau in enumerate(TAUS):
        F1 = np.array([[1.0, tau], [0.0, 1.0]])
        Q1 = q * np.array([[tau**3 / 3, tau**2 / 2], [tau**2 / 2, tau]])
        _assert_matches_closed_form(Phi[k], np.kron(F1, np.eye(dim)))
        _assert_matches_closed_form(Qd[k], np.kron(Q1, np.eye(dim)))
        # The model builder uses the closed form directly.
        assert_allclose(model.F[k], np.kron(F1, np.eye(dim)), rtol=1e-15, atol=0)
        assert_allclose(model.Q[k], np.kron(Q1, np.eye(dim)), rtol=1e-14, atol=0)


@pytest.mark.parametrize("dim", [1, 3])
def test_van_loan_matches_closed_form_constant_acceleration(dim):
    """Van Loan Q_d equals the white-noise-jerk closed form q[[τ⁵/20, τ⁴/8, τ³/6], …] to 1e-12."""
    q = 0.7
    Phi, Qd = discretize(*_ca_continuous(dim, q), TAUS)
    model = constant_acceleration(
        TAUS, dim=dim, jerk_psd=q, measurement_std=1.0, initial_cov=np.eye(3 * dim)
    )
    for k, tau in enumerate(TAUS):
        F1 = np.array([[1.0, tau, tau**2 / 2], [0.0, 1.0, tau], [0.0, 0.0, 1.0]])
        Q1 = q * np.array(
            [
                [tau**5 / 20, tau**4 / 8, tau**3 / 6],
                [tau**4 / 8, tau**3 / 3, tau**2 / 2],
                [tau**3 / 6, tau**2 / 2, tau],
            ]
        )
        _assert_matches_closed_form(Phi[k], np.kron(F1, np.eye(dim)))
        _assert_matches_closed_form(Qd[k], np.kron(Q1, np.eye(dim)))
        # The model builder uses the closed form directly.
        assert_allclose(model.F[k], np.kron(F1, np.eye(dim)), rtol=1e-15, atol=0)
        assert_allclose(model.Q[k], np.kron(Q1, np.eye(dim)), rtol=1e-14, atol=0)


def test_van_loan_scalar_vmap_and_jit_agree():
    """van_loan(τ) for one τ, discretize over a schedule, and jit(discretize) give equal stacks."""
    A, Qc = _singer_continuous(theta=3.0, sigma=2.0)
    stack_phi, stack_q = discretize(A, Qc, TAUS)
    jit_phi, jit_q = jax.jit(discretize)(A, Qc, TAUS)
    for k, tau in enumerate(TAUS):
        Phi, Qd = van_loan(A, Qc, tau)
        assert_allclose(stack_phi[k], Phi, rtol=1e-14, atol=1e-300)
        assert_allclose(stack_q[k], Qd, rtol=1e-14, atol=1e-300)
        assert_array_equal(Qd, Qd.T)  # symmetrised
    assert_allclose(jit_phi, stack_phi, rtol=1e-14, atol=1e-300)
    assert_allclose(jit_q, stack_q, rtol=1e-14, atol=1e-300)
    Phi0, Qd0 = discretize(A, Qc, 0.5)
    assert Phi0.shape == Qd0.shape == (3, 3)


# ---------------------------------------------------------------------------------------------
# Singer


def test_singer_matches_closed_form_phi_and_quadrature_q():
    """Singer Φ equals its closed form, Q a 60-node Gauss–Legendre ∫ΦQcΦᵀ, both to rtol 1e-10
    (entries that are 0 in closed form to 1e-14 of the largest entry)."""
    theta, sigma = 4.0, 3.0
    taus = np.array([0.05, 0.5, 2.0, 10.0])
    model = singer(
        taus,
        dim=2,
        maneuver_time_constant=theta,
        accel_std=sigma,
        measurement_std=1.0,
        initial_cov=np.eye(6),
    )
    _, Qc = _singer_continuous(theta, sigma)
    nodes, weights = np.polynomial.legendre.leggauss(60)
    for k, tau in enumerate(taus):
        Phi1 = _singer_phi(tau, theta)
        s = 0.5 * tau * (nodes + 1.0)
        Q1 = sum(
            0.5 * tau * w * _singer_phi(si, theta) @ Qc @ _singer_phi(si, theta).T
            for si, w in zip(s, weights)
        )
        # Entries that are exactly 0 in closed form come out of the matrix exponential as
        # rounding (seen: 2.4e-17 on one machine's BLAS), so zeros get an absolute tolerance
        # of 1e-14 of the matrix's largest entry.
        Phi_ref, Q_ref = np.kron(Phi1, np.eye(2)), np.kron(Q1, np.eye(2))
        assert_allclose(model.F[k], Phi_ref, rtol=1e-10, atol=1e-14 * np.abs(Phi_ref).max())
        assert_allclose(model.Q[k], Q_ref, rtol=1e-10, atol=1e-14 * np.abs(Q_ref).max())
    # Stationary acceleration: Q[a,a] = σ²(1 − e^{−2τ/θ}).
    assert_allclose(
        model.Q[:, 4, 4], sigma**2 * (1.0 - np.exp(-2.0 * taus / theta)), rtol=1e-12
    )


def test_singer_tends_to_constant_acceleration_for_long_time_constant():
    """θ → ∞ with 2σ²/θ = q fixed: Singer F, Q → white-noise-jerk model (rtol 1e-5 at θ = 1e6)."""
    theta, q, tau = 1e6, 0.3, 0.8
    sigma = np.sqrt(q * theta / 2.0)
    s = singer(
        tau, dim=1, maneuver_time_constant=theta, accel_std=sigma, measurement_std=1.0,
        initial_cov=np.eye(3),
    )
    ca = constant_acceleration(tau, dim=1, jerk_psd=q, measurement_std=1.0, initial_cov=np.eye(3))
    assert_allclose(s.F, ca.F, rtol=1e-5, atol=1e-12)
    assert_allclose(s.Q, ca.Q, rtol=1e-5)


# ---------------------------------------------------------------------------------------------
# derivatives of the discretisation


# Jitted once at module level so every (3, 3) case below shares one compilation.
_VL = jax.jit(van_loan)
_VL_JACFWD = jax.jit(jax.jacfwd(van_loan, argnums=2))


def _random_stable(seed, n=3):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    A = A - (np.max(np.linalg.eigvals(A).real) + 0.5) * np.eye(n)
    B = rng.normal(size=(n, n))
    return A, B @ B.T


@pytest.mark.parametrize(
    "A, Qc, tau",
    [
        (*_singer_continuous(theta=2.0, sigma=1.5), 0.3),
        (*_singer_continuous(theta=2.0, sigma=1.5), 5.0),
        (*_random_stable(0), 0.7),
    ],
    ids=["singer-short", "singer-long", "random-stable"],
)
def test_van_loan_tau_derivative_matches_finite_differences(A, Qc, tau):
    """jacfwd of Φ(τ), Q_d(τ) matches central differences (h = 1e-6 τ) to rtol 1e-6."""
    dphi, dq = _VL_JACFWD(A, Qc, tau)
    h = 1e-6 * tau
    (pp, qp), (pm, qm) = _VL(A, Qc, tau + h), _VL(A, Qc, tau - h)
    fd_phi = (np.asarray(pp) - np.asarray(pm)) / (2 * h)
    fd_q = (np.asarray(qp) - np.asarray(qm)) / (2 * h)
    for ad, fd in ((dphi, fd_phi), (dq, fd_q)):
        scale = np.max(np.abs(fd))
        assert scale > 0
        assert_allclose(ad, fd, rtol=1e-6, atol=1e-9 * scale)
    # Analytic check: dΦ/dτ = A Φ.
    assert_allclose(dphi, A @ np.asarray(_VL(A, Qc, tau)[0]), rtol=1e-10, atol=1e-13)


def test_van_loan_derivative_in_A_matches_finite_differences():
    """∂Q_d/∂A_ij by jacfwd equals central differences (h = 1e-6) to rtol 1e-6."""
    A, Qc = _random_stable(1)
    tau = 0.6
    jac = jax.jit(jax.jacfwd(lambda a, qc, t: van_loan(a, qc, t)[1]))(A, Qc, tau)  # (n,n,n,n)
    h = 1e-6
    for i, j in [(0, 0), (1, 2), (2, 0)]:
        E = np.zeros_like(A)
        E[i, j] = h
        fd = (np.asarray(_VL(A + E, Qc, tau)[1]) - np.asarray(_VL(A - E, Qc, tau)[1])) / (2 * h)
        assert_allclose(jac[..., i, j], fd, rtol=1e-6, atol=1e-9 * np.max(np.abs(fd)))


# ---------------------------------------------------------------------------------------------
# Ho 1968 plant and schedules


def test_ho_plant_matrices():
    """Q(τ=0.1) = diag(0.0259, 10.4) at 1 g and diag(2.59, 1040) at 10 g; F, H, R, P0 as Ho 1968."""
    m1 = ho_plant(0.1)
    assert isinstance(m1, LinearGaussianModel)
    assert_allclose(m1.Q, np.diag([0.0259, 10.4]), rtol=1e-14, atol=0)
    assert_allclose(m1.F, [[1.0, 0.1], [0.0, 1.0]], rtol=0, atol=0)
    assert_array_equal(m1.H, [[1.0, 0.0]])
    assert_array_equal(m1.R, [[1e4]])
    assert_array_equal(m1.initial_cov, np.diag([1e6, 1e6]))
    assert_array_equal(m1.initial_mean, [0.0, 0.0])
    m10 = ho_plant(0.1, g=10.0)
    assert_allclose(m10.Q, np.diag([2.59, 1040.0]), rtol=1e-14, atol=0)


@pytest.mark.parametrize("g", [1.0, 10.0])
def test_ho_plant_q_derivative_is_literal_eq86(g):
    """d Q[k]/d τ_j = δ_kj·diag(0.259, 104)·g² and d F[k]/d τ_j = δ_kj·[[0,1],[0,0]], exactly."""
    taus = jnp.array([0.1, 0.2, 0.125, 1.0 / 3.0])
    dQ = jax.jacfwd(lambda t: ho_plant(t, g=g).Q)(taus)  # (T, 2, 2, T)
    dF = jax.jacfwd(lambda t: ho_plant(t, g=g).F)(taus)
    rate = np.diag([0.259, 104.0]) * g**2
    dF_expected = np.array([[0.0, 1.0], [0.0, 0.0]])
    for k in range(4):
        for j in range(4):
            assert_array_equal(dQ[k, :, :, j], rate if j == k else np.zeros((2, 2)))
            assert_array_equal(dF[k, :, :, j], dF_expected if j == k else np.zeros((2, 2)))


def test_ho_plant_per_step_measurement_variance():
    """measurement_var = 1e3/τ (Ho eq. 87) gives an R stack (T,1,1) with R = 1e4 at τ = 0.1."""
    taus = jnp.array([0.1, 0.2, 0.05])
    model = ho_plant(taus, measurement_var=1e3 / taus)
    assert model.R.shape == (3, 1, 1)
    assert_allclose(model.R[:, 0, 0], [1e4, 5e3, 2e4], rtol=1e-14)
    assert model.num_steps == 3


def test_segment_schedule_ho_example():
    """(10,5,5,10,10): N = 40, times 0.1,…,1.0,1.2,…,3.0,3.1,…,5.0, Σ taus[1:] = 4.9."""
    taus = segment_schedule((10, 5, 5, 10, 10))
    assert taus.shape == (40,)
    expected_taus = np.repeat([0.1, 0.2, 0.2, 0.1, 0.1], [10, 5, 5, 10, 10])
    assert_allclose(taus, expected_taus, rtol=1e-15)
    expected_times = np.concatenate(
        [
            np.arange(1, 11) * 0.1,
            1.0 + np.arange(1, 6) * 0.2,
            2.0 + np.arange(1, 6) * 0.2,
            3.0 + np.arange(1, 11) * 0.1,
            4.0 + np.arange(1, 11) * 0.1,
        ]
    )
    assert_allclose(sample_times(taus), expected_times, rtol=1e-13)
    assert_allclose(sample_times(taus)[-1], 5.0, rtol=1e-14)
    assert_allclose(jnp.sum(taus[1:]), 4.9, rtol=1e-14)
    uniform = segment_schedule([8] * 5, segment_duration=2.0)
    assert uniform.shape == (40,)
    assert_allclose(uniform, 0.25, rtol=1e-15)
    assert_allclose(sample_times(uniform)[-1], 10.0, rtol=1e-14)


def test_segment_schedule_differentiable_in_duration():
    """d taus / d D = 1/n_i per entry."""
    d = jax.jacfwd(lambda D: segment_schedule((2, 4), segment_duration=D))(1.0)
    assert_allclose(d, [0.5, 0.5, 0.25, 0.25, 0.25, 0.25], rtol=1e-15)


# ---------------------------------------------------------------------------------------------
# gradients through per-step schedules, layout


_BUILDERS = {
    "cv": lambda t: constant_velocity(
        t, dim=2, accel_psd=1.3, measurement_std=1.0, initial_cov=jnp.eye(4)
    ),
    "ca": lambda t: constant_acceleration(
        t, dim=1, jerk_psd=0.4, measurement_std=1.0, initial_cov=jnp.eye(3)
    ),
    "singer": lambda t: singer(
        t, dim=2, maneuver_time_constant=5.0, accel_std=2.0, measurement_std=1.0,
        initial_cov=jnp.eye(6),
    ),
    "ho": lambda t: ho_plant(t, g=10.0),
}


@pytest.mark.parametrize("name", sorted(_BUILDERS))
def test_grad_through_per_step_schedule(name):
    """d(ΣQ)/dτ_k and d(ΣF)/dτ_k are finite and nonzero for every k; one matches a central difference."""
    build = _BUILDERS[name]
    taus = jnp.array([0.1, 0.25, 0.5, 1.0, 2.0])

    def sums(t):
        model = build(t)
        return jnp.stack([jnp.sum(model.Q), jnp.sum(model.F)])

    gq, gf = jax.jit(jax.jacrev(sums))(taus)  # one trace for both gradients
    assert np.all(np.isfinite(gq)) and np.all(gq != 0)
    assert np.all(np.isfinite(gf)) and np.all(gf != 0)
    # Central difference in τ_2 alone (h = 1e-6 τ_2) for the Q gradient.
    k, h = 2, 1e-6 * float(taus[2])
    plus, minus = taus.at[k].add(h), taus.at[k].add(-h)
    fd = (jnp.sum(build(plus).Q) - jnp.sum(build(minus).Q)) / (2 * h)
    assert_allclose(gq[k], fd, rtol=1e-6)


def test_state_ordering_and_per_axis_noise():
    """F = F1 ⊗ I_d, Q = Q1 ⊗ diag(q), H = [I_d, 0], R = diag(σ²) with per-axis q and σ."""
    tau, q, std = 0.4, np.array([1.0, 4.0, 9.0]), np.array([0.5, 1.0, 2.0])
    m = constant_velocity(tau, dim=3, accel_psd=q, measurement_std=std, initial_cov=np.eye(6))
    F1 = np.array([[1.0, tau], [0.0, 1.0]])
    Q1 = np.array([[tau**3 / 3, tau**2 / 2], [tau**2 / 2, tau]])
    assert_array_equal(m.F, np.kron(F1, np.eye(3)))
    assert_allclose(m.Q, np.kron(Q1, np.diag(q)), rtol=1e-15, atol=0)
    assert_array_equal(m.H, np.hstack([np.eye(3), np.zeros((3, 3))]))
    assert_allclose(m.R, np.diag(std**2), rtol=1e-15)
    assert_array_equal(m.initial_mean, np.zeros(6))
    assert m.F.shape == (6, 6) and m.num_steps is None


# ---------------------------------------------------------------------------------------------
# bad inputs


_CV_OK = dict(accel_psd=1.0, measurement_std=1.0, initial_cov=np.eye(4))
_SINGER_OK = dict(
    dim=1, maneuver_time_constant=5.0, accel_std=1.0, measurement_std=1.0, initial_cov=np.eye(3)
)


_CA_OK = dict(jerk_psd=1.0, measurement_std=1.0, initial_cov=np.eye(3))
_BAD_INPUTS = {
    "cv-dim-4": (lambda: constant_velocity(0.1, dim=4, **_CV_OK), "dim"),
    "ca-dim-0": (lambda: constant_acceleration(0.1, dim=0, **_CA_OK), "dim"),
    "singer-dim-float": (lambda: singer(0.1, **{**_SINGER_OK, "dim": 2.0}), "dim"),
    "cv-negative-tau": (lambda: constant_velocity(np.array([0.1, -0.2]), **_CV_OK), "taus"),
    "cv-nan-tau": (lambda: constant_velocity(np.array([0.1, np.nan]), **_CV_OK), "taus"),
    "ho-zero-tau": (lambda: ho_plant(0.0), "taus"),
    "ho-2d-taus": (lambda: ho_plant(np.ones((2, 2))), "taus"),
    "vl-nonsquare-A": (lambda: van_loan(np.ones((2, 3)), np.eye(2), 0.1), "A"),
    "vl-Qc-shape": (lambda: van_loan(np.eye(2), np.eye(3), 0.1), "L_Qc_Lt"),
    "vl-Qc-negative": (lambda: van_loan(np.eye(2), -np.eye(2), 0.1), "L_Qc_Lt"),
    "vl-negative-tau": (lambda: van_loan(np.eye(2), np.eye(2), -0.1), "tau"),
    "vl-vector-tau": (lambda: van_loan(np.eye(2), np.eye(2), np.array([0.1, 0.2])), "tau"),
    "discretize-negative-tau": (
        lambda: discretize(np.eye(2), np.eye(2), np.array([0.1, -0.2])),
        "taus",
    ),
    "cv-negative-std": (
        lambda: constant_velocity(0.1, **{**_CV_OK, "measurement_std": -1.0}),
        "measurement_std",
    ),
    "cv-zero-std": (
        lambda: constant_velocity(0.1, **{**_CV_OK, "measurement_std": [1.0, 0.0]}),
        "measurement_std",
    ),
    "cv-std-shape": (
        lambda: constant_velocity(0.1, **{**_CV_OK, "measurement_std": [1.0, 1.0, 1.0]}),
        "measurement_std",
    ),
    "cv-negative-psd": (
        lambda: constant_velocity(0.1, **{**_CV_OK, "accel_psd": -1.0}),
        "accel_psd",
    ),
    "cv-prior-shape": (
        lambda: constant_velocity(0.1, **{**_CV_OK, "initial_cov": np.eye(3)}),
        "initial_cov",
    ),
    "singer-zero-theta": (
        lambda: singer(0.1, **{**_SINGER_OK, "maneuver_time_constant": 0.0}),
        "maneuver_time_constant",
    ),
    "singer-negative-sigma": (
        lambda: singer(0.1, **{**_SINGER_OK, "accel_std": -2.0}),
        "accel_std",
    ),
    "ho-negative-R": (lambda: ho_plant(0.1, measurement_var=-1.0), "measurement_var"),
    "ho-R-length": (
        lambda: ho_plant(np.full(3, 0.1), measurement_var=np.full(4, 1e4)),
        "measurement_var",
    ),
    "segments-zero-count": (lambda: segment_schedule((10, 0, 5)), "counts"),
    "segments-float-count": (lambda: segment_schedule((10, 2.5)), "counts"),
    "segments-empty": (lambda: segment_schedule(()), "counts"),
    "segments-not-sequence": (lambda: segment_schedule(10), "counts"),
    "segments-negative-D": (
        lambda: segment_schedule((10,), segment_duration=-1.0),
        "segment_duration",
    ),
    "times-scalar": (lambda: sample_times(0.1), "taus"),
}


@pytest.mark.parametrize("case", sorted(_BAD_INPUTS))
def test_bad_inputs_raise_input_error_naming_argument(case):
    """Each bad input raises InputError whose message names the offending argument in backticks."""
    call, argname = _BAD_INPUTS[case]
    with pytest.raises(InputError, match=f"`{argname}`"):
        call()


def test_covariance_check_is_independent_of_units():
    """Definiteness is judged on the correlation matrix: variances from 1e-16 to 1e3 pass."""
    import numpy as _np

    from jaxtrack._validation import check_covariance

    rng = _np.random.default_rng(0)
    a = rng.normal(size=(6, 6))
    corr = a @ a.T + 6 * _np.eye(6)
    sd = _np.sqrt(_np.logspace(-16, 3, 6))
    check_covariance("P0", sd[:, None] * corr * sd[None, :])  # must not raise
    singular = _np.ones((3, 3)) * _np.array([1e-12, 1.0, 1e4])[None, :] ** 0.5 * _np.array([1e-12, 1.0, 1e4])[:, None] ** 0.5
    with pytest.raises(InputError, match="P0"):
        check_covariance("P0", singular)
    check_covariance("Q", singular, definite=False)  # rank one: fine as a plant noise
    with pytest.raises(InputError, match="diagonal"):
        check_covariance("Q", _np.diag([1.0, -1.0]), definite=False)

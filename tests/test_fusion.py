"""Track-to-track fusion (jaxtrack.fusion): rules against oracles, properties, Monte Carlo, gradients.

Oracles: Stone Soup's covariance intersection (``CovarianceIntersection.merge_components``, the
``P⁻¹ = Σ ω_i P_i⁻¹`` formula), NumPy transcriptions of the papers' equations written here with
explicit inverses (split CI: Li, Nashashibi & Yang 2013; ellipsoidal intersection: Sijs & Lazar
2012, eqs. (8)–(16c), the equations the NRL Tracker Component Library's ``ellipsoidIntersect``
follows; Bar-Shalom & Campo 1986), SciPy's bounded scalar minimiser for the optimal weight,
central finite differences for the derivatives, and χ² bounds on the Monte Carlo NEES.

The compiled functions are module-level ``jax.jit``s, shared by the tests (one compilation per
state dimension and per static option).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize
import scipy.stats
from helpers import assert_close, random_spd

from jaxtrack import InputError, fusion
from jaxtrack.models import LinearGaussianModel
from jaxtrack.montecarlo import simulate

TOL = 1e-12

_ci = jax.jit(fusion.covariance_intersection, static_argnames=("criterion", "iterations"))
_sci = jax.jit(fusion.split_covariance_intersection, static_argnames=("criterion", "iterations"))
_ei = jax.jit(fusion.ellipsoidal_intersection)
_bc = jax.jit(fusion.bar_shalom_campo)
_independent = jax.jit(fusion.independent_fusion)
_ci_weight = jax.jit(fusion.optimal_ci_weight, static_argnames=("criterion",))
_sci_weight = jax.jit(fusion.optimal_sci_weight, static_argnames=("criterion",))


def _cases(seed: int, count: int = 20, dims=(2, 3, 4, 5, 6)):
    """``count`` random pairs ``(x1, P1, x2, P2)``, dimensions cycling through ``dims``, covariances of
    condition ≤ 100 (rejection-sampled, tests/helpers.py)."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(count):
        n = dims[i % len(dims)]
        scale = 10.0 ** rng.uniform(-1, 1)
        out.append((rng.standard_normal(n) * 3, random_spd(rng, n, 100.0, scale),
                    rng.standard_normal(n) * 3, random_spd(rng, n, 100.0, scale * rng.uniform(0.3, 3))))
    return out


# --- NumPy references, transcribed from the papers with explicit inverses -------------------

inv = np.linalg.inv


def sci_reference(x1, P1, P1i, x2, P2, P2i, w):
    """Li, Nashashibi & Yang (2013): inflate the dependent parts by 1/ω, 1/(1 − ω); fuse; split."""
    P1w = (P1 - P1i) / w + P1i
    P2w = (P2 - P2i) / (1 - w) + P2i
    P = inv(inv(P1w) + inv(P2w))
    x = P @ (inv(P1w) @ x1 + inv(P2w) @ x2)
    Pi = P @ (inv(P1w) @ P1i @ inv(P1w) + inv(P2w) @ P2i @ inv(P2w)) @ P
    return x, P, Pi


def ei_reference(x1, P1, x2, P2, zeta):
    """Sijs & Lazar (2012): eqs. (12a)-(12b), (11), Theorem 6, (13), (16a)-(16c), (8)."""
    d1, S1 = np.linalg.eigh(P1)
    D1_half = np.diag(np.sqrt(d1))
    D1_half_inv = np.diag(1 / np.sqrt(d1))
    d2, S2 = np.linalg.eigh(D1_half_inv @ inv(S1) @ P2 @ inv(S1).T @ D1_half_inv)
    T = S1 @ D1_half @ S2
    dG = np.array([max(1.0, d) for d in d2])
    Gamma = T @ np.diag(dG) @ T.T
    eta = 0.0 if np.all(np.abs(d2 - 1) >= 10 * zeta) else zeta
    W1 = np.diag(1 / d2 - 1 / dG) + eta * np.eye(len(x1))
    W2 = np.diag(1 - 1 / dG) + eta * np.eye(len(x1))
    mu1, mu2 = inv(T) @ x1, inv(T) @ x2
    gamma = T @ inv(W1 + W2) @ (W1 @ mu1 + W2 @ mu2)
    P = inv(inv(P1) + inv(P2) - inv(Gamma))
    x = P @ (inv(P1) @ x1 + inv(P2) @ x2 - inv(Gamma) @ gamma)
    return x, P, gamma, Gamma


def bc_reference(x1, P1, x2, P2, P12):
    """Bar-Shalom & Campo (1986)."""
    U = P1 - P12
    S = P1 + P2 - P12 - P12.T
    return x1 + U @ inv(S) @ (x2 - x1), P1 - U @ inv(S) @ U.T


def _criterion(Y, criterion):
    P = inv(Y)
    return np.trace(P) if criterion == "trace" else np.linalg.slogdet(P)[1]


# --- the rules against their oracles --------------------------------------------------------


def test_covariance_intersection_matches_stone_soup():
    gm = pytest.importorskip("stonesoup.mixturereducer.gaussianmixture")
    from stonesoup.types.state import GaussianState

    rng = np.random.default_rng(7)
    for x1, P1, x2, P2 in _cases(1):
        w = rng.uniform(0.02, 0.98)
        ref = gm.CovarianceIntersection.merge_components(
            GaussianState(x1[:, None], P1), GaussianState(x2[:, None], P2), weights=[w, 1 - w])
        out = _ci(x1, P1, x2, P2, w)
        assert_close(out.cov, np.asarray(ref.covar, float), TOL)
        assert_close(out.mean, np.asarray(ref.state_vector, float).ravel(), TOL)
        assert float(out.weight) == w and bool(out.ok)


def test_split_ci_matches_numpy_reference():
    rng = np.random.default_rng(3)
    for x1, Pd1, x2, Pd2 in _cases(2):
        n = len(x1)
        Pi1, Pi2 = random_spd(rng, n, 100.0, rng.uniform(0.1, 2)), random_spd(rng, n, 100.0, rng.uniform(0.1, 2))
        P1, P2 = Pd1 + Pi1, Pd2 + Pi2
        w = rng.uniform(0.02, 0.98)
        x, P, Pi = sci_reference(x1, P1, Pi1, x2, P2, Pi2, w)
        out = _sci(x1, P1, Pi1, x2, P2, Pi2, w)
        assert_close(out.mean, x, TOL)
        assert_close(out.cov, P, TOL)
        assert_close(out.independent_cov, Pi, TOL)
    # With no independent parts, split CI is CI.
    x1, P1, x2, P2 = _cases(2, 1)[0]
    zero = np.zeros_like(P1)
    assert_close(_sci(x1, P1, zero, x2, P2, zero, 0.3).cov, _ci(x1, P1, x2, P2, 0.3).cov, TOL)


def test_ellipsoidal_intersection_matches_numpy_reference():
    zeta = float(np.sqrt(np.finfo(np.float64).eps))
    for x1, P1, x2, P2 in _cases(3):
        x, P, gamma, Gamma = ei_reference(x1, P1, x2, P2, zeta)
        out = _ei(x1, P1, x2, P2)
        assert_close(out.cov, P, TOL)
        assert_close(out.mean, x, TOL)
        assert_close(out.mutual_cov, Gamma, TOL)
        assert_close(out.mutual_mean, gamma, TOL)


def test_bar_shalom_campo_matches_numpy_reference_and_is_independent_fusion_at_zero_cross_cov():
    rng = np.random.default_rng(4)
    for i in range(20):
        n = 2 + i % 5
        joint = random_spd(rng, 2 * n, 100.0, 10.0 ** rng.uniform(-1, 1))
        P1, P2, P12 = joint[:n, :n], joint[n:, n:], joint[:n, n:]
        x1, x2 = rng.standard_normal(n), rng.standard_normal(n)
        x, P = bc_reference(x1, P1, x2, P2, P12)
        out = _bc(x1, P1, x2, P2, P12)
        assert_close(out.mean, x, TOL)
        assert_close(out.cov, P, TOL)
        # P12 = 0: the information-form fusion (a different formula and code path).
        bc0, ind = _bc(x1, P1, x2, P2, np.zeros((n, n))), _independent(x1, P1, x2, P2)
        Y1, Y2 = inv(P1), inv(P2)
        assert_close(ind.cov, inv(Y1 + Y2), TOL)
        assert_close(bc0.cov, ind.cov, TOL)
        assert_close(bc0.mean, ind.mean, TOL)


def test_optimal_weight_matches_scipy_bounded_minimiser():
    cases = _cases(5, 10, dims=(2, 4))
    # Boundary optima: one estimate much better than the other in every direction.
    x1, P1, x2, P2 = cases[0]
    cases += [(x1, P1, x2, 100 * P1 + P2), (x1, 100 * P2 + P1, x2, P2)]
    for criterion in ("trace", "det"):
        for x1, P1, x2, P2 in cases:
            Y1, Y2 = inv(P1), inv(P2)
            J = lambda w, Y1=Y1, Y2=Y2, c=criterion: _criterion(w * Y1 + (1 - w) * Y2, c)  # noqa: E731
            ref = scipy.optimize.minimize_scalar(J, bounds=(0, 1), method="bounded", options={"xatol": 1e-12})
            out = _ci(x1, P1, x2, P2, criterion=criterion)
            w = float(out.weight)
            # Relative on the trace and on the determinant (absolute on its logarithm). SciPy's
            # bounded Brent stops short of a bound (by ~1e-8), so at a bound ours may be lower.
            scale = abs(ref.fun) if criterion == "trace" else 1.0
            assert J(w) <= ref.fun + 1e-10 * scale, (criterion, w, ref.x)
            if 1e-6 < ref.x < 1 - 1e-6:
                assert J(w) >= ref.fun - 1e-10 * scale, (criterion, w, ref.x)
            assert_close(out.cov, inv(w * Y1 + (1 - w) * Y2), TOL)
        # The bounds exactly (the last two cases); optimal_ci_weight is the same weight.
        for (x1, P1, x2, P2), bound in zip(cases[-2:], (1.0, 0.0)):
            assert float(_ci(x1, P1, x2, P2, criterion=criterion).weight) == bound
    x1, P1, x2, P2 = cases[1]
    assert float(_ci_weight(P1, P2, criterion="trace")) == float(_ci(x1, P1, x2, P2, criterion="trace").weight)
    # Split CI: the same against SciPy on its own criterion.
    rng = np.random.default_rng(6)
    for x1, Pd1, x2, Pd2 in _cases(6, 6, dims=(2, 4)):
        n = len(x1)
        Pi1, Pi2 = random_spd(rng, n, 100.0), random_spd(rng, n, 100.0)
        P1, P2 = Pd1 + Pi1, Pd2 + Pi2
        J = lambda w, a=(x1, P1, Pi1, x2, P2, Pi2): np.trace(sci_reference(*a, w)[1])  # noqa: E731
        ref = scipy.optimize.minimize_scalar(J, bounds=(1e-9, 1 - 1e-9), method="bounded", options={"xatol": 1e-12})
        w = float(_sci_weight(P1, Pi1, P2, Pi2, criterion="trace"))
        assert J(w) <= ref.fun + 1e-10 * abs(ref.fun), (w, ref.x)
        if 1e-6 < ref.x < 1 - 1e-6:
            assert J(w) >= ref.fun - 1e-10 * abs(ref.fun), (w, ref.x)


# --- properties -----------------------------------------------------------------------------


def _fused_error_cov(P, Y1, Y2, joint):
    """The actual covariance of ``P (Y1 e1 + Y2 e2)`` for errors with joint covariance ``joint``."""
    A = P @ np.hstack([Y1, Y2])
    return A @ joint @ A.T


def _correlated_joint(rng, n):
    """A valid joint covariance of (e1, e2) with a common part, e_i = M_i a + b_i, and the
    covariances of the independent parts b_1, b_2."""
    Pa = random_spd(rng, n, 100.0)
    M1, M2 = np.eye(n) + 0.3 * rng.standard_normal((n, n)), np.eye(n) + 0.3 * rng.standard_normal((n, n))
    B1, B2 = random_spd(rng, n, 100.0, rng.uniform(0.05, 1)), random_spd(rng, n, 100.0, rng.uniform(0.05, 1))
    M = np.vstack([M1, M2])
    return M @ Pa @ M.T + np.block([[B1, np.zeros((n, n))], [np.zeros((n, n)), B2]]), B1, B2


def test_ci_and_split_ci_bound_the_actual_error_covariance():
    """P_ci − P_true ⪰ 0 for any valid cross-covariance (CI's defining property), and likewise for
    split CI when the independent parts are independent; the naive rule fails the same check."""
    rng = np.random.default_rng(8)
    naive_failures = 0
    for i in range(20):
        n = (2, 4)[i % 2]
        joint, B1, B2 = _correlated_joint(rng, n)
        P1, P2 = joint[:n, :n], joint[n:, n:]
        x = np.zeros(n)
        for w in (rng.uniform(0, 1), None):
            out = _ci(x, P1, x, P2, w) if w is not None else _ci(x, P1, x, P2, criterion="trace")
            wv = float(out.weight)
            P = np.asarray(out.cov)
            true = _fused_error_cov(P, wv * inv(P1), (1 - wv) * inv(P2), joint)
            assert np.linalg.eigvalsh(P - true)[0] >= -1e-10 * np.max(np.abs(P)), (i, w)
        # Split CI with the independent parts b_i declared as such.
        out = _sci(x, P1, B1, x, P2, B2, None)
        wv, P = float(out.weight), np.asarray(out.cov)
        Y1 = wv * inv(P1 - (1 - wv) * B1)
        Y2 = (1 - wv) * inv(P2 - wv * B2)
        true = _fused_error_cov(P, Y1, Y2, joint)
        assert np.linalg.eigvalsh(P - true)[0] >= -1e-10 * np.max(np.abs(P)), i
        ind = np.asarray(_independent(x, P1, x, P2).cov)
        true = _fused_error_cov(ind, inv(P1), inv(P2), joint)
        naive_failures += np.linalg.eigvalsh(ind - true)[0] < -1e-6 * np.max(np.abs(ind))
    assert naive_failures >= 15  # the check can fail: the naive rule is overconfident here


def test_ellipsoidal_intersection_properties_from_the_paper():
    # Equal covariances: the mutual covariance and the fused covariance are that covariance, and
    # by symmetry the mutual and fused means are the midpoint. Every eigenvalue of eq. (12a) is
    # then 1 (to rounding), where only the η regulariser of eq. (16c) keeps W1 + W2 invertible;
    # the two weights then differ by rounding against η = √ε (relative 1e-8), hence 1e-7.
    x1, P, x2, _ = _cases(9, 1, dims=(4,))[0]
    out = _ei(x1, P, x2, P)
    assert_close(out.cov, P, TOL)
    assert_close(out.mutual_cov, P, TOL)
    assert_close(out.mean, (x1 + x2) / 2, 1e-7)
    assert_close(out.mutual_mean, (x1 + x2) / 2, 1e-7)
    out = _ei(x1, P, x1, P)  # identical inputs: the input itself
    assert_close(out.mean, x1, TOL)
    assert_close(out.cov, P, TOL)
    # Jointly diagonal covariances: along each axis EI keeps the more precise estimate
    # (eq. (8) with eq. (11): P = min(P1, P2) axis by axis, and that estimate's mean).
    rng = np.random.default_rng(9)
    for n in (2, 3, 5):
        a, b = rng.uniform(0.5, 5, n), rng.uniform(0.5, 5, n)
        x1, x2 = rng.standard_normal(n), rng.standard_normal(n)
        out = _ei(x1, np.diag(a), x2, np.diag(b))
        assert_close(out.cov, np.diag(np.minimum(a, b)), 1e-13)
        assert_close(out.mean, np.where(a < b, x1, x2), 1e-13)
    # The strategy object is the function (eagerly, no jit).
    rule = fusion.EllipsoidalIntersection()
    assert_close(rule.fuse(x1, np.diag(a), x2, np.diag(b)).mean, out.mean, 1e-15)


# --- the two-sensor run ---------------------------------------------------------------------

NUM_RUNS, NUM_SCANS = 1000, 4
# A 2-D nearly-constant-velocity target (state x, vx, y, vy; 1 s scans) seen by two position
# sensors, one precise in x and coarse in y, the other the other way round: neither local
# covariance bounds the other, so the optimal CI weight lies inside (0, 1).
_F = np.kron(np.eye(2), np.array([[1.0, 1.0], [0.0, 1.0]]))
_Q = 0.5 * np.kron(np.eye(2), np.array([[1 / 3, 1 / 2], [1 / 2, 1.0]]))
_PRIOR = (np.zeros(4), np.diag([25.0, 4.0, 25.0, 4.0]))
_H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
_R1, _R2 = np.diag([1.0, 16.0]), np.diag([16.0, 1.0])
SENSOR1 = LinearGaussianModel(_F, _Q, _H, _R1, *_PRIOR)
SENSOR2 = LinearGaussianModel(_F, _Q, _H, _R2, *_PRIOR)
BOTH = fusion.stacked_sensor_model(SENSOR1, SENSOR2)
MC_RULES = {
    "ci": fusion.CovarianceIntersection(),
    "sci": fusion.SplitCovarianceIntersection(),
    "bc": fusion.BarShalomCampo(),
    "naive": fusion.IndependentFusion(),
}


@jax.jit
def _monte_carlo_nees(key):
    """Final-scan NEES of every rule over NUM_RUNS runs (run i simulated from fold_in(key, i)),
    and the final CI weight of each run."""

    def one(i):
        traj = simulate(BOTH, jax.random.fold_in(key, i), NUM_SCANS, throw=False)
        z1, z2 = traj.measurements[:, :2], traj.measurements[:, 2:]
        nees = {}
        for name, rule in MC_RULES.items():
            out = fusion.run_track_fusion(rule, SENSOR1, SENSOR2, z1, z2)
            e = traj.states[-1] - out.fused_mean[-1]
            nees[name] = jnp.where(out.ok & traj.ok, e @ jnp.linalg.solve(out.fused_cov[-1], e), jnp.nan)
            if name == "ci":
                weight = out.fused_weight[-1]
        return nees, weight

    return jax.vmap(one)(jnp.arange(NUM_RUNS))


def test_monte_carlo_nees_ci_conservative_naive_not_bc_consistent():
    """Two sensors, one target, common process noise and prior: the local errors are correlated.

    Each run's final NEES is χ²(n) for a consistent rule, so the mean of 1,000 runs lies in
    [χ²⁻¹(0.005; 1000 n), χ²⁻¹(0.995; 1000 n)] / 1000 with probability 0.99 (two-sided 99%;
    n = 4: [3.773, 4.234]). CI and split CI must not exceed the upper bound (conservative), the
    naive rule must exceed it (the test discriminates), Bar-Shalom–Campo with the exact
    cross-covariance must lie inside.
    """
    n = 4
    lower = scipy.stats.chi2.ppf(0.005, NUM_RUNS * n) / NUM_RUNS
    upper = scipy.stats.chi2.ppf(0.995, NUM_RUNS * n) / NUM_RUNS
    nees, weight = _monte_carlo_nees(jax.random.key(2024))
    nees = {k: np.asarray(v) for k, v in nees.items()}
    assert np.all((0.1 < np.asarray(weight)) & (np.asarray(weight) < 0.9))  # CI is not one track
    assert all(np.all(np.isfinite(v)) for v in nees.values())
    mean = {k: float(v.mean()) for k, v in nees.items()}
    assert mean["ci"] <= upper, mean
    assert mean["sci"] <= upper, mean
    assert mean["naive"] > upper, mean
    assert lower <= mean["bc"] <= upper, mean


_run = jax.jit(fusion.run_track_fusion, static_argnames=("first_step",))


def test_run_cross_covariance_and_split_recursions_agree():
    # Two identical sensors: equal gains, so the cross-covariance recursion and each filter's
    # dependent part (P − P_ind) are the same recursion; P_ind must stay below P.
    traj = simulate(BOTH, 5, NUM_SCANS)
    z = traj.measurements[:, :2]
    out = _run(fusion.BarShalomCampo(), SENSOR1, SENSOR1, z, z)
    assert bool(out.ok)
    assert_close(out.cross_cov, np.asarray(out.cov1) - np.asarray(out.independent_cov1), 1e-12)
    # Two different sensors: both local covariances split into non-negative parts.
    out = _run(fusion.BarShalomCampo(), SENSOR1, SENSOR2, traj.measurements[:, :2], traj.measurements[:, 2:])
    for P, Pi in ((out.cov1, out.independent_cov1), (out.cov2, out.independent_cov2)):
        for k in range(NUM_SCANS):
            assert np.linalg.eigvalsh(np.asarray(Pi[k]))[0] >= -1e-12
            assert np.linalg.eigvalsh(np.asarray(P[k] - Pi[k]))[0] >= -1e-12


# --- derivatives ----------------------------------------------------------------------------


def _central(f, x, h):
    return (f(x + h) - f(x - h)) / (2 * h)


def _optimal_fusion_outputs(x1, P1, x2, P2, E, criterion):
    """Functions of ``t``: the optimal weight, a mean component and the fused trace at ``P1 + t E``."""

    def fused(t):
        return _ci(x1, P1 + t * E, x2, P2, criterion=criterion)

    return {"weight": lambda t: fused(t).weight, "mean": lambda t: fused(t).mean[1],
            "trace": lambda t: jnp.trace(fused(t).cov)}


def test_gradients_of_fixed_and_optimal_weight_fusion_match_finite_differences():
    x1, P1, x2, P2 = _cases(11, 1, dims=(4,))[0]  # optimal ω 0.49 (trace), 0.74 (det)
    # d/dω at a fixed ω of the fused trace and of a mean component.
    trace_of = lambda w: jnp.trace(_ci(x1, P1, x2, P2, w).cov)  # noqa: E731
    mean_of = lambda w: _ci(x1, P1, x2, P2, w).mean[0]  # noqa: E731
    for f in (trace_of, mean_of):
        g = float(jax.grad(f)(0.37))
        assert abs(g - _central(lambda w, f=f: float(f(w)), 0.37, 1e-5)) <= 1e-6 * abs(g)
    # d/dP1 (a symmetric direction) through the optimal ω: the weight, a mean component, the
    # trace under the det criterion, at an interior and at a boundary optimum.
    E = np.zeros((4, 4))
    E[0, 1] = E[1, 0] = 1.0
    E[2, 2] = 0.5
    interior, boundary = (x1, P1, x2, P2), (x1, P1, x2, 100 * P1 + P2)
    for at_bound, (a1, A1, a2, A2), criterion in ((False, interior, "trace"), (False, interior, "det"),
                                                   (True, boundary, "det")):
        fs = _optimal_fusion_outputs(a1, A1, a2, A2, E, criterion)
        assert (float(fs["weight"](0.0)) == 1.0) if at_bound else (0.05 < float(fs["weight"](0.0)) < 0.95)
        for name, f in fs.items():
            _, d = jax.jvp(f, (0.0,), (1.0,))
            fd = _central(lambda t, f=f: float(f(t)), 0.0, 1e-5)
            assert abs(float(d) - fd) <= 1e-6 * max(abs(fd), 1e-3), (criterion, name, float(d), fd)
        if at_bound:
            assert float(fs["weight"](0.0)) == 1.0 and float(jax.jvp(fs["weight"], (0.0,), (1.0,))[1]) == 0.0


def test_run_is_differentiable_in_the_weight_and_in_measurement_noise():
    traj = simulate(BOTH, 6, NUM_SCANS)
    z1, z2 = traj.measurements[:, :2], traj.measurements[:, 2:]

    @jax.jit
    def objective(w, r1):
        sensor1 = LinearGaussianModel(_F, _Q, _H, r1 * _R1, *_PRIOR)
        out = fusion.run_track_fusion(fusion.CovarianceIntersection(w), sensor1, SENSOR2, z1, z2)
        return jnp.sum(jnp.trace(out.fused_cov, axis1=1, axis2=2)) + jnp.sum(out.fused_mean[:, 0])

    grad = jax.jit(jax.grad(objective, argnums=(0, 1)))
    dw, dr = (float(g) for g in grad(0.4, 1.3))
    assert abs(dw - _central(lambda w: float(objective(w, 1.3)), 0.4, 1e-5)) <= 1e-6 * abs(dw)
    assert abs(dr - _central(lambda r: float(objective(0.4, r)), 1.3, 1e-5)) <= 1e-6 * abs(dr)


# --- bad input ------------------------------------------------------------------------------


def test_bad_input_errors_name_the_argument():
    x, P = np.zeros(3), np.eye(3)
    with pytest.raises(InputError, match="`cov1`"):
        fusion.covariance_intersection(x, np.ones((3, 2)), x, P, 0.5)
    with pytest.raises(InputError, match="`mean2`"):
        fusion.covariance_intersection(x, P, np.zeros(2), P, 0.5)
    with pytest.raises(InputError, match="`cov2`"):
        fusion.independent_fusion(x, P, x, -P)
    with pytest.raises(InputError, match="`omega`"):
        fusion.covariance_intersection(x, P, x, P, 1.5)
    with pytest.raises(InputError, match="`omega`"):
        fusion.SplitCovarianceIntersection(omega=-0.1)
    with pytest.raises(InputError, match="`criterion`"):
        fusion.CovarianceIntersection(criterion="max")
    with pytest.raises(InputError, match="`criterion`"):
        fusion.optimal_ci_weight(P, P, criterion="volume")
    with pytest.raises(InputError, match="`cross_cov`"):
        fusion.BarShalomCampo().fuse(x, P, x, P)
    with pytest.raises(InputError, match="`cross_cov`"):
        fusion.bar_shalom_campo(x, P, x, P, np.eye(2))
    with pytest.raises(InputError, match="`independent_cov1`"):
        fusion.split_covariance_intersection(x, P, 2 * P, x, P, None, 0.5)
    with pytest.raises(InputError, match="`zeta`"):
        fusion.ellipsoidal_intersection(x, P, x, P, zeta=-1.0)
    z = np.zeros((NUM_SCANS, 2))
    with pytest.raises(InputError, match="`rule`"):
        fusion.run_track_fusion("ci", SENSOR1, SENSOR2, z, z)
    with pytest.raises(InputError, match="`measurements2`"):
        fusion.run_track_fusion(fusion.IndependentFusion(), SENSOR1, SENSOR2, z, z[:-1])
    other = LinearGaussianModel(2 * _F, _Q, _H, _R2, *_PRIOR)
    with pytest.raises(InputError, match="`model2`"):
        fusion.run_track_fusion(fusion.IndependentFusion(), SENSOR1, other, z, z)
    # A traced ω outside [0, 1] cannot raise: NaN, flagged by ok.
    out = _ci(x, P, x, 2 * P, jnp.asarray(1.5))
    assert not bool(out.ok) and np.all(np.isnan(np.asarray(out.mean)))
    assert bool(_ci(x, P, x, 2 * P, jnp.asarray(0.5)).ok)

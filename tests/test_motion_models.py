"""Motion-model components (jaxtrack.models._motion): turn models against Stone Soup, ω → 0 limits,
analytic vs autodiff Jacobians, gradients vs finite differences, block composition, EKF runs."""

from __future__ import annotations

import datetime

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxtrack
from jaxtrack import InputError
from jaxtrack.filters import ExtendedKalmanFilter, KalmanFilter, run_filter
from jaxtrack.models import (
    AbstractMeasurementModel,
    AbstractTransitionModel,
    BlockTransition,
    ConstantAcceleration,
    ConstantVelocity,
    CoordinatedTurn,
    LinearGaussianModel,
    LinearTransition,
    NearlyConstantTurn,
    TrackingModel,
    constant_acceleration,
    constant_velocity,
)
from jaxtrack.models._motion import _cosc, _dcosc, _dsinc, _sinc

stonesoup_linear = pytest.importorskip("stonesoup.models.transition.linear")
stonesoup_nonlinear = pytest.importorskip("stonesoup.models.transition.nonlinear")
from stonesoup.types.array import StateVector  # noqa: E402
from stonesoup.types.state import State  # noqa: E402

# Stone Soup orders [x, vx, y, vy(, ω)]; jaxtrack [x, y, vx, vy(, ω)]: jaxtrack = stonesoup[P].
P4 = np.array([0, 2, 1, 3])
P5 = np.array([0, 2, 1, 3, 4])

TURN_CASES = [(0.1, 1.0), (-0.3, 2.5), (1.2, 0.5), (-2.0, 3.0), (0.05, 10.0), (-1e-3, 1.0), (0.4, 1.3)]


def _dt(tau):
    return datetime.timedelta(seconds=tau)


def _permute(M, p):
    return np.asarray(M)[np.ix_(p, p)]


# --------------------------------------------------------------------------------------------
# against Stone Soup


@pytest.mark.parametrize("omega,tau", TURN_CASES)
def test_coordinated_turn_matches_stonesoup_known_turn_rate(omega, tau):
    q = (0.7, 1.9)
    ss = stonesoup_linear.KnownTurnRate(turn_noise_diff_coeffs=np.array(q), turn_rate=omega)
    ct = CoordinatedTurn(tau, turn_rate=omega, noise_intensity=jnp.array(q))
    F_ss = _permute(ss.matrix(time_interval=_dt(tau)), P4)
    Q_ss = _permute(ss.covar(time_interval=_dt(tau)), P4)
    x_ss = np.array([10.0, -3.0, -25.0, 7.5])
    fx_ss = np.asarray(ss.function(State(StateVector(x_ss)), time_interval=_dt(tau))).ravel()[P4]
    x = jnp.asarray(x_ss[P4])

    np.testing.assert_allclose(ct.transition_matrix(0), F_ss, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(ct.jacobian(x, 0), F_ss, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(ct.mean(x, 0), fx_ss, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(ct.noise_cov(0), Q_ss, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("omega,tau", TURN_CASES)
def test_nearly_constant_turn_matches_stonesoup_constant_turn(omega, tau):
    q, q_omega = (0.7, 1.9), 0.03
    ss = stonesoup_nonlinear.ConstantTurn(linear_noise_coeffs=np.array(q), turn_noise_coeff=q_omega)
    nct = NearlyConstantTurn(tau, noise_intensity=jnp.array(q), turn_rate_intensity=q_omega)
    x_ss = np.array([10.0, -3.0, -25.0, 7.5, omega])
    state = State(StateVector(x_ss))
    fx_ss = np.asarray(ss.function(state, time_interval=_dt(tau))).ravel()[P5]
    Q_ss = _permute(ss.covar(time_interval=_dt(tau)), P5)
    x = jnp.asarray(x_ss[P5])

    np.testing.assert_allclose(nct.mean(x, 0), fx_ss, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(nct.noise_cov(0), Q_ss, rtol=1e-12, atol=1e-12)
    # Stone Soup's ConstantTurn has no analytic Jacobian: its `jacobian` is a forward difference
    # with steps ~1e-8, accurate to ~1e-6 only. The 1e-10 checks are against jax.jacfwd below.
    # At small |ωτ| its direct (1 − cos ωτ)/ω loses digits and that forward difference is off by
    # ~1e-5, so the comparison there is against a central difference (h = 1e-5) of Stone Soup's
    # own function, good to ~1e-8 at every ω.
    J = np.asarray(nct.jacobian(x, 0))
    scale = max(1.0, np.max(np.abs(J)))
    if abs(omega * tau) >= 0.05:
        J_ss = _permute(ss.jacobian(state, time_interval=_dt(tau)), P5)
        assert np.max(np.abs(J - J_ss)) < 2e-6 * scale
    h = 1e-5
    columns = []
    for i in range(5):
        e = np.zeros(5)
        e[i] = h
        plus = ss.function(State(StateVector(x_ss + e)), time_interval=_dt(tau))
        minus = ss.function(State(StateVector(x_ss - e)), time_interval=_dt(tau))
        columns.append((np.asarray(plus) - np.asarray(minus)).ravel() / (2 * h))
    J_cd = _permute(np.stack(columns, axis=1), P5)
    assert np.max(np.abs(J - J_cd)) < 1e-7 * scale


# --------------------------------------------------------------------------------------------
# ω → 0


def _cv_limit_derivative(tau):
    """∂F/∂ω of the 2-D coordinated turn at ω = 0 (series limit), [x, y, vx, vy]."""
    return np.array(
        [[0, 0, 0, -tau**2 / 2], [0, 0, tau**2 / 2, 0], [0, 0, 0, -tau], [0, 0, tau, 0]], dtype=float
    )


@pytest.mark.parametrize("tau", [0.5, 3.0])
def test_coordinated_turn_limit_at_zero_turn_rate(tau):
    @jax.jit
    def F(omega):
        return CoordinatedTurn(tau, turn_rate=omega, noise_intensity=1.0).transition_matrix(0)

    F_cv = ConstantVelocity(tau, noise_intensity=1.0, dim=2).transition_matrix(0)
    np.testing.assert_array_equal(F(0.0), F_cv)
    # Continuity into the limit and across the series/closed-form switch at |ωτ| = 0.5.
    dF0 = jax.jacfwd(F)(0.0)
    assert np.all(np.isfinite(dF0))
    np.testing.assert_allclose(dF0, _cv_limit_derivative(tau), rtol=0, atol=1e-15)
    # Continuity into the limit (first order) and across the series/closed-form switch at |ωτ| = 0.5.
    np.testing.assert_allclose(F(1e-9), F_cv + 1e-9 * dF0, rtol=0, atol=1e-15)
    cut = 0.5 / tau
    below = np.nextafter(cut, 0.0)
    np.testing.assert_allclose(F(below), F(cut), rtol=0, atol=1e-14)
    np.testing.assert_allclose(jax.jacrev(F)(0.0), dF0, rtol=0, atol=1e-15)
    h = 1e-5  # central difference straddling 0 (F is smooth there)
    np.testing.assert_allclose((F(h) - F(-h)) / (2 * h), dF0, rtol=0, atol=1e-9)
    # Second derivative finite too (an EKF gradient differentiates the Jacobian once more).
    assert np.all(np.isfinite(jax.jacfwd(jax.jacfwd(F))(0.0)))


def test_turn_functions_series_and_closed_form_agree():
    # |θ| = 0.5 is the first point on the closed-form side; its neighbour uses the series. Both
    # sides agree in value and derivative, and the derivative functions are the derivatives of the
    # value functions (autodiff through either branch).
    edges = jnp.array([np.nextafter(0.5, 0.0), 0.5, np.nextafter(-0.5, 0.0), -0.5])
    thetas = jnp.array([-3.0, -0.7, -0.49, -1e-3, 2e-2, 0.3, 0.51, 1.7, 6.0, 0.0])

    @jax.jit
    def evaluate(t):
        out = []
        for fn, dfn in ((_sinc, _dsinc), (_cosc, _dcosc)):
            out += [fn(t), dfn(t), jax.vmap(jax.grad(fn))(t), jax.vmap(jax.grad(dfn))(t)]
        return out

    for values in (evaluate(edges)[i] for i in range(8)):
        assert abs(float(values[0] - values[1])) < 1e-14 and abs(float(values[2] - values[3])) < 1e-14
    s1, ds1, gs1, _, c1, dc1, gc1, _ = evaluate(thetas)
    np.testing.assert_allclose(gs1, ds1, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(gc1, dc1, rtol=1e-13, atol=1e-15)
    t = np.asarray(thetas[:-1])
    np.testing.assert_allclose(s1[:-1], np.sin(t) / t, rtol=1e-14)
    np.testing.assert_allclose(c1[:-1], (1 - np.cos(t)) / t, rtol=1e-10)  # numpy's side loses digits
    np.testing.assert_allclose(ds1[:-1], (t * np.cos(t) - np.sin(t)) / t**2, rtol=1e-8)
    np.testing.assert_allclose(dc1[:-1], (t * np.sin(t) - 1 + np.cos(t)) / t**2, rtol=1e-8)
    assert (float(s1[-1]), float(c1[-1]), float(ds1[-1]), float(dc1[-1])) == (1.0, 0.0, 0.0, 0.5)


@pytest.mark.parametrize("tau", [0.5, 2.0])
def test_nearly_constant_turn_jacobian_limit_at_zero(tau):
    nct = NearlyConstantTurn(tau, noise_intensity=0.3, turn_rate_intensity=0.01)
    vx, vy = 3.0, -4.0
    x = jnp.array([1.0, 2.0, vx, vy, 0.0])
    J = nct.jacobian(x, 0)
    limit = np.array([-(tau**2) * vy / 2, tau**2 * vx / 2, -tau * vy, tau * vx, 1.0])
    np.testing.assert_allclose(J[:, 4], limit, rtol=0, atol=1e-14)
    np.testing.assert_allclose(J[:4, :4], ConstantVelocity(tau, noise_intensity=1.0).transition_matrix(0), atol=1e-15)
    np.testing.assert_allclose(jax.jacfwd(nct.mean)(x, 0), J, rtol=0, atol=1e-14)
    # The Jacobian is itself differentiable at ω = 0 (finite second derivatives).
    assert np.all(np.isfinite(jax.jacfwd(nct.jacobian)(x, 0)))
    # Against a central difference straddling ω = 0.
    h = 1e-6
    e = jnp.zeros(5).at[4].set(h)
    np.testing.assert_allclose((nct.mean(x + e, 0) - nct.mean(x - e, 0)) / (2 * h), limit, atol=1e-8)


# --------------------------------------------------------------------------------------------
# analytic Jacobians vs autodiff


def _models():
    return [
        ConstantVelocity(0.7, noise_intensity=jnp.array([0.2, 0.5, 1.0]), dim=3),
        ConstantAcceleration(0.4, noise_intensity=0.3, dim=2),
        CoordinatedTurn(1.5, turn_rate=-0.2, noise_intensity=0.4),
        CoordinatedTurn(0.8, turn_rate=0.9, noise_intensity=jnp.array([0.4, 0.4, 0.1]), dim=3),
        LinearTransition(jnp.array([[1.0, 0.5], [-0.2, 0.9]]), jnp.eye(2)),
        BlockTransition(
            [NearlyConstantTurn(1.2, noise_intensity=0.3, turn_rate_intensity=0.02), ConstantVelocity(1.2,
                noise_intensity=0.1, dim=1)],
            order=(0, 1, 3, 4, 6, 2, 5),
        ),
    ]


@pytest.mark.parametrize("index", range(6))
def test_linear_and_block_jacobians_match_jacfwd(index):
    model = _models()[index]
    n = model.state_dim
    x = jnp.asarray(np.random.default_rng(index).normal(size=n)) + jnp.zeros(n).at[n - 3].set(0.3)
    J, J_fwd, Q = jax.jit(lambda x: (model.jacobian(x, 0), jax.jacfwd(model.mean)(x, 0), model.noise_cov(0)))(x)
    np.testing.assert_allclose(J, J_fwd, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(Q, Q.T, atol=0)
    assert np.min(np.linalg.eigvalsh(Q)) > -1e-12


def test_nearly_constant_turn_jacobian_matches_jacfwd():
    omegas = jnp.array([-2.3, -0.6, -0.5, -0.2, -1e-7, 0.0, 1e-9, 0.05, 0.25, 0.5, 1.1, 4.0])
    for tau in (0.5, 2.0):
        nct = NearlyConstantTurn(tau, noise_intensity=jnp.array([0.3, 0.5]), turn_rate_intensity=0.02)
        xs = jnp.stack([jnp.array([100.0, -50.0, 12.0, -7.0, w]) for w in omegas])

        @jax.jit
        def jacobians(xs, nct=nct):
            k = jnp.array(0)
            one = jax.vmap(lambda x: nct.jacobian(x, k))(xs)
            fwd = jax.vmap(lambda x: jax.jacfwd(nct.mean)(x, k))(xs)
            rev = jax.vmap(lambda x: jax.jacrev(nct.mean)(x, k))(xs)
            return one, fwd, rev

        J, J_fwd, J_rev = jacobians(xs)
        np.testing.assert_allclose(J, J_fwd, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(J, J_rev, rtol=1e-10, atol=1e-10)


# --------------------------------------------------------------------------------------------
# gradients with respect to the parameters vs central finite differences


def _central(f, v, h):
    return (f(v + h) - f(v - h)) / (2 * h)


@pytest.mark.parametrize("omega", [-0.4, 0.0, 0.03, 0.7])
def test_coordinated_turn_gradients_match_finite_differences(omega):
    rng = np.random.default_rng(3)
    x = jnp.asarray(rng.normal(size=6)) * 10
    wm = jnp.asarray(rng.normal(size=6))
    wq = jnp.asarray(rng.normal(size=(6, 6)))

    def loss(om, tau, q):
        ct = CoordinatedTurn(tau, turn_rate=om, noise_intensity=jnp.stack([q, 2 * q, 0.5 * q]), dim=3)
        return wm @ ct.mean(x, 0) + jnp.sum(wq * ct.noise_cov(0))

    args = (omega, 1.7, 0.3)
    grads = jax.jit(jax.grad(loss, argnums=(0, 1, 2)))(*args)
    loss = jax.jit(loss)
    for i, g in enumerate(grads):
        def partial(v, i=i):
            a = list(args)
            a[i] = v
            return loss(*a)

        fd = _central(partial, args[i], 1e-6)
        assert np.isfinite(float(g))
        np.testing.assert_allclose(g, fd, rtol=1e-7, atol=1e-7)


@pytest.mark.parametrize("omega", [-0.3, 0.0, 0.9])
def test_nearly_constant_turn_gradients_match_finite_differences(omega):
    x = jnp.array([5.0, -2.0, 8.0, 3.0, omega])
    w = jnp.array([0.3, -1.1, 0.7, 0.2, 0.5])

    def loss(tau, q_omega, om):
        nct = NearlyConstantTurn(tau, noise_intensity=jnp.array([0.2, 0.4]), turn_rate_intensity=q_omega)
        xx = x.at[4].set(om)
        # Through the mean, the Jacobian (as an EKF would) and Q.
        return w @ nct.mean(xx, 0) + jnp.sum(nct.jacobian(xx, 0) ** 2) + jnp.sum(nct.noise_cov(0))

    args = (1.3, 0.05, omega)
    grads = jax.jit(jax.grad(loss, argnums=(0, 1, 2)))(*args)
    loss = jax.jit(loss)
    for i, g in enumerate(grads):
        def partial(v, i=i):
            a = list(args)
            a[i] = v
            return loss(*a)

        np.testing.assert_allclose(g, _central(partial, args[i], 1e-6), rtol=1e-7, atol=1e-7)


# --------------------------------------------------------------------------------------------
# composition


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("per_step", [False, True])
def test_per_axis_constant_velocity_blocks_equal_constant_velocity(dim, per_step):
    taus = jnp.array([0.3, 1.1, 2.0, 0.7]) if per_step else jnp.array(1.3)
    q = jnp.array([0.5, 2.0, 0.1])[:dim]
    block = BlockTransition.per_axis([ConstantVelocity(taus, noise_intensity=q[i], dim=1) for i in range(dim)])
    ref = constant_velocity(taus, dim=dim, accel_psd=q, measurement_std=1.0, initial_cov=jnp.eye(2 * dim))
    x = jnp.arange(1.0, 2 * dim + 1)
    assert block.num_steps == (4 if per_step else None)
    for k in range(4 if per_step else 1):
        F_ref, Q_ref = ref.transition_matrix(k), ref.process_noise_cov(k)
        np.testing.assert_allclose(block.jacobian(x, k), F_ref, rtol=0, atol=1e-14)
        np.testing.assert_allclose(block.noise_cov(k), Q_ref, rtol=0, atol=1e-14)
        np.testing.assert_allclose(block.mean(x, k), F_ref @ x, rtol=0, atol=1e-13)
        # The multi-axis component is the same model.
        cv = ConstantVelocity(taus, noise_intensity=q, dim=dim)
        np.testing.assert_allclose(cv.transition_matrix(k), F_ref, rtol=0, atol=1e-14)
        np.testing.assert_allclose(cv.noise_cov(k), Q_ref, rtol=0, atol=1e-14)


def test_constant_acceleration_component_equals_builder():
    ca = ConstantAcceleration(0.6, noise_intensity=jnp.array([0.2, 0.9]), dim=2)
    ref = constant_acceleration(0.6, dim=2, jerk_psd=jnp.array([0.2, 0.9]), measurement_std=1.0,
                                initial_cov=jnp.eye(6))
    np.testing.assert_allclose(ca.transition_matrix(0), ref.F, rtol=0, atol=1e-14)
    np.testing.assert_allclose(ca.noise_cov(0), ref.Q, rtol=0, atol=1e-14)
    per_axis = BlockTransition.per_axis([ConstantAcceleration(0.6, noise_intensity=q, dim=1) for q in (0.2, 0.9)])
    assert per_axis.order == (0, 2, 4, 1, 3, 5)
    np.testing.assert_allclose(per_axis.noise_cov(0), ref.Q, rtol=0, atol=1e-14)


@pytest.mark.parametrize("omega", [-0.7, 0.0, 0.02, 1.5])
def test_block_3d_coordinated_turn_equals_dedicated(omega):
    tau, q = 1.4, jnp.array([0.3, 0.5, 0.05])
    dedicated = CoordinatedTurn(tau, turn_rate=omega, noise_intensity=q, dim=3)
    block = BlockTransition(
        [CoordinatedTurn(tau, turn_rate=omega, noise_intensity=q[:2]), ConstantVelocity(tau, noise_intensity=q[2],
            dim=1)], order=(0, 1, 3, 4, 2, 5)
    )
    x = jnp.array([100.0, -20.0, 3000.0, 150.0, 40.0, -2.0])
    np.testing.assert_allclose(block.mean(x, 0), dedicated.mean(x, 0), rtol=0, atol=1e-14 * 3000)
    np.testing.assert_allclose(block.jacobian(x, 0), dedicated.transition_matrix(0), rtol=0, atol=1e-14)
    np.testing.assert_allclose(block.noise_cov(0), dedicated.noise_cov(0), rtol=0, atol=1e-14)


def test_block_transition_order_is_a_permutation_matrix_conjugation():
    # Reference by explicit matrices: u = P x, J_x = Pᵀ blockdiag(J_i) P, Q_x = Pᵀ blockdiag(Q_i) P.
    blocks = [NearlyConstantTurn(0.9, noise_intensity=0.3, turn_rate_intensity=0.01), ConstantAcceleration(0.9,
        noise_intensity=0.2, dim=1)]
    order = (6, 0, 3, 7, 1, 2, 5, 4)
    model = BlockTransition(blocks, order=order)
    P = np.eye(8)[list(order)]
    x = jnp.asarray(np.random.default_rng(0).normal(size=8))
    u = P @ np.asarray(x)
    u1, u2 = jnp.asarray(u[:5]), jnp.asarray(u[5:])
    J_u = jax.scipy.linalg.block_diag(blocks[0].jacobian(u1, 0), blocks[1].jacobian(u2, 0))
    Q_u = jax.scipy.linalg.block_diag(blocks[0].noise_cov(0), blocks[1].noise_cov(0))
    f_u = jnp.concatenate([blocks[0].mean(u1, 0), blocks[1].mean(u2, 0)])
    np.testing.assert_allclose(model.mean(x, 0), P.T @ np.asarray(f_u), rtol=0, atol=1e-14)
    np.testing.assert_allclose(model.jacobian(x, 0), P.T @ np.asarray(J_u) @ P, rtol=0, atol=1e-14)
    np.testing.assert_allclose(model.noise_cov(0), P.T @ np.asarray(Q_u) @ P, rtol=0, atol=1e-14)
    np.testing.assert_allclose(model.jacobian(x, 0), jax.jacfwd(model.mean)(x, 0), rtol=1e-10, atol=1e-10)
    # The identity order is the same as no order.
    assert BlockTransition(blocks, order=range(8)).order is None


def test_per_step_coordinated_turn():
    omegas, taus = jnp.array([0.0, 0.3, -0.2]), jnp.array([1.0, 0.5, 2.0])
    ct = CoordinatedTurn(taus, turn_rate=omegas, noise_intensity=0.4)
    assert ct.num_steps == 3
    for k in range(3):
        single = CoordinatedTurn(taus[k], turn_rate=omegas[k], noise_intensity=0.4)
        np.testing.assert_array_equal(ct.transition_matrix(k), single.transition_matrix(0))
        np.testing.assert_array_equal(ct.noise_cov(k), single.noise_cov(0))
    # Inside a scan the step index is traced.
    Fs = jax.lax.map(ct.transition_matrix, jnp.arange(3))
    np.testing.assert_array_equal(Fs[1], CoordinatedTurn(0.5, turn_rate=0.3, noise_intensity=0.4).transition_matrix(0))
    with pytest.raises(InputError, match="`turn_rate` has 3.*`sample_period` has 2"):
        CoordinatedTurn(taus[:2], turn_rate=omegas, noise_intensity=0.4)
    with pytest.raises(InputError, match="`blocks` disagree on the number of steps"):
        BlockTransition([ConstantVelocity(taus, noise_intensity=1.0, dim=1), ConstantVelocity(taus[:2],
            noise_intensity=1.0, dim=1)])


def test_float32_inputs_stay_float32():
    f32 = jnp.float32
    ct = CoordinatedTurn(jnp.array(1.0, f32), turn_rate=jnp.array(0.0, f32), noise_intensity=jnp.array(0.1, f32))
    assert ct.transition_matrix(0).dtype == f32 and ct.noise_cov(0).dtype == f32
    nct = NearlyConstantTurn(jnp.array(1.0, f32), noise_intensity=jnp.array(0.1, f32),
                             turn_rate_intensity=jnp.array(0.01, f32))
    x = jnp.array([1, 2, 3, 4, 0.0], f32)
    assert nct.mean(x, 0).dtype == f32 and nct.jacobian(x, 0).dtype == f32
    assert nct.noise_cov(0).dtype == f32
    assert np.all(np.isfinite(nct.jacobian(x, 0)))


# --------------------------------------------------------------------------------------------
# errors


@pytest.mark.parametrize(
    "build,name",
    [
        (lambda: CoordinatedTurn(-1.0, turn_rate=0.1, noise_intensity=0.1), "sample_period"),
        (lambda: CoordinatedTurn(1.0, turn_rate=0.1, noise_intensity=-0.1), "noise_intensity"),
        (lambda: CoordinatedTurn(1.0, turn_rate=0.1, noise_intensity=jnp.ones(3)), "noise_intensity"),
        (lambda: CoordinatedTurn(1.0, turn_rate=jnp.ones((2, 2)), noise_intensity=0.1), "turn_rate"),
        (lambda: CoordinatedTurn(1.0, turn_rate=jnp.nan, noise_intensity=0.1), "turn_rate"),
        (lambda: CoordinatedTurn(1.0, turn_rate=0.1, noise_intensity=0.1, dim=1), "dim"),
        (lambda: ConstantVelocity(0.0, noise_intensity=0.1), "sample_period"),
        (lambda: ConstantVelocity(1.0, noise_intensity=0.1, dim=4), "dim"),
        (lambda: ConstantAcceleration(1.0, noise_intensity=jnp.array([0.1, -0.2]), dim=2), "noise_intensity"),
        (lambda: NearlyConstantTurn(1.0, noise_intensity=0.1, turn_rate_intensity=-0.01), "turn_rate_intensity"),
        (lambda: NearlyConstantTurn(-1.0, noise_intensity=0.1, turn_rate_intensity=0.01), "sample_period"),
        (lambda: LinearTransition(jnp.eye(3), jnp.eye(2)), "process_noise_cov"),
        (lambda: LinearTransition(jnp.ones(3), jnp.eye(3)), "transition_matrix"),
        (lambda: LinearTransition(jnp.eye(2), -jnp.eye(2)), "process_noise_cov"),
        (lambda: BlockTransition([]), "blocks"),
        (lambda: BlockTransition([ConstantVelocity(1.0, noise_intensity=0.1, dim=1), "cv"]), "blocks"),
        (lambda: BlockTransition([ConstantVelocity(1.0, noise_intensity=0.1, dim=1)], order=(0, 0)), "order"),
        (lambda: BlockTransition([ConstantVelocity(1.0, noise_intensity=0.1, dim=1)], order=(0, 1, 2)), "order"),
        (lambda: BlockTransition([ConstantVelocity(1.0, noise_intensity=0.1, dim=1)], order=(0.0, 1.0)), "order"),
        (lambda: BlockTransition([ConstantVelocity(1.0, noise_intensity=0.1, dim=1)], order=(1, 2)), "order"),
        (lambda: BlockTransition.per_axis([ConstantVelocity(1.0, noise_intensity=0.1, dim=1),
                                           ConstantAcceleration(1.0, noise_intensity=0.1, dim=1)]), "blocks"),
    ],
)
def test_bad_arguments_raise_input_error_naming_them(build, name):
    with pytest.raises(InputError, match=f"`{name}`"):
        build()


# --------------------------------------------------------------------------------------------
# filters on TrackingModel


class _PositionSensor(AbstractMeasurementModel):
    """z = [x, y] + v (test-only; the library's sensor models live elsewhere)."""

    std: jax.Array
    n: int = eqx.field(static=True)
    angle_components: tuple[int, ...] = eqx.field(static=True)

    def __init__(self, std, n):
        self.std, self.n, self.angle_components = std, n, ()

    def mean(self, x, k):
        return x[:2]

    def noise_cov(self, k):
        return self.std**2 * jnp.eye(2)

    @property
    def meas_dim(self):
        return 2

    def jacobian(self, x, k):
        return jnp.eye(2, self.n)


class _JacfwdOf(AbstractTransitionModel):
    """The same motion model with the default ``jax.jacfwd`` Jacobian (reference)."""

    inner: AbstractTransitionModel

    def mean(self, x, k):
        return self.inner.mean(x, k)

    def noise_cov(self, k):
        return self.inner.noise_cov(k)

    @property
    def state_dim(self):
        return self.inner.state_dim


@eqx.filter_jit
def _simulate(model, x0, steps, key):
    """Truth ``x_0 … x_{steps-1}`` from ``model`` and position measurements with σ = 5 m."""
    kq, kr = jax.random.split(key)

    def step(x, k):
        L = jnp.linalg.cholesky(model.noise_cov(k))
        x = model.mean(x, k) + L @ jax.random.normal(jax.random.fold_in(kq, k), x.shape)
        return x, x

    _, rest = jax.lax.scan(step, x0, jnp.arange(1, steps))
    xs = jnp.concatenate([x0[None], rest])
    return xs, xs[:, :2] + 5.0 * jax.random.normal(kr, (steps, 2))


def test_ekf_on_coordinated_turn_equals_kalman_filter():
    tau, omega, steps = 1.0, 0.08, 60
    ct = CoordinatedTurn(tau, turn_rate=omega, noise_intensity=0.05)
    x0 = jnp.array([0.0, 0.0, 20.0, 0.0])
    _, zs = _simulate(ct, x0, steps, jax.random.PRNGKey(1))
    P0 = jnp.diag(jnp.array([100.0, 100.0, 25.0, 25.0]))
    model = TrackingModel(ct, _PositionSensor(jnp.array(5.0), 4), x0, P0)
    ekf = run_filter(ExtendedKalmanFilter(), model, zs)
    lin = LinearGaussianModel(ct.transition_matrix(0), ct.noise_cov(0), jnp.eye(2, 4), 25.0 * jnp.eye(2), x0, P0)
    kf = run_filter(KalmanFilter(), lin, zs)
    assert bool(ekf.ok)
    np.testing.assert_allclose(ekf.filtered_mean, kf.filtered_mean, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(ekf.filtered_cov, kf.filtered_cov, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(ekf.log_likelihood, kf.log_likelihood, rtol=1e-12)


def test_ekf_on_nearly_constant_turn_analytic_equals_jacfwd_and_tracks_the_turn():
    tau, omega, steps = 1.0, 0.06, 120
    nct = NearlyConstantTurn(tau, noise_intensity=0.02, turn_rate_intensity=1e-6)
    truth, zs = _simulate(nct, jnp.array([0.0, 0.0, 15.0, 0.0, omega]), steps, jax.random.PRNGKey(7))
    m0 = jnp.array([0.0, 0.0, 15.0, 0.0, 0.0])  # starts believing in a straight line
    P0 = jnp.diag(jnp.array([50.0, 50.0, 10.0, 10.0, 0.01]))
    sensor = _PositionSensor(jnp.array(5.0), 5)
    analytic = run_filter(ExtendedKalmanFilter(), TrackingModel(nct, sensor, m0, P0), zs)
    reference = run_filter(ExtendedKalmanFilter(), TrackingModel(_JacfwdOf(nct), sensor, m0, P0), zs)
    assert bool(analytic.ok)
    np.testing.assert_allclose(analytic.filtered_mean, reference.filtered_mean, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(analytic.filtered_cov, reference.filtered_cov, rtol=1e-10, atol=1e-12)
    # The turn rate is learned: the final estimate within 3σ of the truth, and 3σ < |ω| / 2.
    w_hat, w_sd = analytic.final_mean[4], jnp.sqrt(analytic.final_cov[4, 4])
    assert abs(float(w_hat - truth[-1, 4])) < 3 * float(w_sd)
    assert 3 * float(w_sd) < omega / 2


def test_gradient_of_ekf_log_likelihood_wrt_turn_rate():
    tau, steps = 1.0, 30
    x0 = jnp.array([0.0, 0.0, 20.0, 0.0])
    _, zs = _simulate(CoordinatedTurn(tau, turn_rate=0.1, noise_intensity=0.05), x0, steps, jax.random.PRNGKey(2))
    P0 = 10.0 * jnp.eye(4)

    def loglik(omega):
        model = TrackingModel(CoordinatedTurn(tau, turn_rate=omega, noise_intensity=0.05),
                              _PositionSensor(jnp.array(5.0), 4), x0, P0)
        return run_filter(ExtendedKalmanFilter(), model, zs, save="final", throw=False).log_likelihood

    # Forward mode (one scalar parameter; compiles several times faster than reverse mode here),
    # one compilation for the values and the derivatives.
    value_and_derivative = jax.jit(lambda w: jax.jvp(loglik, (w,), (jnp.ones_like(w),)))
    for omega in (0.0, 0.1):
        fd = _central(lambda w: value_and_derivative(jnp.asarray(w))[0], omega, 1e-6)
        np.testing.assert_allclose(value_and_derivative(jnp.asarray(omega))[1], fd, rtol=1e-6)
    assert float(value_and_derivative(jnp.asarray(0.0))[1]) > 0  # the data turn left: ℓ rises with ω


def test_exports():
    for name in ("BlockTransition", "ConstantAcceleration", "ConstantVelocity", "CoordinatedTurn",
                 "LinearTransition", "NearlyConstantTurn"):
        assert getattr(jaxtrack.models, name) is not None


@pytest.mark.parametrize(
    "old, new",
    [
        (lambda: CoordinatedTurn(0.05, 2.0, 0.3), lambda: CoordinatedTurn(2.0, turn_rate=0.05, noise_intensity=0.3)),
        (lambda: ConstantVelocity(2.0, 0.3, dim=3), lambda: ConstantVelocity(2.0, noise_intensity=0.3, dim=3)),
        (lambda: ConstantAcceleration(2.0, 0.3), lambda: ConstantAcceleration(2.0, noise_intensity=0.3)),
        (lambda: NearlyConstantTurn(2.0, 0.3, 1e-3),
         lambda: NearlyConstantTurn(2.0, noise_intensity=0.3, turn_rate_intensity=1e-3)),
    ],
)
def test_motion_models_take_the_period_first_and_the_rest_by_keyword(old, new):
    """One call shape (issue 37: CoordinatedTurn took the turn rate first, the others the period).
    The old positional form works for one release, read in its old order, with a warning that
    spells the new call."""
    with pytest.warns(DeprecationWarning, match=r"positional arguments after the sample period are deprecated.*write"):
        a = old()
    b = new()
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        np.testing.assert_array_equal(x, y)
    assert jax.tree_util.tree_structure(a) == jax.tree_util.tree_structure(b)


def test_a_missing_keyword_is_named():
    with pytest.raises(InputError, match=r"`turn_rate` is required \(keyword\)"):
        CoordinatedTurn(1.0, noise_intensity=0.1)
    with pytest.raises(TypeError, match="multiple values for argument 'noise_intensity'"):
        ConstantVelocity(1.0, 0.5, noise_intensity=0.5)

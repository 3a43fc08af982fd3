"""Ho (1968) sensitivity analysis: targets T1–T15 of specs/ho-sensitivity.md.

Every analytic recursion is held against its autodiff counterpart (or against the exact
perturbed recursion) to rounding; internal values are asserted to the spec's printed digits.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.covariance import actual_covariance, covariance_recursion
from jaxtrack.models import LinearGaussianModel, ho_plant
from jaxtrack.sensitivity import (
    Analytic,
    Autodiff,
    adjoint,
    allowable_gain_ellipsoid,
    covariance_sensitivity,
    denormalize,
    error_transition,
    exact_variation_recursion,
    first_order_variation,
    gain_hessian,
    gain_variation_cost,
    gain_variation_recursion,
    local_variations,
    measurement_noise_period_tradeoff,
    measurement_noise_sensitivity,
    multistage_variation,
    normalize,
    one_stage_update,
    optimal_gain_variation,
    period_sensitivity,
    plant_noise_period_tradeoff,
    plant_noise_sensitivity,
    prediction_variation,
    segment_sensitivity,
    sensitivity_index,
    tangent_recursion,
    time_fixed_sensitivity,
    update_variation,
    value_of_information,
)

L_POS = jnp.diag(jnp.array([1.0, 0.0]))
COUNTS = (10, 10, 10, 10, 10)


def uniform(tau, g=1.0):
    return ho_plant(jnp.full(50, tau), g=g)


def per_segment(g=1.0, smoothed=False):
    def model_fn(segment_taus):
        taus = jnp.repeat(segment_taus, jnp.asarray(COUNTS), total_repeat_length=sum(COUNTS))
        return ho_plant(taus, g=g, measurement_var=1e3 / taus if smoothed else 1e4)

    return model_fn


def spd(key, n):
    a = jax.random.normal(key, (n, n))
    return a @ a.T + n * jnp.eye(n)


@pytest.fixture(scope="module")
def one_stage():
    """Random n = 3, m = 2 stage: P, R, H, a NON-optimal W, and finite variations."""
    ks = jax.random.split(jax.random.PRNGKey(7), 10)
    n, m = 3, 2
    P, R = spd(ks[0], n), spd(ks[1], m)
    H = jax.random.normal(ks[2], (m, n))
    W = jax.random.normal(ks[3], (n, m))
    dP = 0.3 * spd(ks[4], n)
    dR = 0.2 * spd(ks[5], m)
    dW = 0.1 * jax.random.normal(ks[6], (n, m))
    Phi = jnp.eye(n) + 0.3 * jax.random.normal(ks[7], (n, n))
    dPhi = 0.05 * jax.random.normal(ks[8], (n, n))
    Q, dQ = spd(ks[9], n), 0.1 * jnp.eye(n)
    return dict(P=P, R=R, H=H, W=W, dP=dP, dR=dR, dW=dW, Phi=Phi, dPhi=dPhi, Q=Q, dQ=dQ)


def joseph(P, H, R, W):
    I_WH = jnp.eye(P.shape[0]) - W @ H
    return I_WH @ P @ I_WH.T + W @ R @ W.T


def optimal_gain(P, H, R):
    return P @ H.T @ jnp.linalg.inv(H @ P @ H.T + R)


# ---- 5.1 exact algebraic identities (tolerance 1e-10) --------------------------------------------


def test_T1_update_variation_is_exact_for_any_gain(one_stage):
    s = one_stage
    v = update_variation(s["P"], s["H"], s["R"], s["W"], s["dP"], s["dR"], s["dW"])
    direct = joseph(s["P"] + s["dP"], s["H"], s["R"] + s["dR"], s["W"] + s["dW"]) - joseph(s["P"], s["H"], s["R"], s["W"])
    np.testing.assert_allclose(v.dP, direct, atol=1e-10 * float(jnp.max(jnp.abs(direct))))
    assert float(jnp.max(jnp.abs(v.A))) > 1e-3  # W is not optimal, so A is genuinely present


def test_T2_prediction_variation_is_exact(one_stage):
    s = one_stage
    Pf = joseph(s["P"], s["H"], s["R"], s["W"])
    dPf = 0.2 * s["dP"]
    got = prediction_variation(s["Phi"], Pf, dPf, s["dQ"], s["dPhi"])
    direct = (s["Phi"] + s["dPhi"]) @ (Pf + dPf) @ (s["Phi"] + s["dPhi"]).T + s["Q"] + s["dQ"] - (s["Phi"] @ Pf @ s["Phi"].T + s["Q"])
    np.testing.assert_allclose(got, direct, atol=1e-10 * float(jnp.max(jnp.abs(direct))))


def test_T3_T4_readjusted_gain_for_any_nominal_gain(one_stage):
    s = one_stage
    g = optimal_gain_variation(s["P"], s["H"], s["R"], s["W"], s["dP"], s["dR"])
    new_opt = optimal_gain(s["P"] + s["dP"], s["H"], s["R"] + s["dR"])
    np.testing.assert_allclose(s["W"] + g.dW_opt, new_opt, atol=1e-10)  # (B.9)
    v = update_variation(s["P"], s["H"], s["R"], s["W"], s["dP"], s["dR"], g.dW_opt)
    np.testing.assert_allclose(v.A + v.B, g.gain_term, atol=1e-10 * float(jnp.max(jnp.abs(g.gain_term))))  # (B.12)
    assert float(jnp.max(jnp.linalg.eigvalsh(g.gain_term))) < 1e-10  # negative semidefinite


def test_T5_optimal_to_optimal_closed_form(one_stage):
    s = one_stage
    W0 = optimal_gain(s["P"], s["H"], s["R"])
    B0 = value_of_information(s["P"], s["H"], s["R"], W0, s["dP"], s["dR"])
    I_WH = jnp.eye(3) - W0 @ s["H"]
    lhs = I_WH @ s["dP"] @ I_WH.T + W0 @ s["dR"] @ W0.T + B0  # (29)
    P_new = s["P"] + s["dP"]
    direct = joseph(P_new, s["H"], s["R"] + s["dR"], optimal_gain(P_new, s["H"], s["R"] + s["dR"])) - joseph(s["P"], s["H"], s["R"], W0)
    np.testing.assert_allclose(lhs, direct, atol=1e-10 * float(jnp.max(jnp.abs(direct))))
    held = I_WH @ s["dP"] @ I_WH.T + W0 @ s["dR"] @ W0.T  # (28)
    np.testing.assert_allclose(held - lhs, -B0, atol=1e-12)  # (30)


def test_T6_T7_optimal_gain_bracket_vanishes_and_gain_change_costs(one_stage):
    s = one_stage
    W0 = optimal_gain(s["P"], s["H"], s["R"])
    bracket = -(jnp.eye(3) - W0 @ s["H"]) @ s["P"] @ s["H"].T + W0 @ s["R"]
    np.testing.assert_allclose(bracket, 0.0, atol=1e-10)  # (B.7)
    zero = jnp.zeros_like(s["P"])
    v = update_variation(s["P"], s["H"], s["R"], W0, zero, jnp.zeros_like(s["R"]), s["dW"])
    np.testing.assert_allclose(v.A, 0.0, atol=1e-10)
    S = s["H"] @ s["P"] @ s["H"].T + s["R"]
    np.testing.assert_allclose(v.dP, s["dW"] @ S @ s["dW"].T, atol=1e-12)  # (23)/(25)
    assert float(jnp.min(jnp.linalg.eigvalsh(v.dP))) >= -1e-12


@pytest.mark.parametrize("readjust", [False, True])
def test_exact_variation_recursion_equals_perturbed_filter(readjust):
    nominal = ho_plant(jnp.full(30, 0.1))
    perturbed = ho_plant(jnp.full(30, 0.1), g=3.0, measurement_var=2e4, initial_cov=jnp.diag(jnp.array([2e6, 5e5])))
    var = exact_variation_recursion(nominal, perturbed, readjust_gain=readjust)
    base = covariance_recursion(nominal)
    if readjust:  # gains re-optimised: the perturbed model's optimal recursion (Sec. II-G(2))
        target = covariance_recursion(perturbed).filtered_cov
    else:  # gains held: the actual covariance of the nominal filter (Sec. II-G(1))
        target = actual_covariance(perturbed, nominal)[1].filtered_cov
    np.testing.assert_allclose(base.filtered_cov + var.filtered_cov, target, rtol=1e-9, atol=1e-9)


def test_exact_variation_with_changed_dynamics_and_readjusted_gain():
    nominal = ho_plant(jnp.full(20, 0.1))
    perturbed = ho_plant(jnp.full(20, 0.13), g=2.0)  # ΔΦ and ΔQ: a dynamics change the filter knows
    var = exact_variation_recursion(nominal, perturbed, readjust_gain=True)
    target = covariance_recursion(perturbed).filtered_cov
    np.testing.assert_allclose(covariance_recursion(nominal).filtered_cov + var.filtered_cov, target, rtol=1e-9)


def test_exact_variation_rejects_different_measurement_matrix():
    a = ho_plant(jnp.full(5, 0.1))
    b = eqx.tree_at(lambda m: m.H, a, jnp.array([[1.0, 0.5]]))
    with pytest.raises(InputError, match="share H"):
        exact_variation_recursion(a, b)


# ---- 5.2 autodiff versus analytic recursions --------------------------------------------------


@pytest.fixture(scope="module")
def sens_1g():
    return (
        covariance_sensitivity(uniform, 0.1, method=Analytic()),
        covariance_sensitivity(uniform, 0.1, method=Autodiff()),
        covariance_sensitivity(uniform, 0.1, method=Autodiff("rev")),
    )


def test_T8_forward_sensitivity_matches_autodiff(sens_1g):
    analytic, fwd, rev = sens_1g
    expected = np.array([[2701.7407, -327.0011], [-327.0011, -390.5483]])
    np.testing.assert_allclose(analytic.d_filtered_cov[-1], expected, atol=5e-5)  # printed to 4 decimals
    for other in (fwd, rev):
        np.testing.assert_allclose(analytic.d_filtered_cov, other.d_filtered_cov, rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(analytic.d_predicted_cov, other.d_predicted_cov, rtol=1e-10, atol=1e-9)
    h = 1e-6
    fd = (covariance_recursion(uniform(0.1 + h)).filtered_cov[-1, 0, 0] - covariance_recursion(uniform(0.1 - h)).filtered_cov[-1, 0, 0]) / (2 * h)
    assert abs(float(fd) - 2701.74067) < 1e-4


def test_T9_time_fixed_correction(sens_1g):
    analytic, _, _ = sens_1g
    P = covariance_recursion(uniform(0.1)).filtered_cov
    tf = time_fixed_sensitivity(analytic.d_filtered_cov, P, 0.1)
    assert tf[-1, 0, 0] == pytest.approx(7598.13, abs=5e-3)
    manual = analytic.d_filtered_cov[-1, 0, 0] + 490.0 * (P[48, 0, 0] - P[49, 0, 0])
    assert float(tf[-1, 0, 0]) == pytest.approx(float(manual), rel=1e-14)
    np.testing.assert_array_equal(tf[0], analytic.d_filtered_cov[0])


def test_time_fixed_equals_derivative_at_fixed_time_for_linear_interpolation(sens_1g):
    """(50) is the τ-derivative of the posterior linearly interpolated back to the time kτ₀."""
    k, tau0 = 30, 0.1

    def at_fixed_time(tau):
        P = covariance_recursion(uniform(tau)).filtered_cov
        frac = k * (tau - tau0) / tau  # Fig. 3: fraction of an interval to step back
        return P[k] + (P[k - 1] - P[k]) * frac

    ad = jax.jacfwd(at_fixed_time)(0.1)
    tf = time_fixed_sensitivity(sens_1g[0].d_filtered_cov, covariance_recursion(uniform(0.1)).filtered_cov, 0.1)
    np.testing.assert_allclose(tf[k], ad, rtol=1e-9)


@pytest.mark.parametrize("g, k, value", [(1.0, 34, 0.4100042), (10.0, 42, 0.049029)])
def test_T10_adjoint_equals_gradient_fixed_or_recomputed_gains(g, k, value):
    model = uniform(0.1, g)
    analytic = adjoint(model, L_POS)
    recomputed = adjoint(model, L_POS, method=Autodiff())
    held = adjoint(model, L_POS, method=Autodiff(), gain=covariance_recursion(model).gain)
    assert float(analytic.filtered[k, 1, 1]) == pytest.approx(value, abs=1e-6)
    for other in (recomputed, held):
        np.testing.assert_allclose(analytic.filtered, other.filtered, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(analytic.predicted, other.predicted, rtol=1e-10, atol=1e-12)


def test_adjoint_is_the_transpose_of_error_transition():
    model = uniform(0.1)
    D = error_transition(model, covariance_recursion(model))
    L = adjoint(model, L_POS).filtered
    np.testing.assert_allclose(jnp.swapaxes(D, -1, -2) @ L_POS @ D, L, rtol=1e-10, atol=1e-14)  # (42)
    np.testing.assert_array_equal(D[-1], jnp.eye(2))


def test_T11_segment_index_adjoint_equals_autodiff():
    fn = per_segment()
    taus = jnp.full(5, 0.1)
    analytic = sensitivity_index(fn, taus, L_POS)
    for method in (Autodiff(), Autodiff("fwd")):
        np.testing.assert_allclose(analytic, sensitivity_index(fn, taus, L_POS, method=method), rtol=1e-9)
    np.testing.assert_allclose(analytic, [-390.0, -892.7, -715.9, 629.3, 4070.9], atol=0.05)


def test_index_for_every_step_period_and_for_noise_parameters():
    taus = jnp.linspace(0.05, 0.15, 40)
    a = sensitivity_index(ho_plant, taus, L_POS)
    b = sensitivity_index(ho_plant, taus, L_POS, method=Autodiff())
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * float(jnp.max(jnp.abs(b))))
    assert float(a[0]) == 0.0  # the interval before the first sample is unused (prior on it)
    # d: plant-noise level (only Q); r: measurement-noise variance (only R); both scalar
    for fn, alpha in ((lambda d: ho_plant(taus, g=d), 1.0), (lambda r: ho_plant(taus, measurement_var=r), 1e4)):
        s_a = sensitivity_index(fn, alpha, L_POS)
        s_d = sensitivity_index(fn, alpha, L_POS, method=Autodiff())
        assert float(s_a) == pytest.approx(float(s_d), rel=1e-10)
        assert float(s_a) > 0.0  # more noise, larger terminal variance


def test_index_with_gain_depending_on_parameter_includes_A_prime():
    """Eq. (48): a suboptimal gain schedule that depends on α contributes A'_k ≠ 0."""
    model = uniform(0.1)
    W0 = covariance_recursion(model).gain

    def gain(c):
        return W0 * c

    fn = lambda c: model  # noqa: E731  (only the gain depends on c)
    a = sensitivity_index(fn, 0.9, L_POS, gain=gain)
    b = sensitivity_index(fn, 0.9, L_POS, gain=gain, method=Autodiff())
    assert float(a) == pytest.approx(float(b), rel=1e-9)
    assert abs(float(a)) > 1.0
    sa = covariance_sensitivity(fn, 0.9, gain=gain)
    sb = covariance_sensitivity(fn, 0.9, gain=gain, method=Autodiff())
    np.testing.assert_allclose(sa.d_filtered_cov, sb.d_filtered_cov, rtol=1e-9, atol=1e-9)
    assert float(jnp.trace(L_POS @ sa.d_filtered_cov[-1])) == pytest.approx(float(a), rel=1e-9)
    # At c = 1 the gain is optimal and A' vanishes: the index is zero to rounding (B.7).
    assert abs(float(sensitivity_index(fn, 1.0, L_POS, gain=gain))) < 1e-6


def test_array_parameter_returns_jacobian_shape():
    taus = jnp.full(12, 0.1)
    a = covariance_sensitivity(ho_plant, taus)
    b = covariance_sensitivity(ho_plant, taus, method=Autodiff())
    assert a.d_filtered_cov.shape == (12, 2, 2, 12)
    np.testing.assert_allclose(a.d_filtered_cov, b.d_filtered_cov, rtol=1e-10, atol=1e-8)


def test_predict_first_convention_and_matrix_measurement_change():
    def fn(theta):  # θ scales P0 and tilts H: exercises the P0 and ΔH paths
        m = ho_plant(jnp.full(15, 0.1), initial_cov=jnp.diag(jnp.array([1e6, 1e6])) * theta[0])
        return eqx.tree_at(lambda m: m.H, m, jnp.array([[1.0, theta[1]]]))

    theta = jnp.array([1.0, 0.05])
    for first in ("update", "predict"):
        a = sensitivity_index(fn, theta, L_POS, first_step=first)
        b = sensitivity_index(fn, theta, L_POS, first_step=first, method=Autodiff())
        np.testing.assert_allclose(a, b, rtol=1e-9)
        sa = covariance_sensitivity(fn, theta, first_step=first)
        sb = covariance_sensitivity(fn, theta, first_step=first, method=Autodiff())
        np.testing.assert_allclose(sa.d_filtered_cov, sb.d_filtered_cov, rtol=1e-9, atol=1e-7)


def test_T12_local_variations_sum_to_linearisation_and_exact_change_is_second_order():
    model = uniform(0.1)

    def tangent(eps):
        z = jax.tree_util.tree_map(jnp.zeros_like, model)
        vals = (jnp.array([[0.0, 0.01], [0.0, 0.0]]), jnp.diag(jnp.array([0.1, 5.0])), jnp.array([[100.0]]), jnp.diag(jnp.array([1e4, 2e3])))
        fields = (model.F, model.Q, model.R, model.initial_cov)
        return eqx.tree_at(lambda m: (m.F, m.Q, m.R, m.initial_cov), z,
                           tuple(eps * jnp.broadcast_to(v, f.shape) for v, f in zip(vals, fields)))

    t = tangent(1.0)
    first = first_order_variation(model, t)
    _, jvp = jax.jvp(lambda m: covariance_recursion(m).filtered_cov[-1], (model,), (t,))
    np.testing.assert_allclose(first, jvp, rtol=1e-10)
    total, pieces = multistage_variation(model, t, [9, 19, 29, 39, 49])
    np.testing.assert_allclose(total, jvp, rtol=1e-10)  # eq. (36)
    assert pieces.shape == (5, 2, 2)
    history = covariance_recursion(model)
    _, dP = tangent_recursion(model, t, history)
    np.testing.assert_allclose(dP[-1], jvp, rtol=1e-10)  # eq. (32)
    # The exact change minus the first-order one shrinks like ε².
    errs = []
    for eps in (0.2, 0.1):
        pert = jax.tree_util.tree_map(lambda a, b: a + b, model, tangent(eps))
        exact = exact_variation_recursion(model, pert, readjust_gain=True).filtered_cov[-1]
        errs.append(float(jnp.max(jnp.abs(exact - eps * jvp))))
    assert 3.5 < errs[0] / errs[1] < 4.5


def test_local_variation_of_first_sample_is_prior_change():
    model = uniform(0.1)
    z = jax.tree_util.tree_map(jnp.zeros_like, model)
    t = eqx.tree_at(lambda m: m.initial_cov, z, jnp.diag(jnp.array([1.0, 2.0])))
    lv = local_variations(model, t, covariance_recursion(model))
    np.testing.assert_array_equal(lv.predicted_cov[0], t.initial_cov)
    np.testing.assert_array_equal(lv.filtered_cov[1:], 0.0)


@pytest.mark.parametrize("k, ratios", [(10, (0.9960, 0.99996)), (25, (0.9986, 0.999986)), (40, (0.9994, 0.999994))])
def test_T13_second_order_gain_effect(k, ratios):
    model = uniform(0.1)
    h = covariance_recursion(model)
    L = adjoint(model, L_POS).filtered
    J0 = float(h.filtered_cov[-1, 0, 0])

    def actual(eps):
        """The filter uses W°_k(1+ε) at step k and re-optimises every later gain (as a real filter
        propagating its own covariance does)."""
        gains = h.gain.at[k].multiply(1.0 + eps)
        P_k = covariance_recursion(model, gain=gains).filtered_cov[k]
        rest = ho_plant(jnp.full(49 - k, 0.1), initial_cov=model.F[k + 1] @ P_k @ model.F[k + 1].T + model.Q[k + 1])
        return float(covariance_recursion(rest).filtered_cov[-1, 0, 0]) - J0

    for eps, expected, tol in ((0.1, ratios[0], 6e-5), (0.01, ratios[1], 6e-7)):
        dW = jnp.zeros_like(h.gain).at[k].set(eps * h.gain[k])
        predicted = float(gain_variation_cost(L, h.innovation_cov, dW).sum())  # eq. (64)
        assert actual(eps) / predicted == pytest.approx(expected, abs=tol)  # spec §2.7: → 1 as ε²
        assert abs(actual(eps) / predicted - 1.0) < 1e-4 or eps == 0.1
        # With the later gains held at W°, P_T is exactly quadratic in ΔW_k: ratio 1 to rounding.
        held = float(covariance_recursion(model, gain=h.gain + dW).filtered_cov[-1, 0, 0]) - J0
        assert held / predicted == pytest.approx(1.0, abs=1e-6)
        assert float(gain_variation_recursion(model, dW)[-1, 0, 0]) == pytest.approx(predicted, rel=1e-10)


def test_gain_hessian_and_allowable_ellipsoid():
    model = uniform(0.1)
    for k in (5, 34):
        np.testing.assert_allclose(gain_hessian(model, L_POS, k), gain_hessian(model, L_POS, k, method=Autodiff()), rtol=1e-8)
    h = covariance_recursion(model)
    L = adjoint(model, L_POS).filtered[25]
    ell = allowable_gain_ellipsoid(L, h.innovation_cov[25], 10.0)
    lengths, dirs = ell.semi_axes()
    finite = jnp.isfinite(lengths)
    # S is 1×1 and L_{k/k} is singular only at the end, so the 2 gain entries span a 2-D ellipse
    # whose axes are finite exactly where L has a positive eigenvalue.
    assert int(finite.sum()) == int(jnp.sum(jnp.linalg.eigvalsh(L) > 1e-12 * float(jnp.max(jnp.abs(L)))))
    d = dirs[jnp.argmax(finite)] * lengths[jnp.argmax(finite)]
    assert float(ell.cost(d)) == pytest.approx(10.0, rel=1e-10)
    assert bool(ell.contains(0.99 * d)) and not bool(ell.contains(1.01 * d))
    assert float(ell.cost(d)) == pytest.approx(float(gain_variation_cost(L[None], h.innovation_cov[25:26], d[None])[0]), rel=1e-12)


# ---- Sec. IV one-stage closed forms and Appendix C -------------------------------------------

P_XV, TAU, ALPHA, BETA = 0.84, 0.6, 1.3, 0.9


def qx(a, t):
    return a**2 * t**4 / 4


def qv(a, t):
    return a**2 * t**2


def _stack(c):
    return jnp.stack(list(c))


@pytest.mark.parametrize(
    "smoothed, expected",
    [(False, (0.238072, -0.110056, 1.770714)), (True, (-0.479141, -0.639918, 1.394220))],
)
def test_T14_period_sensitivity_closed_form(smoothed, expected):
    r = (lambda t: BETA / t) if smoothed else (lambda t: BETA)
    dr = -BETA / TAU**2 if smoothed else 0.0
    closed = _stack(period_sensitivity(P_XV, TAU, qx(ALPHA, TAU), r(TAU), ALPHA**2 * TAU**3, 2 * ALPHA**2 * TAU, dr))
    ad = jax.jacfwd(lambda t: _stack(one_stage_update(P_XV, t, qx(ALPHA, t), qv(ALPHA, t), r(t))))(TAU)
    np.testing.assert_allclose(closed, ad, rtol=1e-10)
    np.testing.assert_allclose(closed, expected, atol=5e-7)


def test_T14_plant_and_measurement_noise_closed_forms_and_tradeoffs():
    pn = _stack(plant_noise_sensitivity(P_XV, TAU, qx(ALPHA, TAU), BETA, 0.5 * ALPHA * TAU**4, 2 * ALPHA * TAU**2))  # (104)
    ad = jax.jacfwd(lambda a: _stack(one_stage_update(P_XV, TAU, qx(a, TAU), qv(a, TAU), BETA)))(ALPHA)
    np.testing.assert_allclose(pn, ad, rtol=1e-10)
    mn = _stack(measurement_noise_sensitivity(P_XV, TAU, qx(ALPHA, TAU), BETA / TAU, 1.0 / TAU))  # (107)
    ad = jax.jacfwd(lambda b: _stack(one_stage_update(P_XV, TAU, qx(ALPHA, TAU), qv(ALPHA, TAU), b / TAU)))(BETA)
    np.testing.assert_allclose(mn, ad, rtol=1e-10)
    # (112): the implicit-function ratio from autodiff partials of p_x
    px = lambda a, t, b: one_stage_update(P_XV, t, qx(a, t), qv(a, t), b).p_x  # noqa: E731
    d_a, d_t = jax.grad(px, argnums=(0, 1))(ALPHA, TAU, BETA)
    ratio = -(d_a * ALPHA) / (d_t * TAU)
    assert float(plant_noise_period_tradeoff(P_XV, TAU, ALPHA)) == pytest.approx(float(ratio), rel=1e-10)
    assert float(ratio) == pytest.approx(-0.0562458, abs=5e-8)
    # (117): smoothed data R_x = β/τ
    pxs = lambda t, b: one_stage_update(P_XV, t, qx(ALPHA, t), qv(ALPHA, t), b / t).p_x  # noqa: E731
    d_t, d_b = jax.grad(pxs, argnums=(0, 1))(TAU, BETA)
    ratio = -(d_b * BETA) / (d_t * TAU)
    assert float(measurement_noise_period_tradeoff(P_XV, TAU, ALPHA, BETA)) == pytest.approx(float(ratio), rel=1e-10)
    assert float(ratio) == pytest.approx(1.990277, abs=5e-7)


@pytest.mark.parametrize("tau_star, expected", [(0.1, 3159.00), (0.2, 3770.62)])
def test_T15_normalisation_invariance(tau_star, expected):
    P_star = jnp.array([[3422.0, 5380.0], [5380.0, 11973.0]])
    Q_star = jnp.diag(jnp.array([0.259 * tau_star, 104.0 * tau_star]))
    n = normalize(P_star, tau_star, Q_star, 1e4)
    u = one_stage_update(n.P[0, 1], n.tau, n.Q[0, 0], n.Q[1, 1], n.r_x)
    back = denormalize(jnp.array([[u.p_x, u.p_xv], [u.p_xv, u.p_v]]), n.scale)
    F = jnp.array([[1.0, tau_star], [0.0, 1.0]])
    direct = LinearGaussianModel(F, Q_star, jnp.array([[1.0, 0.0]]), jnp.array([[1e4]]), jnp.zeros(2), F @ P_star @ F.T + Q_star)
    P_direct = covariance_recursion(direct, 1).filtered_cov[0]
    np.testing.assert_allclose(back, P_direct, rtol=1e-12)
    assert float(back[0, 0]) == pytest.approx(expected, abs=5e-3)


def test_bad_inputs_are_named():
    with pytest.raises(InputError, match="method"):
        covariance_sensitivity(uniform, 0.1, method="analytic")
    with pytest.raises(InputError, match="LinearGaussianModel"):
        sensitivity_index(lambda t: 3.0, 0.1, L_POS)
    with pytest.raises(InputError, match="weight"):
        sensitivity_index(uniform, 0.1, jnp.eye(3))
    with pytest.raises(InputError, match="first_step"):
        adjoint(uniform(0.1), L_POS, first_step="later")
    with pytest.raises(InputError, match="segment_taus"):
        segment_sensitivity(per_segment(), jnp.full(4, 0.1), COUNTS, L_POS)
    with pytest.raises(InputError, match="mode"):
        Autodiff("sideways")
    with pytest.raises(InputError, match="P_prev"):
        normalize(jnp.eye(3), 0.1, jnp.eye(2), 1.0)

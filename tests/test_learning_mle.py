"""Maximum likelihood with standard errors (jaxtrack.learning.fit) against statsmodels' state-space MLE.

statsmodels is the oracle (tests only). Its model is a small ``MLEModel`` subclass with a *known*
prior (``initialization="known"``), so that both libraries compute the same exact likelihood
(checked first, at the same parameters); its standard errors are ``cov_type="approx"``: the
inverse of the numerical (complex-step) Hessian of the log-likelihood in its natural
(untransformed: variance) parameters, the same quantity as our delta-method natural-scale SEs
from the autodiff Hessian in the unconstrained (log) parameters (equal at an exact optimum).
"""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxtrack
from jaxtrack.filters import KalmanFilter, run_filter
from jaxtrack.learning import PositiveScalar, fit

from _learning_cases import _builder_for, _case, _simulate

sm_mlemodel = pytest.importorskip("statsmodels.tsa.statespace.mlemodel")


class _VarianceModel(sm_mlemodel.MLEModel):
    """``x_k = F x_{k-1} + w``, ``z = H x + v``, ``Q = Σ_i θ_i Q_i``, ``R = θ_last R1``; θ = variances."""

    def __init__(self, y, F, H, Qs, R1, a0, P0):
        k = F.shape[0]
        super().__init__(y, k_states=k, initialization="known", initial_state=a0, initial_state_cov=P0)
        self["design"] = H
        self["transition"] = F
        self["selection"] = np.eye(k)
        self.Qs, self.R1 = Qs, R1

    @property
    def start_params(self):
        return np.ones(len(self.Qs) + 1)

    # statsmodels' own convention for variances: optimise over x with θ = x² (we use log θ).
    def transform_params(self, unconstrained):
        return unconstrained**2

    def untransform_params(self, constrained):
        return constrained**0.5

    def update(self, params, **kwargs):
        params = super().update(params, **kwargs)
        self["state_cov"] = sum(p * Q for p, Q in zip(params[:-1], self.Qs))
        self["obs_cov"] = params[-1] * self.R1


@pytest.mark.parametrize("name", ["local_level", "local_linear_trend", "constant_velocity"])
def test_estimates_and_standard_errors_match_statsmodels(name):
    F, H, Qs, R1, a0, P0, theta = _case(name)
    y = _simulate(F, H, Qs, R1, a0, P0, theta, seed=7)
    mod = _VarianceModel(y, F, H, Qs, R1, a0, P0)
    build = _builder_for(name)

    # 1. Same likelihood at the same parameters first (known prior in both).
    th = theta * 1.3
    ll = run_filter(KalmanFilter(), build({"theta": PositiveScalar.from_value(th)}), y).log_likelihood
    np.testing.assert_allclose(float(ll), mod.loglike(th), rtol=1e-9)

    # 2. The MLE. statsmodels' BFGS (its complex-step score): its default L-BFGS-B uses a
    #    finite-difference gradient (ε = 1e-5) and stops ~1e-4 short. The gradient tolerance is
    #    on its objective −ℓ/n: at gtol = 1e-10 BFGS ends within a factor ~8 of the rounding
    #    floor of the complex-step score (|score| 1.3e-11 here), so on another machine (other
    #    BLAS rounding) its line search can stop on precision loss and statsmodels warns that the
    #    fit did not converge. Over 90 variations of these cases (3 models × 10 data sets × 3
    #    starts) BFGS reports convergence in 54 at gtol 1e-10 and in 87 at 1e-8, the same on
    #    statsmodels 0.14.6 and 0.15.0. 1e-8 is two orders above the floor and still puts the
    #    estimate within ~1e-9 relative of the 1e-10 optimum, inside the tolerances below.
    res = mod.fit(start_params=np.ones(len(theta)), method="bfgs", maxiter=2000, disp=0, cov_type="approx", gtol=1e-8)
    assert res.mle_retvals["converged"], res.mle_retvals
    # statsmodels' own first-order condition at its optimum (score of ℓ/n in its parameters).
    assert np.max(np.abs(mod.score(res.params))) < 1e-6
    f = fit(build, {"theta": PositiveScalar.from_value(np.ones(len(theta)))}, y)
    assert bool(f.ok) and bool(f.converged)
    est = np.asarray(f.natural_params["theta"])
    rel_est = np.max(np.abs(est / res.params - 1))
    assert rel_est < 1e-6, rel_est
    # Ours is at least as good an optimum (same likelihood function, checked above).
    assert float(f.log_likelihood) >= res.llf - 1e-8 * abs(res.llf)

    # 3. Standard errors (natural scale, delta method) against statsmodels' cov_type="approx".
    se = np.asarray(f.standard_errors()["theta"])
    rel_se = np.max(np.abs(se / res.bse - 1))
    assert rel_se < 1e-5, rel_se
    # Like with like at the same parameters (our optimum): only the Hessian method differs.
    bse_here = mod.smooth(est, cov_type="approx").bse
    np.testing.assert_allclose(se, bse_here, rtol=1e-5)
    print(f"{name}: max rel err estimates {rel_est:.2e}, SEs {rel_se:.2e}")


def test_intervals_unconstrained_mapped_and_delta():
    F, H, Qs, R1, a0, P0, theta = _case("local_level")
    y = _simulate(F, H, Qs, R1, a0, P0, theta, seed=7)
    f = fit(_builder_for("local_level"), {"theta": PositiveScalar.from_value(np.ones(2))}, y)
    u = f.params["theta"].log_value
    se_u = f.standard_errors("unconstrained")["theta"].log_value
    se = f.standard_errors()["theta"]
    # Delta method for θ = exp(u): σ_θ = θ σ_u.
    np.testing.assert_allclose(se, jnp.exp(u) * se_u, rtol=1e-12)
    z = 1.959963984540054
    lo, hi = f.confidence_intervals(0.95)
    np.testing.assert_allclose(lo["theta"], jnp.exp(u - z * se_u), rtol=1e-12)
    np.testing.assert_allclose(hi["theta"], jnp.exp(u + z * se_u), rtol=1e-12)
    lo_d, hi_d = f.confidence_intervals(0.95, method="delta")
    np.testing.assert_allclose(hi_d["theta"] - lo_d["theta"], 2 * z * se, rtol=1e-12)
    assert np.all(lo["theta"] > 0)
    # Observed information = −Hessian of ℓ in u; its inverse the covariance.
    info = f.observed_information()
    np.testing.assert_allclose(f.covariance() @ info, np.eye(2), atol=1e-10)
    with pytest.raises(jaxtrack.InputError, match="`level`"):
        f.confidence_intervals(1.5)

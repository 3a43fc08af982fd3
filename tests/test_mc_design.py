"""Design by gradient on a Monte Carlo objective (design_by_monte_carlo) next to the same design on
the actual covariance (design_by_covariance) on a linear problem where both apply: they agree
within the Monte Carlo error of the former.

Problem: 2-D constant velocity, truth q = 1 m²/s³, σ = 10 m; the filter assumes σ* = 15 m (wrong R)
and its process-noise intensity q* = exp(θ) is designed to minimise the time-averaged position MSE
over 40 steps. The best q* for the wrong R is not the true q (θ* ≈ 0.888, q* ≈ 2.43).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.covariance import actual_covariance
from jaxtrack.design import design_by_covariance, design_by_monte_carlo
from jaxtrack.models import constant_velocity
from jaxtrack.montecarlo import differentiable_monte_carlo

P0 = jnp.diag(jnp.array([100.0, 100.0, 25.0, 25.0]))
TRUTH = constant_velocity(1.0, accel_psd=1.0, measurement_std=10.0, initial_cov=P0)
W = jnp.array([1.0, 1.0, 0.0, 0.0])  # positions
T, M, K = 40, 1000, 16


def models(theta):
    return TRUTH, constant_velocity(1.0, accel_psd=jnp.exp(theta), measurement_std=15.0, initial_cov=P0)


def cov_cost(theta):
    _, actual = actual_covariance(*models(theta), T)
    return jnp.mean(jnp.einsum("kii,i->k", actual.filtered_cov, W))


def mc_cost(theta, key):
    res = differentiable_monte_carlo(TRUTH, key, M, num_steps=T, filter_model=models(theta)[1])
    return jnp.mean(res.mse @ W)


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_monte_carlo_design_agrees_with_covariance_design():
    cov = design_by_covariance(models, 0.0, weight=W, num_steps=T)
    mc = design_by_monte_carlo(models, 0.0, jax.random.key(1), M, weight=W, num_steps=T)
    # Both converged (L-BFGS, ‖∇J‖ ≤ 1e-9·J) and the covariance design is the exact optimum of E[J].
    assert abs(cov.gradient) < 1e-6 and abs(mc.gradient) < 1e-6
    assert cov.cost < float(cov_cost(0.0)) and mc.cost < mc.history[0]
    theta_cov, theta_mc = float(cov.params), float(mc.params)
    # Monte Carlo error of the design (sample-average approximation, Shapiro et al. 2009, Thm 5.8):
    # θ_M − θ* ≈ −∇J_M(θ*)/J''(θ*). sd(∇J_M(θ*)) from K = 16 independent keys (M runs each);
    # J'' from the covariance objective (exact). Bound: 4 sd (normal: 99.99%; with the sd
    # estimated from 16 replicates, Student t₁₅: 99.9%).
    keys = jax.random.split(jax.random.key(7), K)
    grads = np.asarray(jax.jit(jax.vmap(jax.grad(mc_cost), in_axes=(None, 0)))(theta_cov, keys))
    # J'' by a central second difference of the (already compiled) objective: smooth, so h = 1e-3
    # leaves O(h²) ≈ 1e-6 relative error (rounding ~1e-10), and no Hessian program to compile
    # (jax.hessian: 6.8 s of this test's 47).
    h = 1e-3
    curvature = float((cov_cost(theta_cov + h) - 2 * cov_cost(theta_cov) + cov_cost(theta_cov - h)) / h**2)
    sd_theta = np.std(grads, ddof=1) / curvature
    assert abs(np.mean(grads)) < 4 * np.std(grads, ddof=1) / np.sqrt(K)  # unbiased gradient at θ*
    assert abs(theta_mc - theta_cov) < 4 * sd_theta, (theta_mc, theta_cov, sd_theta)
    # Measured: θ_cov = 0.8879 (q* = 2.430), θ_MC = 0.8690 (q* = 2.385), sd_θ ≈ 0.03 for M = 1000.
    # The Monte Carlo design's expected cost is within the SAA error of the optimum.
    assert float(cov_cost(theta_mc)) - cov.cost < 0.5 * curvature * (4 * sd_theta) ** 2 + 1e-9


def test_design_input_errors():
    with pytest.raises(InputError, match="`weight`"):
        design_by_covariance(models, 0.0, weight=jnp.ones(3), num_steps=T)
    with pytest.raises(InputError, match="`steps`"):
        design_by_monte_carlo(models, 0.0, jax.random.key(0), 10, num_steps=T, steps=0)
    with pytest.raises(InputError, match="`objective`"):
        design_by_covariance(models, 0.0, num_steps=T, objective="mean")

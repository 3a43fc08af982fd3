"""Cost of covariance sensitivities relative to one covariance pass (issue: Ho sensitivity).

For state sizes n = 2, 6, 12 and 200 steps (constant-velocity blocks, n/2 axes, nonuniform
schedule τ_k), times after compilation, best of several repeats:

- the covariance-only pass (``covariance_recursion``),
- ∂P/∂τ for a uniform scaling of the schedule: analytic recursion (46)–(47), forward-mode
  autodiff (``jax.jacfwd``) and central differences (two covariance passes),
- the gradient of J = tr(L_T P_T) with respect to all 200 per-step τ_k: the adjoint recursion
  (43)+(52) and reverse-mode autodiff (``jax.grad``).

Prints each time as a multiple of the covariance pass measured in the same run (the machine is
shared and noisy; only these ratios mean anything), and ``--json`` prints the same numbers.

    python benchmarks/sensitivity_cost.py [--steps 200] [--repeats 20] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxtrack  # noqa: F401  (float64)
from jaxtrack.covariance import covariance_recursion
from jaxtrack.models import LinearGaussianModel
from jaxtrack.sensitivity import Analytic, Autodiff, covariance_sensitivity, sensitivity_index


def cv_model(taus, n: int) -> LinearGaussianModel:
    """n/2 independent constant-velocity axes, white-noise acceleration 1 m²/s³, σ = 10 m."""
    d = n // 2

    def blocks(tau):
        F1 = jnp.array([[1.0, 0.0], [0.0, 1.0]]) + tau * jnp.array([[0.0, 1.0], [0.0, 0.0]])
        Q1 = jnp.stack([jnp.stack([tau**3 / 3, tau**2 / 2]), jnp.stack([tau**2 / 2, tau])])
        return jnp.kron(F1, jnp.eye(d)), jnp.kron(Q1, jnp.eye(d))

    F, Q = jax.vmap(blocks)(taus)
    H = jnp.eye(d, n)
    return LinearGaussianModel(F, Q, H, 100.0 * jnp.eye(d), jnp.zeros(n), 1e4 * jnp.eye(n))


def _time(fn, *args, repeats):
    jax.block_until_ready(fn(*args))  # compile
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - t0)
    return best


def bench(n: int, steps: int, repeats: int) -> dict:
    taus = jnp.asarray(np.random.default_rng(0).uniform(0.05, 0.15, steps))
    weight = jnp.diag(jnp.concatenate([jnp.ones(n // 2), jnp.zeros(n - n // 2)]))

    def scaled(alpha):  # one scalar parameter: a uniform scaling of the schedule
        return cv_model(alpha * taus, n)

    cov_pass = jax.jit(lambda t: covariance_recursion(cv_model(t, n)).filtered_cov)
    analytic = jax.jit(lambda a: covariance_sensitivity(scaled, a, method=Analytic()).d_filtered_cov)
    forward = jax.jit(lambda a: covariance_sensitivity(scaled, a, method=Autodiff("fwd")).d_filtered_cov)
    h = 1e-6
    central = jax.jit(lambda a: (covariance_recursion(scaled(a + h)).filtered_cov
                                 - covariance_recursion(scaled(a - h)).filtered_cov) / (2 * h))
    per_step = lambda t: cv_model(t, n)  # noqa: E731
    adjoint_grad = jax.jit(lambda t: sensitivity_index(per_step, t, weight, method=Analytic()))
    reverse_grad = jax.jit(lambda t: sensitivity_index(per_step, t, weight, method=Autodiff("rev")))

    one = jnp.asarray(1.0)
    base = _time(cov_pass, taus, repeats=repeats)
    times = {
        "analytic_dP_dtau": _time(analytic, one, repeats=repeats),
        "forward_mode_dP_dtau": _time(forward, one, repeats=repeats),
        "central_differences_dP_dtau": _time(central, one, repeats=repeats),
        "adjoint_grad_all_taus": _time(adjoint_grad, taus, repeats=repeats),
        "reverse_mode_grad_all_taus": _time(reverse_grad, taus, repeats=repeats),
    }
    # The two gradients must agree, or the timing compares different things.
    g_adj, g_rev = adjoint_grad(taus), reverse_grad(taus)
    agree = float(jnp.max(jnp.abs(g_adj - g_rev)) / jnp.max(jnp.abs(g_rev)))
    return {
        "n": n,
        "steps": steps,
        "cores": os.cpu_count(),
        "covariance_pass_s": base,
        **{f"{k}_s": v for k, v in times.items()},
        **{f"{k}_ratio": v / base for k, v in times.items()},
        "adjoint_vs_reverse_max_rel_diff": agree,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--sizes", type=int, nargs="+", default=[2, 6, 12])
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    rows = [bench(n, args.steps, args.repeats) for n in args.sizes]
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    names = ["analytic_dP_dtau", "forward_mode_dP_dtau", "central_differences_dP_dtau",
             "adjoint_grad_all_taus", "reverse_mode_grad_all_taus"]
    print(f"cost relative to one covariance pass ({args.steps} steps, float64, {os.cpu_count()} cores)")
    print(f"{'n':>3} {'cov pass':>10} " + " ".join(f"{n[:18]:>18}" for n in names))
    for r in rows:
        print(f"{r['n']:>3} {r['covariance_pass_s'] * 1e3:>8.3f}ms "
              + " ".join(f"{r[n + '_ratio']:>17.2f}x" for n in names))
    for r in rows:
        print(f"n = {r['n']:>2}: adjoint gradient is {r['reverse_mode_grad_all_taus_ratio'] / r['adjoint_grad_all_taus_ratio']:.1f}x "
              f"faster than reverse mode; they agree to {r['adjoint_vs_reverse_max_rel_diff']:.1e} (max rel.)")


if __name__ == "__main__":
    main()

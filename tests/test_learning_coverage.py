"""Coverage of jaxtrack.learning.fit's 95% intervals over 500 simulated data sets.

A constant-velocity track (dt = 1 s, position measured) with unknown white-noise-acceleration
PSD q (m²/s³) and measurement variance r (m²); T = 200 steps; known prior. The 500 fits run as one
``jit(vmap(fit))`` (one compilation). Acceptance: the fraction of intervals that cover the true q
and the true r lies inside the binomial 99% band around 0.95 for n = 500.
"""

import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

from jaxtrack.learning import PositiveScalar, fit
from jaxtrack.models import LinearGaussianModel

T = 200
NUM_SETS = 500
Q_TRUE, R_TRUE = 0.3, 4.0
F = jnp.array([[1.0, 1.0], [0.0, 1.0]])
Q1 = jnp.array([[1.0 / 3.0, 0.5], [0.5, 1.0]])  # ∫ e^{Fs} G Gᵀ e^{Fᵀs} ds over one 1 s step
H = jnp.array([[1.0, 0.0]])
M0, P0 = jnp.zeros(2), jnp.diag(jnp.array([25.0, 4.0]))


def build(p):
    return LinearGaussianModel(F, p["q"]() * Q1, H, p["r"]() * jnp.eye(1), M0, P0)


def simulate(key):
    k0, kw, kv = jax.random.split(key, 3)
    x0 = M0 + jnp.linalg.cholesky(P0) @ jax.random.normal(k0, (2,))
    w = jax.random.normal(kw, (T, 2)) @ jnp.linalg.cholesky(Q_TRUE * Q1).T

    def step(x, wk):
        return F @ x + wk, x

    _, xs = jax.lax.scan(step, x0, w)
    return xs @ H.T + jnp.sqrt(R_TRUE) * jax.random.normal(kv, (T, 1))


def one(z):
    f = fit(build, {"q": PositiveScalar.from_value(1.0), "r": PositiveScalar.from_value(1.0)}, z, num_iterations=100)
    return f.confidence_intervals(0.95), f.confidence_intervals(0.95, method="delta"), f.converged, f.ok


def test_interval_coverage_over_500_data_sets():
    zs = jax.vmap(simulate)(jax.random.split(jax.random.PRNGKey(2022), NUM_SETS))
    (lo, hi), (lo_d, hi_d), converged, ok = jax.jit(jax.vmap(one))(zs)
    assert bool(jnp.all(ok)) and bool(jnp.all(converged))
    # Binomial 99% band around 0.95 for n = 500.
    band = stats.binom.ppf([0.005, 0.995], NUM_SETS, 0.95) / NUM_SETS
    for name, truth in (("q", Q_TRUE), ("r", R_TRUE)):
        cover = float(np.mean((np.asarray(lo[name]) <= truth) & (truth <= np.asarray(hi[name]))))
        cover_d = float(np.mean((np.asarray(lo_d[name]) <= truth) & (truth <= np.asarray(hi_d[name]))))
        print(f"{name}: coverage log-scale {cover:.3f}, delta {cover_d:.3f}, band {band}")
        # The acceptance is on the intervals mapped from the unconstrained (log) scale, fit's
        # default. The symmetric delta-method ones are measured, not asserted: q̂'s distribution
        # is right-skewed at T = 200, and they under-cover q (0.916 measured, below the band).
        assert band[0] <= cover <= band[1], (name, cover, band)
        assert cover_d > 0.88, (name, cover_d)

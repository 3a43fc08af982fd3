"""RTS smoother on a singular predicted covariance (issue 19): Q = 0 with a singular F.

`P_{k+1/k} = F P_{k/k} Fᵀ` is then singular and its Cholesky factor NaN; the smoother used to
return NaN means with `ok=True` from the filter. It now uses the pseudo-inverse gain, checked
against the dense batch (fixed-interval) Gaussian conditioning of `tests/helpers.py`, which
never inverts a predicted covariance.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack.filters import rts_smoother
from jaxtrack.filters._smoother import _smoother_gain
from jaxtrack.models import LinearGaussianModel

from helpers import assert_close, dense_solution, random_linear_model, simulate_linear

SINGULAR_F = {
    # Third state reset to 0 at every transition (a zero row, last index: the Cholesky factor
    # is finite with a zero last pivot, and the solve divides by it).
    "zero_last_row": [[1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]],
    # Zero row in the middle: the Cholesky factor is NaN from that pivot on.
    "zero_middle_row": [[1.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.5, 0.9]],
    # Rank 2 without a zero row (a projection): P_p is singular only up to rounding (its
    # smallest eigenvalue is ±1e-16 relative), which the relative cutoff must see as zero.
    "dependent_rows": [[0.5, 0.5, 0.0], [0.5, 0.5, 0.0], [0.0, 0.0, 1.0]],
}


def _model(F, T=None):
    F = np.asarray(F)
    if T is not None:
        F = np.broadcast_to(F, (T, 3, 3))
    H = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
    R = np.diag([0.5, 0.2])
    return LinearGaussianModel(F, np.zeros((3, 3)), H, R, np.array([1.0, 2.0, 3.0]), np.diag([4.0, 2.0, 1.0]))


@pytest.mark.parametrize("name", sorted(SINGULAR_F))
@pytest.mark.parametrize("first_step", ["update", "predict"])
def test_singular_predicted_covariance_matches_dense_oracle(name, first_step):
    model = _model(SINGULAR_F[name])
    zs = np.random.default_rng(0).normal(size=(12, 2))
    mask = np.ones((12, 2), bool)
    mask[3, 1] = mask[7] = False
    res = rts_smoother(model, zs, mask=mask, first_step=first_step, throw=False)
    ref = dense_solution(model, zs, mask, first_step)
    assert bool(res.ok)
    assert np.all(np.isfinite(res.smoothed_mean)) and np.all(np.isfinite(res.smoothed_cov))
    assert_close(res.smoothed_mean, ref.smoothed_mean, 1e-9)
    assert_close(res.smoothed_cov, ref.smoothed_cov, 1e-9)
    # The default throw=True no longer raises either.
    assert_close(rts_smoother(model, zs, mask=mask, first_step=first_step).smoothed_mean, ref.smoothed_mean, 1e-9)


def test_singular_only_at_some_steps_per_step_F():
    # Regular transitions except at steps 4 and 9, where F has a zero row: the regular steps use
    # the Cholesky gain, the singular ones the pseudo-inverse, in one scan.
    T = 12
    F = np.broadcast_to(np.array([[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.1, 0.0, 0.8]]), (T, 3, 3)).copy()
    F[4] = SINGULAR_F["zero_middle_row"]
    F[9] = SINGULAR_F["zero_last_row"]
    model = _model(F)
    zs = np.random.default_rng(1).normal(size=(T, 2))
    res = rts_smoother(model, zs, throw=False)
    ref = dense_solution(model, zs)
    assert bool(res.ok)
    assert_close(res.smoothed_mean, ref.smoothed_mean, 1e-9)
    assert_close(res.smoothed_cov, ref.smoothed_cov, 1e-9)


def test_regular_gain_is_the_cholesky_solve_bit_for_bit():
    # The regular path is unchanged: the gain is exactly the Cholesky solve it always was.
    import jax.scipy.linalg as jsl

    model = random_linear_model(np.random.default_rng(2), 4, 2, 30)
    _, zs = simulate_linear(np.random.default_rng(3), model, 30)
    res = rts_smoother(model, zs)
    f = res.filtered
    for k in (0, 10, 28):
        F = model.transition_matrix(k + 1)
        P_p = f.predicted_cov[k + 1]
        expected = jax.jit(lambda P_f, F, P_p: jsl.cho_solve((jnp.linalg.cholesky(P_p), True), F @ P_f).T)(
            f.filtered_cov[k], F, P_p)
        np.testing.assert_array_equal(np.asarray(res.smoother_gain[k]), np.asarray(expected))
    ref = dense_solution(model, zs)
    assert_close(res.smoothed_mean, ref.smoothed_mean, 1e-9)


def test_gain_gradient_is_finite_in_the_regular_case_with_repeated_eigenvalues():
    # The pseudo-inverse branch (eigh) is not differentiable at repeated eigenvalues; the double
    # `where` keeps it out of the regular case's gradient. P_p = 2 I has a repeated eigenvalue.
    P_f = jnp.diag(jnp.array([1.0, 2.0]))
    F = jnp.eye(2)

    def loss(scale):
        return jnp.sum(_smoother_gain(P_f, F, scale * jnp.eye(2)) ** 2)

    g = jax.grad(loss)(2.0)
    # d/ds Σ (P_f / s)² = −2 Σ P_f² / s³ = −2 · 5 / 8.
    assert np.isfinite(g) and abs(g - (-10.0 / 8.0)) < 1e-12

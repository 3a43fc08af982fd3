"""Constrained parametrisations and the symmetric-gradient rule (jaxtrack.learning._params)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxtrack
from jaxtrack.filters import InteractingMultipleModel, KalmanFilter, run_filter
from jaxtrack.learning import (
    Bounded,
    PositiveScalar,
    SPDMatrix,
    StochasticRows,
    natural,
    symmetric_grad,
)
from jaxtrack.models import LinearGaussianModel, constant_velocity


def test_positive_scalar_round_trip_and_value():
    p = PositiveScalar.from_value(jnp.array([0.25, 3.0]))
    np.testing.assert_allclose(p.log_value, np.log([0.25, 3.0]), rtol=1e-15)
    np.testing.assert_allclose(p(), [0.25, 3.0], rtol=1e-15)
    assert p.value.dtype == jnp.float64
    with pytest.raises(jaxtrack.InputError, match="`value`"):
        PositiveScalar.from_value(-1.0)


def test_bounded_round_trip_and_bounds():
    b = Bounded.from_value(jnp.array([-0.9, 0.0, 1.5]), lo=-1.0, hi=2.0)
    np.testing.assert_allclose(b.value, [-0.9, 0.0, 1.5], rtol=1e-14, atol=1e-15)
    # Any logit maps strictly inside the interval.
    far = Bounded(jnp.array([-30.0, 30.0]), lo=-1.0, hi=2.0).value
    assert np.all(far > -1.0) and np.all(far < 2.0)
    # Bounds are static: they are not leaves (no gradient, not fitted).
    assert len(jax.tree_util.tree_leaves(b)) == 1
    with pytest.raises(jaxtrack.InputError, match="strictly inside"):
        Bounded.from_value(2.0, lo=-1.0, hi=2.0)
    with pytest.raises(jaxtrack.InputError, match="lo < hi"):
        Bounded(0.0, lo=1.0, hi=1.0)


def test_spd_matrix_exact_inverse_and_stays_spd():
    S = jnp.array([[4.0, 1.2, -0.5], [1.2, 2.0, 0.3], [-0.5, 0.3, 1.0]])
    p = SPDMatrix.from_value(S)
    assert p.tril.shape == (6,)  # n(n+1)/2 free entries: no redundant direction
    np.testing.assert_allclose(p.value, S, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(SPDMatrix.from_value(p.value).tril, p.tril, rtol=1e-13, atol=1e-14)
    # Every point of the unconstrained space is a valid covariance (exactly symmetric, PD).
    q = SPDMatrix(p.tril + jnp.array([3.0, -5.0, 2.0, 4.0, -7.0, 1.0]), 3)
    V = np.asarray(q.value)
    assert np.array_equal(V, V.T)
    assert np.all(np.linalg.eigvalsh(V) > 0)
    # Gradients flow to the leaves, finite even for large off-diagonal entries.
    g = jax.grad(lambda t: jnp.sum(SPDMatrix(t, 3).value))(jnp.array([0.0, 800.0, 0.0, 0.0, 0.0, 0.0]))
    assert np.all(np.isfinite(g))
    with pytest.raises(jaxtrack.InputError, match="`value`"):
        SPDMatrix.from_value(jnp.array([[1.0, 2.0], [2.0, 1.0]]))


def test_stochastic_rows_imm_convention_and_inverse():
    P = jnp.array([[0.9, 0.05, 0.05], [0.1, 0.8, 0.1]])
    p = StochasticRows.from_value(P)
    assert p.logits.shape == (2, 2)
    np.testing.assert_allclose(p.value, P, rtol=1e-14)
    # The IMM's convention: P = softmax_j(logits) with the last logit of each row pinned at 0.
    full = jnp.concatenate([p.logits, jnp.zeros((2, 1))], axis=-1)
    np.testing.assert_allclose(p.value, jax.nn.softmax(full, axis=-1), rtol=1e-15)
    member = constant_velocity(1.0, dim=1, accel_psd=1.0, measurement_std=1.0, initial_cov=jnp.eye(2))
    sq = StochasticRows.from_value(jnp.array([[0.95, 0.05], [0.2, 0.8]]))
    logits = jnp.concatenate([sq.logits, jnp.zeros((2, 1))], axis=-1)
    imm = InteractingMultipleModel.from_logits([(KalmanFilter(), member), (KalmanFilter(), member)], logits)
    np.testing.assert_allclose(imm.transition_probs, sq.value, rtol=1e-15)
    np.testing.assert_allclose(jnp.sum(StochasticRows(jnp.array([[40.0, -3.0]])).value, -1), 1.0, rtol=1e-15)


def test_natural_maps_a_mixed_pytree():
    params = {"q": PositiveScalar.from_value(2.0), "bias": jnp.array([0.5, -1.0]), "P": SPDMatrix.from_value(jnp.eye(2))}
    nat = natural(params)
    np.testing.assert_allclose(nat["q"], 2.0, rtol=1e-15)
    np.testing.assert_allclose(nat["bias"], [0.5, -1.0])
    np.testing.assert_allclose(nat["P"], np.eye(2), atol=1e-15)


def _cv_model(Q):
    dt = 1.0
    F = jnp.array([[1.0, dt], [0.0, 1.0]])
    H = jnp.array([[1.0, 0.0]])
    return LinearGaussianModel(F, Q, H, jnp.array([[4.0]]), jnp.zeros(2), jnp.diag(jnp.array([10.0, 2.0])))


def test_symmetric_gradient_rule_on_run_filter_log_likelihood():
    rng = np.random.default_rng(3)
    zs = jnp.asarray(np.cumsum(np.cumsum(rng.normal(0, 0.7, 60))) + rng.normal(0, 2.0, 60))[:, None]
    Q = jnp.array([[1.0 / 3.0, 0.5], [0.5, 1.0]]) * 0.5

    def loglik(Q):
        return run_filter(KalmanFilter(), _cv_model(Q), zs).log_likelihood

    G = jax.grad(loglik)(Q)
    # The raw gradient is not symmetric: the filter reads Q[0, 1] and Q[1, 0] in different places.
    asym = float(jnp.max(jnp.abs(G - G.T)))
    assert asym > 1e-3 * float(jnp.max(jnp.abs(G)))
    Gs = symmetric_grad(G)
    assert np.array_equal(np.asarray(Gs), np.asarray(Gs.T))
    # Along symmetric directions, ⟨sym(G), E⟩ is the directional derivative (central differences).
    h = 1e-5
    for E in (jnp.array([[0.0, 1.0], [1.0, 0.0]]), jnp.array([[1.0, 0.3], [0.3, -0.5]])):
        fd = (loglik(Q + h * E) - loglik(Q - h * E)) / (2 * h)
        np.testing.assert_allclose(jnp.sum(Gs * E), fd, rtol=1e-7)
    # sym(G) is the only symmetric matrix with that property; G itself is not on the space: the
    # unit off-diagonal direction reads 2·sym(G)[0, 1], not 2·G[0, 1].
    E01 = jnp.array([[0.0, 1.0], [1.0, 0.0]])
    fd01 = (loglik(Q + h * E01) - loglik(Q - h * E01)) / (2 * h)
    assert abs(2 * float(G[0, 1]) - float(fd01)) > 1e3 * abs(2 * float(Gs[0, 1]) - float(fd01))
    # A raw step leaves the symmetric matrices (the model rejects it); the symmetric one does not.
    with pytest.raises(jaxtrack.InputError):
        _cv_model(Q + 0.01 * G)
    _cv_model(Q + 0.01 * Gs)
    with pytest.raises(jaxtrack.InputError, match="`g`"):
        symmetric_grad(jnp.ones(3))

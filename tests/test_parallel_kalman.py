"""Parallel-in-time Kalman filter and RTS smoother (``scan=ParallelInTime()``) against the sequential scan.

Särkkä & García-Fernández (2021) compute the same posterior as the sequential recursions, so
every field of :class:`FilterResult` and :class:`SmootherResult` must agree with
``scan=Sequential()`` to rounding: here to 1e-10 relative to each field's scale, over T = 10,000
steps, on a constant-velocity model from :mod:`jaxtrack.models`, the same with a mask of missing
steps and components, and a model with per-step F, Q, H, R and offsets run with
``first_step="predict"``; the log-likelihood and its derivative with respect to a model
parameter agree to 1e-10 and 1e-8. Each (model, scan) pair runs once, in a module fixture: the
filter and the smoother compile once per model structure (compilation is most of this file's
cost).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxtrack
from jaxtrack.filters import (
    AutoScan,
    ExtendedKalmanFilter,
    KalmanFilter,
    ParallelInTime,
    Sequential,
    rts_smoother,
    run_filter,
)
from jaxtrack.filters._parallel import _prefix_scan
from jaxtrack.models import LinearGaussianModel, constant_velocity

from helpers import assert_close

T = 10_000
RTOL = 1e-10
FILTER_FIELDS = (
    "filtered_mean", "filtered_cov", "predicted_mean", "predicted_cov", "innovation", "innovation_cov",
    "num_observed", "log_likelihood", "final_mean", "final_cov",
)
SMOOTHER_FIELDS = ("smoothed_mean", "smoothed_cov", "smoother_gain")
PRIOR_COV = np.diag([100.0, 100.0, 10.0, 10.0])


def _cv(taus, accel_psd=0.5):
    return constant_velocity(taus, dim=2, accel_psd=accel_psd, measurement_std=3.0,
                             initial_mean=jnp.array([0.0, 0.0, 5.0, -3.0]), initial_cov=PRIOR_COV)


def _time_varying(rng):
    """Per-step F, Q (random sampling periods), a rotating H, per-step R and a known offset."""
    cv = _cv(rng.uniform(0.2, 2.0, T))
    angle = np.linspace(0.0, 6.0 * np.pi, T)
    rot = np.stack([np.stack([np.cos(angle), -np.sin(angle)], -1), np.stack([np.sin(angle), np.cos(angle)], -1)], -2)
    H = np.concatenate([rot, 0.1 * rot], axis=-1)  # (T, 2, 4): rotated position plus a little velocity
    R = np.einsum("k,ij->kij", rng.uniform(1.0, 16.0, T), np.eye(2)) + 0.5 * np.array([[0.0, 1.0], [1.0, 0.0]])
    b = 0.05 * rng.standard_normal((T, 4))
    return LinearGaussianModel(cv.F, cv.Q, H, R, cv.initial_mean, cv.initial_cov, transition_offset=b)


def _simulate(rng, model, first_step="update"):
    """``z_0..z_{T-1}`` from ``model`` (NumPy; noise from precomputed Cholesky factors)."""
    stack = lambda a, nd: np.broadcast_to(np.asarray(a), (T,) + np.shape(a)[-nd:])  # noqa: E731
    F, Q, H, R = (stack(a, 2) for a in (model.F, model.Q, model.H, model.R))
    b = np.zeros((T, 4)) if model.b is None else stack(model.b, 1)
    w = np.einsum("kij,kj->ki", np.linalg.cholesky(Q), rng.standard_normal((T, 4)))
    v = np.einsum("kij,kj->ki", np.linalg.cholesky(R), rng.standard_normal((T, 2)))
    x = np.asarray(model.initial_mean) + np.linalg.cholesky(PRIOR_COV) @ rng.standard_normal(4)
    zs = np.empty((T, 2))
    for k in range(T):
        if k > 0 or first_step == "predict":
            x = F[k] @ x + b[k] + w[k]
        zs[k] = H[k] @ x + v[k]
    return zs


def _both(model, zs, **kwargs):
    return {name: rts_smoother(model, zs, scan=scan, **kwargs)
            for name, scan in (("sequential", Sequential()), ("parallel", ParallelInTime()))}


@pytest.fixture(scope="module")
def cases():
    rng = np.random.default_rng(20210101)
    cv = _cv(0.5)  # constant F, Q, H, R
    tv = _time_varying(rng)
    mask = rng.random((T, 2)) > 0.2  # missing components
    mask[1000:1050] = False  # missing steps
    mask[T - 3:] = False  # missing at the end (the smoother starts from a prediction)
    # Two model structures, so two compilations of each pass: the time-varying model also
    # carries first_step="predict" (the elements of steps k ≥ 1 do not depend on it).
    return {
        "constant_velocity": (cv, _both(cv, _simulate(rng, cv)), None),
        "missing": (cv, _both(cv, _simulate(rng, cv), mask=mask), mask),
        "time_varying_predict_first": (tv, _both(tv, _simulate(rng, tv, "predict"), first_step="predict"), None),
    }


@pytest.mark.parametrize("case", ["constant_velocity", "missing", "time_varying_predict_first"])
def test_parallel_equals_sequential(cases, case):
    _, results, mask = cases[case]
    seq, par = results["sequential"], results["parallel"]
    for field in FILTER_FIELDS:
        assert_close(getattr(par.filtered, field), getattr(seq.filtered, field), RTOL, err_msg=field)
    for field in SMOOTHER_FIELDS:
        assert_close(getattr(par, field), getattr(seq, field), RTOL, err_msg=field)
    assert bool(par.ok) and bool(par.filtered.ok)
    assert par.filtered.filtered_cov_factor is None  # square-root fields: as the Kalman filter's
    if mask is not None:
        # Missing components contribute nothing: zero innovation, identity rows of S.
        assert np.all(np.asarray(par.filtered.innovation)[~mask] == 0.0)
        assert np.all(np.asarray(par.filtered.num_observed) == mask.sum(1))
        S = np.asarray(par.filtered.innovation_cov)[1000]
        np.testing.assert_array_equal(S, np.eye(2))


def test_where_the_prior_sits(cases):
    # "update": the prior is the prediction at z_0; "predict": P_{0/-1} = F_0 P0 F_0ᵀ + Q_0.
    upd = cases["constant_velocity"][1]["parallel"].filtered
    np.testing.assert_array_equal(upd.predicted_cov[0], PRIOR_COV)
    tv, results, _ = cases["time_varying_predict_first"]
    F0, Q0 = np.asarray(tv.F[0]), np.asarray(tv.Q[0])
    assert_close(results["parallel"].filtered.predicted_cov[0], F0 @ PRIOR_COV @ F0.T + Q0, RTOL)


@pytest.mark.parametrize("save", ["all", "final", "mean"])
def test_save_modes_give_the_sequential_fields(save):
    # Structure and shapes only (traced, not compiled); values of "final": the gradient test.
    model = _cv(0.5)
    zs = jax.ShapeDtypeStruct((T, 2), jnp.float64)
    run = lambda scan: jax.eval_shape(  # noqa: E731
        lambda z: run_filter(KalmanFilter(), model, z, save=save, throw=False, scan=scan), zs)
    seq, par = run(Sequential()), run(ParallelInTime())
    assert jax.tree_util.tree_structure(par) == jax.tree_util.tree_structure(seq)
    assert [(a.shape, a.dtype) for a in jax.tree_util.tree_leaves(par)] == [
        (a.shape, a.dtype) for a in jax.tree_util.tree_leaves(seq)]


def test_log_likelihood_and_its_derivative_agree():
    # d log L / d q (q: the acceleration noise density, a model parameter), forward mode: for one
    # scalar parameter it is the gradient, and it compiles in half the time of jax.grad (reverse
    # mode through the scan schedule is checked in test_prefix_scan_is_the_ordered_product).
    rng = np.random.default_rng(7)
    zs = _simulate(rng, _cv(0.5))

    def value_and_derivative(scan):
        def loglik(q):
            return run_filter(KalmanFilter(), _cv(0.5, q), zs, save="final", scan=scan).log_likelihood

        return jax.jvp(loglik, (jnp.asarray(0.5),), (jnp.asarray(1.0),))

    (l_seq, d_seq), (l_par, d_par) = value_and_derivative(Sequential()), value_and_derivative(ParallelInTime())
    assert abs(float(l_par) - float(l_seq)) <= RTOL * abs(float(l_seq))
    assert np.isfinite(float(d_seq)) and abs(float(d_seq)) > 1.0
    assert abs(float(d_par) - float(d_seq)) <= 1e-8 * abs(float(d_seq))


def test_other_filters_and_gains_are_refused_naming_scan():
    model = _cv(0.5)
    zs = np.zeros((5, 2))
    for call in (
        lambda: run_filter(ExtendedKalmanFilter(), model, zs, scan=ParallelInTime()),
        lambda: rts_smoother(model, zs, filter=ExtendedKalmanFilter(), scan=ParallelInTime()),
        lambda: run_filter(KalmanFilter(gain=np.zeros((4, 2))), model, zs, scan=ParallelInTime()),
    ):
        with pytest.raises(jaxtrack.InputError, match=r"`scan=ParallelInTime\(\)` supports the KalmanFilter"):
            call()
    with pytest.raises(jaxtrack.InputError, match="`scan` must be"):
        run_filter(KalmanFilter(), model, zs, scan="parallel")


def test_auto_scan_is_sequential_on_cpu():
    assert jax.default_backend() == "cpu"
    model = _cv(0.5)
    assert AutoScan().resolve(KalmanFilter(), model, 10**6) == Sequential()
    assert AutoScan().resolve(ExtendedKalmanFilter(), model, 10**6) == Sequential()


def test_prefix_scan_is_the_ordered_product():
    # A non-commutative operator (2x2 matrix products); T = 1 (one block) and T = 15 (blocks of
    # 4, one padded), prefixes and suffixes, values and the reverse-mode gradient.
    rng = np.random.default_rng(3)
    op = lambda earlier, later: later @ earlier  # noqa: E731

    def ordered(x, reverse):
        acc, out = None, []
        for i in (range(len(x) - 1, -1, -1) if reverse else range(len(x))):
            acc = x[i] if acc is None else (op(x[i], acc) if reverse else op(acc, x[i]))
            out.append(acc)
        return (jnp.stack if isinstance(x, jax.Array) else np.stack)(out[::-1] if reverse else out)

    scan = jax.jit(lambda x, reverse: _prefix_scan(op, x, jnp.eye(2), reverse=reverse), static_argnums=1)
    for num in (1, 15):
        x = rng.standard_normal((num, 2, 2))
        for reverse in (False, True):
            np.testing.assert_allclose(scan(x, reverse), ordered(x, reverse), rtol=1e-12, atol=1e-12)
    grad = lambda f: jax.jit(jax.grad(lambda x: jnp.sum(jnp.sin(f(x)))))  # noqa: E731
    np.testing.assert_allclose(grad(lambda x: scan(x, True))(x), grad(lambda x: ordered(x, True))(x),
                               rtol=1e-12, atol=1e-12)

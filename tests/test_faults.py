"""Fault injection: bad inputs under eager, jit (argument / closed over), vmap and grad.

Issue 24 ("no silent failure"). The first part holds one test per example of the issue that this
module fixes (each fails without its fix); the second part is a table of bad inputs, each run
under up to five modes, classified as

- ``clear``: an ``InputError`` or a runtime error from ``equinox.error_if`` whose message names
  the argument;
- ``flagged``: a result whose ``ok`` is False;
- ``unclear``: an error that does not name the argument;
- ``silent``: a result that looks valid (``ok`` True or no flag at all);
- ``hang``: no answer within the per-case time limit.

The last test prints the table and asserts that nothing is silent, unclear or hung.
"""

from __future__ import annotations

import threading
from collections import Counter

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.filters import ExtendedKalmanFilter, KalmanFilter, rts_smoother, run_filter
from jaxtrack.models import CoordinatedTurn, RangeBearing, TrackingModel
from jaxtrack.models import LinearGaussianModel, NonlinearGaussianModel, constant_velocity, ho_plant
from jaxtrack.montecarlo import simulate
from jaxtrack.sensitivity import Analytic, Autodiff, adjoint, covariance_sensitivity, sensitivity_index

T = 6
H = np.array([[1.0, 0.0]])
R = np.array([[0.5]])
F = np.array([[1.0, 1.0], [0.0, 1.0]])
Q = 0.1 * np.eye(2)
Z = np.linspace(0.0, 1.0, T)[:, None]


def _lin(F=F, Q=Q, H=H, R=R, m0=np.zeros(2), P0=np.eye(2)):
    return LinearGaussianModel(F, Q, H, R, m0, P0)


def _runtime_error_types():
    types = [eqx.EquinoxRuntimeError] if hasattr(eqx, "EquinoxRuntimeError") else []
    types.append(getattr(jax.errors, "JaxRuntimeError", RuntimeError))
    try:
        from jaxlib.xla_extension import XlaRuntimeError

        types.append(XlaRuntimeError)
    except ImportError:  # pragma: no cover - newer jaxlib
        pass
    # A failed host callback (how eqx.error_if raises under jax.jit) sometimes surfaces as a
    # plain ValueError("INTERNAL: CpuCallback error ...") carrying equinox's message.
    types.append(ValueError)
    return tuple(types)


RUNTIME_ERRORS = _runtime_error_types()


# ---------------------------------------------------------------------------------------------
# 1. The examples of the issue
# ---------------------------------------------------------------------------------------------


def test_readme_gradient_under_jit_equals_eager():
    """README: jax.jit(jax.grad(loglik)) with the measurements closed over (was a
    TracerArrayConversionError in prepare_measurements)."""
    model = constant_velocity(1.0, dim=2, accel_psd=0.5, measurement_std=10.0,
                              initial_cov=jnp.diag(jnp.array([100.0, 100.0, 10.0, 10.0]) ** 2))
    truth = simulate(model, jax.random.key(0), num_steps=20)

    def loglik(taus):
        m = constant_velocity(taus, dim=2, accel_psd=0.5, measurement_std=10.0,
                              initial_cov=jnp.eye(4) * 100.0)
        return run_filter(KalmanFilter(), m, truth.measurements).log_likelihood

    eager = jax.grad(loglik)(jnp.ones(20))
    jitted = jax.jit(jax.grad(loglik))(jnp.ones(20))
    assert eager.shape == (20,) and np.all(np.isfinite(eager))
    assert float(jnp.max(jnp.abs(eager[1:]))) > 1.0  # a real gradient, not zeros
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(eager), rtol=0, atol=1e-12)


def _singular_model():
    # Q = 0 and a singular F: the constructor accepts it (Q need only be semidefinite), and the
    # predicted covariance F P Fᵀ is singular. Issue 24 flagged this; issue 19 made the smoother
    # exact here (pseudo-inverse gain on the range of P_{k+1/k}; tests/test_smoother_singular.py
    # holds it against the dense oracle), so it is no longer a fault.
    return _lin(F=np.array([[1.0, 0.0], [0.0, 0.0]]), Q=np.zeros((2, 2)))


def test_smoother_on_singular_predicted_covariance_is_finite_and_ok():
    result = rts_smoother(_singular_model(), Z)
    assert bool(result.ok) and bool(result.filtered.ok)
    assert np.all(np.isfinite(np.asarray(result.smoothed_mean)))
    assert np.all(np.isfinite(np.asarray(result.smoothed_cov)))


def _turn_model(turn_rate, noise_std=(1.0, 0.01)):
    return TrackingModel(CoordinatedTurn(1.0, turn_rate=turn_rate, noise_intensity=0.1),
                         RangeBearing(noise_std=noise_std),
                         np.array([100.0, 50.0, 1.0, 0.0]), np.eye(4))


NONSYMMETRIC_L = jnp.array([[1.0, 3.0], [-1.0, 0.5]])


def test_sensitivity_index_nonsymmetric_weight_analytic_equals_autodiff():
    taus = jnp.full(8, 0.1)
    analytic = sensitivity_index(ho_plant, taus, NONSYMMETRIC_L, method=Analytic())
    auto = sensitivity_index(ho_plant, taus, NONSYMMETRIC_L, method=Autodiff())
    assert float(jnp.max(jnp.abs(auto))) > 1.0
    np.testing.assert_allclose(np.asarray(analytic), np.asarray(auto), rtol=1e-10,
                               atol=1e-10 * float(jnp.max(jnp.abs(auto))))
    # Only the symmetric part matters: J = tr(L P) = tr(sym(L) P) for symmetric P.
    sym = 0.5 * (NONSYMMETRIC_L + NONSYMMETRIC_L.T)
    np.testing.assert_allclose(np.asarray(sensitivity_index(ho_plant, taus, sym)), np.asarray(analytic),
                               rtol=1e-12)
    # The adjoint's methods agree as well (both symmetric).
    model = ho_plant(taus)
    a_an = adjoint(model, NONSYMMETRIC_L, method=Analytic())
    a_ad = adjoint(model, NONSYMMETRIC_L, method=Autodiff())
    np.testing.assert_allclose(np.asarray(a_an.filtered), np.asarray(a_ad.filtered), rtol=1e-9, atol=1e-9)


def test_sensitivity_index_nan_weight_and_negative_tau():
    taus = jnp.full(10, 0.1)
    with pytest.raises(InputError, match="`weight`"):
        sensitivity_index(ho_plant, taus, jnp.full((2, 2), jnp.nan))
    with pytest.raises(InputError, match="`taus`"):
        sensitivity_index(ho_plant, -taus, jnp.eye(2))
    with pytest.raises(RUNTIME_ERRORS, match="`alpha`"):
        jax.jit(lambda a: sensitivity_index(ho_plant, a, jnp.eye(2)))(-taus).block_until_ready()
    with pytest.raises(RUNTIME_ERRORS, match="`weight`"):
        jax.jit(lambda L: sensitivity_index(ho_plant, taus, L))(jnp.full((2, 2), jnp.nan))


def test_indefinite_prior_under_jit_is_flagged():
    def ok_of(P0):
        return run_filter(KalmanFilter(), _lin(P0=P0), Z, throw=False).ok

    assert bool(jax.jit(ok_of)(jnp.eye(2)))
    assert not bool(jax.jit(ok_of)(jnp.array([[1.0, 0.0], [0.0, -1.0]])))
    with pytest.raises(RUNTIME_ERRORS, match="`initial_cov`"):
        jax.jit(lambda P0: run_filter(KalmanFilter(), _lin(P0=P0), Z).log_likelihood)(
            jnp.array([[1.0, 0.0], [0.0, -1.0]])
        ).block_until_ready()


def test_simulate_nan_prior_raises():
    bad = eqx.tree_at(lambda m: m.initial_mean, _lin(), jnp.array([jnp.nan, 0.0]))
    with pytest.raises(InputError, match="`initial_mean`"):
        simulate(bad, jax.random.key(0), T)

    def states(m0):
        return simulate(_lin(m0=m0), jax.random.key(0), T).states

    assert np.all(np.isfinite(np.asarray(jax.jit(states)(jnp.zeros(2)))))
    with pytest.raises(RUNTIME_ERRORS, match="`initial_mean`"):
        jax.jit(states)(jnp.array([jnp.nan, 0.0])).block_until_ready()


def _short(x, k):
    return x[:1]


def _identity(x, k):
    return x


def _first(x, k):
    return x[:1]


def test_nonlinear_wrong_shape_names_the_function():
    bad_f = NonlinearGaussianModel(_short, _first, Q, R, np.zeros(2), np.eye(2))
    with pytest.raises(InputError, match=r"`transition_fn` must return shape \(2,\).*returns \(1,\)"):
        run_filter(ExtendedKalmanFilter(), bad_f, Z)
    with pytest.raises(InputError, match="`transition_fn`"):
        simulate(bad_f, jax.random.key(0), T)
    bad_h = NonlinearGaussianModel(_identity, _identity, Q, R, np.zeros(2), np.eye(2))
    with pytest.raises(InputError, match=r"`measurement_fn` must return shape \(1,\).*returns \(2,\)"):
        run_filter(ExtendedKalmanFilter(), bad_h, Z)


def test_wrong_length_initial_mean_blames_initial_mean():
    with pytest.raises(InputError, match=r"^`initial_mean` must have shape \(2,\)"):
        _lin(m0=np.zeros(3))
    with pytest.raises(InputError, match=r"^`initial_cov`"):
        _lin(P0=np.eye(3))


def test_covariance_sensitivity_num_steps_mismatch_blames_num_steps():
    model_fn = lambda tau: ho_plant(jnp.full(12, tau))  # noqa: E731
    with pytest.raises(InputError, match=r"^`num_steps` is 10 .* 12 steps"):
        covariance_sensitivity(model_fn, 0.1, 10)
    with pytest.raises(InputError, match=r"^`num_steps`"):
        sensitivity_index(ho_plant, jnp.full(12, 0.1), jnp.eye(2), 10)


# ---------------------------------------------------------------------------------------------
# 2. The fault-injection table
# ---------------------------------------------------------------------------------------------

MODES = ("eager", "jit_arg", "jit_closed", "vmap", "grad")
TIME_LIMIT_S = 20.0
RESULTS: dict[str, str] = {}


def _kf(model, z=Z, **kw):
    return run_filter(KalmanFilter(), model, z, throw=False, **kw)


def _cv(taus):
    return constant_velocity(taus, dim=1, accel_psd=0.5, measurement_std=1.0, initial_cov=jnp.eye(2))


def _indefinite(x):
    return x * jnp.array([[1.0, 0.0], [0.0, -1.0]])


# Mode sets: each case runs under the modes that exercise a different check path (static shape
# checks need no vmap/grad run; value checks need a traced run), which keeps the file fast.
TRACED4 = ("eager", "jit_arg", "vmap", "grad")
CLOSED4 = ("eager", "jit_arg", "jit_closed", "vmap")
BATCH3 = ("eager", "jit_arg", "vmap")
JIT2 = ("eager", "jit_arg")

# name: (function of the bad value x, the bad value, argument names any one of which the message
# must contain, modes that apply). The function returns a pytree; a field ``ok`` is its flag.
CASES = {
    "indefinite initial_cov (run_filter)": (
        lambda x: _kf(_lin(P0=_indefinite(x))), np.eye(2), ("initial_cov",), TRACED4),
    "indefinite initial_cov (throw=True)": (
        lambda x: run_filter(KalmanFilter(), _lin(P0=_indefinite(x)), Z), np.eye(2), ("initial_cov",), ("jit_arg",)),
    "NaN initial_mean (run_filter)": (
        lambda x: _kf(_lin(m0=x)), np.array([np.nan, 0.0]), ("initial_mean",), JIT2),
    # m = 2 (H = I): a 1 x 1 R is symmetric by construction.
    "non-symmetric R (run_filter)": (
        lambda x: run_filter(KalmanFilter(), _lin(H=np.eye(2), R=x), np.zeros((T, 2)), throw=False),
        np.array([[1.0, 0.5], [0.0, 1.0]]), ("measurement_noise_cov",), BATCH3),
    "non-symmetric initial_cov (run_filter)": (
        lambda x: _kf(_lin(P0=x)), np.array([[1.0, 0.5], [0.0, 1.0]]), ("initial_cov",), JIT2),
    "negative R (run_filter)": (
        lambda x: _kf(_lin(R=x)), np.array([[-0.5]]), ("measurement_noise_cov",), JIT2),
    "NaN measurement (run_filter)": (
        lambda x: _kf(_lin(), z=x), np.where(np.arange(T)[:, None] == 2, np.nan, Z), ("measurements",), CLOSED4),
    "NaN measurement (throw=True)": (
        lambda x: run_filter(KalmanFilter(), _lin(), x), np.where(np.arange(T)[:, None] == 2, np.nan, Z),
        ("measurement",), JIT2),
    "NaN measurement (rts_smoother)": (
        lambda x: rts_smoother(_lin(), x, throw=False), np.where(np.arange(T)[:, None] == 2, np.nan, Z),
        ("measurements",), JIT2),
    "wrong measurement shape": (
        lambda x: _kf(_lin(), z=x), np.zeros((T, 2)), ("measurements",), BATCH3),
    "integer mask": (
        lambda x: _kf(_lin(), mask=x), np.ones(T, np.int32), ("mask",), JIT2),
    "negative tau (constant_velocity)": (
        lambda x: _kf(_cv(x)), -np.ones(T), ("taus",), BATCH3),
    # Issue 19's models: a bad parameter is named whether it arrives eager or traced.
    "NaN turn_rate (CoordinatedTurn)": (
        lambda x: run_filter(ExtendedKalmanFilter(), _turn_model(x), np.zeros((T, 2)), throw=False),
        np.array(np.nan), ("turn_rate",), JIT2),
    "negative noise_std (RangeBearing)": (
        lambda x: run_filter(ExtendedKalmanFilter(), _turn_model(0.1, x), np.zeros((T, 2)), throw=False),
        # Eager only: traced, R = diag(σ²) depends on σ² alone, so a negative σ is the same
        # (valid) sensor, not a fault; an optimiser crossing 0 meets a symmetric objective.
        np.array([-1.0, 0.01]), ("noise_std",), ("eager",)),
    "NaN initial_mean (simulate)": (
        lambda x: simulate(_lin(m0=x), jax.random.key(0), T), np.array([np.nan, 0.0]), ("initial_mean",), TRACED4),
    "NaN Q (simulate)": (
        lambda x: simulate(_lin(Q=x), jax.random.key(0), T), np.full((2, 2), np.nan), ("process_noise_cov",), JIT2),
    "indefinite initial_cov (simulate)": (
        lambda x: simulate(_lin(P0=_indefinite(x)), jax.random.key(0), T), np.eye(2), ("initial_cov",), JIT2),
    "transition_fn wrong shape (run_filter)": (
        lambda x: run_filter(ExtendedKalmanFilter(), NonlinearGaussianModel(_short, _first, Q, R, x, np.eye(2)), Z),
        np.zeros(2), ("transition_fn",), ("eager", "jit_closed")),
    "measurement_fn wrong shape (simulate)": (
        lambda x: simulate(NonlinearGaussianModel(_identity, _identity, Q, R, x, np.eye(2)), jax.random.key(0), T),
        np.zeros(2), ("measurement_fn",), ("eager", "vmap")),
    "wrong-length initial_mean": (
        lambda x: _kf(_lin(m0=x)), np.zeros(3), ("initial_mean",), JIT2),
    "NaN weight (sensitivity_index)": (
        lambda x: sensitivity_index(ho_plant, jnp.full(T, 0.1), x), np.full((2, 2), np.nan), ("weight",), TRACED4),
    "negative tau (sensitivity_index)": (
        lambda x: sensitivity_index(ho_plant, x, jnp.eye(2)), np.full(T, -0.1), ("taus", "alpha"), JIT2),
    "negative tau (covariance_sensitivity)": (
        lambda x: covariance_sensitivity(lambda t: ho_plant(t), x).d_filtered_cov, np.full(T, -0.1),
        ("taus", "alpha"), JIT2),
    "num_steps mismatch (covariance_sensitivity)": (
        lambda x: covariance_sensitivity(lambda t: ho_plant(jnp.full(T, t)), x, T - 1).d_filtered_cov,
        np.array(0.1), ("num_steps",), JIT2),

}

PARAMS = [(name, mode) for name, (_, _, _, modes) in CASES.items() for mode in modes]


def _flag(out):
    """``ok`` of the first result in ``out`` that has one (None if none has)."""
    for leaf in jax.tree_util.tree_leaves(out, is_leaf=lambda x: hasattr(x, "ok")):
        if hasattr(leaf, "ok"):
            return leaf.ok
    return None


def _scalar(out):
    leaves = [a for a in jax.tree_util.tree_leaves(out) if jnp.issubdtype(jnp.result_type(a), jnp.floating)]
    return sum(jnp.sum(a) for a in leaves)


def _call(fn, x, mode):
    """Run ``fn`` on the bad value ``x`` in ``mode``; return ``(flag, values)`` (arrays)."""
    if mode == "eager":
        out = fn(x)
        return _flag(out), out
    if mode == "jit_arg":
        out = jax.jit(fn)(x)
        return _flag(out), out
    if mode == "jit_closed":
        out = jax.jit(lambda: fn(x))()
        return _flag(out), out
    if mode == "vmap":
        out = jax.vmap(fn)(jnp.stack([jnp.asarray(x)] * 2))
        return _flag(out), out
    if mode == "grad":
        def loss(x):
            out = fn(x)
            flag = _flag(out)
            return _scalar(out), (jnp.ones((), bool) if flag is None else flag)

        g, flag = jax.grad(loss, has_aux=True)(jnp.asarray(x, float))
        return flag, g
    raise AssertionError(mode)


def _classify(fn, x, mode, names) -> tuple[str, str]:
    box: dict = {}

    def target():
        try:
            flag, out = _call(fn, x, mode)
            jax.block_until_ready(out)
            box["flag"] = None if flag is None else bool(np.all(np.asarray(flag)))
        except BaseException as error:  # noqa: BLE001  (classified below)
            box["error"] = error

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    thread.join(TIME_LIMIT_S)
    if thread.is_alive():
        return "hang", f"no answer in {TIME_LIMIT_S:.0f} s"
    if "error" in box:
        error = box["error"]
        message = str(error)
        known = isinstance(error, (InputError,) + RUNTIME_ERRORS)
        if known and any(name in message for name in names):
            return "clear", f"{type(error).__name__}"
        return "unclear", f"{type(error).__name__}: {message[:200]}"
    if box["flag"] is False:
        return "flagged", "ok=False"
    return "silent", f"returned, ok={box['flag']}"


@pytest.mark.parametrize(("case", "mode"), PARAMS, ids=[f"{c}-{m}" for c, m in PARAMS])
def test_injected(case, mode):
    fn, x, names, _ = CASES[case]
    kind, detail = _classify(fn, x, mode, names)
    RESULTS[f"{case} [{mode}]"] = kind
    assert kind in ("clear", "flagged"), f"{case} [{mode}]: {kind} ({detail})"


def test_injection_table(capsys):
    """Print the table (pytest -s, or always through capsys.disabled) and check its totals."""
    missing = [f"{c} [{m}]" for c, m in PARAMS if f"{c} [{m}]" not in RESULTS]
    for case, mode in PARAMS:  # a run of this test alone fills the table itself
        key = f"{case} [{mode}]"
        if key in missing:
            fn, x, names, _ = CASES[case]
            RESULTS[key] = _classify(fn, x, mode, names)[0]
    counts = Counter(RESULTS.values())
    width = max(len(k) for k in RESULTS)
    lines = [f"{'case [mode]':<{width}}  result"] + [f"{k:<{width}}  {v}" for k, v in RESULTS.items()]
    lines.append(
        f"fault injection: {len(RESULTS)} cases tried, {counts['clear']} clear errors, "
        f"{counts['flagged']} flagged, {counts['unclear']} unclear errors, {counts['silent']} silent, "
        f"{counts['hang']} hangs"
    )
    with capsys.disabled():
        print("\n" + "\n".join(lines))
    assert len(RESULTS) == len(PARAMS) >= 55
    assert counts["silent"] == 0 and counts["hang"] == 0 and counts["unclear"] == 0

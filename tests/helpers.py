"""Shared test utilities: random models and NumPy reference computations.

Everything here is plain NumPy/SciPy (no jaxtrack arithmetic), so that it can serve as an
independent oracle for the JAX implementations. The only jaxtrack object built here is the
:class:`~jaxtrack.models.LinearGaussianModel` handed to the code under test; the references read
their matrices back through :func:`model_arrays`.

Conventions (those of jaxtrack): per-step arrays are indexed by the measurement step they lead
INTO; ``first_step="update"`` puts the prior on ``x_0``, ``first_step="predict"`` puts it one
transition before, on ``x_{-1}``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.linalg

from jaxtrack.models import LinearGaussianModel

LOG_2PI = np.log(2.0 * np.pi)


def as_rng(key_or_rng) -> np.random.Generator:
    """A NumPy ``Generator`` from a Generator, an int seed, or a JAX PRNG key."""
    if isinstance(key_or_rng, np.random.Generator):
        return key_or_rng
    if isinstance(key_or_rng, (int, np.integer)):
        return np.random.default_rng(int(key_or_rng))
    # A JAX key (typed or raw uint32): derive a seed from its bits.
    import jax

    data = key_or_rng
    if jax.dtypes.issubdtype(getattr(data, "dtype", None), jax.dtypes.prng_key):
        data = jax.random.key_data(data)
    return np.random.default_rng(np.asarray(data, dtype=np.uint32).ravel().tolist())


def random_spd(key_or_rng, n: int, cond_max: float = 1e3, scale: float = 1.0) -> np.ndarray:
    """Random symmetric positive definite ``(n, n)`` matrix with condition number ≤ ``cond_max``.

    Rejection sampling of ``G Gᵀ / n + 0.05 I`` (``G`` standard normal), rescaled by ``scale``.
    The result is exactly symmetric.
    """
    rng = as_rng(key_or_rng)
    for _ in range(1000):
        G = rng.standard_normal((n, n))
        A = G @ G.T / n + 0.05 * np.eye(n)
        A = 0.5 * (A + A.T)
        eig = np.linalg.eigvalsh(A)
        if eig[0] > 0 and eig[-1] / eig[0] <= cond_max:
            return scale * A
    raise RuntimeError(f"random_spd: no sample with condition number <= {cond_max} for n={n}")


def random_taus(rng: np.random.Generator, T: int, nonuniform: bool = True) -> np.ndarray:
    """Sampling intervals ``τ_k`` in [0.05, 0.3] (constant 0.1 when ``nonuniform`` is False)."""
    if nonuniform:
        return rng.uniform(0.05, 0.3, size=T)
    return np.full(T, 0.1)


def random_linear_model(
    rng,
    n: int,
    m: int,
    T: int,
    nonuniform_tau: bool = True,
    *,
    offset: bool = False,
    per_step_measurement: bool = False,
) -> LinearGaussianModel:
    """Random linear-Gaussian model with per-step ``F_k = expm(A τ_k)`` and ``Q_k = τ_k Q_c``.

    ``A`` has N(0, 0.5²) entries (so ``F_k`` is well conditioned over τ ≤ 0.3), ``Q_c``, ``R``
    and ``P0`` are SPD with condition number ≤ 1e3, ``H`` is N(0, 1), the prior mean N(0, 1).
    ``offset=True`` adds a per-step known input ``b_k``; ``per_step_measurement=True`` makes
    ``H`` and ``R`` per step too.
    """
    rng = as_rng(rng)
    tau = random_taus(rng, T, nonuniform_tau)
    A = 0.5 * rng.standard_normal((n, n))
    F = np.stack([scipy.linalg.expm(A * t) for t in tau])
    Qc = random_spd(rng, n)
    Q = tau[:, None, None] * Qc[None]
    if per_step_measurement:
        H = rng.standard_normal((T, m, n))
        R = np.stack([random_spd(rng, m, scale=0.5) for _ in range(T)])
    else:
        H = rng.standard_normal((m, n))
        R = random_spd(rng, m, scale=0.5)
    P0 = random_spd(rng, n, scale=2.0)
    m0 = rng.standard_normal(n)
    b = 0.3 * rng.standard_normal((T, n)) if offset else None
    return LinearGaussianModel(F, Q, H, R, m0, P0, transition_offset=b)


class ModelArrays(NamedTuple):
    """A linear model's matrices as NumPy arrays broadcast to ``T`` steps."""

    F: np.ndarray  # (T, n, n)
    Q: np.ndarray  # (T, n, n)
    H: np.ndarray  # (T, m, n)
    R: np.ndarray  # (T, m, m)
    b: np.ndarray  # (T, n), zeros if the model has no offset
    m0: np.ndarray  # (n,)
    P0: np.ndarray  # (n, n)


def model_arrays(model: LinearGaussianModel, T: int) -> ModelArrays:
    def per_step(a, nd):
        a = np.asarray(a, dtype=np.float64)
        return a if a.ndim == nd + 1 else np.broadcast_to(a, (T,) + a.shape).copy()

    n = model.state_dim
    b = np.zeros((T, n)) if model.b is None else per_step(model.b, 1)
    return ModelArrays(
        per_step(model.F, 2),
        per_step(model.Q, 2),
        per_step(model.H, 2),
        per_step(model.R, 2),
        b,
        np.asarray(model.initial_mean, dtype=np.float64),
        np.asarray(model.initial_cov, dtype=np.float64),
    )


def simulate_linear(rng, model: LinearGaussianModel, T: int, first_step: str = "update"):
    """Draw one trajectory ``x_0..x_{T-1}`` and its measurements ``z_0..z_{T-1}`` (NumPy).

    With ``first_step="predict"`` the prior sample is ``x_{-1}`` and ``F_0, Q_0, b_0`` take it to
    ``x_0``; with ``"update"`` the prior sample is ``x_0``. Returns ``(xs (T, n), zs (T, m))``.
    """
    rng = as_rng(rng)
    a = model_arrays(model, T)
    n, m = a.m0.shape[0], a.H.shape[1]
    x = rng.multivariate_normal(a.m0, a.P0)
    xs = np.empty((T, n))
    zs = np.empty((T, m))
    for k in range(T):
        if k > 0 or first_step == "predict":
            x = a.F[k] @ x + a.b[k] + rng.multivariate_normal(np.zeros(n), a.Q[k])
        xs[k] = x
        zs[k] = a.H[k] @ x + rng.multivariate_normal(np.zeros(m), a.R[k])
    return xs, zs


def observed_matrix(mask, T: int, m: int) -> np.ndarray:
    """A ``(T, m)`` boolean array from ``None``, a ``(T,)`` or a ``(T, m)`` mask."""
    if mask is None:
        return np.ones((T, m), bool)
    mask = np.asarray(mask, bool)
    return np.broadcast_to(mask[:, None] if mask.ndim == 1 else mask, (T, m)).copy()


def gaussian_logpdf(x: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> float:
    """``log N(x; mean, cov)`` by Cholesky (0 for an empty vector)."""
    d = x.shape[0]
    if d == 0:
        return 0.0
    L = np.linalg.cholesky(cov)
    w = scipy.linalg.solve_triangular(L, x - mean, lower=True)
    return float(-0.5 * (w @ w + 2.0 * np.sum(np.log(np.diag(L))) + d * LOG_2PI))


class DenseSolution(NamedTuple):
    """Batch (all-at-once) Gaussian conditioning of all states on all observed measurements."""

    prior_mean: np.ndarray  # (T, n): E[x_k]
    prior_cov: np.ndarray  # (T n, T n): Cov of the stacked states
    smoothed_mean: np.ndarray  # (T, n): E[x_k | z]
    smoothed_cov: np.ndarray  # (T, n, n): marginal Cov[x_k | z]
    log_likelihood: float  # log N(z_obs; E[z_obs], Cov[z_obs])


def dense_solution(model: LinearGaussianModel, zs, mask=None, first_step="update") -> DenseSolution:
    """Joint Gaussian of ``x_0..x_{T-1}`` and the observed measurement components, conditioned.

    The stacked state is ``X = μ + L ε`` with ``ε = (x_0 − E x_0, w_1, …, w_{T-1})`` independent;
    with ``first_step="predict"`` the prior of ``x_0`` is ``N(F_0 m0 + b_0, F_0 P0 F_0ᵀ + Q_0)``
    (the transition from ``x_{-1}`` marginalised out). Then ``Z = Hb X + V`` restricted to the
    observed rows, and ``X | Z`` is obtained by the Schur complement.
    """
    zs = np.asarray(zs, dtype=np.float64)
    T = zs.shape[0]
    a = model_arrays(model, T)
    n, m = a.m0.shape[0], a.H.shape[1]
    if first_step == "predict":
        x0_mean = a.F[0] @ a.m0 + a.b[0]
        x0_cov = a.F[0] @ a.P0 @ a.F[0].T + a.Q[0]
    else:
        x0_mean, x0_cov = a.m0, a.P0
    # Means.
    mu = np.empty((T, n))
    mu[0] = x0_mean
    for k in range(1, T):
        mu[k] = a.F[k] @ mu[k - 1] + a.b[k]
    # X − μ = L ε, block lower triangular: L[k, j] = F_k F_{k-1} … F_{j+1}.
    L = np.zeros((T * n, T * n))
    for j in range(T):
        block = np.eye(n)
        for k in range(j, T):
            if k > j:
                block = a.F[k] @ block
            L[k * n : (k + 1) * n, j * n : (j + 1) * n] = block
    D = scipy.linalg.block_diag(x0_cov, *[a.Q[k] for k in range(1, T)])
    Sigma = L @ D @ L.T
    Sigma = 0.5 * (Sigma + Sigma.T)
    # Measurements: all rows, then keep the observed ones.
    Hb = scipy.linalg.block_diag(*[a.H[k] for k in range(T)])
    Rb = scipy.linalg.block_diag(*[a.R[k] for k in range(T)])
    obs = observed_matrix(mask, T, m).ravel()
    Hb, Rb = Hb[obs], Rb[np.ix_(obs, obs)]
    z = zs.ravel()[obs]
    z_mean = Hb @ mu.ravel()
    S = Hb @ Sigma @ Hb.T + Rb
    S = 0.5 * (S + S.T)
    C = Sigma @ Hb.T
    if z.shape[0]:
        K = scipy.linalg.cho_solve(scipy.linalg.cho_factor(S, lower=True), C.T).T
    else:
        K = np.zeros((T * n, 0))
    post_mean = mu.ravel() + K @ (z - z_mean)
    post_cov = Sigma - K @ C.T
    post_cov = 0.5 * (post_cov + post_cov.T)
    sm_cov = np.stack([post_cov[k * n : (k + 1) * n, k * n : (k + 1) * n] for k in range(T)])
    ll = gaussian_logpdf(z, z_mean, S)
    return DenseSolution(mu, Sigma, post_mean.reshape(T, n), sm_cov, ll)


def joseph_covariances(model: LinearGaussianModel, gains, T: int, mask=None, first_step="update"):
    """Actual error covariances of a linear filter that uses the given gains (Joseph recursion).

    ``gains`` is ``(n, m)`` or ``(T, n, m)``; columns of missing components are zeroed, as the
    filter under test does. Returns ``(predicted (T, n, n), filtered (T, n, n))``.
    """
    a = model_arrays(model, T)
    n, m = a.m0.shape[0], a.H.shape[1]
    gains = np.asarray(gains, dtype=np.float64)
    if gains.ndim == 2:
        gains = np.broadcast_to(gains, (T, n, m))
    obs = observed_matrix(mask, T, m).astype(np.float64)
    P = a.P0
    pred, filt = np.empty((T, n, n)), np.empty((T, n, n))
    for k in range(T):
        if k > 0 or first_step == "predict":
            P = a.F[k] @ P @ a.F[k].T + a.Q[k]
        pred[k] = P
        W = gains[k] * obs[k][None, :]
        A = np.eye(n) - W @ a.H[k]
        P = A @ P @ A.T + W @ a.R[k] @ W.T
        filt[k] = P
    return pred, filt


def assert_close(actual, desired, rtol: float, atol_rel: float | None = None, err_msg: str = ""):
    """``assert_allclose`` with ``atol = atol_rel · max|desired|`` (default ``atol_rel = rtol``).

    Entries of a covariance or mean that are near zero only by cancellation cannot be compared
    relatively; the absolute tolerance is scaled to the magnitude of the whole array instead.
    """
    actual = np.asarray(actual, dtype=np.float64)
    desired = np.asarray(desired, dtype=np.float64)
    atol_rel = rtol if atol_rel is None else atol_rel
    scale = float(np.max(np.abs(desired))) if desired.size else 0.0
    np.testing.assert_allclose(actual, desired, rtol=rtol, atol=atol_rel * scale, err_msg=err_msg)

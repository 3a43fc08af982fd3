"""Random linear-Gaussian cases for the property-based tests (``tests/test_properties.py``).

Hypothesis draws a small :class:`Spec` (a shape from :data:`SHAPES`, the state dimension, the
mask kind, whether units are scaled, a seed); :func:`build_case` turns it into matrices with
NumPy. Drawing one integer seed instead of every matrix entry keeps an example cheap and its
printed form short enough to paste into ``@example(Spec(...))``.

**Why a few fixed shapes.** Every new ``(n, m, T)`` costs a fresh compilation of each filter
(1–5 s each on two cores), which would dominate the run. The compiled shapes in :data:`SHAPES`
cover the code paths that depend on a size (a scalar measurement, ``m`` 2–4, state sizes on both
sides of ``_linalg.MATMUL_UNROLL_MAX``, ``T = 1``, shared-path block lengths with and without a
remainder); within a shape the drawn model has ``n`` states, ``1 ≤ n ≤ n_pad``, embedded exactly:
the other ``n_pad − n`` states are independent and unobserved (block-diagonal ``F``, ``Q``, ``P0``;
zero columns of ``H``), so the drawn model's posterior is a block of the embedded one's. The
oracles below work on the embedded model as it is; nothing is compared on a sub-block only.

**Units.** The model is drawn in well-scaled units (condition numbers of ``P0``, ``Q_c``, ``R``
below about 100, ``‖A τ‖ ≲ 1.5``), and the library sees it after a change of units
``x' = S x``, ``z' = D z`` with ``S``, ``D`` diagonal, entries ``10^k``, ``k ∈ {−3, …, 3}``
(6 decades): ``F' = S F S⁻¹``, ``Q' = S Q S``, ``H' = D H S⁻¹``, ``R' = D R D``, ``b' = S b``,
``m0' = S m0``, ``P0' = S P0 S``. Results are mapped back (``x = S⁻¹ x'``, ``P = S⁻¹ P' S⁻¹``,
``log p(z) = log p(z') + Σ log d_j`` over observed components) and compared with the oracle
computed in the well-scaled units, so a tolerance relative to the size of each quantity is
meaningful whatever the units.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import equinox as eqx
import numpy as np
import scipy.linalg
from helpers import random_spd
from hypothesis import strategies as st
from jaxtyping import Array, Float

from jaxtrack.models import AbstractStateSpaceModel, LinearGaussianModel


class Shape(NamedTuple):
    """A compiled shape: ``n_pad`` states, ``m`` measurement components, ``T`` steps."""

    n_pad: int
    m: int
    T: int
    first_step: str


# Each shape is compiled once per filter (about 12 s per shape for all six properties on two
# loaded cores; the shared-covariance path alone 5–9 s), so there are few. Together they
# exercise: m = 1 (the scalar-gain branch of condition_linearized) and every m in 2..4 (unrolled
# Cholesky factors); n_pad ≤ 7 (written-out products, _linalg.MATMUL_UNROLL_MAX) and 8, 9 (`@`);
# T = 1 (the smoother's one-step case); the shared-covariance path's blocks of 16 // m steps with
# a remainder (T = 11, m = 2 → 8 + 3; T = 7, m = 3 → 5 + 2), without (T = 12, m = 4 → 3 × 4) and
# as one block (T = 12, m = 1); both first_step conventions.
SHAPES = (
    Shape(8, 1, 12, "update"),
    Shape(4, 2, 11, "predict"),
    Shape(6, 3, 7, "update"),
    Shape(9, 4, 12, "predict"),
    Shape(3, 4, 1, "update"),
)

MASK_KINDS = ("none", "step", "component")


@dataclasses.dataclass(frozen=True)
class Spec:
    """Everything that determines one example; ``repr`` is valid Python for ``@example``.

    - ``shape``: index into :data:`SHAPES`; ``n``: the drawn state dimension (``≤ n_pad``).
    - ``mask``: ``"none"`` (all observed), ``"step"`` (a ``(T,)`` mask: whole steps missing) or
      ``"component"`` (a ``(T, m)`` mask).
    - ``scaled``: apply the random change of units (else ``S = D = I``).
    - ``tight``: measurement noise 10⁶ times smaller (a near-singular posterior; property 2).
    - ``seed``: the NumPy seed of every matrix, τ, mask pattern, scale and measurement.
    """

    shape: int
    n: int
    mask: str
    scaled: bool
    seed: int
    tight: bool = False


@st.composite
def specs(draw, mask_kinds=MASK_KINDS, tight=st.just(False)) -> Spec:
    """Strategy for :class:`Spec` (``mask_kinds`` restricts the mask kinds drawn)."""
    shape = draw(st.integers(0, len(SHAPES) - 1))
    n = draw(st.integers(1, SHAPES[shape].n_pad))
    mask = draw(st.sampled_from(mask_kinds))
    scaled = draw(st.booleans())
    seed = draw(st.integers(0, 2**32 - 1))
    return Spec(shape, n, mask, scaled, seed, draw(tight))


class Arrays(NamedTuple):
    """A linear model's matrices, per step (NumPy float64): as in ``helpers.ModelArrays``."""

    F: np.ndarray  # (T, n, n)
    Q: np.ndarray  # (T, n, n)
    H: np.ndarray  # (T, m, n)
    R: np.ndarray  # (T, m, m)
    b: np.ndarray  # (T, n)
    m0: np.ndarray  # (n,)
    P0: np.ndarray  # (n, n)


class Case(NamedTuple):
    """One drawn example: the well-scaled arrays (for the oracles) and what the library sees."""

    spec: Spec
    shape: Shape
    arrays: Arrays  # well-scaled units
    state_scale: np.ndarray  # (n_pad,): x' = state_scale * x
    meas_scale: np.ndarray  # (m,): z' = meas_scale * z
    model: LinearGaussianModel  # in the scaled units
    zs: np.ndarray  # (B, T, m) well-scaled measurements (B = 1 unless asked for more)
    zs_scaled: np.ndarray  # (B, T, m) as given to the library; NaN where missing if requested
    mask: np.ndarray | None  # None, (T,) or (T, m): the mask argument
    observed: np.ndarray  # (T, m) bool

    @property
    def first_step(self) -> str:
        return self.shape.first_step


def _sym(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + np.swapaxes(a, -1, -2))


def _draw_dynamics(rng, n: int, tau: np.ndarray):
    """Per-step ``F_k``, ``Q_k`` for intervals ``tau``: constant-velocity blocks or ``expm(A τ)``."""
    T = tau.shape[0]
    if n >= 2 and rng.random() < 0.5:
        # Position-velocity pairs (and one random-walk state if n is odd), each with its own
        # white-acceleration intensity: the closed-form discretisation, no expm.
        F = np.zeros((T, n, n))
        Q = np.zeros((T, n, n))
        for i in range(0, n - 1, 2):
            q = 10.0 ** rng.uniform(-1.0, 1.0)
            F[:, i, i] = F[:, i + 1, i + 1] = 1.0
            F[:, i, i + 1] = tau
            Q[:, i, i] = q * tau**3 / 3.0
            Q[:, i, i + 1] = Q[:, i + 1, i] = q * tau**2 / 2.0
            Q[:, i + 1, i + 1] = q * tau
        if n % 2:
            F[:, -1, -1] = 1.0
            Q[:, -1, -1] = 10.0 ** rng.uniform(-1.0, 1.0) * tau
        return F, Q
    A = rng.normal(0.0, 0.7 / np.sqrt(n), (n, n))
    F = np.stack([scipy.linalg.expm(A * t) for t in tau])
    Qc = random_spd(rng, n, cond_max=1e2)
    return F, tau[:, None, None] * Qc[None]


def draw_arrays(rng, shape: Shape, n: int, tight: bool = False) -> Arrays:
    """A random well-scaled linear model with ``n`` coupled states embedded in ``shape.n_pad``."""
    n_pad, m, T = shape.n_pad, shape.m, shape.T
    tau = rng.uniform(0.02, 0.5, T)  # nonuniform sampling: intervals differ by up to 25×
    F = np.zeros((T, n_pad, n_pad))
    Q = np.zeros((T, n_pad, n_pad))
    F[:, :n, :n], Q[:, :n, :n] = _draw_dynamics(rng, n, tau)
    H = np.zeros((T, m, n_pad))
    H[:, :, :n] = rng.standard_normal((T, m, n))
    r_scale = 10.0 ** rng.uniform(-1.0, 1.0) * (1e-6 if tight else 1.0)
    R = np.stack([random_spd(rng, m, cond_max=1e2) for _ in range(T)]) * r_scale
    P0 = np.zeros((n_pad, n_pad))
    P0[:n, :n] = random_spd(rng, n, cond_max=1e2, scale=10.0 ** rng.uniform(-1.0, 1.0))
    m0 = np.zeros(n_pad)
    m0[:n] = rng.standard_normal(n)
    b = np.zeros((T, n_pad))
    b[:, :n] = 0.3 * rng.standard_normal((T, n))
    # The embedding states: independent, unobserved, mean-reverting random walks.
    k = n_pad - n
    if k:
        lam = rng.uniform(0.1, 1.0, k)
        F[:, n:, n:] = np.exp(-lam[None, :] * tau[:, None])[:, :, None] * np.eye(k)
        Q[:, n:, n:] = tau[:, None, None] * np.eye(k)
        P0[n:, n:] = np.eye(k)
    return Arrays(F, _sym(Q), H, _sym(R), b, m0, _sym(P0))


def simulate(rng, a: Arrays, first_step: str, runs: int) -> np.ndarray:
    """``runs`` measurement sequences ``(runs, T, m)`` drawn from the model (well-scaled units)."""
    T, m, n = a.H.shape
    zs = np.empty((runs, T, m))
    chol_P0 = np.linalg.cholesky(a.P0)
    chol_Q, chol_R = np.linalg.cholesky(a.Q), np.linalg.cholesky(a.R)
    for r in range(runs):
        x = a.m0 + chol_P0 @ rng.standard_normal(n)
        for k in range(T):
            if k > 0 or first_step == "predict":
                x = a.F[k] @ x + a.b[k] + chol_Q[k] @ rng.standard_normal(n)
            zs[r, k] = a.H[k] @ x + chol_R[k] @ rng.standard_normal(m)
    return zs


def build_case(spec: Spec, *, runs: int = 1, nan_missing: bool = False, mask: str | None = None) -> Case:
    """The :class:`Case` of ``spec``: arrays, scales, the scaled model, measurements and mask.

    ``runs`` measurement sequences are drawn; with ``nan_missing`` the entries the mask marks
    missing are NaN in ``zs_scaled`` (the library must never read them). ``mask`` overrides
    ``spec.mask``.
    """
    shape = SHAPES[spec.shape]
    rng = np.random.default_rng(spec.seed)
    a = draw_arrays(rng, shape, spec.n, spec.tight)
    T, m = shape.T, shape.m
    zs = simulate(rng, a, shape.first_step, runs)
    kind = spec.mask if mask is None else mask
    p = rng.uniform(0.2, 1.0)  # observation probability: from mostly missing to all observed
    if kind == "none":
        mask_arg, observed = None, np.ones((T, m), bool)
    elif kind == "step":
        mask_arg = rng.random(T) < p
        observed = np.broadcast_to(mask_arg[:, None], (T, m)).copy()
    else:
        mask_arg = rng.random((T, m)) < p
        observed = mask_arg.copy()
    if spec.scaled:
        s = 10.0 ** rng.integers(-3, 4, shape.n_pad).astype(float)
        d = 10.0 ** rng.integers(-3, 4, m).astype(float)
    else:
        s, d = np.ones(shape.n_pad), np.ones(m)
    ss = s[:, None] * s[None, :]
    model = LinearGaussianModel(
        s[None, :, None] * a.F / s[None, None, :],
        _sym(ss[None] * a.Q),
        d[None, :, None] * a.H / s[None, None, :],
        _sym((d[:, None] * d[None, :])[None] * a.R),
        s * a.m0,
        _sym(ss * a.P0),
        transition_offset=s[None, :] * a.b,
    )
    zs_scaled = zs * d
    if nan_missing:
        zs_scaled = np.where(observed[None], zs_scaled, np.nan)
    return Case(spec, shape, a, s, d, model, zs, zs_scaled, mask_arg, observed)


# ---------------------------------------------------------------------------------------------
# Mapping results back to the well-scaled units
# ---------------------------------------------------------------------------------------------


def unscale_mean(case: Case, x) -> np.ndarray:
    """``S⁻¹ x'`` on the last axis."""
    return np.asarray(x, np.float64) / case.state_scale


def unscale_cov(case: Case, P) -> np.ndarray:
    """``S⁻¹ P' S⁻¹`` on the last two axes."""
    s = case.state_scale
    return np.asarray(P, np.float64) / (s[:, None] * s[None, :])


def unscale_meas(case: Case, y) -> np.ndarray:
    """``D⁻¹ y'`` on the last axis (innovations)."""
    return np.asarray(y, np.float64) / case.meas_scale


def unscale_meas_cov(case: Case, S) -> np.ndarray:
    """``D⁻¹ S' D⁻¹`` on the last two axes (innovation covariances)."""
    d = case.meas_scale
    return np.asarray(S, np.float64) / (d[:, None] * d[None, :])


def unscale_log_likelihood(case: Case, ll) -> np.ndarray:
    """``log p(z) = log p(z') + Σ_{observed (k, j)} log d_j`` (the Jacobian of ``z' = D z``)."""
    return np.asarray(ll, np.float64) + float(np.sum(case.observed * np.log(case.meas_scale)))


# ---------------------------------------------------------------------------------------------
# Oracles (NumPy, float64, well-scaled units)
# ---------------------------------------------------------------------------------------------


class Dense(NamedTuple):
    """Marginals of the joint Gaussian of all states conditioned on sets of measurements."""

    filtered_mean: np.ndarray  # (T, n): E[x_k | z_0..z_k]
    filtered_cov: np.ndarray  # (T, n, n)
    predicted_mean: np.ndarray  # (T, n): E[x_k | z_0..z_{k-1}]
    predicted_cov: np.ndarray  # (T, n, n)
    smoothed_mean: np.ndarray  # (T, n): E[x_k | all z]
    smoothed_cov: np.ndarray  # (T, n, n)
    log_likelihood: float  # log N(z_obs; E z_obs, Cov z_obs)


def dense_oracle(a: Arrays, z: np.ndarray, observed: np.ndarray, first_step: str) -> Dense:
    """Batch conditioning of the stacked states ``X = (x_0 … x_{T-1})`` on observed measurements.

    The prior covariance of ``X`` is built block by block from ``F``, ``Q`` and the prior (the same
    joint as ``helpers.dense_solution``, which is checked against it); each marginal is the Schur complement over the observed measurement components of
    steps ``≤ k`` (filtered), ``< k`` (predicted) or all steps (smoothed). No recursion is shared
    with the code under test.
    """
    T, m, n = a.H.shape
    if first_step == "predict":
        x0_mean = a.F[0] @ a.m0 + a.b[0]
        x0_cov = a.F[0] @ a.P0 @ a.F[0].T + a.Q[0]
    else:
        x0_mean, x0_cov = a.m0, a.P0
    mu = np.empty((T, n))
    mu[0] = x0_mean
    for k in range(1, T):
        mu[k] = a.F[k] @ mu[k - 1] + a.b[k]
    # Cov(x_k, x_j) = F_k Cov(x_{k-1}, x_j) for j < k, Cov(x_k, x_k) = F_k Cov(x_{k-1}, x_{k-1}) F_kᵀ + Q_k:
    # the prior of the stacked states block by block (small products, not (T n)² ones: this runs
    # once per example).
    S4 = np.zeros((T, n, T, n))
    S4[0, :, 0, :] = x0_cov
    for k in range(1, T):
        for j in range(k):
            S4[k, :, j, :] = a.F[k] @ S4[k - 1, :, j, :]
            S4[j, :, k, :] = S4[k, :, j, :].T
        S4[k, :, k, :] = _sym(a.F[k] @ S4[k - 1, :, k - 1, :] @ a.F[k].T + a.Q[k])
    Sigma = S4.reshape(T * n, T * n)
    SHt4 = np.einsum("iajb,jmb->iajm", S4, a.H)  # Cov(x_i, z_j) = Cov(x_i, x_j) H_jᵀ
    SHt = SHt4.reshape(T * n, T * m)
    Szz = np.einsum("ila,iajm->iljm", a.H, SHt4).reshape(T * m, T * m)
    Szz = _sym(Szz + scipy.linalg.block_diag(*a.R))  # Cov(Z)
    Hb = scipy.linalg.block_diag(*a.H)
    innov = z.ravel() - Hb @ mu.ravel()
    obs = observed.ravel()
    step_of_row = np.repeat(np.arange(T), m)
    blocks = [slice(k * n, (k + 1) * n) for k in range(T)]

    fm, pm, sm = np.empty((T, n)), np.empty((T, n)), np.empty((T, n))
    fc, pc, sc = np.empty((T, n, n)), np.empty((T, n, n)), np.empty((T, n, n))
    pm[0], pc[0] = mu[0], Sigma[blocks[0], blocks[0]]
    ll = 0.0
    for k in range(T):
        # One factorisation of Cov(Z_rows) for the rows of steps ≤ k: it gives the filtered
        # marginal at k, the predicted one at k + 1 and, at k = T − 1, the smoothed ones.
        rows = obs & (step_of_row <= k)
        targets = list(range(T)) if k == T - 1 else [k] + ([k + 1] if k + 1 < T else [])
        if rows.any():
            cho = scipy.linalg.cho_factor(Szz[np.ix_(rows, rows)], lower=True)
            w = scipy.linalg.cho_solve(cho, innov[rows])
        for j in targets:
            blk = blocks[j]
            if rows.any():
                C = SHt[blk][:, rows]
                mean = mu[j] + C @ w
                cov = _sym(Sigma[blk, blk] - C @ scipy.linalg.cho_solve(cho, C.T))
            else:
                mean, cov = mu[j].copy(), Sigma[blk, blk].copy()
            if j == k:
                fm[k], fc[k] = mean, cov
            if j == k + 1:
                pm[j], pc[j] = mean, cov
            if k == T - 1:
                sm[j], sc[j] = mean, cov
        if k == T - 1 and rows.any():
            logdet = 2.0 * np.sum(np.log(np.diag(cho[0])))
            ll = -0.5 * (innov[rows] @ w + logdet + rows.sum() * np.log(2.0 * np.pi))
    return Dense(fm, fc, pm, pc, sm, sc, float(ll))


class ReducedRows(NamedTuple):
    """The sequential Kalman filter that updates with the observed rows of ``H``, ``R``, ``z`` only."""

    filtered_mean: np.ndarray  # (T, n)
    filtered_cov: np.ndarray  # (T, n, n)
    predicted_mean: np.ndarray  # (T, n)
    predicted_cov: np.ndarray  # (T, n, n)
    innovation: np.ndarray  # (T, m), 0 where missing
    innovation_cov: np.ndarray  # (T, m, m), the observed block; NaN elsewhere (not defined)
    log_likelihood: float


def reduced_row_filter(a: Arrays, z: np.ndarray, observed: np.ndarray, first_step: str) -> ReducedRows:
    """At each step: drop the missing rows of ``H``, ``R``, ``z``; standard update with the rest."""
    T, m, n = a.H.shape
    x, P = a.m0.copy(), a.P0.copy()
    fm, pm = np.empty((T, n)), np.empty((T, n))
    fc, pc = np.empty((T, n, n)), np.empty((T, n, n))
    innov = np.zeros((T, m))
    innov_cov = np.full((T, m, m), np.nan)
    ll = 0.0
    for k in range(T):
        if k > 0 or first_step == "predict":
            x = a.F[k] @ x + a.b[k]
            P = _sym(a.F[k] @ P @ a.F[k].T + a.Q[k])
        pm[k], pc[k] = x, P
        rows = observed[k]
        if rows.any():
            Hk, Rk = a.H[k][rows], a.R[k][np.ix_(rows, rows)]
            y = z[k][rows] - Hk @ x
            S = _sym(Hk @ P @ Hk.T + Rk)
            cho = scipy.linalg.cho_factor(S, lower=True)
            K = scipy.linalg.cho_solve(cho, Hk @ P).T
            x = x + K @ y
            A = np.eye(n) - K @ Hk
            P = _sym(A @ P @ A.T + K @ Rk @ K.T)
            innov[k, rows] = y
            innov_cov[k][np.ix_(rows, rows)] = S
            logdet = 2.0 * np.sum(np.log(np.diag(cho[0])))
            ll += -0.5 * (y @ scipy.linalg.cho_solve(cho, y) + logdet + rows.sum() * np.log(2 * np.pi))
        fm[k], fc[k] = x, P
    return ReducedRows(fm, fc, pm, pc, innov, innov_cov, ll)


# ---------------------------------------------------------------------------------------------
# A linear model the filters can only see through f, h (EKF: Jacobians by jax.jacfwd)
# ---------------------------------------------------------------------------------------------


class OpaqueLinearModel(AbstractStateSpaceModel):
    """``f_k(x) = F_k x + b_k``, ``h_k(x) = H_k x`` as a user-written model (no analytic Jacobians).

    A :class:`~jaxtrack.models.NonlinearGaussianModel` keeps ``f`` and ``h`` as static callables,
    so matrices closed over by them would recompile every example; a subclass with array fields
    (the library's documented way to write a model with parameters) compiles once per shape.
    """

    F: Float[Array, "T n n"]
    Q: Float[Array, "T n n"]
    H: Float[Array, "T m n"]
    R: Float[Array, "T m m"]
    b: Float[Array, "T n"]
    initial_mean: Float[Array, " n"]
    initial_cov: Float[Array, "n n"]
    angle_components: tuple[int, ...] = eqx.field(static=True)

    @classmethod
    def of(cls, model: LinearGaussianModel) -> "OpaqueLinearModel":
        return cls(
            F=model.F, Q=model.Q, H=model.H, R=model.R, b=model.b, initial_mean=model.initial_mean,
            initial_cov=model.initial_cov, angle_components=(),
        )

    def transition(self, x, k):
        return self.F[k] @ x + self.b[k]

    def measurement(self, x, k):
        return self.H[k] @ x

    def process_noise_cov(self, k):
        return self.Q[k]

    def measurement_noise_cov(self, k):
        return self.R[k]

    @property
    def num_steps(self) -> int:
        return self.F.shape[0]


# ---------------------------------------------------------------------------------------------
# Comparisons relative to the size of each quantity
# ---------------------------------------------------------------------------------------------


def assert_moments_close(mean, cov, ref_mean, ref_cov, rtol: float, what: str) -> None:
    """Per-step means and covariances ``(T, n)``, ``(T, n, n)`` against a reference.

    Step ``k``'s covariance entries may differ by ``rtol · max_i P_k[i, i]`` (the largest entry
    of a positive semidefinite matrix is on its diagonal), its mean entries by
    ``rtol · (max|x̂_k| + max_i √P_k[i, i])``: a mean near zero by cancellation is judged against
    its own uncertainty. Raises ``AssertionError`` naming ``what`` and the worst step.
    """
    mean, cov = np.asarray(mean, np.float64), np.asarray(cov, np.float64)
    var = np.max(np.diagonal(ref_cov, axis1=-2, axis2=-1), axis=-1)  # (T,)
    cov_tol = rtol * var
    mean_tol = rtol * (np.max(np.abs(ref_mean), axis=-1) + np.sqrt(var))
    cov_err = np.max(np.abs(cov - ref_cov), axis=(-2, -1))
    mean_err = np.max(np.abs(mean - ref_mean), axis=-1)
    for name, err, tol in (("mean", mean_err, mean_tol), ("cov", cov_err, cov_tol)):
        bad = ~(err <= tol)  # NaN fails
        if bad.any():
            k = int(np.argmax(np.where(bad, err / np.where(tol > 0, tol, 1.0), -np.inf)))
            raise AssertionError(
                f"{what} {name}: step {k} differs by {err[k]:.3g} > tolerance {tol[k]:.3g} "
                f"(rtol {rtol:g}); {int(bad.sum())} of {bad.size} steps off"
            )


def assert_scalar_close(actual, desired, rtol: float, scale: float, what: str) -> None:
    """``|actual − desired| ≤ rtol · max(|desired|, scale, 1)`` (elementwise)."""
    actual, desired = np.asarray(actual, np.float64), np.asarray(desired, np.float64)
    tol = rtol * np.maximum(np.maximum(np.abs(desired), scale), 1.0)
    err = np.abs(actual - desired)
    if not np.all(err <= tol):
        raise AssertionError(f"{what}: {actual} vs {desired} (difference {err}, tolerance {tol})")


def assert_array_close(actual, desired, rtol: float, what: str, *, matrix: bool = False) -> None:
    """Entries compared with ``atol = rtol · max|desired|`` over the last axis (two if ``matrix``).

    The scale is taken per leading index (step, or run and step), so that a large quantity at one
    step does not loosen the comparison at another.
    """
    actual, desired = np.asarray(actual, np.float64), np.asarray(desired, np.float64)
    lead = desired.ndim - (2 if matrix else 1)
    axes = tuple(range(lead, desired.ndim))
    scale = np.max(np.abs(desired), axis=axes, keepdims=True)
    err = np.abs(actual - desired)
    ok = err <= rtol * (np.abs(desired) + scale)
    if not np.all(ok):
        raise AssertionError(
            f"{what}: max difference {np.nanmax(err):.3g}, {int((~ok).sum())} entries beyond "
            f"rtol {rtol:g} relative to their step's scale"
        )


def spd_margin(P: np.ndarray) -> np.ndarray:
    """Smallest eigenvalue of the correlation form ``D^{-1/2} P D^{-1/2}`` (``D = diag P``), per matrix.

    Positive definiteness does not depend on units; the correlation form makes "how far from
    singular" comparable across the 6 decades of scaling (its eigenvalues lie in ``[0, n]``).
    """
    P = np.asarray(P, np.float64)
    d = np.diagonal(P, axis1=-2, axis2=-1)
    if np.any(~(d > 0)):
        return np.full(P.shape[:-2], -np.inf)
    inv = 1.0 / np.sqrt(d)
    corr = P * inv[..., :, None] * inv[..., None, :]
    return np.linalg.eigvalsh(corr)[..., 0]

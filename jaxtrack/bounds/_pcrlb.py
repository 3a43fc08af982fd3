"""The posterior Cramér–Rao bound (PCRLB) of Tichavský, Muravchik & Nehorai (1998) by autodiff.

For the additive-Gaussian models of :mod:`jaxtrack.models`,

.. math::

    x_k = f_k(x_{k-1}) + w_k,\\ w_k \\sim N(0, Q_k), \\qquad z_k = h_k(x_k) + v_k,\\ v_k \\sim N(0, R_k),

the Fisher information ``J_k`` of the state ``x_k`` (the inverse of the lower bound on the mean
squared error matrix of *any* estimator of ``x_k`` from ``z_0, …, z_k``) obeys Tichavský et al.'s
recursion (1998, Proposition 1, eq. (21))

.. math::

    J_k = D^{22}_k - D^{21}_k (J_{k-1} + D^{11}_k)^{-1} D^{12}_k,

with, for additive Gaussian noise (their Sec. III), ``F̃_k = ∂f_k/∂x`` at the true ``x_{k-1}``
and ``H̃_k = ∂h_k/∂x`` at the true ``x_k``,

.. math::

    D^{11}_k = E[F̃_k^T Q_k^{-1} F̃_k],\\quad D^{12}_k = (D^{21}_k)^T = -E[F̃_k]^T Q_k^{-1},\\quad
    D^{22}_k = Q_k^{-1} + E[H̃_k^T R_k^{-1} H̃_k].

**The form computed here.** Write ``G_k = E[F̃_k]`` and ``S_k = E[(F̃_k − G_k)^T Q_k^{-1} (F̃_k − G_k)]``
(the spread of the transition Jacobian over the true trajectories), so that
``D^{11}_k = G_k^T Q_k^{-1} G_k + S_k``. The matrix inversion lemma turns eq. (21) into

.. math::

    J_k = \\bigl(Q_k + G_k (J_{k-1} + S_k)^{-1} G_k^T\\bigr)^{-1} + E[H̃_k^T R_k^{-1} H̃_k],

algebraically the same bound, but one that needs no ``Q_k^{-1}`` when ``S_k = 0`` (always for a
linear transition, whatever the measurement). That is how a **singular** ``Q`` (``Q = 0`` for a
static parameter, noise on some components only) is handled: ``S_k`` is computed with the
pseudo-inverse of ``Q_k``, which is exact when the transition Jacobian varies only within the
range of ``Q_k``; when it varies in ``Q_k``'s null space, ``D^{11}`` is infinite there (no finite
bound) and :func:`pcrlb` raises ``InputError`` naming the model. For a linear-Gaussian model the
recursion is the Kalman filter's covariance recursion in information form, so the bound equals the
Kalman filter's filtered covariance. The bound itself is computed without inverting ``J``:
with ``P_k = Q_k + G_k (J_{k-1} + S_k)^{-1} G_k^T = L L^T`` and ``M_k = E[H̃^T R^{-1} H̃]``,
``J_k^{-1} = L (I + L^T M_k L)^{-1} L^T`` (Cholesky factors: symmetric positive definite by
construction). ``P_k`` must be positive definite (it is unless ``Q_k`` and ``G_k`` are both
singular; the prior ``P_0`` is positive definite by the models' construction).

**Expectations** are Monte Carlo averages over true trajectories drawn exactly as
:func:`jaxtrack.montecarlo.simulate` draws run ``i`` of a study, from ``fold_in(key, i)`` (the
same functions are called), so a bound and a Monte Carlo study with the same key use the same
truths. ``S_k`` is accumulated about the Jacobian along the noise-free nominal trajectory so that
it is exactly 0 for a linear transition (no cancellation).

**Missing measurements.** ``mask[k] = False`` drops the measurement term at step ``k`` (the
sensor reported nothing; P_D = 1 otherwise). With ``detection_probability`` ``P_D < 1`` (no
clutter), the measurement term is multiplied by ``P_D`` — the information-reduction-factor bound
(Hernandez, Farina & Ristic 2004, "PCRLB for tracking in clutter", with IRF ``q = P_D`` without
false alarms), the bound of Stone Soup's ``irf`` argument. Clutter (an IRF below ``P_D``) is not
implemented.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from .._validation import InputError, as_key, check_finite, check_shape, is_concrete
from ..filters._linalg import cholesky, cholesky_and_inverse, matmul
from ..models import AbstractStateSpaceModel
from ..montecarlo._result import MonteCarloResult
from ..montecarlo._simulate import (
    _check_model_values,
    _guard_traced_model,
    _resolve_num_steps,
    _simulate_jit,
    check_detection_probability,
    draw_initial_state,
    noise_factors,
    step_keys,
)

__all__ = ["PosteriorCRB", "pcrlb", "pcrlb_along", "efficiency"]

# Runs per compiled block of the Monte Carlo expectation: large enough to amortise dispatch, small
# enough that a block's Jacobians (block × T × n × n) stay small.
_BLOCK = 256


class PosteriorCRB(eqx.Module):
    """The posterior Cramér–Rao bound per step (Tichavský, Muravchik & Nehorai 1998).

    **Fields:**

    - ``information`` ``(T, n, n)``: the Fisher information ``J_k`` of the state at step ``k``
      (inverse state units squared).
    - ``bound`` ``(T, n, n)``: ``J_k^{-1}``, the lower bound on the mean squared error matrix
      ``E[(x̂_k − x_k)(x̂_k − x_k)^T]`` of any estimator of ``x_k`` from ``z_0, …, z_k`` (state units
      squared; in the sense of positive semidefinite matrices).
    - ``num_runs``: the number of true trajectories averaged over (1 for :func:`pcrlb_along`).
    """

    information: Float[Array, "T n n"]
    bound: Float[Array, "T n n"]
    num_runs: int = eqx.field(static=True)

    def rmse_bound(self, components) -> Float[Array, " T"]:
        """The lower bound on the RMSE of a group of components, ``sqrt(Σ_{i ∈ components} bound[k, i, i])``.

        **Arguments:**

        - ``components``: state indices (e.g. the positions ``(0, 1)``), a sequence of ints.

        **Returns:** ``(T,)``, in the components' units (for the position components of a
        kinematic state: the bound on the root mean squared position error, metres).
        """
        idx = _components("components", components, self.bound.shape[-1])
        diag = jnp.diagonal(self.bound, axis1=-2, axis2=-1)
        return jnp.sqrt(jnp.sum(diag[:, idx], axis=-1))


def _components(name: str, components, n: int) -> np.ndarray:
    try:
        idx = np.asarray(components, dtype=int).reshape(-1)
    except (TypeError, ValueError) as err:
        raise InputError(f"`{name}` must be a sequence of state indices; got {components!r}.") from err
    if idx.size == 0 or np.any(idx < 0) or np.any(idx >= n):
        raise InputError(f"`{name}` must be a non-empty sequence of indices in [0, {n}); got {components!r}.")
    return idx


# --------------------------------------------------------------------------------------------
# per-step pieces


def _pinv_psd(Q: Array) -> tuple[Array, Array]:
    """``(Q⁺, N)``: the pseudo-inverse of a symmetric PSD ``Q`` and the projector onto its null space.

    ``jnp.linalg.pinv`` rather than an eigendecomposition: its derivative is the closed-form one of
    the pseudo-inverse, finite where eigenvalues repeat (``Q = Q_1d ⊗ I`` has every one twice),
    so a bound stays differentiable in τ and ``q``.
    """
    pinv = jnp.linalg.pinv(Q)
    pinv = 0.5 * (pinv + pinv.T)
    null = jnp.eye(Q.shape[-1], dtype=Q.dtype) - pinv @ Q
    return pinv, 0.5 * (null + null.T)


def _measurement_information(model, x, k) -> Array:
    """``H̃ᵀ R⁻¹ H̃`` at the true state ``x`` of step ``k``."""
    H = model.measurement_jacobian(x, k)
    R = model.measurement_noise_cov(k)
    # filters._linalg's factor (written out for m ≤ 4): a LAPACK call per step under vmap costs
    # far more than the arithmetic.
    _, L_inv = cholesky_and_inverse(R)
    A = matmul(L_inv, H)  # L⁻¹ H: AᵀA = Hᵀ R⁻¹ H
    return matmul(A.T, A)


def _nominal_jacobians(model, num_steps: int, first_step) -> Array:
    """The transition Jacobians ``C_k`` along the noise-free trajectory from the prior mean, ``(T, n, n)``.

    The centre about which the spread ``S_k`` is accumulated: for a linear transition every draw's
    Jacobian equals it, so ``S_k`` is exactly 0.
    """

    def step(x_prev, k):
        C = model.transition_jacobian(x_prev, k)
        x = model.transition(x_prev, k)
        if first_step == "update":
            x = jnp.where(k == 0, x_prev, x)
        return x, C

    _, Cs = jax.lax.scan(step, model.initial_mean, jnp.arange(num_steps))
    return Cs


def _noise_terms(model, num_steps: int):
    """``(Q⁺_k, N_k)`` per step ``(T, n, n)`` each (the process noise's pseudo-inverse and null projector)."""
    return jax.vmap(lambda k: _pinv_psd(model.process_noise_cov(k)))(jnp.arange(num_steps))


def _run_terms(model, x_prevs, xs, Cs, Qpinv, Qnull):
    """One run's per-step terms: ``F̃``, ``(F̃ − C)ᵀQ⁺(F̃ − C)``, ``H̃ᵀR⁻¹H̃``, ``max |N(F̃ − C)|``.

    ``x_prevs`` ``(T, n)``: the state each transition starts from (``x_{k-1}``); ``xs`` ``(T, n)``.
    """
    ks = jnp.arange(xs.shape[0])

    def per_step(x_prev, x, k, C, Qp, N):
        F = model.transition_jacobian(x_prev, k)
        dev = F - C
        spread = dev.T @ Qp @ dev
        in_null = jnp.max(jnp.abs(N @ dev))
        return F, spread, _measurement_information(model, x, k), in_null

    return jax.vmap(per_step)(x_prevs, xs, ks, Cs, Qpinv, Qnull)


@eqx.filter_jit
def _block_sums(model, key, start, num_valid, block, num_steps, first_step, Cs, Qpinv, Qnull):
    """Sums over runs ``start, …, start + block − 1`` (the first ``num_valid``) of the per-step terms."""
    runs = start + jnp.arange(block)
    weights = (jnp.arange(block) < num_valid).astype(model.initial_mean.dtype)

    def one_run(i):
        run_key = jax.random.fold_in(key, i)
        # The very draw of simulate(model, fold_in(key, i), T): same function, same key.
        xs = _simulate_jit(model, run_key, num_steps, first_step, None).states
        # x_{-1} under "predict" is the prior draw (simulate's first draw); under "update" the
        # transition into step 0 is not used, and the prior draw (= x_0) is a harmless stand-in.
        x_first = draw_initial_state(model, noise_factors(model, num_steps), step_keys(run_key)[0])
        x_prevs = jnp.concatenate([x_first[None], xs[:-1]], axis=0)
        return _run_terms(model, x_prevs, xs, Cs, Qpinv, Qnull)

    F, spread, info, in_null = jax.vmap(one_run)(runs)
    w3 = weights[:, None, None, None]
    return (jnp.sum(w3 * F, 0), jnp.sum(w3 * spread, 0), jnp.sum(w3 * info, 0),
            jnp.max(weights[:, None] * in_null, 0))


def _recursion(P0, G, S, M, Q, update_first: bool):
    """The bound recursion over steps (see the module docstring).

    ``G``, ``M``, ``Q``: ``(T, n, n)`` (``M`` already masked / scaled by ``P_D``); ``S``: ``(T, n, n)``
    or None for no Jacobian spread (one given truth).
    **Returns:** ``(information, bound)``, ``(T, n, n)`` each.
    """
    n = P0.shape[-1]
    eye = jnp.eye(n, dtype=P0.dtype)

    def sym(A):
        return 0.5 * (A + jnp.swapaxes(A, -1, -2))

    def inverse_plus(L, A):
        """``(L⁻ᵀL⁻¹ + A)⁻¹ = W Wᵀ`` with ``W = L C⁻ᵀ``, ``C Cᵀ = I + Lᵀ A L`` (``A`` PSD)."""
        _, C_inv = cholesky_and_inverse(eye + matmul(matmul(L.T, A), L))
        W = matmul(L, C_inv.T)
        return matmul(W, W.T)

    def step(B_prev, inputs):
        k, G_k, S_k, M_k, Q_k = inputs
        # (J_{k-1} + S_k)⁻¹ with B = J_{k-1}⁻¹ = L Lᵀ: no inverse of J, and exactly B when S = 0.
        # Cholesky factors (written out for n ≤ 4, filters._linalg) keep every matrix symmetric
        # positive definite by construction and cost no LAPACK call per step.
        A_inv = B_prev if S_k is None else inverse_plus(cholesky(B_prev), S_k)
        P = sym(Q_k + matmul(matmul(G_k, A_inv), G_k.T))
        if update_first:
            # The prior is on x_0 itself: no transition into step 0.
            P = jnp.where(k == 0, B_prev, P)
        B = inverse_plus(cholesky(P), M_k)  # (P⁻¹ + M)⁻¹
        return B, (P, B)

    T = G.shape[0]
    _, (P, B) = jax.lax.scan(step, P0, (jnp.arange(T), G, S, M, Q))
    # The information J_k = P_k⁻¹ + M_k, one batched inverse outside the sequential scan.
    return sym(jnp.linalg.inv(P) + M), B


def _per_step(model, num_steps, fn) -> Array:
    return jax.vmap(fn)(jnp.arange(num_steps))


def _measurement_weights(mask, detection_probability, num_steps, dtype) -> Array:
    """Per-step multipliers of the measurement term: ``mask[k] · P_D[k]``, ``(T,)``."""
    w = np.ones((num_steps,))
    if mask is not None:
        try:
            m = np.asarray(mask)
        except (TypeError, jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError) as err:
            raise InputError("`mask` must be a concrete boolean array of shape (T,).") from err
        if m.dtype != bool:
            raise InputError(f"`mask` must be boolean (True = measured); got dtype {m.dtype}.")
        if m.shape != (num_steps,):
            raise InputError(f"`mask` must have shape ({num_steps},) (one flag per step); got shape {m.shape}.")
        w = w * m
    if detection_probability is not None:
        w = w * check_detection_probability(detection_probability, num_steps)
    return jnp.asarray(w, dtype)


def _check_common(model, first_step) -> None:
    if not isinstance(model, AbstractStateSpaceModel):
        raise InputError(f"`model` must be a jaxtrack state-space model; got {type(model).__name__}.")
    if first_step not in ("update", "predict"):
        raise InputError(f"`first_step` must be 'update' or 'predict'; got {first_step!r}.")
    model.check_functions()


@eqx.filter_jit
def _setup(model, num_steps, first_step):
    """``(C, Q⁺, N)`` per step: nominal transition Jacobians, the pseudo-inverse of ``Q`` and its null projector."""
    Qpinv, Qnull = _noise_terms(model, num_steps)
    return _nominal_jacobians(model, num_steps, first_step), Qpinv, Qnull


@eqx.filter_jit
def _finish(model, num_steps, first_step, num_runs, weights, Cs, Qpinv, sum_F, sum_spread, sum_info):
    """The expectations from the run sums, then the recursion: ``(information, bound)``."""
    G = sum_F / num_runs
    dev = G - Cs
    # S = E[(F̃−C)ᵀQ⁺(F̃−C)] − (G−C)ᵀQ⁺(G−C) = E[(F̃−G)ᵀQ⁺(F̃−G)].
    S = sum_spread / num_runs - jnp.einsum("kji,kjl,klm->kim", dev, Qpinv, dev)
    S = 0.5 * (S + jnp.swapaxes(S, -1, -2))
    M = sum_info / num_runs * weights[:, None, None]
    Q = _per_step(model, num_steps, model.process_noise_cov).astype(G.dtype)
    return _recursion(model.initial_cov, G, S, M, Q, first_step == "update")


@eqx.filter_jit
def _along(model, X, weights, first_step):
    """:func:`pcrlb_along`'s computation: ``(information, bound)``."""
    T = X.shape[0]
    x_prevs = jnp.concatenate([model.initial_mean[None], X[:-1]], axis=0)
    ks = jnp.arange(T)
    G = jax.vmap(model.transition_jacobian)(x_prevs, ks)
    M = jax.vmap(lambda x, k: _measurement_information(model, x, k))(X, ks) * weights[:, None, None]
    Q = _per_step(model, T, model.process_noise_cov).astype(X.dtype)
    return _recursion(model.initial_cov, G, None, M, Q, first_step == "update")


def pcrlb(
    model: AbstractStateSpaceModel,
    key: PRNGKeyArray | ArrayLike,  # an int seed too (as_key); ArrayLike so the suite's type checker lets as_key answer
    num_runs: int,
    num_steps: int | None = None,
    *,
    mask: ArrayLike | None = None,
    detection_probability: float | ArrayLike | None = None,
    first_step: str = "update",
) -> PosteriorCRB:
    r"""The posterior Cramér–Rao bound of ``model``, expectations by Monte Carlo over true trajectories.

    Tichavský, Muravchik & Nehorai (1998), Proposition 1, eq. (21), for additive Gaussian noise
    (their Sec. III), in the form $J_k = \big(Q_k + G_k (J_{k-1} + S_k)^{-1} G_kᵀ\big)^{-1} + E[H̃ᵀ R^{-1} H̃]$
    derived in :mod:`jaxtrack.bounds._pcrlb` (the same bound; it allows a singular ``Q``). The
    Jacobians are the model's ``transition_jacobian`` / ``measurement_jacobian`` (``jax.jacfwd``
    of ``transition`` / ``measurement`` unless the model supplies analytic ones), at the true
    states of ``num_runs`` trajectories: run ``i`` is ``simulate(model, fold_in(key, i), T,
    first_step=first_step).states``, so a Monte Carlo study with the same key runs on the same
    truths. Runs are processed in blocks of 256 (memory ``O(256 · T · n²)``).

    The prior is ``J = P_0⁻¹`` on ``x_0`` under ``first_step="update"`` (plus the measurement
    term of step 0), on ``x_{-1}`` under ``"predict"`` (``F̃_0``, ``Q_0`` take it to ``x_0``).

    **Arguments:**

    - ``model``: an additive-Gaussian state-space model (``R_k`` positive definite).
    - ``key``: a PRNG key or an int seed; ``num_runs``: the number of true trajectories (≥ 1; for a linear
      model the Jacobians do not depend on the state and 1 run gives the exact bound).
    - ``num_steps``: ``T`` (defaults to the model's per-step length).
    - ``mask``: optional boolean ``(T,)``, True where a measurement is taken; False drops the
      measurement term of that step (missing measurement).
    - ``detection_probability``: optional ``P_D`` in ``(0, 1]``, scalar or ``(T,)``: the
      measurement term is multiplied by ``P_D`` (information-reduction factor without clutter,
      Hernandez, Farina & Ristic 2004).
    - ``first_step``: ``"update"`` (default) or ``"predict"``, as in
      :func:`~jaxtrack.filters.run_filter`.

    **Returns:** a :class:`PosteriorCRB` with ``information`` and ``bound`` ``(T, n, n)``.

    **Raises:** ``InputError`` for a bad model, key count, ``num_steps``, ``mask``,
    ``detection_probability`` or ``first_step``; and, for a concrete model whose ``Q_k`` is
    singular while the transition Jacobian varies across the true trajectories in ``Q_k``'s null
    space (``D¹¹`` infinite: no finite bound in that form), naming the model and the step.
    """
    key = as_key(key)
    _check_common(model, first_step)
    _check_model_values(model)  # the prior the runs are drawn from (concrete values; traced: below)
    T = _resolve_num_steps(model, num_steps)
    if not isinstance(num_runs, (int, np.integer)) or isinstance(num_runs, bool) or num_runs < 1:
        raise InputError(f"`num_runs` must be a positive int; got {num_runs!r}.")
    dtype = model.initial_mean.dtype
    weights = _measurement_weights(mask, detection_probability, T, dtype)

    Cs, Qpinv, Qnull = _setup(model, T, first_step)
    n = model.state_dim
    sum_F = jnp.zeros((T, n, n), dtype)
    sum_spread = jnp.zeros((T, n, n), dtype)
    sum_info = jnp.zeros((T, n, n), dtype)
    max_null = jnp.zeros((T,), dtype)
    # Blocks in run order, summed in that order: the result does not depend on anything but the
    # key and num_runs.
    # A study smaller than a block is one block of its own size (no padded runs).
    block = min(_BLOCK, int(num_runs))
    for start in range(0, int(num_runs), block):
        valid = min(block, int(num_runs) - start)
        dF, dS, dM, dN = _block_sums(model, key, jnp.asarray(start, jnp.uint32), jnp.asarray(valid), block,
                                     T, first_step, Cs, Qpinv, Qnull)
        sum_F, sum_spread, sum_info = sum_F + dF, sum_spread + dS, sum_info + dM
        max_null = jnp.maximum(max_null, dN)
    _check_null_space(model, max_null, Cs, first_step)
    J, B = _finish(model, T, first_step, jnp.asarray(num_runs, dtype), weights, Cs, Qpinv, sum_F, sum_spread,
                   sum_info)
    return _guard_traced_model(model, PosteriorCRB(information=J, bound=B, num_runs=int(num_runs)))


def _check_null_space(model, max_null, Cs, first_step) -> None:
    """Raise ``InputError`` if the transition Jacobian varies in the null space of a singular ``Q``."""
    if not (is_concrete(max_null) and is_concrete(Cs)):
        return  # traced: the caller takes responsibility (documented)
    dev = np.asarray(max_null)
    scale = 1.0 + np.max(np.abs(np.asarray(Cs)), axis=(-2, -1))
    bad = dev > 1e-9 * scale
    if first_step == "update":
        bad[0] = False  # no transition into step 0
    if np.any(bad):
        k = int(np.argmax(bad))
        raise InputError(
            f"`model` ({type(model).__name__}): the process-noise covariance Q is singular at step {k} and the "
            "transition Jacobian varies across true trajectories in its null space, so the Fisher information "
            "term D11 = E[F̃ᵀQ⁻¹F̃] is infinite there (Tichavský et al. 1998); give Q full rank in those "
            "directions (e.g. a small regularising noise) or make the transition linear in them."
        )


def pcrlb_along(
    model: AbstractStateSpaceModel,
    truth_states: ArrayLike,
    *,
    mask: ArrayLike | None = None,
    detection_probability: float | ArrayLike | None = None,
    first_step: str = "update",
) -> PosteriorCRB:
    """The bound recursion linearised along ONE given true trajectory (no expectation).

    The recursion of :func:`pcrlb` with ``F̃_k``, ``H̃_k`` evaluated at the given states instead
    of averaged over trajectories (``S_k = 0``): ``J_k = (Q_k + F̃_k J_{k-1}⁻¹ F̃_kᵀ)⁻¹ +
    H̃_kᵀR_k⁻¹H̃_k`` — what Stone Soup's ``PCRBMetric`` computes (Tichavský et al. 1998, eq. (21)
    for one trajectory; Hernandez, Ristic & Farina 2005). It is the conditional bound of that
    trajectory, not the PCRLB (which averages over truths) unless the model is linear.

    **Arguments:**

    - ``model``: an additive-Gaussian state-space model.
    - ``truth_states``: the true states ``x_0, …, x_{T-1}``, ``(T, n)``.
    - ``mask``, ``detection_probability``: as in :func:`pcrlb` (Stone Soup's PCRBMetric has no
      measurement at its first state: pass ``mask`` with ``mask[0] = False``; its ``irf`` is
      ``detection_probability``).
    - ``first_step``: ``"update"`` (prior on ``x_0``) or ``"predict"`` (prior on ``x_{-1}``; the
      Jacobian of the transition into step 0 is then taken at the prior mean, since ``x_{-1}`` is
      not among the given states).

    **Returns:** a :class:`PosteriorCRB` with ``num_runs = 1``.

    **Raises:** ``InputError`` for a bad model, states, ``mask``, ``detection_probability`` or
    ``first_step``.
    """
    _check_common(model, first_step)
    dtype = model.initial_mean.dtype
    X = jnp.asarray(truth_states)
    n = model.state_dim
    check_shape("truth_states", X, [(None, n)])
    check_finite("truth_states", X)
    X = X.astype(dtype)
    T = X.shape[0]
    if T < 1:
        raise InputError("`truth_states` must hold at least one state.")
    T = _resolve_num_steps(model, T)
    weights = _measurement_weights(mask, detection_probability, T, dtype)
    J, B = _along(model, X, weights, first_step)
    return PosteriorCRB(information=J, bound=B, num_runs=1)


def efficiency(
    result: MonteCarloResult,
    bound: PosteriorCRB,
    components,
    result_components=None,
) -> Float[Array, " T"]:
    """An estimator's RMSE relative to the PCRLB's RMSE bound, per step.

    ``sqrt(Σ_i mse[k, i]) / sqrt(Σ_i bound[k, i, i])``: at least 1 for an unbiased estimator
    (Tichavský et al. 1998, eq. (2): the MSE matrix dominates ``J_k⁻¹``), up to the Monte Carlo
    error of the RMSE; 1 for an efficient one (a Kalman filter on a linear-Gaussian model).

    **Arguments:**

    - ``result``: a :class:`~jaxtrack.montecarlo.MonteCarloResult` over the same ``T`` steps (and
      for a meaningful comparison the same truth model).
    - ``bound``: a :class:`PosteriorCRB`.
    - ``components``: the state indices of the bound to compare (e.g. the positions ``(0, 1)``).
    - ``result_components``: the corresponding columns of ``result.mse`` in the same order;
      defaults to ``components`` (right when the Monte Carlo scored the whole truth state).

    **Returns:** ``(T,)``, dimensionless.

    **Raises:** ``InputError`` for indices out of range, unequal numbers of components or a
    different number of steps.
    """
    if not isinstance(result, MonteCarloResult):
        raise InputError(f"`result` must be a MonteCarloResult; got {type(result).__name__}.")
    if not isinstance(bound, PosteriorCRB):
        raise InputError(f"`bound` must be a PosteriorCRB; got {type(bound).__name__}.")
    idx = _components("components", components, bound.bound.shape[-1])
    ridx = idx if result_components is None else _components(
        "result_components", result_components, result.mse.shape[-1])
    if ridx.size != idx.size or np.any(ridx >= result.mse.shape[-1]):
        raise InputError(
            f"`result_components` must name {idx.size} of the {result.mse.shape[-1]} columns of `result.mse`; "
            f"got {ridx.tolist()}.")
    if result.mse.shape[0] != bound.bound.shape[0]:
        raise InputError(
            f"`result` has {result.mse.shape[0]} steps but `bound` has {bound.bound.shape[0]}.")
    rmse = jnp.sqrt(jnp.sum(result.mse[:, ridx], axis=-1))
    return rmse / bound.rmse_bound(idx)

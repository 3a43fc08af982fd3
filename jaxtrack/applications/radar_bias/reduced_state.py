"""Sec. 3 general case: the reduced-state bias filter (42)–(69) as the library's consider filter.

The bias λ is not estimated: the filter subtracts its mean and designs its gain through the
error sensitivity ``D = ∂ε/∂λ``. That is the consider (Schmidt–Kalman) filter on the augmented
model ``[x; λ]`` of :func:`~.scenario.reduced_state_model`
(:class:`jaxtrack.filters.ConsiderKalmanFilter`): its gain is (69) (inverse on the right, spec
A16), its Joseph update with zero λ rows is (67), and its cross-covariance is ``D Λ``. Every
recursion here is :func:`jaxtrack.filters.run_filter` or the data-free
:func:`jaxtrack.filters.covariance_pass` of that filter; the paper's split
``S = M + D Λ D'`` (V25) comes from two more passes of the same step with the same gains:
a zero bias block gives ``M`` (58)–(59), a unit one gives ``D`` (60)–(63) (the cross-covariance
recursion is linear in the bias block, so with ``Λ = I`` it is ``D`` itself, also when Λ is
singular).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from ..._validation import InputError, check_shape
from ...filters import ConsiderKalmanFilter, condition_linearized, consider_gain, covariance_pass, run_filter
from ...models import LinearGaussianModel
from ...montecarlo import simulate


class ReducedStateHistory(eqx.Module):
    """Per-step output of :func:`reduced_state_filter`, steps ``k = 1 … T`` (row ``k−1``).

    - ``filtered_mean`` ``(T, n)``: x̂(k|k) (``None`` for the data-free recursion).
    - ``gain`` ``(T, n, q)``: K(k) (69).
    - ``predicted_noise_cov`` ``(T, n, n)``: M(k|k−1) (58).
    - ``predicted_total_cov`` ``(T, n, n)``: S(k|k−1) (64).
    - ``innovation_cov`` ``(T, q, q)``: the bracket of (69).
    - ``noise_cov`` ``(T, n, n)``: M(k|k) (59), the noise-only error covariance.
    - ``sensitivity`` ``(T, n, p)``: D(k|k) (63), the error sensitivity ∂ε/∂λ.
    - ``total_cov`` ``(T, n, n)``: S(k|k) = M + D Λ D' (= (67), V25).
    - ``total_cov_eq67`` ``(T, n, n)``: S(k|k) by (67) itself (the consider filter's Joseph update).
    """

    filtered_mean: Float[Array, "T n"] | None
    gain: Float[Array, "T n q"]
    predicted_noise_cov: Float[Array, "T n n"]
    predicted_total_cov: Float[Array, "T n n"]
    innovation_cov: Float[Array, "T q q"]
    noise_cov: Float[Array, "T n n"]
    sensitivity: Float[Array, "T n p"]
    total_cov: Float[Array, "T n n"]
    total_cov_eq67: Float[Array, "T n n"]


def _with_bias_cov(model: LinearGaussianModel, num_estimated: int, bias_cov: Array) -> LinearGaussianModel:
    n = num_estimated
    cov = model.initial_cov.at[n:, n:].set(bias_cov).at[:n, n:].set(0.0).at[n:, :n].set(0.0)
    return eqx.tree_at(lambda m: m.initial_cov, model, cov)


def _check_model(model, num_estimated):
    if not isinstance(model, LinearGaussianModel):
        raise InputError(f"`model` must be the LinearGaussianModel of reduced_state_model; got {type(model).__name__}.")
    ConsiderKalmanFilter(num_estimated).check_model(model)
    if num_estimated >= model.state_dim:
        raise InputError(f"`num_estimated` = {num_estimated} leaves no bias state in a model of dimension {model.state_dim}.")


def _check_gain(gain, num_steps, n, q, dtype):
    if gain is None:
        return None
    gain = jnp.asarray(gain, dtype=dtype)
    check_shape("gain", gain, [(n, q), (num_steps, n, q)])
    return jnp.broadcast_to(gain, (num_steps, n, q))


@eqx.filter_jit
def _covariance_jit(model, num_estimated, gains, num_steps):
    n, dtype = num_estimated, model.initial_cov.dtype
    p = model.state_dim - n
    observed = jnp.ones((num_steps, model.meas_dim), bool)
    pred, filt, gain, innov = covariance_pass(ConsiderKalmanFilter(n, gains), model, observed, "predict")
    gain = gain[:, :n]
    noise = _with_bias_cov(model, n, jnp.zeros((p, p), dtype))
    pred_m, filt_m, _, _ = covariance_pass(ConsiderKalmanFilter(n, gain), noise, observed, "predict")
    unit = _with_bias_cov(model, n, jnp.eye(p, dtype=dtype))
    _, filt_d, _, _ = covariance_pass(ConsiderKalmanFilter(n, gain), unit, observed, "predict")
    m, d = filt_m[:, :n, :n], filt_d[:, :n, n:]
    lam = model.initial_cov[n:, n:]
    total = m + jnp.einsum("kip,pq,kjq->kij", d, lam, d)
    return ReducedStateHistory(None, gain, pred_m[:, :n, :n], pred[:, :n, :n], innov, m, d, total, filt[:, :n, :n])


def reduced_state_covariance(model: LinearGaussianModel, num_estimated: int, num_steps: int, *,
                             gain: ArrayLike | None = None) -> ReducedStateHistory:
    """The data-free part of :func:`reduced_state_filter`: gains, M, D and S for ``num_steps`` steps.

    Per step k → k+1 (spec §3.4): ``M⁻ = Φ M Φ' + Q``; ``S⁻ = M⁻ + Φ D Λ D' Φ'``; K from (69) (or
    ``gain``); ``M = L̃ M⁻ L̃' + K N K'`` with ``L̃ = I − K H̃`` (spec A24); ``D = L̃ Φ D − K G``;
    ``S = M + D Λ D'`` — all as :func:`jaxtrack.filters.covariance_pass` of
    :class:`~jaxtrack.filters.ConsiderKalmanFilter` (see the module docstring).

    **Arguments:** ``model`` from :func:`~.scenario.reduced_state_model` (prior on x(0));
    ``num_estimated`` ``n`` (2 for the α-β models); ``num_steps`` ``T``; ``gain``: optional fixed
    gain ``(n, q)`` or ``(T, n, q)`` (e.g. an α-β filter), which replaces (69) while M, D, S stay
    the exact covariances of that filter.

    **Returns:** a :class:`ReducedStateHistory` (``filtered_mean`` None). Differentiable in every
    array of the model and in ``gain``.
    """
    if isinstance(num_steps, bool) or not isinstance(num_steps, int) or num_steps < 1:
        raise InputError(f"`num_steps` must be a positive int; got {num_steps!r}.")
    _check_model(model, num_estimated)
    gains = _check_gain(gain, num_steps, num_estimated, model.meas_dim, model.initial_cov.dtype)
    return _covariance_jit(model, num_estimated, gains, num_steps)


def reduced_state_filter(model: LinearGaussianModel, num_estimated: int, measurements: ArrayLike, *,
                         gain: ArrayLike | None = None) -> ReducedStateHistory:
    """Run the reduced-state bias filter (42)–(69) over measurements z(1) … z(T).

    ``x̂ = x̂⁻ + K(z − H x̂⁻ − W u(x̂⁻, λ̄))`` (45) is the consider filter's mean update on the
    augmented model (its λ estimate stays λ̄), by :func:`jaxtrack.filters.run_filter` with
    ``first_step="predict"`` (prior on x(0), first measurement z(1)); the covariances are those
    of :func:`reduced_state_covariance`.

    **Arguments:** ``model``, ``num_estimated``, ``gain`` as in :func:`reduced_state_covariance`;
    ``measurements`` ``(T, q)``.

    **Returns:** a :class:`ReducedStateHistory`.
    """
    _check_model(model, num_estimated)
    z = jnp.asarray(measurements, dtype=model.initial_cov.dtype)
    check_shape("measurements", z, [(None, model.meas_dim)])
    hist = reduced_state_covariance(model, num_estimated, z.shape[0], gain=gain)
    fixed = None if gain is None else hist.gain
    result = run_filter(ConsiderKalmanFilter(num_estimated, fixed), model, z, first_step="predict", save="mean")
    return eqx.tree_at(lambda h: h.filtered_mean, hist, result.filtered_mean[:, :num_estimated],
                       is_leaf=lambda x: x is None)


def _one_step_prior(pred_total_cov, pred_sensitivity, bias_cov, H_tilde, G):
    cross = pred_sensitivity @ bias_cov
    cov = jnp.block([[pred_total_cov, cross], [cross.T, bias_cov]])
    return cov, jnp.concatenate([H_tilde, G], axis=1)


def reduced_state_gain(pred_total_cov, pred_sensitivity, H_tilde, G, N, bias_cov) -> Array:
    """The bias-optimised gain (69), with the inverse on the **right** (spec A16).

    ``K = (S⁻ H̃' + X) (H̃ S⁻ H̃' + Ñ + H̃ X + X' H̃')⁻¹`` with ``X = Φ D(k|k) Λ G'``, ``Ñ = N + G Λ G'``
    (66): :func:`jaxtrack.filters.consider_gain` on the augmented prior
    ``[[S⁻, Φ D Λ], [Λ D' Φ', Λ]]`` and ``[H̃, G]``.

    **Arguments:** ``pred_total_cov`` S⁻ ``(n, n)``; ``pred_sensitivity`` ``Φ D(k|k)`` ``(n, p)``
    (spec A15: not called D(k+1|k)); ``H_tilde`` H̃ ``(q, n)``; ``G`` = W ∂u/∂λ ``(q, p)``;
    ``N`` ``(q, q)``; ``bias_cov`` Λ ``(p, p)``.

    **Returns:** K ``(n, q)``.
    """
    cov, H = _one_step_prior(pred_total_cov, pred_sensitivity, bias_cov, H_tilde, G)
    return consider_gain(cov, H, N, pred_total_cov.shape[0])


def filtered_total_cov(gain, pred_total_cov, pred_sensitivity, H_tilde, G, N, bias_cov) -> Array:
    """Total error covariance after the update for any gain K (67).

    ``S(k+1|k+1) = L̃ S⁻ L̃' + K Ñ K' − L̃ Φ D Λ G' K' − K G Λ D' Φ' L̃'`` with ``L̃ = I − K H̃``: the
    estimated block of :func:`jaxtrack.filters.condition_linearized` (Joseph) with the gain
    ``[K; 0]`` on the augmented prior of :func:`reduced_state_gain`.

    **Arguments:** ``gain`` K ``(n, q)``, the rest as in :func:`reduced_state_gain`.
    **Returns:** ``(n, n)``.
    """
    cov, H = _one_step_prior(pred_total_cov, pred_sensitivity, bias_cov, H_tilde, G)
    n, q = gain.shape
    padded = jnp.concatenate([gain, jnp.zeros((cov.shape[0] - n, q), gain.dtype)])
    post = condition_linearized(jnp.zeros(cov.shape[0], cov.dtype), cov, jnp.zeros(q, cov.dtype), H, N,
                                jnp.ones(q, bool), padded)
    return post.cov[:n, :n]


class BiasedTrajectory(eqx.Module):
    """One realisation: ``states`` x(1…T) ``(T, n)``, ``measurements`` z(1…T) ``(T, q)`` and the
    bias λ ``(p,)`` drawn once for the run."""

    states: Float[Array, "T n"]
    measurements: Float[Array, "T q"]
    bias: Float[Array, " p"]


def simulate_biased(model: LinearGaussianModel, num_estimated: int, key: PRNGKeyArray, num_steps: int,
                    bias: ArrayLike | None = None) -> BiasedTrajectory:
    """Simulate one realisation with :func:`jaxtrack.montecarlo.simulate` on the augmented model.

    x(0) ~ N(x̂(0|0), P0) and λ ~ N(λ̄, Λ) are drawn **once** from the prior (spec A23); with
    ``bias`` given, λ is that value (differentiable). ``W u(x(k), λ)`` is in every measurement.

    **Arguments:**

    - ``model``: the augmented model, state ``[x, λ]`` with ``n + p`` components.
    - ``num_estimated``: ``n``, the estimated states (the last ``p`` are the bias λ).
    - ``key``: a PRNG key; ``num_steps``: ``T``.
    - ``bias``: optional λ, ``(p,)``, in the measurement's units (default: drawn from the prior).

    **Returns:** a :class:`BiasedTrajectory`.
    """
    return _simulate_jit(model, num_estimated, key, num_steps, bias)


@eqx.filter_jit
def _simulate_jit(model, num_estimated, key, num_steps, bias):
    n = num_estimated
    if bias is not None:
        p = model.state_dim - n
        bias = jnp.asarray(bias, model.initial_mean.dtype)
        model = _with_bias_cov(model, n, jnp.zeros((p, p), model.initial_cov.dtype))
        model = eqx.tree_at(lambda m: m.initial_mean, model, model.initial_mean.at[n:].set(bias))
    traj = simulate(model, key, num_steps, first_step="predict")
    return BiasedTrajectory(traj.states[:, :n], traj.measurements, traj.states[0, n:])


class EstimationErrors(eqx.Module):
    """``errors`` ε(k|k) = x(k) − x̂(k|k), k = 1 … T, ``(T, n)`` of one realisation and its ``bias`` λ ``(p,)``."""

    errors: Float[Array, "T n"]
    bias: Float[Array, " p"]


def estimation_errors(model: LinearGaussianModel, num_estimated: int, key: PRNGKeyArray, num_steps: int,
                      bias: ArrayLike | None = None, gains: Array | None = None) -> EstimationErrors:
    """Errors of the reduced-state filter on one :func:`simulate_biased` realisation.

    The filter is :class:`~jaxtrack.filters.ConsiderKalmanFilter` through
    :func:`jaxtrack.filters.run_filter` (optimal gains (69), or ``gains`` ``(T, n, q)``).
    Differentiable in ``bias``: ``jax.jacfwd`` gives ∂ε(k|k)/∂λ, which equals D(k|k) (V28).

    **Arguments:**

    - ``model``: the augmented model, state ``[x, λ]`` with ``n + p`` components.
    - ``num_estimated``: ``n``, the estimated states.
    - ``key``: a PRNG key; ``num_steps``: ``T``.
    - ``bias``: optional λ, ``(p,)`` (default: drawn from the prior).
    - ``gains``: optional filter gains ``(T, n, q)`` (default: the optimal gains).

    **Returns:** an :class:`EstimationErrors`.
    """
    return _errors_jit(model, ConsiderKalmanFilter(num_estimated, gains), key, num_steps, bias)


@eqx.filter_jit
def _errors_jit(model, filter, key, num_steps, bias):
    run = _simulate_jit(model, filter.num_estimated, key, num_steps, bias)
    est = run_filter(filter, model, run.measurements, first_step="predict", save="mean", throw=False)
    return EstimationErrors(run.states - est.filtered_mean[:, :filter.num_estimated], run.bias)


def terminal_error_moments(key: PRNGKeyArray, args) -> tuple[Array, Array, Array]:
    """One Monte Carlo run for :func:`~.montecarlo.bias_monte_carlo`: ``(ε, ε ε', ε Δλ')`` at the last step.

    ``args = (model, filter)`` with a :class:`~jaxtrack.filters.ConsiderKalmanFilter` holding the
    gains ``(T, n, q)`` (their length is the number of steps).

    **Arguments:**

    - ``key``: the run's PRNG key.
    - ``args``: ``(model, filter)``, as above.

    **Returns:** ``(ε, ε ε', ε Δλ')`` at step ``T``: shapes ``(n,)``, ``(n, n)``, ``(n, p)``, in the state's
    units (``Δλ = λ − λ̄``).
    """
    model, filter = args
    n = filter.num_estimated
    run = _errors_jit(model, filter, key, filter.gain.shape[0], None)
    eps = run.errors[-1]
    dlam = run.bias - model.initial_mean[n:]
    return eps, jnp.outer(eps, eps), jnp.outer(eps, dlam)

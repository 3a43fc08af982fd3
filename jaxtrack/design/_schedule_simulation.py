"""Monte Carlo of a sensor schedule (:func:`simulate_sensor_schedule`): the targets drawn from
their priors, each look measured, each target's Kalman filter updated by the looks it gets, so a
schedule's tracking accuracy (GOSPA) can be scored on draws shared between schedules."""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError
from ..filters._updates import condition_linearized
from ._sensor_management import SensorSchedulingProblem, _as_schedule, _check_problem, _positive_int

__all__ = ["ScheduleSimulation", "simulate_sensor_schedule"]


class ScheduleSimulation(NamedTuple):
    """What :func:`simulate_sensor_schedule` returns (``R`` runs, ``T`` scans, ``N`` targets, ``m``
    measured components, in the measurement's units: m for positions).

    - ``truth`` ``(R, T, N, m)``: each target's measured part ``H_i x_i`` at each scan;
    - ``estimates`` ``(R, T, N, m)``: the Kalman filter's ``H_i x̂^{(i)}_{k/k}`` under the schedule;
    - ``errors`` (property) ``estimates − truth``.
    """

    truth: Float[Array, "R T N m"]
    estimates: Float[Array, "R T N m"]

    @property
    def errors(self) -> Float[Array, "R T N m"]:
        return self.estimates - self.truth


def _simulate_one(problem: SensorSchedulingProblem, schedule: Array, means: Array, key: Array):
    F, Q, H, R, P0 = (problem.transition_matrix, problem.process_noise_cov, problem.measurement_matrix,
                      problem.measurement_noise_cov, problem.initial_cov)
    N, n = P0.shape[:2]
    S, m = R.shape[:2]
    k0, k_steps = jax.random.split(key)
    x = means + jnp.einsum("iab,ib->ia", jnp.linalg.cholesky(P0), jax.random.normal(k0, (N, n), P0.dtype))
    chol_Q, chol_R = jnp.linalg.cholesky(Q), jnp.linalg.cholesky(R)
    observed = jnp.ones((m,), bool)

    def scan(carry, inputs):
        x, xhat, P = carry
        looks, key = inputs
        kw, kv = jax.random.split(key)
        x = jnp.einsum("iab,ib->ia", F, x) + jnp.einsum("iab,ib->ia", chol_Q, jax.random.normal(kw, (N, n), x.dtype))
        xhat = jnp.einsum("iab,ib->ia", F, xhat)
        P = jnp.einsum("iab,ibc,idc->iad", F, P, F) + Q
        # Sensor s's noise at this scan is drawn whichever target it looks at (common random numbers
        # across schedules run from the same key).
        noise = jnp.einsum("sab,sb->sa", chol_R, jax.random.normal(kv, (S, m), x.dtype))
        for s in range(S):  # sensors in order, as the cost's recursion applies them
            i = looks[s]
            z = H[i] @ x[i] + noise[s]
            post = condition_linearized(xhat[i], P[i], z - H[i] @ xhat[i], H[i], R[s], observed)  # Joseph form
            xhat, P = xhat.at[i].set(post.mean), P.at[i].set(post.cov)
        measured = lambda v: jnp.einsum("iab,ib->ia", H, v)  # noqa: E731
        return (x, xhat, P), (measured(x), measured(xhat))

    keys = jax.random.split(k_steps, problem.num_scans)
    _, (truth, est) = jax.lax.scan(scan, (x, means, P0), (schedule, keys))
    return truth, est


@eqx.filter_jit
def _simulate(problem, schedule, means, keys):
    return jax.vmap(lambda k: _simulate_one(problem, schedule, means, k))(keys)


def simulate_sensor_schedule(problem: SensorSchedulingProblem, schedule: ArrayLike, key: Array, num_runs: int, *,
                             separation: float = 1.0e4) -> ScheduleSimulation:
    r"""Monte Carlo of a schedule: draw the targets and the looks' measurements, run each target's
    Kalman filter on the looks it gets, return the truth and the estimates at every scan.

    Target ``i`` starts at ``x_0 ~ N(μ_i, P_0^{(i)})`` one scan period before the first look and
    moves by ``x_k = F_i x_{k−1} + w_k``, ``w_k ~ N(0, Q_i)``; at scan ``k`` sensor ``s`` measures
    the target ``schedule[k, s]`` looks at, ``z = H_i x_k + v``, ``v ~ N(0, R_s)``; each target's
    filter starts at ``(μ_i, P_0^{(i)})`` (its known prior) and is updated by the looks in sensor
    order, the recursion :func:`schedule_cost` prices. The means ``μ_i`` put the targets' measured
    parts ``separation`` apart on the first measured axis (``μ_i = i·separation`` there, 0
    elsewhere), far beyond their errors, so that a metric's optimal assignment (GOSPA) pairs each
    estimate with its own target; the covariances, hence ``J``, do not depend on the means.

    For linear-Gaussian models the filter is unbiased with error covariance ``P^{(i)}_{k/k}``, so
    ``E Σ_i ‖H_i(x̂_i − x_i)‖² = Σ_i tr(H_iᵀH_i P^{(i)}_{k/k})``: with the default ``weight``
    ``L = H_1ᵀH_1`` and unit ``target_weights``, ``J = Σ_k E[GOSPA_k²]`` for GOSPA of order
    ``p = 2`` (``α = 2``) with a cut-off beyond every error and no missed or false targets — the
    cost the design minimises is the expected squared GOSPA summed over the scans.

    **Arguments:**

    - ``problem``: the :class:`SensorSchedulingProblem`; ``schedule``: integer ``(T,)`` for one
      sensor or ``(T, S)``, entries in ``[0, N)``.
    - ``key``: a JAX PRNG key; run ``r`` uses ``jax.random.fold_in(key, r)``, so two schedules
      simulated from the same key share the targets' paths and the sensors' noise draws (common
      random numbers: their difference has a smaller variance than either).
    - ``num_runs``: ``R``, a positive int; ``separation``: finite, > 0, in the measurement's units.

    **Returns:** a :class:`ScheduleSimulation` (``truth``, ``estimates``: ``(R, T, N, m)``).

    **Raises:** :class:`~jaxtrack.InputError` naming ``problem``, ``schedule`` (as
    :func:`schedule_cost`), ``num_runs`` or ``separation``.
    """
    problem = _check_problem(problem)
    schedule = _as_schedule(problem, schedule)
    num_runs = _positive_int("num_runs", num_runs)
    if isinstance(separation, bool) or not isinstance(separation, (int, float, np.integer, np.floating)) \
            or not np.isfinite(separation) or separation <= 0:
        raise InputError(f"`separation` must be a finite number > 0; got {separation!r}.")
    dtype = problem.initial_cov.dtype
    N, n = problem.initial_cov.shape[:2]
    # μ_i: i·separation on the state component the first target's H measures first.
    axis = int(np.argmax(np.abs(np.asarray(problem.measurement_matrix[0, 0]))))
    means = jnp.zeros((N, n), dtype).at[:, axis].set(separation * jnp.arange(N, dtype=dtype))
    keys = jax.vmap(lambda r: jax.random.fold_in(key, r))(jnp.arange(num_runs))
    truth, est = _simulate(problem, schedule, means, keys)
    return ScheduleSimulation(truth, est)

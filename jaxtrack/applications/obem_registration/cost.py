"""Computational cost of AAM (14 states) versus OBEM (8 states) (abstract; spec §2.7, V14)."""

from __future__ import annotations

import math
import time

import jax
import jax.numpy as jnp

from ..._validation import InputError
from ...filters import KalmanFilter
from .estimators import filter_means, prior_cov, registration_model
from .frames import obem_columns
from .scenario import RegistrationInputs

__all__ = ["update_multiply_adds", "cubic_cost_ratio", "update_flops", "measure_filter_times"]


def update_multiply_adds(n: int, m: int = 3, *, joseph: bool = False) -> int:
    """Multiply–adds of one KF update, ``2mn² + 2m²n`` (+ ``2n³`` for the Joseph form) (spec §2.7).

    **Arguments:** ``n`` states, ``m`` measurement components. **Returns:** an int.
    """
    return 2 * m * n * n + 2 * m * m * n + (2 * n**3 if joseph else 0)


def cubic_cost_ratio(n_small: int = 8, n_large: int = 14) -> float:
    """``(n_small/n_large)³``, the O(n³) cost ratio behind "about 80% reduction" (spec §6 item 24 [R]).

    **Arguments:** the two state dimensions. **Returns:** the ratio (float).
    """
    return (n_small / n_large) ** 3


def _update(model, mean, cov, z):
    post = KalmanFilter().update(model, mean, cov, z, jnp.ones(3, bool), jnp.asarray(0))
    return post.mean, post.cov


def update_flops(n: int) -> float:
    """XLA's FLOP count of one compiled registration update with ``n`` states (V14).

    Counts :meth:`jaxtrack.filters.KalmanFilter.update` (Joseph form) on :func:`registration_model`
    with a 3-row measurement, as compiled for this machine
    (``jax.jit(...).lower(...).compile().cost_analysis()``).

    **Arguments:** ``n`` states. **Returns:** the FLOP count.
    """
    if not isinstance(n, int) or n < 1:
        raise InputError(f"`n` must be a positive int; got {n!r}.")
    model = registration_model(jnp.ones((3, n)), jnp.eye(3), jnp.eye(n))
    cost = jax.jit(_update).lower(model, jnp.zeros(n), jnp.eye(n), jnp.ones(3)).compile().cost_analysis()
    cost = cost[0] if isinstance(cost, (list, tuple)) else cost
    return float(cost["flops"])


@jax.jit
def _batched_filter(z, h, r, p0):
    return jax.vmap(filter_means, in_axes=(0, 0, 0, None))(z, h, r, p0)


def measure_filter_times(inputs: RegistrationInputs, num_runs: int = 100, repeats: int = 7) -> tuple[float, float]:
    """Wall-clock seconds of the jitted, ``vmap``-ed AAM and OBEM filters over ``num_runs`` runs (V14).

    ``inputs`` are one run's :class:`RegistrationInputs` (from :func:`registration_inputs`),
    replicated ``num_runs`` times: the arithmetic does not depend on the values. Only the filters
    are timed, best of ``repeats`` after a warm-up call. Small jitted kernels carry fixed
    overheads (loop control, memory traffic), so the ratio is not expected to reach the O(n³)
    0.19; it is reported, never asserted.

    **Arguments:**

    - ``inputs``: one run's :class:`RegistrationInputs`.
    - ``num_runs``: runs per batched call (default 100); ``repeats``: timed calls per filter (default 7).

    **Returns:** ``(t_aam, t_obem)``, s.

    **Raises:** ``InputError`` for ``inputs`` that are not :class:`RegistrationInputs` or a
    non-positive ``num_runs``.
    """
    if not isinstance(inputs, RegistrationInputs):
        raise InputError(f"`inputs` must be RegistrationInputs; got {type(inputs).__name__}.")
    if not isinstance(num_runs, int) or num_runs < 1:
        raise InputError(f"`num_runs` must be a positive int; got {num_runs!r}.")
    z, h, r = (jnp.broadcast_to(a, (num_runs,) + a.shape) for a in (inputs.Z, inputs.H, inputs.R))
    times = []
    for hm, p in ((h, prior_cov("aam")), (obem_columns(h), prior_cov("obem"))):
        jax.block_until_ready(_batched_filter(z, hm, r, p))
        best = math.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(_batched_filter(z, hm, r, p))
            best = min(best, time.perf_counter() - t0)
        times.append(best)
    return times[0], times[1]

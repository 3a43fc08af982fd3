"""Bearings-only TMA analysis: the stacked measurement matrix of §2 and Appendix A, the error
transition and initial-range sensitivity of Appendix C, track errors and their statistics.

The batch estimation formulas (eqs. 30–34, 52–65) and the observability analysis (A-1…A-4) are
the library's :mod:`jaxtrack.estimation`; this module builds their inputs from bearings.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._validation import InputError, check_shape
from ...models import constant_velocity_transition, pseudolinear_measurement_row, wrap_angle
from .estimators import initial_relative_state, track_solution
from .scenario import Scenario


def stacked_measurement_matrix(measurement_rows: ArrayLike, sample_period: ArrayLike, k: int) -> Array:
    """``A(k)`` of eq. (22): rows ``H(i) Φ(i, k)`` for ``i = k, k−1, …, 1`` (newest first, eq. 17).

    **Arguments:** ``measurement_rows`` ``(≥k, 4)``, row ``j`` is ``H(j+1)``; ``sample_period`` s;
    ``k`` the number of rows. Row ``H(i)Φ(i,k)`` is ``[h₁, h₂, (i−k)t_s h₁, (i−k)t_s h₂]`` (A-4).

    **Returns:** ``(k, 4)``; analyse it with :func:`jaxtrack.estimation.observability`.
    """
    H = jnp.asarray(measurement_rows)
    H = H.astype(jnp.result_type(H, float))
    check_shape("measurement_rows", H, [(None, 4)])
    if not 1 <= k <= H.shape[0]:
        raise InputError(f"`k` must lie in 1..{H.shape[0]}; got {k}.")
    rows = H[:k][::-1]
    dt = (jnp.arange(k, 0, -1, dtype=H.dtype) - k) * jnp.asarray(sample_period, H.dtype)
    return jnp.concatenate([rows[:, :2], dt[:, None] * rows[:, :2]], axis=1)


def error_transition(gain: ArrayLike, measurement_rows: ArrayLike, sample_period: ArrayLike) -> Array:
    """``φ(k, 0)`` for ``k = 0..K`` (eq. 63b, C-1): ``φ(k+1, k) = [I − K(k+1)H(k+1)] Φ(k+1, k)``.

    **Arguments:** ``gain`` ``(K, 4)`` and ``measurement_rows`` ``(K, 4)`` as returned/used by the
    filter (:attr:`PseudoLinearEstimate.gain`); ``sample_period`` s.

    **Returns:** ``(K+1, 4, 4)`` with ``φ(0, 0) = I``. By (C-14) ``φ(k,0) = [I − Ã#A] Φ(k,0)``.
    """
    K = jnp.asarray(gain)
    K = K.astype(jnp.result_type(K, float))
    H = jnp.asarray(measurement_rows, K.dtype)
    check_shape("gain", K, [(None, 4)])
    check_shape("measurement_rows", H, [K.shape])
    phi = constant_velocity_transition(sample_period, dtype=K.dtype)
    eye = jnp.eye(4, dtype=K.dtype)
    steps = (eye[None] - K[:, :, None] * H[:, None, :]) @ phi[None]
    # Cumulative product φ(k,0) = φ(k,k−1)…φ(1,0), later factors on the left.
    phis = jax.lax.associative_scan(lambda earlier, later: later @ earlier, steps)
    return jnp.concatenate([eye[None], phis], axis=0)


def initial_range_sensitivity(bearings: ArrayLike, gain: ArrayLike, sample_period: ArrayLike) -> Array:
    """Analytic ``∂x̂_R(k|k)/∂r̂_s(0) = b_k = φ(k,0)[sin β_m(0), cos β_m(0), 0, 0]'`` (spec §3.5 item 1).

    The Table 2 estimate is exactly ``x̂_R(k|k) = r̂_s(0) b_k + a_k`` with ``a_k`` the estimate for
    ``r̂_s(0) = 0``, because ``K`` and ``P_N`` do not depend on the state.

    **Arguments:** ``bearings`` ``(K+1,)`` rad; ``gain`` ``(K, 4)`` from
    :func:`normalized_pseudolinear_filter`; ``sample_period`` s. **Returns:** ``(K+1, 4)`` (1, 1/s).
    """
    b = jnp.asarray(bearings)
    b = b.astype(jnp.result_type(b, float))
    phis = error_transition(gain, pseudolinear_measurement_row(b[1:]), sample_period)
    return phis @ initial_relative_state(b[0], jnp.ones((), b.dtype))


def los_velocity_variances(scenario: Scenario, normalized_cov: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """``P_N`` velocity variance along and across the true line of sight at each sample (V26).

    **Arguments:** ``normalized_cov`` ``(K+1, 4, 4)``. **Returns:** ``(along, across)``, each ``(K+1,)`` 1/s².
    """
    b = np.asarray(scenario.bearings)
    P = np.asarray(normalized_cov)[:, 2:, 2:]
    los = np.stack([np.sin(b), np.cos(b)], axis=1)
    cross = np.stack([np.cos(b), -np.sin(b)], axis=1)
    return np.einsum("ki,kij,kj->k", los, P, los), np.einsum("ki,kij,kj->k", cross, P, cross)


class TrackErrors(eqx.Module):
    """Estimate minus truth per sample: ``range`` (m), ``course`` (deg, wrapped to (−180, 180]),
    ``speed`` (m/s). Shapes follow the estimates (``(..., K+1)``)."""

    range: Float[Array, "... K1"]
    course: Float[Array, "... K1"]
    speed: Float[Array, "... K1"]


def track_errors(relative_estimate: ArrayLike, scenario: Scenario) -> TrackErrors:
    """Range, course and speed errors of relative-state estimates ``(..., K+1, 4)`` (A17).

    **Arguments:**

    - ``relative_estimate``: relative target states ``[x, y, ẋ, ẏ]``, ``(..., K+1, 4)``, m and m/s.
    - ``scenario``: the :class:`Scenario` (the truth).

    **Returns:** :class:`TrackErrors`.
    """
    est = track_solution(relative_estimate, scenario.observer[:, 2:])

    def minus(estimate, truth):
        return estimate - jnp.broadcast_to(truth, estimate.shape)

    return TrackErrors(
        minus(est.range, scenario.slant_range),
        jnp.degrees(wrap_angle(minus(est.course, scenario.target_course))),
        minus(est.speed, scenario.target_speed),
    )


class ErrorStatistics(eqx.Module):
    """Across-run statistics per sample (``(…, K+1)``): mean and rms of the range error (m),
    rms course error (deg), rms and mean speed error (m/s), and the standard error of the mean
    range error (m)."""

    mean_range: np.ndarray
    rms_range: np.ndarray
    rms_course: np.ndarray
    rms_speed: np.ndarray
    mean_speed: np.ndarray
    range_sem: np.ndarray


def error_statistics(estimates: ArrayLike, scenario: Scenario) -> ErrorStatistics:
    """Statistics over the leading (run) axis of ``estimates`` ``(N, ..., K+1, 4)``.

    **Arguments:**

    - ``estimates``: relative-state estimates, ``(N, ..., K+1, 4)``, m and m/s.
    - ``scenario``: the :class:`Scenario` (the truth).

    **Returns:** :class:`ErrorStatistics` with shapes ``(..., K+1)`` (``range_sem`` needs N ≥ 2).
    """
    err = track_errors(estimates, scenario)
    r, c, s = (np.asarray(e) for e in (err.range, err.course, err.speed))
    n = r.shape[0]
    return ErrorStatistics(
        r.mean(0), np.sqrt((r**2).mean(0)), np.sqrt((c**2).mean(0)), np.sqrt((s**2).mean(0)), s.mean(0),
        r.std(0, ddof=1) / math.sqrt(n),
    )


def sample_index(scenario: Scenario, t: float) -> int:
    """Index ``k`` of the sample at time ``t`` (s).

    **Arguments:**

    - ``scenario``: the :class:`Scenario`; ``t``: the time (s), a sample instant.

    **Returns:** ``k``, a Python int.

    **Raises:** ``InputError`` if no sample lies at ``t``.
    """
    idx = np.flatnonzero(np.abs(np.asarray(scenario.times) - t) < 1e-9)
    if idx.size != 1:
        raise InputError(f"no sample at t = {t} s (samples every {float(scenario.sample_period):g} s).")
    return int(idx[0])

"""The Sec. III-E scenario of Ho (1968): the 1/s² plant, its segment schedules and covariance histories.

The 1/s² plant in feet, position measured with σ = 100 ft, 1-g or 10-g plant noise, 5 s split into
five 1-s segments with ``counts[i]`` equally spaced samples each (``specs/ho-sensitivity.md`` §4.1:
Q literal in τ, samples at segment ends with the prior on the first sample). The numerics are
:func:`jaxtrack.models.ho_plant` and :func:`jaxtrack.covariance.covariance_recursion`.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from ...covariance import CovarianceHistory, covariance_recursion
from ..._validation import InputError
from ...models import LinearGaussianModel, ho_plant, sample_times, segment_schedule
from ...sensitivity import adjoint

UNIFORM = (10, 10, 10, 10, 10)  # Fig. 7 curve a
COARSE = (8, 8, 8, 8, 8)  # Fig. 7 curve b
HO_RULE_1G = (10, 5, 5, 10, 10)  # Fig. 7 curve c: 10 points removed from segments 2 and 3
HO_RULE_10G = (5, 5, 10, 10, 10)  # Fig. 10 curve c
SMOOTHED_R_COEFF = 1e3  # Example 2: R = 10³/τ ft² (eq. 87)
POSITION = np.diag([1.0, 0.0])  # L_T/T: J = P_T(1,1), the terminal position variance
# Sec. IV Ex. 1 input (eq. 136): the paper's P*(t = 1 s) of the 1-g (10,…) filter, in ft units
SEC4_P = np.array([[3422.0, 5380.0], [5380.0, 11973.0]])


def measurement_var(taus, smoothed: bool):
    """``R_k`` in ft²: 10⁴, or Example 2's presmoothed ``10³/τ_k`` (eq. 87) when ``smoothed``.

    **Arguments:**

    - ``taus``: the sampling periods ``τ_k`` (s), scalar or ``(T,)``.
    - ``smoothed``: use Example 2's presmoothed variance.

    **Returns:** ``R_k`` (ft²): the shape of ``taus`` when ``smoothed``, else the Python float 10⁴.
    """
    return SMOOTHED_R_COEFF / taus if smoothed else 1e4


def sample_index(times, t: float, name: str = "t") -> int:
    """Index of the sample whose time is ``t`` seconds (to 1e-9 s) among ``times`` ``(T,)`` s.

    **Arguments:**

    - ``times``: the sample times, ``(T,)``, s; ``t``: the time sought (s).
    - ``name``: the argument name for the error message (default ``"t"``).

    **Returns:** an int. **Raises:** :class:`~jaxtrack.InputError` naming ``name`` when no sample
    is at ``t``.
    """
    hits = np.flatnonzero(np.abs(np.asarray(times) - t) < 1e-9)
    if hits.size != 1:
        raise InputError(f"`{name}` = {t!r} s is not a sample time of the scheme (samples at {np.asarray(times)[:3]} … s).")
    return int(hits[0])


def scenario(counts: Sequence[int], g: float = 1.0, *, smoothed: bool = False) -> tuple[LinearGaussianModel, jnp.ndarray]:
    """The Sec. III-E model for a segment scheme.

    **Arguments:** ``counts`` samples per 1-s segment ``(S,)``; ``g`` plant-noise level in g;
    ``smoothed=True`` is Example 2 (presmoothed data, ``R_k = 10³/τ_k`` ft², eq. 87).

    **Returns:** ``(model, taus)``: the :class:`~jaxtrack.models.LinearGaussianModel` and the
    per-step periods ``(Σ counts,)`` in seconds.
    """
    taus = segment_schedule(tuple(counts))
    return ho_plant(taus, g=g, measurement_var=measurement_var(taus, smoothed)), taus


def history(counts: Sequence[int], g: float = 1.0, *, smoothed: bool = False) -> tuple[CovarianceHistory, np.ndarray]:
    """Covariance history of the optimal filter and the sample times for a scheme.

    **Arguments:** as :func:`scenario`.

    **Returns:** ``(history, times)``: :class:`~jaxtrack.covariance.CovarianceHistory` (ft units)
    and the sample times ``(T,)`` in seconds.
    """
    model, taus = scenario(counts, g, smoothed=smoothed)
    return covariance_recursion(model), np.asarray(sample_times(taus))


def terminal_position_variance(counts: Sequence[int], g: float = 1.0, *, smoothed: bool = False) -> float:
    """``P_{T/T}(1,1)`` in ft² at the sample at 5.0 s (the paper's J with L_T = diag(1, 0)).

    **Arguments:** as :func:`scenario`. **Returns:** a float, ft².
    """
    hist, _ = history(counts, g, smoothed=smoothed)
    return float(hist.filtered_cov[-1, 0, 0])


def covariance_at(counts: Sequence[int], g: float, t: float, *, smoothed: bool = False) -> np.ndarray:
    """``P_{k/k}`` at the sample whose time is ``t`` seconds (to 1e-9 s).

    **Arguments:** as :func:`scenario`, plus ``t`` in seconds. **Returns:** ``(2, 2)`` (ft², ft²/s, ft²/s²).
    """
    hist, times = history(counts, g, smoothed=smoothed)
    return np.asarray(hist.filtered_cov[sample_index(times, t)])


def integer_second_curve(counts: Sequence[int], g: float = 1.0, *, smoothed: bool = False) -> np.ndarray:
    """``P(1,1)`` at t = 1, 2, 3, 4, 5 s (the rows of the spec's Fig. 7 and Fig. 10 tables).

    **Arguments:** as :func:`scenario`. **Returns:** ``(5,)``, ft².
    """
    return np.array([covariance_at(counts, g, float(t), smoothed=smoothed)[0, 0] for t in range(1, 6)])


def segment_model_fn(counts: Sequence[int], g: float = 1.0, *, smoothed: bool = False):
    """``segment_taus -> model`` for a scheme: one τ_i per segment, repeated over its samples.

    **Arguments:** as :func:`scenario`. **Returns:** a function ``(S,) seconds -> LinearGaussianModel``.
    """
    counts = tuple(int(c) for c in counts)

    def model_fn(segment_taus):
        taus = jnp.repeat(segment_taus, jnp.asarray(counts), total_repeat_length=sum(counts))
        return ho_plant(taus, g=g, measurement_var=measurement_var(taus, smoothed))

    return model_fn


def adjoint_history(counts: Sequence[int] = UNIFORM, g: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Adjoint matrices (eq. (43)) for ``J = P_T(1,1)`` and the sample times (Figs. 9, 12).

    **Arguments:** as :func:`scenario`.

    **Returns:** ``(L_{k/k}, times)``: ``(T, 2, 2)`` (ft² of J per unit of P) and ``(T,)`` seconds.
    """
    model, taus = scenario(counts, g)
    return np.asarray(adjoint(model, POSITION).filtered), np.asarray(sample_times(taus))

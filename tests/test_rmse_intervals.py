"""time_averaged_rmse and time_averaged_rmse_ratio: coverage of their delta-method intervals.

Data with a known answer: e_ik = (σ_k z_ik)² with z_i· an AR(1) sequence over steps (ρ = 0.9:
steps strongly dependent within a run, as in a filter), so E e_ik = σ_k² and the time-averaged
RMSE is exactly mean_k σ_k. Coverage over 400 independent repetitions must be 95% within
±0.04 (binomial SE 0.011; the delta method's O(1/M) bias at M = 300 is far below that).
"""

from __future__ import annotations

import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.montecarlo import time_averaged_rmse, time_averaged_rmse_ratio

M, T, REPS = 300, 30, 400
SIGMA = np.linspace(1.0, 3.0, T)


def _ar1(rng, shape, rho=0.9):
    z = np.empty(shape)
    z[..., 0] = rng.standard_normal(shape[:-1])
    for k in range(1, shape[-1]):
        z[..., k] = rho * z[..., k - 1] + np.sqrt(1 - rho**2) * rng.standard_normal(shape[:-1])
    return z


def test_time_averaged_rmse_interval_covers_at_its_confidence():
    rng = np.random.default_rng(11)
    truth = SIGMA.mean()
    z = _ar1(rng, (REPS, M, T))
    hits = [(lambda iv: iv.lower <= truth <= iv.upper)(time_averaged_rmse((SIGMA * z[r]) ** 2))
            for r in range(REPS)]
    assert 0.91 <= np.mean(hits) <= 0.99, np.mean(hits)


def test_paired_ratio_interval_covers_and_is_narrow():
    """a = σ(0.8 z + 0.3 w), b = σ z on the same runs: true ratio √0.73. The paired interval
    covers at 95% ± 0.04 and is narrower than the ratio of two unpaired intervals would be."""
    rng = np.random.default_rng(12)
    truth = np.sqrt(0.73)
    z, w = _ar1(rng, (REPS, M, T)), _ar1(rng, (REPS, M, T))
    hits, widths = [], []
    for r in range(REPS):
        b = (SIGMA * z[r]) ** 2
        a = (SIGMA * (0.8 * z[r] + 0.3 * w[r])) ** 2
        iv = time_averaged_rmse_ratio(a, b)
        hits.append(iv.lower <= truth <= iv.upper)
        widths.append(iv.upper - iv.lower)
    assert 0.91 <= np.mean(hits) <= 0.99, np.mean(hits)
    ia, ib = time_averaged_rmse(a), time_averaged_rmse(b)
    unpaired = (ia.upper - ia.lower) / ib.value + ia.value * (ib.upper - ib.lower) / ib.value**2
    assert np.mean(widths) < 0.7 * unpaired


def test_bad_input():
    with pytest.raises(InputError, match="M ≥ 2"):
        time_averaged_rmse(np.ones((1, 5)))
    with pytest.raises(InputError, match="non-negative"):
        time_averaged_rmse(-np.ones((3, 5)))
    with pytest.raises(InputError, match="reference_squared_error"):
        time_averaged_rmse_ratio(np.ones((3, 5)), np.ones((3, 4)))
    with pytest.raises(InputError, match="confidence"):
        time_averaged_rmse(np.ones((3, 5)), confidence=1.5)

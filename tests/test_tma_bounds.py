"""Bearings-only TMA: the PCRLB of each geometry against the EKF's and the PLKF's Monte Carlo MSE.

Acceptance (issue 21): on each geometry the EKF's Monte Carlo MSE is not below the PCRLB beyond Monte
Carlo error. Stated test, per step ``k`` (all 49 samples) of the position MSE (trace, m²):
``mse_k ≥ B_k − z · sqrt(s.e.(mse_k)² + sd(B_k)²)`` with ``z = 3.5`` (one-sided; 2 estimators × 147
comparisons at a family-wise level < 1% by Bonferroni), where ``s.e.(mse_k)`` is the per-run spread
/ √N and ``sd(B_k)`` is the Monte Carlo error of the bound itself (the spread of four independent
300-truth bounds: the PCRLB's expectation is a Monte Carlo average too). Truths are drawn from the
bound's prior (the Bayesian bound holds for any estimator there; see ``bearings_tma.bounds``); the
bound ``B`` and the Monte Carlo use the same 300 truths (CI size; ``reproduce tma`` uses 2000).
"""

import jax
import numpy as np
import pytest

from jaxtrack.applications.bearings_tma import bounds as tb
from jaxtrack.applications.bearings_tma import figure_bounds
from jaxtrack.applications.bearings_tma import geometry
from jaxtrack.bounds import pcrlb, pcrlb_along

# Runtime-bound (300-run particle-filter and EKF Monte Carlos): XLA's default level, not the
# suite's -O0 (tests/conftest.py): 38.2 -> 29.0 CPU-s, cold cache, one process. The particle-filter
# notebook reuses these programs and runs at the same level (tests/test_notebooks.py).
pytestmark = pytest.mark.xla_optimized

RUNS = 300  # CI size; the reproduction uses 2000


@pytest.fixture(scope="module")
def comparisons():
    return {name: tb.bound_comparison(name, jax.random.key(11), RUNS) for name in ("R1", "R2", "R3")}


def _bound_spread(name):
    """sd over four independent keys of the 300-truth position bound (trace, m²), per step."""
    model = tb.bound_model(geometry(name))
    b = [np.asarray(pcrlb(model, jax.random.key(100 + i), RUNS).bound) for i in range(4)]
    return np.std([x[:, 0, 0] + x[:, 1, 1] for x in b], axis=0, ddof=1)


@pytest.mark.parametrize("name", ["R1", "R2", "R3"])
def test_ekf_mse_not_below_pcrlb(comparisons, name):
    c = comparisons[name]
    assert float(c.ekf_ok) == 1.0
    sd_b = _bound_spread(name)
    b = np.asarray(c.position_bound)
    for mse, se in ((c.ekf_mse, c.ekf_se_mean), (c.plkf_mse, c.plkf_se_mean)):
        mse, se = np.asarray(mse), np.asarray(se)
        assert np.all(mse >= b - 3.5 * np.sqrt(se**2 + sd_b**2)), np.min(mse / b)
    # Informative: the bound is not trivially small (the EKF is within 3× of it at the end on R1/R2).
    eff = np.asarray(c.efficiency("ekf"))
    assert eff.min() >= 0.95
    if name != "R3":
        assert eff[-1] < 3.0


def test_bound_monte_carlo_error_small():
    s = geometry("R3")  # the geometry with the widest spread of truths' information
    model = tb.bound_model(s)
    a = np.asarray(pcrlb(model, jax.random.key(0), RUNS).rmse_bound((0, 1)))
    b = np.asarray(pcrlb(model, jax.random.key(1), RUNS).rmse_bound((0, 1)))
    # Measured: at most 7% on R3 (truths passing close to the observer carry much information).
    assert np.max(np.abs(a / b - 1)) < 0.15


def test_bayesian_bound_below_bound_along_nominal_truth():
    # Jensen: E[J(x)] ≥ J(x̄) in the information ordering is not guaranteed pointwise, but with no
    # plant noise the averaged information is better conditioned; what must hold is that both are
    # positive and finite and that at k = 0 both are bounded by the prior (250 m per axis).
    s = geometry("R1")
    model = tb.bound_model(s)
    bayes = np.asarray(pcrlb(model, jax.random.key(0), RUNS).rmse_bound((0, 1)))
    along = np.asarray(pcrlb_along(model, s.relative).rmse_bound((0, 1)))
    prior = np.sqrt(2) * tb.PRIOR_POSITION_STD
    assert np.all(np.isfinite(bayes)) and np.all(bayes > 0)
    assert bayes[0] <= prior + 1e-9 and along[0] <= prior + 1e-9
    assert bayes[-1] < along[-1]


def test_table_mentions_extra_and_every_geometry(comparisons):
    text = tb.bound_table(list(comparisons.values()))
    assert text.startswith("extra (not in the paper): PCRLB vs Monte Carlo RMSE")
    for name in ("R1", "R2", "R3"):
        assert f"\n{name:>8}" in text


@pytest.mark.slow
@pytest.mark.parametrize("name", ["R1", "R2", "R3"])
def test_ekf_mse_not_below_pcrlb_2000_runs(name):
    c = tb.bound_comparison(name, jax.random.key(12), 2000)
    b, sd_b = np.asarray(c.position_bound), _bound_spread(name) / np.sqrt(2000 / RUNS)
    for mse, se in ((c.ekf_mse, c.ekf_se_mean), (c.plkf_mse, c.plkf_se_mean)):
        mse, se = np.asarray(mse), np.asarray(se)
        assert np.all(mse >= b - 3.5 * np.sqrt(se**2 + sd_b**2))


PF_PARTICLES = 1000


def test_particle_filter_is_efficient_where_the_ekf_is_not():
    """Issue 34: the regularised particle filter (``bounds.particle_filter``: bootstrap, the
    bound's own prior, Musso et al.'s move, since the model has no plant noise) on R1's truths.

    Where the EKF is inefficient (240 s, end of leg 1: EKF RMSE 12.9× the PCRLB) the particle
    filter is at 1.84× the PCRLB, and that factor is the bound's own slack, not the filter's: the
    PCRLB averages the Fisher information over truths before inverting it, E[J]⁻¹, which is below
    the mean of the per-truth bounds E[J(x)⁻¹] (Jensen; no plant noise keeps each truth's
    information apart) by 1.70× at 240 s and 2.01× at 960 s (R3: 4.6× at 960 s). So "PF RMSE /
    PCRLB ≤ 1.1" (the issue's wording) cannot be met by any estimator whose MSE is near the
    per-truth bounds; it is tested against the mean per-truth bound (``pcrlb_along`` of each
    truth) instead. Measured, 300 runs, N = 1000: PF / per-truth bound 1.08 at 240 s, at most 1.26
    over the 49 steps (N = 2000, 200 runs: 1.06 and 1.17); the Monte Carlo error of the ratio is
    about ±0.05 (1σ)."""
    name, key = "R1", jax.random.key(11)
    c = tb.bound_comparison(name, key, RUNS, particles=PF_PARTICLES)
    per_truth_bound = np.asarray(tb.mean_per_truth_bound(name, key, RUNS))
    k240 = int(np.argmin(np.abs(np.asarray(c.times) - 240.0)))
    pf, ekf = np.asarray(c.efficiency("pf")), np.asarray(c.efficiency("ekf"))
    tight = np.sqrt(np.asarray(c.pf_mse) / per_truth_bound)
    print(f"R1 at 240 s: PF/PCRLB {pf[k240]:.3f}, EKF/PCRLB {ekf[k240]:.2f}, PF/per-truth {tight[k240]:.3f}; "
          f"max PF/per-truth {tight.max():.3f}; Jensen gap {np.sqrt(per_truth_bound / np.asarray(c.position_bound))[[k240, -1]]}")
    assert pf[k240] < 0.2 * ekf[k240]
    assert tight[k240] <= 1.1 and tight.max() <= 1.3, (tight[k240], tight.max())
    # The PCRLB holds for the particle filter too (same 3.5-σ rule as the EKF and the PLKF above).
    se = np.asarray(c.pf_se_mean)
    assert np.all(np.asarray(c.pf_mse) >= np.asarray(c.position_bound) - 3.5 * se)
    assert "PF RMSE" in tb.bound_table([c]) and c.num_particles == PF_PARTICLES
    import matplotlib

    matplotlib.use("Agg")
    fig = figure_bounds([c])
    assert any("particle filter" in t.get_text() for t in fig.axes[0].get_legend().get_texts())

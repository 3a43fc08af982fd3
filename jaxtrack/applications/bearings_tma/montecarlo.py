"""Bearings-only TMA Monte Carlo: Table 2 against the Appendix D EKF, on
:func:`jaxtrack.montecarlo.monte_carlo_map` (run ``i`` from ``fold_in(key, i)``), and the
report's qualitative findings as numbers (spec §4.4)."""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ..._validation import InputError
from ...montecarlo import monte_carlo_map, normalized_squared_error
from .analysis import ErrorStatistics, error_statistics, sample_index, track_errors
from .estimators import bearing_ekf, ekf_prior, normalized_pseudolinear_filter
from .scenario import EKF_VELOCITY_STD, NOISE_CONFIGS, Scenario, geometry, noisy_bearings

PLKF_RANGES = (10_000.0, 0.0, 5000.0, 20_000.0)  # m: Fig. 6's 10 km and 0, plus A6's others
EKF_RANGES = (10_000.0, 5000.0, 20_000.0)  # m: the EKF cannot start at 0 (A9)
DEFAULT_RUNS = 2000  # A7: N = 2000 runs


class TmaMonteCarlo(eqx.Module):
    """Per-run results of :func:`monte_carlo` (``N`` runs, ``K+1`` samples).

    - ``bearings``: ``(N, K+1)`` the measured bearings of each run (rad).
    - ``initial_ranges`` ``(P,)`` and ``plkf_mean`` ``(N, P, K+1, 4)``: Table 2 estimates for
      each ``r̂_s(0)``, all on the same noise of each run.
    - ``plkf_position_nees`` ``(N, P, K+1)``: position NEES ``e'P⁻¹e`` (2 dof) with the filter's
      operational covariance ``P = r̂_s²(k|k) P_N(k|k)`` (eq. 69 with the only range the filter
      has); NaN where ``r̂_s = 0``.
    - ``plkf_range_std`` ``(N, P, K+1)``: that covariance's σ along the estimated line of sight.
    - ``ekf_initial_ranges`` ``(E,)``, ``ekf_mean`` ``(N, E, K+1, 4)``,
      ``ekf_position_nees`` ``(N, E, K+1)``, ``ekf_range_std`` ``(N, E, K+1)`` (the EKF's own
      σ of the range), ``ekf_ok`` ``(N, E)`` (False if the EKF went non-finite).
    """

    bearings: Float[Array, "N K1"]
    initial_ranges: Float[Array, " P"]
    plkf_mean: Float[Array, "N P K1 4"]
    plkf_position_nees: Float[Array, "N P K1"]
    plkf_range_std: Float[Array, "N P K1"]
    ekf_initial_ranges: Float[Array, " E"]
    ekf_mean: Float[Array, "N E K1 4"]
    ekf_position_nees: Float[Array, "N E K1"]
    ekf_range_std: Float[Array, "N E K1"]
    ekf_ok: Bool[Array, "N E"]

    @property
    def num_runs(self) -> int:
        return int(self.plkf_mean.shape[0])


class _RunArgs(eqx.Module):
    scenario: Scenario
    true_std: Array
    filter_std: Array
    initial_ranges: Array
    ekf_initial_ranges: Array
    ekf_velocity_std: Array
    preaverage: bool = eqx.field(static=True)


def _position_consistency(err, cov, est):
    """Position NEES ``e'P⁻¹e`` (2 dof) and the σ of the range along the estimated line of sight, per sample."""
    nees = jax.vmap(normalized_squared_error)(err[:, :2], cov[:, :2, :2])
    rng = jnp.hypot(est[:, 0], est[:, 1])
    g = est[:, :2] / rng[:, None]
    return nees, jnp.sqrt(jnp.einsum("ki,kij,kj->k", g, cov[:, :2, :2], g))


def _tma_run(key, args: _RunArgs):
    """One run: draw the bearings, run Table 2 for every initial range and the EKF for every EKF range."""
    s = args.scenario
    beta_m = noisy_bearings(s, key, args.true_std, preaverage=args.preaverage)

    def plkf(r0):
        est = normalized_pseudolinear_filter(beta_m, s.observer_input, s.sample_period, args.filter_std, r0,
                                             with_gain=False)
        rng2 = est.mean[:, 0] ** 2 + est.mean[:, 1] ** 2
        nees, std = _position_consistency(est.mean - s.relative, rng2[:, None, None] * est.cov, est.mean)
        return est.mean, nees, std

    out = (beta_m, *jax.vmap(plkf)(args.initial_ranges))
    if args.ekf_initial_ranges.shape[0] == 0:
        return out

    def ekf(r0):
        m0, P0 = ekf_prior(beta_m[0], r0, s.observer[0, 2:], velocity_std=args.ekf_velocity_std)
        est = bearing_ekf(beta_m, s.observer_input, s.sample_period, args.filter_std, m0, P0, throw=False)
        nees, std = _position_consistency(est.mean - s.relative, est.cov, est.mean)
        return est.mean, nees, std, est.ok

    return out + jax.vmap(ekf)(args.ekf_initial_ranges)


def monte_carlo(
    scenario: Scenario,
    key,
    num_runs: int,
    *,
    true_std: float,
    filter_std: float,
    initial_ranges: Sequence[float] = (10_000.0, 0.0),
    ekf_initial_ranges: Sequence[float] = (10_000.0,),
    ekf_velocity_std: float = EKF_VELOCITY_STD,
    preaverage: bool = False,
    progress: bool = False,
) -> TmaMonteCarlo:
    """Monte Carlo of Table 2 and the Appendix D EKF on one scenario (spec §4.4, A7).

    Run ``i`` draws one bearing-noise sequence from ``jax.random.fold_in(key, i)`` (σ ``true_std``
    rad; the raw 1-s σ when ``preaverage``) and runs Table 2 for every ``initial_ranges`` entry (m)
    and the EKF for every ``ekf_initial_ranges`` entry (m, all > 0, A9) on the same bearings, with
    filter σ ``filter_std`` (rad), through :func:`jaxtrack.montecarlo.monte_carlo_map`.

    **Arguments:**

    - ``scenario``: the :class:`Scenario`; ``key``: a PRNG key; ``num_runs``: ``N ≥ 1``.
    - ``true_std``: the simulated bearing-noise σ (rad); ``filter_std``: the filters' bearing σ (rad).
    - ``initial_ranges``: the Table 2 initial ranges ``r̂_s(0)``, ``(P,)``, m (≥ 0).
    - ``ekf_initial_ranges``: the EKF initial ranges, ``(E,)``, m (> 0; empty for no EKF runs).
    - ``ekf_velocity_std``: the σ of the EKF prior's velocity (m/s).
    - ``preaverage``: simulate raw 1-s bearings and average them (see :func:`noisy_bearings`).
    - ``progress``: show a progress bar.

    **Returns:** :class:`TmaMonteCarlo`; summaries: :func:`error_statistics`.

    **Raises:** ``InputError`` for ``num_runs < 1``, a negative range, a non-positive EKF range or
    bearing σ.
    """
    if num_runs < 1:
        raise InputError(f"`num_runs` must be at least 1; got {num_runs}.")
    if any(r <= 0 for r in ekf_initial_ranges):
        raise InputError("`ekf_initial_ranges` must all be positive: the EKF divides by r̂_s (A9).")
    if any(r < 0 for r in initial_ranges):
        raise InputError(f"`initial_ranges` must be non-negative (m); got {tuple(initial_ranges)}.")
    if true_std < 0 or filter_std <= 0:
        raise InputError(f"bearing σ must be positive (rad); got true {true_std}, filter {filter_std}.")
    dtype = scenario.target.dtype
    args = _RunArgs(
        scenario, jnp.asarray(true_std, dtype), jnp.asarray(filter_std, dtype),
        jnp.asarray(tuple(initial_ranges), dtype).reshape(-1), jnp.asarray(tuple(ekf_initial_ranges), dtype).reshape(-1),
        jnp.asarray(ekf_velocity_std, dtype), bool(preaverage),
    )
    out = [jnp.asarray(a) for a in monte_carlo_map(_tma_run, key, num_runs, args=args, reduce="stack",
                                                   progress=progress, desc="TMA Monte Carlo")]
    if len(out) == 4:
        k1 = scenario.times.shape[0]
        out += [jnp.zeros((num_runs, 0, k1, 4), dtype), jnp.zeros((num_runs, 0, k1), dtype),
                jnp.zeros((num_runs, 0, k1), dtype), jnp.ones((num_runs, 0), bool)]
    beta_m, p_mean, p_nees, p_std, e_mean, e_nees, e_std, e_ok = out
    return TmaMonteCarlo(beta_m, args.initial_ranges, p_mean, p_nees, p_std, args.ekf_initial_ranges,
                         e_mean, e_nees, e_std, e_ok)


class GeometryStudy(eqx.Module):
    """One geometry's Monte Carlo with its summaries (spec §4.4 tables).

    ``name`` (R1–R3), ``config`` (A–C), ``scenario``, ``mc``; ``plkf`` / ``ekf``:
    :class:`ErrorStatistics` with a leading axis over ``mc.initial_ranges`` /
    ``mc.ekf_initial_ranges`` (``ekf`` is ``None`` without EKF runs).
    """

    name: str = eqx.field(static=True)
    config: str = eqx.field(static=True)
    scenario: Scenario
    mc: TmaMonteCarlo
    plkf: ErrorStatistics
    ekf: ErrorStatistics | None


def geometry_study(
    name: str,
    num_runs: int,
    key,
    *,
    config: str = "A",
    initial_ranges: Sequence[float] = PLKF_RANGES,
    ekf_initial_ranges: Sequence[float] = EKF_RANGES,
    progress: bool = False,
) -> GeometryStudy:
    """Monte Carlo of Table 2 and the EKF on geometry ``name`` under noise configuration ``config`` (A2).

    **Arguments:**

    - ``name``: ``"R1"``, ``"R2"`` or ``"R3"``; ``num_runs``: ``N``; ``key``: a PRNG key.
    - ``config``: ``"A"``, ``"B"`` or ``"C"`` (the true and filter bearing σ of ``NOISE_CONFIGS``).
    - ``initial_ranges``, ``ekf_initial_ranges``: as in :func:`monte_carlo`, m.
    - ``progress``: show a progress bar.

    **Returns:** :class:`GeometryStudy`.

    **Raises:** ``InputError`` for an unknown ``config``.
    """
    if config not in NOISE_CONFIGS:
        raise InputError(f"`config` must be one of {sorted(NOISE_CONFIGS)}; got {config!r}.")
    scenario = geometry(name)
    true_std, filter_std = NOISE_CONFIGS[config]
    mc = monte_carlo(
        scenario, key, num_runs, true_std=true_std, filter_std=filter_std,
        initial_ranges=initial_ranges, ekf_initial_ranges=ekf_initial_ranges, progress=progress,
    )
    ekf = error_statistics(mc.ekf_mean, scenario) if len(ekf_initial_ranges) else None
    return GeometryStudy(name, config, scenario, mc, error_statistics(mc.plkf_mean, scenario), ekf)


def run_studies(num_runs: int = DEFAULT_RUNS, seed: int = 0) -> dict[str, GeometryStudy]:
    """The Monte Carlo studies behind the table and figures: R1 under configs A, B, C; R2, R3 under A.

    **Arguments:**

    - ``num_runs``: runs per study (default ``DEFAULT_RUNS``).
    - ``seed``: the integer seed of the study keys.

    **Returns:** a dict of :class:`GeometryStudy` keyed ``"R1-A"``, ``"R1-B"``, ``"R1-C"``, ``"R2-A"``,
    ``"R3-A"``.
    """
    keys = jax.random.split(jax.random.key(seed), 5)
    return {
        "R1-A": geometry_study("R1", num_runs, keys[0]),
        "R1-B": geometry_study("R1", num_runs, keys[1], config="B", ekf_initial_ranges=()),
        "R1-C": geometry_study("R1", num_runs, keys[2], config="C", ekf_initial_ranges=()),
        "R2-A": geometry_study("R2", num_runs, keys[3]),
        "R3-A": geometry_study("R3", num_runs, keys[4]),
    }


def leg1_collapse_factor(study: GeometryStudy, t: float = 240.0) -> float:
    """Mean of ``r̂(t)/r̂_s(0)`` over runs at the end of leg 1 (spec §3.5 item 3, V24).

    Uses the first nonzero entry of ``initial_ranges``; on leg 1 the ratio does not depend on it
    (the estimate is exactly proportional to ``r̂_s(0)``, V13).

    **Arguments:**

    - ``study``: a :class:`GeometryStudy`.
    - ``t``: the time (s), a sample instant (default 240, the end of leg 1).

    **Returns:** the mean ratio, a Python float (dimensionless).
    """
    ranges = np.asarray(study.mc.initial_ranges)
    (j,) = np.flatnonzero(ranges > 0)[:1]
    x = np.asarray(study.mc.plkf_mean[:, j, sample_index(study.scenario, t)])
    return float(np.mean(np.hypot(x[:, 0], x[:, 1])) / ranges[j])


def initial_range_difference(study: GeometryStudy, t: float, ranges=(10_000.0, 0.0)) -> float:
    """Median over runs of ``|r̂(t; r̂₀=a) − r̂(t; r̂₀=b)|`` on the same noise, m (V25).

    **Arguments:**

    - ``study``: a :class:`GeometryStudy`; ``t``: the time (s), a sample instant.
    - ``ranges``: ``(a, b)``, two entries of ``study.mc.initial_ranges``, m.

    **Returns:** the median difference, a Python float, m.
    """
    rs = list(np.asarray(study.mc.initial_ranges))
    ia, ib = rs.index(ranges[0]), rs.index(ranges[1])
    k = sample_index(study.scenario, t)
    x = np.asarray(study.mc.plkf_mean[:, :, k, :2])
    return float(np.median(np.abs(np.hypot(x[:, ia, 0], x[:, ia, 1]) - np.hypot(x[:, ib, 0], x[:, ib, 1]))))


def _check_which(which: str) -> None:
    if which not in ("plkf", "ekf"):
        raise InputError(f"`which` must be 'plkf' or 'ekf'; got {which!r}.")


def divergence_fraction(study: GeometryStudy, which: str, t: float = 960.0, threshold: float = 0.25) -> np.ndarray:
    """Fraction of runs with ``|range error| > threshold·r_s(t)`` at ``t`` (spec §4.4), per initial range.

    **Arguments:**

    - ``study``: a :class:`GeometryStudy`; ``which``: ``"plkf"`` or ``"ekf"``.
    - ``t``: the time (s), a sample instant (default 960).
    - ``threshold``: the error bound as a fraction of the true range (default 0.25).

    **Returns:** the fractions, NumPy ``(P,)`` (``"plkf"``) or ``(E,)`` (``"ekf"``).
    """
    _check_which(which)
    mean = study.mc.plkf_mean if which == "plkf" else study.mc.ekf_mean
    k = sample_index(study.scenario, t)
    err = np.abs(np.asarray(track_errors(mean, study.scenario).range[..., k]))
    return (err > threshold * float(study.scenario.slant_range[k])).mean(axis=0)


def overconfident_fraction(study: GeometryStudy, which: str, t: float = 960.0, sigmas: float = 5.0) -> np.ndarray:
    """Fraction of runs whose range error exceeds ``sigmas`` times the filter's own range σ at ``t``.

    A consistent Gaussian filter gives ~6e-7 for 5σ; a collapsed covariance (the report's EKF
    finding on geometry 2) gives far more. Per initial range.

    **Arguments:**

    - ``study``: a :class:`GeometryStudy`; ``which``: ``"plkf"`` or ``"ekf"``.
    - ``t``: the time (s), a sample instant (default 960).
    - ``sigmas``: the bound in filter σ (default 5).

    **Returns:** the fractions, NumPy ``(P,)`` (``"plkf"``) or ``(E,)`` (``"ekf"``).
    """
    _check_which(which)
    mc = study.mc
    mean, std = (mc.plkf_mean, mc.plkf_range_std) if which == "plkf" else (mc.ekf_mean, mc.ekf_range_std)
    k = sample_index(study.scenario, t)
    err = np.abs(np.asarray(track_errors(mean, study.scenario).range[..., k]))
    return (err > sigmas * np.asarray(std[..., k])).mean(axis=0)

"""Bearings-only TMA figures (Figs. 5–8 of the report and a consistency plot). matplotlib is
imported inside each function; every number comes from the study's other modules."""

from __future__ import annotations

import math
from collections.abc import Sequence

import jax
import numpy as np

from ...plotting import log_scale_y
from .analysis import initial_range_sensitivity, los_velocity_variances
from .estimators import normalized_pseudolinear_filter
from .montecarlo import GeometryStudy
from .scenario import (
    AVERAGED_BEARING_STD,
    INITIAL_RANGE_GUESSES,
    LEG_DURATION,
    NOISE_CONFIGS,
    NUM_LEGS,
    Scenario,
    first_maneuver_index,
    geometry,
    geometry_spec,
    make_scenario,
    noisy_bearings,
)

_COLORS = {0.0: "C3", 5000.0: "C1", 10_000.0: "C0", 20_000.0: "C2"}


def _legs(ax, scenario: Scenario):
    for t in np.arange(1, NUM_LEGS) * LEG_DURATION:
        if t < float(scenario.times[-1]):
            ax.axvline(t, color="0.85", lw=0.8, zorder=0)


def figure_tracks():
    """Figs. 5a, 7a, 8a: observer and target tracks of the reconstructed geometries R1–R3."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(12, 4.2), constrained_layout=True)
    for ax, name in zip(axes, ("R1", "R2", "R3")):
        s = geometry(name)
        spec = geometry_spec(name)
        fine = make_scenario(spec.path, spec.target_position, spec.target_course, sample_period=5.0, num_averaged=1)
        ax.plot(fine.observer[:, 0] / 1e3, fine.observer[:, 1] / 1e3, "k", lw=1.2, label="observer")
        ax.plot(fine.target[:, 0] / 1e3, fine.target[:, 1] / 1e3, "C3", lw=1.2, label="target")
        for k in range(0, s.times.shape[0], 12):
            ax.plot([s.observer[k, 0] / 1e3, s.target[k, 0] / 1e3], [s.observer[k, 1] / 1e3, s.target[k, 1] / 1e3],
                    ":", color="0.6", lw=0.8)
        ax.set_aspect("equal")
        ax.set_xlabel("x (east) [km]")
        ax.set_ylabel("y (north) [km]")
        ax.set_title(f"{name}: " + ("point maneuvers" if name == "R1" else "3°/s turns"))
        ax.grid(True, alpha=0.25)
    axes[0].legend(fontsize=8)
    return fig


def figure_first_leg(key=None, initial_ranges=(5000.0, 10_000.0, 20_000.0)):
    """Fig. 5b / A-1: leg-1 relative track for several ``r̂_s(0)``, noise-free and configs A, B (A20).

    Each panel uses one noise draw (``key``) for every initial range: the solutions are exactly
    proportional to ``r̂_s(0)`` (V13); only with little noise relative to the filter σ is the
    proportionality constant the true range normalisation (the report's "scaled solutions").
    """
    import matplotlib.pyplot as plt

    key = jax.random.key(5) if key is None else key
    s = geometry("R1")
    km = first_maneuver_index(s)
    panels = [("noise-free, filter σ = 0.112°", s.bearings, AVERAGED_BEARING_STD)]
    for cfg in ("A", "B"):
        true_std, filter_std = NOISE_CONFIGS[cfg]
        panels.append((f"config {cfg}: true {math.degrees(true_std):.3f}°, filter {math.degrees(filter_std):.3f}°",
                       noisy_bearings(s, key, true_std), filter_std))
    fig, axes = plt.subplots(1, 3, figsize=(12, 4.2), constrained_layout=True, sharey=True)
    for ax, (title, bm, fstd) in zip(axes, panels):
        ax.plot(s.relative[:km, 0] / 1e3, s.relative[:km, 1] / 1e3, "k", lw=2, label="true relative track")
        for r0 in initial_ranges:
            est = normalized_pseudolinear_filter(bm, s.observer_input, s.sample_period, fstd, r0)
            ax.plot(est.mean[:km, 0] / 1e3, est.mean[:km, 1] / 1e3, ".-", color=_COLORS[r0], lw=1,
                    label=f"r̂(0) = {r0 / 1e3:g} km")
        ax.plot([0], [0], "k^")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("r_x [km]")
        ax.grid(True, alpha=0.25)
    axes[0].set_ylabel("r_y [km]")
    axes[0].legend(fontsize=8)
    fig.suptitle("Leg 1 (0–220 s) relative solutions scale with r̂_s(0); noise shrinks them toward 0")
    return fig


def figure_initial_range(key=None):
    """Fig. 5c: range estimates for several ``r̂_s(0)`` on one config-A run, and ``‖∂r̂_pos/∂r̂_s(0)‖``."""
    import matplotlib.pyplot as plt

    key = jax.random.key(6) if key is None else key
    s = geometry("R1")
    bm = noisy_bearings(s, key, AVERAGED_BEARING_STD)
    t = np.asarray(s.times)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    for r0 in INITIAL_RANGE_GUESSES:
        est = normalized_pseudolinear_filter(bm, s.observer_input, s.sample_period, AVERAGED_BEARING_STD, r0)
        axes[0].plot(t, np.hypot(est.mean[:, 0], est.mean[:, 1]) / 1e3, ".-", color=_COLORS[r0], lw=1,
                     label=f"r̂(0) = {r0 / 1e3:g} km")
    axes[0].plot(t, s.slant_range / 1e3, "k", lw=2, label="true range")
    est = normalized_pseudolinear_filter(bm, s.observer_input, s.sample_period, AVERAGED_BEARING_STD, 10_000.0)
    b = initial_range_sensitivity(bm, est.gain, s.sample_period)
    axes[1].plot(t, np.hypot(b[:, 0], b[:, 1]), "k.-", lw=1)
    log_scale_y(axes[1])
    axes[0].set_ylabel("estimated range [km]")
    axes[1].set_ylabel("‖∂r̂_pos(k|k)/∂r̂_s(0)‖  (analytic b_k)")
    for ax in axes:
        _legs(ax, s)
        ax.set_xlabel("time [s]")
        ax.grid(True, which="both", alpha=0.25)
    axes[0].legend(fontsize=8)
    fig.suptitle("The initial range guess stops mattering after the first maneuver (240 s)")
    return fig


def figure_errors(study: GeometryStudy):
    """Figs. 6a–c / 7b–d / 8b–d: rms range, course, speed error and mean range error over time."""
    import matplotlib.pyplot as plt

    s = study.scenario
    t = np.asarray(s.times)
    fig, axes = plt.subplots(1, 4, figsize=(16, 3.9), constrained_layout=True)
    lines = []
    for j, r0 in enumerate(np.asarray(study.mc.initial_ranges)):
        lines.append((f"PLKF r̂(0)={r0 / 1e3:g} km", study.plkf, j, "-", _COLORS.get(float(r0), None)))
    if study.ekf is not None:
        for j, r0 in enumerate(np.asarray(study.mc.ekf_initial_ranges)):
            lines.append((f"EKF r̂(0)={r0 / 1e3:g} km", study.ekf, j, "--", _COLORS.get(float(r0), None)))
    # From k = 1: at k = 0 the r̂(0) = 10 km start has zero range error, which a log axis cannot show.
    for label, st, j, ls, color in lines:
        axes[0].plot(t[1:], st.rms_range[j, 1:], ls, color=color, lw=1.1, label=label)
        axes[1].plot(t[1:], st.rms_course[j, 1:], ls, color=color, lw=1.1)
        axes[2].plot(t[1:], st.rms_speed[j, 1:], ls, color=color, lw=1.1)
        axes[3].plot(t, st.mean_range[j], ls, color=color, lw=1.1)
    # The r̂(0) = 0 PLKF estimates a zero velocity on leg 1, so its speed error there is zero to
    # round-off (1e-16 m/s): log_scale_y leaves those values out instead of spanning 18 decades.
    for ax in axes[:3]:
        log_scale_y(ax)
    for ax, lab in zip(axes, ("rms range error [m]", "rms course error [deg]", "rms speed error [m/s]",
                              "mean range error (bias) [m]")):
        _legs(ax, s)
        ax.set_xlabel("time [s]")
        ax.set_ylabel(lab)
    axes[3].set_yscale("symlog", linthresh=100)
    axes[3].grid(True, which="both", alpha=0.25)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{study.name}, config {study.config}: Table 2 (PLKF) vs Appendix D EKF, {study.mc.num_runs} runs")
    return fig


def figure_consistency(studies: Sequence[GeometryStudy]):
    """Run-averaged position NEES (2 dof) of the PLKF (``P = r̂² P_N``) and the EKF, with 95% χ² bounds."""
    import matplotlib.pyplot as plt

    from ...montecarlo import chi2_mean_bounds

    fig, axes = plt.subplots(1, len(studies), figsize=(5.5 * len(studies), 4), constrained_layout=True, squeeze=False)
    for ax, st in zip(axes[0], studies):
        t = np.asarray(st.scenario.times)
        mc = st.mc
        for j, r0 in enumerate(np.asarray(mc.initial_ranges)):
            if r0 > 0:
                ax.plot(t[1:], np.nanmean(np.asarray(mc.plkf_position_nees[:, j, 1:]), axis=0), "-",
                        color=_COLORS.get(float(r0)), lw=1, label=f"PLKF r̂(0)={r0 / 1e3:g} km")
        for j, r0 in enumerate(np.asarray(mc.ekf_initial_ranges)):
            ax.plot(t[1:], np.nanmean(np.asarray(mc.ekf_position_nees[:, j, 1:]), axis=0), "--",
                    color=_COLORS.get(float(r0)), lw=1, label=f"EKF r̂(0)={r0 / 1e3:g} km")
        lo, hi = chi2_mean_bounds(2, mc.num_runs)
        ax.axhspan(lo, hi, color="0.8", alpha=0.6, label="95% χ² bounds")
        _legs(ax, st.scenario)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("average position NEES")
        log_scale_y(ax)
        ax.set_title(f"{st.name}, config {st.config}, {mc.num_runs} runs")
        ax.grid(True, which="both", alpha=0.25)
    axes[0, 0].legend(fontsize=7)
    return fig


def figure_velocity_variance():
    """Figs. 5d/5f finding (V26): ``P_N`` velocity variance along / across the line of sight, R1 noise-free."""
    import matplotlib.pyplot as plt

    s = geometry("R1")
    est = normalized_pseudolinear_filter(s.bearings, s.observer_input, s.sample_period, AVERAGED_BEARING_STD, 10_000.0)
    along, across = los_velocity_variances(s, est.cov)
    t = np.asarray(s.times)
    fig, ax = plt.subplots(figsize=(6.4, 4), constrained_layout=True)
    ax.plot(t[1:], along[1:], ".-", label="along the line of sight")
    ax.plot(t[1:], across[1:], ".-", label="across the line of sight")
    log_scale_y(ax)
    _legs(ax, s)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("P_N velocity variance [1/s²]")
    ax.set_title("Leg 2 runs parallel: the LOS velocity variance stays flat")
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=8)
    return fig



def figure_bounds(comparisons):
    """Extra (not in the report): the PCRLB's RMSE bound next to the EKF's and the PLKF's (and the
    particle filter's, when run) Monte Carlo position RMSE (truths drawn from the bound's prior,
    :mod:`.bounds`), one panel per geometry."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(comparisons), figsize=(5.2 * len(comparisons), 4), constrained_layout=True,
                             squeeze=False)
    for ax, c in zip(axes[0], comparisons):
        t = np.asarray(c.times)
        ax.plot(t, np.sqrt(np.asarray(c.position_bound)), "k", lw=2, label="PCRLB (√ trace of position block)")
        lines = [(c.ekf_mse, c.ekf_se_mean, "C1", "EKF"), (c.plkf_mse, c.plkf_se_mean, "C0", "PLKF (Table 2)")]
        if c.pf_mse is not None:
            lines.append((c.pf_mse, c.pf_se_mean, "C2", f"particle filter (N = {c.num_particles})"))
        for mse, se, color, label in lines:
            mse, se = np.asarray(mse), np.asarray(se)
            rmse = np.sqrt(mse)
            half = se / rmse  # 2 s.e. of the RMSE (delta method): 2 · se / (2 √mse)
            ax.plot(t, rmse, color=color, lw=1.2, label=f"{label} RMSE")
            ax.fill_between(t, rmse - half, rmse + half, color=color, alpha=0.25, lw=0)
        log_scale_y(ax)
        _legs(ax, geometry(c.name))
        ax.set_xlabel("time [s]")
        ax.set_ylabel("position RMSE [m]")
        ax.set_title(f"{c.name}: {c.num_runs} runs, r̂(0) = 10 km", fontsize=10)
        ax.grid(True, which="both", alpha=0.25)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("extra (not in the paper): PCRLB vs Monte Carlo RMSE (truths from the prior)")
    return fig

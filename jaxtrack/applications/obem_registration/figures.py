"""Figures of the study (Figs 8–10, the observability spectrum, the unequal-tilt caveat and
Proposition 2). matplotlib is imported inside the functions only; each returns a Figure."""

from __future__ import annotations

import numpy as np
from jaxtyping import ArrayLike

import jax.numpy as jnp

from ...estimation import observability
from .analysis import equivalent_errors_exact, equivalent_errors_first_order
from .frames import DEG, merged_columns, obem_columns
from .montecarlo import CORRECTIONS, MODELS, RegistrationMonteCarlo
from .scenario import Scans

__all__ = ["figure_bias_rmse", "figure_attitude_rmse", "figure_rectified_position", "figure_observability",
           "figure_unequal_tilt", "figure_proposition2"]

_RADAR_COLORS = ("tab:red", "tab:blue")


def _scans_axis(num_scans):
    return np.arange(1, num_scans + 1)


def figure_bias_rmse(mc: RegistrationMonteCarlo):
    """Fig. 8: RMSE of (a) gross range bias, (b) elevation bias, (c) Δθ−Δφ; solid AAM, dashed OBEM,
    red radar 1, blue radar 2.

    **Returns:** a matplotlib ``Figure``.
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13.0, 3.8), constrained_layout=True)
    k = _scans_axis(mc.gross_range.shape[-1])
    panels = (("(a) gross range bias Δr + k_r·r [m]", mc.gross_range, 1.0),
              ("(b) elevation bias Δε [deg]", mc.elevation, 1 / DEG),
              ("(c) Δθ − Δφ [deg]", mc.azimuth_minus_yaw, 1 / DEG))
    for ax, (title, curves, scale) in zip(axes, panels):
        for m, style in ((0, "-"), (1, "--")):
            for i in (0, 1):
                ax.plot(k, np.asarray(curves[m, i]) * scale, style, color=_RADAR_COLORS[i], lw=1.2,
                        label=f"{MODELS[m]}, radar {i + 1}")
        ax.set_yscale("log")
        ax.set_xlabel("scan k")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3, which="both")
    axes[2].axhline(0.5, color="k", lw=0.8, ls=":", label="paper: < 0.5°")
    axes[2].legend(fontsize=7)
    fig.suptitle(f"Fig. 8: RMSE of the radar bias estimates ({mc.num_runs} runs)")
    return fig


def figure_attitude_rmse(mc: RegistrationMonteCarlo):
    """Fig. 9: RMSE of AAM's pitch and roll estimates (truth 1°).

    **Returns:** a matplotlib ``Figure``.
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.8), constrained_layout=True)
    k = _scans_axis(mc.pitch_roll.shape[-1])
    for i in (0, 1):
        for j, style in ((0, "-"), (1, "--")):
            ax.plot(k, np.asarray(mc.pitch_roll[i, j]) / DEG, style, color=_RADAR_COLORS[i],
                    label=f"{('pitch', 'roll')[j]}, platform {i + 1}")
    ax.axhline(1.0, color="k", lw=0.8, ls=":", label="true value 1°")
    ax.set_xlabel("scan k")
    ax.set_ylabel("RMSE [deg]")
    ax.set_title(f"Fig. 9: AAM pitch and roll do not converge ({mc.num_runs} runs)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def figure_rectified_position(mc: RegistrationMonteCarlo):
    """Fig. 10: RMSE of radar 1's rectified position in its ENU axes: raw (black), OBEM (red),
    AAM with all estimates (blue), AAM without pitch and roll (green).

    **Returns:** a matplotlib ``Figure``.
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13.0, 3.8), constrained_layout=True)
    k = _scans_axis(mc.position.shape[1])
    colors = ("k", "tab:red", "tab:blue", "tab:green")
    for a, ax in enumerate(axes):
        for c, name in enumerate(CORRECTIONS):
            ax.plot(k, np.asarray(mc.position[c, :, a]), color=colors[c], lw=1.2, label=name)
        ax.set_title(f"({'abc'[a]}) {'xyz'[a]} (ENU {'ENU'[a]}) [m]", fontsize=10)
        ax.set_xlabel("scan k")
        ax.set_yscale("log")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=8)
    fig.suptitle(f"Fig. 10: RMSE of radar 1's rectified target position ({mc.num_runs} runs)")
    return fig


def figure_observability(measurement_matrices: ArrayLike):
    """Eigenvalues of the column-normalised observability matrix for AAM-14, AAM-12 and OBEM-8 (V11).

    **Returns:** a matplotlib ``Figure``.
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.8), constrained_layout=True)
    h = jnp.asarray(measurement_matrices)
    for x, (name, hm) in enumerate((("AAM-14", h), ("AAM-12 (Prop. 1)", merged_columns(h)), ("OBEM-8", obem_columns(h)))):
        ev = np.abs(np.asarray(observability(hm).eigenvalues))
        ax.plot(np.full(ev.shape, x), np.maximum(ev, 1e-18), "o", ms=6, alpha=0.7)
    lam_max = float(observability(h).eigenvalues[-1])
    ax.axhline(1e-10 * lam_max, color="k", lw=0.8, ls=":", label="1e-10·λ_max")
    ax.set_xticks([0, 1, 2], ["AAM-14", "AAM-12 (Prop. 1)", "OBEM-8"])
    ax.set_yscale("log")
    ax.set_ylabel("|eigenvalue| of column-normalised M")
    ax.set_title("Observability: AAM-12 keeps a null direction (rotation about the baseline)", fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return fig


def figure_unequal_tilt(mc_paper: RegistrationMonteCarlo, mc_tilt: RegistrationMonteCarlo):
    """Elevation-bias RMSE of AAM and OBEM with equal tilts (paper) and unequal tilts (spec §4.6 [X]).

    **Returns:** a matplotlib ``Figure``.
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11.0, 3.8), constrained_layout=True, sharey=True)
    k = _scans_axis(mc_paper.elevation.shape[-1])
    for ax, mc, title in ((axes[0], mc_paper, "paper: both platforms (Δη, Δψ) = (1°, 1°)"),
                          (axes[1], mc_tilt, "unequal: platform 2 (Δη, Δψ) = (−1°, −1°)")):
        for m, style in ((0, "-"), (1, "--")):
            for i in (0, 1):
                ax.plot(k, np.asarray(mc.elevation[m, i]) / DEG, style, color=_RADAR_COLORS[i],
                        label=f"{MODELS[m]}, radar {i + 1}")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("scan k")
        ax.set_yscale("log")
        ax.grid(alpha=0.3, which="both")
    axes[0].set_ylabel("RMSE of Δε [deg]")
    axes[1].legend(fontsize=8)
    fig.suptitle("Where OBEM's elevation advantage ends: unequal platform tilts")
    return fig


def figure_proposition2(scans: Scans, attitude: ArrayLike):
    """Proposition 2 along a track: exact and first-order Δθ_c, Δε_c for both radars (eqs 36, 45).

    **Returns:** a matplotlib ``Figure``.
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11.0, 3.8), constrained_layout=True)
    k = _scans_axis(scans.target_enu.shape[1])
    for i in (0, 1):
        exact = np.asarray(equivalent_errors_exact(attitude, scans.target_enu[i])) / DEG
        first = np.asarray(equivalent_errors_first_order(attitude, scans.target_enu[i])) / DEG
        for ax, j in ((axes[0], 1), (axes[1], 2)):
            ax.plot(k, exact[:, j], "-", color=_RADAR_COLORS[i], label=f"exact, radar {i + 1}")
            ax.plot(k, first[:, j], ":", color=_RADAR_COLORS[i], lw=2, label=f"first order, radar {i + 1}")
    axes[0].set_title("Δθ_c ≈ −Δφ (eq. 36) [deg]", fontsize=10)
    axes[1].set_title("Δε_c ≈ −(Δψ sinθ + Δη cosθ) (eq. 45) [deg]", fontsize=10)
    for ax in axes:
        ax.set_xlabel("scan k")
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=8)
    fig.suptitle("Proposition 2: equivalent measurement errors of the attitude biases (2°, 1°, 1°)")
    return fig

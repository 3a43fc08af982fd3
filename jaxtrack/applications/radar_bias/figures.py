"""Figures of the radar-bias study (matplotlib is imported inside the functions)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .reduced_state import reduced_state_covariance
from .scenario import GENERAL_SCENARIO, NUM_ESTIMATED, cost_discrepancy_table, general_scenario
from .steady_state import (
    PAPER_BETA_TABLE,
    _OBJECTIVES,
    _objective_by_index,
    noise_ratio,
    optimal_alpha_beta,
    optimise_alpha_beta,
    paper_beta,
)


def figure_gain_transient(num_steps: int = 30):
    """General-case gains α_k and β_k (= T·K_2) for Λ = 25 and Λ = 0 against the steady-state optimum."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.6), constrained_layout=True)
    a_star, b_star = optimal_alpha_beta(noise_ratio(1.0, 1.0, 2.0))
    steps = np.arange(1, num_steps + 1)
    for lam, style in ((25.0, "-o"), (0.0, "--s")):
        gains = np.asarray(reduced_state_covariance(general_scenario(lam), NUM_ESTIMATED, num_steps).gain[:, :, 0])
        axes[0].plot(steps, gains[:, 0], style, ms=3, label=f"Λ = {lam:g} m²")
        axes[1].plot(steps, gains[:, 1] * GENERAL_SCENARIO["period"], style, ms=3, label=f"Λ = {lam:g} m²")
    for ax, star, name in ((axes[0], a_star, "α"), (axes[1], b_star, "β")):
        ax.axhline(float(star), color="k", lw=0.8, label=f"{name}* = {float(star):.6f} (bias-free Kalman)")
        ax.set_xlabel("step k")
        ax.set_ylabel(f"{name}_k")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Reduced-state filter (69): Λ changes the transient, not the limit (T=1, q22=2, N=1)")
    return fig


def figure_alpha_beta_plane(rho: float = 2.0, objective: str = "position"):
    """log₁₀ M̄11/N over the (α, β) stability triangle at ρ, with the paper's relation (104),
    the paper's table points, the jointly optimal gain and an optax descent path."""
    import matplotlib.pyplot as plt

    alpha = np.linspace(0.02, 1.98, 160)
    beta = np.linspace(0.005, 3.9, 160)
    aa, bb = np.meshgrid(alpha, beta)
    inside = bb < 4 - 2 * aa
    index = _OBJECTIVES.index(objective)
    obj = jax.jit(jax.vmap(jax.vmap(lambda a, b: _objective_by_index(a, b, 1.0, 1.0, rho, index))))
    vals = np.where(inside, np.asarray(obj(jnp.asarray(np.where(inside, aa, 0.5)), jnp.asarray(np.where(inside, bb, 0.3)))), np.nan)
    fig, ax = plt.subplots(figsize=(6.4, 4.6), constrained_layout=True)
    cs = ax.contourf(aa, bb, np.log10(vals), levels=30, cmap="viridis")
    fig.colorbar(cs, ax=ax, label=f"log₁₀ M̄{'11' if objective == 'position' else ''}/N")
    a_line = np.linspace(0.02, 1.98, 200)
    ax.plot(a_line, np.asarray(paper_beta(jnp.asarray(a_line), rho)), "-", color="magenta", lw=1.2,
            label="paper relation (104), cubic root")
    a_opt = np.linspace(0.01, 0.99, 100)  # ρ = β²/(1−α) > 0 needs α < 1
    ax.plot(a_opt, a_opt**2 / (2 - a_opt), ":", color="cyan", lw=1.5, label="β = α²/(2−α): (G1)∧(G2) for some ρ")
    pts = [(a, b) for r, a, b, _ in PAPER_BETA_TABLE if r == rho]
    if pts:
        ax.plot(*np.array(pts).T, "rx", ms=8, label=f"paper table points (ρ = {rho:g})")
    a_s, b_s = optimal_alpha_beta(rho)
    path = optimise_alpha_beta(1.0, 1.0, rho, objective=objective).path
    ax.plot(*np.asarray(path).T, ".-", color="orange", ms=3, lw=0.8, label="optax L-BFGS path from (0.5, 0.3)")
    ax.plot([float(a_s)], [float(b_s)], "r*", ms=12, label=f"joint optimum ({float(a_s):.4f}, {float(b_s):.4f})")
    ax.set_xlabel("α")
    ax.set_ylabel("β")
    ax.set_ylim(0, 4)
    ax.set_title(f"Steady-state α-β filter, ρ = q22T²/N = {rho:g}")
    ax.legend(fontsize=7, loc="upper right")
    return fig


def figure_bias_examples():
    """Sec. 2 examples a–d: F(e*) of (13) against the paper's printed "Cost" (= Σ e²/k², spec A8)."""
    import matplotlib.pyplot as plt

    table = cost_discrepancy_table()
    names = [r["example"] for r in table]
    f_star = [r["F_star"] for r in table]
    printed = [r["printed_cost"] for r in table]
    recomputed = [r["sum_e2_over_k2"] for r in table]
    x = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(6.4, 3.8), constrained_layout=True)
    ax.bar(x - 0.27, f_star, 0.27, label="F(e*) by eq. (13)")
    ax.bar(x, printed, 0.27, label="paper's printed 'Cost'")
    ax.bar(x + 0.27, recomputed, 0.27, label="Σ e*²/k² (reproduces the print)")
    ax.set_xticks(x, [f"example {n}" for n in names])
    ax.set_yscale("log")
    ax.set_ylim(1e4, 6e5)
    ax.set_ylabel("cost [m²]")
    ax.set_title("Sec. 2: the printed cost is not the minimised F (identical e*)")
    ax.legend(fontsize=8, ncol=3, loc="upper center")
    return fig

"""Figures of Ho (1968) Sec. III-E and IV and of the designed schedules (matplotlib only here).

Each ``figure_*`` returns a matplotlib Figure built from the study's functions; nothing here
computes a number the tables use.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from ...covariance import CovarianceHistory, covariance_recursion
from ...models import ho_plant
from ...sensitivity import dimensionless_period_sensitivity
from .analysis import segment_sensitivities
from .scenario import COARSE, HO_RULE_1G, HO_RULE_10G, UNIFORM, adjoint_history, history
from .schedules import DesignComparison, design_comparison, per_step_example


def sawtooth(hist: CovarianceHistory, times, i: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Interleave ``P_{k/k-1}`` and ``P_{k/k}`` at each sample time: the covariance's saw-tooth.

    **Arguments:** ``hist`` a :class:`~jaxtrack.covariance.CovarianceHistory` with ``T`` steps;
    ``times`` ``(T,)`` s; ``i`` the state component.

    **Returns:** ``(t, p)``, each ``(2T,)``: times (s) and the variance ``P(i, i)``.
    """
    t = np.repeat(np.asarray(times), 2)
    p = np.stack([np.asarray(hist.predicted_cov[:, i, i]), np.asarray(hist.filtered_cov[:, i, i])], axis=1).ravel()
    return t, p


def figure_covariance_histories(curves: Sequence[tuple], title: str, *, figsize=(6.8, 4.2), fontsize: float = 8):
    """Position variance ``P(1,1)`` against time (saw-tooth, log scale) for several filters.

    **Arguments:** ``curves``: ``(label, history, times)`` or ``(label, history, times,
    linestyle)`` items, ``times`` ``(T,)`` s; ``title``; ``figsize`` inches; ``fontsize`` of
    the legend.

    **Returns:** a matplotlib Figure (one axis, ``fig.axes[0]``).
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=figsize, constrained_layout=True)
    for label, hist, times, *style in curves:
        t, p = sawtooth(hist, times)
        ax.plot(t, p, lw=1.0, ls=style[0] if style else "-", label=label)
    ax.set_yscale("log")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("position error variance P(1,1) [ft²]")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=fontsize)
    return fig


def figure_covariance_curves(g: float = 1.0):
    """Fig. 7 (1 g) / Fig. 10 (10 g): position variance for the uniform, coarse and Ho-rule schemes.

    **Arguments:** ``g`` plant noise in g (1 or 10). **Returns:** a matplotlib Figure.
    """
    schemes = {"a": UNIFORM, "b": COARSE, "c": HO_RULE_1G if g == 1.0 else HO_RULE_10G}
    curves = []
    for label, counts in schemes.items():
        hist, times = history(counts, g)
        curves.append((f"{label}: {counts}, terminal {float(hist.filtered_cov[-1, 0, 0]):.1f} ft²", hist, times))
    fig = figure_covariance_histories(
        curves, f"Ho 1968 Fig. {7 if g == 1.0 else 10}: {g:g}-g plant noise, σ_z = 100 ft", figsize=(6.4, 4.2)
    )
    ax = fig.axes[0]
    ax.set_ylim(3e2, 2e4)
    for edge in range(1, 5):
        ax.axvline(edge, color="0.85", lw=0.8, zorder=0)
    return fig


def figure_segment_sensitivity(g: float = 1.0, *, smoothed: bool = False):
    """Figs. 8 (1 g), 11 (10 g), 13 (smoothed data): ``s(τ_i)`` per segment, time- and sample-fixed.

    **Arguments:** ``g`` plant noise in g; ``smoothed`` for ``R = 10³/τ``. **Returns:** a matplotlib Figure.
    """
    import matplotlib.pyplot as plt

    s = segment_sensitivities(UNIFORM, g, smoothed=smoothed)
    fig, ax = plt.subplots(figsize=(6.4, 4.0), constrained_layout=True)
    idx = np.arange(1, 6)
    ax.bar(idx - 0.18, s.time_fixed, width=0.36, label="time-fixed s(τ_i) (Ho's, Convention 3)")
    ax.bar(idx + 0.18, s.sample_fixed, width=0.36, label="sample-fixed ∂J/∂τ_i (eq. 52)")
    for i, v in zip(idx, s.time_fixed):
        ax.annotate(f"{v:.1f}", (i - 0.18, v), ha="center", va="bottom" if v >= 0 else "top", fontsize=7)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_yscale("symlog", linthresh=10.0)
    ax.set_xlabel("segment i (1-s segments, 10 samples each)")
    ax.set_ylabel("∂P_T(1,1)/∂τ_i [ft²/s]")
    number = {(1.0, False): 8, (10.0, False): 11}.get((g, smoothed), 13)
    ax.set_title(f"Ho 1968 Fig. {number}: segment sensitivity, {g:g} g" + (", R = 10³/τ" if smoothed else ""))
    ax.legend(fontsize=8)
    return fig


def figure_adjoint(g: float = 1.0):
    """Fig. 9 (1 g) / Fig. 12 (10 g): diagonals of the adjoint ``L_{k/k}`` for ``J = P_T(1,1)``.

    **Arguments:** ``g`` plant noise in g. **Returns:** a matplotlib Figure.
    """
    import matplotlib.pyplot as plt

    L, t = adjoint_history(UNIFORM, g)
    fig, ax = plt.subplots(figsize=(6.4, 4.0), constrained_layout=True)
    ax.plot(t, L[:, 0, 0], label="a: L11 (position)")
    ax.plot(t, L[:, 1, 1], label="b: L22 (velocity)")
    k = int(np.argmax(L[:, 1, 1]))
    ax.annotate(f"max L22 = {L[k, 1, 1]:.3f} at {t[k]:.1f} s", (t[k], L[k, 1, 1]), xytext=(0.5, 0.8),
                textcoords="axes fraction", arrowprops={"arrowstyle": "->", "lw": 0.6}, fontsize=8)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("adjoint ∂P_T(1,1)/∂P_k/k (diagonal)")
    ax.set_title(f"Ho 1968 Fig. {9 if g == 1.0 else 12}: adjoint matrices, {g:g} g")
    ax.grid(True, alpha=0.25)
    ax.legend(fontsize=8)
    return fig


def figure_designed_schedules(g: float = 1.0, comparison: DesignComparison | None = None):
    """Covariance histories of the uniform, Ho-rule, gradient-designed and optimal 40-sample schemes
    (and the per-step design of 50 samples), position variance against time.

    **Arguments:** ``g`` plant noise in g; ``comparison`` a :class:`DesignComparison` (computed
    when None). **Returns:** a matplotlib Figure.
    """
    comparison = design_comparison(g) if comparison is None else comparison
    curves = []
    for name in ("uniform", "ho", "gradient", "optimum"):
        scheme = getattr(comparison, name)
        hist, times = history(scheme.counts, g)
        curves.append((f"{name}: {scheme.counts}, P_T = {float(scheme.cost):.1f} ft²", hist, times))
    ps = per_step_example(g)
    hist = covariance_recursion(ho_plant(jnp.asarray(ps.taus), g=g))
    curves.append((f"per-step τ_k, 50 samples, P_T = {ps.cost:.1f} ft²", hist, ps.times, "--"))
    return figure_covariance_histories(curves, f"Designed schedules, {g:g} g (40 samples, 1 ≤ n_i ≤ 20)", fontsize=7)


def figure_one_stage_sensitivity():
    """Figs. 16–17: one-stage dimensionless sensitivity (Δp_x/p_x)/(Δτ/τ), eq. (134), a = 0 and 1.

    **Returns:** a matplotlib Figure (two axes).
    """
    import matplotlib.pyplot as plt

    tau = np.linspace(0.01, 3.0, 300)
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.6), sharey=True, constrained_layout=True)
    for ax, a, number in zip(axes, (0.0, 1.0), (16, 17)):
        for r in (0.1, 0.5, 1.0, 2.0, 5.0):
            ax.plot(tau, dimensionless_period_sensitivity(a, tau, r), label=f"r_x = {r:g}")
        ax.set_title(f"Fig. {number}: a = {a:g}")
        ax.set_xlabel("normalised sampling period τ")
        ax.grid(True, alpha=0.25)
    axes[0].set_ylabel("(Δp_x/p_x) / (Δτ/τ)")
    axes[1].legend(fontsize=8)
    return fig

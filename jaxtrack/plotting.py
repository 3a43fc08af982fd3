"""Figures built from library results (the CLI, the notebooks and the tests use these)."""

from __future__ import annotations

from collections.abc import Sequence

# The user's matplotlib backend is left alone (a notebook keeps its inline figures); the CLI
# picks the headless Agg backend for itself (jaxtrack.cli.main).
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import ScalarFormatter

from .montecarlo import MonteCarloResult


def plot_monte_carlo(
    results: dict[str, MonteCarloResult],
    *,
    rmse_components: dict[str, Sequence[int]] | None = None,
    theory_rmse: dict[str, np.ndarray] | None = None,
    times: np.ndarray | None = None,
    time_unit: str = "s",
    rmse_unit: dict[str, str] | None = None,
):
    """RMSE per step and run-averaged NEES against its χ² bounds, one line per filter.

    **Arguments:**

    - ``results``: label → :class:`~jaxtrack.montecarlo.MonteCarloResult` (same ``T``).
    - ``rmse_components``: panel title → state indices whose RMSE is drawn (e.g.
      ``{"position": (0, 1), "velocity": (2, 3)}``); default one panel over all states.
    - ``theory_rmse``: label → ``(T,)`` predicted RMSE (e.g. √tr P) drawn dashed, per panel
      title.
    - ``times``: ``(T,)`` time axis (default: step index); ``time_unit`` its label.
    - ``rmse_unit``: panel title → unit string for the y label.

    **Returns:** the matplotlib ``Figure`` (the caller saves or shows it).
    """
    rmse_components = rmse_components or {"state": None}
    rmse_unit = rmse_unit or {}
    first = next(iter(results.values()))
    T = first.nees.shape[0]
    t = np.arange(T) if times is None else np.asarray(times)
    panels = len(rmse_components) + 1
    fig, axes = plt.subplots(1, panels, figsize=(4.6 * panels, 3.8), constrained_layout=True)
    for ax, (title, comps) in zip(axes, rmse_components.items()):
        for label, res in results.items():
            (line,) = ax.plot(t, np.asarray(res.rmse(None if comps is None else tuple(comps))), label=label)
            if theory_rmse and (label, title) in theory_rmse:
                ax.plot(t, theory_rmse[(label, title)], "--", color=line.get_color(), lw=1,
                        label=f"{label}: filter's √tr P")
        ax.set_title(f"{title} RMSE ({first.num_runs} runs)")
        ax.set_xlabel(f"time [{time_unit}]" if times is not None else "step")
        unit = rmse_unit.get(title)
        ax.set_ylabel(f"RMSE [{unit}]" if unit else "RMSE")
        _log_axis(ax)
        ax.legend(fontsize=8)
    ax = axes[-1]
    n = first.mse.shape[1]
    for label, res in results.items():
        ax.plot(t, np.asarray(res.nees), label=f"{label} (ANEES {float(res.anees):.3f})")
    bounds = np.asarray(first.nees_bounds)
    ax.fill_between(t, bounds[:, 0], bounds[:, 1], color="0.8", alpha=0.7,
                    label=f"{first.confidence:.0%} χ² bounds")
    ax.axhline(n, color="k", lw=0.8)
    ax.set_title("average NEES")
    ax.set_xlabel(f"time [{time_unit}]" if times is not None else "step")
    ax.set_ylabel(f"NEES (n = {n})")
    _log_axis(ax)
    ax.legend(fontsize=8)
    return fig


def _log_axis(ax):
    """Log y axis with plain numbers (not 9×10⁰) on its ticks."""
    ax.set_yscale("log")
    for axis in (ax.yaxis,):
        axis.set_major_formatter(ScalarFormatter())
        axis.set_minor_formatter(ScalarFormatter())
    ax.grid(True, which="both", alpha=0.3)


def plot_mode_probabilities(
    mode_probs: dict[str, np.ndarray],
    mode_names: Sequence[str],
    *,
    times: np.ndarray | None = None,
    time_unit: str = "s",
    shade: np.ndarray | None = None,
    shade_label: str = "maneuver",
):
    """Mode probabilities over time, one panel per mode, one line per source.

    **Arguments:**

    - ``mode_probs``: label → ``(T, K)`` probabilities (e.g. an IMM Monte Carlo's
      :attr:`~jaxtrack.montecarlo.MonteCarloResult.mode_probs`, a smoother's average).
    - ``mode_names``: the ``K`` mode names, panel titles.
    - ``times``: ``(T,)`` time axis (default: step index); ``time_unit`` its label.
    - ``shade``: optional boolean ``(T,)``: steps shaded grey (e.g. where the truth turns),
      named ``shade_label`` in the legend.

    **Returns:** the matplotlib ``Figure``.
    """
    first = np.asarray(next(iter(mode_probs.values())))
    T, K = first.shape
    if len(mode_names) != K:
        raise ValueError(f"`mode_names` has {len(mode_names)} names for {K} modes.")
    t = np.arange(T) if times is None else np.asarray(times)
    fig, axes = plt.subplots(1, K, figsize=(4.6 * K, 3.4), constrained_layout=True, squeeze=False)
    for k, ax in enumerate(axes[0]):
        if shade is not None:
            ax.fill_between(t, 0, 1, where=np.asarray(shade, bool), color="0.88", step="mid", label=shade_label)
        for label, mu in mode_probs.items():
            ax.plot(t, np.asarray(mu)[:, k], label=label)
        ax.set_ylim(0, 1)
        ax.set_title(f"P(mode = {mode_names[k]})")
        ax.set_xlabel(f"time [{time_unit}]" if times is not None else "step")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    return fig

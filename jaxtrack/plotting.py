"""Figures built from library results (the CLI, the notebooks and the tests use these)."""

from __future__ import annotations

from collections.abc import Sequence

# The user's matplotlib backend is left alone (a notebook keeps its inline figures); the CLI
# picks the headless Agg backend for itself (jaxtrack.cli.main).
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import FuncFormatter

from .montecarlo import MonteCarloResult

__all__ = [
    "plot_monte_carlo",
    "plot_mode_probabilities",
    "log_scale_y",
]


def plot_monte_carlo(
    results: dict[str, MonteCarloResult],
    *,
    rmse_components: dict[str, Sequence[int]] | None = None,
    theory_rmse: dict[str, np.ndarray] | None = None,
    times: np.ndarray | None = None,
    time_unit: str = "s",
    rmse_unit: dict[str, str] | None = None,
    bound=None,
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
    - ``bound``: an optional :class:`~jaxtrack.bounds.PosteriorCRB` over the same steps: its RMSE
      bound (:meth:`~jaxtrack.bounds.PosteriorCRB.rmse_bound` of each panel's components, which
      must then be given and index the bound's state) is drawn dotted in black, and each label
      gains the estimator's efficiency at the last step, RMSE / bound
      (:func:`~jaxtrack.bounds.efficiency`; ≥ 1 up to Monte Carlo error).

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
        floor = None
        if bound is not None and comps is not None:
            floor = np.asarray(bound.rmse_bound(tuple(comps)))
            ax.plot(t, floor, ":", color="k", lw=1.4, zorder=3, label="PCRLB (RMSE bound)")
        for label, res in results.items():
            rmse = np.asarray(res.rmse(None if comps is None else tuple(comps)))
            shown = label if floor is None else f"{label} (RMSE/bound {rmse[-1] / floor[-1]:.2f} at end)"
            (line,) = ax.plot(t, rmse, label=shown)
            if theory_rmse and (label, title) in theory_rmse:
                ax.plot(t, theory_rmse[(label, title)], "--", color=line.get_color(), lw=1,
                        label=f"{label}: filter's √tr P")
        ax.set_title(f"{title} RMSE ({first.num_runs} runs)")
        ax.set_xlabel(f"time [{time_unit}]" if times is not None else "step")
        unit = rmse_unit.get(title)
        ax.set_ylabel(f"RMSE [{unit}]" if unit else "RMSE")
        log_scale_y(ax)
        ax.legend(fontsize=8)
    ax = axes[-1]
    n = first.mse.shape[1]
    for label, res in results.items():
        ax.plot(t, np.asarray(res.nees), lw=1, label=f"{label} (ANEES {float(res.anees):.3f})")
    ax.axhline(n, color="k", lw=0.6, ls=":", zorder=1.5)
    bounds = np.asarray(first.nees_bounds)
    # With 10⁴ runs the band is ±1.4 % of n, a few pixels high: a light fill alone disappears
    # under the NEES line inside it, so its two edges are drawn as dark lines above the data.
    ax.fill_between(t, bounds[:, 0], bounds[:, 1], color="C2", alpha=0.35, lw=0, zorder=1,
                    label=f"{first.confidence:.0%} χ² bounds")
    for edge in (bounds[:, 0], bounds[:, 1]):
        ax.plot(t, edge, color="k", lw=0.9, zorder=3)
    ax.set_title("average NEES")
    ax.set_xlabel(f"time [{time_unit}]" if times is not None else "step")
    ax.set_ylabel(f"NEES (n = {n})")
    log_scale_y(ax)
    ax.legend(fontsize=8)
    return fig


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


# Log axes: a log scale only where the data span at least three 1-2-5 ticks, a factor of 5 or more
# (below that a log axis shows one tick label or none, or two far apart, and reads no better than a
# linear one); and values that are zero to round-off (1e-16 next to 1e3) are left out: drawn,
# they stretch the axis over 18 decades and flatten every curve that matters. Genuine data over
# many decades (a variance falling from 1 to 1e-11) stay: the round-off threshold is near the
# float64 epsilon, and no decade limit is applied unless asked for.
_NICE = (1.0, 2.0, 5.0)


def _nice_ticks_between(lo: float, hi: float) -> int:
    """How many 1-2-5 × 10^k values lie in ``[lo, hi]`` (``0 < lo ≤ hi``)."""
    count = 0
    for k in range(int(np.floor(np.log10(lo))), int(np.floor(np.log10(hi))) + 1):
        count += sum(lo <= s * 10.0**k <= hi for s in _NICE)
    return count


def log_scale_y(ax, *, max_decades: float | None = None, roundoff: float = 1e-13) -> bool:
    """Put ``ax``'s y axis on a readable log scale, or on a linear one where log would not help.

    Call it after the lines are drawn. Values at or below ``roundoff`` × the largest value are
    zero to round-off: they are not drawn (a note on the axes says so), since a log axis cannot
    show zero. With ``max_decades``, the lower limit is at most that many decades below the
    largest value (curves below it leave the axes). When the
    remaining data span fewer than three 1-2-5 ticks (say 7 to 24 m: only 10 and 20) the axis
    stays linear, so that every axis has several labelled ticks. Wide log axes (over 3 decades)
    keep matplotlib's decade ticks; narrower ones get 1-2-5 ticks labelled as plain numbers.

    **Arguments:**

    - ``ax``: a matplotlib ``Axes`` with its lines drawn (``Line2D`` artists, y data in any
      positive unit).
    - ``max_decades``: the most decades shown below the largest value (default: no limit).
    - ``roundoff``: relative size (to the largest value on the axes) at or below which a value
      counts as zero; the default is about 450 float64 epsilons.

    **Returns:** ``True`` if the axis is logarithmic, ``False`` if it was left linear.
    """
    from matplotlib.ticker import LogLocator, NullFormatter

    lines = [ln for ln in ax.get_lines() if np.size(ln.get_ydata()) > 2]
    values = np.concatenate([np.asarray(ln.get_ydata(), float).ravel() for ln in lines]) if lines else np.zeros(0)
    positive = values[np.isfinite(values) & (values > 0)]
    if positive.size == 0:  # nothing drawn as lines (markers, fills): a plain log axis
        ax.set_yscale("log")
        return True
    hi = float(positive.max())
    zero = roundoff * hi
    masked = False
    for ln in lines:
        y = np.asarray(ln.get_ydata(), float)
        if np.any(np.isfinite(y) & (y <= zero)):
            ln.set_ydata(np.where(y <= zero, np.nan, y))
            masked = True
    if masked:
        ax.text(0.01, 0.01, f"values ≤ {roundoff:g} × max (zero to round-off) not drawn", transform=ax.transAxes,
                fontsize=6, color="0.35", va="bottom")
    kept = positive[positive > zero]
    lo = float(kept.min()) if max_decades is None else max(float(kept.min()), hi / 10.0**max_decades)
    if _nice_ticks_between(lo, hi) < 3:
        ax.set_yscale("linear")
        ax.relim()
        ax.autoscale_view()
        ax.grid(True, which="major", alpha=0.3)
        return False
    ax.set_yscale("log")
    pad = (hi / lo) ** 0.04
    ax.set_ylim(lo / pad, hi * pad)
    if np.log10(hi / lo) <= 3.0:
        # 1-2-5 major ticks labelled as plain numbers, unlabelled minor ticks: at most three
        # labels a decade, so they never overlap.
        ax.yaxis.set_major_locator(LogLocator(subs=_NICE))
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        ax.yaxis.set_minor_formatter(NullFormatter())
    ax.grid(True, which="both", alpha=0.25)
    return True

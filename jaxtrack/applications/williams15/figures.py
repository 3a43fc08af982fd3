"""The Williams (2015) study's figure: the reference's four plots (RMS GOSPA per scan and its
localisation, missed and false parts) for the five methods in one figure. Every number comes
from :mod:`.montecarlo`."""

from __future__ import annotations

import numpy as np

from .montecarlo import Williams15Study
from .scenario import LABELS, METHODS

PARTS = (("localisation", "localisation"), ("missed", "missed targets"), ("false", "false targets"))


def figure_gospa(study: Williams15Study):
    """RMS GOSPA per scan (``sqrt`` of the mean squared GOSPA, as the reference plots it) and
    the square roots of its mean parts, one line per method."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True, constrained_layout=True)
    names = [n for n in METHODS if n in study.results]
    first = study.results[names[0]]
    k = np.arange(1, len(np.asarray(first.gospa)) + 1)
    panels = [("RMS GOSPA", lambda r, n: study.rms_gospa(n))] + [
        (f"RMS GOSPA, {lab}", lambda r, n, p=p: np.sqrt(np.asarray(getattr(r, p)))) for p, lab in PARTS]
    for ax, (title, value) in zip(axes.ravel(), panels):
        for i, name in enumerate(names):
            r = study.results[name]
            v = value(r, name)
            ax.plot(k, v, color=f"C{i}", lw=1.3,
                    label=f"{LABELS[name]} ({float(np.sqrt(np.mean(v ** 2))):.2f} m)")
        ax.set(title=title, ylabel="m", ylim=(0, None))
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    for ax in axes[1]:
        ax.set_xlabel("time step")
    fig.suptitle(f"Williams (2015) scenario, GOSPA c = {first.cutoff:g} m, p = {first.order:g}, α = 2, "
                 f"{study.num_runs} runs (legend: RMS over all steps)", fontsize=10)
    return fig

"""The labelled-RFS study's figure: mean GOSPA per scan with its 95% interval, and the mean
number of estimates against the true number of targets, for both filters. Every number comes
from :mod:`.montecarlo`."""

from __future__ import annotations

import numpy as np

from .montecarlo import VoVoStudy
from .scenario import LABELS, METHODS


def figure_study(study: VoVoStudy):
    """Left: mean GOSPA per scan (c, p of the study) with its 95% interval; right: mean number of
    estimates per scan and the true number of targets."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2), constrained_layout=True)
    first = study.results[METHODS[0]]
    k = np.arange(1, len(np.asarray(first.gospa)) + 1)
    for i, name in enumerate(METHODS):
        r = study.results[name]
        lo, hi = np.asarray(r.gospa_interval).T
        axes[0].plot(k, np.asarray(r.gospa), color=f"C{i}", lw=1.3, label=f"{LABELS[name]} ({r.mean_gospa():.1f} m)")
        axes[0].fill_between(k, lo, hi, color=f"C{i}", alpha=0.2)
        axes[1].plot(k, np.asarray(r.num_tracks), color=f"C{i}", lw=1.3, label=LABELS[name])
    axes[1].step(k, np.asarray(first.num_targets), where="mid", color="k", lw=2, label="true number of targets")
    axes[0].set(title=f"mean GOSPA (c = {first.cutoff:g} m, p = {first.order:g}, α = 2)", xlabel="scan",
                ylabel="m", ylim=(0, None))
    axes[1].set(title="mean number of estimates", xlabel="scan", ylabel="targets", ylim=(0, None))
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"Vo & Vo's linear benchmark, {study.num_runs} runs", fontsize=10)
    return fig

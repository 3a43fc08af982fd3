"""Multi-target study figures. Every number comes from :mod:`.montecarlo`
(:class:`~jaxtrack.multitarget.MultiTargetMonteCarloResult` fields, one run's
:class:`~jaxtrack.multitarget.TrackerResult`)."""

from __future__ import annotations

import numpy as np

from ...multitarget import CONFIRMED
from .montecarlo import MultiTargetStudy
from .scenario import LABELS, TRACKERS

PARTS = (("localisation", "localisation"), ("missed", "missed targets"), ("false", "false tracks"))


def figure_gospa(study: MultiTargetStudy):
    """Mean GOSPA per scan with its 95% band for the three trackers (left), and each tracker's
    mean GOSPA^p split into its localisation, missed and false parts, stacked (right)."""
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(11, 5.2), constrained_layout=True)
    grid = fig.add_gridspec(len(TRACKERS), 2, width_ratios=(1.25, 1))
    ax = fig.add_subplot(grid[:, 0])
    k = np.arange(study.num_scans)
    for i, name in enumerate(TRACKERS):
        r = study.results[name]
        lo, hi = np.asarray(r.gospa_interval).T
        ax.fill_between(k, lo, hi, color=f"C{i}", alpha=0.25, lw=0)
        ax.plot(k, np.asarray(r.gospa), color=f"C{i}", label=f"{LABELS[name]} (mean {r.mean_gospa():.1f} m)")
    first = study.results[TRACKERS[0]]
    ax.set(xlabel="scan", ylabel="GOSPA [m]", ylim=(0, None),
           title=f"mean GOSPA (c = {first.cutoff:g} m, p = {first.order:g}), 95% band, {study.num_runs} runs")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    top = max(float(np.max(sum(np.asarray(getattr(study.results[n], p)) for p, _ in PARTS))) for n in TRACKERS)
    for i, name in enumerate(TRACKERS):
        r = study.results[name]
        a = fig.add_subplot(grid[i, 1])
        a.stackplot(k, *(np.asarray(getattr(r, p)) for p, _ in PARTS), labels=[lab for _, lab in PARTS],
                    colors=("0.55", "C3", "C1"), alpha=0.8)
        a.set_ylim(0, 1.05 * top)
        a.set_ylabel(f"{LABELS[name]}\nGOSPA$^{r.order:g}$ [m$^{r.order:g}$]", fontsize=8)
        a.grid(True, alpha=0.3)
        if i == 0:
            a.set_title("mean GOSPA$^p$ by part", fontsize=10)
            a.legend(fontsize=7, loc="upper right")
        if i == len(TRACKERS) - 1:
            a.set_xlabel("scan")
        else:
            a.tick_params(labelbottom=False)
    return fig


def figure_track_counts(study: MultiTargetStudy):
    """Mean number of confirmed tracks per scan of each tracker against the alive targets."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.6), constrained_layout=True)
    k = np.arange(study.num_scans)
    ax.plot(k, np.asarray(study.results[TRACKERS[0]].num_targets), "k--", lw=1.5, label="alive targets")
    for i, name in enumerate(TRACKERS):
        ax.plot(k, np.asarray(study.results[name].num_tracks), color=f"C{i}", label=LABELS[name])
    ax.set(xlabel="scan", ylabel="mean number", title=f"confirmed tracks, {study.num_runs} runs")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def figure_run(truth, tracks: dict):
    """One run: the true paths, the scans' measurements (clutter grey) and each tracker's
    confirmed tracks, East–North in km (``truth``, ``tracks``: from :func:`~.montecarlo.example_run`)."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(tracks), figsize=(4.2 * len(tracks), 4.3), sharex=True, sharey=True,
                             constrained_layout=True)
    axes = np.atleast_1d(axes)
    z = np.asarray(truth.scans.measurements)
    valid = np.asarray(truth.scans.valid)
    zx, zy = z[..., 0] * np.cos(z[..., 1]), z[..., 0] * np.sin(z[..., 1])
    x, alive = np.asarray(truth.states), np.asarray(truth.alive)
    for ax, (name, res) in zip(axes, tracks.items()):
        ax.plot(zx[valid] / 1e3, zy[valid] / 1e3, ".", color="0.8", ms=1.5, zorder=0)
        for j in range(x.shape[1]):
            ax.plot(np.where(alive[:, j], x[:, j, 0], np.nan) / 1e3, np.where(alive[:, j], x[:, j, 1], np.nan) / 1e3,
                    "k-", lw=3, alpha=0.35, label="truth" if j == 0 else None)
        conf = np.asarray(res.status) == CONFIRMED
        ids, mean = np.asarray(res.track_id), np.asarray(res.mean)
        for c, tid in enumerate(np.unique(ids[conf])):
            sel = conf & (ids == tid)
            ax.plot(mean[..., 0][sel] / 1e3, mean[..., 1][sel] / 1e3, ".", color=f"C{c % 10}", ms=2.5)
        ax.set(title=f"{LABELS.get(name, name)}: {len(np.unique(ids[conf]))} confirmed tracks",
               xlabel="East [km]", aspect="equal")
        ax.grid(True, alpha=0.3)
    seen = x[alive]
    lo, hi = seen[:, :2].min(axis=0) - 500.0, seen[:, :2].max(axis=0) + 500.0
    axes[0].set(xlim=(lo[0] / 1e3, hi[0] / 1e3), ylim=(lo[1] / 1e3, hi[1] / 1e3), ylabel="North [km]")
    axes[0].legend(fontsize=8, loc="upper left")
    return fig

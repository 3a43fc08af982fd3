"""Figures are read by people: their axes must show the data that matter, with readable ticks.

Each test inspects the returned matplotlib ``Figure`` (limits, tick labels, artists), not pixels.
"""

import os
import subprocess
import sys
import types

import jax
import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.figure import Figure

from jaxtrack.plotting import log_scale_y

matplotlib.use("Agg")  # this test file draws off screen; the library never picks a backend


def _labelled_major_ticks(ax, which="y"):
    """Texts of the major tick labels drawn inside the axis limits."""
    ax.figure.canvas.draw()
    axis = ax.yaxis if which == "y" else ax.xaxis
    lo, hi = sorted(ax.get_ylim() if which == "y" else ax.get_xlim())
    return [lab.get_text() for lab, loc in zip(axis.get_ticklabels(), axis.get_ticklocs())
            if lab.get_visible() and lab.get_text() and lo <= loc <= hi]


def _overlapping_labels(ax):
    """Pairs of tick labels of one axis (major and minor) whose drawn boxes overlap."""
    fig = ax.figure
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    pairs = []
    for axis in (ax.xaxis, ax.yaxis):
        lo, hi = sorted(ax.get_xlim() if axis is ax.xaxis else ax.get_ylim())
        labels = [lab for lab, loc in zip(axis.get_ticklabels() + axis.get_ticklabels(minor=True),
                                          list(axis.get_ticklocs()) + list(axis.get_minorticklocs()))
                  if lab.get_visible() and lab.get_text() and lo <= loc <= hi]
        boxes = [lab.get_window_extent(renderer) for lab in labels]
        pairs += [(labels[i].get_text(), labels[j].get_text()) for i in range(len(boxes))
                  for j in range(i + 1, len(boxes)) if boxes[i].overlaps(boxes[j])]
    return pairs


def test_log_scale_y_drops_roundoff_zeros_and_avoids_one_tick_log_axes():
    fig, ax = plt.subplots()
    t = np.arange(50.0)
    ax.plot(t, 1 + t)  # 1 … 50
    ax.plot(t, np.where(t < 20, 1e-16, 0.5 + t))  # zero to round-off on its first 20 steps
    assert log_scale_y(ax) is True
    lo, hi = ax.get_ylim()
    assert np.log10(hi / lo) < 2.5 and lo <= 1.0 and hi >= 50.0
    assert np.isnan(ax.get_lines()[1].get_ydata()[:20]).all()
    fig2, ax2 = plt.subplots()
    ax2.plot(t, 7 + t / 3)  # 7 … 23.3: two 1-2-5 ticks (10, 20) only
    assert log_scale_y(ax2) is False and ax2.get_yscale() == "linear"
    assert len(_labelled_major_ticks(ax2)) >= 2
    fig3, ax3 = plt.subplots()
    ax3.plot(t, 10.0 ** (-t / 4.5))  # genuine data over 11 decades (a variance, 1 … 1e-11): all kept
    assert log_scale_y(ax3) is True and not np.isnan(ax3.get_lines()[0].get_ydata()).any()
    assert ax3.get_ylim()[0] <= 1e-11
    plt.close(fig), plt.close(fig2), plt.close(fig3)


def test_tma_fig08_speed_axis_shows_the_curves_that_matter():
    """R3 (fig08): the r̂(0) = 0 PLKF has a zero speed error on leg 1; the axis used to span
    1e-16 … 7e3 (19.8 decades), now the curves' own range (≈ 4 decades)."""
    from jaxtrack.applications.bearings_tma import figure_errors
    from jaxtrack.applications.bearings_tma.montecarlo import geometry_study

    study = geometry_study("R3", 20, jax.random.key(4))
    fig = figure_errors(study)
    assert isinstance(fig, Figure)
    for ax in fig.axes[:3]:
        assert ax.get_yscale() == "log"
        lo, hi = ax.get_ylim()
        assert np.log10(hi / lo) < 6, (ax.get_ylabel(), lo, hi)
        for line in ax.get_lines():
            y = np.asarray(line.get_ydata(), float)
            y = y[np.isfinite(y)]
            if y.size > 2:  # every drawn curve lies inside the limits
                assert lo <= y.min() and y.max() <= hi, (ax.get_ylabel(), line.get_label())
        assert len(_labelled_major_ticks(ax)) >= 2
    speed = fig.axes[2]
    drawn = [np.asarray(ln.get_ydata(), float) for ln in speed.get_lines() if np.size(ln.get_ydata()) > 2]
    assert sum(np.isnan(y).any() for y in drawn) == 1  # only the degenerate curve lost points
    plt.close(fig)


def test_sar_shared_position_error_axes_have_two_labelled_ticks():
    """rs1_shared_position_error: σ curves of 7 … 47 m (the RS-1 ranges) used to sit on log axes
    of less than a decade with one tick label or none."""
    from jaxtrack.applications.sar_navigation import figure_shared_position_error

    t = np.linspace(0.0, 240.0, 49)
    s = t / 240.0
    # Per-axis σ [m] of the "radar" case (N, E, D), the shapes and ranges of the real analysis.
    air = np.stack([14.5 + 3 * s, 15 + 9 * s**2, 20 + 14 * s**2], -1)
    tgt = np.stack([17.6 - 3 * s, 23.9 - 5 * s, 47.5 - 14 * s], -1)
    rel = np.stack([6.6 + 2 * s, 9.4 + 5 * (s - 0.45) ** 2, 25 + 9 * (s - 0.45) ** 2], -1)
    as_cov = lambda sig: np.einsum("ti,ij->tij", sig**2, np.eye(3))  # noqa: E731
    analysis = types.SimpleNamespace(times=t, aircraft_cov=as_cov(air), target_cov=as_cov(tgt),
                                     relative_cov=as_cov(rel))
    fig = figure_shared_position_error(analysis)
    assert isinstance(fig, Figure)
    for ax in fig.axes:
        assert ax.get_yscale() == "linear", ax.get_title()  # under a factor 5 on every axis
        for which in "xy":
            assert len(_labelled_major_ticks(ax, which)) >= 2, (ax.get_title(), which)
        assert not _overlapping_labels(ax)
    plt.close(fig)


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    """The default demo (10⁴ runs, 100 steps), written as the CLI writes it; open figures before."""
    from jaxtrack.cli._demo import run_demo

    before = set(plt.get_fignums())
    out = run_demo(num_runs=10_000, num_steps=100, chunk_size=10_000, progress=False,
                   out_dir=tmp_path_factory.mktemp("demo"))
    return out, before, set(plt.get_fignums())


@pytest.fixture(scope="module")
def demo_figure_10k(demo_run):
    from jaxtrack.cli._demo import demo_figure

    out, _, _ = demo_run
    fig = demo_figure(out["results"], out["theory"], 100)
    fig.set_dpi(120)  # as written to demo.png
    yield fig
    plt.close(fig)


def test_demo_tick_labels_do_not_overlap(demo_figure_10k):
    for ax in demo_figure_10k.axes:
        assert not _overlapping_labels(ax), ax.get_title()
        assert len(_labelled_major_ticks(ax)) >= 2, ax.get_title()


def test_demo_chi2_band_is_visible(demo_figure_10k):
    """At the default 10⁴ runs the 95 % NEES band is ±1.4 % of n = 4: at least 4 px high at the
    PNG's 120 dpi, with its edges drawn in black above the NEES curves (a light fill under a
    1.5 pt line was invisible)."""
    ax = demo_figure_10k.axes[-1]
    demo_figure_10k.canvas.draw()
    (band,) = [c for c in ax.collections if c.get_label().endswith("χ² bounds")]
    verts = band.get_paths()[0].vertices
    px = ax.transData.transform(verts)[:, 1]
    assert px.max() - px.min() >= 4.0
    lo, hi = verts[:, 1].min(), verts[:, 1].max()
    data = [ln for ln in ax.get_lines() if ln.get_label().startswith(("matched", "Q/10"))]
    edges = [ln for ln in ax.get_lines() if np.size(ln.get_ydata()) > 2 and ln not in data
             and np.allclose(np.ptp(ln.get_ydata()), 0, atol=hi - lo) and lo <= np.mean(ln.get_ydata()) <= hi]
    assert len(edges) == 2 and len(data) == 2
    assert all(matplotlib.colors.to_rgb(e.get_color()) == (0, 0, 0) for e in edges)
    assert min(e.get_zorder() for e in edges) > max(d.get_zorder() for d in data)


def test_demo_writer_closes_its_figure(demo_run):
    """demo_figure returns the figure open; run_demo, its writer, saves and closes it."""
    out, before, after = demo_run
    assert after == before
    assert os.path.getsize(out["figure"]) > 10_000


def test_importing_plotting_and_figures_keeps_the_users_backend():
    """A notebook's backend survives importing the plotting module and every study's figures."""
    code = ("import matplotlib; matplotlib.use('svg'); import importlib, jaxtrack.plotting\n"
            "for s in ('bearings_tma', 'ho_sensitivity', 'maneuvering', 'multitarget', 'obem_registration', 'radar_bias',"
            " 'sar_navigation'):\n"
            "    importlib.import_module(f'jaxtrack.applications.{s}.figures')\n"
            "import matplotlib.pyplot as plt; print(matplotlib.get_backend(), len(plt.get_fignums()))")
    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.split() == ["svg", "0"]


def test_monte_carlo_figure_draws_the_pcrlb_and_the_efficiency():
    """A Kalman filter on its own linear model is efficient: the PCRLB curve equals its RMSE
    bound and the legend's RMSE/bound is 1 within Monte Carlo error (400 runs: the RMSE's
    relative standard error is about 1/sqrt(2·400·2) = 1.8 %, so within 10 %)."""
    from jaxtrack.bounds import pcrlb
    from jaxtrack.models import constant_velocity
    from jaxtrack.montecarlo import monte_carlo
    from jaxtrack.plotting import plot_monte_carlo

    model = constant_velocity(1.0, dim=2, accel_psd=0.5, measurement_std=10.0,
                              initial_cov=np.diag([100.0, 100.0, 25.0, 25.0]))
    res = monte_carlo(model, jax.random.key(0), 400, num_steps=30, progress=False)
    crb = pcrlb(model, jax.random.key(1), 1, 30)
    fig = plot_monte_carlo({"KF": res}, rmse_components={"position": (0, 1)}, bound=crb)
    try:
        ax = fig.axes[0]
        (floor,) = [ln for ln in ax.get_lines() if ln.get_label() == "PCRLB (RMSE bound)"]
        np.testing.assert_allclose(floor.get_ydata(), np.asarray(crb.rmse_bound((0, 1))), rtol=1e-12)
        (kf,) = [ln for ln in ax.get_lines() if ln.get_label().startswith("KF (RMSE/bound ")]
        ratio = float(kf.get_label().split("RMSE/bound ")[1].split()[0])
        assert abs(ratio - 1.0) < 0.1, ratio
    finally:
        plt.close(fig)

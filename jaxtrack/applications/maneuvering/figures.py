"""Maneuvering-study figures. Every number comes from :mod:`.montecarlo` and the library's
plotting functions (:func:`jaxtrack.plotting.plot_monte_carlo`,
:func:`jaxtrack.plotting.plot_mode_probabilities`)."""

from __future__ import annotations

import jax
import numpy as np

from ...montecarlo import simulate
from .montecarlo import ManeuveringStudy
from .scenario import TAU, truth_model, turn_steps

LABELS = {"cv": "CV only", "ct": "CT only", "imm": "IMM", "imm_smoother": "IMM smoother",
          "imm_learned": "IMM, learned parameters"}


def _times(num_steps):
    return np.arange(num_steps) * TAU


def figure_rmse_nees(study: ManeuveringStudy):
    """Position and velocity RMSE and the 4-state NEES of the three filters against χ² bounds."""
    from ...plotting import plot_monte_carlo

    res = {LABELS[k]: study.results[k] for k in ("cv", "ct", "imm")}
    T = study.results["imm"].nees.shape[0]
    return plot_monte_carlo(res, rmse_components={"position": (0, 1), "velocity": (2, 3)},
                            times=_times(T), rmse_unit={"position": "m", "velocity": "m/s"})


def figure_mode_probabilities(study: ManeuveringStudy):
    """The IMM's filtered and smoothed mode probabilities (run averages); turns shaded."""
    from ...plotting import plot_mode_probabilities

    T = study.smoothed_mode_probs.shape[0]
    return plot_mode_probabilities(
        {"IMM filter": study.results["imm"].mode_probs, "IMM smoother": study.smoothed_mode_probs,
         "learned IMM filter": study.results["imm_learned"].mode_probs},
        ("CV", "turn"), times=_times(T), shade=turn_steps(T), shade_label="truth turns")


def figure_estimators(study: ManeuveringStudy):
    """Position RMSE per step of all five estimators (from the paired per-run errors)."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 3.8), constrained_layout=True)
    T = study.squared_position_error["imm"].shape[1]
    t = _times(T)
    ax.fill_between(t, 0, 1, where=turn_steps(T), color="0.9", step="mid",
                    transform=ax.get_xaxis_transform(), label="truth turns")
    for key, label in LABELS.items():
        ax.plot(t, np.sqrt(study.squared_position_error[key].mean(axis=0)), label=label)
    ax.set_yscale("log")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("position RMSE [m]")
    ax.set_title(f"position RMSE, {study.num_runs} runs")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, ncol=2)
    return fig


def figure_scenario(study: ManeuveringStudy | None = None):
    """One run's true track and radar position (run 0 of the evaluation key)."""
    import matplotlib.pyplot as plt

    from .montecarlo import EVALUATION_KEY

    truth = truth_model()
    run = simulate(truth, jax.random.fold_in(jax.random.key(EVALUATION_KEY), 0), truth.num_steps)
    x = np.asarray(run.states)
    turns = turn_steps(x.shape[0])
    fig, ax = plt.subplots(figsize=(6, 4.2), constrained_layout=True)
    ax.plot(x[:, 0] / 1e3, x[:, 1] / 1e3, color="C0", label="target (run 0)")
    ax.plot(np.where(turns, x[:, 0], np.nan) / 1e3, np.where(turns, x[:, 1], np.nan) / 1e3, color="C3", lw=3,
            label="turns (±0.06 rad/s)")
    ax.plot(0, 0, "k^", ms=9, label="radar")
    ax.set_aspect("equal")
    ax.set_xlabel("East [km]")
    ax.set_ylabel("North [km]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def figure_learning(source):
    """The learned IMM's training log-likelihood per iteration (``source``: an
    :class:`~jaxtrack.learning.IMMFit`, or a :class:`ManeuveringStudy` holding one)."""
    import matplotlib.pyplot as plt

    fit = source.fit if isinstance(source, ManeuveringStudy) else source
    ll = np.asarray(fit.log_likelihood_history)
    fig, ax = plt.subplots(figsize=(5.5, 3.5), constrained_layout=True)
    ax.plot(np.arange(ll.shape[0]), ll)
    ax.set_xlabel("optimiser step (Adam)")
    ax.set_ylabel("training log-likelihood [nats]")
    ax.set_title("IMM parameters learned from measurements")
    ax.grid(True, alpha=0.3)
    return fig

"""Figures of the SAR + INS study (matplotlib is imported inside the functions only)."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from ...models import gyro_bias_position_response, horizontal_accel_bias_response, schuler_rates, vertical_accel_bias_response
from ...plotting import log_scale_y
from .analysis import CovarianceAnalysis, SingleLookAnalysis, rs1_covariance_analysis, single_look_analysis
from .error_model import error_response
from .experiments import RESPONSE_TIMES
from .scenario import CASES, rs1_look
from .states import ACCEL_BIAS, DEG_PER_HOUR, GYRO_BIAS, MICRO_G, NUM_STATES


def _label(ax, xlabel: str, ylabel: str, title: str | None = None, *, log: bool = False, legend: bool = True) -> None:
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title is not None:
        ax.set_title(title)
    if log:
        # Log only where the data span three 1-2-5 ticks: the RS-1 σ curves span less than a
        # decade (7 to 47 m), where a log axis showed one tick label or none.
        log = log_scale_y(ax)
    ax.grid(True, which="both" if log else "major", alpha=0.25)
    if legend:
        ax.legend(fontsize=8)


def figure_target_error(analyses: dict[str, CovarianceAnalysis] | None = None):
    """Horizontal CEP of the absolute and relative target error over time for the three cases.

    **Arguments:** ``analyses``: ``{case: CovarianceAnalysis}`` (computed for :data:`CASES` if None).

    **Returns:** the matplotlib Figure.
    """
    import matplotlib.pyplot as plt

    analyses = analyses or {c: rs1_covariance_analysis(c) for c in CASES}
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    for case, res in analyses.items():
        t = np.asarray(res.times)
        (line,) = ax[0].plot(t, np.asarray(res.target_cep), label=CASES[case])
        ax[1].plot(t, np.asarray(res.relative_cep), color=line.get_color(), label=CASES[case])
    ax[0].set_title("absolute target location error (horizontal CEP)")
    ax[1].set_title("relative target error δr_t − δr_a (horizontal CEP)")
    for a in ax:
        _label(a, "time [s]", "CEP [m]", log=True)
    fig.suptitle("RS-1 [EXT]: 33-state covariance analysis, a look (and GPS fix) every 5 s after the first-look fix", fontsize=10)
    return fig


def figure_shared_position_error(analysis: CovarianceAnalysis | None = None):
    """Without GPS: σ of the aircraft, absolute-target and relative errors per axis (V-21).

    **Arguments:** ``analysis``: the ``"radar"`` :class:`CovarianceAnalysis` (computed if None).

    **Returns:** the matplotlib Figure.
    """
    import matplotlib.pyplot as plt

    res = analysis if analysis is not None else rs1_covariance_analysis("radar")
    t = np.asarray(res.times)
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.8), constrained_layout=True)
    for i, axis in enumerate("NED"):
        ax[i].plot(t, np.sqrt(np.asarray(res.aircraft_cov[:, i, i])), label="aircraft δr_a")
        ax[i].plot(t, np.sqrt(np.asarray(res.target_cov[:, i, i])), "--", label="target δr_t (absolute)")
        ax[i].plot(t, np.sqrt(np.asarray(res.relative_cov[:, i, i])), label="relative δr_t − δr_a")
        _label(ax[i], "time [s]", "σ [m]", f"{axis} axis", log=True, legend=False)
    ax[0].legend(fontsize=8)
    fig.suptitle("No GPS: the shared position error of aircraft and target is unobservable", fontsize=10)
    return fig


def _ellipse(cov2, p=0.5, n=200):
    k = math.sqrt(-2.0 * math.log(1.0 - p))
    w, V = np.linalg.eigh(np.asarray(cov2))
    th = np.linspace(0, 2 * np.pi, n)
    return (V @ (k * np.sqrt(w)[:, None] * np.stack([np.cos(th), np.sin(th)]))).T


def figure_single_look(analysis: SingleLookAnalysis | None = None):
    """RS-1 single look: 50% N/E error ellipses and CEP circles of the three covariances.

    **Arguments:** ``analysis``: the RS-1 :class:`SingleLookAnalysis` (computed if None).

    **Returns:** the matplotlib Figure.
    """
    import matplotlib.pyplot as plt

    a = analysis if analysis is not None else single_look_analysis(rs1_look())
    fig, ax = plt.subplots(figsize=(5.6, 5.2), constrained_layout=True)
    th = np.linspace(0, 2 * np.pi, 200)
    for label, cov, cep in (("least squares, white", a.least_squares_cov, a.cep_least_squares),
                            ("closed form §1.7, white", a.closed_form_cov, a.cep_closed_form),
                            ("least squares + consider biases", a.consider_cov, a.cep_consider)):
        e = _ellipse(np.asarray(cov)[:2, :2])
        (line,) = ax.plot(e[:, 1], e[:, 0], label=f"{label}: CEP {float(cep):.2f} m")
        ax.plot(float(cep) * np.sin(th), float(cep) * np.cos(th), ":", color=line.get_color(), lw=0.9)
    ax.set_aspect("equal")
    _label(ax, "East error [m]", "North error [m]", "RS-1 single look: 50% ellipses (solid) and CEP (dotted)")
    return fig


def figure_ins_error_responses():
    """The 33-state F (Van Loan) against the Schuler closed forms (V-17, V-18), 10–600 s.

    **Returns:** the matplotlib Figure.
    """
    import matplotlib.pyplot as plt

    t = RESPONSE_TIMES
    rates = schuler_rates()
    b, eps = 30 * MICRO_G, 0.004 * DEG_PER_HOUR
    horiz = error_response(rates, jnp.zeros(NUM_STATES).at[ACCEL_BIAS.start].set(b), t)
    vert = error_response(rates, jnp.zeros(NUM_STATES).at[ACCEL_BIAS.start + 2].set(b), t)
    gyro = error_response(rates, jnp.zeros(NUM_STATES).at[GYRO_BIAS.start + 1].set(eps), t)
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    for label, model, closed in (("30 µg horizontal accel bias", horiz[:, 0], horizontal_accel_bias_response(b, t)),
                                 ("30 µg vertical accel bias", vert[:, 2], vertical_accel_bias_response(b, t)),
                                 ("0.004 °/h gyro bias", -gyro[:, 0], gyro_bias_position_response(eps, t))):
        closed = np.asarray(closed)
        (line,) = ax.plot(t, np.asarray(model), label=f"{label} (33-state F)")
        ax.plot(t, closed, "o", ms=3, mfc="none", color=line.get_color(), label="closed form")
    _label(ax, "time [s]", "position error [m]", "INS error responses, Ω = ρ = 0 (V-17, V-18)")
    return fig

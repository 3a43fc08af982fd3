"""The paper rows of the SAR + INS study (spec verification targets V-5b … V-24) and :func:`reproduce`."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ...models import schuler_frequency, schuler_rates
from ...montecarlo import circular_error_probable
from .._report import PaperRow, write_figures
from .analysis import CASES, SingleLookAnalysis, rs1_covariance_analysis, single_look_analysis
from .budgets import designation_noise_factor, h423_budget, sar_noise_std, table6_budget, table7_budget
from .error_model import error_response
from .experiments import RESPONSE_TIMES, accelerometer_bias_experiment
from .figures import figure_ins_error_responses, figure_shared_position_error, figure_single_look, figure_target_error
from .geometry import (
    atmospheric_loss,
    clutter_cross_section,
    designation_factor_ref2,
    radar_measurements,
    rain_loss,
    range_resolution,
    signal_to_clutter_noise,
    signal_to_noise,
    to_db,
)
from .scenario import RS1_SPEED, rs1_look, v5b_look, v10_look
from .states import ACCEL_BIAS, ATTITUDE, DEG_PER_HOUR, GYRO_BIAS, MICRO_G, MRAD, NUM_STATES
from .targeting import targeting_round_trip_error

def _row(tid: str, quantity: str, paper: float, value, last_digit: float, floor: float = 1e-6) -> PaperRow:
    """A row whose tolerance is the spec's (``floor``) or half a unit in the printed last digit.

    Its reference is the spec's (``source="spec"``): the report is a derivation with no numerical
    results (spec §0), so every number here is an [EXT] reference value, a closed form or a unit
    conversion computed in the specification.
    """
    return PaperRow(tid, quantity, float(paper), float(value), max(floor, 0.5 * last_digit / abs(paper)), source="spec")


def paper_rows(single: SingleLookAnalysis | None = None) -> list[PaperRow]:
    """Every number of the spec's verification targets that jaxtrack reproduces, as table rows.

    V-22 to V-24 at the spec's relative tolerance 1e-6 (or half a printed unit when coarser);
    V-10, V-16 to V-18 at their printed precision.

    **Arguments:** ``single``: a precomputed RS-1 :class:`SingleLookAnalysis` (computed if None).

    **Returns:** the list of :class:`~jaxtrack.applications._report.PaperRow`.
    """
    rows: list[PaperRow] = []
    add = rows.append

    # V-5b: the literal |ṙ| mirrors a receding target.
    look = v5b_look()
    add(_row("V-5b", "literal |ṙ| targeting error, receding target [m]", 20000.0,
             targeting_round_trip_error(jax.tree.map(lambda a: a[None], look), doppler_cone="literal")[0], 1e-3))

    # V-10: the generic geometry's angles.
    ang = np.degrees(np.asarray(radar_measurements(v10_look())[2:]))
    add(_row("V-10", "A at the V-10 geometry [deg]", 99.918, ang[0], 1e-3))
    add(_row("V-10", "E at the V-10 geometry [deg]", 83.647, ang[1], 1e-3))

    # V-16: nonlinear rotating-Earth truth against the Pinson model.
    phys = accelerometer_bias_experiment()
    lit = accelerometer_bias_experiment(gamma="report")
    add(_row("V-16", "|δrⁿ| after 1500 s, 30 µg-class nav bias [m]", 2157.0, jnp.linalg.norm(phys.nonlinear[-1]), 1.0))
    add(_row("V-16", "|linear − nonlinear| with Γ33 = −ω_s² (report) [m]", 629.0,
             jnp.linalg.norm(lit.linear[-1] - lit.nonlinear[-1]), 1.0))

    # V-17, V-18: Schuler closed forms, from the 33-state F discretised by Van Loan.
    ws = schuler_frequency()
    add(_row("V-17", "ω_s² = g/R [1/s²]", 1.5375e-6, ws ** 2, 1e-10))
    add(_row("V-17", "ω_s [rad/s]", 1.2399764e-3, ws, 1e-10))
    add(_row("V-17", "Schuler period [min]", 84.4530, 2 * math.pi / ws / 60.0, 1e-4))
    rates = schuler_rates()
    b, eps = 30 * MICRO_G, 0.004 * DEG_PER_HOUR
    t = RESPONSE_TIMES  # ends at 600 s
    add(_row("V-17", "δr_N at 600 s, 30 µg North accel bias [m]", 50.5579,
             error_response(rates, jnp.zeros(NUM_STATES).at[ACCEL_BIAS.start].set(b), t)[-1, 0], 1e-4))
    add(_row("V-17", "flat-Earth ½bt² at 600 s [m]", 52.9559, 0.5 * b * 600.0 ** 2, 1e-4))
    add(_row("V-17", "δr_D at 600 s, 30 µg vertical accel bias [m]", 58.0251,
             error_response(rates, jnp.zeros(NUM_STATES).at[ACCEL_BIAS.start + 2].set(b), t)[-1, 2], 1e-4))
    gyro = error_response(rates, jnp.zeros(NUM_STATES).at[GYRO_BIAS.start + 1].set(eps), t)[-1]
    add(_row("V-18", "|ψ| at 600 s, 0.004 °/h gyro bias [rad]", 1.163553e-5, jnp.linalg.norm(gyro[ATTITUDE]), 1e-11))
    add(_row("V-18", "horizontal |δr| at 600 s, 0.004 °/h gyro bias [m]", 6.65933, jnp.linalg.norm(gyro[0:2]), 1e-5))

    # V-22: budget arithmetic.
    mono = table7_budget()
    add(_row("V-22", "σ_A white (Table 7 RSS) [mrad]", 0.7035624, mono.white_std / MRAD, 1e-7))
    add(_row("V-22", "σ_A with TEMP bias [mrad]", 0.8093207, mono.total_std / MRAD, 1e-7))
    add(_row("V-22", "sqrt(K² + 1/12 + 0.25), K = 2", 2.0816660, designation_noise_factor(2.0), 1e-7))

    # V-23: unit conversions.
    ins, alt = h423_budget(), h423_budget("per_sqrt_hour")
    add(_row("V-23", "30 µg [m/s²]", 2.941995e-4, ins.accel_bias, 1e-10))
    add(_row("V-23", "0.004 °/h [rad/s]", 1.939255e-8, ins.gyro_bias, 1e-14))
    add(_row("V-23", "0.01 ft [m]", 3.048e-3, table6_budget().range_clock, 1e-6))
    add(_row("V-23", "0.001 ft/s [m/s]", 3.048e-4, table6_budget().doppler_bias, 1e-7))
    add(_row("V-23", "literal √q_v [m/s^1.5]", 7.620e-4, jnp.sqrt(ins.accel_noise_psd), 1e-7))
    add(_row("V-23", "literal √q_ψ [rad/√s]", 9.69627e-9, jnp.sqrt(ins.gyro_noise_psd), 1e-14))
    add(_row("V-23", "literal q_v [m²/s³] (§3.1)", 5.80644e-7, ins.accel_noise_psd, 1e-12))
    add(_row("V-23", "literal q_ψ [rad²/s] (§3.1)", 9.40177e-17, ins.gyro_noise_psd, 1e-22))
    add(_row("V-23", "per-√h √q_v [m/s^1.5] (§3.1)", 1.2700e-5, jnp.sqrt(alt.accel_noise_psd), 1e-9))
    add(_row("V-23", "per-√h √q_ψ [rad/√s] (§3.1)", 5.81776e-7, jnp.sqrt(alt.gyro_noise_psd), 1e-12))
    add(_row("V-23", "Δr = c/(2B), B = 150 MHz [m]", 0.9993082, range_resolution(150e6), 1e-7))

    # V-24: RS-1.
    a = single if single is not None else single_look_analysis(rs1_look())
    r, rdot = a.measurements[0], a.measurements[1]
    add(_row("V-24", "RS-1 r [m]", 29292.736301, r, 1e-6))
    add(_row("V-24", "RS-1 ṙ [m/s]", -136.552624, rdot, 1e-6))
    add(_row("V-24", "RS-1 cos β", 0.68276312, a.cos_cone, 1e-8))
    add(_row("V-24", "RS-1 A [deg]", 90.0, np.degrees(float(a.measurements[2])), 1e-6))
    add(_row("V-24", "RS-1 E [deg]", 90.0, np.degrees(float(a.measurements[3])), 1e-6))
    add(_row("V-24", "RS-1 ω_t = Δṙ for Δaz = 1 m [rad/s]", 4.988539e-3, a.los_rate, 1e-9))
    add(_row("V-24", "RS-1 r̈ [m/s²]", 0.7289650, a.range_accel, 1e-7))
    add(_row("V-24", "RS-1 σ_r, T_d|ṙ| timing [m]", 2.0861400, a.noise_std[0], 1e-7))
    add(_row("V-24", "RS-1 σ_ṙ, T_d|r̈| timing [m/s]", 1.0410027e-2, a.noise_std[1], 1e-9))
    lit_r, lit_rdot = sar_noise_std(table6_budget(timing_model="literal"), r, rdot, RS1_SPEED)
    add(_row("V-24", "RS-1 σ_r, literal T_d·r timing [m]", 29.36661, lit_r, 1e-5))
    add(_row("V-24", "RS-1 σ_ṙ, literal T_d·ṙ timing [m/s]", 0.1369469, lit_rdot, 1e-7))
    add(_row("V-24", "RS-1 σ_A = σ_E [mrad]", 0.7035624, a.noise_std[2] / MRAD, 1e-7))
    for name, cov, cep, paper, paper_cep in (
        ("least squares", a.least_squares_cov, a.cep_least_squares, (2.080825, 7.591038, 19.273055), 5.592468),
        ("consider", a.consider_cov, a.cep_consider, (2.173114, 15.226058, 39.627643), 10.50533),
        ("closed form", a.closed_form_cov, a.cep_closed_form, (2.086486, 7.863663, 19.907149), 5.759898),
    ):
        sig = np.sqrt(np.diag(np.asarray(cov)))
        for i, axis in enumerate("NED"):
            add(_row("V-24", f"RS-1 {name} σ_{axis} [m]", paper[i], sig[i], 1e-6))
        add(_row("V-24", f"RS-1 {name} horizontal CEP [m]", paper_cep, cep, 1e-6 if name != "consider" else 1e-5))
    s_ls = np.sort(np.sqrt(np.linalg.eigvalsh(np.asarray(a.least_squares_cov)[:2, :2])))
    add(_row("V-24", "RS-1 least squares 0.5887(σ₁ + σ₂) [m]", 5.6938, 0.5887 * s_ls.sum(), 1e-4))
    J = np.asarray(a.closed_form_jacobian)
    for (i, j), paper, digit in (((0, 0), 0.6827631, 1e-7), ((0, 1), -146.4637, 1e-4), ((1, 0), 0.6827631, 1e-7),
                                 ((1, 1), 146.4637, 1e-4), ((1, 3), 10776.31, 1e-2), ((2, 0), 0.2601327, 1e-7),
                                 ((2, 3), -28284.27, 1e-2)):
        add(_row("V-24", f"RS-1 closed-form J[{'NED'[i]}, {('r', 'ṙ', 'A', 'E')[j]}]", paper, J[i, j], digit))
    la = atmospheric_loss(r)
    snr = signal_to_noise(10.0, r)
    cnr = signal_to_noise(clutter_cross_section(1.0, 1.0), r)
    cnr1 = signal_to_noise(clutter_cross_section(1.0, 1.0), r, range_exponent=1.0)
    scnr = signal_to_clutter_noise(snr, cnr)
    add(_row("V-24", "RS-1 L_a", 0.8644257, la, 1e-7))
    add(_row("V-24", "RS-1 SNR, ρ_t = 10 m²", 5943.65, snr, 1e-2))
    add(_row("V-24", "RS-1 SNR [dB]", 37.741, to_db(snr), 1e-3))
    add(_row("V-24", "RS-1 CNR, n = 4", 59.4365, cnr, 1e-4))
    add(_row("V-24", "RS-1 CNR, n = 4 [dB]", 17.741, to_db(cnr), 1e-3))
    add(_row("V-24", "RS-1 SCNR = SNR/(CNR + 1)", 98.345, scnr, 1e-3))
    add(_row("V-24", "RS-1 SCNR [dB]", 19.928, to_db(scnr), 1e-3))
    add(_row("V-24", "RS-1 ref [2] K = 1/(2√SCNR)", 0.05042, designation_factor_ref2(scnr), 1e-5))
    add(_row("V-24", "RS-1 CNR, literal n = 1", 0.44265, cnr1, 1e-5))
    add(_row("V-24", "RS-1 CNR, literal n = 1 [dB]", -3.54, to_db(cnr1), 1e-2))
    add(_row("V-24", "RS-1 rain L_r, η = 10 mm/h", 0.0261934, rain_loss(r, 10.0), 1e-7))
    add(_row("V-24", "exact CEP / σ, circular Gaussian", 1.1774100,
             circular_error_probable(jnp.eye(2)), 1e-7))
    return rows


def reproduce(out_dir) -> tuple[list[PaperRow], list[str]]:
    """Compute every row of :func:`paper_rows` and write the study's figures as PNG into ``out_dir``.

    **Arguments:** ``out_dir``: a directory (str or path) for the PNG files.

    **Returns:** ``(rows, figure paths)``.
    """
    single = single_look_analysis(rs1_look())
    rows = paper_rows(single)
    analyses = {c: rs1_covariance_analysis(c) for c in CASES}
    figures = write_figures(out_dir, [
        ("rs1_single_look.png", lambda: figure_single_look(single)),
        ("rs1_target_error.png", lambda: figure_target_error(analyses)),
        ("rs1_shared_position_error.png", lambda: figure_shared_position_error(analyses["radar"])),
        ("ins_error_responses.png", figure_ins_error_responses),
    ])
    return rows, figures

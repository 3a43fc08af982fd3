"""Paper rows of Ho (1968), "Sensitivity of the Kalman filter with respect to parameter variations".

Every printed number of Sec. III-E and Sec. IV that jaxtrack reproduces, the Sec. III algorithm
targets, and :func:`reproduce` (``jaxtrack reproduce ho``): table rows plus the figures as PNG.
Specification: ``specs/ho-sensitivity.md``.
"""

from __future__ import annotations

import numpy as np

from ... import design
from ...sensitivity import updated_position_variance
from .._report import PaperRow, printed_rtol, write_figures
from .analysis import sec4_example1, sec4_example3, segment_sensitivities, velocity_measurement_estimate
from .figures import (
    figure_adjoint,
    figure_covariance_curves,
    figure_designed_schedules,
    figure_one_stage_sensitivity,
    figure_segment_sensitivity,
)
from .scenario import (
    COARSE,
    HO_RULE_1G,
    HO_RULE_10G,
    UNIFORM,
    adjoint_history,
    covariance_at,
    terminal_position_variance,
)
from .schedules import allocation_example, design_comparison, newton_example, segment_problem


def paper_rows(include_design: bool = True) -> list[PaperRow]:
    """Every printed number of Sec. III-E and Sec. IV that jaxtrack reproduces, as table rows.

    Tolerances: rtol 5e-3 for the paper's values (spec §5.3; the paper's own computations differ
    from exact ones by ~0.1%), or half a unit in the last printed digit when that is coarser.
    Every reference number here is printed in the memo (``source="paper"``, after the spec's OCR
    fixes such as "854" → 894); the design rows are the spec's reference values (``"spec"``).

    **Arguments:** ``include_design``: also the Sec. III algorithm rows of :func:`design_rows`.

    **Returns:** a list of :class:`~jaxtrack.applications._report.PaperRow` (units in each quantity).
    """
    rows: list[PaperRow] = []
    add = rows.append
    terminal = [
        ("T16", "P_T(1,1) 1 g (10,10,10,10,10) [ft²]", UNIFORM, 1.0, False, 876),
        ("T17", "P_T(1,1) 1 g (8,8,8,8,8) [ft²]", COARSE, 1.0, False, 1060),
        ("T18", "P_T(1,1) 1 g (10,5,5,10,10) [ft²] (OCR '854' = 894)", HO_RULE_1G, 1.0, False, 894),
        ("T19", "P_T(1,1) 10 g (10,10,10,10,10) [ft²]", UNIFORM, 10.0, False, 2249),
        ("T20", "P_T(1,1) 10 g (5,5,10,10,10) [ft²]", HO_RULE_10G, 10.0, False, 2250),
        ("T21", "P_T(1,1) 10 g (8,8,8,8,8) [ft²]", COARSE, 10.0, False, 2600),
        ("T22", "P_T(1,1) 10 g R=10³/τ (10,10,10,10,6) [ft²]", (10, 10, 10, 10, 6), 10.0, True, 2070),
    ]
    values = {}
    for tid, quantity, counts, g, smoothed, paper in terminal:
        values[tid] = terminal_position_variance(counts, g, smoothed=smoothed)
        add(PaperRow(tid, quantity, paper, values[tid], 5e-3, source="paper"))
    base_smoothed = terminal_position_variance(UNIFORM, 10.0, smoothed=True)
    add(PaperRow("T22", "reduction from 2249 by (10,10,10,10,6), R=10³/τ [ft²]", 179,
                 base_smoothed - values["T22"], printed_rtol(179, 1), source="paper"))

    p1 = covariance_at(UNIFORM, 1.0, 1.0)
    for (i, j), paper in {(0, 0): 3422, (0, 1): 5380, (1, 1): 11973}.items():
        add(PaperRow("T23", f"P({i + 1},{j + 1}) at t = 1 s, 1 g (Sec. IV Ex. 1 input)", paper, float(p1[i, j]), 2e-3, source="paper"))
    p22_35 = float(covariance_at(UNIFORM, 1.0, 3.5)[1, 1])
    p22_43 = float(covariance_at(UNIFORM, 10.0, 4.3)[1, 1])
    add(PaperRow("T24", "P(2,2) at 3.5 s, 1 g [(ft/s)²]", 413, p22_35, 5e-3, source="paper"))
    add(PaperRow("T24", "P(2,2) at 4.3 s, 10 g [(ft/s)²]", 8240, p22_43, 5e-3, source="paper"))

    add(PaperRow("T29", "1 g (8,…) deterioration over (10,…) [%]", 21,
                 100 * (values["T17"] / values["T16"] - 1), printed_rtol(21, 1), source="paper"))
    # The paper derives these two from its rounded terminal values (2600 read off a plot to ±5,
    # 894 and 876 to ±0.5), so the tolerance is that rounding carried through: ±0.22 percentage
    # points and ±1 ft². (From its own 2600 and 2249 the increase is 15.6%, not 15.5%.)
    add(PaperRow("T29", "10 g (8,…) increase over (10,…) [%]", 15.5,
                 100 * (values["T21"] / values["T19"] - 1), (100 * 5 / 2249) / 15.5, source="paper"))
    add(PaperRow("T29", "1 g (10,5,5,10,10) increase over (10,…) [ft²]", 18,
                 values["T18"] - values["T16"], 1.0 / 18, source="paper"))

    # Sec. III-E segment sensitivities (Convention 3) and adjoints
    s1 = segment_sensitivities(UNIFORM, 1.0)
    add(PaperRow("T25", "s(τ_2), 1 g, time-fixed [ft²/s] (Fig. 8)", 227, float(s1.time_fixed[1]), 5e-3, source="paper"))
    add(PaperRow("T25", "s(τ_3), 1 g, time-fixed [ft²/s] (Fig. 8)", 331, float(s1.time_fixed[2]), 5e-3, source="paper"))
    add(PaperRow("T25", "predicted ΔP_T for (10,5,5,10,10): 0.1(s_2+s_3) [ft²]", 55.8,
                 0.1 * float(s1.time_fixed[1] + s1.time_fixed[2]), 5e-3, source="paper"))
    order = np.argsort(s1.time_fixed) + 1
    add(PaperRow("T25", "least-sensitive segment (1 g)", 2, float(order[0]), 0.0, source="paper"))
    add(PaperRow("T25", "next least-sensitive segment (1 g)", 3, float(order[1]), 0.0, source="paper"))
    L1, t1 = adjoint_history(UNIFORM, 1.0)
    k_max = int(np.argmax(L1[:, 1, 1]))
    add(PaperRow("T28", "max of L22 (1 g), Fig. 9 curve b", 0.4, float(L1[k_max, 1, 1]), 0.05, source="paper"))
    add(PaperRow("T28", "time of the L22 maximum (1 g) [s]", 3.5, float(t1[k_max]), 0.05, source="paper"))
    v1 = velocity_measurement_estimate(3.5, 1.0)
    v10 = velocity_measurement_estimate(4.3, 10.0)
    add(PaperRow("T28", "L22 at 4.3 s (10 g), Fig. 12", 0.05, float(v10.L22), 0.05, source="paper"))
    add(PaperRow("T29", "velocity-measurement gain 0.4×313, 1 g [ft²]", 125, float(v1.estimate), 0.05, source="paper"))
    add(PaperRow("T29", "velocity-measurement gain 0.05×8140, 10 g [ft²]", 407, float(v10.estimate), 0.05, source="paper"))

    # Sec. IV one-stage examples (formula values; spec §5.4)
    ex1 = sec4_example1(0.1)
    for key, quantity, paper, digit in (
        ("rho", "ρ = 5380/6400 (eq. 137)", 0.840, 0.001),
        ("tau_scale", "τ/τ* = sqrt(p_v*/p_x*) (eq. 137)", 1.87, 0.01),
        ("r_x", "r_x = 10⁴/3422 (eq. 138)", 2.92, 0.01),
        ("alpha", "α in q_x = ατ (eq. 138)", 4.05e-5, 1e-7),
        ("a", "a = 2ρ + α (eq. 131)", 1.68, 0.01),
        ("p_x", "(p_x)_k/k at τ* = 0.1 s (eq. 139)", 0.92, 0.01),
    ):
        add(PaperRow("T30", quantity, paper, float(getattr(ex1, key)), printed_rtol(paper, digit), source="paper"))
    add(PaperRow("T15", "(p_x*)_k/k at τ* = 0.1 s, 3422 → [ft²]", 3150, float(ex1.p_x_ft2), 5e-3, source="paper"))
    # Ex. 2 (eq. 140): smoothed data, r_x ∝ 1/τ through the Ex. 1 point: r_x = 2.92·0.187/τ
    tau2 = 0.2 * float(ex1.tau_scale)
    r_smoothed = float(ex1.r_x) * float(ex1.tau) / tau2
    p_smoothed = float(updated_position_variance(float(ex1.a), tau2, r_smoothed))
    add(PaperRow("T31", "(p_x)_k/k at τ* = 0.2 s, smoothed r_x = 0.187·2.92/τ", 0.8, p_smoothed, printed_rtol(0.8, 0.1), source="paper"))
    ex3 = sec4_example3()
    add(PaperRow("T32", "(p_x)_k/k at τ = 1, a = 1, r_x = 1", 0.75, float(ex3.p_x), 1e-9, source="paper"))
    add(PaperRow("T32", "a needed at τ = 2 to keep 0.75", -1.0, float(ex3.a_needed), 1e-9, source="paper"))
    add(PaperRow("T32", "r_x needed at τ = 2 to keep 0.75 ('about 0.8')", 0.8, float(ex3.r_x_needed), printed_rtol(0.8, 0.1), source="paper"))
    if include_design:
        rows.extend(design_rows())
    return rows


def design_rows() -> list[PaperRow]:
    """Sec. III algorithm targets T33–T35 (spec §5.5; reference values, not printed in the memo:
    ``source="spec"``).

    **Returns:** a list of :class:`~jaxtrack.applications._report.PaperRow`.
    """
    rows: list[PaperRow] = []
    add = rows.append
    newton = newton_example()
    for i, ref in enumerate((0.1, 0.145801, 0.137330, 0.137153, 0.13715278)):
        add(PaperRow("T33", f"Newton iterate {i} of τ for J* = 1000 ft² [s]", ref, float(newton.taus[i]), 1e-5, source="spec"))
    for g, ref in ((1.0, 585.8), (10.0, 1416.0)):
        c = design_comparison(g)
        add(PaperRow("T34", f"exhaustive optimum, 40 samples, caps [1,20], {g:g} g [ft²]", ref, float(c.optimum.cost), 1e-4, source="spec"))
        add(PaperRow("T34", f"gradient design (optax + rounding + local search), {g:g} g [ft²]", ref, float(c.gradient.cost), 1e-2, source="spec"))
    ho_counts = design.ho_reduction(segment_problem(1.0), UNIFORM, 10)
    add(PaperRow("T34", "Ho's rule (10,…) − 10 samples, 1 g [ft²] (10,5,5,10,10)", 893.55,
                 terminal_position_variance(ho_counts, 1.0), 1e-5, source="spec"))
    alloc = allocation_example()
    add(PaperRow("T35", "Σ(c_i + Δc_i) after allocation (78) [Hz]", float(alloc.capacity), float(alloc.new_total_rate), 1e-12, source="spec"))
    dJ = np.asarray(alloc.dJ_predicted)
    for i in (1, 2):
        add(PaperRow("T35", f"equal degradation (77): s_{i + 1}Δc_{i + 1} / s_1Δc_1", 1.0, float(dJ[i] / dJ[0]), 1e-12, source="spec"))
    return rows


def reproduce(out_dir) -> tuple[list[PaperRow], list[str]]:
    """Compute every row of :func:`paper_rows` and write the Sec. III-E figures as PNG into ``out_dir``.

    **Arguments:** ``out_dir``: folder for the PNG files (created if missing).

    **Returns:** ``(rows, figure_paths)``.
    """
    rows = paper_rows()
    figures = write_figures(out_dir, [
        ("fig07_covariance_1g.png", lambda: figure_covariance_curves(1.0)),
        ("fig08_segment_sensitivity_1g.png", lambda: figure_segment_sensitivity(1.0)),
        ("fig09_adjoint_1g.png", lambda: figure_adjoint(1.0)),
        ("fig10_covariance_10g.png", lambda: figure_covariance_curves(10.0)),
        ("fig11_segment_sensitivity_10g.png", lambda: figure_segment_sensitivity(10.0)),
        ("fig12_adjoint_10g.png", lambda: figure_adjoint(10.0)),
        ("fig13_segment_sensitivity_smoothed_1g.png", lambda: figure_segment_sensitivity(1.0, smoothed=True)),
        ("fig13_segment_sensitivity_smoothed_10g.png", lambda: figure_segment_sensitivity(10.0, smoothed=True)),
        ("fig16_17_one_stage_sensitivity.png", figure_one_stage_sensitivity),
        ("design_schedules_1g.png", lambda: figure_designed_schedules(1.0)),
    ])
    return rows, figures

"""The radar-bias study's paper rows and :func:`reproduce` (``jaxtrack reproduce bias``)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .._report import PaperRow, write_figures
from .absolute import printed_cost
from .figures import figure_alpha_beta_plane, figure_bias_examples, figure_gain_transient
from .scenario import _EXAMPLE_WEIGHTS, E_NAMES, EXAMPLES, solve_example
from .steady_state import PAPER_BETA_TABLE, paper_beta, paper_quartic_real_roots


def paper_rows() -> list[PaperRow]:
    """Every number the paper prints that jaxtrack reproduces, as table rows.

    - V7: the 24 printed Δ values of examples a–d (rtol 1e-4; spec §4). The four printed zeros
      (example b, Δψ1, Δψ2) pass only if the solver returns them exactly (it does: sin 0 = 0).
    - V8: the printed "Cost" of each example, as Σ e²/k² (spec A8; F(e*) itself is 1.9e5, 1.45e5).
    - V19: the 9 rows of the β table, both printed roots of (104); tolerance atol 5e-5 (spec §4,
      A22) expressed as rtol.

    Every reference number is printed in the paper (``source="paper"``): the Δ values and costs
    of §2.3 and both real roots of each row of the β table.
    """
    rows: list[PaperRow] = []
    weights = jnp.asarray(_EXAMPLE_WEIGHTS)
    for name, ex in EXAMPLES.items():
        sol = solve_example(name)
        e = np.asarray(jnp.concatenate([sol.e1, sol.e2]))
        for label, paper, value in zip(E_NAMES, ex.printed_e, e):
            rows.append(PaperRow("V7", f"example {name}: {label}", paper, float(value), 1e-4, source="paper"))
        rows.append(PaperRow("V8", f"example {name}: printed 'Cost' = Σe²/k² [m²] (F* = {float(sol.cost):.4g})",
                             ex.printed_cost, float(printed_cost(e, weights)), 1e-4, source="paper"))
    for rho, alpha, beta_paper, other in PAPER_BETA_TABLE:
        rows.append(PaperRow("V19", f"ρ={rho:g}, α={alpha:g}: β, real root of cubic of (105)", beta_paper,
                             float(paper_beta(alpha, rho)), 5e-5 / beta_paper, source="paper"))
        rows.append(PaperRow("V19", f"ρ={rho:g}, α={alpha:g}: other real root of (104)", other,
                             float(paper_quartic_real_roots(alpha, rho)[-1]), 5e-5 / other, source="paper"))
    return rows


def reproduce(out_dir) -> tuple[list[PaperRow], list[str]]:
    """Compute every row of :func:`paper_rows` and write the study's figures as PNG into ``out_dir``."""
    rows = paper_rows()
    figures = write_figures(out_dir, [
        ("sec2_costs.png", figure_bias_examples),
        ("sec3_gain_transient.png", figure_gain_transient),
        ("sec3_alpha_beta_plane.png", figure_alpha_beta_plane),
    ], dpi=110)
    return rows, figures

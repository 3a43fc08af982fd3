"""``jaxtrack demo``: Monte Carlo of a 2-D constant-velocity tracker, matched and mismatched."""

from __future__ import annotations

import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ..applications._report import atomic_path
from ..filters import KalmanFilter, run_filter
from ..models import constant_velocity
from ..montecarlo import monte_carlo

# Scenario: 1 Hz position fixes with 10 m noise on a target whose acceleration is white noise of
# spectral density 0.5 m²/s³ (a slowly maneuvering ship or aircraft in cruise).
SAMPLING_PERIOD = 1.0  # s
ACCEL_PSD = 0.5  # m²/s³
MEASUREMENT_STD = 10.0  # m
INITIAL_STD = (100.0, 100.0, 10.0, 10.0)  # m, m, m/s, m/s


def demo_models():
    """The true model and two filter models: matched, and Q 10× too small."""
    prior = jnp.diag(jnp.asarray(INITIAL_STD) ** 2)
    truth = constant_velocity(
        SAMPLING_PERIOD, dim=2, accel_psd=ACCEL_PSD, measurement_std=MEASUREMENT_STD, initial_cov=prior
    )
    small_q = constant_velocity(
        SAMPLING_PERIOD, dim=2, accel_psd=ACCEL_PSD / 10, measurement_std=MEASUREMENT_STD, initial_cov=prior
    )
    return truth, {"matched": truth, "Q/10": small_q}


def filter_rmse(model, num_steps: int, components) -> np.ndarray:
    """The RMSE the filter predicts for itself, √tr of a block of P_{k/k} (data-free)."""
    zeros = jnp.zeros((num_steps, model.meas_dim))
    covs = run_filter(KalmanFilter(), model, zeros).filtered_cov
    idx = jnp.asarray(components)
    return np.sqrt(np.asarray(jnp.trace(covs[:, idx][:, :, idx], axis1=1, axis2=2)))


def run_demo(num_runs: int = 10_000, num_steps: int = 100, seed: int = 0, out_dir: str | Path = "results/demo",
             chunk_size: int = 2_000, progress: bool = True, mesh=None, write: bool = True) -> dict:
    """Run the demo, write ``demo.png`` and ``demo.json`` into ``out_dir``, return the table rows.

    ``rows``: one dict per filter (keys and units in ``jaxtrack/cli/schemas/demo.schema.json``);
    ``figure`` and ``table``: the written paths (None when ``write=False``); ``results`` and
    ``theory``: the Monte Carlo results and √tr P curves behind the figure (:func:`demo_figure`).

    ``mesh``: share the runs over a device mesh (see :func:`jaxtrack.montecarlo.run_mesh`; the
    numbers are those of one device). ``write=False`` skips the files (processes other than 0).
    """
    truth, filters = demo_models()
    key = jax.random.key(seed)
    results, rows, theory = {}, [], {}
    for label, model in filters.items():
        t0 = time.perf_counter()
        res = monte_carlo(truth, key, num_runs, num_steps=num_steps, filter_model=model,
                          chunk_size=chunk_size, progress=progress, mesh=mesh)
        elapsed = time.perf_counter() - t0
        results[label] = res
        pos = filter_rmse(model, num_steps, (0, 1))
        vel = filter_rmse(model, num_steps, (2, 3))
        theory[(label, "position")] = pos
        theory[(label, "velocity")] = vel
        lo, hi = (float(b) for b in res.anees_bounds)
        rows.append({
            "filter": label,
            "runs": res.num_runs,
            "failed": res.num_failed,
            "final_position_rmse_m": float(res.rmse((0, 1))[-1]),
            "filter_position_sigma_m": float(pos[-1]),
            "final_velocity_rmse_mps": float(res.rmse((2, 3))[-1]),
            "filter_velocity_sigma_mps": float(vel[-1]),
            "anees": float(res.anees),
            "anees_lo": lo,
            "anees_hi": hi,
            "consistent": bool(lo <= float(res.anees) <= hi),
            "nees_steps_inside": float(res.fraction_nees_inside()),
            "seconds": elapsed,
        })
    out = Path(out_dir)
    if not write:
        return {"rows": rows, "figure": None, "table": None, "results": results, "theory": theory}
    out.mkdir(parents=True, exist_ok=True)
    fig = demo_figure(results, theory, num_steps)
    # Temporary names renamed when complete: Ctrl-C while saving leaves no partial file. The
    # figure is closed here, by its writer (demo_figure returns it open, as plotting does).
    try:
        with atomic_path(out / "demo.png") as tmp:
            fig.savefig(tmp, dpi=120, format="png")
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)
    with atomic_path(out / "demo.json") as tmp:
        tmp.write_text(json.dumps(json_document(rows), indent=2))
    return {"rows": rows, "figure": str(out / "demo.png"), "table": str(out / "demo.json"),
            "results": results, "theory": theory}


def demo_figure(results: dict, theory: dict, num_steps: int):
    """The demo's figure: position and velocity RMSE against √tr P, and NEES in its χ² band.

    **Arguments:**

    - ``results``: filter label → :class:`~jaxtrack.montecarlo.MonteCarloResult`.
    - ``theory``: ``(label, "position" | "velocity")`` → ``(num_steps,)`` √tr P, m and m/s.
    - ``num_steps``: steps per run (time axis ``SAMPLING_PERIOD × k``, s).

    **Returns:** the matplotlib ``Figure`` (the caller saves and closes it).
    """
    from ..plotting import plot_monte_carlo

    fig = plot_monte_carlo(
        results,
        rmse_components={"position": (0, 1), "velocity": (2, 3)},
        theory_rmse=theory,
        times=SAMPLING_PERIOD * np.arange(num_steps),
        rmse_unit={"position": "m", "velocity": "m/s"},
    )
    fig.suptitle(f"2-D constant velocity, τ = {SAMPLING_PERIOD} s, q = {ACCEL_PSD} m²/s³, σ = {MEASUREMENT_STD} m")
    return fig


# Version of the JSON written by ``demo --json`` and into demo.json; raise it when a key changes
# meaning or disappears (adding a key keeps it). The schema: jaxtrack/cli/schemas/demo.schema.json.
SCHEMA_VERSION = 1


def json_document(rows: list[dict]) -> dict:
    """The ``demo --json`` document: ``{"schema_version": 1, "rows": rows}``.

    **Arguments:** ``rows``: the table rows of :func:`run_demo` (one dict per filter).

    **Returns:** the dict printed by ``jaxtrack demo --json`` and written to ``demo.json``; its
    keys, types and units are in ``jaxtrack/cli/schemas/demo.schema.json``.
    """
    return {"schema_version": SCHEMA_VERSION, "rows": rows}


def format_table(rows) -> str:
    head = (f"{'filter':<8} {'runs':>6} {'pos RMSE':>9} {'√trP_pos':>9} {'vel RMSE':>9} {'√trP_vel':>9} "
            f"{'ANEES':>7} {'95% bounds':>17} {'consistent':>10}")
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r['filter']:<8} {r['runs']:>6} {r['final_position_rmse_m']:>9.3f} {r['filter_position_sigma_m']:>9.3f} "
            f"{r['final_velocity_rmse_mps']:>9.3f} {r['filter_velocity_sigma_mps']:>9.3f} {r['anees']:>7.3f} "
            f"[{r['anees_lo']:.3f}, {r['anees_hi']:.3f}] {'yes' if r['consistent'] else 'NO':>10}"
        )
    lines.append("RMSE and √tr P at the last step, in m and m/s.")
    return "\n".join(lines)

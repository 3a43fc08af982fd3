"""Monte Carlo: simulate truth and measurements, blocks of runs, streaming consistency metrics,
on one device or sharded over devices and hosts."""

from ._cep import circular_error_probable as circular_error_probable
from ._ospa import GOSPA as GOSPA, OSPA as OSPA, gospa as gospa, ospa as ospa
from ._engine import MonteCarloInterrupted as MonteCarloInterrupted, monte_carlo_map as monte_carlo_map
from ._differentiable import differentiable_monte_carlo as differentiable_monte_carlo
from ._metrics import (
    Interval as Interval,
    chi2_mean_bounds as chi2_mean_bounds,
    normalized_squared_error as normalized_squared_error,
    time_averaged_rmse as time_averaged_rmse,
    time_averaged_rmse_ratio as time_averaged_rmse_ratio,
)
from ._run import (
    MonteCarloResult as MonteCarloResult,
    monte_carlo as monte_carlo,
    monte_carlo_sweep as monte_carlo_sweep,
)
from ._result import summarize_runs as summarize_runs
from ._sharding import run_mesh as run_mesh, sweep_mesh as sweep_mesh
from ._simulate import (
    Trajectory as Trajectory,
    psd_sqrt as psd_sqrt,
    simulate as simulate,
    simulate_step as simulate_step,
)

__all__ = [
    "circular_error_probable",
    "GOSPA",
    "OSPA",
    "gospa",
    "ospa",
    "monte_carlo_map",
    "MonteCarloInterrupted",
    "Interval",
    "chi2_mean_bounds",
    "normalized_squared_error",
    "time_averaged_rmse",
    "time_averaged_rmse_ratio",
    "MonteCarloResult",
    "monte_carlo",
    "monte_carlo_sweep",
    "summarize_runs",
    "run_mesh",
    "sweep_mesh",
    "Trajectory",
    "psd_sqrt",
    "simulate",
    "simulate_step",
    "differentiable_monte_carlo",
]

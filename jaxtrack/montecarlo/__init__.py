"""Monte Carlo: simulate truth and measurements, vmap over run keys, streaming consistency metrics."""

from ._metrics import (
    chi2_mean_bounds as chi2_mean_bounds,
    normalized_squared_error as normalized_squared_error,
)
from ._run import MonteCarloResult as MonteCarloResult, monte_carlo as monte_carlo
from ._simulate import (
    Trajectory as Trajectory,
    psd_sqrt as psd_sqrt,
    simulate as simulate,
    simulate_step as simulate_step,
)

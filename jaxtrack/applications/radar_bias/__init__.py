"""Study: Serakos, Gray, Youssef, "Topics in mitigating radar bias" (NSWC Dahlgren).

Everything the CLI (``jaxtrack reproduce bias``), the notebook and the tests need is here.
Specification: ``specs/radar-bias.md`` (equation numbers are the paper's; "[derived]" marks results
of the spec, not of the paper). The numerics live in the library: frames in
:mod:`jaxtrack.geometry`, the constrained least squares in :mod:`jaxtrack.estimation`, the
reduced-state filter is :class:`jaxtrack.filters.ConsiderKalmanFilter`, the Monte Carlo is
:func:`jaxtrack.montecarlo.monte_carlo_map`.

- ``absolute``: Sec. 2, absolute spherical biases from the relative bias (KKT, three forms);
- ``scenario``: the paper's examples a–d and the Sec. 3 bias models (augmented ``[x; λ]``);
- ``reduced_state``: Sec. 3 general case (42)–(69) through the consider filter;
- ``montecarlo``: the V26 Monte Carlo;
- ``steady_state``: Sec. 3 α-β closed forms, the paper's relation (104), the joint optimum;
- ``figures``; ``rows``: paper rows and :func:`reproduce`.
"""

from .absolute import AbsoluteBias as AbsoluteBias
from .absolute import BiasDescent as BiasDescent
from .absolute import SensorGeometry as SensorGeometry
from .absolute import Site as Site
from .absolute import absolute_bias as absolute_bias
from .absolute import absolute_bias_by_descent as absolute_bias_by_descent
from .absolute import absolute_bias_from_tracks as absolute_bias_from_tracks
from .absolute import bias_cost as bias_cost
from .absolute import bias_sensitivity as bias_sensitivity
from .absolute import constraint_jacobian as constraint_jacobian
from .absolute import printed_cost as printed_cost
from .absolute import relative_bias as relative_bias
from .figures import figure_alpha_beta_plane as figure_alpha_beta_plane
from .figures import figure_bias_examples as figure_bias_examples
from .figures import figure_gain_transient as figure_gain_transient
from .montecarlo import BiasMonteCarlo as BiasMonteCarlo
from .montecarlo import bias_monte_carlo as bias_monte_carlo
from .reduced_state import BiasedTrajectory as BiasedTrajectory
from .reduced_state import EstimationErrors as EstimationErrors
from .reduced_state import ReducedStateHistory as ReducedStateHistory
from .reduced_state import estimation_errors as estimation_errors
from .reduced_state import filtered_total_cov as filtered_total_cov
from .reduced_state import reduced_state_covariance as reduced_state_covariance
from .reduced_state import reduced_state_filter as reduced_state_filter
from .reduced_state import reduced_state_gain as reduced_state_gain
from .reduced_state import simulate_biased as simulate_biased
from .rows import paper_rows as paper_rows
from .rows import reproduce as reproduce
from .scenario import E_NAMES as E_NAMES
from .scenario import EXAMPLES as EXAMPLES
from .scenario import GENERAL_SCENARIO as GENERAL_SCENARIO
from .scenario import NUM_ESTIMATED as NUM_ESTIMATED
from .scenario import ExampleInputs as ExampleInputs
from .scenario import PaperExample as PaperExample
from .scenario import alpha_beta_bias_model as alpha_beta_bias_model
from .scenario import cost_discrepancy_table as cost_discrepancy_table
from .scenario import example_inputs as example_inputs
from .scenario import general_scenario as general_scenario
from .scenario import reduced_state_model as reduced_state_model
from .scenario import solve_example as solve_example
from .steady_state import PAPER_BETA_TABLE as PAPER_BETA_TABLE
from .steady_state import AlphaBetaDescent as AlphaBetaDescent
from .steady_state import SteadyState as SteadyState
from .steady_state import alpha_beta_gain as alpha_beta_gain
from .steady_state import gain_condition_residuals as gain_condition_residuals
from .steady_state import lyapunov_system as lyapunov_system
from .steady_state import noise_covariance_from_measurement as noise_covariance_from_measurement
from .steady_state import noise_covariance_from_plant as noise_covariance_from_plant
from .steady_state import noise_ratio as noise_ratio
from .steady_state import nonoptimality_table as nonoptimality_table
from .steady_state import optimal_alpha_beta as optimal_alpha_beta
from .steady_state import optimise_alpha_beta as optimise_alpha_beta
from .steady_state import paper_beta as paper_beta
from .steady_state import paper_quartic as paper_quartic
from .steady_state import paper_quartic_factored as paper_quartic_factored
from .steady_state import paper_quartic_real_roots as paper_quartic_real_roots
from .steady_state import predicted_noise_covariance_terms as predicted_noise_covariance_terms
from .steady_state import steady_state as steady_state
from .steady_state import steady_state_eigenvalues as steady_state_eigenvalues
from .steady_state import steady_state_objective as steady_state_objective
from .steady_state import steady_state_transition as steady_state_transition

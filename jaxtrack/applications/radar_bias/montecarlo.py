"""Sec. 3 Monte Carlo (V26): the reduced-state filter's terminal errors over many realisations.

Built on :func:`jaxtrack.montecarlo.monte_carlo_map`: run ``i`` uses ``fold_in(key, i)``, draws
x(0), λ (once) and the noises by :func:`~.reduced_state.simulate_biased`, filters with the
library's consider filter and returns ``(ε, εε', εΔλ')`` at the last step; the engine sums them
block by block (memory flat, results independent of block and chunk sizes).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from ..._validation import InputError
from ...filters import ConsiderKalmanFilter
from ...models import LinearGaussianModel
from ...montecarlo import monte_carlo_map
from .reduced_state import reduced_state_covariance, terminal_error_moments


class BiasMonteCarlo(eqx.Module):
    """Terminal-step Monte Carlo statistics of the reduced-state filter (V26).

    - ``num_runs``: number of realisations.
    - ``error_mean`` ``(n,)``: sample mean of ε(T|T).
    - ``error_cov`` ``(n, n)``: sample covariance of ε(T|T) (compare with S(T|T)).
    - ``sensitivity`` ``(n, p)``: sample ``E[ε Δλ'] Λ⁻¹`` (compare with D(T|T); pseudo-inverse of Λ).
    """

    num_runs: int = eqx.field(static=True)
    error_mean: Float[Array, " n"]
    error_cov: Float[Array, "n n"]
    sensitivity: Float[Array, "n p"]


def bias_monte_carlo(model: LinearGaussianModel, num_estimated: int, key: PRNGKeyArray, num_runs: int,
                     num_steps: int, *, block_size: int = 512, progress: bool = False) -> BiasMonteCarlo:
    """Monte Carlo of the general-case filter (V26) with :func:`jaxtrack.montecarlo.monte_carlo_map`.

    Each run draws x(0) ~ N(x̂(0|0), P0), λ ~ N(λ̄, Λ) once, and the plant and measurement noise;
    the filter (optimal gains (69), computed once) subtracts only λ̄.

    **Arguments:** ``model`` from :func:`~.scenario.reduced_state_model`; ``num_estimated`` n;
    ``key``; ``num_runs`` ≥ 2; ``num_steps`` T; ``block_size`` runs per compiled block;
    ``progress`` a progress bar.

    **Returns:** a :class:`BiasMonteCarlo`.
    """
    if isinstance(num_runs, bool) or not isinstance(num_runs, int) or num_runs < 2:
        raise InputError(f"`num_runs` must be an int ≥ 2; got {num_runs!r}.")
    gains = reduced_state_covariance(model, num_estimated, num_steps).gain
    s1, s2, s3 = monte_carlo_map(terminal_error_moments, key, num_runs,
                                 args=(model, ConsiderKalmanFilter(num_estimated, gains)),
                                 block_size=block_size, progress=progress)
    total = num_runs
    mean = s1 / total
    cov = (s2 - total * np.outer(mean, mean)) / (total - 1)
    lam = np.asarray(model.initial_cov[num_estimated:, num_estimated:])
    sens = (s3 / total) @ np.linalg.pinv(lam)
    return BiasMonteCarlo(total, jnp.asarray(mean), jnp.asarray(cov), jnp.asarray(sens))

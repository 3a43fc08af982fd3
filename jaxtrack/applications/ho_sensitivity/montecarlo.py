"""Monte Carlo check of Ho's (1968) III-D maneuver compensation, on :func:`jaxtrack.montecarlo.monte_carlo`."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ...montecarlo import monte_carlo
from .schedules import ManeuverExample, maneuver_example


class ManeuverMonteCarlo(eqx.Module):
    """Empirical terminal position-error variances of :func:`maneuver_monte_carlo`.

    - ``theory``: the :class:`ManeuverExample` (its ``nominal``, ``uncompensated`` and
      ``compensated`` J, ft²).
    - ``uncompensated``, ``compensated``: Monte Carlo ``E[(p − p̂)²]`` at the last stage, ft².
    - ``rel_halfwidth``: ``3·sqrt(2/M)``, the 99.7% half-width of a variance estimate's
      relative error; ``runs``: ``M``.
    """

    theory: ManeuverExample
    uncompensated: Float[Array, ""]
    compensated: Float[Array, ""]
    rel_halfwidth: Float[Array, ""]
    runs: int = eqx.field(static=True)


def maneuver_monte_carlo(runs: int = 20_000, seed: int = 0, **kwargs) -> ManeuverMonteCarlo:
    """Monte Carlo of :func:`maneuver_example`: empirical terminal position-error variance with and
    without the period change (truth and matched filter share the raised noise).

    Both configurations use the same key (common random numbers); run ``i`` draws from
    ``jax.random.fold_in(key, i)`` inside :func:`~jaxtrack.montecarlo.monte_carlo`.

    **Arguments:** ``runs`` M; ``seed`` the PRNG seed; ``kwargs`` for :func:`maneuver_example`.

    **Returns:** :class:`ManeuverMonteCarlo`.
    """
    ex = maneuver_example(**kwargs)
    key = jax.random.key(seed)
    mse = {}
    for name, tau in (("uncompensated", 0.1), ("compensated", ex.tau)):
        mc = monte_carlo(ex.model_fn(tau, ex.a), key, runs, first_step="predict", progress=False)
        mse[name] = mc.rmse((0,))[-1] ** 2
    return ManeuverMonteCarlo(theory=ex, rel_halfwidth=jnp.asarray(3.0 * np.sqrt(2.0 / runs)), runs=runs, **mse)

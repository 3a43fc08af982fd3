r"""One clutter vocabulary for scenarios, trackers and random-finite-set filters.

Clutter is a Poisson point process on a region of measurement space (Bar-Shalom, Willett & Tian
2011, §3.4; Mahler 2007, §12.3). Three numbers describe it, with one relation:

- ``clutter_rate`` ``λ``: the mean number of clutter points per scan (dimensionless) — what a
  :class:`~jaxtrack.multitarget.Scenario` draws (``Poisson(λ)`` points a scan) and the GM-CPHD's
  cardinality needs;
- ``clutter_volume`` ``V``: the measure of the clutter region in measurement space (m² for
  positions, m·rad for range and bearing: the product of the region's widths);
- ``clutter_density`` ``κ = λ / V``: the clutter intensity, points per unit measurement volume per
  scan — what the association weights and the PHD/PMBM updates divide by. Stone Soup calls it
  ``clutter_spatial_density`` (``PDAHypothesiser``, ``PHDUpdater``); jaxtrack accepts that name
  too, with the same meaning, so a Stone Soup user's number carries over.

Every multi-target constructor (:class:`~jaxtrack.multitarget.Tracker`, ``GMPHD``, ``GMCPHD``,
``PMB``, ``PMBM``, ``GLMB``, ``LMB``) takes ``clutter_density`` (or ``clutter_spatial_density``), or ``clutter_rate``
with ``clutter_volume``; ``scenario.clutter_density`` converts a scenario's rate and region.
"""

from __future__ import annotations

import numpy as np

from .._validation import InputError, is_concrete


def resolve_clutter(cls: str, *, clutter_density=None, clutter_spatial_density=None, clutter_rate=None,
                    clutter_volume=None):
    """``(κ, λ or None, V or None)`` from the keywords a constructor was given (module docstring),
    or :class:`~jaxtrack.InputError` naming them: ``κ`` by either of its names (not both), or
    ``λ / V`` from ``clutter_rate`` and ``clutter_volume``; all three given must agree (when
    concrete, to 1e-12 relative). Values stay arrays (traced ones pass; each constructor checks
    ranges)."""
    import jax.numpy as jnp

    if clutter_density is not None and clutter_spatial_density is not None:
        raise InputError(f"{cls}: give `clutter_density` or its Stone Soup name `clutter_spatial_density`, not both "
                         "(the same κ = λ/V, clutter points per unit measurement volume per scan).")
    kappa = clutter_density if clutter_density is not None else clutter_spatial_density
    name = "clutter_density" if clutter_density is not None else "clutter_spatial_density"
    rate = None if clutter_rate is None else jnp.asarray(clutter_rate, float)
    volume = None if clutter_volume is None else jnp.asarray(clutter_volume, float)
    if volume is not None and (volume.shape != () or (is_concrete(volume) and not 0.0 < float(volume) < np.inf)):
        raise InputError(f"`clutter_volume` must be a finite positive scalar (the clutter region's measure in "
                         f"measurement space); got {np.asarray(clutter_volume)!r}.")
    if kappa is None:
        if rate is None or volume is None:
            raise InputError(f"{cls} needs the clutter: `clutter_density` κ (per unit measurement volume per scan; "
                             "Stone Soup's `clutter_spatial_density`), or `clutter_rate` λ with `clutter_volume` V "
                             "(κ = λ/V; a Scenario's `clutter_density` property converts its own).")
        return rate / volume, rate, volume
    kappa = jnp.asarray(kappa, float)
    if rate is not None and volume is not None and all(map(is_concrete, (kappa, rate, volume))):
        if not np.isclose(float(kappa), float(rate) / float(volume), rtol=1e-12, atol=0.0):
            raise InputError(f"{cls}: `{name}` {float(kappa)} is not `clutter_rate` / `clutter_volume` = "
                             f"{float(rate) / float(volume)}; give two of the three.")
    return kappa, rate, volume

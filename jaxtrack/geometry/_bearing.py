"""Compass angles in a horizontal plane: bearing of a position, course of a velocity.

Navigation convention (x east, y north): angles are measured clockwise from north (+y) toward
east (+x), so a target due east has bearing π/2 and a ship heading north has course 0. This is
the mirror image of the mathematical angle ``atan2(y, x)`` and is what bearings-only target motion
analysis uses (Lindgren & Gong 1977, eq. 5).
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike

__all__ = ["bearing", "course"]


def _float(x: ArrayLike) -> Array:
    x = jnp.asarray(x)
    return x.astype(jnp.result_type(x, float))


def bearing(relative_position: ArrayLike) -> Array:
    """Compass bearing ``β = atan2(r_x, r_y)`` of a position (Lindgren & Gong 1977, eq. 5).

    **Arguments:** ``relative_position`` ``(..., ≥2)``: the first two components are east and north
    ``r_x, r_y`` (any length unit; further components, e.g. velocities, are ignored).

    **Returns:** ``(...)`` rad in (−π, π], clockwise from north: due north 0, due east π/2,
    due west −π/2.
    """
    r = _float(relative_position)
    return jnp.arctan2(r[..., 0], r[..., 1])


def course(velocity: ArrayLike) -> Array:
    """Compass course ``C = atan2(V_x, V_y)`` of a velocity, wrapped to [0, 2π) (Lindgren & Gong, Table 1 item 1-11).

    **Arguments:** ``velocity`` ``(..., ≥2)``: east and north components first (m/s or any unit).

    **Returns:** ``(...)`` rad in [0, 2π), clockwise from north (heading west is 3π/2).
    """
    v = _float(velocity)
    return jnp.remainder(jnp.arctan2(v[..., 0], v[..., 1]), 2 * jnp.pi)

"""Ship-borne radar conventions: compass-azimuth spherical coordinates and the small-angle
attitude error of a stabilised platform.

Source: G. H. Wang, L. Chen, S. Y. Jia, I. Progri, "Optimized Bias Estimation Model for Mobile
Radar Error Registration", *The Journal of Navigation* (2012), eqs 1–9 (specs/obem-registration.md
§1.4). The exact platform rotation is :func:`jaxtrack.geometry.platform_to_enu_rotation`.

Radars report azimuth as a **compass** angle θ: from North, clockwise (towards East). The rest
of :mod:`jaxtrack.geometry` uses the mathematical azimuth ψ (from East, counter-clockwise); the
two are related by ``ψ = π/2 − θ``. Elevation ε is measured up from the horizontal plane in both.
Metres and radians throughout; every function follows its input's floating dtype and is
vectorised over leading axes.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._frames import cartesian_to_spherical, spherical_to_cartesian
from ._rotations import skew

__all__ = [
    "compass_to_math_azimuth",
    "math_to_compass_azimuth",
    "compass_spherical_to_cartesian",
    "cartesian_to_compass_spherical",
    "platform_rotation_vector",
    "platform_attitude_generators",
    "platform_attitude_error_matrix",
]


def _float(x) -> Array:
    x = jnp.asarray(x)
    return x.astype(jnp.result_type(x, float))


def _wrap(angle: Array) -> Array:
    # (−π, π], as jaxtrack.models.wrap_angle (geometry sits below models, so it cannot import it).
    wrapped = jnp.remainder(angle + jnp.pi, 2 * jnp.pi) - jnp.pi
    return jnp.where(wrapped == -jnp.pi, jnp.pi, wrapped)


def compass_to_math_azimuth(azimuth: ArrayLike) -> Float[Array, "..."]:
    """Compass azimuth θ (from North, clockwise) to mathematical azimuth ψ = π/2 − θ (from East,
    counter-clockwise), not wrapped.

    **Arguments:** ``azimuth`` θ, rad, any shape ``(...)``.

    **Returns:** ψ, rad, shape ``(...)``, in (−π/2, 3π/2] for θ ∈ (−π, π].
    """
    return 0.5 * jnp.pi - _float(azimuth)


def math_to_compass_azimuth(azimuth: ArrayLike) -> Float[Array, "..."]:
    """Mathematical azimuth ψ (from East, counter-clockwise) to compass azimuth θ = π/2 − ψ,
    wrapped to (−π, π].

    **Arguments:** ``azimuth`` ψ, rad, any shape ``(...)``.

    **Returns:** θ, rad, shape ``(...)``, in (−π, π].
    """
    return _wrap(0.5 * jnp.pi - _float(azimuth))


def compass_spherical_to_cartesian(polar: ArrayLike) -> Float[Array, "... 3"]:
    """Radar ``[r, θ, ε]`` with compass azimuth θ to Cartesian ``[r sθ cε, r cθ cε, r sε]``
    (Wang et al. 2012, eq. 1).

    x is East, y North, z Up (ENU or a platform frame with those nominal axes). It is
    :func:`jaxtrack.geometry.spherical_to_cartesian` with ψ = :func:`compass_to_math_azimuth` (θ).

    **Arguments:** ``polar`` ``(..., 3)``: range r (m), compass azimuth θ (rad), elevation ε (rad).

    **Returns:** ``(..., 3)`` position, m.
    """
    polar = _float(polar)
    r, theta, eps = polar[..., 0], polar[..., 1], polar[..., 2]
    return spherical_to_cartesian(jnp.stack([r, compass_to_math_azimuth(theta), eps], axis=-1))


def cartesian_to_compass_spherical(position: ArrayLike) -> Float[Array, "... 3"]:
    """Cartesian ``[x, y, z]`` (East, North, Up) to radar ``[r, θ, ε]`` with compass azimuth
    ``θ = atan2(x, y)`` in (−π, π] and ``ε = atan2(z, √(x² + y²))`` (inverse of Wang et al. eq. 1).

    **Arguments:** ``position`` ``(..., 3)``, m.

    **Returns:** ``(..., 3)``: range (m), compass azimuth (rad), elevation (rad). At the origin and
    on the z axis the undefined angles are set as in :func:`jaxtrack.geometry.cartesian_to_spherical`.
    """
    s = cartesian_to_spherical(_float(position))
    return jnp.stack([s[..., 0], math_to_compass_azimuth(s[..., 1]), s[..., 2]], axis=-1)


def platform_rotation_vector(yaw: ArrayLike, pitch: ArrayLike, roll: ArrayLike) -> Float[Array, "... 3"]:
    """The ENU rotation vector ``ω = [Δη, −Δψ, −Δφ]`` of small platform attitude errors
    (Wang et al. 2012, eqs 8–9; specs/obem-registration.md §1.4 [X]).

    To first order ``platform_to_enu_rotation(Δφ, Δη, Δψ) ≈ I + [ω×]``: pitch turns about East,
    roll about −North and yaw about −Up (yaw and roll follow the left-hand rule).

    **Arguments:** ``yaw`` Δφ, ``pitch`` Δη, ``roll`` Δψ (rad), broadcast-compatible shapes ``(...)``.

    **Returns:** ``(..., 3)`` ENU components, rad.
    """
    yaw, pitch, roll = jnp.broadcast_arrays(_float(yaw), _float(pitch), _float(roll))
    return jnp.stack([pitch, -roll, -yaw], axis=-1)


def platform_attitude_error_matrix(yaw: ArrayLike, pitch: ArrayLike, roll: ArrayLike) -> Float[Array, "... 3 3"]:
    """``Δ(α) = [[0, Δφ, −Δψ], [−Δφ, 0, −Δη], [Δψ, Δη, 0]]`` (Wang et al. 2012, eqs 8–9):
    ``platform_to_enu_rotation(α) = I + Δ(α) + O(|α|²)``.

    Skew-symmetric, ``Δ v = ω × v`` with ω = :func:`platform_rotation_vector` (yaw, pitch, roll).

    **Arguments:** ``yaw`` Δφ, ``pitch`` Δη, ``roll`` Δψ (rad), broadcast-compatible shapes ``(...)``.

    **Returns:** ``(..., 3, 3)``, rad.
    """
    return skew(platform_rotation_vector(yaw, pitch, roll))


def platform_attitude_generators(dtype=None) -> Float[Array, "3 3 3"]:
    """The generators ``∂ T_p2ENU / ∂(Δφ, Δη, Δψ)`` at zero attitude (Wang et al. 2012, eq. 8),
    stacked in the order (yaw Δφ, pitch Δη, roll Δψ):

    ``G_φ = [[0,1,0],[−1,0,0],[0,0,0]]``, ``G_η = [[0,0,0],[0,0,−1],[0,1,0]]``,
    ``G_ψ = [[0,0,−1],[0,0,0],[1,0,0]]``, so ``Δ(α) = Δφ G_φ + Δη G_η + Δψ G_ψ``.

    **Arguments:** ``dtype``: floating dtype of the result (default: JAX's default float).

    **Returns:** ``(3, 3, 3)``, unitless (per rad).
    """
    dtype = jnp.result_type(float) if dtype is None else dtype
    return platform_attitude_error_matrix(jnp.eye(3, dtype=dtype)[:, 0], jnp.eye(3, dtype=dtype)[:, 1],
                                          jnp.eye(3, dtype=dtype)[:, 2])

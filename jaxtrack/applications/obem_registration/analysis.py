"""Proposition 2 (equivalent measurement errors of the attitude biases, eqs 28–45, App. A) and
the unobservable rotation about the baseline (Proposition 1; spec §2.4 [X]).

The observability analysis itself (column-normalised Gramian, eqs 21–27) is
:func:`jaxtrack.estimation.observability`.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ... import geometry
from ...models import wrap_angle
from .frames import _float, attitude_matrix

__all__ = [
    "equivalent_errors_exact",
    "equivalent_errors_first_order",
    "east_axis_azimuth_error",
    "baseline_rotation_attitudes",
]


def equivalent_errors_exact(attitude: ArrayLike, target_enu: ArrayLike) -> Float[Array, "... 3"]:
    """Exact ``[Δr_c, Δθ_c, Δε_c]`` that attitude α adds to a target at ``target_enu`` (Prop. 2, exact).

    The radar measures in the platform frame, ``X_p = T_ENU2p(α) X_ENU`` (eq. 6); the equivalent
    errors are ``cart2radar(X_p) − cart2radar(X_ENU)`` with the azimuth difference wrapped.
    ``Δr_c`` is zero to rounding because T is orthogonal (spec §2.3 [X]).

    **Arguments:** ``attitude`` ``(3,)`` ``[Δφ, Δη, Δψ]`` rad; ``target_enu`` ``(..., 3)`` m.

    **Returns:** ``(..., 3)`` (m, rad, rad).
    """
    x = _float(target_enu)
    t = attitude_matrix(attitude)
    x_p = geometry.rotate(jnp.swapaxes(t, -1, -2), x)
    d = geometry.cartesian_to_compass_spherical(x_p) - geometry.cartesian_to_compass_spherical(x)
    return d.at[..., 1].set(wrap_angle(d[..., 1]))


def equivalent_errors_first_order(attitude: ArrayLike, target_enu: ArrayLike) -> Float[Array, "... 3"]:
    """First-order ``[Δr_c, Δθ_c, Δε_c]`` of Proposition 2 (eqs 31, 36, 45).

    ``Δr_c = 0``; ``Δθ_c = −Δφ + (y z Δψ − x z Δη)/(x² + y²)``; ``Δε_c = (−x Δψ − y Δη)/sqrt(x² + y²)``,
    i.e. ``Δθ_c = −Δφ + tanε (cosθ Δψ − sinθ Δη)`` and ``Δε_c = −(Δψ sinθ + Δη cosθ)``.

    **Arguments:** ``attitude`` ``(3,)`` rad; ``target_enu`` ``(..., 3)`` m.

    **Returns:** ``(..., 3)`` (m, rad, rad).
    """
    x = _float(target_enu)
    a = jnp.asarray(attitude, x.dtype)
    px, py, pz = x[..., 0], x[..., 1], x[..., 2]
    rho2 = px * px + py * py
    d_theta = -a[0] + (py * pz * a[2] - px * pz * a[1]) / rho2
    d_eps = (-px * a[2] - py * a[1]) / jnp.sqrt(rho2)
    return jnp.stack([jnp.zeros_like(d_theta), d_theta, d_eps], axis=-1)


def east_axis_azimuth_error(attitude: ArrayLike, horizontal_range: ArrayLike, height: ArrayLike) -> Float[Array, "..."]:
    """Eq. (40): for a target on the East axis, ``Δθ_c ≈ −Δφ − (z / r_xoy) Δη``.

    **Arguments:** ``attitude`` ``(3,)`` rad; ``horizontal_range`` r_xoy and ``height`` z, m.

    **Returns:** Δθ_c, rad.
    """
    a = _float(attitude)
    return -a[0] - jnp.asarray(height) / jnp.asarray(horizontal_range) * a[1]


def baseline_rotation_attitudes(site1: ArrayLike, site2: ArrayLike) -> Float[Array, "2 3"]:
    """Attitude biases of both platforms for a unit rotation about the baseline (spec §2.4 [X]).

    With ``T_i Δ_i X_i = (T_i ω_i) × (T_i X_i)`` and ω_i = :func:`jaxtrack.geometry.platform_rotation_vector`,
    both platforms rotated by the same ECEF vector ``Ω ∥ b = X_2s − X_1s`` give
    ``D1α1 − D2α2 = Ω × b = 0``: an unobservable direction of AAM that survives the azimuth/yaw merge.

    **Arguments:** ``site1``, ``site2`` ``[L, λ, h]`` ``(3,)`` (rad, rad, m).

    **Returns:** ``[[Δφ1, Δη1, Δψ1], [Δφ2, Δη2, Δψ2]]`` ``(2, 3)``, rad per rad of rotation.
    """
    s1 = _float(site1)
    s2 = jnp.asarray(site2, s1.dtype)
    b = geometry.geodetic_to_ecef(s2[0], s2[1], s2[2]) - geometry.geodetic_to_ecef(s1[0], s1[1], s1[2])
    omega = b / jnp.linalg.norm(b)
    rows = []
    for s in (s1, s2):
        w = geometry.ecef_to_enu_rotation(s[0], s[1]) @ omega
        # Invert ω = [Δη, −Δψ, −Δφ].
        rows.append(jnp.stack([-w[2], w[0], -w[1]]))
    return jnp.stack(rows)

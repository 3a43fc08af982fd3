"""Frames and conversions: spherical ↔ Cartesian, ENU ↔ radar FACE, geodetic/ECEF (WGS-84), ENU ↔ ENU.

Every function is pure, differentiable and vectorised over leading axes: angles and heights may
carry any (broadcast-compatible) batch shape ``(...)``, and vectors carry a trailing axis of 3.
Broadcasting between batch shapes is done explicitly with ``jnp.broadcast_arrays`` (jaxtrack's
tests run with ``jax_numpy_rank_promotion="raise"``).

Units: metres and radians throughout.

Conventions (Serakos, Gray, Youssef, "Topics in mitigating radar bias", eqs 1–9 and Appendix):

- ENU: x = East, y = North, z = Up, origin at a site.
- Spherical ``[r, ψ, θ]``: range, azimuth ψ measured **from East towards North** (mathematical
  convention, not compass azimuth), elevation θ up from the horizontal plane.
- Rotations are active and right-handed (:mod:`jaxtrack.geometry._rotations`); a frame
  transformation called ``T_A2B`` (``a_to_b_rotation``) maps the components of a vector in frame A to its components in
  frame B: ``v_B = T_A2B @ v_A``.
- ECEF: Earth-centred, Earth-fixed; x through Greenwich on the equator, z along the spin axis.
  (The paper calls this frame "ECI" although no time or Earth rotation appears; it is ECEF.)
"""

from __future__ import annotations

import jax.numpy as jnp

from ._rotations import _stack_matrix, rotation_x, rotation_y, rotation_z

__all__ = [
    "WGS84_A",
    "WGS84_E2",
    "spherical_to_cartesian",
    "cartesian_to_spherical",
    "enu_to_face_rotation",
    "face_to_enu_rotation",
    "face_bias_matrix",
    "prime_vertical_radius",
    "geodetic_to_ecef",
    "ecef_to_enu_rotation",
    "enu_to_ecef",
    "ecef_to_enu",
    "enu_to_enu_rotation",
    "enu_site_offset",
    "enu_to_enu",
    "rotate",
    "platform_to_enu_rotation",
    "ecef_to_geodetic",
]

WGS84_A = 6378137.0
"""WGS-84 equatorial radius r_ee, metres."""
WGS84_E2 = 6.69437999014e-3
"""WGS-84 first eccentricity squared e², unitless."""




def _broadcast(*xs):
    return jnp.broadcast_arrays(*(jnp.asarray(x, dtype=jnp.result_type(float)) for x in xs))


def _add(a, b):
    """``a + b`` for vectors with possibly different batch ranks (explicit broadcast)."""
    a, b = jnp.broadcast_arrays(a, b)
    return a + b


def rotate(rot, vec) -> jnp.ndarray:
    """``rot @ vec`` over broadcast leading axes: ``(..., 3, 3)``, ``(..., 3)`` → ``(..., 3)``.

    Use it to carry vectors (biases, velocities) between frames, e.g. with
    :func:`enu_to_enu_rotation`.

    **Arguments:**

    - ``rot``: rotation matrices, ``(..., 3, 3)``; ``vec``: vectors, ``(..., 3)``, any units.

    **Returns:** the rotated vectors, ``(..., 3)`` (broadcast leading axes), in the units of ``vec``.
    """
    vec = jnp.asarray(vec, dtype=jnp.result_type(rot, vec))
    rot, vec = jnp.broadcast_arrays(rot, vec[..., None, :])
    return jnp.sum(rot * vec, axis=-1)


def _safe_hypot(a, b):
    """``sqrt(a² + b²)`` whose gradient is 0 (not NaN) at a = b = 0 (double-``where``)."""
    sq = a * a + b * b
    pos = sq > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)


def _safe_atan2(y, x):
    """``atan2(y, x)`` with gradient 0 (not NaN) at the undefined point y = x = 0."""
    zero = (x == 0) & (y == 0)
    return jnp.where(zero, 0.0, jnp.arctan2(jnp.where(zero, 0.0, y), jnp.where(zero, 1.0, x)))


# --------------------------------------------------------------------------------------------
# Spherical ↔ Cartesian (eqs 1–2)


def spherical_to_cartesian(spherical) -> jnp.ndarray:
    """Spherical ``π = [r, ψ, θ]`` to Cartesian ``p = [x, y, z]`` (Serakos et al., eq. 2, ``f(π)``).

    ``f(π) = [r cosθ cosψ, r cosθ sinψ, r sinθ]'``

    **Arguments:**

    - ``spherical``: ``(..., 3)`` array ``[r, ψ, θ]``: range (m), azimuth ψ from East towards
      North (rad), elevation θ above the horizontal plane (rad).

    **Returns:** ``(..., 3)`` Cartesian ``[x, y, z]`` (m) in the same frame (e.g. ENU: East, North, Up).
    """
    spherical = jnp.asarray(spherical, dtype=jnp.result_type(spherical, float))
    r, psi, theta = spherical[..., 0], spherical[..., 1], spherical[..., 2]
    c_theta = jnp.cos(theta)
    return jnp.stack([r * c_theta * jnp.cos(psi), r * c_theta * jnp.sin(psi), r * jnp.sin(theta)], axis=-1)


def cartesian_to_spherical(cartesian) -> jnp.ndarray:
    """Cartesian ``p = [x, y, z]`` to spherical ``[r, ψ, θ]`` (Serakos et al., eq. 2, ``f⁻¹(p)``).

    ``f⁻¹(p) = [sqrt(x²+y²+z²), atan2(y, x), atan2(z, sqrt(x²+y²))]'``. The paper prints
    ``arctan(y/x)``, which loses the quadrant; ``atan2`` returns ψ ∈ (−π, π] and θ ∈ [−π/2, π/2].
    At the origin (and on the z axis for ψ) the angles are set to 0 with a zero gradient, so that
    autodiff never produces NaN.

    **Arguments:**

    - ``cartesian``: ``(..., 3)`` array ``[x, y, z]`` (m).

    **Returns:** ``(..., 3)`` array ``[r, ψ, θ]``: range (m), azimuth and elevation (rad).
    """
    cartesian = jnp.asarray(cartesian, dtype=jnp.result_type(cartesian, float))
    x, y, z = cartesian[..., 0], cartesian[..., 1], cartesian[..., 2]
    horizontal = _safe_hypot(x, y)
    r = _safe_hypot(horizontal, z)
    return jnp.stack([r, _safe_atan2(y, x), _safe_atan2(z, horizontal)], axis=-1)


# --------------------------------------------------------------------------------------------
# Elementary rotations and the radar FACE frame (eqs 7–12)


def enu_to_face_rotation(psi, theta) -> jnp.ndarray:
    """``T_ENU2FACE(ψ, θ) = R_y(θ) R_z(ψ)`` in closed form (Serakos et al., eq. 7; eq. 9 for face j).

    The paper's yaw factor ``R_z(ψ)`` is passive; with jaxtrack's active rotations
    ``T_ENU2FACE = rotation_y(θ) @ rotation_z(−ψ)`` (tested).

    ``[[cθcψ, cθsψ, sθ], [−sψ, cψ, 0], [−sθcψ, −sθsψ, cθ]]``. Row 1 is the boresight
    ``u_r = f(1, ψ, θ)``; rows 2 and 3 are the horizontal and vertical cross-range axes
    ``u_cA``, ``u_cB``.

    **Arguments:** ``psi`` (yaw/azimuth of the face boresight from East towards North, rad) and
    ``theta`` (pitch/elevation, rad), broadcast-compatible shapes ``(...)``.

    **Returns:** ``(..., 3, 3)`` rotation with ``v_FACE = T @ v_ENU``.
    """
    psi, theta = _broadcast(psi, theta)
    cp, sp, ct, st = jnp.cos(psi), jnp.sin(psi), jnp.cos(theta), jnp.sin(theta)
    return _stack_matrix([[ct * cp, ct * sp, st], [-sp, cp, jnp.zeros_like(cp)], [-st * cp, -st * sp, ct]])


def face_to_enu_rotation(psi, theta) -> jnp.ndarray:
    """``T_FACE2ENU(ψ, θ) = T_ENU2FACE(ψ, θ)'`` (Serakos et al., eq. 8); columns ``u_r, u_cA, u_cB``.

    Shapes as :func:`enu_to_face_rotation`; returns ``(..., 3, 3)`` with ``v_ENU = T @ v_FACE``.

    **Arguments:**

    - ``psi``: the face boresight azimuth from East towards North (rad); ``theta``: its elevation (rad).
      Broadcast-compatible shapes ``(...)``.

    **Returns:** ``T_FACE2ENU``, shape ``(..., 3, 3)``.
    """
    return jnp.swapaxes(enu_to_face_rotation(psi, theta), -1, -2)


def face_bias_matrix(slant_range, psi, theta) -> jnp.ndarray:
    """The matrix ``A(p, ψ, θ)`` mapping spherical bias ``e = [Δr, Δψ, Δθ]`` to an ENU bias (eqs 12, 18–19).

    ``A = T_FACE2ENU(ψ, θ) · diag(1, p, p)``, so ``B_ENU = A e = Δr u_r + p Δψ u_cA + p Δθ u_cB``
    (eq. 11) and ``det A = p²``.

    Note the paper's cross-range convention: the azimuth term is ``p Δψ``, not ``p cosθ Δψ``, so
    Δψ is a *face cross-range angle*, and ``A = (∂f/∂π) · diag(1, 1/cosθ, 1)``, not the Jacobian
    of :func:`spherical_to_cartesian`.

    **Arguments:** ``slant_range`` p (sensor-to-target distance, m; the paper's ``p_Ti``, taken
    from the measured position), ``psi``, ``theta`` (line-of-sight azimuth and elevation, rad);
    broadcast-compatible shapes ``(...)``.

    **Returns:** ``(..., 3, 3)``; columns in m per (m, rad, rad).
    """
    p, psi, theta = _broadcast(slant_range, psi, theta)
    scale = jnp.stack([jnp.ones_like(p), p, p], axis=-1)
    return face_to_enu_rotation(psi, theta) * scale[..., None, :]


# --------------------------------------------------------------------------------------------
# Geodetic, ECEF and ENU on WGS-84 (Appendix)


def prime_vertical_radius(lat) -> jnp.ndarray:
    """Prime-vertical radius of curvature ``N(L) = r_ee / sqrt(1 − e² sin²L)`` on WGS-84, metres.

    **Arguments:**

    - ``lat``: the geodetic latitude ``L`` (rad), shape ``(...)``.

    **Returns:** ``N(L)``, shape ``(...)``, m.
    """
    (lat,) = _broadcast(lat)
    return WGS84_A / jnp.sqrt(1.0 - WGS84_E2 * jnp.sin(lat) ** 2)


def geodetic_to_ecef(lat, lon, h=0.0) -> jnp.ndarray:
    """Geodetic latitude, longitude, height to ECEF position on WGS-84 (Serakos et al., Appendix).

    ``P = [(N+h) cL cΩ, (N+h) cL sΩ, (N(1−e²)+h) sL]'`` with ``N`` from
    :func:`prime_vertical_radius`. With h = 0 this is the paper's site position
    ``r_ee/sqrt(1 − e² sin²L) · [cL cΩ, cL sΩ, (1−e²) sL]'``.

    **Arguments:** ``lat`` (geodetic latitude L, rad), ``lon`` (longitude Ω, rad), ``h`` (height
    above the ellipsoid, m); broadcast-compatible shapes ``(...)``.

    **Returns:** ``(..., 3)`` ECEF position, metres.
    """
    lat, lon, h = _broadcast(lat, lon, h)
    n = prime_vertical_radius(lat)
    cl = jnp.cos(lat)
    return jnp.stack(
        [(n + h) * cl * jnp.cos(lon), (n + h) * cl * jnp.sin(lon), (n * (1.0 - WGS84_E2) + h) * jnp.sin(lat)],
        axis=-1,
    )


def ecef_to_enu_rotation(lat, lon) -> jnp.ndarray:
    """``T_ECEF2ENU(L, Ω) = R1(L) · R2(Ω) · Perm`` in closed form (Serakos et al., Appendix, "T_ECI2ENU").

    ``[[−sΩ, cΩ, 0], [−sL cΩ, −sL sΩ, cL], [cL cΩ, cL sΩ, sL]]`` (rows: East, North, Up). Use it as
    ``p_ENU = R @ (p_ECEF − p_ECEF_origin)``.

    **Arguments:** ``lat`` (geodetic latitude L, rad), ``lon`` (longitude Ω, rad); broadcast-compatible
    shapes ``(...)``.

    **Returns:** ``(..., 3, 3)`` rotation.
    """
    lat, lon = _broadcast(lat, lon)
    sl, cl, so, co = jnp.sin(lat), jnp.cos(lat), jnp.sin(lon), jnp.cos(lon)
    return _stack_matrix([[-so, co, jnp.zeros_like(so)], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]])


def enu_to_ecef(p_enu, lat, lon, h=0.0) -> jnp.ndarray:
    """ENU position at a site to ECEF (Appendix): ``P_ECEF = P_site + T_ECEF2ENU' · P_ENU``.

    **Arguments:** ``p_enu`` ``(..., 3)`` (m); site ``lat``, ``lon`` (rad), ``h`` (m), shapes ``(...)``.

    **Returns:** ``(..., 3)`` ECEF position, metres. For a velocity, use the rotation only.
    """
    rot = jnp.swapaxes(ecef_to_enu_rotation(lat, lon), -1, -2)
    return _add(geodetic_to_ecef(lat, lon, h), rotate(rot, p_enu))


def ecef_to_enu(p_ecef, lat, lon, h=0.0) -> jnp.ndarray:
    """ECEF position to the ENU frame of a site: ``P_ENU = T_ECEF2ENU (P_ECEF − P_site)`` (Appendix).

    **Arguments:** ``p_ecef`` ``(..., 3)`` (m); site ``lat``, ``lon`` (rad), ``h`` (m), shapes ``(...)``.

    **Returns:** ``(..., 3)`` ENU position, metres.
    """
    site = geodetic_to_ecef(lat, lon, h)
    return rotate(ecef_to_enu_rotation(lat, lon), _add(jnp.asarray(p_ecef, dtype=site.dtype), -site))


def enu_to_enu_rotation(lat1, lon1, lat2, lon2) -> jnp.ndarray:
    """``T_ENU(1)2ENU(2) = R1(L2) · R2(Ω2 − Ω1) · R1(L1)'`` in closed form (Serakos et al., Appendix).

    Equal to ``T_ECEF2ENU(2) · T_ECEF2ENU(1)'``. Its transpose is ``T_ENU(2)2ENU(1)``. Rotates
    vectors (velocities, biases) only; for positions use :func:`enu_to_enu`.

    **Arguments:** site latitudes ``lat1``, ``lat2`` and longitudes ``lon1``, ``lon2`` (rad),
    broadcast-compatible shapes ``(...)``.

    **Returns:** ``(..., 3, 3)`` rotation with ``v_ENU(2) = T @ v_ENU(1)``.
    """
    l1, l2, o1, o2 = _broadcast(lat1, lat2, lon1, lon2)
    s1, c1, s2, c2 = jnp.sin(l1), jnp.cos(l1), jnp.sin(l2), jnp.cos(l2)
    d = o2 - o1
    sd, cd = jnp.sin(d), jnp.cos(d)
    return _stack_matrix(
        [
            [cd, s1 * sd, -c1 * sd],
            [-s2 * sd, c1 * c2 + s1 * s2 * cd, c2 * s1 - c1 * s2 * cd],
            [c2 * sd, c1 * s2 - c2 * s1 * cd, s1 * s2 + c1 * c2 * cd],
        ]
    )


def enu_site_offset(lat1, lon1, lat2, lon2, h1=0.0, h2=0.0, *, frame: int = 1) -> jnp.ndarray:
    """Vector from site 1 to site 2, ``P_ENU(1)2ENU(2)``, in ENU(``frame``) (Serakos et al., Appendix).

    ``P_ENU(1)2ENU(2),ENU(i) = T_ECEF2ENU(i) · (P_site2,ECEF − P_site1,ECEF)``. With ``frame=1`` this
    is ``P_1TO2,ENU(1)`` of eq. 5. The paper puts both sites at zero height (h1 = h2 = 0).

    **Arguments:** site latitudes/longitudes (rad) and heights (m), broadcast-compatible shapes
    ``(...)``; ``frame``: 1 or 2, the ENU frame the offset is expressed in.

    **Returns:** ``(..., 3)`` offset, metres.
    """
    if frame not in (1, 2):
        from .._validation import InputError

        raise InputError(f"`frame` must be 1 or 2 (the ENU frame of site 1 or site 2); got {frame!r}.")
    delta = geodetic_to_ecef(lat2, lon2, h2) - geodetic_to_ecef(lat1, lon1, h1)
    rot = ecef_to_enu_rotation(lat1, lon1) if frame == 1 else ecef_to_enu_rotation(lat2, lon2)
    return rotate(rot, delta)


def enu_to_enu(p_enu1, lat1, lon1, lat2, lon2, h1=0.0, h2=0.0) -> jnp.ndarray:
    """A position in ENU(1) to ENU(2) (Serakos et al., Appendix).

    ``P_ENU(2) = −P_ENU(1)2ENU(2),ENU(2) + T_ENU(1)2ENU(2) · P_ENU(1)``. The inverse is the same
    call with the sites swapped.

    **Arguments:** ``p_enu1`` ``(..., 3)`` position in ENU(1) (m); site latitudes/longitudes (rad)
    and heights (m), broadcast-compatible shapes ``(...)``.

    **Returns:** ``(..., 3)`` position in ENU(2), metres.
    """
    rot = enu_to_enu_rotation(lat1, lon1, lat2, lon2)
    return _add(rotate(rot, p_enu1), -enu_site_offset(lat1, lon1, lat2, lon2, h1, h2, frame=2))


# --------------------------------------------------------------------------------------------
# Added for the mobile-radar registration study (Wang, Chen, Jia, Progri 2012; specs/obem-registration.md)


def platform_to_enu_rotation(yaw, pitch, roll) -> jnp.ndarray:
    """Stabilised-platform frame to local ENU, ``T_p2ENU = T_Δφ T_Δη T_Δψ`` (Wang et al. 2012, eqs 2–5, 7).

    The platform axes are nominally East, North, Up and differ from ENU by the attitude errors
    (yaw Δφ, pitch Δη, roll Δψ), applied as roll about the platform y axis, then pitch about the
    intermediate x axis, then yaw about the final z axis:

    ``T_Δψ = [[cψ,0,−sψ],[0,1,0],[sψ,0,cψ]] = rotation_y(−ψ)``, ``T_Δη = rotation_x(η)``,
    ``T_Δφ = [[cφ,sφ,0],[−sφ,cφ,0],[0,0,1]] = rotation_z(−φ)`` (active rotations, see :mod:`jaxtrack.geometry`)

    (yaw and roll follow the left-hand rule, pitch the right-hand rule). Δφ > 0 turns the
    platform x axis clockwise (a target at compass azimuth θ is seen at θ − Δφ); Δη > 0 tilts the
    platform North axis up; Δψ > 0 tilts the platform East axis up. The inverse
    ``T_ENU2p`` is the transpose (eq. 6).

    **Arguments:** ``yaw`` Δφ, ``pitch`` Δη, ``roll`` Δψ (rad), broadcast-compatible shapes ``(...)``.

    **Returns:** ``(..., 3, 3)`` rotation with ``v_ENU = T @ v_platform``.
    """
    yaw, pitch, roll = _broadcast(yaw, pitch, roll)
    return rotation_z(-yaw) @ rotation_x(pitch) @ rotation_y(-roll)


def ecef_to_geodetic(p_ecef, iterations: int = 6) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
    """ECEF position to WGS-84 geodetic latitude, longitude and height (inverse of :func:`geodetic_to_ecef`).

    Fixed-point iteration on the latitude, ``tan L = z / (p (1 − e² N/(N + h)))`` with
    ``p = sqrt(x² + y²)``, started from the h = 0 solution ``tan L = z / (p (1 − e²))``. Each pass
    shrinks the latitude error by about e² (≈ 7e-3), so the fixed count (default 6) reaches
    float64 resolution anywhere near the Earth's surface and the function jits and
    differentiates like any other. The height is ``p cos L + z sin L − r_ee sqrt(1 − e² sin²L)``,
    which stays accurate at the poles (no division by cos L).

    **Arguments:** ``p_ecef`` ``(..., 3)`` ECEF position (m); ``iterations``: latitude passes.

    **Returns:** ``(lat, lon, h)``: geodetic latitude and longitude (rad), height above the
    ellipsoid (m), each of shape ``(...)``.
    """
    p_ecef = jnp.asarray(p_ecef, dtype=jnp.result_type(p_ecef, float))
    x, y, z = p_ecef[..., 0], p_ecef[..., 1], p_ecef[..., 2]
    p = _safe_hypot(x, y)
    lon = _safe_atan2(y, x)
    lat = jnp.arctan2(z, p * (1.0 - WGS84_E2))
    for _ in range(iterations):
        n = prime_vertical_radius(lat)
        h = p * jnp.cos(lat) + z * jnp.sin(lat) - WGS84_A * jnp.sqrt(1.0 - WGS84_E2 * jnp.sin(lat) ** 2)
        lat = jnp.arctan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
    h = p * jnp.cos(lat) + z * jnp.sin(lat) - WGS84_A * jnp.sqrt(1.0 - WGS84_E2 * jnp.sin(lat) ** 2)
    return lat, lon, h

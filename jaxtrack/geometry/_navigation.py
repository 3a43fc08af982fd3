"""Navigation frames and attitude errors: NED ↔ ECEF, heading/path/body/antenna frames, ψ angles.

Frames (Layne & Blasch 1997, "Integrated SAR and navigation systems for targeting applications",
Sec. 4.1–4.2, E9–E13):

- ECEF ``e``: Earth-centred, Earth-fixed; x through Greenwich on the equator, z along the spin axis.
- navigation ``n``: local-level **NED** (x North, y East, z Down) at latitude φ, longitude λ.
- heading ``h``: ``n`` turned by the ground-track heading η_z about Down.
- path ``p``: ``h`` turned by the flight-path angle η_y (positive climbing) about y^h; x^p is
  along the velocity.
- body ``b``: ``n`` turned by the 3-2-1 Euler angles ``[roll, pitch, yaw]``.
- antenna ``a``: ``b`` turned by the antenna's 3-2-1 angles; x^a is the array boresight.

Convention: the same as :mod:`jaxtrack.geometry` — rotation matrices are active and right-handed,
and a function named ``a_to_b_rotation`` returns ``C_a^b`` with ``v_b = C_a^b @ v_a``; the reverse
transform is the transpose.

Attitude errors (Sec. 8.1, E98–E115): the indicated DCM is ``C̄_b^n = (I − [ψ×]) C_b^n`` to first
order, ``ψ`` (rad, nav axes) being the "psi angle" of the ψ-angle INS error model
(:mod:`jaxtrack.models._ins`). Angles in radians, lengths in metres.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._validation import check_shape
from ._rotations import _stack_matrix, euler_321_to_dcm, rotation_y, rotation_z

_ANGLES3 = [(3,), (None, 3), (None, None, 3)]


def _vec3(name: str, x, dtype=None) -> Array:
    """``x`` as a float array of shape ``(3,)`` (in ``dtype`` when given), or an InputError naming it."""
    x = jnp.asarray(x)
    x = x.astype(jnp.result_type(x, float) if dtype is None else dtype)
    check_shape(name, x, [(3,)])
    return x


def ned_to_ecef_rotation(lat: ArrayLike, lon: ArrayLike) -> Float[Array, "... 3 3"]:
    """``C_n^e`` (Layne & Blasch 1997, E9): the NED frame at ``lat``, ``lon`` → ECEF.

    ``[[−sφ cλ, −sλ, −cφ cλ], [−sφ sλ, cλ, −cφ sλ], [cφ, 0, −sφ]]``; its columns are North, East
    and Down in ECEF. At ``lat = lon = 0``: North = +z^e, East = +y^e, Down = −x^e. On an
    ellipsoid ``lat`` is the geodetic latitude (Down is the inward normal). It equals
    ``ecef_to_enu_rotation(lat, lon).T`` with the ENU → NED axis swap.

    **Arguments:** ``lat`` φ, ``lon`` λ (rad), broadcast-compatible shapes ``(...)``.

    **Returns:** ``(..., 3, 3)`` with ``v_ECEF = C @ v_NED``.
    """
    lat, lon = jnp.asarray(lat), jnp.asarray(lon)
    dtype = jnp.result_type(lat, lon, float)
    lat, lon = jnp.broadcast_arrays(lat.astype(dtype), lon.astype(dtype))
    sf, cf, sl, cl = jnp.sin(lat), jnp.cos(lat), jnp.sin(lon), jnp.cos(lon)
    return _stack_matrix([[-sf * cl, -sl, -cf * cl], [-sf * sl, cl, -cf * sl], [cf, jnp.zeros_like(sf), -sf]])


def heading_to_ned_rotation(heading: ArrayLike) -> Float[Array, "... 3 3"]:
    """``C_h^n = rotation_z(η_z)`` (E10, with η_z for the printed η_x): ground-track heading frame → NED.

    **Arguments:** ``heading`` η_z (rad, clockwise from North seen from above), shape ``(...)``.

    **Returns:** ``(..., 3, 3)``; its first column is ``[cos η_z, sin η_z, 0]``.
    """
    return rotation_z(heading)


def path_to_heading_rotation(flight_path_angle: ArrayLike) -> Float[Array, "... 3 3"]:
    """``C_p^h = rotation_y(η_y)`` (E11): flight-path frame → heading frame.

    **Arguments:** ``flight_path_angle`` η_y (rad, positive climbing), shape ``(...)``.

    **Returns:** ``(..., 3, 3)``; ``x^p = [cos η_y, 0, −sin η_y]^h``.
    """
    return rotation_y(flight_path_angle)


def body_to_ned_rotation(attitude: ArrayLike) -> Float[Array, "... 3 3"]:
    """``C_b^n`` (E12) from the 3-2-1 Euler angles ``attitude = [roll α_x, pitch α_y, yaw α_z]`` (rad).

    ``rotation_z(α_z) @ rotation_y(α_y) @ rotation_x(α_x)`` (:func:`~jaxtrack.geometry.euler_321_to_dcm`).

    **Arguments:** ``attitude`` shape ``(3,)``, ``(B, 3)`` or ``(B1, B2, 3)``.

    **Returns:** ``(..., 3, 3)`` with ``v_NED = C @ v_body``.
    """
    a = jnp.asarray(attitude)
    check_shape("attitude", a, _ANGLES3)
    return euler_321_to_dcm(a)


def antenna_to_body_rotation(antenna_angles: ArrayLike) -> Float[Array, "... 3 3"]:
    """``C_a^b`` (E13): the 3-2-1 rotation of the antenna roll, pitch and yaw ``ζ = [ζ_x, ζ_y, ζ_z]`` (rad).

    ``x^a`` is the boresight (normal to the array face); ``y^a``, ``z^a`` lie in the face.

    **Arguments:** ``antenna_angles`` shape ``(3,)``, ``(B, 3)`` or ``(B1, B2, 3)``.

    **Returns:** ``(..., 3, 3)`` with ``v_body = C @ v_antenna``.
    """
    z = jnp.asarray(antenna_angles)
    check_shape("antenna_angles", z, _ANGLES3)
    return euler_321_to_dcm(z)


def euler_321_perturbation(attitude: ArrayLike, attitude_error: ArrayLike) -> Float[Array, "3 3"]:
    """First-order ``δC = Σ_k (∂C/∂α_k) δα_k`` of ``C = euler_321_to_dcm(α)`` (E106, element by element).

    Equal to ``jax.jvp(euler_321_to_dcm, (α,), (δα,))[1]`` (tested).

    **Arguments:** ``attitude`` α and ``attitude_error`` δα, ``[roll, pitch, yaw]`` in rad, shape ``(3,)``.

    **Returns:** ``δC``, shape ``(3, 3)``.
    """
    a, d = _vec3("attitude", attitude), _vec3("attitude_error", attitude_error)
    sx, cx, sy, cy, sz, cz = jnp.sin(a[0]), jnp.cos(a[0]), jnp.sin(a[1]), jnp.cos(a[1]), jnp.sin(a[2]), jnp.cos(a[2])
    dx, dy, dz = d[0], d[1], d[2]
    return _stack_matrix([
        [-dy * sy * cz - dz * sz * cy,
         dx * (sx * sz + sy * cx * cz) + dy * sx * cy * cz - dz * (sx * sy * sz + cx * cz),
         dx * (-sx * sy * cz + sz * cx) + dy * cx * cy * cz + dz * (sx * cz - sy * sz * cx)],
        [-dy * sy * sz + dz * cy * cz,
         dx * (-sx * cz + sy * sz * cx) + dy * sx * sz * cy + dz * (sx * sy * cz - sz * cx),
         dx * (-sx * sy * sz - cx * cz) + dy * sz * cx * cy + dz * (sx * sz + sy * cx * cz)],
        [-dy * cy, dx * cx * cy - dy * sx * sy, -dx * sx * cy - dy * sy * cx],
    ])


def psi_from_dcm_error(dcm: ArrayLike, perturbation: ArrayLike, *, printed_e112: bool = False) -> Float[Array, "3"]:
    """Attitude-error angles ψ from a DCM ``C`` and its error ``δC`` (E109–E113), rad.

    ``[ψ×] = ½[C δCᵀ − δC Cᵀ]``, i.e. ``(C + δC)_o = (I − [ψ×]) C`` to first order (E109), written
    out element by element (E111–E113). ``printed_e112=True`` uses the report's misprinted middle
    term ``c13 δc32 − c32 δc13`` in ψ_y instead of ``c12 δc32 − c32 δc12`` (a regression check).

    **Arguments:** ``dcm`` ``C`` and ``perturbation`` ``δC``, shape ``(3, 3)``.

    **Returns:** ψ, shape ``(3,)`` (in the axes of C's output frame, e.g. NED for ``C_b^n``).
    """
    c, d = jnp.asarray(dcm), jnp.asarray(perturbation)
    check_shape("dcm", c, [(3, 3)])
    check_shape("perturbation", d, [(3, 3)])
    psi_x = 0.5 * (c[2, 0] * d[1, 0] - c[1, 0] * d[2, 0] + c[2, 1] * d[1, 1] - c[1, 1] * d[2, 1]
                   + c[2, 2] * d[1, 2] - c[1, 2] * d[2, 2])
    middle = (c[0, 2] * d[2, 1] - c[2, 1] * d[0, 2]) if printed_e112 else (c[0, 1] * d[2, 1] - c[2, 1] * d[0, 1])
    psi_y = 0.5 * (c[0, 0] * d[2, 0] - c[2, 0] * d[0, 0] + middle + c[0, 2] * d[2, 2] - c[2, 2] * d[0, 2])
    psi_z = 0.5 * (c[1, 0] * d[0, 0] - c[0, 0] * d[1, 0] + c[1, 1] * d[0, 1] - c[0, 1] * d[1, 1]
                   + c[1, 2] * d[0, 2] - c[0, 2] * d[1, 2])
    return jnp.stack([psi_x, psi_y, psi_z])


def euler_error_matrix(attitude: ArrayLike) -> Float[Array, "3 3"]:
    """``M(α)`` with ``ψ = −M δα`` for ``C_b^n = euler_321_to_dcm(α)`` (Layne & Blasch spec §2.4.1).

    From ``δC_b^n = −[ψ×] C_b^n``: ``M = [[cψ cθ, −sψ, 0], [sψ cθ, cψ, 0], [−sθ, 0, 1]]`` with θ the
    pitch and ψ the yaw; singular at pitch ±90°. The same relation maps antenna-angle errors δζ to
    the misalignment β (E114–E115) with ζ in place of α.

    **Arguments:** ``attitude`` α ``[roll, pitch, yaw]`` (rad), shape ``(3,)``.

    **Returns:** ``M``, shape ``(3, 3)``.
    """
    a = _vec3("attitude", attitude)
    sy, cy, sz, cz = jnp.sin(a[1]), jnp.cos(a[1]), jnp.sin(a[2]), jnp.cos(a[2])
    zero, one = jnp.zeros_like(sy), jnp.ones_like(sy)
    return _stack_matrix([[cz * cy, -sz, zero], [sz * cy, cz, zero], [-sy, zero, one]])


def psi_to_euler_error(attitude: ArrayLike, psi: ArrayLike) -> Float[Array, "3"]:
    """``δα = −M⁻¹ ψ``: the Euler-angle error equivalent to the attitude error ψ (spec §2.4.1).

    ``M⁻¹`` is written in closed form (see :func:`euler_error_matrix`); singular at pitch ±90°.

    **Arguments:** ``attitude`` α (rad) and ``psi`` ψ (rad), shape ``(3,)`` each.

    **Returns:** δα ``[roll, pitch, yaw]`` (rad), shape ``(3,)``; the corrected attitude is ``α̂ − δα``
    for an indicated ``α̂ = α + δα``.
    """
    a, psi = _vec3("attitude", attitude), _vec3("psi", psi)
    sy, cy, sz, cz = jnp.sin(a[1]), jnp.cos(a[1]), jnp.sin(a[2]), jnp.cos(a[2])
    zero, one = jnp.zeros_like(sy), jnp.ones_like(sy)
    M_inv = _stack_matrix([[cz / cy, sz / cy, zero], [-sz, cz, zero], [cz * sy / cy, sz * sy / cy, one]])
    return -M_inv @ psi

"""Frames, rotations and coordinate conversions.

One rotation convention throughout (see :mod:`jaxtrack.geometry._rotations`): rotation matrices
are active and right-handed, ``rotation_z(a) @ v`` turns ``v`` by ``+a`` about z; a frame
transformation named ``a_to_b_rotation`` maps components in frame ``a`` to frame ``b``:
``v_b = T @ v_a``. Metres and radians throughout.
"""

from ._frames import (
    WGS84_A as WGS84_A,
    WGS84_E2 as WGS84_E2,
    cartesian_to_spherical as cartesian_to_spherical,
    ecef_to_enu as ecef_to_enu,
    ecef_to_enu_rotation as ecef_to_enu_rotation,
    ecef_to_geodetic as ecef_to_geodetic,
    enu_site_offset as enu_site_offset,
    enu_to_ecef as enu_to_ecef,
    enu_to_enu as enu_to_enu,
    enu_to_enu_rotation as enu_to_enu_rotation,
    enu_to_face_rotation as enu_to_face_rotation,
    face_bias_matrix as face_bias_matrix,
    face_to_enu_rotation as face_to_enu_rotation,
    geodetic_to_ecef as geodetic_to_ecef,
    platform_to_enu_rotation as platform_to_enu_rotation,
    prime_vertical_radius as prime_vertical_radius,
    rotate as rotate,
    spherical_to_cartesian as spherical_to_cartesian,
)
from ._navigation import (
    antenna_to_body_rotation as antenna_to_body_rotation,
    body_to_ned_rotation as body_to_ned_rotation,
    euler_321_perturbation as euler_321_perturbation,
    euler_error_matrix as euler_error_matrix,
    heading_to_ned_rotation as heading_to_ned_rotation,
    ned_to_ecef_rotation as ned_to_ecef_rotation,
    path_to_heading_rotation as path_to_heading_rotation,
    psi_from_dcm_error as psi_from_dcm_error,
    psi_to_euler_error as psi_to_euler_error,
)
from ._platform import (
    cartesian_to_compass_spherical as cartesian_to_compass_spherical,
    compass_spherical_to_cartesian as compass_spherical_to_cartesian,
    compass_to_math_azimuth as compass_to_math_azimuth,
    math_to_compass_azimuth as math_to_compass_azimuth,
    platform_attitude_error_matrix as platform_attitude_error_matrix,
    platform_attitude_generators as platform_attitude_generators,
    platform_rotation_vector as platform_rotation_vector,
)
from ._bearing import bearing as bearing, course as course
from ._rotations import (
    euler_321_to_dcm as euler_321_to_dcm,
    orthonormalize as orthonormalize,
    orthonormalize_first_order as orthonormalize_first_order,
    rotation_vector_to_dcm as rotation_vector_to_dcm,
    rotation_x as rotation_x,
    rotation_y as rotation_y,
    rotation_z as rotation_z,
    skew as skew,
    vee as vee,
)

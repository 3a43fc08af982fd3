"""Study: Layne & Blasch (1997), "Integrated SAR and navigation systems for targeting applications".

Everything the CLI (``jaxtrack reproduce sar``), the notebook and the tests need is in this one
module, as pure functions of the geometry and the error budgets. Specification:
``specs/sar-navigation.md`` (it corrects the OCR'd report; its [FIX-n] numbers are cited below).
Equation numbers ``(E#)`` are the report's.

Contents, in the order of the report:

1. Frames and direction-cosine matrices (E9–E13): ECEF, navigation (NED), heading, path, body,
   antenna; ``skew``/``vee``.
2. SAR and monopulse geometry (E14–E29), SAR background relations (E1–E8, E62–E72).
3. The corrected closed-form single-look targeting solution (§1.7, E30–E55).
4. DCM perturbations and the ψ/β attitude-error angles (E98–E115).
5. Error budgets: INS (Table 5), SAR (Table 6), monopulse (Table 7) and the per-look noise.
6. The 33-state linearised error model: F (Tables 1–2, E178–E184), process noise, the analytic H
   (Tables 3–4) and the exact nonlinear measurement error whose Jacobian at zero is H.
7. Verification experiments: Schuler closed forms, a nonlinear rotating-Earth inertial error
   simulation, a DCM simulation of the ψ dynamics.
8. The reference scenario RS-1 [EXT]: single-look least-squares, consider and closed-form
   covariances and CEP; covariance analysis over time (radar only, SAR only, radar + GPS)
   through :func:`jaxtrack.covariance.covariance_recursion` with Van Loan discretisation.
9. Figures and the reproduction table (:func:`reproduce`).

Units are SI and radians throughout; vectors in the navigation frame are NED.

Conventions that the spec leaves open, chosen here (each a keyword where it matters):

- Doppler sign (E2, FIX-38): closing gives ``F_d > 0`` and ``ṙ = −λF_d/2 < 0``.
- Attitude error (E109, FIX-24): ``C̄_b^n = (I − [ψ×]) C_b^n`` and the consistent dynamics
  ``F_vψ = +[A×]``, ``ψ̇ = −[ω×]ψ − ε − diag(ω)k_ε`` (``psi_sign_convention="consistent"``;
  ``"report_literal"`` keeps Table 1 as printed).
- Gravity gradient (FIX-25): ``Γ = ω_s² diag(−1, −1, +2)`` (``vertical_gravity_gradient``).
- Sensor-error coupling (FIX-32): local-level as printed (``sensor_frame="nav"``) or strapdown.
- δv is the nav-frame derivative of δr (FIX-39); navigation-frame tilt is neglected (FIX-40).
- Timing noise (FIX-19): ``T_d|ṙ|`` and ``T_d|r̈|`` (``timing_model="derivative"``).
- TEMP errors are random biases unless ``temperature_inverse_correlation_time > 0`` (FIX-26).
- INS white-noise units (FIX-20): the literal √PSD reading (``ins_noise_units="per_sqrt_hz"``).
"""

from __future__ import annotations

import functools
import math
from typing import Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError, check_shape, is_concrete
from ..covariance import CovarianceHistory, covariance_recursion
from ..models import LinearGaussianModel, discretize, van_loan
from ._report import PaperRow, write_figures

# --------------------------------------------------------------------------------------------
# Constants [EXT: the report gives no Earth constants; spec §3.4]

EARTH_RATE = 7.292115e-5  # Ω_e, rad/s
EARTH_RADIUS = 6378137.0  # R, m (spherical Earth of the ψ-angle model)
GRAVITY = 9.80665  # g, m/s²
EARTH_MU = 3.986004418e14  # μ, m³/s² (Newtonian truth of V-16)
SPEED_OF_LIGHT = 299792458.0  # c, m/s
FOOT = 0.3048  # m
MICRO_G = 1e-6 * GRAVITY  # m/s²
DEG_PER_HOUR = math.pi / 180.0 / 3600.0  # rad/s
MRAD = 1e-3  # rad

# Index map of the 33-state error vector (spec §2.6, [EXT]); E174 with δr_t^e (FIX-23).
POSITION = slice(0, 3)  # δr_aⁿ, m (NED)
VELOCITY = slice(3, 6)  # δv_aⁿ, m/s
ATTITUDE = slice(6, 9)  # ψ, rad
ACCEL_BIAS = slice(9, 12)  # ∇, m/s²
ACCEL_SCALE = slice(12, 15)  # k_∇, –
GYRO_BIAS = slice(15, 18)  # ε, rad/s
GYRO_SCALE = slice(18, 21)  # k_ε, –
TARGET = slice(21, 24)  # δr_t^e, m (ECEF)
MISALIGNMENT = slice(24, 27)  # β, rad (body axes)
RANGE_CLOCK, DOPPLER_BIAS, PROPAGATION_SPEED, FREQUENCY, TEMP_AZIMUTH, TEMP_ELEVATION = range(27, 33)
NUM_INS_STATES = 27
NUM_STATES = 33
STATE_NAMES = (
    [f"dr_a_{c}" for c in "NED"] + [f"dv_a_{c}" for c in "NED"] + [f"psi_{c}" for c in "xyz"]
    + [f"accel_bias_{c}" for c in "xyz"] + [f"accel_sf_{c}" for c in "xyz"]
    + [f"gyro_bias_{c}" for c in "xyz"] + [f"gyro_sf_{c}" for c in "xyz"]
    + [f"dr_t_{c}" for c in "xyz"] + [f"beta_{c}" for c in "xyz"]
    + ["range_clock", "doppler", "propagation_speed", "frequency", "temp_A", "temp_E"]
)
MEASUREMENT_NAMES = ("range", "range_rate", "azimuth", "elevation")

PsiConvention = Literal["consistent", "report_literal"]
GravityGradient = Literal["physical", "report"]
SensorFrame = Literal["nav", "body"]
TimingModel = Literal["derivative", "literal"]
NoiseUnits = Literal["per_sqrt_hz", "per_sqrt_hour"]


def _choice(name: str, value, allowed) -> None:
    if value not in allowed:
        raise InputError(f"`{name}` must be one of {', '.join(map(repr, allowed))}; got {value!r}.")


def _vec3(name: str, x) -> Array:
    x = jnp.asarray(x)
    x = x.astype(jnp.result_type(x, float))
    check_shape(name, x, [(3,)])
    return x


def _matrix(rows) -> Array:
    """Stack a nested list of equally shaped arrays into ``(..., len(rows), len(rows[0]))``."""
    flat = jnp.broadcast_arrays(*[e for row in rows for e in row])
    ncol = len(rows[0])
    rows = [flat[i * ncol:(i + 1) * ncol] for i in range(len(rows))]
    return jnp.stack([jnp.stack(row, axis=-1) for row in rows], axis=-2)


def _safe_sqrt(q: Array) -> Array:
    """``sqrt(max(q, 0))`` whose derivative stays finite (zero) where ``q ≤ 0``."""
    positive = q > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, q, 1.0)), 0.0)


# --------------------------------------------------------------------------------------------
# 1. Frames (Sec. 4.1–4.2)


def skew(a: ArrayLike) -> Float[Array, "... 3 3"]:
    """``[a×]`` with ``[a×] b = a × b`` (the report's ``a*``, E181); ``a`` shape ``(..., 3)``."""
    a = jnp.asarray(a)
    zero = jnp.zeros_like(a[..., 0])
    return _matrix([[zero, -a[..., 2], a[..., 1]], [a[..., 2], zero, -a[..., 0]], [-a[..., 1], a[..., 0], zero]])


def vee(S: ArrayLike) -> Float[Array, "... 3"]:
    """Inverse of :func:`skew`: the axial vector of the skew part of ``S`` (``(..., 3, 3)``)."""
    S = jnp.asarray(S)
    A = 0.5 * (S - jnp.swapaxes(S, -1, -2))
    return jnp.stack([A[..., 2, 1], A[..., 0, 2], A[..., 1, 0]], axis=-1)


def rotation_vector_to_dcm(rotation: ArrayLike) -> Float[Array, "3 3"]:
    """``exp([a×]) = I + (sin θ/θ)[a×] + ((1 − cos θ)/θ²)[a×]²``, θ = ‖a‖ (Rodrigues), rad.

    Series coefficients are used for θ² < 1e-8, so the value and its derivatives stay exact and
    finite at ``a = 0`` (where the error-state Jacobians are taken).
    """
    a = jnp.asarray(rotation)
    theta2 = a @ a
    small = theta2 < 1e-8
    theta = jnp.sqrt(jnp.where(small, 1.0, theta2))
    f1 = jnp.where(small, 1.0 - theta2 / 6.0, jnp.sin(theta) / theta)
    f2 = jnp.where(small, 0.5 - theta2 / 24.0, (1.0 - jnp.cos(theta)) / jnp.where(small, 1.0, theta2))
    K = skew(a)
    return jnp.eye(3, dtype=K.dtype) + f1 * K + f2 * (K @ K)


def rotation_x(angle: ArrayLike) -> Float[Array, "... 3 3"]:
    """Rotation by ``angle`` (rad) about x: maps a rotated frame's coordinates into the parent's."""
    a = jnp.asarray(angle)
    c, s, one, zero = jnp.cos(a), jnp.sin(a), jnp.ones_like(a), jnp.zeros_like(a)
    return _matrix([[one, zero, zero], [zero, c, -s], [zero, s, c]])


def rotation_y(angle: ArrayLike) -> Float[Array, "... 3 3"]:
    """Rotation by ``angle`` (rad) about y (same convention as :func:`rotation_x`)."""
    a = jnp.asarray(angle)
    c, s, one, zero = jnp.cos(a), jnp.sin(a), jnp.ones_like(a), jnp.zeros_like(a)
    return _matrix([[c, zero, s], [zero, one, zero], [-s, zero, c]])


def rotation_z(angle: ArrayLike) -> Float[Array, "... 3 3"]:
    """Rotation by ``angle`` (rad) about z (same convention as :func:`rotation_x`)."""
    a = jnp.asarray(angle)
    c, s, one, zero = jnp.cos(a), jnp.sin(a), jnp.ones_like(a), jnp.zeros_like(a)
    return _matrix([[c, -s, zero], [s, c, zero], [zero, zero, one]])


def nav_to_ecef(lat: ArrayLike, lon: ArrayLike) -> Float[Array, "... 3 3"]:
    """``C_n^e`` (E9): NED navigation frame at latitude ``lat``, longitude ``lon`` (rad) → ECEF.

    At ``lat = lon = 0``: North = +z^e, East = +y^e, Down = −x^e. On an ellipsoid, ``lat`` is the
    geodetic latitude. The reverse transform ``C_e^n`` is the transpose.
    """
    lat, lon = jnp.asarray(lat), jnp.asarray(lon)
    sf, cf, sl, cl = jnp.sin(lat), jnp.cos(lat), jnp.sin(lon), jnp.cos(lon)
    return _matrix([[-sf * cl, -sl, -cf * cl], [-sf * sl, cl, -cf * sl], [cf, jnp.zeros_like(sf), -sf]])


def heading_to_nav(heading: ArrayLike) -> Float[Array, "... 3 3"]:
    """``C_h^n`` (E10, with η_z for the printed η_x, FIX-4): ground-track heading η_z (rad)."""
    return rotation_z(heading)


def path_to_heading(flight_path_angle: ArrayLike) -> Float[Array, "... 3 3"]:
    """``C_p^h`` (E11): flight-path angle η_y (rad), positive climbing; ``x^p = [cos η_y, 0, −sin η_y]^h``."""
    return rotation_y(flight_path_angle)


def _euler_321(angles: Array) -> Array:
    """``R_z(a_z) R_y(a_y) R_x(a_x)`` written out element by element as in E12."""
    ax, ay, az = angles[..., 0], angles[..., 1], angles[..., 2]
    sx, cx, sy, cy, sz, cz = jnp.sin(ax), jnp.cos(ax), jnp.sin(ay), jnp.cos(ay), jnp.sin(az), jnp.cos(az)
    return _matrix([
        [cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
        [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
        [-sy, cy * sx, cy * cx],
    ])


def body_to_nav(attitude: ArrayLike) -> Float[Array, "... 3 3"]:
    """``C_b^n`` (E12) from ``attitude = [roll α_x, pitch α_y, yaw α_z]`` (rad), 3-2-1 order."""
    a = jnp.asarray(attitude)
    check_shape("attitude", a, [(3,), (None, 3), (None, None, 3)])
    return _euler_321(a)


def antenna_to_body(antenna_angles: ArrayLike) -> Float[Array, "... 3 3"]:
    """``C_a^b`` (E13): E12 with the antenna roll, pitch and yaw ``ζ = [ζ_x, ζ_y, ζ_z]`` (rad).

    ``x^a`` is the boresight (normal to the array), ``y^a`` and ``z^a`` lie in the array face.
    """
    z = jnp.asarray(antenna_angles)
    check_shape("antenna_angles", z, [(3,), (None, 3), (None, None, 3)])
    return _euler_321(z)


def boresight_angles(los_body: ArrayLike, roll: ArrayLike = 0.0) -> Float[Array, "... 3"]:
    """Antenna angles ζ that put the boresight ``x^a`` on the body-frame direction ``los_body``.

    [EXT] Steering of the electronically scanned array: ``ζ_z = atan2(p_y, p_x)``,
    ``ζ_y = −atan2(p_z, ‖p_xy‖)``, ``ζ_x = roll``.
    """
    p = jnp.asarray(los_body)
    horizontal = jnp.sqrt(p[..., 0] ** 2 + p[..., 1] ** 2)
    roll = jnp.broadcast_to(jnp.asarray(roll, p.dtype), horizontal.shape)
    return jnp.stack([roll, -jnp.arctan2(p[..., 2], horizontal), jnp.arctan2(p[..., 1], p[..., 0])], axis=-1)


# --------------------------------------------------------------------------------------------
# 2. Geometry and measurements (Sec. 4.3–4.4) and SAR background (Sec. 2, Sec. 6.1)


class LookGeometry(eqx.Module):
    """The true state of aircraft, target and antenna at one SAR look (inputs of E14–E29).

    **Fields** (leaves; a batch of looks has a leading axis on every field):

    - ``aircraft_position``: ``r_aⁿ``, m, shape ``(3,)``, NED at the look.
    - ``target_position``: ``r_tⁿ``, m, shape ``(3,)``, same frame.
    - ``velocity``: ``v_aⁿ``, Earth-referenced, m/s, shape ``(3,)``.
    - ``attitude``: body roll, pitch, yaw ``α``, rad, shape ``(3,)`` (E12).
    - ``antenna``: antenna roll, pitch, yaw ``ζ`` relative to the body, rad, shape ``(3,)`` (E13).
    - ``lat``, ``lon``: the aircraft's latitude and longitude, rad, shape ``()`` (for ``C_e^n``).
    """

    aircraft_position: Float[Array, "*B 3"]
    target_position: Float[Array, "*B 3"]
    velocity: Float[Array, "*B 3"]
    attitude: Float[Array, "*B 3"]
    antenna: Float[Array, "*B 3"]
    lat: Float[Array, "*B"]
    lon: Float[Array, "*B"]

    def __init__(self, aircraft_position, target_position, velocity, attitude=(0.0, 0.0, 0.0),
                 antenna=(0.0, 0.0, 0.0), lat=0.0, lon=0.0):
        fields = dict(aircraft_position=aircraft_position, target_position=target_position,
                      velocity=velocity, attitude=attitude, antenna=antenna)
        arrays = {k: jnp.asarray(v) for k, v in fields.items()}
        dtype = jnp.result_type(*arrays.values(), lat, lon, float)
        for name, a in arrays.items():
            if a.shape[-1:] != (3,):
                raise InputError(f"`{name}` must have shape (..., 3); got shape {a.shape}.")
            setattr(self, name, a.astype(dtype))
        self.lat = jnp.asarray(lat, dtype)
        self.lon = jnp.asarray(lon, dtype)

    @property
    def line_of_sight(self) -> Array:
        """``pⁿ = r_t − r_a`` (E14), m."""
        return self.target_position - self.aircraft_position

    def body_to_nav(self) -> Array:
        return body_to_nav(self.attitude)

    def antenna_to_body(self) -> Array:
        return antenna_to_body(self.antenna)

    def nav_to_ecef(self) -> Array:
        return nav_to_ecef(self.lat, self.lon)


def slant_range(los: ArrayLike) -> Array:
    """``r = ‖p‖`` (E15, E20), m; ``los`` shape ``(..., 3)``."""
    return jnp.linalg.norm(jnp.asarray(los), axis=-1)


def range_rate(los: ArrayLike, velocity: ArrayLike) -> Array:
    """``ṙ = −u_pᵀ v_a`` (E19, E21) for a stationary target, m/s; negative when closing."""
    los, velocity = jnp.asarray(los), jnp.asarray(velocity)
    return -jnp.sum(los * velocity, axis=-1) / slant_range(los)


def monopulse_angles(los: ArrayLike, antenna_to_nav: ArrayLike) -> tuple[Array, Array]:
    """Monopulse direction-cosine angles ``(A, E)`` (E22–E29), rad in [0, π].

    ``A = acos(u_pᵀ u_py)`` and ``E = acos(u_pᵀ u_pz)``, with ``u_py``, ``u_pz`` the antenna
    ``y^a``, ``z^a`` axes in nav coordinates (columns 1 and 2 of ``C_a^n = C_b^n C_a^b``). A
    target on boresight has ``A = E = π/2``. The derivative of acos is singular for a target in
    the antenna plane (A or E = 0, π); the cosines are clipped so the value stays defined there.
    """
    los, C = jnp.asarray(los), jnp.asarray(antenna_to_nav)
    u = los / slant_range(los)[..., None]
    cos_a = jnp.sum(u * C[..., :, 1], axis=-1)
    cos_e = jnp.sum(u * C[..., :, 2], axis=-1)
    return jnp.arccos(jnp.clip(cos_a, -1.0, 1.0)), jnp.arccos(jnp.clip(cos_e, -1.0, 1.0))


def _radar(r_a, v, r_t, C_bn, C_ab) -> Array:
    p = r_t - r_a
    A, E = monopulse_angles(p, C_bn @ C_ab)
    return jnp.stack([slant_range(p), range_rate(p, v), A, E])


def radar_measurements(look: LookGeometry) -> Float[Array, "4"]:
    """Noise-free ``[r, ṙ, A, E]`` of one look (E14–E29): m, m/s, rad, rad.

    Use ``jax.vmap`` over a batch of looks.
    """
    return _radar(look.aircraft_position, look.velocity, look.target_position, look.body_to_nav(), look.antenna_to_body())


def los_from_monopulse(azimuth: ArrayLike, elevation: ArrayLike) -> Float[Array, "... 3"]:
    """Unit LOS in antenna axes from the monopulse angles (E51–E53).

    ``u^a = [+sqrt(1 − cos²A − cos²E), cos A, cos E]``: the target is in front of the array.
    """
    ca, ce = jnp.cos(jnp.asarray(azimuth)), jnp.cos(jnp.asarray(elevation))
    return jnp.stack([_safe_sqrt(1.0 - ca * ca - ce * ce), ca, ce], axis=-1)


def range_from_round_trip(round_trip_time: ArrayLike) -> Array:
    """``r = cT/2`` (E1, FIX-1), m, from the round-trip transit time T (s)."""
    return SPEED_OF_LIGHT * jnp.asarray(round_trip_time) / 2.0


def range_rate_from_doppler(doppler: ArrayLike, wavelength: ArrayLike) -> Array:
    """``ṙ = −λF_d/2`` (E2 with the sign convention of FIX-38: closing ⇒ F_d > 0, ṙ < 0), m/s."""
    return -jnp.asarray(wavelength) * jnp.asarray(doppler) / 2.0


def focusing_phase(offset: ArrayLike, boresight_range: ArrayLike, wavelength: ArrayLike) -> Array:
    """Focused-SAR phase correction ``θ_k ≈ (2π/λ)(d_k²/R)`` (E3–E8), rad.

    ``offset`` is ``d_k``, the distance of pulse ``k`` from the array centre (m); valid for
    ``ΔR_k = d_k²/(2R) ≪ 2R`` (E7).
    """
    d = jnp.asarray(offset)
    return 2.0 * jnp.pi / jnp.asarray(wavelength) * d * d / jnp.asarray(boresight_range)


def range_resolution(bandwidth: ArrayLike) -> Array:
    """``Δr = c/(2B)`` (E68), m, for bandwidth B in Hz (stripmap and spotlight)."""
    return SPEED_OF_LIGHT / (2.0 * jnp.asarray(bandwidth))


def stripmap_azimuth_resolution(antenna_length: ArrayLike) -> Array:
    """``Δaz = D/2`` (E69), m; D is the along-track real-aperture length (FIX-44)."""
    return jnp.asarray(antenna_length) / 2.0


def spotlight_azimuth_resolution(wavelength: ArrayLike, integration_angle: ArrayLike) -> Array:
    """``Δaz = λ/(2φ)`` (E70), m; φ is the LOS rotation during the collection (rad, FIX-6)."""
    return jnp.asarray(wavelength) / (2.0 * jnp.asarray(integration_angle))


def los_rotation_rate(range_: ArrayLike, range_rate_: ArrayLike, speed: ArrayLike) -> Array:
    """``ω_t = (|v|/r) sqrt(1 − (ṙ/|v|)²) = |v| sin β / r`` (E72, FIX-18), rad/s."""
    speed = jnp.asarray(speed)
    return speed / jnp.asarray(range_) * _safe_sqrt(1.0 - (jnp.asarray(range_rate_) / speed) ** 2)


def range_rate_resolution(azimuth_resolution: ArrayLike, los_rate: ArrayLike) -> Array:
    """``Δṙ = ω_t Δaz`` (E71), m/s."""
    return jnp.asarray(los_rate) * jnp.asarray(azimuth_resolution)


def atmospheric_loss(range_: ArrayLike) -> Array:
    """``L_a = 10^(−2.16e-6 r)`` (E65, FIX-17), one-way-in-the-exponent attenuation ≤ 1; r in m."""
    return 10.0 ** (-2.16e-6 * jnp.asarray(range_))


def rain_loss(range_: ArrayLike, rain_rate: ArrayLike) -> Array:
    """``L_r = 10^(−5.4e-6 η r)`` (E66, FIX-17); rain rate η in mm/h, r in m."""
    return 10.0 ** (-5.4e-6 * jnp.asarray(rain_rate) * jnp.asarray(range_))


def clutter_cross_section(range_res: ArrayLike, azimuth_res: ArrayLike, reflectivity: float = 0.1) -> Array:
    """``ρ_c = σ⁰ Δr Δaz`` with σ⁰ = 0.1 (E67), m²."""
    return reflectivity * jnp.asarray(range_res) * jnp.asarray(azimuth_res)


def signal_to_noise(rcs, range_, *, reference_range=1.5e5, gain_loss=1.0, integration_time=1.0,
                    rain_rate=0.0, range_exponent: float = 4.0) -> Array:
    """``SNR = ρ ΔG² L_a L_r T_I (r_0/r)^n`` (E63 with n = 4; E62 for clutter, FIX-15).

    ``rcs`` is the target RCS ρ_t (or the clutter ρ_c) in m²; ``reference_range`` r_0 (m) is
    where SNR = 1 for 1 m², 1 s and full gain; ``range_exponent`` is 4 (radar equation) or the
    printed 1 of E62.
    """
    range_ = jnp.asarray(range_)
    return (jnp.asarray(rcs) * gain_loss * atmospheric_loss(range_) * rain_loss(range_, rain_rate)
            * integration_time * (reference_range / range_) ** range_exponent)


def signal_to_clutter_noise(snr: ArrayLike, cnr: ArrayLike, noise_term: float = 1.0) -> Array:
    """``SCNR = SNR/(CNR + 1)`` (E64 corrected, FIX-16); ``noise_term=0.1`` is the printed form."""
    return jnp.asarray(snr) / (jnp.asarray(cnr) + noise_term)


def designation_factor_ref2(scnr: ArrayLike) -> Array:
    """``K = 1/(2√SCNR)`` of ref. [2] (FIX-35); the report itself uses K = 2."""
    return 0.5 / jnp.sqrt(jnp.asarray(scnr))


def to_db(ratio: ArrayLike) -> Array:
    return 10.0 * jnp.log10(jnp.asarray(ratio))


# --------------------------------------------------------------------------------------------
# 3. Single-look targeting (Sec. 5), corrected (FIX-7 … FIX-11)


def single_look_target(
    measurements: ArrayLike,
    aircraft_position: ArrayLike,
    velocity: ArrayLike,
    body_to_nav_dcm: ArrayLike,
    antenna_to_body_dcm: ArrayLike,
    *,
    doppler_cone: Literal["general", "literal"] = "general",
) -> Float[Array, "3"]:
    r"""Closed-form target position from one look (Sec. 5, E30–E55, spec §1.7), m, NED.

    The target is the intersection of the range sphere, the Doppler cone about the velocity and
    the plane ``h_t`` below the aircraft, with ``h_t = r u_pzⁿ`` from the monopulse LOS (E55):

    .. math::

        p^p = \bigl[r\cos β,\ s\sqrt{r^2 − p_x^2 − p_z^2},\ \tan η_y\, p_x + h_t/\cos η_y\bigr],
        \qquad \cos β = −ṙ/|v_a|

    (E31, E40, E47–E48 corrected), with η_z, η_y the heading and climb angle of the velocity
    (E49–E50, FIX-11) and ``s`` the side of the monopulse LOS in the path frame (FIX-8). The
    solution is ``r_tⁿ = r_aⁿ + C_h^n C_p^h p^p``; for ECEF, ``r_t^e = r_a^e + C_n^e (r_tⁿ − r_aⁿ)``.

    **Arguments:**

    - ``measurements``: ``[r, ṙ, A, E]`` (m, m/s, rad, rad), shape ``(4,)``.
    - ``aircraft_position``: INS ``r_aⁿ``, m, shape ``(3,)``.
    - ``velocity``: INS ``v_aⁿ``, m/s, shape ``(3,)`` (not vertical).
    - ``body_to_nav_dcm``: INS ``C_b^n``, shape ``(3, 3)``.
    - ``antenna_to_body_dcm``: ``C_a^b`` from the gimbal/ESA angles, shape ``(3, 3)``.
    - ``doppler_cone``: ``"general"`` (FIX-7) or ``"literal"``, the printed ``cos β = |ṙ|/|v|``,
      which mirrors receding targets across the cross-track plane (V-5b).

    **Returns:** ``r_tⁿ``, shape ``(3,)``.

    **Raises:** :class:`~jaxtrack.InputError` for wrong shapes, or (when concrete) angles that put
    the target behind the array face (``cos²A + cos²E > 1``).
    """
    _choice("doppler_cone", doppler_cone, ("general", "literal"))
    m = jnp.asarray(measurements)
    check_shape("measurements", m, [(4,)])
    r_a = _vec3("aircraft_position", aircraft_position)
    v = _vec3("velocity", velocity)
    C_bn, C_ab = jnp.asarray(body_to_nav_dcm), jnp.asarray(antenna_to_body_dcm)
    check_shape("body_to_nav_dcm", C_bn, [(3, 3)])
    check_shape("antenna_to_body_dcm", C_ab, [(3, 3)])
    r, rdot, A, E = m[0], m[1], m[2], m[3]
    if is_concrete(m):
        front = 1.0 - np.cos(float(A)) ** 2 - np.cos(float(E)) ** 2
        if front < -1e-12:
            raise InputError(
                f"`measurements` angles A, E give cos²A + cos²E = {1 - front:.6g} > 1: the target "
                f"would be behind the array face (E51 needs u_px^a ≥ 0)."
            )
    u_n = C_bn @ C_ab @ los_from_monopulse(A, E)  # E54
    h_t = r * u_n[2]  # E55
    speed = jnp.linalg.norm(v)
    heading = jnp.arctan2(v[1], v[0])
    C_hn = heading_to_nav(heading)
    v_h = C_hn.T @ v
    climb = jnp.arctan2(-v_h[2], v_h[0])  # E49/E50 (FIX-11)
    C_ph = path_to_heading(climb)
    # FIX-7: cos β = −ṙ/|v| holds on both sides of broadside; |ṙ|/|v| only for β ≤ π/2.
    cos_cone = jnp.abs(rdot) / speed if doppler_cone == "literal" else -rdot / speed
    p_x = r * cos_cone  # E31, E33
    p_z = jnp.tan(climb) * p_x + h_t / jnp.cos(climb)  # E47 (FIX-9)
    side = jnp.sign((C_hn @ C_ph).T @ u_n)[1]  # resolves the ± of E40 (FIX-8)
    p_y = side * _safe_sqrt(r * r - p_x * p_x - p_z * p_z)  # E40 (FIX-8, FIX-10)
    return r_a + C_hn @ C_ph @ jnp.stack([p_x, p_y, p_z])


def targeting_round_trip_error(looks: LookGeometry, *, doppler_cone: Literal["general", "literal"] = "general") -> Array:
    """‖closed-form target − true target‖ (m) from the looks' own noise-free measurements (V-5).

    ``looks`` is a batch (leading axis) of :class:`LookGeometry`; returns shape ``(B,)``.
    """

    def one(look):
        est = single_look_target(radar_measurements(look), look.aircraft_position, look.velocity,
                                 look.body_to_nav(), look.antenna_to_body(), doppler_cone=doppler_cone)
        return jnp.linalg.norm(est - look.target_position)

    return jax.jit(jax.vmap(one))(looks)


@functools.partial(jax.jit, static_argnums=1)
def random_targeting_geometries(key: Array, num: int) -> LookGeometry:
    """Random looks for the round-trip test V-5 (a batch of ``num`` :class:`LookGeometry`).

    Slant range 5–60 km, aircraft 1–12 km above the target plane (and below 0.95 r), speed
    100–300 m/s, any heading, flight-path angle ±0.3 rad, squint 10°–160° off the ground track
    on either side, roll ±0.3 rad, pitch and yaw within 0.1 rad of the velocity, and an antenna
    pointed within 0.3 rad (yaw, pitch) and 0.5 rad (roll) of the target.
    """
    k = jax.random.split(key, 10)
    u = lambda i, lo, hi: jax.random.uniform(k[i], (num,), minval=lo, maxval=hi)  # noqa: E731
    rng = u(0, 5e3, 6e4)
    height = jnp.minimum(u(1, 1e3, 1.2e4), 0.95 * rng)
    speed = u(2, 100.0, 300.0)
    heading = u(3, -jnp.pi, jnp.pi)
    climb = u(4, -0.3, 0.3)
    squint = u(5, jnp.deg2rad(10.0), jnp.deg2rad(160.0)) * jnp.where(jax.random.bernoulli(k[6], 0.5, (num,)), 1.0, -1.0)
    ground = jnp.sqrt(rng * rng - height * height)
    bearing = heading + squint
    zeros = jnp.zeros_like(rng)
    r_a = jnp.stack([zeros, zeros, -height], axis=-1)
    r_t = jnp.stack([ground * jnp.cos(bearing), ground * jnp.sin(bearing), zeros], axis=-1)
    v = speed[:, None] * jnp.stack([jnp.cos(climb) * jnp.cos(heading), jnp.cos(climb) * jnp.sin(heading), -jnp.sin(climb)], axis=-1)
    offsets = jax.random.uniform(k[7], (num, 3), minval=-1.0, maxval=1.0) * jnp.array([0.3, 0.1, 0.1])[None, :]
    attitude = jnp.stack([zeros, climb, heading], axis=-1) + offsets
    los_b = jnp.einsum("bji,bj->bi", body_to_nav(attitude), r_t - r_a)
    point = boresight_angles(los_b)
    antenna = point + jax.random.uniform(k[8], (num, 3), minval=-1.0, maxval=1.0) * jnp.array([0.5, 0.3, 0.3])[None, :]
    lat = u(9, -1.2, 1.2)
    return LookGeometry(r_a, r_t, v, attitude, antenna, lat, jnp.zeros_like(lat))


# --------------------------------------------------------------------------------------------
# 4. DCM perturbations and the attitude-error angles (Sec. 8.1)


def dcm_perturbation(attitude: ArrayLike, attitude_error: ArrayLike) -> Float[Array, "3 3"]:
    """First-order ``δC_b^n = Σ_k (∂C_b^n/∂α_k) δα_k`` (E106, the spec's element-wise form).

    ``attitude`` α and ``attitude_error`` δα are ``[roll, pitch, yaw]`` in rad, shape ``(3,)``.
    """
    a, d = _vec3("attitude", attitude), _vec3("attitude_error", attitude_error)
    sx, cx, sy, cy, sz, cz = jnp.sin(a[0]), jnp.cos(a[0]), jnp.sin(a[1]), jnp.cos(a[1]), jnp.sin(a[2]), jnp.cos(a[2])
    dx, dy, dz = d[0], d[1], d[2]
    return _matrix([
        [-dy * sy * cz - dz * sz * cy,
         dx * (sx * sz + sy * cx * cz) + dy * sx * cy * cz - dz * (sx * sy * sz + cx * cz),
         dx * (-sx * sy * cz + sz * cx) + dy * cx * cy * cz + dz * (sx * cz - sy * sz * cx)],
        [-dy * sy * sz + dz * cy * cz,
         dx * (-sx * cz + sy * sz * cx) + dy * sx * sz * cy + dz * (sx * sy * cz - sz * cx),
         dx * (-sx * sy * sz - cx * cz) + dy * sz * cx * cy + dz * (sx * sz + sy * cx * cz)],
        [-dy * cy, dx * cx * cy - dy * sx * sy, -dx * sx * cy - dy * sy * cx],
    ])


def orthonormalize(dcm: ArrayLike) -> Float[Array, "3 3"]:
    """Optimal orthogonalisation ``(C̄)_o = C̄ (C̄ᵀC̄)^{−1/2}`` (E107, Britting; FIX-13)."""
    C = jnp.asarray(dcm)
    check_shape("dcm", C, [(3, 3)])
    w, V = jnp.linalg.eigh(C.T @ C)
    return C @ (V * (1.0 / jnp.sqrt(w))[None, :]) @ V.T


def orthonormalize_first_order(dcm: ArrayLike, perturbation: ArrayLike) -> Float[Array, "3 3"]:
    """``(C + δC)_o ≈ (I + ½[δC Cᵀ − C δCᵀ]) C`` (E108), for an orthonormal ``C``."""
    C, dC = jnp.asarray(dcm), jnp.asarray(perturbation)
    return (jnp.eye(3, dtype=C.dtype) + 0.5 * (dC @ C.T - C @ dC.T)) @ C


def psi_from_dcm_error(dcm: ArrayLike, perturbation: ArrayLike, *, printed_e112: bool = False) -> Float[Array, "3"]:
    """Attitude-error angles ψ from ``C`` and ``δC`` (E109–E113), rad.

    ``Ψ = [ψ×] = ½[C δCᵀ − δC Cᵀ]``, i.e. ``(C + δC)_o = (I − Ψ) C`` (E109). ``printed_e112=True``
    uses the OCR's middle term ``c13 δc32 − c32 δc13`` in ψ_y instead of ``c12 δc32 − c32 δc12``
    (FIX-14), for the regression test only.
    """
    c, d = jnp.asarray(dcm), jnp.asarray(perturbation)
    psi_x = 0.5 * (c[2, 0] * d[1, 0] - c[1, 0] * d[2, 0] + c[2, 1] * d[1, 1] - c[1, 1] * d[2, 1]
                   + c[2, 2] * d[1, 2] - c[1, 2] * d[2, 2])
    middle = (c[0, 2] * d[2, 1] - c[2, 1] * d[0, 2]) if printed_e112 else (c[0, 1] * d[2, 1] - c[2, 1] * d[0, 1])
    psi_y = 0.5 * (c[0, 0] * d[2, 0] - c[2, 0] * d[0, 0] + middle + c[0, 2] * d[2, 2] - c[2, 2] * d[0, 2])
    psi_z = 0.5 * (c[1, 0] * d[0, 0] - c[0, 0] * d[1, 0] + c[1, 1] * d[0, 1] - c[0, 1] * d[1, 1]
                   + c[1, 2] * d[0, 2] - c[0, 2] * d[1, 2])
    return jnp.stack([psi_x, psi_y, psi_z])


def euler_error_matrix(attitude: ArrayLike) -> Float[Array, "3 3"]:
    """``M`` with ``ψ = −M δα`` (spec §2.4.1 [EXT], from δC_b^n = −Ψ C_b^n); singular at pitch ±90°.

    The same relation maps antenna-angle errors δζ to β with ζ in place of α.
    """
    a = _vec3("attitude", attitude)
    sy, cy, sz, cz = jnp.sin(a[1]), jnp.cos(a[1]), jnp.sin(a[2]), jnp.cos(a[2])
    zero, one = jnp.zeros_like(sy), jnp.ones_like(sy)
    return _matrix([[cz * cy, -sz, zero], [sz * cy, cz, zero], [-sy, zero, one]])


def psi_to_euler_error(attitude: ArrayLike, psi: ArrayLike) -> Float[Array, "3"]:
    """``δα = −M⁻¹ ψ`` (spec §2.4.1 [EXT]): the Euler-angle correction for an attitude error ψ."""
    a, psi = _vec3("attitude", attitude), _vec3("psi", psi)
    sy, cy, sz, cz = jnp.sin(a[1]), jnp.cos(a[1]), jnp.sin(a[2]), jnp.cos(a[2])
    zero, one = jnp.zeros_like(sy), jnp.ones_like(sy)
    M_inv = _matrix([[cz / cy, sz / cy, zero], [-sz, cz, zero], [cz * sy / cy, sz * sy / cy, one]])
    return -M_inv @ psi


# --------------------------------------------------------------------------------------------
# 5. Error budgets (Tables 5–7) and the per-look measurement noise (Sec. 6)


class INSErrorBudget(eqx.Module):
    """INS error budget (Table 5): RMS of the random constants and the white-noise PSDs.

    - ``accel_bias``: ∇ RMS, m/s².   ``accel_scale_factor``: k_∇ RMS, –.
    - ``accel_noise_psd``: q_v, m²/s³ (per axis).
    - ``gyro_bias``: ε RMS, rad/s.   ``gyro_scale_factor``: k_ε RMS, –.
    - ``gyro_noise_psd``: q_ψ, rad²/s (per axis).
    """

    accel_bias: Float[Array, ""]
    accel_scale_factor: Float[Array, ""]
    accel_noise_psd: Float[Array, ""]
    gyro_bias: Float[Array, ""]
    gyro_scale_factor: Float[Array, ""]
    gyro_noise_psd: Float[Array, ""]


def h423_budget(ins_noise_units: NoiseUnits = "per_sqrt_hz") -> INSErrorBudget:
    """Table 5 (Honeywell H423): 30 µg, 175 PPM, 0.004 °/h, 2 PPM and the white noises.

    ``ins_noise_units`` (FIX-20): ``"per_sqrt_hz"`` reads "0.0025 FPS √Hz" and "0.0020 Deg/Hr/√Hz"
    as √PSD (√q_v = 7.62e-4 m/s^1.5, √q_ψ = 9.69627e-9 rad/√s); ``"per_sqrt_hour"`` reads them as
    0.0025 ft/s/√h and 0.002 °/√h.
    """
    _choice("ins_noise_units", ins_noise_units, ("per_sqrt_hz", "per_sqrt_hour"))
    if ins_noise_units == "per_sqrt_hz":
        sqrt_qv, sqrt_qpsi = 0.0025 * FOOT, 0.0020 * DEG_PER_HOUR
    else:
        sqrt_qv, sqrt_qpsi = 0.0025 * FOOT / 60.0, 0.0020 * math.pi / 180.0 / 60.0
    f = lambda x: jnp.asarray(x, float)  # noqa: E731
    return INSErrorBudget(f(30 * MICRO_G), f(175e-6), f(sqrt_qv ** 2), f(0.004 * DEG_PER_HOUR), f(2e-6), f(sqrt_qpsi ** 2))


class SARErrorBudget(eqx.Module):
    """SAR geometry error budget (Table 6, Sec. 6.1).

    - ``range_clock``: δr_CL RMS, m (0.01 ft).   ``doppler_bias``: δṙ_D RMS, m/s (0.001 ft/s).
    - ``propagation_speed``: δC RMS, fraction (10 PPM).   ``frequency``: δF RMS, fraction (20 PPM).
    - ``range_resolution`` Δr and ``azimuth_resolution`` Δaz, m.
    - ``designation_factor``: K (designation error K·Δr, K·Δṙ; the report uses 2).
    - ``processing_delay``: T_d, s.
    - ``timing_model`` (static): ``"derivative"`` (σ_rT = T_d|ṙ|, σ_ṙT = T_d|r̈|) or
      ``"literal"`` (T_d·r, T_d·ṙ; dimensionally wrong, FIX-19).
    """

    range_clock: Float[Array, ""]
    doppler_bias: Float[Array, ""]
    propagation_speed: Float[Array, ""]
    frequency: Float[Array, ""]
    range_resolution: Float[Array, ""]
    azimuth_resolution: Float[Array, ""]
    designation_factor: Float[Array, ""]
    processing_delay: Float[Array, ""]
    timing_model: TimingModel = eqx.field(static=True)

    def __check_init__(self):
        _choice("timing_model", self.timing_model, ("derivative", "literal"))


def table6_budget(range_res: float = 1.0, azimuth_res: float = 1.0, *, designation_factor: float = 2.0,
                  processing_delay: float = 1e-3, timing_model: TimingModel = "derivative") -> SARErrorBudget:
    """Table 6 with the RS-1 resolutions (Δr = Δaz = 1 m, K = 2, T_d = 1 ms) by default."""
    f = lambda x: jnp.asarray(x, float)  # noqa: E731
    return SARErrorBudget(f(0.01 * FOOT), f(0.001 * FOOT), f(10e-6), f(20e-6), f(range_res), f(azimuth_res),
                          f(designation_factor), f(processing_delay), timing_model)


# Table 7 white terms, per angle (mrad): mechanical alignment, flexure, radome phase uniformity,
# Rx channel cross coupling, monopulse slope, thermal noise, quantisation, radome.
MONOPULSE_WHITE_TERMS = {"MA": 0.30, "FL": 0.10, "PU": 0.35, "CC": 0.15, "MS": 0.10, "TN": 0.20, "Q": 0.20, "RAD": 0.40}


class MonopulseErrorBudget(eqx.Module):
    """Monopulse error budget (Table 7, Sec. 6.2); every value applies to A and to E.

    - ``temperature``: δA_TEMP, δE_TEMP RMS, rad (0.40 mrad).
    - ``white_terms``: the eight white RMS terms, rad, shape ``(8,)`` (MONOPULSE_WHITE_TERMS order).
    - ``misalignment``: antenna misalignment β RMS per body axis, rad (1.20 mrad).
    - ``temperature_inverse_correlation_time``: β_TEMP, 1/s; 0 makes TEMP a random bias (FIX-26).
    """

    temperature: Float[Array, ""]
    white_terms: Float[Array, "8"]
    misalignment: Float[Array, ""]
    temperature_inverse_correlation_time: Float[Array, ""]

    @property
    def white_std(self) -> Array:
        """RSS of the eight white terms (E82–E83): 0.7035624 mrad for Table 7."""
        return jnp.sqrt(jnp.sum(self.white_terms ** 2))

    @property
    def total_std(self) -> Array:
        """White RSS with the TEMP bias: 0.8093207 mrad for Table 7."""
        return jnp.sqrt(self.white_std ** 2 + self.temperature ** 2)


def table7_budget(temperature_inverse_correlation_time: float = 0.0) -> MonopulseErrorBudget:
    """Table 7 in rad."""
    f = lambda x: jnp.asarray(x, float)  # noqa: E731
    return MonopulseErrorBudget(f(0.40 * MRAD), f(np.array(list(MONOPULSE_WHITE_TERMS.values())) * MRAD),
                                f(1.20 * MRAD), f(temperature_inverse_correlation_time))


def designation_noise_factor(designation_factor: ArrayLike) -> Array:
    """``sqrt(K² + 1/12 + 0.25)``: designation, quantisation and "other" white terms per resolution
    cell (E73–E77, E80–E81); 2.0816660 for K = 2."""
    K = jnp.asarray(designation_factor)
    return jnp.sqrt(K * K + 1.0 / 12.0 + 0.25)


def sar_noise_std(budget: SARErrorBudget, range_: ArrayLike, range_rate_: ArrayLike, speed: ArrayLike) -> tuple[Array, Array]:
    """White SAR noise ``(σ_r, σ_ṙ)`` per look (E73–E81, Table 6), m and m/s.

    ``σ_r² = (K² + 1/12 + ¼) Δr² + σ_rT²`` and ``σ_ṙ² = (K² + 1/12 + ¼) Δṙ² + σ_ṙT²`` with
    ``Δṙ = ω_t Δaz`` (E71–E72) and the timing terms of ``budget.timing_model`` (FIX-19;
    ``r̈ = (|v|² − ṙ²)/r`` for straight, unaccelerated flight).
    """
    r, rdot, speed = jnp.asarray(range_), jnp.asarray(range_rate_), jnp.asarray(speed)
    factor = designation_noise_factor(budget.designation_factor)
    d_rdot = range_rate_resolution(budget.azimuth_resolution, los_rotation_rate(r, rdot, speed))
    if budget.timing_model == "derivative":
        timing_r, timing_rdot = budget.processing_delay * jnp.abs(rdot), budget.processing_delay * jnp.abs((speed ** 2 - rdot ** 2) / r)
    else:
        timing_r, timing_rdot = budget.processing_delay * r, budget.processing_delay * jnp.abs(rdot)
    sigma_r = jnp.sqrt((factor * budget.range_resolution) ** 2 + timing_r ** 2)
    sigma_rdot = jnp.sqrt((factor * d_rdot) ** 2 + timing_rdot ** 2)
    return sigma_r, sigma_rdot


def measurement_noise_cov(look: LookGeometry, sar: SARErrorBudget, monopulse: MonopulseErrorBudget) -> Float[Array, "4 4"]:
    """``R = diag(σ_r², σ_ṙ², σ_A², σ_E²)`` of one look (E187; the four sums are independent)."""
    m = radar_measurements(look)
    sigma_r, sigma_rdot = sar_noise_std(sar, m[0], m[1], jnp.linalg.norm(look.velocity))
    sa = monopulse.white_std
    return jnp.diag(jnp.stack([sigma_r ** 2, sigma_rdot ** 2, sa ** 2, sa ** 2]))


# --------------------------------------------------------------------------------------------
# 6. The 33-state error model (Sec. 10–11, Tables 1–4)


class ErrorModelOptions(eqx.Module):
    """Conventions of the error dynamics that the spec leaves open (all static).

    - ``psi_sign_convention``: ``"consistent"`` (F_vψ = +[A×], ψ̇ = −[ω×]ψ − ε − diag(ω)k_ε, to
      match H's C̄ = (I − [ψ×])C) or ``"report_literal"`` (Table 1: −[A×], +ε) (FIX-24).
    - ``vertical_gravity_gradient``: ``"physical"`` Γ = ω_s² diag(−1, −1, +2) or ``"report"``
      Γ = −ω_s² I (FIX-25).
    - ``sensor_frame``: ``"nav"`` (Table 1, local-level coupling) or ``"body"`` (strapdown:
      ∇ → C_b^n∇, k_∇ → C_b^n diag(f^b), ε → C_b^n ε, k_ε → C_b^n diag(ω_ib^b)) (FIX-32).
    """

    psi_sign_convention: PsiConvention = eqx.field(static=True, default="consistent")
    vertical_gravity_gradient: GravityGradient = eqx.field(static=True, default="physical")
    sensor_frame: SensorFrame = eqx.field(static=True, default="nav")

    def __check_init__(self):
        _choice("psi_sign_convention", self.psi_sign_convention, ("consistent", "report_literal"))
        _choice("vertical_gravity_gradient", self.vertical_gravity_gradient, ("physical", "report"))
        _choice("sensor_frame", self.sensor_frame, ("nav", "body"))


class NavigationRates(NamedTuple):
    """The reference-trajectory quantities that enter F (Sec. 10), all in nav axes (NED).

    - ``earth_rate`` Ω (rad/s), ``transport_rate`` ρ (rad/s), ``transport_rate_dot`` ρ̇ (rad/s²).
    - ``specific_force`` A = f = a − g (m/s²; ≈ [0, 0, −g] in level flight) (FIX-24).
    - ``gravity_gradient`` Γ (1/s², ``(3, 3)``).
    - ``body_to_nav`` C_b^n and ``body_rate`` ω_ib^b (rad/s): used by ``sensor_frame="body"``.
    """

    earth_rate: Array
    transport_rate: Array
    transport_rate_dot: Array
    specific_force: Array
    gravity_gradient: Array
    body_to_nav: Array
    body_rate: Array


def earth_rate_nav(lat: ArrayLike) -> Float[Array, "... 3"]:
    """``Ωⁿ = Ω_e [cos φ, 0, −sin φ]`` (spec §2.6 [EXT]), rad/s."""
    lat = jnp.asarray(lat)
    return EARTH_RATE * jnp.stack([jnp.cos(lat), jnp.zeros_like(lat), -jnp.sin(lat)], axis=-1)


def transport_rate(lat: ArrayLike, height: ArrayLike, velocity: ArrayLike, radius: float = EARTH_RADIUS) -> Float[Array, "3"]:
    """``ρⁿ = [v_E, −v_N, −v_E tan φ]/(R + h)`` (spec §2.6 [EXT], spherical Earth), rad/s."""
    v = jnp.asarray(velocity)
    rh = radius + jnp.asarray(height)
    return jnp.stack([v[1], -v[0], -v[1] * jnp.tan(jnp.asarray(lat))]) / rh


def gravity_gradient(convention: GravityGradient = "physical", *, gravity: float = GRAVITY,
                     radius: float = EARTH_RADIUS) -> Float[Array, "3 3"]:
    """Γ with ``ω_s² = g/R`` (FIX-25): ``ω_s² diag(−1, −1, +2)`` or the printed ``−ω_s² I``."""
    _choice("vertical_gravity_gradient", convention, ("physical", "report"))
    ws2 = gravity / radius
    return ws2 * jnp.diag(jnp.array([-1.0, -1.0, 2.0 if convention == "physical" else -1.0]))


def navigation_rates(lat, height, velocity, attitude, *, acceleration=(0.0, 0.0, 0.0),
                     options: ErrorModelOptions = ErrorModelOptions(), radius: float = EARTH_RADIUS,
                     gravity: float = GRAVITY) -> NavigationRates:
    """:class:`NavigationRates` of a flight condition on a spherical Earth [EXT].

    ``acceleration`` is the nav-frame derivative of ``v_aⁿ`` (m/s²). ρ̇ is the derivative of ρⁿ
    along the trajectory (φ̇ = v_N/(R + h), ḣ = −v_D), by ``jax.jvp``. The specific force is
    ``f = v̇ + (2Ω + ρ) × v − [0, 0, g]`` (the navigation equation) and the body rate is
    ``ω_ib^b = C_n^b (Ω + ρ)`` (attitude held fixed relative to the nav frame).
    """
    lat, height = jnp.asarray(lat, float), jnp.asarray(height, float)
    v, vdot = _vec3("velocity", velocity), _vec3("acceleration", acceleration)
    rh = radius + height
    rho, rho_dot = jax.jvp(lambda la, h, vel: transport_rate(la, h, vel, radius), (lat, height, v),
                           (v[0] / rh, -v[2], vdot))
    Omega = earth_rate_nav(lat)
    f = vdot + jnp.cross(2.0 * Omega + rho, v) - jnp.array([0.0, 0.0, gravity])
    C_bn = body_to_nav(_vec3("attitude", attitude))
    return NavigationRates(Omega, rho, rho_dot, f, gravity_gradient(options.vertical_gravity_gradient, gravity=gravity, radius=radius),
                           C_bn, C_bn.T @ (Omega + rho))


def velocity_error_position_gain(rho: ArrayLike, rho_dot: ArrayLike, earth_rate: ArrayLike, gamma: ArrayLike) -> Float[Array, "3 3"]:
    """``F_vr`` (E178 corrected, FIX-25), written out element by element, 1/s².

    ``ω = Ω + ρ``; entries ``ω² − Ω² − (ω_i + Ω_i)ρ_i + Γ_ii`` on the diagonal and the ρ̇ terms
    off it. Equals ``−[ω̇×] − [ω×]² + [Ω×]² + Γ`` with ``ω̇ = ρ̇ + Ω × ρ`` (V-15).
    """
    r, rd, W, G = (jnp.asarray(a) for a in (rho, rho_dot, earth_rate, gamma))
    w = W + r
    s = w + W
    d = w @ w - W @ W
    return G + _matrix([
        [d - s[0] * r[0], rd[2] - s[1] * r[0], -rd[1] - s[2] * r[0]],
        [-rd[2] - s[0] * r[1], d - s[1] * r[1], rd[0] - s[2] * r[1]],
        [rd[1] - s[0] * r[2], -rd[0] - s[1] * r[2], d - s[2] * r[2]],
    ])


def velocity_error_position_gain_compact(rho, rho_dot, earth_rate, gamma) -> Float[Array, "3 3"]:
    """``F_vr = −[ω̇×] − [ω×]² + [Ω×]² + Γ`` with ``ω̇ = ρ̇ + Ω × ρ`` (the spec's compact E178)."""
    r, rd, W, G = (jnp.asarray(a) for a in (rho, rho_dot, earth_rate, gamma))
    w = skew(W + r)
    return -skew(rd + jnp.cross(W, r)) - w @ w + skew(W) @ skew(W) + G


def ins_error_dynamics(rates: NavigationRates, options: ErrorModelOptions = ErrorModelOptions()) -> Float[Array, "27 27"]:
    """``F_Ind`` (Table 1 corrected, E178–E182; spec §2.6), the 27 INS, target and β states.

    .. code-block:: text

        d/dt δr_a = δv_a
        d/dt δv_a = F_vr δr_a − 2[ω×] δv_a ± [A×] ψ + ∇ + diag(A) k_∇
        d/dt ψ    = −[ω×] ψ ∓ ε ∓ diag(ω) k_ε
        d/dt (∇, k_∇, ε, k_ε, δr_t^e, β) = 0

    with the upper signs for ``psi_sign_convention="consistent"`` and the lower for
    ``"report_literal"``; the strapdown coupling when ``sensor_frame="body"``.
    """
    Omega, rho = rates.earth_rate, rates.transport_rate
    omega = Omega + rho
    f = rates.specific_force
    dtype = jnp.result_type(omega, f, rates.gravity_gradient)
    I3 = jnp.eye(3, dtype=dtype)
    sign = 1.0 if options.psi_sign_convention == "consistent" else -1.0
    if options.sensor_frame == "nav":
        accel_bias, accel_scale = I3, jnp.diag(f)
        gyro_bias, gyro_scale = I3, jnp.diag(omega)
    else:
        C = rates.body_to_nav
        accel_bias, accel_scale = C, C @ jnp.diag(C.T @ f)
        gyro_bias, gyro_scale = C, C @ jnp.diag(rates.body_rate)
    F = jnp.zeros((NUM_INS_STATES, NUM_INS_STATES), dtype)
    F = F.at[POSITION, VELOCITY].set(I3)
    F = F.at[VELOCITY, POSITION].set(velocity_error_position_gain(rho, rates.transport_rate_dot, Omega, rates.gravity_gradient))
    F = F.at[VELOCITY, VELOCITY].set(-2.0 * skew(omega))  # E179
    F = F.at[VELOCITY, ATTITUDE].set(sign * skew(f))  # E180 with FIX-24
    F = F.at[VELOCITY, ACCEL_BIAS].set(accel_bias)
    F = F.at[VELOCITY, ACCEL_SCALE].set(accel_scale)  # E182
    F = F.at[ATTITUDE, ATTITUDE].set(-skew(omega))  # E181
    F = F.at[ATTITUDE, GYRO_BIAS].set(-sign * gyro_bias)
    F = F.at[ATTITUDE, GYRO_SCALE].set(-sign * gyro_scale)
    return F


def error_dynamics(rates: NavigationRates, monopulse: MonopulseErrorBudget,
                   options: ErrorModelOptions = ErrorModelOptions()) -> Float[Array, "33 33"]:
    """``F = blockdiag(F_Ind, F_Radar)`` (E177), with ``F_Radar = diag(0, 0, 0, 0, −β_ATEMP, −β_ETEMP)`` (Table 2)."""
    F_ind = ins_error_dynamics(rates, options)
    F = jnp.zeros((NUM_STATES, NUM_STATES), F_ind.dtype).at[:NUM_INS_STATES, :NUM_INS_STATES].set(F_ind)
    beta = monopulse.temperature_inverse_correlation_time
    return F.at[TEMP_AZIMUTH, TEMP_AZIMUTH].set(-beta).at[TEMP_ELEVATION, TEMP_ELEVATION].set(-beta)


def process_noise_density(ins: INSErrorBudget, monopulse: MonopulseErrorBudget) -> Float[Array, "33 33"]:
    """State-space PSD of ``w = [w_Ind; w_Radar]`` (E183–E184, spec §2.8).

    ``q_v I`` on δv, ``q_ψ I`` on ψ (the same in nav or body axes, since ``C q I Cᵀ = q I``), and
    ``2 β_TEMP σ_TEMP²`` on the TEMP states (zero for the default random bias; FIX-26).
    """
    diag = jnp.zeros((NUM_STATES,), jnp.result_type(ins.accel_noise_psd, float))
    diag = diag.at[VELOCITY].set(ins.accel_noise_psd).at[ATTITUDE].set(ins.gyro_noise_psd)
    q_temp = 2.0 * monopulse.temperature_inverse_correlation_time * monopulse.temperature ** 2
    return jnp.diag(diag.at[TEMP_AZIMUTH].set(q_temp).at[TEMP_ELEVATION].set(q_temp))


def _look_frame(look: LookGeometry):
    p = look.line_of_sight
    r = jnp.linalg.norm(p)
    u = p / r
    C_bn = look.body_to_nav()
    C_an = C_bn @ look.antenna_to_body()
    return p, r, u, C_bn, C_an


@functools.partial(jax.jit, static_argnames=("printed_e133", "printed_e163"))
def measurement_matrix(look: LookGeometry, *, printed_e133: bool = False, printed_e163: bool = False) -> Float[Array, "4 33"]:
    r"""Analytic ``H = [H_Ind  H_Radar]`` of one look (Tables 3–4 corrected; E170–E173), rows
    ``[z_r, z_ṙ, z_A, z_E]``.

    Footnote quantities ``L = −(1/r)[I − u_p u_pᵀ]`` (FIX-22),
    ``(∇Aⁿ)ᵀ = −u_pyᵀ[I − u_p u_pᵀ]/(r sin A)``, ``(∇Eⁿ)ᵀ = −u_pzᵀ[I − u_p u_pᵀ]/(r sin E)`` (E150,
    E163 with FIX-31); ``C_e^n`` at the look's latitude and longitude (FIX-23).

    ``printed_e133=True`` uses the printed ``L = +(1/r)[I − uuᵀ]`` and ``printed_e163=True`` the
    printed ∇E without its minus sign: both are wrong and exist for the regression test V-13.
    """
    p, r, u, C_bn, C_an = _look_frame(look)
    v = look.velocity
    C_en = look.nav_to_ecef().T
    u_py, u_pz = C_an[:, 1], C_an[:, 2]
    P = jnp.eye(3, dtype=u.dtype) - jnp.outer(u, u)
    L = (1.0 if printed_e133 else -1.0) / r * P
    sin_a = jnp.sqrt(1.0 - (u @ u_py) ** 2)
    sin_e = jnp.sqrt(1.0 - (u @ u_pz) ** 2)
    grad_a = -(u_py @ P) / (r * sin_a)
    grad_e = (1.0 if printed_e163 else -1.0) * (u_pz @ P) / (r * sin_e)
    rdot = -(u @ v)
    U = skew(u)
    H = jnp.zeros((4, NUM_STATES), u.dtype)
    H = H.at[0, POSITION].set(-u).at[0, TARGET].set(u @ C_en)
    H = H.at[1, POSITION].set(-(v @ L)).at[1, VELOCITY].set(-u).at[1, TARGET].set(v @ L @ C_en)
    for row, grad in ((2, grad_a), (3, grad_e)):
        H = H.at[row, POSITION].set(-grad).at[row, TARGET].set(grad @ C_en)
        H = H.at[row, ATTITUDE].set(-r * grad @ U).at[row, MISALIGNMENT].set(-r * grad @ U @ C_bn)
    H = H.at[0, RANGE_CLOCK].set(-1.0).at[0, PROPAGATION_SPEED].set(-r)  # Table 4 (FIX-33)
    H = H.at[1, DOPPLER_BIAS].set(-1.0).at[1, PROPAGATION_SPEED].set(-rdot).at[1, FREQUENCY].set(-rdot)
    return H.at[2, TEMP_AZIMUTH].set(-1.0).at[3, TEMP_ELEVATION].set(-1.0)


def _indicated(x: Array, look: LookGeometry):
    """INS-indicated aircraft/target state and DCMs for the error state ``x`` (E86–E97, E116–E117).

    The attitude errors act as exact rotations, ``C̄_b^n = exp(−[ψ×]) C_b^n`` and
    ``C̄_a^b = exp(−[β×]) C_a^b`` (first order: E109, E114). δv is added to the true velocity
    (FIX-39) and the nav frame is not perturbed (FIX-40).
    """
    C_en = look.nav_to_ecef().T
    r_a = look.aircraft_position + x[POSITION]
    r_t = look.target_position + C_en @ x[TARGET]
    v = look.velocity + x[VELOCITY]
    C_bn = rotation_vector_to_dcm(-x[ATTITUDE]) @ look.body_to_nav()
    C_ab = rotation_vector_to_dcm(-x[MISALIGNMENT]) @ look.antenna_to_body()
    return r_a, v, r_t, C_bn, C_ab


def _measured(x: Array, truth: Array, white: Array) -> Array:
    """Radar truth models (E56, E57, E82, E83): true values plus bias states minus white noise."""
    r, rdot = truth[0], truth[1]
    bias = jnp.stack([
        x[RANGE_CLOCK] + r * x[PROPAGATION_SPEED],
        x[DOPPLER_BIAS] + rdot * x[PROPAGATION_SPEED] + rdot * x[FREQUENCY],  # + ṙδF as printed (FIX-37)
        x[TEMP_AZIMUTH],
        x[TEMP_ELEVATION],
    ])
    return truth + bias - white


@jax.jit
def measurement_error(x: ArrayLike, look: LookGeometry) -> Float[Array, "4"]:
    """Exact nonlinear ``z(x) = indicated − measured`` (E166–E169; spec §2.7 [EXT]), white noise 0.

    ``jax.jacfwd(measurement_error)(zeros(33), look)`` equals :func:`measurement_matrix` (V-10);
    ``z(0) = 0`` (V-9). ``x`` is the 33-state error vector (index map in the module constants).
    """
    x = jnp.asarray(x)
    check_shape("x", x, [(NUM_STATES,)])
    truth = radar_measurements(look)
    indicated = _radar(*_indicated(x, look))
    return indicated - _measured(x, truth, jnp.zeros((4,), x.dtype))


@jax.jit
def autodiff_measurement_matrix(look: LookGeometry) -> Float[Array, "4 33"]:
    """``∂z/∂x`` at ``x = 0`` of :func:`measurement_error` by ``jax.jacfwd``: the cross-check of
    :func:`measurement_matrix` (V-10)."""
    return jax.jacfwd(measurement_error)(jnp.zeros(NUM_STATES), look)


def gps_measurement_matrix() -> Float[Array, "3 33"]:
    """Loosely coupled GPS position ``z = r̄_aⁿ − r̃_GPS = δr_aⁿ + v`` (spec §2.10, [EXT], not in the report)."""
    return jnp.zeros((3, NUM_STATES)).at[:, POSITION].set(jnp.eye(3))


def first_look_target_error(x: ArrayLike, white: ArrayLike, look: LookGeometry) -> Float[Array, "3"]:
    """``δr_t^e`` of the closed-form first-look solution (§1.7) for error state ``x`` and white noise.

    The solution uses the measured ``[r, ṙ, A, E]`` (truth models E56–E83, with the white noise
    ``white`` of shape ``(4,)``) and the INS-indicated position, velocity and attitude with the
    nominal antenna DCM; the result is ``C_n^e (r̂_tⁿ − r_tⁿ)``. Its Jacobians in ``x`` and
    ``white`` give the correlated first-look prior of spec §2.8.
    """
    x, white = jnp.asarray(x), jnp.asarray(white)
    r_a, v, _, C_bn, C_ab = _indicated(x, look)
    measured = _measured(x, radar_measurements(look), white)
    estimate = single_look_target(measured, r_a, v, C_bn, C_ab)
    return look.nav_to_ecef() @ (estimate - look.target_position)


# --------------------------------------------------------------------------------------------
# 7. Verification experiments of the error dynamics (V-16 … V-19)


def schuler_rates(gravity: float = GRAVITY, radius: float = EARTH_RADIUS) -> NavigationRates:
    """Rates of the classical closed forms (V-17, V-18): Ω = ρ = 0, A = [0, 0, −g],
    Γ = ω_s² diag(−1, −1, 2) with ω_s² = g/R, level attitude."""
    z = jnp.zeros(3)
    return NavigationRates(z, z, z, jnp.array([0.0, 0.0, -gravity]), gravity_gradient("physical", gravity=gravity, radius=radius),
                           jnp.eye(3), z)


def schuler_frequency(gravity: float = GRAVITY, radius: float = EARTH_RADIUS) -> float:
    """``ω_s = sqrt(g/R)``, rad/s (1.2399764e-3; period 84.4530 min)."""
    return math.sqrt(gravity / radius)


def error_response(rates: NavigationRates, initial_error: ArrayLike, times: ArrayLike,
                   monopulse: MonopulseErrorBudget | None = None, options: ErrorModelOptions = ErrorModelOptions()) -> Float[Array, "T 33"]:
    """Mean error-state response ``x(t) = Φ(t) x(0)`` of the 33-state model with constant rates.

    ``Φ(t)`` comes from :func:`jaxtrack.models.discretize` (Van Loan, as in the covariance
    analysis); ``times`` in s, shape ``(T,)``, each > 0.
    """
    monopulse = table7_budget() if monopulse is None else monopulse
    F = error_dynamics(rates, monopulse, options)
    x0 = jnp.asarray(initial_error)
    check_shape("initial_error", x0, [(NUM_STATES,)])
    phis, _ = discretize(F, jnp.zeros_like(F), jnp.asarray(times, float))
    return phis @ x0


RESPONSE_TIMES = np.linspace(10.0, 600.0, 60)  # s: the grid of V-17/V-18 rows and their figure


def horizontal_accel_bias_response(bias, t, omega_s: float | None = None):
    """Schuler closed form ``δr = b(1 − cos ω_s t)/ω_s²`` (V-17), m."""
    ws = schuler_frequency() if omega_s is None else omega_s
    return bias * (1.0 - np.cos(ws * t)) / ws ** 2


def vertical_accel_bias_response(bias, t, omega_s: float | None = None):
    """Vertical-channel closed form ``δr_D = b(cosh(√2 ω_s t) − 1)/(2ω_s²)`` (V-17), m."""
    ws = schuler_frequency() if omega_s is None else omega_s
    return bias * (np.cosh(math.sqrt(2.0) * ws * t) - 1.0) / (2.0 * ws ** 2)


def gyro_bias_position_response(gyro_bias, t, omega_s: float | None = None, gravity: float = GRAVITY):
    """Horizontal position error ``R ε (t − sin(ω_s t)/ω_s)`` with ``R = g/ω_s²`` (V-18), m."""
    ws = schuler_frequency() if omega_s is None else omega_s
    return gravity / ws ** 2 * gyro_bias * (t - np.sin(ws * t) / ws)


def _rk4_scan(rhs, y0, t0, dt, num_steps):
    def step(y, k):
        t = t0 + k * dt
        k1 = rhs(t, y)
        k2 = rhs(t + 0.5 * dt, jax.tree.map(lambda a, b: a + 0.5 * dt * b, y, k1))
        k3 = rhs(t + 0.5 * dt, jax.tree.map(lambda a, b: a + 0.5 * dt * b, y, k2))
        k4 = rhs(t + dt, jax.tree.map(lambda a, b: a + dt * b, y, k3))
        y = jax.tree.map(lambda a, b1, b2, b3, b4: a + dt / 6.0 * (b1 + 2 * b2 + 2 * b3 + b4), y, k1, k2, k3, k4)
        return y, y

    _, ys = jax.lax.scan(step, y0, jnp.arange(num_steps))
    return ys


class InertialErrorExperiment(NamedTuple):
    """Result of :func:`accelerometer_bias_experiment`: times (s) and δrⁿ histories (m)."""

    times: Array
    nonlinear: Array
    linear: Array


def accelerometer_bias_experiment(
    bias_nav=(1e-3, -2e-3, 5e-4), duration: float = 1500.0, *, dt: float = 1.0, lat0: float = 0.6, lon0: float = 0.3,
    height: float = 7620.0, velocity_ne=(150.0, 130.0), gamma: GravityGradient = "physical",
) -> InertialErrorExperiment:
    """V-16: the Pinson model against a nonlinear rotating-Earth inertial simulation.

    Truth: a constant-altitude flight with constant ``v_N``, ``v_E`` over a spherical Earth with
    Newtonian gravitation ``G = −μ r/|r|³`` rotating at Ω_e. The error caused by a constant
    nav-axis accelerometer bias obeys, in ECEF, the exact equation
    ``δr̈ = C_n^e b + G(r + δr) − G(r) − 2Ω × δṙ − Ω × (Ω × δr)`` (the specific forces of the true
    and erroneous trajectories cancel). The linear model propagates ``[δrⁿ, δvⁿ]`` with
    ``F_vr = −[ω̇×] − [ω×]² + Γ`` and ``F_vv = −2[ω×]`` along the same trajectory, with
    ``Γ = (μ/r³) diag(−1, −1, 2)`` (``gamma="physical"``) or the printed ``−(μ/r³) I``; there is
    no ``[Ω×]²`` term, because G is Newtonian (not plumb-bob) gravity. Both are integrated with
    RK4 at ``dt``.
    """
    _choice("gamma", gamma, ("physical", "report"))
    b = _vec3("bias_nav", bias_nav)
    rh = EARTH_RADIUS + height
    Gamma = EARTH_MU / rh ** 3 * jnp.diag(jnp.array([-1.0, -1.0, 2.0 if gamma == "physical" else -1.0]))
    n = int(round(duration / dt))
    params = jnp.array([dt, lat0, lon0, height, velocity_ne[0], velocity_ne[1]], float)
    return InertialErrorExperiment(*_accelerometer_bias_core(b, Gamma, params, n))


@functools.partial(jax.jit, static_argnums=3)
def _accelerometer_bias_core(b, Gamma, params, n):
    dt, lat0, lon0, height, vn, ve = (params[i] for i in range(6))
    rh = EARTH_RADIUS + height
    Omega_e = jnp.array([0.0, 0.0, EARTH_RATE])

    def lat_lon(t):
        lat = lat0 + vn * t / rh
        # constant v_E: dλ/dφ = (v_E/v_N) sec φ, integrated in closed form (inverse Gudermannian)
        lon = lon0 + ve / vn * (jnp.arctanh(jnp.sin(lat)) - jnp.arctanh(jnp.sin(lat0)))
        return lat, lon

    def position(t):
        lat, lon = lat_lon(t)
        return rh * jnp.stack([jnp.cos(lat) * jnp.cos(lon), jnp.cos(lat) * jnp.sin(lon), jnp.sin(lat)])

    def gravitation(r):
        return -EARTH_MU * r / jnp.linalg.norm(r) ** 3

    def nonlinear_rhs(t, y):
        dr, dv = y
        lat, lon = lat_lon(t)
        r = position(t)
        acc = (nav_to_ecef(lat, lon) @ b + gravitation(r + dr) - gravitation(r)
               - 2.0 * jnp.cross(Omega_e, dv) - jnp.cross(Omega_e, jnp.cross(Omega_e, dr)))
        return (dv, acc)

    def omega_nav(t):
        lat, _ = lat_lon(t)
        return earth_rate_nav(lat) + transport_rate(lat, height, jnp.stack([vn, ve, 0.0 * vn]))

    def linear_rhs(t, y):
        dr, dv = y
        w = omega_nav(t)
        w_dot = jax.jacfwd(omega_nav)(t)
        W = skew(w)
        F_vr = -skew(w_dot) - W @ W + Gamma
        return (dv, F_vr @ dr - 2.0 * W @ dv + b)

    zeros = (jnp.zeros(3), jnp.zeros(3))
    dr_e, _ = _rk4_scan(nonlinear_rhs, zeros, 0.0, dt, n)
    dr_n, _ = _rk4_scan(linear_rhs, zeros, 0.0, dt, n)
    times = dt * jnp.arange(1, n + 1)
    lat, lon = lat_lon(times)
    nonlinear = jnp.einsum("tji,tj->ti", nav_to_ecef(lat, lon), dr_e)
    return times, nonlinear, dr_n


class AttitudeErrorExperiment(NamedTuple):
    """Result of :func:`gyro_bias_attitude_experiment`: times (s), ψ from the DCMs and from the model (rad)."""

    times: Array
    psi_simulated: Array
    psi_model: Array


def gyro_bias_attitude_experiment(
    gyro_bias_body=(4e-5, -6e-5, 3e-5), body_rate=(0.02, -0.01, 0.015), nav_rate=(5e-5, -3e-5, 8e-5),
    duration: float = 100.0, *, dt: float = 0.05,
) -> AttitudeErrorExperiment:
    """V-19: the ψ dynamics against a simulation of the true and the indicated DCM.

    ``Ċ = C[ω_ib^b×] − [ω_inⁿ×]C`` for the truth and the same with ``ω_ib^b + ε^b`` for the
    indicated ``C̄``; ψ is read from ``C̄Cᵀ = I − [ψ×]`` (skew part). The model integrates the
    consistent ``ψ̇ = −ω_in × ψ − C_b^n ε^b`` (FIX-24). Rates are constant, rad/s.
    """
    eps, wb, wn = _vec3("gyro_bias_body", gyro_bias_body), _vec3("body_rate", body_rate), _vec3("nav_rate", nav_rate)
    C0 = body_to_nav(jnp.array([0.1, -0.2, 0.7]))

    def rhs(t, y):
        C, C_bar, psi = y
        return (C @ skew(wb) - skew(wn) @ C, C_bar @ skew(wb + eps) - skew(wn) @ C_bar, -jnp.cross(wn, psi) - C @ eps)

    n = int(round(duration / dt))
    C, C_bar, psi = jax.jit(lambda: _rk4_scan(rhs, (C0, C0, jnp.zeros(3)), 0.0, dt, n))()
    psi_sim = -vee(C_bar @ jnp.swapaxes(C, -1, -2))
    return AttitudeErrorExperiment(dt * jnp.arange(1, n + 1), psi_sim, psi)


# --------------------------------------------------------------------------------------------
# 8. Reference scenario RS-1 [EXT: spec §3.5; not from the report]

RS1_LATITUDE = math.radians(40.0)
RS1_HEIGHT = 7620.0  # m above the target plane
RS1_SPEED = 200.0  # m/s, level, due north
RS1_TARGET = (20000.0, 20000.0, 0.0)  # r_tⁿ, m, local NED at the aircraft
RS1_ANTENNA = (0.0, math.radians(-15.077939), math.radians(45.0))  # ζ: boresight on the target


def rs1_look() -> LookGeometry:
    """RS-1 at the first look: r_aⁿ = [0, 0, −7620], v = [200, 0, 0], α = 0, target
    [20000, 20000, 0] m, antenna ζ = [0, −15.077939°, 45°], latitude 40°, longitude 0."""
    return LookGeometry([0.0, 0.0, -RS1_HEIGHT], list(RS1_TARGET), [RS1_SPEED, 0.0, 0.0], [0.0, 0.0, 0.0],
                        list(RS1_ANTENNA), RS1_LATITUDE, 0.0)


def circular_error_probable(cov: ArrayLike, probability: float = 0.5, *, num_nodes: int = 128) -> Array:
    r"""Exact radius of the circle about the mean holding ``probability`` of a 2-D Gaussian (CEP).

    With ``σ_1 ≤ σ_2`` the principal standard deviations,

    .. math::

        P(R) = \int_{-π/2}^{π/2} φ\!\left(\frac{R \sin t}{σ_2}\right)
               \operatorname{erf}\!\left(\frac{R \cos t}{\sqrt2\,σ_1}\right) \frac{R\cos t}{σ_2}\,dt

    (conditioning on the major-axis component), by Gauss–Legendre quadrature; ``P(R) = p`` is
    solved by bisection and one implicit-function Newton step makes the result differentiable.
    Circular case: ``sqrt(2 ln 2) σ = 1.1774100 σ``; the approximation ``0.5887(σ_1 + σ_2)`` holds
    for ``σ_1/σ_2 ≳ 0.3`` (spec §2.9).

    **Arguments:** ``cov`` a 2×2 covariance (m²), or a stack ``(..., 2, 2)``; ``probability`` in
    (0, 1). **Returns:** the radius, m, shape ``(...)``.
    """
    cov = jnp.asarray(cov)
    if cov.shape[-2:] != (2, 2):
        raise InputError(f"`cov` must have shape (..., 2, 2); got shape {cov.shape}.")
    if not 0.0 < probability < 1.0:
        raise InputError(f"`probability` must lie in (0, 1); got {probability}.")
    if is_concrete(cov) and np.any(np.linalg.eigvalsh(np.asarray(cov, float)) <= 0):
        raise InputError("`cov` must be positive definite: CEP needs both principal σ > 0.")
    return _cep(cov, probability, num_nodes)


@functools.partial(jax.jit, static_argnames=("probability", "num_nodes"))
def _cep(cov, probability, num_nodes):
    nodes, weights = np.polynomial.legendre.leggauss(num_nodes)
    t, w = jnp.asarray(nodes * np.pi / 2), jnp.asarray(weights * np.pi / 2)
    flat = cov.reshape((-1, 2, 2))

    def one(c):
        ev = jnp.linalg.eigvalsh(c)
        s1, s2 = jnp.sqrt(ev[0]), jnp.sqrt(ev[1])

        def prob(R):
            z = R * jnp.sin(t) / s2
            phi = jnp.exp(-0.5 * z * z) / jnp.sqrt(2.0 * jnp.pi)
            return jnp.sum(w * phi * jax.scipy.special.erf(R * jnp.cos(t) / (jnp.sqrt(2.0) * s1)) * R * jnp.cos(t) / s2)

        def bisect(_, bracket):
            lo, hi = bracket
            mid = 0.5 * (lo + hi)
            below = prob(mid) < probability
            return jnp.where(below, mid, lo), jnp.where(below, hi, mid)

        s1c, s2c = jax.lax.stop_gradient(s1), jax.lax.stop_gradient(s2)
        # P(R) ≥ P(|major component| ≤ R) and P(‖x‖ ≤ R) ≤ P for a circle of σ_2, so the root lies in
        # [0, R_circ(σ_2)·(1 + margin)] for p ≤ 0.99; widen generously.
        lo, hi = jax.lax.fori_loop(0, 80, bisect, (jnp.zeros_like(s2c), 4.0 * s2c + s1c))
        R = jax.lax.stop_gradient(0.5 * (lo + hi))
        # Implicit-function step: value unchanged (P(R) = p), derivative −∂P/∂θ / ∂P/∂R.
        return R - (prob(R) - probability) / jax.lax.stop_gradient(jax.grad(prob)(R))

    return jax.vmap(one)(flat).reshape(cov.shape[:-2])


class SingleLookAnalysis(eqx.Module):
    """Single-look target-location accuracy of one look (spec §3.5, V-24). Covariances in nav axes (m²).

    - ``measurements`` ``[r, ṙ, A, E]``; ``cos_cone`` cos β = −ṙ/|v|; ``los_rate`` ω_t (E72);
      ``range_accel`` r̈ = (|v|² − ṙ²)/r; ``noise_std`` ``[σ_r, σ_ṙ, σ_A, σ_E]``.
    - ``target_jacobian`` ``H_t = ∂[r, ṙ, A, E]/∂r_tⁿ`` (4×3).
    - ``least_squares_cov`` ``(H_tᵀR⁻¹H_t)⁻¹`` (white noise only).
    - ``consider_cov``: the same estimator with the radar biases (Tables 6–7) and β as consider
      parameters.
    - ``closed_form_jacobian`` ``J = ∂r_t/∂[r, ṙ, A, E]`` of §1.7 (3×4) and ``closed_form_cov`` ``J R Jᵀ``.
    - ``cep_least_squares``, ``cep_consider``, ``cep_closed_form``: exact horizontal CEP (m).
    """

    measurements: Array
    cos_cone: Array
    los_rate: Array
    range_accel: Array
    noise_std: Array
    target_jacobian: Array
    least_squares_cov: Array
    consider_cov: Array
    closed_form_jacobian: Array
    closed_form_cov: Array
    cep_least_squares: Array
    cep_consider: Array
    cep_closed_form: Array


def bias_covariance(sar: SARErrorBudget, monopulse: MonopulseErrorBudget) -> Float[Array, "9 9"]:
    """Prior covariance of the consider parameters ``[δr_CL, δṙ_D, δC, δF, δA_TEMP, δE_TEMP, β]``."""
    s = jnp.stack([sar.range_clock, sar.doppler_bias, sar.propagation_speed, sar.frequency,
                   monopulse.temperature, monopulse.temperature, *(monopulse.misalignment,) * 3])
    return jnp.diag(s ** 2)


_BIAS_COLUMNS = np.r_[RANGE_CLOCK:TEMP_ELEVATION + 1, MISALIGNMENT.start:MISALIGNMENT.stop]


def single_look_analysis(look: LookGeometry, sar: SARErrorBudget | None = None,
                         monopulse: MonopulseErrorBudget | None = None) -> SingleLookAnalysis:
    """Least-squares, consider and closed-form covariance of one look (spec §3.5, V-24)."""
    sar = table6_budget() if sar is None else sar
    monopulse = table7_budget() if monopulse is None else monopulse
    return _single_look_analysis(look, sar, monopulse)


@eqx.filter_jit
def _single_look_analysis(look, sar, monopulse):
    m = radar_measurements(look)
    speed = jnp.linalg.norm(look.velocity)
    R = measurement_noise_cov(look, sar, monopulse)
    H = measurement_matrix(look)
    H_t = H[:, TARGET] @ look.nav_to_ecef()  # δr_t^e = C_n^e δr_tⁿ
    R_inv = jnp.linalg.inv(R)
    P_ls = jnp.linalg.inv(H_t.T @ R_inv @ H_t)
    K = P_ls @ H_t.T @ R_inv
    H_b = H[:, _BIAS_COLUMNS]
    P_consider = P_ls + K @ H_b @ bias_covariance(sar, monopulse) @ H_b.T @ K.T
    J = jax.jacfwd(single_look_target)(m, look.aircraft_position, look.velocity, look.body_to_nav(), look.antenna_to_body())
    P_cf = J @ R @ J.T
    ceps = _cep(jnp.stack([P_ls[:2, :2], P_consider[:2, :2], P_cf[:2, :2]]), 0.5, 128)
    return SingleLookAnalysis(m, -m[1] / speed, los_rotation_rate(m[0], m[1], speed), (speed ** 2 - m[1] ** 2) / m[0],
                              jnp.sqrt(jnp.diagonal(R)), H_t, P_ls, P_consider, J, P_cf, ceps[0], ceps[1], ceps[2])


class NavigationPrior(eqx.Module):
    """Initial σ of the navigation states [EXT: the report gives none, spec §2.8, FIX-42].

    ``position_std`` (m, NED), ``velocity_std`` (m/s), ``attitude_std`` (rad, ψ), each ``(3,)``.
    Defaults: a navigation-grade INS some minutes after a good fix.
    """

    position_std: Float[Array, "3"] = eqx.field(converter=jnp.asarray, default=(15.0, 15.0, 20.0))
    velocity_std: Float[Array, "3"] = eqx.field(converter=jnp.asarray, default=(0.05, 0.05, 0.05))
    attitude_std: Float[Array, "3"] = eqx.field(converter=jnp.asarray, default=(5e-5, 5e-5, 2e-4))


def prior_std(ins: INSErrorBudget, sar: SARErrorBudget, monopulse: MonopulseErrorBudget,
              nav: NavigationPrior) -> Float[Array, "33"]:
    """σ of every state before the first look (Tables 5–7 and ``nav``); the target entry is 0."""
    ones = jnp.ones(3)
    return jnp.concatenate([
        nav.position_std * ones, nav.velocity_std * ones, nav.attitude_std * ones,
        ins.accel_bias * ones, ins.accel_scale_factor * ones, ins.gyro_bias * ones, ins.gyro_scale_factor * ones,
        jnp.zeros(3), monopulse.misalignment * ones,
        jnp.stack([sar.range_clock, sar.doppler_bias, sar.propagation_speed, sar.frequency, monopulse.temperature, monopulse.temperature]),
    ])


@jax.jit
def first_look_prior(look: LookGeometry, std: ArrayLike, R: ArrayLike) -> Float[Array, "33 33"]:
    """Prior covariance with the target initialised by the closed-form first look (spec §2.8).

    ``δr_t^e = G x + J_w w`` with ``G``, ``J_w`` the Jacobians of
    :func:`first_look_target_error`; the target block is ``G P Gᵀ + J_w R J_wᵀ`` and its
    cross-covariance with the other states ``G P`` (the first-look error is correlated with
    δr_a, δv_a, ψ, β and the radar biases; treating it as independent would be optimistic).
    ``std`` is :func:`prior_std` (its target entries are ignored); ``R`` the first look's noise.
    """
    std = jnp.asarray(std).at[TARGET].set(0.0)
    P = jnp.diag(std ** 2)
    x0, w0 = jnp.zeros(NUM_STATES), jnp.zeros(4)
    G = jax.jacfwd(first_look_target_error, argnums=0)(x0, w0, look)
    J_w = jax.jacfwd(first_look_target_error, argnums=1)(x0, w0, look)
    A = jnp.eye(NUM_STATES).at[TARGET, :].set(G)
    B = jnp.zeros((NUM_STATES, 4)).at[TARGET, :].set(J_w)
    P0 = A @ P @ A.T + B @ jnp.asarray(R) @ B.T
    return 0.5 * (P0 + P0.T)  # the two products round differently


Case = Literal["radar", "sar_only", "radar_gps"]
CASES: dict[str, str] = {
    "radar": "SAR + monopulse, no GPS (the report's filter)",
    "sar_only": "SAR range/range-rate only, no GPS",
    "radar_gps": "SAR + monopulse + GPS position [EXT]",
}


class CovarianceScenario(eqx.Module):
    """RS-1 flown over time for the covariance analysis [EXT: no scenario in the report, FIX-42].

    The aircraft flies level, due north at 200 m/s and 7620 m over a spherical Earth from 40° N;
    the target is the RS-1 target (fixed in ECEF). The ESA boresight is steered onto the target
    at every look. Steps are ``step`` seconds apart; the closed-form first look at ``t = 0``
    initialises the target (:func:`first_look_prior`), then a look every ``look_every`` steps
    and, where the case has GPS, a position fix every ``gps_every`` steps.

    - ``num_steps``, ``look_every``, ``gps_every`` (static ints); ``step`` (s). Default: 49 steps
      of 5 s (0–240 s), a look and a GPS fix at every step.
    - ``gps_std``: GPS position σ per axis, m [EXT].
    - ``nav``: :class:`NavigationPrior`.
    - ``flat_earth`` (static): fixed tangent frame (C_e^n, latitude held), as V-21 asks.
    """

    num_steps: int = eqx.field(static=True, default=49)
    look_every: int = eqx.field(static=True, default=1)
    gps_every: int = eqx.field(static=True, default=1)
    step: float = 5.0
    gps_std: float = 5.0
    nav: NavigationPrior = NavigationPrior()
    flat_earth: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        for name in ("num_steps", "look_every", "gps_every"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise InputError(f"`{name}` must be a positive int; got {value!r}.")

    @property
    def times(self) -> Array:
        return self.step * jnp.arange(self.num_steps, dtype=float)


def rs1_trajectory(times: ArrayLike, *, flat_earth: bool = False) -> LookGeometry:
    """The RS-1 looks at ``times`` (s), a batched :class:`LookGeometry` (one per time).

    Curved (default): the aircraft's latitude advances at ``v/(R + h)`` and the LOS is expressed
    in the current NED frame; flat: the aircraft moves in the fixed RS-1 tangent frame.
    """
    t = jnp.asarray(times, float)
    rh = EARTH_RADIUS + RS1_HEIGHT
    r0 = jnp.array([0.0, 0.0, -RS1_HEIGHT])
    target0 = jnp.asarray(RS1_TARGET)
    if flat_earth:
        lat = jnp.full_like(t, RS1_LATITUDE)
        los = target0[None, :] - (r0[None, :] + RS1_SPEED * t[:, None] * jnp.array([1.0, 0.0, 0.0])[None, :])
    else:
        lat = RS1_LATITUDE + RS1_SPEED * t / rh
        radial = lambda la: jnp.stack([jnp.cos(la), jnp.zeros_like(la), jnp.sin(la)], axis=-1)  # noqa: E731
        target_e = rh * radial(jnp.asarray(RS1_LATITUDE)) + nav_to_ecef(RS1_LATITUDE, 0.0) @ (target0 - r0)
        los = jnp.einsum("tji,tj->ti", nav_to_ecef(lat, jnp.zeros_like(lat)), target_e[None, :] - rh * radial(lat))
    zeros = jnp.zeros_like(t)
    n = t.shape[0]
    aircraft = jnp.broadcast_to(r0, (n, 3))
    return LookGeometry(aircraft, aircraft + los, jnp.broadcast_to(jnp.array([RS1_SPEED, 0.0, 0.0]), (n, 3)),
                        jnp.zeros((n, 3)), boresight_angles(los), lat, zeros)


class CovarianceAnalysis(eqx.Module):
    """Covariance history of the 33-state filter on RS-1 and the derived target errors.

    - ``times`` ``(T,)`` s; ``radar_observed`` ``(T,)`` bool (a look at that step).
    - ``history``: the :class:`~jaxtrack.covariance.CovarianceHistory` (P in the state's units).
    - ``target_cov`` ``(T, 3, 3)``: ``P_tⁿ = C_e^n P_t^e C_n^e`` after each step's update (m²).
    - ``relative_cov`` ``(T, 3, 3)``: ``cov(δr_tⁿ − δr_aⁿ)``, the relative targeting error (m²).
    - ``aircraft_cov`` ``(T, 3, 3)``: ``cov(δr_aⁿ)`` (m²).
    - ``target_cep``, ``relative_cep``, ``aircraft_cep`` ``(T,)``: exact horizontal CEPs (m).
    - ``common_mode_correlation`` ``(T,)``: correlation of the North errors of target and aircraft.
    """

    times: Array
    radar_observed: Array
    history: CovarianceHistory
    target_cov: Array
    relative_cov: Array
    aircraft_cov: Array
    target_cep: Array
    relative_cep: Array
    aircraft_cep: Array
    common_mode_correlation: Array


@eqx.filter_jit
def _rs1_arrays(looks, rates, ins, sar, monopulse, options, gps_std, step, std, noise_on):
    """Per-step F, Q (Van Loan), H, R and the first-look prior, in SI units; ``rates`` per step."""
    Qc = process_noise_density(ins, monopulse) * noise_on

    def dynamics(r):
        return van_loan(error_dynamics(r, monopulse, options), Qc, step)

    def measurement(look):
        H = jnp.concatenate([measurement_matrix(look), gps_measurement_matrix()])
        R = jax.scipy.linalg.block_diag(measurement_noise_cov(look, sar, monopulse), gps_std ** 2 * jnp.eye(3))
        return H, R

    F, Q = jax.vmap(dynamics)(rates)
    H, R = jax.vmap(measurement)(looks)
    P0 = first_look_prior(jax.tree.map(lambda a: a[0], looks), std, R[0, :4, :4])
    return F, Q, H, R, P0


@eqx.filter_jit
def _trajectory_rates(lat, velocity, attitude, options):
    return jax.vmap(lambda la, v, a: navigation_rates(la, RS1_HEIGHT, v, a, options=options))(lat, velocity, attitude)


def rs1_model(case: Case = "radar", scenario: CovarianceScenario = CovarianceScenario(), *,
              ins: INSErrorBudget | None = None, sar: SARErrorBudget | None = None,
              monopulse: MonopulseErrorBudget | None = None, options: ErrorModelOptions = ErrorModelOptions(),
              rates: NavigationRates | None = None, process_noise: bool = True) -> tuple[LinearGaussianModel, Array, LookGeometry, Array]:
    """The per-step 33-state :class:`~jaxtrack.models.LinearGaussianModel` of RS-1 and its mask, in scaled units.

    Measurements per step are ``[r, ṙ, A, E, GPS_N, GPS_E, GPS_D]`` (7 components); the mask
    selects those of ``case`` (:data:`CASES`). ``F``, ``Q`` per step come from
    :func:`jaxtrack.models.van_loan` of the continuous model at the interval's midpoint. ``rates``
    overrides the trajectory's :func:`navigation_rates` (V-21 freezes them); ``process_noise=False``
    sets Q = 0. Returns ``(model, mask (T, 7), looks, scale (33,))``: the model's state is
    ``x_s = x / scale`` (each state in units of its prior σ; see the comment in the code), so
    a covariance ``P_s`` of the model is ``scale scaleᵀ ∘ P_s`` in SI units.
    """
    _choice("case", case, tuple(CASES))
    ins = h423_budget() if ins is None else ins
    sar = table6_budget() if sar is None else sar
    monopulse = table7_budget() if monopulse is None else monopulse
    times = scenario.times
    looks = rs1_trajectory(times, flat_earth=scenario.flat_earth)
    if rates is None:  # the trajectory's rates at each interval's midpoint
        mid = rs1_trajectory(times - 0.5 * scenario.step, flat_earth=scenario.flat_earth)
        rates = _trajectory_rates(mid.lat, mid.velocity, mid.attitude, options)
    else:
        rates = jax.tree.map(lambda a: jnp.broadcast_to(a, (scenario.num_steps, *jnp.shape(a))), rates)
    F, Q, H, R, P0 = _rs1_arrays(looks, rates, ins, sar, monopulse, options, jnp.asarray(scenario.gps_std, float),
                                 jnp.asarray(scenario.step, float), prior_std(ins, sar, monopulse, scenario.nav),
                                 jnp.asarray(1.0 if process_noise else 0.0))
    k = np.arange(scenario.num_steps)
    look_steps = (k % scenario.look_every == 0) & (k > 0)  # the first look initialised the target
    gps_steps = k % scenario.gps_every == 0
    radar_cols = {"radar": [0, 1, 2, 3], "sar_only": [0, 1], "radar_gps": [0, 1, 2, 3]}[case]
    mask = np.zeros((scenario.num_steps, 7), bool)
    mask[np.ix_(look_steps, radar_cols)] = True
    if case == "radar_gps":
        mask[gps_steps, 4:] = True
    # The states' variances span ~20 orders of magnitude (ε² ≈ 4e-16 rad²/s² beside 1e3 m²), below
    # what an eigenvalue or Cholesky test of P resolves in float64 (eps·‖P‖ ≈ 4e-13). The filter
    # therefore runs in units of each state's prior σ: x = S x_s with S = diag(σ_0), F_s = S⁻¹FS,
    # Q_s = S⁻¹QS⁻¹, H_s = HS, P_s = S⁻¹PS⁻¹. Covariances are identical after unscaling (S P_s S).
    scale = jnp.sqrt(jnp.diagonal(P0))
    model = LinearGaussianModel(F * scale[None, None, :] / scale[None, :, None], Q / jnp.outer(scale, scale)[None],
                                H * scale[None, None, :], R, jnp.zeros(NUM_STATES), P0 / jnp.outer(scale, scale))
    return model, jnp.asarray(mask), looks, scale


def rs1_covariance_analysis(case: Case = "radar", scenario: CovarianceScenario = CovarianceScenario(), **kwargs) -> CovarianceAnalysis:
    """Target-location error and CEP over time on RS-1 for one ``case`` (spec §2.9–2.10 [EXT]).

    Runs :func:`jaxtrack.covariance.covariance_recursion` (the Kalman filter's own Joseph-form
    step, data-free) on :func:`rs1_model`. Without GPS the shared (common-mode) position error
    of aircraft and target is unobservable (V-21): the looks bound the relative error
    δr_t − δr_a, while the absolute target error stays at the INS position error.
    """
    model, mask, looks, scale = rs1_model(case, scenario, **kwargs)
    hist = unscale_history(covariance_recursion(model, mask=mask), scale)
    return _target_errors(hist, looks, scenario.times, mask[:, 0])


def unscale_history(hist: CovarianceHistory, scale: ArrayLike) -> CovarianceHistory:
    """A :class:`~jaxtrack.covariance.CovarianceHistory` of :func:`rs1_model` back in SI units."""
    s = jnp.asarray(scale)
    S = jnp.outer(s, s)[None]
    return CovarianceHistory(hist.predicted_cov * S, hist.filtered_cov * S, hist.gain * s[None, :, None], hist.innovation_cov)


@jax.jit
def _target_errors_jit(P, C_ne):
    C_en = jnp.swapaxes(C_ne, -1, -2)
    T_target = jnp.zeros((P.shape[0], 3, NUM_STATES)).at[:, :, TARGET].set(C_en)
    T_relative = T_target.at[:, :, POSITION].set(jnp.broadcast_to(-jnp.eye(3), (P.shape[0], 3, 3)))
    sandwich = lambda T: T @ P @ jnp.swapaxes(T, -1, -2)  # noqa: E731
    target, relative = sandwich(T_target), sandwich(T_relative)
    aircraft = P[:, POSITION, POSITION]
    cross = jnp.einsum("tij,tjk->tik", T_target, P[:, :, POSITION])[:, 0, 0]
    corr = cross / jnp.sqrt(target[:, 0, 0] * aircraft[:, 0, 0])
    return target, relative, aircraft, corr


def _target_errors(hist, looks, times, observed) -> CovarianceAnalysis:
    target, relative, aircraft, corr = _target_errors_jit(hist.filtered_cov, looks.nav_to_ecef())
    ceps = circular_error_probable(jnp.stack([target, relative, aircraft])[..., :2, :2])
    return CovarianceAnalysis(times, observed, hist, target, relative, aircraft, ceps[0], ceps[1], ceps[2], corr)


def common_mode_information(cov: ArrayLike, direction: ArrayLike, nav_to_ecef_dcm: ArrayLike) -> Array:
    """``nᵀP⁻¹n`` for the unobservable direction ``n = [δr_a = c, δr_t^e = C_n^e c, 0 …]`` (V-21).

    ``direction`` is ``c`` (m, NED, shape ``(3,)``). The solve runs on the correlation matrix
    (``P`` scaled to unit diagonal), because the states' variances span ~20 orders of magnitude.
    """
    P, c, C_ne = jnp.asarray(cov), _vec3("direction", direction), jnp.asarray(nav_to_ecef_dcm)
    n = jnp.zeros(P.shape[-1]).at[POSITION].set(c).at[TARGET].set(C_ne @ c)
    d = jnp.sqrt(jnp.diagonal(P))
    corr = P / jnp.outer(d, d)
    y = n / d  # P = D C D with D = diag(σ): nᵀP⁻¹n = (D⁻¹n)ᵀ C⁻¹ (D⁻¹n)
    chol = jnp.linalg.cholesky(corr)
    return y @ jax.scipy.linalg.cho_solve((chol, True), y)


# --------------------------------------------------------------------------------------------
# 9. Figures and the reproduction table


def figure_target_error(analyses: dict[str, CovarianceAnalysis] | None = None):
    """Horizontal CEP of the absolute and relative target error over time for the three cases."""
    import matplotlib.pyplot as plt

    analyses = analyses or {c: rs1_covariance_analysis(c) for c in CASES}
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    for case, res in analyses.items():
        t = np.asarray(res.times)
        (line,) = ax[0].plot(t, np.asarray(res.target_cep), label=CASES[case])
        ax[1].plot(t, np.asarray(res.relative_cep), color=line.get_color(), label=CASES[case])
    ax[0].set_title("absolute target location error (horizontal CEP)")
    ax[1].set_title("relative target error δr_t − δr_a (horizontal CEP)")
    for a in ax:
        a.set_xlabel("time [s]")
        a.set_ylabel("CEP [m]")
        a.set_yscale("log")
        a.grid(True, which="both", alpha=0.25)
        a.legend(fontsize=8)
    fig.suptitle("RS-1 [EXT]: 33-state covariance analysis, a look (and GPS fix) every 5 s after the first-look fix", fontsize=10)
    return fig


def figure_shared_position_error(analysis: CovarianceAnalysis | None = None):
    """Without GPS: σ of the aircraft, absolute-target and relative errors per axis (V-21)."""
    import matplotlib.pyplot as plt

    res = analysis if analysis is not None else rs1_covariance_analysis("radar")
    t = np.asarray(res.times)
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.8), constrained_layout=True)
    for i, axis in enumerate("NED"):
        ax[i].plot(t, np.sqrt(np.asarray(res.aircraft_cov[:, i, i])), label="aircraft δr_a")
        ax[i].plot(t, np.sqrt(np.asarray(res.target_cov[:, i, i])), "--", label="target δr_t (absolute)")
        ax[i].plot(t, np.sqrt(np.asarray(res.relative_cov[:, i, i])), label="relative δr_t − δr_a")
        ax[i].set_title(f"{axis} axis")
        ax[i].set_xlabel("time [s]")
        ax[i].set_ylabel("σ [m]")
        ax[i].set_yscale("log")
        ax[i].grid(True, which="both", alpha=0.25)
    ax[0].legend(fontsize=8)
    fig.suptitle("No GPS: the shared position error of aircraft and target is unobservable", fontsize=10)
    return fig


def _ellipse(cov2, p=0.5, n=200):
    k = math.sqrt(-2.0 * math.log(1.0 - p))
    w, V = np.linalg.eigh(np.asarray(cov2))
    th = np.linspace(0, 2 * np.pi, n)
    return (V @ (k * np.sqrt(w)[:, None] * np.stack([np.cos(th), np.sin(th)]))).T


def figure_single_look(analysis: SingleLookAnalysis | None = None):
    """RS-1 single look: 50% N/E error ellipses and CEP circles of the three covariances."""
    import matplotlib.pyplot as plt

    a = analysis if analysis is not None else single_look_analysis(rs1_look())
    fig, ax = plt.subplots(figsize=(5.6, 5.2), constrained_layout=True)
    th = np.linspace(0, 2 * np.pi, 200)
    for label, cov, cep in (("least squares, white", a.least_squares_cov, a.cep_least_squares),
                            ("closed form §1.7, white", a.closed_form_cov, a.cep_closed_form),
                            ("least squares + consider biases", a.consider_cov, a.cep_consider)):
        e = _ellipse(np.asarray(cov)[:2, :2])
        (line,) = ax.plot(e[:, 1], e[:, 0], label=f"{label}: CEP {float(cep):.2f} m")
        ax.plot(float(cep) * np.sin(th), float(cep) * np.cos(th), ":", color=line.get_color(), lw=0.9)
    ax.set_aspect("equal")
    ax.set_xlabel("East error [m]")
    ax.set_ylabel("North error [m]")
    ax.set_title("RS-1 single look: 50% ellipses (solid) and CEP (dotted)")
    ax.grid(True, alpha=0.25)
    ax.legend(fontsize=8)
    return fig


def figure_ins_error_responses():
    """The 33-state F (Van Loan) against the Schuler closed forms (V-17, V-18), 10–600 s."""
    import matplotlib.pyplot as plt

    t = RESPONSE_TIMES
    rates = schuler_rates()
    b, eps = 30 * MICRO_G, 0.004 * DEG_PER_HOUR
    horiz = error_response(rates, jnp.zeros(NUM_STATES).at[ACCEL_BIAS.start].set(b), t)
    vert = error_response(rates, jnp.zeros(NUM_STATES).at[ACCEL_BIAS.start + 2].set(b), t)
    gyro = error_response(rates, jnp.zeros(NUM_STATES).at[GYRO_BIAS.start + 1].set(eps), t)
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    for label, model, closed in (("30 µg horizontal accel bias", horiz[:, 0], horizontal_accel_bias_response(b, t)),
                                 ("30 µg vertical accel bias", vert[:, 2], vertical_accel_bias_response(b, t)),
                                 ("0.004 °/h gyro bias", -gyro[:, 0], gyro_bias_position_response(eps, t))):
        (line,) = ax.plot(t, np.asarray(model), label=f"{label} (33-state F)")
        ax.plot(t, closed, "o", ms=3, mfc="none", color=line.get_color(), label="closed form")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("position error [m]")
    ax.set_title("INS error responses, Ω = ρ = 0 (V-17, V-18)")
    ax.grid(True, alpha=0.25)
    ax.legend(fontsize=8)
    return fig


def _row(tid: str, quantity: str, paper: float, value, last_digit: float, floor: float = 1e-6) -> PaperRow:
    """A row whose tolerance is the spec's (``floor``) or half a unit in the printed last digit."""
    return PaperRow(tid, quantity, float(paper), float(value), max(floor, 0.5 * last_digit / abs(paper)))


def paper_rows(single: SingleLookAnalysis | None = None) -> list[PaperRow]:
    """Every number of the spec's verification targets that jaxtrack reproduces, as table rows.

    V-22 to V-24 at the spec's relative tolerance 1e-6 (or half a printed unit when coarser);
    V-10, V-16 to V-18 at their printed precision.
    """
    rows: list[PaperRow] = []
    add = rows.append

    # V-5b: the literal |ṙ| mirrors a receding target.
    look = v5b_look()
    add(_row("V-5b", "literal |ṙ| targeting error, receding target [m]", 20000.0,
             targeting_round_trip_error(jax.tree.map(lambda a: a[None], look), doppler_cone="literal")[0], 1e-3))

    # V-10: the generic geometry's angles.
    ang = np.degrees(np.asarray(radar_measurements(v10_look())[2:]))
    add(_row("V-10", "A at the V-10 geometry [deg]", 99.918, ang[0], 1e-3))
    add(_row("V-10", "E at the V-10 geometry [deg]", 83.647, ang[1], 1e-3))

    # V-16: nonlinear rotating-Earth truth against the Pinson model.
    phys = accelerometer_bias_experiment()
    lit = accelerometer_bias_experiment(gamma="report")
    add(_row("V-16", "|δrⁿ| after 1500 s, 30 µg-class nav bias [m]", 2157.0, jnp.linalg.norm(phys.nonlinear[-1]), 1.0))
    add(_row("V-16", "|linear − nonlinear| with Γ33 = −ω_s² (report) [m]", 629.0,
             jnp.linalg.norm(lit.linear[-1] - lit.nonlinear[-1]), 1.0))

    # V-17, V-18: Schuler closed forms, from the 33-state F discretised by Van Loan.
    ws = schuler_frequency()
    add(_row("V-17", "ω_s² = g/R [1/s²]", 1.5375e-6, ws ** 2, 1e-10))
    add(_row("V-17", "ω_s [rad/s]", 1.2399764e-3, ws, 1e-10))
    add(_row("V-17", "Schuler period [min]", 84.4530, 2 * math.pi / ws / 60.0, 1e-4))
    rates = schuler_rates()
    b, eps = 30 * MICRO_G, 0.004 * DEG_PER_HOUR
    t = RESPONSE_TIMES  # ends at 600 s
    add(_row("V-17", "δr_N at 600 s, 30 µg North accel bias [m]", 50.5579,
             error_response(rates, jnp.zeros(NUM_STATES).at[ACCEL_BIAS.start].set(b), t)[-1, 0], 1e-4))
    add(_row("V-17", "flat-Earth ½bt² at 600 s [m]", 52.9559, 0.5 * b * 600.0 ** 2, 1e-4))
    add(_row("V-17", "δr_D at 600 s, 30 µg vertical accel bias [m]", 58.0251,
             error_response(rates, jnp.zeros(NUM_STATES).at[ACCEL_BIAS.start + 2].set(b), t)[-1, 2], 1e-4))
    gyro = error_response(rates, jnp.zeros(NUM_STATES).at[GYRO_BIAS.start + 1].set(eps), t)[-1]
    add(_row("V-18", "|ψ| at 600 s, 0.004 °/h gyro bias [rad]", 1.163553e-5, jnp.linalg.norm(gyro[ATTITUDE]), 1e-11))
    add(_row("V-18", "horizontal |δr| at 600 s, 0.004 °/h gyro bias [m]", 6.65933, jnp.linalg.norm(gyro[0:2]), 1e-5))

    # V-22: budget arithmetic.
    mono = table7_budget()
    add(_row("V-22", "σ_A white (Table 7 RSS) [mrad]", 0.7035624, mono.white_std / MRAD, 1e-7))
    add(_row("V-22", "σ_A with TEMP bias [mrad]", 0.8093207, mono.total_std / MRAD, 1e-7))
    add(_row("V-22", "sqrt(K² + 1/12 + 0.25), K = 2", 2.0816660, designation_noise_factor(2.0), 1e-7))

    # V-23: unit conversions.
    ins, alt = h423_budget(), h423_budget("per_sqrt_hour")
    add(_row("V-23", "30 µg [m/s²]", 2.941995e-4, ins.accel_bias, 1e-10))
    add(_row("V-23", "0.004 °/h [rad/s]", 1.939255e-8, ins.gyro_bias, 1e-14))
    add(_row("V-23", "0.01 ft [m]", 3.048e-3, table6_budget().range_clock, 1e-6))
    add(_row("V-23", "0.001 ft/s [m/s]", 3.048e-4, table6_budget().doppler_bias, 1e-7))
    add(_row("V-23", "literal √q_v [m/s^1.5]", 7.620e-4, jnp.sqrt(ins.accel_noise_psd), 1e-7))
    add(_row("V-23", "literal √q_ψ [rad/√s]", 9.69627e-9, jnp.sqrt(ins.gyro_noise_psd), 1e-14))
    add(_row("V-23", "literal q_v [m²/s³] (§3.1)", 5.80644e-7, ins.accel_noise_psd, 1e-12))
    add(_row("V-23", "literal q_ψ [rad²/s] (§3.1)", 9.40177e-17, ins.gyro_noise_psd, 1e-22))
    add(_row("V-23", "per-√h √q_v [m/s^1.5] (§3.1)", 1.2700e-5, jnp.sqrt(alt.accel_noise_psd), 1e-9))
    add(_row("V-23", "per-√h √q_ψ [rad/√s] (§3.1)", 5.81776e-7, jnp.sqrt(alt.gyro_noise_psd), 1e-12))
    add(_row("V-23", "Δr = c/(2B), B = 150 MHz [m]", 0.9993082, range_resolution(150e6), 1e-7))

    # V-24: RS-1.
    a = single if single is not None else single_look_analysis(rs1_look())
    r, rdot = a.measurements[0], a.measurements[1]
    add(_row("V-24", "RS-1 r [m]", 29292.736301, r, 1e-6))
    add(_row("V-24", "RS-1 ṙ [m/s]", -136.552624, rdot, 1e-6))
    add(_row("V-24", "RS-1 cos β", 0.68276312, a.cos_cone, 1e-8))
    add(_row("V-24", "RS-1 A [deg]", 90.0, np.degrees(float(a.measurements[2])), 1e-6))
    add(_row("V-24", "RS-1 E [deg]", 90.0, np.degrees(float(a.measurements[3])), 1e-6))
    add(_row("V-24", "RS-1 ω_t = Δṙ for Δaz = 1 m [rad/s]", 4.988539e-3, a.los_rate, 1e-9))
    add(_row("V-24", "RS-1 r̈ [m/s²]", 0.7289650, a.range_accel, 1e-7))
    add(_row("V-24", "RS-1 σ_r, T_d|ṙ| timing [m]", 2.0861400, a.noise_std[0], 1e-7))
    add(_row("V-24", "RS-1 σ_ṙ, T_d|r̈| timing [m/s]", 1.0410027e-2, a.noise_std[1], 1e-9))
    lit_r, lit_rdot = sar_noise_std(table6_budget(timing_model="literal"), r, rdot, RS1_SPEED)
    add(_row("V-24", "RS-1 σ_r, literal T_d·r timing [m]", 29.36661, lit_r, 1e-5))
    add(_row("V-24", "RS-1 σ_ṙ, literal T_d·ṙ timing [m/s]", 0.1369469, lit_rdot, 1e-7))
    add(_row("V-24", "RS-1 σ_A = σ_E [mrad]", 0.7035624, a.noise_std[2] / MRAD, 1e-7))
    for name, cov, cep, paper, paper_cep in (
        ("least squares", a.least_squares_cov, a.cep_least_squares, (2.080825, 7.591038, 19.273055), 5.592468),
        ("consider", a.consider_cov, a.cep_consider, (2.173114, 15.226058, 39.627643), 10.50533),
        ("closed form", a.closed_form_cov, a.cep_closed_form, (2.086486, 7.863663, 19.907149), 5.759898),
    ):
        sig = np.sqrt(np.diag(np.asarray(cov)))
        for i, axis in enumerate("NED"):
            add(_row("V-24", f"RS-1 {name} σ_{axis} [m]", paper[i], sig[i], 1e-6))
        add(_row("V-24", f"RS-1 {name} horizontal CEP [m]", paper_cep, cep, 1e-6 if name != "consider" else 1e-5))
    s_ls = np.sort(np.sqrt(np.linalg.eigvalsh(np.asarray(a.least_squares_cov)[:2, :2])))
    add(_row("V-24", "RS-1 least squares 0.5887(σ₁ + σ₂) [m]", 5.6938, 0.5887 * s_ls.sum(), 1e-4))
    J = np.asarray(a.closed_form_jacobian)
    for (i, j), paper, digit in (((0, 0), 0.6827631, 1e-7), ((0, 1), -146.4637, 1e-4), ((1, 0), 0.6827631, 1e-7),
                                 ((1, 1), 146.4637, 1e-4), ((1, 3), 10776.31, 1e-2), ((2, 0), 0.2601327, 1e-7),
                                 ((2, 3), -28284.27, 1e-2)):
        add(_row("V-24", f"RS-1 closed-form J[{'NED'[i]}, {('r', 'ṙ', 'A', 'E')[j]}]", paper, J[i, j], digit))
    la = atmospheric_loss(r)
    snr = signal_to_noise(10.0, r)
    cnr = signal_to_noise(clutter_cross_section(1.0, 1.0), r)
    cnr1 = signal_to_noise(clutter_cross_section(1.0, 1.0), r, range_exponent=1.0)
    scnr = signal_to_clutter_noise(snr, cnr)
    add(_row("V-24", "RS-1 L_a", 0.8644257, la, 1e-7))
    add(_row("V-24", "RS-1 SNR, ρ_t = 10 m²", 5943.65, snr, 1e-2))
    add(_row("V-24", "RS-1 SNR [dB]", 37.741, to_db(snr), 1e-3))
    add(_row("V-24", "RS-1 CNR, n = 4", 59.4365, cnr, 1e-4))
    add(_row("V-24", "RS-1 CNR, n = 4 [dB]", 17.741, to_db(cnr), 1e-3))
    add(_row("V-24", "RS-1 SCNR = SNR/(CNR + 1)", 98.345, scnr, 1e-3))
    add(_row("V-24", "RS-1 SCNR [dB]", 19.928, to_db(scnr), 1e-3))
    add(_row("V-24", "RS-1 ref [2] K = 1/(2√SCNR)", 0.05042, designation_factor_ref2(scnr), 1e-5))
    add(_row("V-24", "RS-1 CNR, literal n = 1", 0.44265, cnr1, 1e-5))
    add(_row("V-24", "RS-1 CNR, literal n = 1 [dB]", -3.54, to_db(cnr1), 1e-2))
    add(_row("V-24", "RS-1 rain L_r, η = 10 mm/h", 0.0261934, rain_loss(r, 10.0), 1e-7))
    add(_row("V-24", "exact CEP / σ, circular Gaussian", 1.1774100,
             circular_error_probable(jnp.eye(2)), 1e-7))
    return rows


def v5b_look() -> LookGeometry:
    """V-5b: v = [200, 0, 0], r_a = [0, 0, −8000], r_t = [−10000, 15000, 0] (a receding target),
    level attitude, boresight on the target."""
    r_a, r_t = jnp.array([0.0, 0.0, -8000.0]), jnp.array([-10000.0, 15000.0, 0.0])
    return LookGeometry(r_a, r_t, [200.0, 0.0, 0.0], [0.0, 0.0, 0.0], boresight_angles(r_t - r_a), 0.7, 0.0)


def v10_look() -> LookGeometry:
    """The generic geometry of V-10: r_a = [100, −50, −7620], r_t = [20000, 15000, 0],
    v = [180, 40, −5], α = [0.05, 0.03, 0.25], ζ = [0.02, −0.2, 0.6], φ = 0.7, λ = −1.4."""
    return LookGeometry([100.0, -50.0, -7620.0], [20000.0, 15000.0, 0.0], [180.0, 40.0, -5.0],
                        [0.05, 0.03, 0.25], [0.02, -0.2, 0.6], 0.7, -1.4)


def reproduce(out_dir) -> tuple[list[PaperRow], list[str]]:
    """Compute every row of :func:`paper_rows` and write the study's figures as PNG into ``out_dir``."""
    single = single_look_analysis(rs1_look())
    rows = paper_rows(single)
    analyses = {c: rs1_covariance_analysis(c) for c in CASES}
    figures = write_figures(out_dir, [
        ("rs1_single_look.png", lambda: figure_single_look(single)),
        ("rs1_target_error.png", lambda: figure_target_error(analyses)),
        ("rs1_shared_position_error.png", lambda: figure_shared_position_error(analyses["radar"])),
        ("ins_error_responses.png", figure_ins_error_responses),
    ])
    return rows, figures

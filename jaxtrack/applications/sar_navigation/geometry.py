"""Look geometry (E14–E29): aircraft, target and antenna at one SAR look, the radar measurements
``[r, ṙ, A, E]``, antenna steering, and the SAR background relations (E1–E8, E62–E72).

Frames are those of :mod:`jaxtrack.geometry` (NED navigation frame, ``C_b^n``, ``C_a^b``, ``C_n^e``).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._validation import InputError
from ...geometry import antenna_to_body_rotation, body_to_ned_rotation, ned_to_ecef_rotation
from .states import SPEED_OF_LIGHT, _safe_sqrt

def boresight_angles(los_body: ArrayLike, roll: ArrayLike = 0.0) -> Float[Array, "... 3"]:
    """Antenna angles ζ that put the boresight ``x^a`` on the body-frame direction ``los_body``.

    [EXT] Steering of the electronically scanned array: ``ζ_z = atan2(p_y, p_x)``,
    ``ζ_y = −atan2(p_z, ‖p_xy‖)``, ``ζ_x = roll``.

    **Arguments:** ``los_body``: LOS in body axes (any length unit), ``(..., 3)``; ``roll`` ζ_x (rad).

    **Returns:** ζ ``[ζ_x, ζ_y, ζ_z]`` (rad), ``(..., 3)``.
    """
    p = jnp.asarray(los_body)
    horizontal = jnp.sqrt(p[..., 0] ** 2 + p[..., 1] ** 2)
    roll = jnp.broadcast_to(jnp.asarray(roll, p.dtype), horizontal.shape)
    return jnp.stack([roll, -jnp.arctan2(p[..., 2], horizontal), jnp.arctan2(p[..., 1], p[..., 0])], axis=-1)



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
        """``C_b^n`` (E12), shape ``(*B, 3, 3)``."""
        return body_to_ned_rotation(self.attitude)

    def antenna_to_body(self) -> Array:
        """``C_a^b`` (E13), shape ``(*B, 3, 3)``."""
        return antenna_to_body_rotation(self.antenna)

    def nav_to_ecef(self) -> Array:
        """``C_n^e`` (E9) at the look's latitude and longitude, shape ``(*B, 3, 3)``."""
        return ned_to_ecef_rotation(self.lat, self.lon)


def slant_range(los: ArrayLike) -> Array:
    """``r = ‖p‖`` (E15, E20), m; ``los`` shape ``(..., 3)``.

    **Arguments:** ``los`` p (m), ``(..., 3)``. **Returns:** r (m), ``(...)``.
    """
    return jnp.linalg.norm(jnp.asarray(los), axis=-1)


def range_rate(los: ArrayLike, velocity: ArrayLike) -> Array:
    """``ṙ = −u_pᵀ v_a`` (E19, E21) for a stationary target, m/s; negative when closing.

    **Arguments:** ``los`` p (m) and ``velocity`` v_a (m/s), ``(..., 3)``. **Returns:** ṙ (m/s), ``(...)``.
    """
    los, velocity = jnp.asarray(los), jnp.asarray(velocity)
    return -jnp.sum(los * velocity, axis=-1) / slant_range(los)


def monopulse_angles(los: ArrayLike, antenna_to_nav: ArrayLike) -> tuple[Array, Array]:
    """Monopulse direction-cosine angles ``(A, E)`` (E22–E29), rad in [0, π].

    ``A = acos(u_pᵀ u_py)`` and ``E = acos(u_pᵀ u_pz)``, with ``u_py``, ``u_pz`` the antenna
    ``y^a``, ``z^a`` axes in nav coordinates (columns 1 and 2 of ``C_a^n = C_b^n C_a^b``). A
    target on boresight has ``A = E = π/2``. The derivative of acos is singular for a target in
    the antenna plane (A or E = 0, π); the cosines are clipped so the value stays defined there.

    **Arguments:** ``los`` p (m), ``(..., 3)``; ``antenna_to_nav`` ``C_a^n``, ``(..., 3, 3)``.

    **Returns:** the pair ``(A, E)`` (rad), each ``(...)``.
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

    **Arguments:** ``look``: one :class:`LookGeometry`. **Returns:** ``[r, ṙ, A, E]``, shape ``(4,)``.
    """
    return _radar(look.aircraft_position, look.velocity, look.target_position, look.body_to_nav(), look.antenna_to_body())


def los_from_monopulse(azimuth: ArrayLike, elevation: ArrayLike) -> Float[Array, "... 3"]:
    """Unit LOS in antenna axes from the monopulse angles (E51–E53).

    ``u^a = [+sqrt(1 − cos²A − cos²E), cos A, cos E]``: the target is in front of the array.

    **Arguments:** ``azimuth`` A, ``elevation`` E (rad), broadcast-compatible ``(...)``.

    **Returns:** ``u^a``, ``(..., 3)``.
    """
    ca, ce = jnp.cos(jnp.asarray(azimuth)), jnp.cos(jnp.asarray(elevation))
    return jnp.stack([_safe_sqrt(1.0 - ca * ca - ce * ce), ca, ce], axis=-1)


def range_from_round_trip(round_trip_time: ArrayLike) -> Array:
    """``r = cT/2`` (E1, FIX-1), m, from the round-trip transit time T (s).

    **Arguments:** ``round_trip_time`` T (s). **Returns:** r (m), same shape.
    """
    return SPEED_OF_LIGHT * jnp.asarray(round_trip_time) / 2.0


def range_rate_from_doppler(doppler: ArrayLike, wavelength: ArrayLike) -> Array:
    """``ṙ = −λF_d/2`` (E2 with the sign convention of FIX-38: closing ⇒ F_d > 0, ṙ < 0), m/s.

    **Arguments:** ``doppler`` F_d (Hz), ``wavelength`` λ (m). **Returns:** ṙ (m/s).
    """
    return -jnp.asarray(wavelength) * jnp.asarray(doppler) / 2.0


def focusing_phase(offset: ArrayLike, boresight_range: ArrayLike, wavelength: ArrayLike) -> Array:
    """Focused-SAR phase correction ``θ_k ≈ (2π/λ)(d_k²/R)`` (E3–E8), rad.

    ``offset`` is ``d_k``, the distance of pulse ``k`` from the array centre (m); valid for
    ``ΔR_k = d_k²/(2R) ≪ 2R`` (E7).

    **Arguments:** ``offset`` d_k (m), ``boresight_range`` R (m), ``wavelength`` λ (m).

    **Returns:** θ_k (rad), the broadcast shape.
    """
    d = jnp.asarray(offset)
    return 2.0 * jnp.pi / jnp.asarray(wavelength) * d * d / jnp.asarray(boresight_range)


def range_resolution(bandwidth: ArrayLike) -> Array:
    """``Δr = c/(2B)`` (E68), m, for bandwidth B in Hz (stripmap and spotlight).

    **Arguments:** ``bandwidth`` B (Hz). **Returns:** Δr (m).
    """
    return SPEED_OF_LIGHT / (2.0 * jnp.asarray(bandwidth))


def stripmap_azimuth_resolution(antenna_length: ArrayLike) -> Array:
    """``Δaz = D/2`` (E69), m; D is the along-track real-aperture length (FIX-44).

    **Arguments:** ``antenna_length`` D (m). **Returns:** Δaz (m).
    """
    return jnp.asarray(antenna_length) / 2.0


def spotlight_azimuth_resolution(wavelength: ArrayLike, integration_angle: ArrayLike) -> Array:
    """``Δaz = λ/(2φ)`` (E70), m; φ is the LOS rotation during the collection (rad, FIX-6).

    **Arguments:** ``wavelength`` λ (m), ``integration_angle`` φ (rad). **Returns:** Δaz (m).
    """
    return jnp.asarray(wavelength) / (2.0 * jnp.asarray(integration_angle))


def los_rotation_rate(range_: ArrayLike, range_rate_: ArrayLike, speed: ArrayLike) -> Array:
    """``ω_t = (|v|/r) sqrt(1 − (ṙ/|v|)²) = |v| sin β / r`` (E72, FIX-18), rad/s.

    **Arguments:** ``range_`` r (m), ``range_rate_`` ṙ (m/s), ``speed`` |v| (m/s).

    **Returns:** ω_t (rad/s), the broadcast shape.
    """
    speed = jnp.asarray(speed)
    return speed / jnp.asarray(range_) * _safe_sqrt(1.0 - (jnp.asarray(range_rate_) / speed) ** 2)


def range_rate_resolution(azimuth_resolution: ArrayLike, los_rate: ArrayLike) -> Array:
    """``Δṙ = ω_t Δaz`` (E71), m/s.

    **Arguments:** ``azimuth_resolution`` Δaz (m), ``los_rate`` ω_t (rad/s). **Returns:** Δṙ (m/s).
    """
    return jnp.asarray(los_rate) * jnp.asarray(azimuth_resolution)


def atmospheric_loss(range_: ArrayLike) -> Array:
    """``L_a = 10^(−2.16e-6 r)`` (E65, FIX-17), one-way-in-the-exponent attenuation ≤ 1; r in m.

    **Arguments:** ``range_`` r (m). **Returns:** L_a (–), same shape.
    """
    return 10.0 ** (-2.16e-6 * jnp.asarray(range_))


def rain_loss(range_: ArrayLike, rain_rate: ArrayLike) -> Array:
    """``L_r = 10^(−5.4e-6 η r)`` (E66, FIX-17); rain rate η in mm/h, r in m.

    **Arguments:** ``range_`` r (m), ``rain_rate`` η (mm/h). **Returns:** L_r (–).
    """
    return 10.0 ** (-5.4e-6 * jnp.asarray(rain_rate) * jnp.asarray(range_))


def clutter_cross_section(range_res: ArrayLike, azimuth_res: ArrayLike, reflectivity: float = 0.1) -> Array:
    """``ρ_c = σ⁰ Δr Δaz`` with σ⁰ = 0.1 (E67), m².

    **Arguments:** ``range_res`` Δr, ``azimuth_res`` Δaz (m); ``reflectivity`` σ⁰ (–).

    **Returns:** ρ_c (m²).
    """
    return reflectivity * jnp.asarray(range_res) * jnp.asarray(azimuth_res)


def signal_to_noise(rcs, range_, *, reference_range=1.5e5, gain_loss=1.0, integration_time=1.0,
                    rain_rate=0.0, range_exponent: float = 4.0) -> Array:
    """``SNR = ρ ΔG² L_a L_r T_I (r_0/r)^n`` (E63 with n = 4; E62 for clutter, FIX-15).

    ``rcs`` is the target RCS ρ_t (or the clutter ρ_c) in m²; ``reference_range`` r_0 (m) is
    where SNR = 1 for 1 m², 1 s and full gain; ``range_exponent`` is 4 (radar equation) or the
    printed 1 of E62.

    **Arguments:** ``rcs`` (m²), ``range_`` (m) and the keywords above.

    **Returns:** SNR (linear, –), the broadcast shape.
    """
    range_ = jnp.asarray(range_)
    return (jnp.asarray(rcs) * gain_loss * atmospheric_loss(range_) * rain_loss(range_, rain_rate)
            * integration_time * (reference_range / range_) ** range_exponent)


def signal_to_clutter_noise(snr: ArrayLike, cnr: ArrayLike, noise_term: float = 1.0) -> Array:
    """``SCNR = SNR/(CNR + 1)`` (E64 corrected, FIX-16); ``noise_term=0.1`` is the printed form.

    **Arguments:** ``snr``, ``cnr`` (linear); ``noise_term``. **Returns:** SCNR (linear).
    """
    return jnp.asarray(snr) / (jnp.asarray(cnr) + noise_term)


def designation_factor_ref2(scnr: ArrayLike) -> Array:
    """``K = 1/(2√SCNR)`` of ref. [2] (FIX-35); the report itself uses K = 2.

    **Arguments:** ``scnr`` (linear). **Returns:** K (–).
    """
    return 0.5 / jnp.sqrt(jnp.asarray(scnr))


def to_db(ratio: ArrayLike) -> Array:
    """``10 log10(ratio)``, dB.

    **Arguments:** ``ratio`` (linear, > 0). **Returns:** dB, same shape.
    """
    return 10.0 * jnp.log10(jnp.asarray(ratio))

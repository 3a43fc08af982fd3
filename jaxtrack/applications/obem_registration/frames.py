"""The measurement model and the registration equation (Wang et al. 2012, eqs 1, 12–19, 25–27, 46–47).

Radar i measures ``[r, θ, ε]`` (compass azimuth, see :mod:`jaxtrack.geometry._platform`) in its
platform frame; offset biases ``β_i = [Δr, k_r, Δθ, Δε]`` and platform attitude biases
``α_i = [Δφ, Δη, Δψ]`` move it. Mapping both radars to ECEF and equating them gives, to first
order, the 3-row pseudo-measurement ``Z = H β + G w`` of eq. (17). Frames come from
:mod:`jaxtrack.geometry`; what is here is the registration-specific algebra (A_i, C_i, D_i, Z, H, G).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ... import geometry

__all__ = [
    "DEG",
    "attitude_matrix",
    "offset_corrected_position",
    "offset_jacobian",
    "noise_jacobian",
    "attitude_jacobian",
    "ecef_position",
    "RegistrationTerms",
    "registration_terms",
    "pseudo_measurement_noise_cov",
    "nonlinear_pseudo_measurement",
    "AAM_STATES",
    "OBEM_STATES",
    "MERGED_STATES",
    "obem_columns",
    "merged_columns",
    "aam_truth",
    "obem_truth",
]

DEG = math.pi / 180.0
"""One degree in radians."""


def _float(x) -> Array:
    x = jnp.asarray(x)
    return x.astype(jnp.result_type(x, float))


def attitude_matrix(attitude: ArrayLike) -> Float[Array, "... 3 3"]:
    """``T_p2ENU(α) = T_Δφ T_Δη T_Δψ`` (eqs 2–7) of an attitude vector: the vector form of
    :func:`jaxtrack.geometry.platform_to_enu_rotation`.

    **Arguments:** ``attitude`` α = ``[Δφ, Δη, Δψ]`` (yaw, pitch, roll, rad), shape ``(..., 3)``.

    **Returns:** ``(..., 3, 3)`` rotation, ``X_ENU = T X_p``; ``T_ENU2p`` (eq. 6) is its transpose.
    """
    a = _float(attitude)
    return geometry.platform_to_enu_rotation(a[..., 0], a[..., 1], a[..., 2])


def _enu_to_ecef_rotation(lat, lon):
    """``T_i`` of eq. (11): the transpose of :func:`jaxtrack.geometry.ecef_to_enu_rotation`."""
    return jnp.swapaxes(geometry.ecef_to_enu_rotation(lat, lon), -1, -2)


def offset_corrected_position(raw: ArrayLike, offset_bias: ArrayLike, noise: ArrayLike | None = None) -> Float[Array, "3"]:
    """``X_p(β, w) = sph2cart(r − Δr − k_r r − δ_r, θ − Δθ − δ_θ, ε − Δε − δ_ε)`` (eq. 1 basis, spec §1.7).

    The target position in the platform frame from radar i's raw measurement with its offset
    biases (and optionally noise) removed. The gain multiplies the *measured* range, as the paper
    does ("approximated by the range measurement").

    **Arguments:** ``raw`` ``[r, θ, ε]`` ``(3,)`` (m, rad, rad); ``offset_bias`` β_i ``(4,)``
    ``[Δr (m), k_r, Δθ (rad), Δε (rad)]``; ``noise`` ``[δ_r, δ_θ, δ_ε]`` ``(3,)`` or None.

    **Returns:** ``(3,)`` position, m. At β = 0, w = 0 it is ``X_i`` of eq. (1).
    """
    raw = _float(raw)
    b = jnp.asarray(offset_bias, raw.dtype)
    w = jnp.zeros(3, raw.dtype) if noise is None else jnp.asarray(noise, raw.dtype)
    r, theta, eps = raw[0], raw[1], raw[2]
    return geometry.compass_spherical_to_cartesian(
        jnp.stack([r - b[0] - b[1] * r - w[0], theta - b[2] - w[1], eps - b[3] - w[2]]))


def offset_jacobian(raw: ArrayLike) -> Float[Array, "3 4"]:
    """``A_i = ∂X_p/∂β_i`` at β = 0 (eq. 1; explicit form of spec §1.7), shape ``(3, 4)``.

    ``[[−sθcε, −r sθcε, −r cθcε, r sθsε], [−cθcε, −r cθcε, r sθcε, r cθsε], [−sε, −r sε, 0, −r cε]]``
    at the raw ``[r, θ, ε]`` (m, rad, rad). Columns 1 and 2 are collinear (col2 = r·col1).

    **Arguments:** ``raw`` ``(3,)``. **Returns:** ``(3, 4)``, m per (m, 1, rad, rad).
    """
    raw = _float(raw)
    r, theta, eps = raw[0], raw[1], raw[2]
    st, ct, se, ce = jnp.sin(theta), jnp.cos(theta), jnp.sin(eps), jnp.cos(eps)
    zero = jnp.zeros_like(r)
    return jnp.stack(
        [
            jnp.stack([-st * ce, -r * st * ce, -r * ct * ce, r * st * se]),
            jnp.stack([-ct * ce, -r * ct * ce, r * st * ce, r * ct * se]),
            jnp.stack([-se, -r * se, zero, -r * ce]),
        ]
    )


def noise_jacobian(raw: ArrayLike) -> Float[Array, "3 3"]:
    """``C_i = ∂X_p/∂w_i = A_i[:, [0, 2, 3]]`` (eq. 1).

    **Arguments:** ``raw`` ``[r, θ, ε]`` ``(3,)``. **Returns:** ``(3, 3)``, m per (m, rad, rad).
    """
    a = offset_jacobian(raw)
    return jnp.stack([a[:, 0], a[:, 2], a[:, 3]], axis=1)


def attitude_jacobian(position: ArrayLike, lat: ArrayLike, lon: ArrayLike) -> Float[Array, "3 3"]:
    """``D_i`` of eq. (19) as corrected (spec §2.1, OCR item 3), ``T_i Δ_i X_i = D_i α_i`` (eq. 25).

    ``[[x a d − y c, y b d + z a d, x b d + z c],
       [x a c + y d, y b c + z a c, x b c − z d],
       [−x b,        y a − z b,     x a        ]]``

    with ``(x, y, z) = X_i`` (m, from the raw measurement) and ``a, b, c, d`` = ``sin L, cos L,
    sin λ, cos λ`` of radar i (rad). Columns ordered (Δφ, Δη, Δψ).

    **Arguments:** ``position`` X_i ``(3,)`` m; ``lat``, ``lon`` of radar i, rad.
    **Returns:** ``(3, 3)``, m/rad.
    """
    p = _float(position)
    x, y, z = p[0], p[1], p[2]
    a, b, c, d = jnp.sin(lat), jnp.cos(lat), jnp.sin(lon), jnp.cos(lon)
    return jnp.stack(
        [
            jnp.stack([x * a * d - y * c, y * b * d + z * a * d, x * b * d + z * c]),
            jnp.stack([x * a * c + y * d, y * b * c + z * a * c, x * b * c - z * d]),
            jnp.stack([-x * b, y * a - z * b, x * a]),
        ]
    )


def ecef_position(raw: ArrayLike, site: ArrayLike, offset_bias: ArrayLike, attitude: ArrayLike) -> Float[Array, "3"]:
    """``g_i(β_i, α_i) = X_is + T_i T_p2ENU(α_i) X_p(raw; β_i)``: the bias-corrected target in ECEF (eq. 12, exact).

    **Arguments:** ``raw`` ``(3,)`` (m, rad, rad); ``site`` ``[L, λ, h]`` ``(3,)`` (rad, rad, m);
    ``offset_bias`` ``(4,)``; ``attitude`` ``(3,)`` rad.

    **Returns:** ``(3,)`` ECEF, m.
    """
    site = _float(site)
    x_enu = attitude_matrix(attitude) @ offset_corrected_position(raw, offset_bias)
    return geometry.enu_to_ecef(x_enu, site[0], site[1], site[2])


class RegistrationTerms(eqx.Module):
    """The registration equation of one scan (eqs 17–19).

    - ``pseudo_measurement`` Z ``(3,)``, m: ``X_2s − X_1s + T_2X_2 − T_1X_1`` (eq. 18).
    - ``measurement_matrix`` H_AAM ``(3, 14)``: ``[T1A1, −T2A2, D1, −D2]`` (eq. 17), m per state unit.
    - ``noise_matrix`` G ``(3, 6)``: ``[T1C1, −T2C2]``, m per (m, rad, rad).
    """

    pseudo_measurement: Float[Array, "3"]
    measurement_matrix: Float[Array, "3 14"]
    noise_matrix: Float[Array, "3 6"]


def registration_terms(raw1: ArrayLike, site1: ArrayLike, raw2: ArrayLike, site2: ArrayLike) -> RegistrationTerms:
    """Z, H_AAM and G of one scan from the two raw measurements and the known sites (eqs 17–19).

    Everything is evaluated at the raw measurements with zero bias (the paper's fixed
    linearisation point, spec §2.6). H_OBEM is ``H_AAM[:, :8]`` (eq. 47), see :func:`obem_columns`.

    **Arguments:** ``raw1``, ``raw2`` ``[r, θ, ε]`` ``(3,)`` (m, rad, rad); ``site1``, ``site2``
    ``[L, λ, h]`` ``(3,)`` (rad, rad, m).

    **Returns:** :class:`RegistrationTerms`.
    """
    out = []
    for raw, site in ((raw1, site1), (raw2, site2)):
        site = _float(site)
        x = offset_corrected_position(raw, jnp.zeros(4, site.dtype))
        t = _enu_to_ecef_rotation(site[0], site[1])
        out.append((geometry.geodetic_to_ecef(site[0], site[1], site[2]), t, x, t @ offset_jacobian(raw),
                    t @ noise_jacobian(raw), attitude_jacobian(x, site[0], site[1])))
    (s1, t1, x1, ta1, tc1, d1), (s2, t2, x2, ta2, tc2, d2) = out
    # Z subtracts two ECEF positions ~6.4e6 m apart from their km-sized difference: group the
    # site difference first so that the cancellation happens once, in float64.
    z = (s2 - s1) + (t2 @ x2 - t1 @ x1)
    h = jnp.concatenate([ta1, -ta2, d1, -d2], axis=1)
    g = jnp.concatenate([tc1, -tc2], axis=1)
    return RegistrationTerms(z, h, g)


def pseudo_measurement_noise_cov(noise_matrix: ArrayLike, noise_std: ArrayLike) -> Float[Array, "... 3 3"]:
    """``R = G diag(σ_r1², σ_θ1², σ_ε1², σ_r2², σ_θ2², σ_ε2²) Gᵀ`` (implied by eq. 17; spec [R] §2.2).

    **Arguments:** ``noise_matrix`` G ``(..., 3, 6)``; ``noise_std`` ``(2, 3)`` per radar
    ``[σ_r (m), σ_θ (rad), σ_ε (rad)]``.

    **Returns:** ``(..., 3, 3)``, m², full and time-varying.
    """
    g = _float(noise_matrix)
    var = jnp.reshape(jnp.asarray(noise_std, g.dtype) ** 2, (6,))
    gs = g * jnp.broadcast_to(var, g.shape)
    return gs @ jnp.swapaxes(g, -1, -2)


def nonlinear_pseudo_measurement(aam_state: ArrayLike, raw1, site1, raw2, site2) -> Float[Array, "3"]:
    """``h(β) = [g_1(β1, α1) − g_1(0)] − [g_2(β2, α2) − g_2(0)]``, the exact registration map (spec §2.6).

    Noise-free, ``Z = h(β_true)`` holds with the exact forward model up to the range-gain
    convention; ``jax.jacfwd(h)(0)`` is H_AAM (V9).

    **Arguments:** ``aam_state`` ``(14,)`` ordered as eq. (16) (:data:`AAM_STATES`); ``raw1``,
    ``site1``, ``raw2``, ``site2`` as in :func:`registration_terms`.

    **Returns:** ``(3,)``, m.
    """
    b = _float(aam_state)
    zero4, zero3 = jnp.zeros(4, b.dtype), jnp.zeros(3, b.dtype)
    g1 = ecef_position(raw1, site1, b[0:4], b[8:11]) - ecef_position(raw1, site1, zero4, zero3)
    g2 = ecef_position(raw2, site2, b[4:8], b[11:14]) - ecef_position(raw2, site2, zero4, zero3)
    return g1 - g2


AAM_STATES = ("Δr1", "kr1", "Δθ1", "Δε1", "Δr2", "kr2", "Δθ2", "Δε2",
              "Δφ1", "Δη1", "Δψ1", "Δφ2", "Δη2", "Δψ2")
"""AAM state names, eq. (16) (0-based position = index)."""
OBEM_STATES = ("Δr1", "kr1", "Δθ1−Δφ1", "Δε1", "Δr2", "kr2", "Δθ2−Δφ2", "Δε2")
"""OBEM state names, eq. (46)."""
MERGED_STATES = OBEM_STATES + ("Δη1", "Δψ1", "Δη2", "Δψ2")
"""The 12-state model of Proposition 1: azimuth and yaw merged, pitch and roll kept."""


def obem_columns(h_aam: ArrayLike) -> Float[Array, "... 3 8"]:
    """H_OBEM = the first 8 columns of H_AAM (eq. 47).

    **Arguments:** ``h_aam`` ``(..., 3, 14)``. **Returns:** ``(..., 3, 8)``.
    """
    return jnp.asarray(h_aam)[..., :8]


def merged_columns(h_aam: ArrayLike) -> Float[Array, "... 3 12"]:
    """The 12-state H of Proposition 1: drop the yaw columns (9 and 12, 1-based).

    Because ``H(:,9) = −H(:,3)`` and ``H(:,12) = −H(:,7)`` (eq. 27), the azimuth columns then
    multiply ``Δθ_i − Δφ_i``. Order: :data:`MERGED_STATES`.

    **Arguments:** ``h_aam`` ``(..., 3, 14)``. **Returns:** ``(..., 3, 12)``.
    """
    h = jnp.asarray(h_aam)
    return jnp.concatenate([h[..., :8], h[..., 9:11], h[..., 12:14]], axis=-1)


def aam_truth(offset_bias: ArrayLike, attitude_bias: ArrayLike) -> Float[Array, "14"]:
    """β_AAM (eq. 16).

    **Arguments:** ``offset_bias`` ``(2, 4)``; ``attitude_bias`` ``(2, 3)`` (m, 1, rad).
    **Returns:** ``(14,)`` ordered as :data:`AAM_STATES`.
    """
    o = _float(offset_bias)
    a = jnp.asarray(attitude_bias, o.dtype)
    return jnp.concatenate([o[0], o[1], a[0], a[1]])


def obem_truth(offset_bias: ArrayLike, attitude_bias: ArrayLike) -> Float[Array, "8"]:
    """β_OBEM (eq. 46): the offsets with azimuth replaced by Δθ_i − Δφ_i.

    **Arguments:** ``offset_bias`` ``(2, 4)``; ``attitude_bias`` ``(2, 3)`` (m, 1, rad).
    **Returns:** ``(8,)`` ordered as :data:`OBEM_STATES`.
    """
    o = _float(offset_bias)
    a = jnp.asarray(attitude_bias, o.dtype)
    merged = o.at[:, 2].add(-a[:, 0])
    return jnp.reshape(merged, (8,))

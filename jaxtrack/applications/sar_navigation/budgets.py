"""Error budgets of the report (Tables 5–7), the per-look SAR and monopulse noise (Sec. 6, E73–E83)
and the priors of the 33 error states (spec §2.8 [EXT]).

The INS budget type is the library's :class:`jaxtrack.models.INSErrorBudget`; Table 5 fills it
for the Honeywell H423.
"""

from __future__ import annotations

import math
from typing import Literal

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ...models import INSErrorBudget
from .geometry import LookGeometry, los_rotation_rate, radar_measurements, range_rate_resolution
from .states import DEG_PER_HOUR, FOOT, MICRO_G, MRAD, _choice

TimingModel = Literal["derivative", "literal"]
NoiseUnits = Literal["per_sqrt_hz", "per_sqrt_hour"]


def h423_budget(ins_noise_units: NoiseUnits = "per_sqrt_hz") -> INSErrorBudget:
    """Table 5 (Honeywell H423): 30 µg, 175 PPM, 0.004 °/h, 2 PPM and the white noises.

    ``ins_noise_units`` (FIX-20): ``"per_sqrt_hz"`` reads "0.0025 FPS √Hz" and "0.0020 Deg/Hr/√Hz"
    as √PSD (√q_v = 7.62e-4 m/s^1.5, √q_ψ = 9.69627e-9 rad/√s); ``"per_sqrt_hour"`` reads them as
    0.0025 ft/s/√h and 0.002 °/√h.

    **Arguments:** ``ins_noise_units``: ``"per_sqrt_hz"`` or ``"per_sqrt_hour"``.

    **Returns:** :class:`~jaxtrack.models.INSErrorBudget` in SI units.
    """
    _choice("ins_noise_units", ins_noise_units, ("per_sqrt_hz", "per_sqrt_hour"))
    if ins_noise_units == "per_sqrt_hz":
        sqrt_qv, sqrt_qpsi = 0.0025 * FOOT, 0.0020 * DEG_PER_HOUR
    else:
        sqrt_qv, sqrt_qpsi = 0.0025 * FOOT / 60.0, 0.0020 * math.pi / 180.0 / 60.0
    f = jnp.asarray
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
    """Table 6 with the RS-1 resolutions (Δr = Δaz = 1 m, K = 2, T_d = 1 ms) by default.

    **Arguments:** ``range_res`` Δr, ``azimuth_res`` Δaz (m); ``designation_factor`` K;
    ``processing_delay`` T_d (s); ``timing_model``.

    **Returns:** :class:`SARErrorBudget` in SI units.
    """
    f = jnp.asarray
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
    """Table 7 in rad.

    **Arguments:** ``temperature_inverse_correlation_time`` β_TEMP (1/s).

    **Returns:** :class:`MonopulseErrorBudget` in rad.
    """
    f = jnp.asarray
    return MonopulseErrorBudget(f(0.40 * MRAD), f(np.array(list(MONOPULSE_WHITE_TERMS.values())) * MRAD),
                                f(1.20 * MRAD), f(temperature_inverse_correlation_time))


def designation_noise_factor(designation_factor: ArrayLike) -> Array:
    """``sqrt(K² + 1/12 + 0.25)``: designation, quantisation and "other" white terms per resolution
    cell (E73–E77, E80–E81); 2.0816660 for K = 2.

    **Arguments:** ``designation_factor`` K. **Returns:** the factor (–), same shape.
    """
    K = jnp.asarray(designation_factor)
    return jnp.sqrt(K * K + 1.0 / 12.0 + 0.25)


def sar_noise_std(budget: SARErrorBudget, range_: ArrayLike, range_rate_: ArrayLike, speed: ArrayLike) -> tuple[Array, Array]:
    """White SAR noise ``(σ_r, σ_ṙ)`` per look (E73–E81, Table 6), m and m/s.

    ``σ_r² = (K² + 1/12 + ¼) Δr² + σ_rT²`` and ``σ_ṙ² = (K² + 1/12 + ¼) Δṙ² + σ_ṙT²`` with
    ``Δṙ = ω_t Δaz`` (E71–E72) and the timing terms of ``budget.timing_model`` (FIX-19;
    ``r̈ = (|v|² − ṙ²)/r`` for straight, unaccelerated flight).

    **Arguments:** ``budget``: :class:`SARErrorBudget`; ``range_`` r (m), ``range_rate_`` ṙ (m/s),
    ``speed`` |v| (m/s), broadcast-compatible.

    **Returns:** the pair ``(σ_r, σ_ṙ)`` (m, m/s).
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
    """``R = diag(σ_r², σ_ṙ², σ_A², σ_E²)`` of one look (E187; the four sums are independent).

    **Arguments:** ``look``: one :class:`LookGeometry`; ``sar``, ``monopulse``: the budgets.

    **Returns:** ``R``, shape ``(4, 4)`` (m², m²/s², rad², rad²).
    """
    m = radar_measurements(look)
    sigma_r, sigma_rdot = sar_noise_std(sar, m[0], m[1], jnp.linalg.norm(look.velocity))
    sa = monopulse.white_std
    return jnp.diag(jnp.stack([sigma_r ** 2, sigma_rdot ** 2, sa ** 2, sa ** 2]))


def bias_covariance(sar: SARErrorBudget, monopulse: MonopulseErrorBudget) -> Float[Array, "9 9"]:
    """Prior covariance of the consider parameters ``[δr_CL, δṙ_D, δC, δF, δA_TEMP, δE_TEMP, β]``.

    **Arguments:** the SAR and monopulse budgets.

    **Returns:** diagonal covariance, shape ``(9, 9)`` (SI units of each bias).
    """
    s = jnp.stack([sar.range_clock, sar.doppler_bias, sar.propagation_speed, sar.frequency,
                   monopulse.temperature, monopulse.temperature, *(monopulse.misalignment,) * 3])
    return jnp.diag(s ** 2)


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
    """σ of every state before the first look (Tables 5–7 and ``nav``); the target entry is 0.

    **Arguments:** the three budgets and a :class:`NavigationPrior`.

    **Returns:** σ, shape ``(33,)``, in each state's unit.
    """
    ones = jnp.ones(3)
    return jnp.concatenate([
        nav.position_std * ones, nav.velocity_std * ones, nav.attitude_std * ones,
        ins.accel_bias * ones, ins.accel_scale_factor * ones, ins.gyro_bias * ones, ins.gyro_scale_factor * ones,
        jnp.zeros(3), monopulse.misalignment * ones,
        jnp.stack([sar.range_clock, sar.doppler_bias, sar.propagation_speed, sar.frequency, monopulse.temperature, monopulse.temperature]),
    ])

"""Units, the 33-state error vector's index map and small input helpers of the SAR + INS study.

The first 21 states are the ψ-angle INS error states of :mod:`jaxtrack.models` (same order and
slices); the study appends the target position error, the antenna misalignment and six radar
biases (spec §2.6 [EXT]; E174 with δr_t^e, FIX-23).
"""

from __future__ import annotations

import math

import jax.numpy as jnp
from jaxtyping import Array

from ...geometry._navigation import _vec3 as _vec3  # noqa: F401  (re-used by the study's modules)
from ...models._ins import (
    GRAVITY,
    INS_ACCEL_BIAS,
    INS_ACCEL_SCALE,
    INS_ATTITUDE,
    INS_GYRO_BIAS,
    INS_GYRO_SCALE,
    INS_POSITION,
    INS_VELOCITY,
)
from ...models._ins import _choice as _choice  # noqa: F401

SPEED_OF_LIGHT = 299792458.0  # c, m/s
FOOT = 0.3048  # m
MICRO_G = 1e-6 * GRAVITY  # m/s²
DEG_PER_HOUR = math.pi / 180.0 / 3600.0  # rad/s
MRAD = 1e-3  # rad

# Index map of the 33-state error vector (spec §2.6, [EXT]); E174 with δr_t^e (FIX-23).
POSITION = INS_POSITION  # δr_aⁿ, m (NED)
VELOCITY = INS_VELOCITY  # δv_aⁿ, m/s
ATTITUDE = INS_ATTITUDE  # ψ, rad
ACCEL_BIAS = INS_ACCEL_BIAS  # ∇, m/s²
ACCEL_SCALE = INS_ACCEL_SCALE  # k_∇, –
GYRO_BIAS = INS_GYRO_BIAS  # ε, rad/s
GYRO_SCALE = INS_GYRO_SCALE  # k_ε, –
TARGET = slice(21, 24)  # δr_t^e, m (ECEF)
MISALIGNMENT = slice(24, 27)  # β, rad (body axes)
RANGE_CLOCK, DOPPLER_BIAS, PROPAGATION_SPEED, FREQUENCY, TEMP_AZIMUTH, TEMP_ELEVATION = range(27, 33)
NUM_INS_STATES = 27  # the report's F_Ind: 21 INS states, target and β
NUM_STATES = 33
STATE_NAMES = (
    [f"dr_a_{c}" for c in "NED"] + [f"dv_a_{c}" for c in "NED"] + [f"psi_{c}" for c in "xyz"]
    + [f"accel_bias_{c}" for c in "xyz"] + [f"accel_sf_{c}" for c in "xyz"]
    + [f"gyro_bias_{c}" for c in "xyz"] + [f"gyro_sf_{c}" for c in "xyz"]
    + [f"dr_t_{c}" for c in "xyz"] + [f"beta_{c}" for c in "xyz"]
    + ["range_clock", "doppler", "propagation_speed", "frequency", "temp_A", "temp_E"]
)
MEASUREMENT_NAMES = ("range", "range_rate", "azimuth", "elevation")


def _safe_sqrt(q: Array) -> Array:
    """``sqrt(max(q, 0))`` whose derivative stays finite (zero) where ``q ≤ 0``."""
    positive = q > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, q, 1.0)), 0.0)

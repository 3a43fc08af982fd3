"""The Monte Carlo cases that ``test_sharding.py`` runs on one device and on many (shared by the
test and its worker processes)."""

import jax.numpy as jnp
import numpy as np

from jaxtrack.filters import ExtendedKalmanFilter, KalmanFilter
from jaxtrack.models import constant_velocity

# Not multiples of the block sizes (2048 shared, 512 per run) or of the device counts: the last
# round has partial and empty blocks (4 devices: shared 2048 + 552, per run 4 x 512 + 552, i.e.
# one full, one partial and two empty blocks).
NUM_RUNS = 2600
SWEEP_RUNS = 1500
NUM_STEPS = 25
SWEEP_VALUES = (0.1, 0.5, 2.0)  # acceleration PSD of the truth (m²/s³); the filter assumes 0.5
FIELDS = ("mse", "mean_error", "nees", "nees_std", "nis", "nis_dof")


def cv(accel_psd=0.5):
    prior = jnp.diag(jnp.asarray([100.0, 100.0, 10.0, 10.0]) ** 2)
    return constant_velocity(1.0, dim=2, accel_psd=accel_psd, measurement_std=10.0, initial_cov=prior)


def cases():
    """Shared-covariance path (KF, mismatched Q, a gap in the measurements), per-run path (EKF),
    and per-run detections (probability 0.7) with the Kalman filter (per run, with per-run masks
    too: rows sliced by run index, the padding runs of the last round clamped) and the EKF."""
    mask = jnp.ones(NUM_STEPS, bool).at[10:13].set(False)
    run_mask = np.random.default_rng(0).random((NUM_RUNS, NUM_STEPS)) < 0.9
    return {
        "kf": {"truth": cv(2.0), "filter_model": cv(0.5), "mask": mask},
        "ekf": {"truth": cv(0.5), "filter": ExtendedKalmanFilter()},
        "kf_detect": {"truth": cv(0.5), "filter": KalmanFilter(), "covariance": "per_run", "mask": run_mask,
                      "detection_probability": 0.7},
        "ekf_detect": {"truth": cv(0.5), "filter": ExtendedKalmanFilter(), "detection_probability": 0.7},
    }


def sweep_models(q):
    return cv(q), cv(0.5)

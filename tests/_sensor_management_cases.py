"""Sensor-scheduling scenarios shared by tests/test_sensor_management.py and
benchmarks/sensor_management.py: the jaxtrack problem, a plain-NumPy covariance recursion (the
oracle), and the same scenario run through Stone Soup's ``BruteForceSensorManager``.

Stone Soup has no stock sensor whose action chooses which target it measures, nor a reward on the
trace of the position covariance (its ``UncertaintyRewardFunction`` rewards the fall in the
Frobenius norm of the whole covariance). Both are built here from Stone Soup's own base classes,
as its documentation invites: an ``ActionableProperty`` ``target`` on a ``Sensor`` (with an
``Action`` and an ``ActionGenerator`` over the target indices), a linear position measurement
(``LinearGaussian``), and a ``RewardFunction`` that predicts every track with ``KalmanPredictor``,
updates the looked-at ones with ``KalmanUpdater`` and returns the fall in
``Σ_i c_i tr(P_i[pos, pos])``. The manager itself, the predictor and the updater are Stone Soup's.
Stone Soup is imported lazily (only these helpers need it).
"""

from __future__ import annotations

import copy
import datetime
import functools
from dataclasses import dataclass

import numpy as np

from jaxtrack.design import SensorSchedulingProblem
from jaxtrack.models import constant_velocity

# jaxtrack's 2-D constant-velocity state is [x, y, vx, vy]; Stone Soup's is [x, vx, y, vy]:
# jaxtrack x = stonesoup x[PERM].
PERM = np.array([0, 2, 1, 3])


@dataclass(frozen=True)
class Scenario:
    """``N`` 2-D constant-velocity targets seen by ``S`` position sensors at scan period ``tau`` s."""

    tau: float
    accel_psd: np.ndarray  # (N,) m²/s³
    initial_cov: np.ndarray  # (N, 4, 4) jaxtrack order, m², m²/s, m²/s²
    noise_std: np.ndarray  # (S,) m, per sensor (R_s = σ_s² I)
    num_scans: int

    @property
    def num_targets(self) -> int:
        return len(self.accel_psd)

    @property
    def num_sensors(self) -> int:
        return len(self.noise_std)

    def models(self):
        return [constant_velocity(self.tau, accel_psd=float(q), measurement_std=float(self.noise_std[0]),
                                  initial_cov=P0) for q, P0 in zip(self.accel_psd, self.initial_cov)]

    def R(self) -> np.ndarray:
        return np.stack([s**2 * np.eye(2) for s in self.noise_std])

    def problem(self) -> SensorSchedulingProblem:
        R = self.R()
        return SensorSchedulingProblem(self.models(), self.num_scans,
                                       measurement_noise_cov=R[0] if self.num_sensors == 1 else R)


def scenario(num_targets: int, num_scans: int, *, seed: int = 0, noise_std=(10.0,), tau: float = 1.0) -> Scenario:
    """Targets that differ in prior (position σ 5–60 m, velocity σ 1–15 m/s) and in manoeuvre noise
    (q 0.05–5 m²/s³), so that where a look pays off depends on the target and on the scan."""
    rng = np.random.default_rng(seed)
    q = np.exp(rng.uniform(np.log(0.05), np.log(5.0), num_targets))
    pos = rng.uniform(5.0, 60.0, num_targets)
    vel = rng.uniform(1.0, 15.0, num_targets)
    rho = rng.uniform(-0.5, 0.5, num_targets)  # position-velocity correlation per axis
    P0 = np.zeros((num_targets, 4, 4))
    for i in range(num_targets):
        block = np.array([[pos[i] ** 2, rho[i] * pos[i] * vel[i]], [rho[i] * pos[i] * vel[i], vel[i] ** 2]])
        P0[i] = np.kron(block, np.eye(2))
    return Scenario(tau, q, P0, np.asarray(noise_std, float), num_scans)


# ----------------------------------------------------------------------------------------------
# NumPy oracle


def numpy_costs(problem: SensorSchedulingProblem, schedules: np.ndarray) -> np.ndarray:
    """``J`` of ``B`` schedules ``(B, T, S)`` by the textbook Kalman covariance recursion (optimal
    gain, Joseph form), vectorised over the schedules; float64 NumPy, independent of jaxtrack's
    information-form code."""
    F, Q, H = (np.asarray(a) for a in (problem.transition_matrix, problem.process_noise_cov,
                                       problem.measurement_matrix))
    R, P0, L, c = (np.asarray(a) for a in (problem.measurement_noise_cov, problem.initial_cov, problem.weight,
                                           problem.target_weights))
    schedules = np.asarray(schedules).reshape(len(schedules), problem.num_scans, problem.num_sensors)
    B, T, S = schedules.shape
    n = P0.shape[-1]
    rows = np.arange(B)
    P = np.broadcast_to(P0, (B, *P0.shape)).copy()
    total = np.zeros(B)
    for k in range(T):
        P = np.einsum("iab,Xibc,idc->Xiad", F, P, F) + Q
        for s in range(S):
            i = schedules[:, k, s]
            Pi, Hi = P[rows, i], H[i]
            Sm = Hi @ Pi @ np.swapaxes(Hi, -1, -2) + R[s]
            K = Pi @ np.swapaxes(Hi, -1, -2) @ np.linalg.inv(Sm)
            A = np.eye(n) - K @ Hi
            P[rows, i] = A @ Pi @ np.swapaxes(A, -1, -2) + K @ R[s] @ np.swapaxes(K, -1, -2)
        total += np.einsum("i,ab,Xiba->X", c, L, P)
    return total


def numpy_relaxed_cost(problem: SensorSchedulingProblem, weights: np.ndarray) -> float:
    """``J`` of look weights ``(T, S, N)`` in information form, by explicit inverses:
    ``Y⁺ = (F P Fᵀ + Q)⁻¹ + Σ_s w_s Hᵀ R_s⁻¹ H``, ``P = (Y⁺)⁻¹`` (NumPy, float64)."""
    F, Q, H, R, P, L, c = (np.asarray(a) for a in (
        problem.transition_matrix, problem.process_noise_cov, problem.measurement_matrix,
        problem.measurement_noise_cov, problem.initial_cov, problem.weight, problem.target_weights))
    weights = np.asarray(weights, float).reshape(problem.num_scans, problem.num_sensors, problem.num_targets)
    total = 0.0
    for w in weights:
        P = np.einsum("iab,ibc,idc->iad", F, P, F) + Q
        Y = np.linalg.inv(P)
        for s in range(problem.num_sensors):
            Y = Y + w[s][:, None, None] * np.einsum("iab,bc,icd->iad", np.swapaxes(H, -1, -2), np.linalg.inv(R[s]), H)
        P = np.linalg.inv(Y)
        total += float(np.einsum("i,ab,iba->", c, L, P))
    return total


def all_schedules(problem: SensorSchedulingProblem) -> np.ndarray:
    """Every schedule ``(N^(T·S), T, S)``."""
    T, S, N = problem.num_scans, problem.num_sensors, problem.num_targets
    grids = np.meshgrid(*([np.arange(N)] * (T * S)), indexing="ij")
    return np.stack([g.ravel() for g in grids], axis=-1).reshape(-1, T, S)


# ----------------------------------------------------------------------------------------------
# Stone Soup


@functools.cache
def _stonesoup_classes():
    from stonesoup.base import Property
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.sensor.sensor import Sensor
    from stonesoup.sensormanager.action import Action, ActionableProperty, ActionGenerator
    from stonesoup.sensormanager.reward import RewardFunction
    from stonesoup.types.array import CovarianceMatrix
    from stonesoup.types.detection import Detection, TrueDetection
    from stonesoup.types.hypothesis import SingleHypothesis

    class LookAtTarget(Action):
        """Point the sensor at target ``target_value`` (an index) for the scan."""

        def act(self, current_time, timestamp, init_value, **kwargs):
            return self.target_value

    class LookGenerator(ActionGenerator):
        """One :class:`LookAtTarget` per target."""

        num_targets: int = Property(doc="Number of targets")

        def __contains__(self, item):
            value = item.target_value if isinstance(item, Action) else item
            return value in range(self.num_targets)

        def __iter__(self):
            for i in range(self.num_targets):
                yield LookAtTarget(generator=self, end_time=self.end_time, target_value=i)

        @property
        def default_action(self):
            return LookAtTarget(generator=self, end_time=self.end_time, target_value=self.current_value)

    class TargetLookSensor(Sensor):
        """Measures the position of the one target it is pointed at (state order [x, vx, y, vy])."""

        num_targets: int = Property(doc="Number of targets")
        noise_covar: CovarianceMatrix = Property(doc="Position noise covariance (2, 2), m²")
        target: int = ActionableProperty(
            doc="Index of the target looked at", default=0,
            generator_cls=LookGenerator, generator_kwargs_mapping={"num_targets": "num_targets"})

        @property
        def measurement_model(self):
            return LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=self.noise_covar)

        def measure(self, ground_truths, noise=True, **kwargs):
            model = self.measurement_model
            return {TrueDetection(model.function(truth, noise=noise), measurement_model=model,
                                  timestamp=truth.timestamp, groundtruth_path=truth)
                    for truth in ground_truths if truth.metadata.get("target") == self.target}

    class PositionTraceReduction(RewardFunction):
        """Fall in ``Σ_i tr(P_i[pos, pos])`` over the tracks when the configuration's looks are
        made at ``metric_time`` (``tracks`` is a list, track ``i`` = target ``i``)."""

        predictors: list = Property(doc="One KalmanPredictor per target")
        updater: object = Property(doc="KalmanUpdater")

        def __call__(self, config, tracks, metric_time, *args, **kwargs):
            predictions = [p.predict(track.state, timestamp=metric_time) for p, track in zip(self.predictors, tracks)]
            posteriors = list(predictions)
            for actionable, actions in config.items():
                sensor = copy.deepcopy(actionable)
                sensor.add_actions(actions)
                sensor.act(metric_time)
                posteriors[sensor.target] = _update(self.updater, posteriors[sensor.target], sensor.measurement_model,
                                                    metric_time)
            return sum(_position_trace(a) - _position_trace(b) for a, b in zip(predictions, posteriors))

    def _update(updater, prediction, model, timestamp):
        # The covariance does not depend on the measured value: measure the prediction itself.
        detection = Detection(model.function(prediction, noise=False), timestamp=timestamp, measurement_model=model)
        return updater.update(SingleHypothesis(prediction, detection))

    return TargetLookSensor, PositionTraceReduction, _update


def _position_trace(state) -> float:
    P = np.asarray(state.covar)
    return float(P[0, 0] + P[2, 2])


def stonesoup_setup(sc: Scenario):
    """Stone Soup's objects for ``sc``: ``(manager, sensors, tracks, predictors, updater, t0)``."""
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.sensormanager import BruteForceSensorManager
    from stonesoup.types.array import CovarianceMatrix, StateVector
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import KalmanUpdater

    TargetLookSensor, PositionTraceReduction, _ = _stonesoup_classes()
    t0 = datetime.datetime(2026, 1, 1)
    predictors, tracks = [], []
    for q, P0 in zip(sc.accel_psd, sc.initial_cov):
        cv = ConstantVelocity(noise_diff_coeff=float(q))
        predictors.append(KalmanPredictor(CombinedLinearGaussianTransitionModel([cv, cv])))
        P_ss = np.zeros((4, 4))
        P_ss[np.ix_(PERM, PERM)] = P0
        tracks.append(Track([GaussianState(StateVector(np.zeros(4)), CovarianceMatrix(P_ss), timestamp=t0)]))
    sensors = [TargetLookSensor(num_targets=sc.num_targets, noise_covar=CovarianceMatrix(R)) for R in sc.R()]
    updater = KalmanUpdater(measurement_model=None)
    manager = BruteForceSensorManager(sensors=set(sensors),
                                      reward_function=PositionTraceReduction(predictors=predictors, updater=updater))
    return manager, sensors, tracks, predictors, updater, t0


def stonesoup_schedule(sc: Scenario) -> np.ndarray:
    """Run Stone Soup's ``BruteForceSensorManager`` for ``sc.num_scans`` scans: at each, choose the
    looks, enact them (the sensors act, every track is predicted, the looked-at ones updated).
    **Returns:** the chosen targets ``(T, S)`` (sensor columns in ``sc.noise_std`` order)."""
    manager, sensors, tracks, predictors, updater, t0 = stonesoup_setup(sc)
    _, _, _update = _stonesoup_classes()
    column = {id(s): j for j, s in enumerate(sensors)}
    schedule = np.zeros((sc.num_scans, sc.num_sensors), dtype=np.int64)
    for k in range(1, sc.num_scans + 1):
        t = t0 + datetime.timedelta(seconds=k * sc.tau)
        config = manager.choose_actions(tracks, t)[0]
        posteriors = [p.predict(track.state, timestamp=t) for p, track in zip(predictors, tracks)]
        for sensor, actions in config.items():
            sensor.add_actions(actions)
            sensor.act(t)
            schedule[k - 1, column[id(sensor)]] = sensor.target
            posteriors[sensor.target] = _update(updater, posteriors[sensor.target], sensor.measurement_model, t)
        for track, post in zip(tracks, posteriors):
            track.append(post)
    return schedule

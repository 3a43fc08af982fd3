"""The same targets seen by two sensors: :class:`TwoSensorScenario` and :func:`simulate_two_sensors`.

What a two-sensor tracker (:class:`~jaxtrack.multitarget.TrackFusionTracker`) reads: one truth,
two independent streams of detections, measurement noise and clutter, each sensor with its own
measurement model, ``P_D``, clutter and ``max_measurements``, the scans stacked as
``(T, 2, M, m)``. Sensor 1's run is exactly ``simulate_scenario(sensor1, key)`` (truth and
scans); sensor 2's is :func:`~jaxtrack.multitarget.simulate_scenario`'s simulation of
``sensor2`` with the truth fixed to sensor 1's states, from the key ``fold_in(key,
SENSOR2_STREAM)`` (so its noise is independent of sensor 1's: both scenarios draw their
measurement noise from the same streams of their run key). The truth is random per run (with
sensor 1's process noise), so both sensors' local tracks share its errors: the "unknown
correlation" of track-to-track fusion.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, PRNGKeyArray

from .._validation import InputError, as_key
from ._scenario import (
    PADDING,
    AbstractScenario,
    MultiTargetTrajectory,
    Scan,
    Scenario,
    _simulate_one,
    _warn_on_overflow,
)

# The word folded into the run key for sensor 2's draws ("sen2").
SENSOR2_STREAM = 0x73656E32


class TwoSensorTrajectory(eqx.Module):
    """One simulated run of a :class:`TwoSensorScenario`.

    **Fields:** ``states`` ``(T, N, n)`` and ``alive`` ``(T, N)``: the truth (sensor 1's run);
    ``scans``: a :class:`~jaxtrack.multitarget.Scan` whose arrays lead with ``(T, 2)`` (sensor 0
    = ``sensor1``): ``measurements`` ``(T, 2, M, m)`` with ``M``, ``m`` the larger sensor's,
    the smaller sensor's rows padded (``valid`` False, ``origin`` PADDING) and its columns padded
    with 0 (each local tracker reads its own first ``m_i`` columns); ``sensor1``, ``sensor2``: each
    sensor's own :class:`~jaxtrack.multitarget.MultiTargetTrajectory` (unpadded); ``overflow``
    ``()``: a scan of either sensor overflowed.
    """

    states: Float[Array, "T N n"]
    alive: Bool[Array, "T N"]
    scans: Scan
    sensor1: MultiTargetTrajectory
    sensor2: MultiTargetTrajectory
    overflow: Bool[Array, ""]


def _pad_scan(scan: Scan, M: int, m: int) -> Scan:
    """A ``(T, M_i, m_i)`` scan padded to ``(T, M, m)``: rows invalid, extra columns 0."""
    _, Mi, mi = scan.measurements.shape
    z = jnp.pad(scan.measurements, ((0, 0), (0, M - Mi), (0, m - mi)))
    valid = jnp.pad(scan.valid, ((0, 0), (0, M - Mi)))
    origin = jnp.pad(scan.origin, ((0, 0), (0, M - Mi)), constant_values=PADDING)
    return Scan(z, valid, origin, scan.num_clutter, scan.num_dropped, scan.overflow)


class TwoSensorScenario(AbstractScenario):
    """Two sensors observing the same targets: what :func:`simulate_two_sensors` and the Monte Carlo
    of a :class:`~jaxtrack.multitarget.TrackFusionTracker` simulate.

    **Arguments:** ``sensor1``, ``sensor2``: two :class:`~jaxtrack.multitarget.Scenario` s of the
    same targets (the same ``initial_states``, ``birth_step``, ``death_step``, ``num_steps`` and
    state dimension), each with its own sensor (``model``'s measurement function and noise),
    ``detection_probability``, clutter and ``max_measurements``. The targets move as ``sensor1``
    says (its model's transition and process noise, its ``process_noise`` and ``truth_states``);
    of ``sensor2`` only the sensor is used.

    ``model`` is ``sensor1.model``; ``max_measurements`` and ``scan_meas_dim`` the larger of the
    two (narrower scans are padded), ``scan_sensors`` ``(2,)``.

    **Raises:** :class:`~jaxtrack.InputError` naming ``sensor1``/``sensor2`` when either is not a
    ``Scenario`` or they do not describe the same targets.
    """

    sensor1: Scenario
    sensor2: Scenario

    def __init__(self, sensor1: Scenario, sensor2: Scenario):
        for name, s in (("sensor1", sensor1), ("sensor2", sensor2)):
            if not isinstance(s, Scenario):
                raise InputError(f"`{name}` must be a jaxtrack.multitarget.Scenario; got {type(s).__name__}.")
        if sensor2.model.state_dim != sensor1.model.state_dim:
            raise InputError(f"`sensor2`'s model has {sensor2.model.state_dim} states, `sensor1`'s "
                             f"{sensor1.model.state_dim}: both sensors see the same targets.")
        if sensor2.num_steps != sensor1.num_steps:
            raise InputError(f"`sensor2` has {sensor2.num_steps} steps, `sensor1` {sensor1.num_steps}.")
        for field in ("initial_states", "birth_step", "death_step"):
            a, b = np.asarray(getattr(sensor1, field)), np.asarray(getattr(sensor2, field))
            if a.shape != b.shape or not np.array_equal(a, b):
                raise InputError(f"`sensor2`'s `{field}` differ from `sensor1`'s: both sensors must see the same "
                                 "targets (build both Scenarios from the same targets, each with its own sensor).")
        self.sensor1 = sensor1
        self.sensor2 = sensor2

    @property
    def model(self):
        return self.sensor1.model

    @property
    def max_measurements(self) -> int:
        return max(self.sensor1.max_measurements, self.sensor2.max_measurements)

    @property
    def num_steps(self) -> int:
        return self.sensor1.num_steps

    @property
    def scan_sensors(self) -> tuple[int, ...]:
        return (2,)

    @property
    def scan_meas_dim(self) -> int:
        return max(self.sensor1.model.meas_dim, self.sensor2.model.meas_dim)

    def sample(self, key: PRNGKeyArray) -> TwoSensorTrajectory:
        """One run from ``key`` (traceable): sensor 1's run from ``key``, sensor 2's on the same truth
        from ``fold_in(key, SENSOR2_STREAM)`` (module docstring)."""
        run1 = _simulate_one(self.sensor1, key)
        run2 = _simulate_one(self.sensor2, jax.random.fold_in(key, SENSOR2_STREAM), truth_states=run1.states)
        M, m = self.max_measurements, self.scan_meas_dim
        scans = jax.tree.map(lambda a, b: jnp.stack([a, b], axis=1),
                             _pad_scan(run1.scans, M, m), _pad_scan(run2.scans, M, m))
        return TwoSensorTrajectory(run1.states, run1.alive, scans, run1, run2, run1.overflow | run2.overflow)


@eqx.filter_jit
def _sample_jit(scenario: TwoSensorScenario, key) -> TwoSensorTrajectory:
    return scenario.sample(key)


def simulate_two_sensors(sensor1: Scenario, sensor2: Scenario, key: PRNGKeyArray | int) -> TwoSensorTrajectory:
    """Simulate one run of the same targets seen by two sensors, the scans stacked ``(T, 2, M, m)``.

    **Arguments:** ``sensor1``, ``sensor2``: :class:`~jaxtrack.multitarget.Scenario` s of the same
    targets, each with its own sensor (:class:`TwoSensorScenario` says what must agree); ``key``:
    the run's PRNG key (Threefry) or an int seed.

    **Returns:** a :class:`TwoSensorTrajectory`; ``scans.measurements`` and ``scans.valid`` are what
    :class:`~jaxtrack.multitarget.TrackFusionTracker` steps on. Its ``sensor1`` run equals
    ``simulate_scenario(sensor1, key)``.

    **Warns:** :class:`~jaxtrack.multitarget.CapacityWarning` when a scan of either sensor held more
    than its ``max_measurements``.

    **Raises:** :class:`~jaxtrack.InputError` naming the argument (as :class:`TwoSensorScenario`, or a
    bad ``key``).
    """
    scenario = TwoSensorScenario(sensor1, sensor2)
    out = _sample_jit(scenario, as_key(key))
    _warn_on_overflow(out.sensor1, sensor1.max_measurements)
    _warn_on_overflow(out.sensor2, sensor2.max_measurements)
    return out

r"""The multi-target contract: what every tracker and random-finite-set filter implements, and
the one scan that runs them all.

A multi-target method is what :class:`~jaxtrack.filters.AbstractFilter` is for one target, with
optax's ``init``/``update`` shape:

- ``init() -> state``: the state before the first scan (a pytree of fixed shapes);
- ``step(state, measurements, valid) -> (state, info)``: one scan, ``measurements`` ``(M, m)``
  padded, ``valid`` ``(M,)`` bool; ``info`` is the family's step record (a NamedTuple with an
  ``ok`` field: the scan was answered with finite numbers within the method's capacities);
- ``estimates(state) -> Estimates(states, mask, ids)``: the reported targets, ``(K, n)``,
  ``(K,)``, ``(K,)`` (track identities for a labelled method, −1 where masked);
- ``capacity_events(state) -> ()`` int: everything a static capacity refused so far (track
  births without a slot, components left over by a reduction, rows an assignment had no room
  for, scans an associator could not answer), summed over the run — never lost in silence.

:class:`~jaxtrack.multitarget.Tracker` (GNN, JPDA, JIPDA), :class:`~jaxtrack.multitarget.GMPHD`,
:class:`~jaxtrack.multitarget.GMCPHD`, :class:`~jaxtrack.multitarget.PMB`,
:class:`~jaxtrack.multitarget.PMBM`, :class:`~jaxtrack.multitarget.GLMB`,
:class:`~jaxtrack.multitarget.LMB` and the two-sensor
:class:`~jaxtrack.multitarget.TrackFusionTracker` implement it; :func:`run_multitarget` (one
``lax.scan``) and :func:`~jaxtrack.multitarget.multitarget_monte_carlo` serve all eight, with no
dispatch on the family (a method declares the shape of its scans, ``scan_sensors`` and
``scan_meas_dim``: ``(M, m)`` for one sensor, ``(2, M, m)`` for two stacked). A new family gets both by implementing the four methods. The state layout (the order of
the state components) is the single-target model's: ``model.state_layout``, e.g.
``("x", "y", "vx", "vy")`` for :class:`~jaxtrack.models.ConstantVelocity` in the plane.

Manual stepping, as with a single-target filter::

    step = equinox.filter_jit(method.step)      # compiled once; a bound method of a Module
    state = method.init()                       # is a pytree: filter_jit, not jax.jit
    for z, v in zip(scans.measurements, scans.valid):     # (M, m), (M,)
        state, info = step(state, z, v)
        states, mask, ids = method.estimates(state)
"""

from __future__ import annotations

import abc
import warnings
from typing import Any, Callable, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._validation import InputError, is_concrete
from ._scenario import CapacityWarning


class Estimates(NamedTuple):
    """A multi-target method's reported targets after one scan (or ``T`` scans, with a leading axis).

    ``states`` ``(K, n)``: the targets' states in the model's units and layout (``model.state_layout``),
    0 where masked; ``mask`` ``(K,)`` bool: the rows that hold a target; ``ids`` ``(K,)`` int32:
    the track identity of each row for a labelled method (tracker, PMB, PMBM, GLMB, LMB), the mixture slot for
    a GM-PHD/GM-CPHD (no identity across scans), −1 where masked.
    """

    states: Float[Array, "K n"]
    mask: Bool[Array, " K"]
    ids: Int[Array, " K"]


class AbstractMultiTargetFilter(eqx.Module):
    """A multi-target tracker or random-finite-set filter: ``init``, ``step``, ``estimates``,
    ``capacity_events`` (the module docstring gives the contract).

    Concrete families are final classes. ``labelled`` says whether ``Estimates.ids`` are track
    identities that persist over scans (the track-level scores of
    :func:`~jaxtrack.multitarget.score_tracks` then mean something); ``model`` is the
    single-target state-space model every target follows (its ``state_layout`` names the state).
    """

    model: eqx.AbstractVar[Any]
    labelled: ClassVar[bool]

    @abc.abstractmethod
    def init(self) -> Any:
        """The state before the first scan."""

    @abc.abstractmethod
    def step(self, state: Any, measurements: Float[Array, "M m"], valid: Bool[Array, " M"]) -> tuple[Any, Any]:
        """One scan: ``(state, measurements (M, m), valid (M,)) -> (state, info)``."""

    @abc.abstractmethod
    def estimates(self, state: Any) -> Estimates:
        """The reported targets of ``state``: :class:`Estimates` ``(states (K, n), mask (K,), ids (K,))``."""

    @abc.abstractmethod
    def capacity_events(self, state: Any) -> Int[Array, ""]:
        """Everything a static capacity refused so far, summed over the run (``()`` int32)."""

    @property
    def scan_sensors(self) -> tuple[int, ...]:
        """The axes of one scan before its ``M`` measurement slots: ``()`` for one sensor (a scan
        is ``(M, m)``, every family but the two-sensor fusion), ``(2,)`` for
        :class:`~jaxtrack.multitarget.TrackFusionTracker` (a scan is ``(2, M, m)``, both sensors
        stacked). :func:`run_multitarget` and the Monte Carlo check scans against it; declared by
        the method, so that neither dispatches on its class."""
        return ()

    @property
    def scan_meas_dim(self) -> int:
        """``m``, the width of a scan's measurement rows (the model's ``meas_dim`` for one sensor;
        the wider sensor's for stacked sensors, whose narrower rows are padded)."""
        return self.model.meas_dim

    def capacity_message(self, events: int) -> str:
        """What to tell a user on the host when ``events`` capacity events happened (which
        capacities to raise). Families override it with their own capacities' names."""
        return (f"{events} capacity events: a capacity of the {type(self).__name__} was too small "
                "(see its capacity fields); raise it")


class MultiTargetResult(eqx.Module):
    """A multi-target method's run over ``T`` scans (:func:`run_multitarget`).

    **Fields:** ``estimates``: :class:`Estimates` with a leading ``T`` axis (``states`` ``(T, K, n)``,
    ``mask`` ``(T, K)``, ``ids`` ``(T, K)``); ``ok`` ``(T,)``: each scan's ``info.ok``;
    ``capacity_events`` ``(T,)``: the running count after each scan; ``info``: every scan's step
    record (the family's ``*StepInfo`` with a leading ``T`` axis) or None (``save_info=False``);
    ``final``: the state after the last scan.
    """

    estimates: Estimates
    ok: Bool[Array, " T"]
    capacity_events: Int[Array, " T"]
    info: Any
    final: Any


def check_method(method, name: str = "method") -> None:
    """:class:`~jaxtrack.InputError` unless ``method`` implements the multi-target contract."""
    if not isinstance(method, AbstractMultiTargetFilter):
        raise InputError(
            f"`{name}` must be a multi-target method (Tracker, GMPHD, GMCPHD, PMB, PMBM, GLMB, LMB or another "
            f"AbstractMultiTargetFilter); got {type(method).__name__}."
        )


def check_scans(measurements, valid, meas_dim: int, sensors: tuple[int, ...] = ()) -> tuple[Array, Array]:
    """``(measurements (T, *sensors, M, m), valid (T, *sensors, M))`` as arrays, or
    :class:`~jaxtrack.InputError` naming the bad one: shapes, the model's ``m``, a boolean mask, and
    (when concrete) finite values wherever ``valid`` is True (a NaN or inf marked valid would be
    tracked as a number). ``sensors`` is the method's :attr:`~AbstractMultiTargetFilter.scan_sensors`
    (``()``: one sensor, ``(T, M, m)``)."""
    measurements = jnp.asarray(measurements)
    valid = jnp.asarray(valid)
    sensors = tuple(sensors)
    axes = "".join(f"{s}, " for s in sensors)
    if measurements.ndim != 3 + len(sensors) or measurements.shape[1:1 + len(sensors)] != sensors:
        raise InputError(f"`measurements` must be (T, {axes}M, m); got shape {measurements.shape}.")
    if measurements.shape[-1] != meas_dim:
        raise InputError(f"`measurements` have {measurements.shape[-1]} components; the model measures {meas_dim}.")
    if valid.shape != measurements.shape[:-1] or valid.dtype != bool:
        raise InputError(f"`valid` must be boolean (T, {axes}M) = {measurements.shape[:-1]}; got {valid.dtype} "
                         f"{valid.shape}.")
    if is_concrete(measurements) and is_concrete(valid):
        bad = np.asarray(valid) & ~np.all(np.isfinite(np.asarray(measurements)), axis=-1)
        if np.any(bad):
            where = tuple(int(i) for i in np.argwhere(bad)[0])
            k, j = where[0], where[-1]
            sensor = f"sensor {where[1]}, " if sensors else ""
            raise InputError(
                f"`measurements` hold {int(bad.sum())} non-finite values marked valid (first: scan {k}, {sensor}slot {j}: "
                f"{np.asarray(measurements)[where].tolist()}); mark them invalid in `valid` or remove them."
            )
    return measurements, valid


def scan_ok(measurements: Array, valid: Array) -> Bool[Array, ""]:
    """Every measurement marked valid is finite (the traced counterpart of :func:`check_scans`)."""
    return jnp.all(~valid | jnp.all(jnp.isfinite(measurements), axis=-1))


@eqx.filter_jit
def scan_method(method: AbstractMultiTargetFilter, measurements, valid, record: Callable):
    """THE multi-target scan: ``lax.scan`` of ``method.step`` over ``(T, M, m)`` scans, keeping
    ``record(method, state, info)`` of every scan. Every multi-target run (:func:`run_multitarget`,
    the families' ``run_*``, the Monte Carlo) is this one function; ``record`` is a module-level
    function (part of the compilation key). **Returns:** ``(final state, records with a T axis)``."""

    def body(state, scan):
        state, info = method.step(state, *scan)
        return state, record(method, state, info)

    return jax.lax.scan(body, method.init(), (measurements, valid))


def _record_estimates(method, state, info):
    return method.estimates(state), info.ok, method.capacity_events(state)


def _record_estimates_and_info(method, state, info):
    return method.estimates(state), info.ok, method.capacity_events(state), info


def warn_capacity(method: AbstractMultiTargetFilter, events, stacklevel: int = 3) -> None:
    """A host-side :class:`CapacityWarning` when ``events`` (concrete) is not 0."""
    if is_concrete(events) and int(events) > 0:
        warnings.warn(method.capacity_message(int(events)) + ".", CapacityWarning, stacklevel=stacklevel)


def warn_not_ok(method: AbstractMultiTargetFilter, ok, stacklevel: int = 3) -> None:
    """A host-side ``RuntimeWarning`` naming the scans whose step was not ok (concrete ``ok`` only)."""
    if is_concrete(ok) and not bool(jnp.all(ok)):
        bad = np.flatnonzero(~np.asarray(ok))
        warnings.warn(
            f"the {type(method).__name__} could not answer scans {bad.tolist()[:20]}{' …' if bad.size > 20 else ''} "
            "with finite numbers within its capacities (`ok` False): check the parameters (probabilities in "
            "(0, 1], a finite positive clutter density), the measurements marked valid, and the capacities.",
            RuntimeWarning, stacklevel=stacklevel,
        )


def run_multitarget(
    method: AbstractMultiTargetFilter,
    measurements: ArrayLike,
    valid: ArrayLike,
    *,
    save_info: bool = False,
    warn: bool = True,
) -> MultiTargetResult:
    """Run any multi-target method over ``T`` scans: one jitted ``lax.scan`` of ``method.step``.

    **Arguments:**

    - ``method``: a :class:`AbstractMultiTargetFilter` (:class:`~jaxtrack.multitarget.Tracker`,
      :class:`~jaxtrack.multitarget.GMPHD`, :class:`~jaxtrack.multitarget.GMCPHD`,
      :class:`~jaxtrack.multitarget.PMB`, :class:`~jaxtrack.multitarget.PMBM`,
      :class:`~jaxtrack.multitarget.GLMB`, :class:`~jaxtrack.multitarget.LMB`, or your own).
    - ``measurements``: ``(T, M, m)`` padded scans in the sensor's units (padding may be NaN);
      ``valid``: boolean ``(T, M)``, False for padding (a scenario's ``trajectory.scans``). For a
      method with several sensors (:attr:`AbstractMultiTargetFilter.scan_sensors`, e.g. ``(2,)``)
      ``(T, 2, M, m)`` and ``(T, 2, M)``.
    - ``save_info``: also keep every scan's step record (``info``).
    - ``warn``: on the host (concrete results only), a :class:`CapacityWarning` when a capacity
      was too small and a ``RuntimeWarning`` when a scan was not ``ok``.

    **Returns:** a :class:`MultiTargetResult`. The families' own runs
    (:func:`~jaxtrack.multitarget.run_tracker`, :func:`~jaxtrack.multitarget.run_phd`, …) are the
    same scan with more of the state kept.

    **Raises:** :class:`~jaxtrack.InputError` naming ``method``, ``measurements`` or ``valid``
    (non-finite measurements marked valid included).
    """
    check_method(method)
    measurements, valid = check_scans(measurements, valid, method.scan_meas_dim, method.scan_sensors)
    record = _record_estimates_and_info if save_info else _record_estimates
    final, recs = scan_method(method, measurements, valid, record)
    estimates, ok, events = recs[:3]
    result = MultiTargetResult(estimates, ok, events, recs[3] if save_info else None, final)
    if warn:
        warn_capacity(method, events[-1])
        warn_not_ok(method, ok)
    return result

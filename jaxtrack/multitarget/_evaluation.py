"""Scoring a tracker: GOSPA per scan, track-level counts, and the Monte Carlo of a tracker.

- :func:`score_tracks`: one run's confirmed tracks against the truth, scan by scan: the GOSPA
  distance with its parts (:func:`jaxtrack.montecarlo.gospa`, α = 2) and, from GOSPA's own
  optimal assignment, the track-level counts a tracking paper reports (Ristic, Vo, Clark & Vo
  2011, "A metric for performance evaluation of multi-target tracking algorithms", §II, for
  the switch count; Blackman & Popoli 1999, §13.6, for false and broken tracks).
- :func:`multitarget_monte_carlo`: the Monte Carlo of any multi-target method (the contract of
  :mod:`._base`) on a scenario through the same run primitive as every jaxtrack Monte Carlo
  (:func:`jaxtrack.montecarlo.run_blocks`: run ``i`` from ``fold_in(key, i)``, blocks of vmapped
  runs, streaming sums), so that run ``i`` is ``simulate_scenario(scenario, fold_in(key, i))``
  run through :func:`~jaxtrack.multitarget.run_multitarget`'s scan. Every run's GOSPA per scan is
  kept too; ``tracker_monte_carlo`` is its former name.
"""

from __future__ import annotations

import warnings
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._export import Exportable
from .._validation import InputError, as_key
from ..models._layout import position_indices
from ..montecarlo._engine import MonteCarloInterrupted, block_size_for, masked_run_sums, refuse_traced, run_blocks
from ..montecarlo._ospa import GOSPA, gospa
from ._base import AbstractMultiTargetFilter, _record_estimates, check_method, scan_method
from ._scenario import AbstractScenario, CapacityWarning


class TrackScores(Exportable, eqx.Module):
    """Track-level counts of one run (integers; summed over runs they stay counts).

    A confirmed track is one stretch of scans in which a slot holds the same track id with
    status confirmed; it is *assigned* at a scan when GOSPA's optimal assignment pairs it with a
    target (distance below the cut-off).

    **Fields:**

    - ``num_confirmed``: confirmed tracks.
    - ``num_false``: confirmed tracks never assigned to any target (false tracks).
    - ``num_switches``: scans at which a target alive in the previous scan is assigned to a
      different track than in the previous scan (identity switches).
    - ``num_breaks``: scans at which a target alive and assigned in the previous scan has no
      track (track breaks; a lost target that is later picked up again counts once per break).
    """

    _export_kind: ClassVar[str] = "jaxtrack.TrackScores"

    num_confirmed: Int[Array, ""]
    num_false: Int[Array, ""]
    num_switches: Int[Array, ""]
    num_breaks: Int[Array, ""]


def _positions(layout, name: str) -> tuple[int, ...]:
    if layout is None:
        raise InputError(
            f"`{name}` declares no state layout, so the position components to score are unknown; "
            "build it from jaxtrack's motion models or pass `state_layout=`."
        )
    idx = position_indices(layout)
    if not idx:
        raise InputError(f"`{name}`'s state layout {layout} has no position component (x, y, z).")
    return idx


def score_tracks(
    target_positions: Float[Array, "T N d"],
    alive: Bool[Array, "T N"],
    track_positions: Float[Array, "T K d"],
    confirmed: Bool[Array, "T K"],
    track_id: Int[Array, "T K"],
    *,
    cutoff: float,
    order: float = 2.0,
) -> tuple[GOSPA, TrackScores]:
    """GOSPA per scan and the track-level counts of one run.

    **Arguments:**

    - ``target_positions`` ``(T, N, d)`` and ``alive`` ``(T, N)``: the truth, in metres (or the
      position units); ``track_positions`` ``(T, K, d)``, ``confirmed`` ``(T, K)`` and
      ``track_id`` ``(T, K)``: the tracker's table after each scan (only confirmed tracks count).
    - ``cutoff``: GOSPA's ``c`` (same units); ``order``: ``p``.

    **Returns:** ``(gospa, scores)``: a :class:`~jaxtrack.montecarlo.GOSPA` with a leading ``T``
    axis, and the run's :class:`TrackScores`.
    """
    track_id = jnp.asarray(track_id, jnp.int32)
    alive, confirmed = jnp.asarray(alive, bool), jnp.asarray(confirmed, bool)
    K = track_positions.shape[1]
    N = target_positions.shape[1]

    def step(carry, inputs):
        prev_tid, prev_alive, slot_id, slot_conf, slot_hit, counts = carry
        x, a, y, c, ids = inputs
        g = gospa(x, a, y, c, cutoff=cutoff, order=order)
        assigned_slot = g.assignment  # (N,) slot or -1
        tid = jnp.where(assigned_slot >= 0, ids[jnp.maximum(assigned_slot, 0)], -1)
        hit_now = jnp.zeros((K + 1,), bool).at[jnp.where(assigned_slot >= 0, assigned_slot, K)].set(True)[:K]
        same = slot_conf & c & (slot_id == ids)  # the same confirmed track continues
        started = c & ~same
        ended = slot_conf & ~same
        num_false = jnp.sum(ended & ~slot_hit)
        slot_hit = jnp.where(same, slot_hit | hit_now, hit_now) & c
        was = prev_alive & a & (prev_tid >= 0)
        switches = jnp.sum(was & (tid >= 0) & (tid != prev_tid))
        breaks = jnp.sum(was & (tid < 0))
        counts = counts + jnp.stack([jnp.sum(started), num_false, switches, breaks]).astype(jnp.int32)
        return (tid, a, ids, c, slot_hit, counts), g

    init = (
        jnp.full((N,), -1, jnp.int32),
        jnp.zeros((N,), bool),
        jnp.full((K,), -1, jnp.int32),
        jnp.zeros((K,), bool),
        jnp.zeros((K,), bool),
        jnp.zeros((4,), jnp.int32),
    )
    (_, _, _, slot_conf, slot_hit, counts), per_step = jax.lax.scan(
        step, init, (target_positions, alive, track_positions, confirmed, track_id)
    )
    # Tracks still confirmed at the end and never assigned are false too.
    counts = counts.at[1].add(jnp.sum(slot_conf & ~slot_hit).astype(jnp.int32))
    return per_step, TrackScores(counts[0], counts[1], counts[2], counts[3])


class MultiTargetMonteCarloResult(Exportable, eqx.Module):
    """A multi-target method's Monte Carlo on a scenario: GOSPA per scan with its parts, track
    counts, and every run's GOSPA.

    **Fields** (``T`` scans, ``R = num_runs`` runs; means over the runs):

    - ``gospa`` ``(T,)``: the mean GOSPA distance per scan (units of the positions);
      ``gospa_interval`` ``(T, 2)``: its 95% confidence interval (normal approximation,
      ``mean ± 1.96 s/√R``).
    - ``localisation``, ``missed``, ``false`` ``(T,)``: the means of GOSPA's parts (units to the
      power ``p``); ``num_targets``, ``num_tracks`` ``(T,)``: mean numbers of alive targets and of
      reported targets (confirmed tracks, a random-finite-set filter's estimates).
    - ``per_run_gospa`` ``(R, T)``: every run's GOSPA distance per scan (run ``i`` from
      ``fold_in(key, i)``), for other statistics than the mean (quantiles, a paired comparison of
      two methods on the same runs).
    - ``scores``: the :class:`TrackScores` averaged over runs (floats; meaningful for labelled
      methods only: a GM-PHD's rows carry no identity).
    - ``scans_overflowed``, ``capacity_events``: totals over all runs (ints): scans that held more
      than ``max_measurements``, and the method's capacity events
      (:meth:`~jaxtrack.multitarget.AbstractMultiTargetFilter.capacity_events`); ``scans_not_ok``:
      scans whose step was not ``ok``.
    - ``num_runs``, ``cutoff``, ``order``; ``completed``: False for the partial result of an
      interrupted run (the first ``num_runs`` runs, whole blocks), ``method_name``: the method's class.
    """

    _export_kind: ClassVar[str] = "jaxtrack.MultiTargetMonteCarloResult"
    _export_dims: ClassVar[dict] = {
        "gospa": ("scan",), "gospa_interval": ("scan", "bound"), "localisation": ("scan",), "missed": ("scan",),
        "false": ("scan",), "num_targets": ("scan",), "num_tracks": ("scan",), "per_run_gospa": ("run", "scan"),
    }
    _export_units: ClassVar[dict] = {
        "gospa": "position units", "gospa_interval": "position units", "per_run_gospa": "position units",
        "localisation": "position units^p", "missed": "position units^p", "false": "position units^p",
        "num_targets": "count", "num_tracks": "count",
    }

    gospa: Float[Array, " T"]
    gospa_interval: Float[Array, "T 2"]
    localisation: Float[Array, " T"]
    missed: Float[Array, " T"]
    false: Float[Array, " T"]
    num_targets: Float[Array, " T"]
    num_tracks: Float[Array, " T"]
    per_run_gospa: Float[Array, "R T"]
    scores: TrackScores
    scans_overflowed: int = eqx.field(static=True)
    capacity_events: int = eqx.field(static=True)
    scans_not_ok: int = eqx.field(static=True)
    num_runs: int = eqx.field(static=True)
    cutoff: float = eqx.field(static=True)
    order: float = eqx.field(static=True)
    completed: bool = eqx.field(static=True, default=True)
    method_name: str = eqx.field(static=True, default="")

    def mean_gospa(self) -> float:
        """The GOSPA distance averaged over runs and scans (one number per method)."""
        return float(np.mean(self.gospa))

    @property
    def births_dropped(self) -> int:
        """Former name of :attr:`capacity_events`."""
        return self.capacity_events


TrackerMonteCarloResult = MultiTargetMonteCarloResult  # the former name


def _one_run(key, args):
    method, scenario, target_idx, track_idx, cutoff, order = args
    truth = scenario.sample(key)
    _, (est, ok, events) = scan_method(method, truth.scans.measurements, truth.scans.valid, _record_estimates)
    g, scores = score_tracks(
        truth.states[..., target_idx], truth.alive, est.states[..., track_idx], est.mask,
        est.ids, cutoff=cutoff, order=order,
    )
    sums = {
        "gospa": g.distance,
        "gospa_sq": g.distance**2,
        "localisation": g.localisation,
        "missed": g.missed,
        "false": g.false,
        "num_targets": jnp.sum(truth.alive, axis=1),
        "num_tracks": jnp.sum(est.mask, axis=1),
        "scores": scores,
        "scans_overflowed": jnp.sum(truth.scans.overflow),
        "capacity_events": events[-1],
        "scans_not_ok": jnp.sum(~ok),
    }
    return sums, g.distance


def _mc_block(common, value, key, start, valid):
    """One block: the runs' sums (:func:`~jaxtrack.montecarlo._engine.masked_run_sums`, as
    ``monte_carlo_map`` adds them) and every run's GOSPA per scan."""
    args = common
    keys = jax.vmap(lambda i: jax.random.fold_in(key, i))(start + jnp.arange(valid.shape[0]))
    sums, per_run = jax.vmap(_one_run, in_axes=(0, None))(keys, args)
    return masked_run_sums(sums, valid), per_run, start


def _mc_accumulate(totals, delta, start):
    sums, buffer = totals
    block_sums, per_run, _ = delta
    sums = jax.tree_util.tree_map(jnp.add, sums, block_sums)
    return sums, jax.lax.dynamic_update_slice_in_dim(buffer, per_run.astype(buffer.dtype), start, axis=0)


def _summary(method, scenario, sums, per_run, R, cutoff, order, completed):
    mean = sums["gospa"] / R
    var = np.maximum(sums["gospa_sq"] / R - mean**2, 0.0) * R / (R - 1) if R > 1 else np.full_like(mean, np.nan)
    half = 1.959963984540054 * np.sqrt(var / R)
    scores = jax.tree.map(lambda s: np.asarray(s, float) / R, sums["scores"])
    return MultiTargetMonteCarloResult(
        gospa=mean,
        gospa_interval=np.stack([mean - half, mean + half], axis=-1),
        localisation=sums["localisation"] / R,
        missed=sums["missed"] / R,
        false=sums["false"] / R,
        num_targets=sums["num_targets"] / R,
        num_tracks=sums["num_tracks"] / R,
        per_run_gospa=np.asarray(per_run)[:R],
        scores=scores,
        scans_overflowed=int(sums["scans_overflowed"]),
        capacity_events=int(sums["capacity_events"]),
        scans_not_ok=int(sums["scans_not_ok"]),
        num_runs=R,
        cutoff=float(cutoff),
        order=float(order),
        completed=completed,
        method_name=type(method).__name__,
    )


def multitarget_monte_carlo(
    method: AbstractMultiTargetFilter,
    scenario: AbstractScenario,
    key,
    num_runs: int,
    *,
    cutoff: float,
    order: float = 2.0,
    block_size: int = 64,
    progress: bool = False,
) -> MultiTargetMonteCarloResult:
    """Monte Carlo of any multi-target method on a scenario: mean GOSPA per scan with its parts,
    every run's GOSPA, track counts.

    Run ``i`` simulates ``scenario`` from ``fold_in(key, i)`` (exactly
    ``simulate_scenario(scenario, fold_in(key, i))``), runs ``method`` over its scans (the scan of
    :func:`~jaxtrack.multitarget.run_multitarget`) and scores the positions of its
    :meth:`~jaxtrack.multitarget.AbstractMultiTargetFilter.estimates` against the alive targets'
    (:func:`score_tracks`): a tracker's confirmed tracks, a PMBM's, PMB's, GLMB's or LMB's estimated tracks
    (with their ids: labels for the last two), a GM-PHD's or GM-CPHD's extracted estimates (unlabelled, so their track-level
    counts are not meaningful). Runs go in blocks of ``block_size`` vmapped runs (one
    compilation); the sums are added in block order (the statistics do not depend on how the runs
    are split), every run's GOSPA per scan is written to a ``(R, T)`` store.

    **Arguments:**

    - ``method``: any :class:`~jaxtrack.multitarget.AbstractMultiTargetFilter`
      (:class:`~jaxtrack.multitarget.Tracker`, :class:`~jaxtrack.multitarget.GMPHD`,
      :class:`~jaxtrack.multitarget.GMCPHD`, :class:`~jaxtrack.multitarget.PMB`,
      :class:`~jaxtrack.multitarget.PMBM`, :class:`~jaxtrack.multitarget.GLMB`,
      :class:`~jaxtrack.multitarget.LMB`; its model may differ from the scenario's: a mismatched
      study); ``scenario``: a :class:`Scenario`, or a
      :class:`~jaxtrack.multitarget.TwoSensorScenario` for the two-sensor
      :class:`~jaxtrack.multitarget.TrackFusionTracker` (any :class:`AbstractScenario` whose
      ``scan_sensors`` and ``scan_meas_dim`` are the method's). Both models must declare their state layout (the
      position components are scored).
    - ``key``: PRNG key or int seed; ``num_runs``: ``R ≥ 2``.
    - ``cutoff``: GOSPA's ``c`` (position units, > 0); ``order``: ``p ≥ 1`` (default 2).
    - ``block_size``: runs per compiled block; ``progress``: a progress bar.

    **Returns:** a :class:`MultiTargetMonteCarloResult` (``save``/``load``/``to_xarray`` like
    :class:`~jaxtrack.montecarlo.MonteCarloResult`).

    **Warns:** :class:`CapacityWarning` when scans overflowed ``max_measurements`` or a capacity
    of the method was too small (counted in ``capacity_events``); ``RuntimeWarning`` when some scan
    was not ``ok``.

    **Interrupted** (Ctrl-C): raises :class:`~jaxtrack.montecarlo.MonteCarloInterrupted` (a
    ``KeyboardInterrupt``) whose ``partial`` is the result of the blocks that had finished
    (``completed=False``; None when fewer than 2 runs had), so an interrupted study keeps what it
    computed: ``except KeyboardInterrupt as e: result = getattr(e, "partial", None)``.
    """
    if not isinstance(scenario, AbstractScenario):
        raise InputError("`scenario` must be a jaxtrack.multitarget.Scenario or TwoSensorScenario (an AbstractScenario); "
                         f"got {type(scenario).__name__}.")
    check_method(method)
    if not isinstance(num_runs, int) or num_runs < 2:
        raise InputError(f"`num_runs` must be an int >= 2 (for the interval); got {num_runs!r}.")
    if not float(cutoff) > 0:
        raise InputError(f"`cutoff` must be positive; got {cutoff}.")
    if not float(order) >= 1:
        raise InputError(f"`order` must be >= 1; got {order}.")
    if not isinstance(block_size, int) or block_size < 1:
        raise InputError(f"`block_size` must be a positive int; got {block_size!r}.")
    if method.scan_sensors != scenario.scan_sensors:
        raise InputError(
            f"the method reads scans of sensor axes {method.scan_sensors}, the scenario simulates "
            f"{scenario.scan_sensors} (one sensor: (); two stacked: (2,))."
        )
    if method.scan_meas_dim != scenario.scan_meas_dim:
        raise InputError(
            f"the method's model measures {method.scan_meas_dim} components, the scenario's "
            f"sensor {scenario.scan_meas_dim}."
        )
    target_idx = _positions(scenario.model.state_layout, "scenario.model")
    track_idx = _positions(method.model.state_layout, "method.model")
    if len(target_idx) != len(track_idx):
        raise InputError(
            f"the scenario's targets have {len(target_idx)} position axes, the method's states "
            f"{len(track_idx)}."
        )
    key = as_key(key)
    args = (method, scenario, np.asarray(target_idx), np.asarray(track_idx), float(cutoff), float(order))
    refuse_traced("multitarget_monte_carlo", key, args)
    block = block_size_for(num_runs, block_size)
    shape = jax.eval_shape(lambda k: _one_run(k, args), jax.random.fold_in(key, 0))

    def zero(sd):
        return jnp.zeros(sd.shape, jnp.int32 if (sd.dtype == bool or jnp.issubdtype(sd.dtype, jnp.integer)) else sd.dtype)

    padded = -(-num_runs // block) * block
    totals = (jax.tree_util.tree_map(zero, shape[0]), jnp.zeros((padded,) + shape[1].shape, shape[1].dtype))
    try:
        sums, per_run = run_blocks(_mc_block, totals, common=args, key=key, num_runs=num_runs, block=block,
                                   accumulate=_mc_accumulate, progress=progress, desc="multi-target Monte Carlo")
    except MonteCarloInterrupted as stop:
        if stop.totals is not None and stop.num_runs_done >= 2:
            sums, per_run = stop.totals
            stop.partial = _summary(method, scenario, sums, per_run, stop.num_runs_done, cutoff, order, False)
        raise
    result = _summary(method, scenario, sums, per_run, num_runs, cutoff, order, True)
    R = num_runs
    if result.scans_overflowed:
        warnings.warn(
            f"{result.scans_overflowed} scans over {R} runs held more than max_measurements="
            f"{scenario.max_measurements} measurements (the excess was not tracked); raise it.",
            CapacityWarning, stacklevel=2,
        )
    if result.capacity_events:
        warnings.warn(method.capacity_message(result.capacity_events) + f" (over {R} runs).", CapacityWarning,
                      stacklevel=2)
    if result.scans_not_ok:
        warnings.warn(f"{result.scans_not_ok} scans over {R} runs were not ok (the {type(method).__name__} could not "
                      "answer them with finite numbers within its capacities).", RuntimeWarning, stacklevel=2)
    return result


def tracker_monte_carlo(tracker, scenario, key, num_runs, **kwargs) -> MultiTargetMonteCarloResult:
    """Deprecated: the former name of :func:`multitarget_monte_carlo` (same arguments, ``tracker``
    being the method), removed in jaxtrack 0.3."""
    from .._deprecation import REMOVED_IN

    warnings.warn(f"`tracker_monte_carlo` is deprecated: use `multitarget_monte_carlo` (the same arguments); it will "
                  f"be removed in jaxtrack {REMOVED_IN}.", DeprecationWarning, stacklevel=2)
    return multitarget_monte_carlo(tracker, scenario, key, num_runs, **kwargs)

"""Scoring a tracker: GOSPA per scan, track-level counts, and the Monte Carlo of a tracker.

- :func:`score_tracks`: one run's confirmed tracks against the truth, scan by scan: the GOSPA
  distance with its parts (:func:`jaxtrack.montecarlo.gospa`, α = 2) and, from GOSPA's own
  optimal assignment, the track-level counts a tracking paper reports (Ristic, Vo, Clark & Vo
  2011, "A metric for performance evaluation of multi-target tracking algorithms", §II, for
  the switch count; Blackman & Popoli 1999, §13.6, for false and broken tracks).
- :func:`tracker_monte_carlo`: the Monte Carlo of a tracker on a scenario through the same run
  primitive as every jaxtrack Monte Carlo (:func:`jaxtrack.montecarlo.monte_carlo_map`: run ``i``
  from ``fold_in(key, i)``, blocks of vmapped runs, streaming sums), so that run ``i`` is
  ``simulate_scenario(scenario, fold_in(key, i))`` tracked by ``run_tracker``.
"""

from __future__ import annotations

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._validation import InputError, as_key
from ..models._layout import position_indices
from ..montecarlo._engine import monte_carlo_map
from ..montecarlo._ospa import GOSPA, gospa
from ._scenario import CapacityWarning, Scenario, _check_scenario, _simulate_one
from ._tracker import CONFIRMED, Tracker, _run_tracker


class TrackScores(eqx.Module):
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


class TrackerMonteCarloResult(eqx.Module):
    """A tracker's Monte Carlo on a scenario: GOSPA per scan with its parts, and track counts.

    **Fields** (``T`` scans; means over ``num_runs`` runs):

    - ``gospa`` ``(T,)``: the mean GOSPA distance per scan (units of the positions);
      ``gospa_interval`` ``(T, 2)``: its 95% confidence interval (normal approximation,
      ``mean ± 1.96 s/√R``).
    - ``localisation``, ``missed``, ``false`` ``(T,)``: the means of GOSPA's parts (units to the
      power ``p``); ``num_targets``, ``num_tracks`` ``(T,)``: mean numbers of alive targets and of
      confirmed tracks (a random-finite-set filter's estimates).
    - ``scores``: the :class:`TrackScores` averaged over runs (floats).
    - ``scans_overflowed``, ``births_dropped``: totals over all runs (ints): scans that held more
      than ``max_measurements`` and capacity events: track births refused for want of table
      slots (a tracker), or the filter's capacity events (see :func:`tracker_monte_carlo`).
    - ``num_runs``, ``cutoff``, ``order``: what was run.
    """

    gospa: Float[Array, " T"]
    gospa_interval: Float[Array, "T 2"]
    localisation: Float[Array, " T"]
    missed: Float[Array, " T"]
    false: Float[Array, " T"]
    num_targets: Float[Array, " T"]
    num_tracks: Float[Array, " T"]
    scores: TrackScores
    scans_overflowed: int = eqx.field(static=True)
    births_dropped: int = eqx.field(static=True)
    num_runs: int = eqx.field(static=True)
    cutoff: float = eqx.field(static=True)
    order: float = eqx.field(static=True)

    def mean_gospa(self) -> float:
        """The GOSPA distance averaged over runs and scans (one number per method)."""
        return float(np.mean(self.gospa))


def _method_estimates(method, measurements, valid):
    """A method's estimates over one run, as ``(states (T, K, n), reported (T, K), ids (T, K),
    capacity_events ())``: a tracker's confirmed tracks, a GM-PHD's or GM-CPHD's extracted
    estimates (no labels: the slot index stands for the id), a PMBM's or PMB's estimated tracks."""
    from ._cphd import GMCPHD, _run_cphd
    from ._multibernoulli import _run as _run_mb
    from ._phd import GMPHD, _run_phd

    if isinstance(method, Tracker):
        r = _run_tracker(method, measurements, valid, False)
        return r.mean, r.status == CONFIRMED, r.track_id, r.final.num_dropped_births
    if isinstance(method, (GMPHD, GMCPHD)):
        r = (_run_phd if isinstance(method, GMPHD) else _run_cphd)(method, measurements, valid)
        slots = jnp.broadcast_to(jnp.arange(r.estimate_mask.shape[1], dtype=jnp.int32), r.estimate_mask.shape)
        return r.estimates, r.estimate_mask, slots, jnp.sum(r.num_dropped)
    r = _run_mb(method, measurements, valid)
    fs = r.final
    events = fs.num_dropped_tracks + fs.poisson_num_dropped + fs.assignment_overflow + jnp.sum(~r.association_ok)
    return r.estimates, r.estimate_mask, r.estimate_id, events


def _one_run(key, args):
    tracker, scenario, target_idx, track_idx, cutoff, order = args
    truth = _simulate_one(scenario, key)
    est, reported, ids, events = _method_estimates(tracker, truth.scans.measurements, truth.scans.valid)
    confirmed = reported
    g, scores = score_tracks(
        truth.states[..., target_idx], truth.alive, est[..., track_idx], confirmed,
        ids, cutoff=cutoff, order=order,
    )
    return {
        "gospa": g.distance,
        "gospa_sq": g.distance**2,
        "localisation": g.localisation,
        "missed": g.missed,
        "false": g.false,
        "num_targets": jnp.sum(truth.alive, axis=1),
        "num_tracks": jnp.sum(confirmed, axis=1),
        "scores": scores,
        "scans_overflowed": jnp.sum(truth.scans.overflow),
        "births_dropped": events,
    }


def tracker_monte_carlo(
    tracker: Tracker,
    scenario: Scenario,
    key,
    num_runs: int,
    *,
    cutoff: float,
    order: float = 2.0,
    block_size: int = 64,
    progress: bool = False,
) -> TrackerMonteCarloResult:
    """Monte Carlo of a tracker or a random-finite-set filter on a scenario: mean GOSPA per scan
    with its parts, track counts.

    Run ``i`` simulates ``scenario`` from ``fold_in(key, i)`` (exactly
    ``simulate_scenario(scenario, fold_in(key, i))``), runs ``tracker`` over its scans
    (:func:`run_tracker`, :func:`run_phd`, :func:`run_cphd` or :func:`run_pmbm`) and scores its
    estimates' positions against the alive targets' (:func:`score_tracks`): a tracker's confirmed
    tracks, a PMBM's or PMB's estimated tracks (with their ids), a GM-PHD's or GM-CPHD's
    extracted estimates (unlabelled, so their track-level counts are not meaningful). Runs go through :func:`jaxtrack.montecarlo.monte_carlo_map` in blocks
    of ``block_size`` vmapped runs (one compilation), summed in streaming form.

    **Arguments:**

    - ``tracker``: a :class:`Tracker`, :class:`GMPHD`, :class:`GMCPHD`, :class:`PMBM` or
      :class:`PMB` (its model may differ from the scenario's: a mismatched study);
      ``scenario``: a :class:`Scenario`. Both models must declare their state layout
      (the position components are scored).
    - ``key``: PRNG key or int seed; ``num_runs``: ``R ≥ 2``.
    - ``cutoff``: GOSPA's ``c`` (position units, > 0); ``order``: ``p ≥ 1`` (default 2).
    - ``block_size``: runs per compiled block; ``progress``: a progress bar.

    **Returns:** a :class:`TrackerMonteCarloResult`.

    **Warns:** :class:`CapacityWarning` when scans overflowed ``max_measurements`` or a capacity
    of the method was too small (the counts are in the result: ``births_dropped`` counts track
    births refused, Gaussian components left over by a PHD/CPHD reduction, and for a PMBM/PMB
    also gated measurements or tracks its assignment had no room for and scans its associator
    could not answer).
    """
    _check_scenario(scenario)
    from ._cphd import GMCPHD
    from ._phd import GMPHD
    from ._pmb import PMB
    from ._pmbm import PMBM

    if not isinstance(tracker, (Tracker, GMPHD, GMCPHD, PMBM, PMB)):
        raise InputError(f"`tracker` must be a Tracker, GMPHD, GMCPHD, PMBM or PMB; got {type(tracker).__name__}.")
    if not isinstance(num_runs, int) or num_runs < 2:
        raise InputError(f"`num_runs` must be an int >= 2 (for the interval); got {num_runs!r}.")
    if not float(cutoff) > 0:
        raise InputError(f"`cutoff` must be positive; got {cutoff}.")
    if not float(order) >= 1:
        raise InputError(f"`order` must be >= 1; got {order}.")
    if tracker.model.meas_dim != scenario.model.meas_dim:
        raise InputError(
            f"the tracker's model measures {tracker.model.meas_dim} components, the scenario's "
            f"sensor {scenario.model.meas_dim}."
        )
    target_idx = _positions(scenario.model.state_layout, "scenario.model")
    track_idx = _positions(tracker.model.state_layout, "tracker.model")
    if len(target_idx) != len(track_idx):
        raise InputError(
            f"the scenario's targets have {len(target_idx)} position axes, the tracker's states "
            f"{len(track_idx)}."
        )
    args = (tracker, scenario, np.asarray(target_idx), np.asarray(track_idx), float(cutoff), float(order))
    sums = monte_carlo_map(
        _one_run, as_key(key), num_runs, args=args, block_size=block_size, progress=progress,
        desc="tracker Monte Carlo",
    )
    R = num_runs
    mean = sums["gospa"] / R
    var = np.maximum(sums["gospa_sq"] / R - mean**2, 0.0) * R / (R - 1)
    half = 1.959963984540054 * np.sqrt(var / R)
    scores = jax.tree.map(lambda s: np.asarray(s, float) / R, sums["scores"])
    overflowed, dropped = int(sums["scans_overflowed"]), int(sums["births_dropped"])
    if overflowed:
        warnings.warn(
            f"{overflowed} scans over {R} runs held more than max_measurements="
            f"{scenario.max_measurements} measurements (the excess was not tracked); raise it.",
            CapacityWarning, stacklevel=2,
        )
    if dropped:
        what = (f"track births over {R} runs were refused: the table's capacity ({tracker.capacity} slots) was too "
                "small; raise `capacity`" if isinstance(tracker, Tracker) else
                f"capacity events over {R} runs (components, tracks or assignment rows with no room, or scans the "
                f"associator could not answer): a capacity of the {type(tracker).__name__} was too small; raise it")
        warnings.warn(f"{dropped} {what}.", CapacityWarning, stacklevel=2)
    return TrackerMonteCarloResult(
        gospa=mean,
        gospa_interval=np.stack([mean - half, mean + half], axis=-1),
        localisation=sums["localisation"] / R,
        missed=sums["missed"] / R,
        false=sums["false"] / R,
        num_targets=sums["num_targets"] / R,
        num_tracks=sums["num_tracks"] / R,
        scores=scores,
        scans_overflowed=overflowed,
        births_dropped=dropped,
        num_runs=R,
        cutoff=float(cutoff),
        order=float(order),
    )

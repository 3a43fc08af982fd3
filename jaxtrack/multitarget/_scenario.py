"""Multi-target scenarios: births, deaths, detection probability and Poisson clutter.

A :class:`Scenario` says what to simulate: ``max_targets`` target slots that share one
state-space model and differ by their initial states and their lifetimes, a detection probability,
a Poisson clutter rate and the box in measurement space over which clutter is uniform.
:func:`simulate_scenario` draws one run of truth and scans from a key, :func:`simulate_scenarios`
a batch of runs (run ``i`` from ``jax.random.fold_in(key, i)``, as the single-target Monte Carlo).
With ``truth_states`` the scenario carries one fixed truth, shared by every run; only the
detections, the measurement noise and the clutter are drawn per run. The named scenarios
(:func:`~jaxtrack.multitarget.crossing_targets`, :func:`~jaxtrack.multitarget.williams15`) are
built in :mod:`jaxtrack.multitarget._named_scenarios`.

**A scan is a padded array, a mask and an origin** (``/shared/STYLE-multitarget.md``, point 1): a
:class:`Scan` holds ``max_measurements`` slots; the detections of the targets come first, in
target order, then the clutter points in the order drawn, then padding. ``origin`` labels each slot
with the target index, :data:`CLUTTER` (−1) or :data:`PADDING` (−2). The shapes are static, so a
tracker can be scanned over time and vmapped over runs. When the detections and the clutter
exceed ``max_measurements``, the excess is counted (``num_dropped``, ``overflow``) and reported by
a :class:`CapacityWarning` on the host, never dropped in silence. Clutter is dropped before
target detections (the targets fill the first slots).

**Random streams.** Every random quantity is a function of the run key, the step ``k`` and its
own index only, so a run does not depend on how many steps, targets or slots are simulated around
it (raising ``max_measurements`` keeps the stored clutter and appends the points that were
dropped):

each stream has its own key words, ``W(s, j) = threefry2x32(key, counter=(s, j))``
(:func:`stream_words`), and

- target ``j``'s noise at step ``k``: the ``n + m`` standard normals of the single-target
  simulator, ``step_normals(W(TARGET_STREAM, j), k, n + m)`` (as
  :func:`jaxtrack.montecarlo.simulate_step` draws them): plant noise from the first ``n``,
  measurement noise from the last ``m`` (with a fixed truth the first ``n`` are drawn and not
  used, so the measurement noise is the same numbers as without it);
- target ``j``'s detection at step ``k``: the uniform with Threefry counter ``(k, j)`` under
  ``W(DETECTION_STREAM, 0)``;
- the clutter count at step ``k``: the uniform with counter ``(k, 0)`` under
  ``W(CLUTTER_COUNT_STREAM, 0)``, turned into a Poisson count by inversion
  (:func:`poisson_inverse_cdf`);
- clutter point ``i`` of step ``k``: the ``m`` uniforms with counters ``(k, i·m + c)``, ``c < m``,
  under ``W(CLUTTER_POSITION_STREAM, 0)``.

Keys must use JAX's default Threefry implementation (as for :func:`jaxtrack.montecarlo.simulate`).
"""

from __future__ import annotations

import abc
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray

from .._validation import CapacityWarning, InputError, as_key, check_finite, check_shape, is_concrete
from ..filters._linalg import matmul
from ..models import AbstractStateSpaceModel, at_step
from ..montecarlo._noise import key_words, step_normals, threefry2x32
from ..montecarlo._simulate import noise_factors

__all__ = [
    "CLUTTER",
    "PADDING",
    "AbstractScenario",
    "CapacityWarning",
    "MultiTargetTrajectory",
    "Scan",
    "Scenario",
    "simulate_scenario",
    "simulate_scenarios",
]

CLUTTER = -1
"""``Scan.origin`` of a clutter point."""

PADDING = -2
"""``Scan.origin`` of an empty slot (``valid`` False)."""

# Stream constants, folded into the run key (arbitrary ASCII words: "targ", "dete", "ccnt",
# "cpos"). Each random quantity has its own stream, so adding one (e.g. a detection
# probability) leaves the others' draws unchanged.
TARGET_STREAM = 0x74617267
DETECTION_STREAM = 0x64657465
CLUTTER_COUNT_STREAM = 0x63636E74
CLUTTER_POSITION_STREAM = 0x63706F73


class AbstractScenario(eqx.Module):
    """What a multi-target Monte Carlo simulates: one run of truth and scans from a key.

    :class:`Scenario` (one sensor) and :class:`~jaxtrack.multitarget.TwoSensorScenario` (the same
    targets seen by two sensors) implement it; :func:`~jaxtrack.multitarget.multitarget_monte_carlo`
    takes either and calls :meth:`sample` for run ``i`` with ``fold_in(key, i)``. ``model`` is the
    targets' state-space model (its ``state_layout`` names the positions GOSPA scores);
    ``max_measurements`` the slots of a scan, ``num_steps`` the scans of a run.
    ``scan_sensors`` and ``scan_meas_dim`` say what a scan looks like, as the methods'
    (:attr:`~jaxtrack.multitarget.AbstractMultiTargetFilter.scan_sensors`): the Monte Carlo
    requires the method's and the scenario's to agree.
    """

    model: eqx.AbstractVar[AbstractStateSpaceModel]
    max_measurements: eqx.AbstractVar[int]
    num_steps: eqx.AbstractVar[int]

    @property
    def scan_sensors(self) -> tuple[int, ...]:
        """The axes of a scan before its slots: ``()`` for one sensor."""
        return ()

    @property
    def scan_meas_dim(self) -> int:
        """``m``, the width of a scan's measurement rows."""
        return self.model.meas_dim

    @abc.abstractmethod
    def sample(self, key: PRNGKeyArray):
        """One run from ``key`` (traceable: no host checks, no warnings): a trajectory with fields
        ``states`` ``(T, N, n)``, ``alive`` ``(T, N)`` and ``scans`` (a :class:`Scan` whose arrays
        lead with ``(T, *scan_sensors)``)."""


class Scenario(AbstractScenario):
    """What to simulate: targets with lifetimes, one motion and sensor model, ``P_D`` and clutter.

    Every target moves and is measured through the same state-space model ``model`` (usually a
    :class:`~jaxtrack.models.TrackingModel`): target ``j`` is born at step ``birth_step[j]``
    exactly at ``initial_states[j]``, then follows ``x_k = f_k(x_{k-1}) + w_k``,
    ``w_k ~ N(0, Q_k)`` (``w_k = 0`` with ``process_noise=False``), and is alive for
    ``birth_step[j] <= k < death_step[j]``. An alive target is detected with probability
    ``P_D[k, j]``, independently of the other steps and targets; a detection is
    ``z = h_k(x_k) + v_k``, ``v_k ~ N(0, R_k)`` (the angles are not wrapped, as in
    :func:`jaxtrack.montecarlo.simulate`). Detections are kept wherever they fall, inside the
    clutter region or not. Each scan also holds ``Poisson(clutter_rate)`` clutter points, uniform
    over the box ``clutter_region`` of measurement space (the standard clutter model: Bar-Shalom,
    Willett & Tian 2011, *Tracking and Data Fusion*, §3.4; Mahler 2007, §12.3). The model's prior
    (``initial_mean``, ``initial_cov``) is not used by the simulation; a tracker may use it.

    **A fixed truth.** With ``truth_states`` (``(T, N, n)``) the targets are not moved: every
    run takes its states from ``truth_states`` (the same truth in every run, as in studies that
    draw the trajectories once and redraw only the measurements over the Monte Carlo runs, e.g.
    García-Fernández et al. 2018, Sec. VI). The lifetimes, detections, measurement noise and
    clutter are drawn per run as without it, from the same streams (module docstring), so
    ``truth_states = simulate_scenario(s, key).states`` reproduces that run's scans exactly.

    **Arguments:**

    - ``model``: an :class:`~jaxtrack.models.AbstractStateSpaceModel` with ``n`` states and ``m``
      measurement components (time-invariant, or per step with ``num_steps`` steps).
    - ``initial_states``: ``(N, n)``, each target's state at its birth step, in the model's units
      (``N = max_targets``); ``None`` when ``truth_states`` is given (it is then read from
      ``truth_states`` at the birth steps).
    - ``birth_step``, ``death_step``: ``(N,)`` integers, ``0 <= birth_step < death_step``; the death
      step is exclusive. A slot with ``birth_step >= num_steps`` is never alive (a padded slot).
    - ``detection_probability``: ``P_D`` in ``[0, 1]``, a scalar, one per target ``(N,)`` or one
      per step and target ``(num_steps, N)`` (a fixed design value, not traced).
    - ``clutter_rate``: ``λ``, the mean number of clutter points per scan, ``>= 0``.
    - ``clutter_region``: ``(m, 2)``, the lower and upper bound of each measurement component
      (e.g. ``[[0, 10_000], [-π/4, π/4]]`` for range in m and bearing in rad), lower < upper.
    - ``max_measurements``: the slots of a scan (static int, ``>= 1``).
    - ``num_steps``: ``T``, the steps of a run (static int, ``>= 1``).
    - ``process_noise``: draw the truth with the model's plant noise (default) or move the
      targets with the noise-free transition (static bool; not used with ``truth_states``).
    - ``truth_states``: optional ``(T, N, n)``, concrete and finite, in the model's units: the
      states of every target at every step, used by every run instead of propagating
      ``initial_states``. The entries of a target outside its lifetime are kept as given but never
      measured (read ``alive``). Default ``None``: the truth is drawn per run.

    **Fields:** the arguments, with ``detection_probability`` broadcast to ``(T, N)``, the steps as
    int32 and the floats in the model's dtype; ``initial_states`` is filled from ``truth_states``
    (at step ``min(birth_step, T − 1)``) when that is given.

    **Raises:** ``InputError`` naming the argument for a wrong type, shape or value.
    """

    model: AbstractStateSpaceModel
    initial_states: Float[Array, "N n"]
    birth_step: Int[Array, " N"]
    death_step: Int[Array, " N"]
    detection_probability: Float[Array, "T N"]
    clutter_rate: Float[Array, ""]
    clutter_region: Float[Array, "m 2"]
    truth_states: Float[Array, "T N n"] | None
    max_measurements: int = eqx.field(static=True)
    num_steps: int = eqx.field(static=True)
    process_noise: bool = eqx.field(static=True)

    def __init__(
        self,
        model: AbstractStateSpaceModel,
        initial_states: ArrayLike | None,
        birth_step: ArrayLike,
        death_step: ArrayLike,
        *,
        detection_probability: float | ArrayLike,
        clutter_rate: float | ArrayLike,
        clutter_region: ArrayLike,
        max_measurements: int,
        num_steps: int,
        process_noise: bool = True,
        truth_states: ArrayLike | None = None,
    ):
        if not isinstance(model, AbstractStateSpaceModel):
            raise InputError(f"`model` must be a jaxtrack state-space model (e.g. TrackingModel); got {type(model).__name__}.")
        num_steps = _positive_int("num_steps", num_steps)
        max_measurements = _positive_int("max_measurements", max_measurements)
        if not isinstance(process_noise, (bool, np.bool_)):
            raise InputError(f"`process_noise` must be a bool; got {process_noise!r}.")
        if model.num_steps is not None and model.num_steps != num_steps:
            raise InputError(f"`num_steps` is {num_steps} but the model's per-step arrays have {model.num_steps} steps.")
        model.check_functions()
        dtype = model.initial_mean.dtype
        n, m = model.state_dim, model.meas_dim

        if truth_states is None:
            if initial_states is None:
                raise InputError("`initial_states` is required (shape (N, n)) unless `truth_states` is given.")
            truth = None
            x0 = jnp.asarray(initial_states, dtype)
            check_shape("initial_states", x0, [(None, n)])
            if x0.shape[0] < 1:
                raise InputError("`initial_states` must hold at least one target; got shape (0, n).")
            check_finite("initial_states", x0)
        else:
            if initial_states is not None:
                raise InputError(
                    "`initial_states` must be None when `truth_states` is given (the initial states are "
                    "`truth_states` at the birth steps)."
                )
            truth = _concrete_floats("truth_states", truth_states)
            check_shape("truth_states", truth, [(num_steps, None, n)])
            if truth.shape[1] < 1:
                raise InputError(f"`truth_states` must hold at least one target; got shape {truth.shape}.")
            check_finite("truth_states", truth)
            truth = jnp.asarray(truth, dtype)
            x0 = None
        N = x0.shape[0] if truth is None else truth.shape[1]

        birth = _concrete_steps("birth_step", birth_step, N)
        death = _concrete_steps("death_step", death_step, N)
        if truth is not None:
            x0 = truth[np.minimum(birth, num_steps - 1), np.arange(N)]
        if np.any(birth < 0):
            j = int(np.flatnonzero(birth < 0)[0])
            raise InputError(f"`birth_step` must be >= 0; target {j} has {birth[j]}.")
        if np.any(death <= birth):
            j = int(np.flatnonzero(death <= birth)[0])
            raise InputError(
                f"`death_step` must be greater than `birth_step` (the death step is exclusive); target {j} has "
                f"birth_step {birth[j]} and death_step {death[j]}."
            )

        pd = _concrete_floats("detection_probability", detection_probability)
        if pd.shape not in ((), (N,), (num_steps, N)):
            raise InputError(
                f"`detection_probability` must be a scalar or have shape ({N},) (per target) or ({num_steps}, {N}) "
                f"(per step and target); got shape {pd.shape}."
            )
        if not np.all((pd >= 0.0) & (pd <= 1.0)):
            raise InputError(f"`detection_probability` must lie in [0, 1]; got values in [{np.min(pd)}, {np.max(pd)}].")

        rate = _concrete_floats("clutter_rate", clutter_rate)
        if rate.shape != ():
            raise InputError(f"`clutter_rate` must be a scalar (mean clutter points per scan); got shape {rate.shape}.")
        if not (np.isfinite(rate) and rate >= 0.0):
            raise InputError(f"`clutter_rate` must be finite and >= 0; got {float(rate)}.")

        region = _concrete_floats("clutter_region", clutter_region)
        check_shape("clutter_region", region, [(m, 2)])
        check_finite("clutter_region", region)
        if np.any(region[:, 0] >= region[:, 1]):
            i = int(np.flatnonzero(region[:, 0] >= region[:, 1])[0])
            raise InputError(
                f"`clutter_region` must have lower < upper in every measurement component; component {i} "
                f"has [{region[i, 0]}, {region[i, 1]}]."
            )

        self.model = model
        self.initial_states = x0
        self.birth_step = jnp.asarray(birth, jnp.int32)
        self.death_step = jnp.asarray(death, jnp.int32)
        self.detection_probability = jnp.asarray(np.broadcast_to(pd, (num_steps, N)), dtype)
        self.clutter_rate = jnp.asarray(rate, dtype)
        self.clutter_region = jnp.asarray(region, dtype)
        self.truth_states = truth
        self.max_measurements = max_measurements
        self.num_steps = num_steps
        self.process_noise = bool(process_noise)

    @property
    def max_targets(self) -> int:
        """``N``, the number of target slots."""
        return self.initial_states.shape[0]

    def sample(self, key: PRNGKeyArray) -> MultiTargetTrajectory:
        """One run from ``key``: :func:`simulate_scenario` without its checks and warning (traceable)."""
        return _simulate_one(self, key)

    @property
    def clutter_volume(self) -> Float[Array, ""]:
        """``V``: the clutter region's measure in measurement space (the product of its widths,
        e.g. m² or m·rad)."""
        widths = self.clutter_region[:, 1] - self.clutter_region[:, 0]
        return jnp.prod(widths)

    @property
    def clutter_spatial_density(self) -> Float[Array, ""]:
        """Stone Soup's name of :attr:`clutter_density` (``λ / V``)."""
        return self.clutter_density

    @property
    def clutter_density(self) -> Float[Array, ""]:
        """``λ / V``: the clutter's spatial density, per unit volume of measurement space (the
        product of the region's widths, e.g. m·rad)."""
        widths = self.clutter_region[:, 1] - self.clutter_region[:, 0]
        return self.clutter_rate / jnp.prod(widths)


class Scan(eqx.Module):
    """The measurements of one step, padded to ``max_measurements`` slots ``M``.

    With a leading axis (``(T, M, m)`` …) it is every step of a run, as in
    :attr:`MultiTargetTrajectory.scans`.

    **Fields:**

    - ``measurements``: ``(M, m)``, in the model's measurement units; target detections first (in
      target order), then clutter (in the order drawn), then padding (zeros).
    - ``valid``: ``(M,)`` bool, True for a detection or a clutter point.
    - ``origin``: ``(M,)`` int32, the index of the target that made the measurement, :data:`CLUTTER`
      (−1) or :data:`PADDING` (−2).
    - ``num_clutter``: ``()`` int32, the clutter points drawn (stored or not; the Poisson count).
    - ``num_dropped``: ``()`` int32, detections plus clutter points beyond ``M``, not stored.
    - ``overflow``: ``()`` bool, ``num_dropped > 0``.
    """

    measurements: Float[Array, "*T M m"]
    valid: Bool[Array, "*T M"]
    origin: Int[Array, "*T M"]
    num_clutter: Int[Array, "*T"]
    num_dropped: Int[Array, "*T"]
    overflow: Bool[Array, "*T"]


class MultiTargetTrajectory(eqx.Module):
    """One simulated run of a :class:`Scenario` (with a leading run axis from :func:`simulate_scenarios`).

    **Fields:**

    - ``states``: ``(T, N, n)``, each target's state, in the model's units. Before its birth a slot
      holds its initial state, after its death its last state (with the scenario's
      ``truth_states``: those states, as given); read ``alive``.
    - ``alive``: ``(T, N)`` bool, ``birth_step <= k < death_step``.
    - ``detected``: ``(T, N)`` bool, alive and detected (never True for a target not alive).
    - ``target_measurements``: ``(T, N, m)``, ``h_k(x_k) + v_k`` drawn for every target and step,
      detected or not (a detected target's is the one in its scan).
    - ``scans``: a :class:`Scan` with a leading ``T`` axis.
    - ``overflow``: ``()`` bool, any scan overflowed.
    """

    states: Float[Array, "*R T N n"]
    alive: Bool[Array, "*R T N"]
    detected: Bool[Array, "*R T N"]
    target_measurements: Float[Array, "*R T N m"]
    scans: Scan
    overflow: Bool[Array, "*R"]


def simulate_scenario(scenario: Scenario, key: PRNGKeyArray | int) -> MultiTargetTrajectory:
    """Simulate one run of a scenario: the truth of every target and the padded scans.

    One ``lax.scan`` over the steps moves and measures all targets (the model's ``transition``
    and ``measurement`` vmapped over targets); the detection, clutter-count and clutter-position
    draws are made for all steps at once, each from its own stream (module docstring), and the
    scans assembled per step. Jitted (``eqx.filter_jit``): a second call with a scenario of the same
    shapes does not recompile.

    **Arguments:**

    - ``scenario``: a :class:`Scenario`.
    - ``key``: the run's PRNG key (Threefry) or an int seed.

    **Returns:** a :class:`MultiTargetTrajectory`.

    **Warns:** :class:`CapacityWarning` when a scan held more than ``max_measurements``
    measurements (called outside ``jit``; under tracing read ``overflow``).

    **Raises:** ``InputError`` for a ``scenario`` that is not a :class:`Scenario` or a bad ``key``.
    """
    _check_scenario(scenario)
    out = _simulate_jit(scenario, as_key(key))
    _warn_on_overflow(out, scenario.max_measurements)
    return out


def simulate_scenarios(scenario: Scenario, key: PRNGKeyArray | int, num_runs: int) -> MultiTargetTrajectory:
    """Simulate ``num_runs`` independent runs of a scenario, run ``i`` from ``fold_in(key, i)``.

    Run ``i`` equals ``simulate_scenario(scenario, jax.random.fold_in(key, i))`` (the same run
    primitive, ``jax.vmap``-ed over the runs and jitted once).

    **Arguments:**

    - ``scenario``: a :class:`Scenario`.
    - ``key``: the PRNG key (Threefry) or an int seed.
    - ``num_runs``: the number of runs ``R`` (static int, ``>= 1``).

    **Returns:** a :class:`MultiTargetTrajectory` whose arrays have a leading ``R`` axis.

    **Warns:** :class:`CapacityWarning` naming ``max_measurements``, the number of scans that
    overflowed and the largest number of measurements seen in a scan (outside ``jit``).

    **Raises:** ``InputError`` for a bad ``scenario``, ``key`` or ``num_runs``.
    """
    _check_scenario(scenario)
    num_runs = _positive_int("num_runs", num_runs)
    out = _simulate_runs_jit(scenario, as_key(key), num_runs)
    _warn_on_overflow(out, scenario.max_measurements)
    return out


@eqx.filter_jit
def _simulate_jit(scenario: Scenario, key) -> MultiTargetTrajectory:
    return _simulate_one(scenario, key)


@eqx.filter_jit
def _simulate_runs_jit(scenario: Scenario, key, num_runs: int) -> MultiTargetTrajectory:
    runs = jnp.arange(num_runs, dtype=jnp.uint32)
    return jax.vmap(lambda i: _simulate_one(scenario, jax.random.fold_in(key, i)))(runs)


def _simulate_one(scenario: Scenario, key, truth_states=None) -> MultiTargetTrajectory:
    """One run. ``truth_states`` ``(T, N, n)`` (possibly traced) replaces the scenario's truth: the
    targets another sensor's run drew (:class:`~jaxtrack.multitarget.TwoSensorScenario`)."""
    model = scenario.model
    truth_states = scenario.truth_states if truth_states is None else truth_states
    T, N, M = scenario.num_steps, scenario.max_targets, scenario.max_measurements
    n, m = model.state_dim, model.meas_dim
    dtype = scenario.initial_states.dtype
    factors = noise_factors(model, T)
    targets = jnp.arange(N, dtype=jnp.uint32)
    steps = jnp.arange(T)
    # (N, 2) key words: step_normals then draws every target's numbers in one fused hash.
    words = stream_words(key, TARGET_STREAM, targets)

    def step(x_prev, k):
        eps = step_normals(words, k, n + m, dtype)  # (n + m, N): targets on the trailing axis
        if truth_states is not None:
            x = truth_states[k]  # the fixed truth; eps[:n] is drawn and not used
        else:
            moved = jax.vmap(model.transition, in_axes=(0, None))(x_prev, k)
            if scenario.process_noise:
                moved = moved + matmul(at_step(factors.process, k, 2), eps[:n]).T
            # Born exactly at the given state; frozen after death (the slot keeps its last state).
            x = jnp.where((k <= scenario.birth_step)[:, None], scenario.initial_states,
                          jnp.where((k >= scenario.death_step)[:, None], x_prev, moved))
        z = jax.vmap(model.measurement, in_axes=(0, None))(x, k) + matmul(at_step(factors.measurement, k, 2), eps[n:]).T
        return x, (x, z)

    _, (states, target_z) = jax.lax.scan(step, scenario.initial_states, steps)

    alive = (steps[:, None] >= scenario.birth_step[None, :]) & (steps[:, None] < scenario.death_step[None, :])
    # u ∈ [0, 1): P(u < P_D) = P_D; P_D = 0 never detects, P_D = 1 always does.
    u = _uniforms(stream_words(key, DETECTION_STREAM), T, N, dtype)
    detected = alive & (u < scenario.detection_probability)
    count_u = _uniforms(stream_words(key, CLUTTER_COUNT_STREAM), T, 1, dtype)[:, 0]
    num_clutter = poisson_inverse_cdf(count_u, scenario.clutter_rate)
    lower, upper = scenario.clutter_region[:, 0], scenario.clutter_region[:, 1]
    # At most M clutter points of a step can be stored, so only the first M are drawn; point i
    # of step k uses the counters (k, i·m + c), c < m.
    unit = _uniforms(stream_words(key, CLUTTER_POSITION_STREAM), T, M * m, dtype).reshape(T, M, m)
    clutter = lower[None, None, :] + (upper - lower)[None, None, :] * unit  # (T, M, m)

    scans = jax.vmap(lambda z, d, c, pts: _assemble_scan(z, d, c, pts, M))(target_z, detected, num_clutter, clutter)
    return MultiTargetTrajectory(states, alive, detected, target_z, scans, jnp.any(scans.overflow))


def stream_words(key: PRNGKeyArray, stream: int, index=0) -> Array:
    """The ``uint32`` key words of sub-stream ``index`` of the run's stream ``stream``.

    ``threefry2x32(key, counter=(stream, index))``: one hash (cheaper to compile than
    ``jax.random.fold_in`` twice, which lowers a rolled Threefry loop per call).

    **Arguments:** ``key``: the run's Threefry key; ``stream``: a stream constant (e.g.
    :data:`TARGET_STREAM`); ``index``: an int or uint32 array ``(*B)`` (e.g. the target indices).

    **Returns:** the key words, ``uint32`` ``(*B, 2)``, for :func:`~jaxtrack.montecarlo._noise.step_normals`
    or :func:`_uniforms`.
    """
    words = key_words(key)
    index = jnp.asarray(index).astype(jnp.uint32)
    hi, lo = threefry2x32(words[0], words[1], jnp.full(index.shape, stream, jnp.uint32), index)
    return jnp.stack([hi, lo], axis=-1)


def _uniforms(words: Array, rows: int, cols: int, dtype) -> Array:
    """Uniforms on ``[0, 1)``, ``(rows, cols)``: entry ``(k, j)`` from the Threefry counter ``(k, j)``.

    One unrolled Threefry-2x32 hash per number (:func:`jaxtrack.montecarlo._noise.threefry2x32`),
    so entry ``(k, j)`` depends on the stream's key and ``(k, j)`` only, and the hash fuses into
    one element-wise loop over all runs (``jax.random.uniform`` under nested ``vmap``/``fold_in``
    compiles a rolled loop per call, several times slower to compile here). Float64 takes the top
    52 bits of the 64-bit output, as ``jax.random.uniform`` does; float32 the top 23 of ``hi``.
    """
    shape = (rows, cols)
    step = jax.lax.broadcasted_iota(jnp.uint32, shape, 0)
    counter = jax.lax.broadcasted_iota(jnp.uint32, shape, 1)
    hi, lo = threefry2x32(jnp.broadcast_to(words[0], shape), jnp.broadcast_to(words[1], shape), step, counter)
    dtype = jnp.dtype(dtype)
    if dtype.itemsize == 8:
        bits = (hi.astype(jnp.uint64) << np.uint64(32)) | lo.astype(jnp.uint64)
        one = np.array(1.0, np.float64).view(np.uint64)
        return jax.lax.bitcast_convert_type((bits >> np.uint64(12)) | one, jnp.float64) - 1.0
    one = np.array(1.0, np.float32).view(np.uint32)
    return (jax.lax.bitcast_convert_type((hi >> np.uint32(9)) | one, jnp.float32) - 1.0).astype(dtype)


def poisson_inverse_cdf(u: Float[Array, "*B"], rate: Float[ArrayLike, ""]) -> Int[Array, "*B"]:
    """``Poisson(rate)`` draws by inversion: the least ``c`` with ``F(c) > u``, for ``u ~ U[0, 1)``.

    Sequential search from 0 (Devroye 1986, *Non-Uniform Random Variate Generation*, §X.3.3),
    in log space so that ``e^{−λ}`` never underflows (any finite ``λ ≥ 0``): ``log p_0 = −λ``,
    ``log p_c = log p_{c−1} + log(λ / c)``, ``log F_c = logaddexp(log F_{c−1}, log p_c)``. The
    loop runs ``max c + 1`` times over the batch (about ``λ + 6√λ`` for a batch of thousands);
    a ``u`` so close to 1 that ``F`` rounds below it stops once ``p_c`` is negligible
    (``log p_c < −745`` beyond the mean). Exact up to the rounding of ``F`` (relative ~1e-15);
    no count is capped.

    **Arguments:** ``u``: uniforms on ``[0, 1)``, any shape; ``rate``: ``λ >= 0``, a scalar.

    **Returns:** int32 counts, ``u``'s shape.
    """
    rate = jnp.asarray(rate, u.dtype)
    log_u = jnp.log(u)
    log_rate = jnp.log(rate)  # −inf at λ = 0: then p_c = 0 for c ≥ 1 and F_0 = 1 > u

    def searching(state):
        c, log_p, log_f = state
        return jnp.any((log_u >= log_f) & ((c < rate) | (log_p > -745.0)))

    def step(state):
        c, log_p, log_f = state
        go = (log_u >= log_f) & ((c < rate) | (log_p > -745.0))
        c_next = c + 1
        log_p_next = log_p + log_rate - jnp.log(c_next.astype(u.dtype))
        return (jnp.where(go, c_next, c), jnp.where(go, log_p_next, log_p),
                jnp.where(go, jnp.logaddexp(log_f, log_p_next), log_f))

    zero = jnp.zeros(u.shape, jnp.int32)
    start = jnp.broadcast_to(-rate, u.shape)
    c, _, _ = jax.lax.while_loop(searching, step, (zero, start, start))
    return c


def _assemble_scan(target_z, detected, num_clutter, clutter, max_measurements: int) -> Scan:
    """Fill the ``M`` slots of one step: detections in target order, then clutter, then padding."""
    M = max_measurements
    slots = jnp.arange(M, dtype=jnp.int32)
    num_detected = jnp.sum(detected, dtype=jnp.int32)
    # The first M detected targets in index order (the fill value is never read: those slots
    # are not detections).
    (who,) = jnp.nonzero(detected, size=M, fill_value=0)
    is_target = slots < num_detected
    is_clutter = ~is_target & (slots < num_detected + num_clutter)
    clutter_index = jnp.clip(slots - num_detected, 0, M - 1)
    z = jnp.where(is_target[:, None], target_z[who],
                  jnp.where(is_clutter[:, None], clutter[clutter_index], jnp.zeros_like(clutter)))
    origin = jnp.where(is_target, who.astype(jnp.int32), jnp.where(is_clutter, CLUTTER, PADDING)).astype(jnp.int32)
    num_dropped = jnp.maximum(num_detected + num_clutter - M, 0).astype(jnp.int32)
    return Scan(z, is_target | is_clutter, origin, num_clutter, num_dropped, num_dropped > 0)


def _warn_on_overflow(out: MultiTargetTrajectory, max_measurements: int) -> None:
    """Host side of the capacity rule: a :class:`CapacityWarning` if any scan overflowed."""
    if not is_concrete(out.overflow) or not bool(np.any(np.asarray(out.overflow))):
        return
    scans = out.scans
    overflowed = np.asarray(scans.overflow)
    counts = np.sum(np.asarray(scans.valid), axis=-1) + np.asarray(scans.num_dropped)
    warnings.warn(
        f"{int(overflowed.sum())} of {overflowed.size} scans held more measurements than "
        f"max_measurements={max_measurements} (largest count seen: {int(counts.max())}); the excess "
        f"({int(np.asarray(scans.num_dropped).sum())} measurements, clutter first) was not stored. "
        f"Read `scans.num_dropped`, or raise `max_measurements`.",
        CapacityWarning,
        stacklevel=3,
    )


# ---------------------------------------------------------------------------------------------
# host-side checks


def _positive_int(name: str, value) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < 1:
        raise InputError(f"`{name}` must be a positive int; got {value!r}.")
    return int(value)


def _concrete_floats(name: str, value) -> np.ndarray:
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError) as err:
        raise InputError(
            f"`{name}` must be a concrete number or array of numbers (a fixed design value, not a traced one); "
            f"got {type(value).__name__}."
        ) from err


def _concrete_steps(name: str, value, num_targets: int) -> np.ndarray:
    try:
        arr = np.asarray(value)
    except (TypeError, jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError) as err:
        raise InputError(f"`{name}` must be concrete integers (step indices); got {type(value).__name__}.") from err
    if not np.issubdtype(arr.dtype, np.integer):
        raise InputError(f"`{name}` must be integers (step indices); got dtype {arr.dtype}.")
    check_shape(name, arr, [(num_targets,)])
    return arr.astype(np.int64)


def _check_scenario(scenario) -> None:
    if not isinstance(scenario, Scenario):
        raise InputError(f"`scenario` must be a jaxtrack.multitarget.Scenario; got {type(scenario).__name__}.")

"""The named multi-target scenarios: :func:`crossing_targets`, :func:`williams15` and :func:`vo_vo_linear`.

- :func:`crossing_targets`: the library's own test scenario, targets crossing in front of a
  range–bearing radar, the truth drawn per run;
- :func:`williams15`: the linear-Gaussian coalescence scenario of Williams (2015) as García-Fernández's
  MATLAB reference of the PMBM filter defines it, with one truth fixed over the Monte Carlo runs
  (``Scenario(truth_states=...)``), and the filter and metric settings of that reference
  (:class:`Williams15Settings`);
- :func:`vo_vo_linear`: the linear benchmark of the labelled-RFS papers of B.-T. Vo and B.-N. Vo
  (12 noise-free tracks, at most 10 at once, in a 2 km square with 66 clutter points a scan), with
  its LMB birth and filter settings (:class:`VoVoLinearSettings`).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from .._validation import InputError, as_key
from ..models import ConstantVelocity, LinearGaussianModel, RangeBearing, TrackingModel, constant_velocity
from ._mixture import GaussianMixture
from ._scenario import Scenario, _positive_int

__all__ = ["VoVoLinearSettings", "Williams15Settings", "crossing_targets", "vo_vo_linear", "williams15"]

# The Williams (2015) scenario of the MATLAB reference (ScenarioWilliams15.m, Scenario_number = 1),
# converted to jaxtrack's state layout [x, y, vx, vy] (the reference's is [x, vx, y, vy]).
WILLIAMS15_NUM_TARGETS = 4
WILLIAMS15_NUM_STEPS = 81  # Nsteps (odd: the truth starts from the midpoint step)
WILLIAMS15_SAMPLE_PERIOD = 1.0  # T, s
WILLIAMS15_ACCEL_PSD = 0.01  # Q = 0.01·[[T³/3, T²/2], [T²/2, T]] per axis, m²/s³
WILLIAMS15_MEASUREMENT_STD = 1.0  # R = I₂ m²
WILLIAMS15_AREA = 300.0  # clutter over [0, 300] × [0, 300] m
WILLIAMS15_MIDPOINT_MEAN = (150.0, 150.0, 0.0, 0.0)  # [Area/2, Area/2, 0, 0]: m, m, m/s, m/s
WILLIAMS15_MIDPOINT_VAR = 0.1  # Pmid = 0.1·I₄ (m², m²/s²)
WILLIAMS15_DEATH_STEP_0 = 40  # 0-indexed, exclusive: target 0 alive at steps 0..39 (t_death = 41)


class Williams15Settings(eqx.Module):
    """The filter and metric settings of the MATLAB reference's Williams (2015) scenario.

    What a filter (GM-PHD, CPHD, PMBM, …) and the study need beside the :class:`Scenario`,
    from ``ScenarioWilliams15.m`` of García-Fernández's PMBM reference (GitHub
    ``Agarciafernandez/MTT``, folder ``PMBM filter``), in jaxtrack's state layout
    ``[x, y, vx, vy]`` (m, m, m/s, m/s; the reference's is ``[x, vx, y, vy]``).

    **Fields:**

    - ``prob_survival``: ``P_S = 0.99``, ``()``.
    - ``prob_detect``: ``P_D = 0.9``, ``()`` (as the scenario's ``detection_probability``).
    - ``clutter_rate``: ``λ = 10`` clutter points per scan, ``()``; ``clutter_density``:
      ``λ / 300² = 10/90000`` per m², ``()`` (as ``Scenario.clutter_density``).
    - ``birth_weights``, ``birth_means``, ``birth_covs``: the Poisson birth intensity per step,
      one Gaussian component: ``(1,)`` weight 0.005; ``(1, 4)`` mean ``[100, 100, 0, 0]``;
      ``(1, 4, 4)`` covariance ``diag([150², 150², 1, 1])`` (m², m², m²/s², m²/s²).
    - ``initial_weights``, ``initial_means``, ``initial_covs``: the Poisson intensity at time 0
      (before the first scan), ``λ0 = 3`` times the same Gaussian: ``(1,)``, ``(1, 4)``, ``(1, 4, 4)``.
    - ``gospa_cutoff``: GOSPA's ``c = 10`` m; ``gospa_order``: ``p = 2``; ``gospa_alpha``:
      ``α = 2`` (static floats).
    - ``num_runs``: 100 Monte Carlo runs (static int).
    """

    prob_survival: Float[Array, ""]
    prob_detect: Float[Array, ""]
    clutter_rate: Float[Array, ""]
    clutter_density: Float[Array, ""]
    birth_weights: Float[Array, " J"]
    birth_means: Float[Array, "J n"]
    birth_covs: Float[Array, "J n n"]
    initial_weights: Float[Array, " J0"]
    initial_means: Float[Array, "J0 n"]
    initial_covs: Float[Array, "J0 n n"]
    gospa_cutoff: float = eqx.field(static=True)
    gospa_order: float = eqx.field(static=True)
    gospa_alpha: float = eqx.field(static=True)
    num_runs: int = eqx.field(static=True)

    @property
    def birth(self) -> GaussianMixture:
        """The birth intensity as the filters take it (``birth=``)."""
        return GaussianMixture(self.birth_weights, self.birth_means, self.birth_covs)

    @property
    def initial(self) -> GaussianMixture:
        """The time-0 intensity as the filters take it (``initial=``)."""
        return GaussianMixture(self.initial_weights, self.initial_means, self.initial_covs)


def williams15(key: PRNGKeyArray | int = 0, *, max_measurements: int = 40) -> tuple[Scenario, Williams15Settings]:
    """The Williams (2015) coalescence scenario, as the MATLAB reference of the PMBM filter defines it.

    Four targets move with nearly constant velocity in the plane and pass close to each other in
    the middle of the run, where they are hard to tell apart (Williams 2015, "Marginal
    multi-Bernoulli filters: RFS derivation of MHT, JIPDA and association-based MeMBer", IEEE
    TAES 51(3), Sec. VI; García-Fernández, Williams, Granström & Svensson 2018, "Poisson
    multi-Bernoulli mixture filter: direct derivation and implementation", IEEE TAES 54(4),
    Sec. VI). The numbers are those of García-Fernández's MATLAB reference (GitHub
    ``Agarciafernandez/MTT``, folder ``PMBM filter``: ``ScenarioWilliams15.m`` with
    ``Scenario_number = 1``, ``TrajectoryWilliams15.m``, ``CreateMeasurement.m``):

    - ``T = 81`` steps, sampling period 1 s; state ``[x, y, vx, vy]`` (m, m/s) — jaxtrack's
      layout (``docs/conventions.md``); the reference orders it ``[x, vx, y, vy]`` and every
      number below is converted. ``F = [[I₂, I₂], [0, I₂]]``,
      ``Q = 0.01·[[1/3, 1/2], [1/2, 1]] ⊗ I₂`` (:func:`~jaxtrack.models.constant_velocity` with
      ``accel_psd = 0.01`` m²/s³); ``z = [x, y] + v``, ``R = I₂`` m².
    - ``P_D = 0.9``; clutter ``Poisson(10)`` per scan, uniform over ``[0, 300] × [0, 300]`` m
      (density ``10/90000`` per m²).
    - The truth, drawn once from ``key`` and fixed over the runs (only the detections,
      measurement noise and clutter are drawn per run; ``Scenario.truth_states``): at the midpoint
      step 40 (0-indexed; 41 in the reference) every target's state is
      ``x_40 ~ N([150, 150, 0, 0], 0.1·I₄)``, independently; then forward
      ``x_{k+1} = F x_k + w_k`` and backward ``x_{k−1} = F⁻¹ (x_k + w_k)``, ``w_k ~ N(0, Q)``
      independent. Every target is alive from step 0; target 0 dies at step 40 (alive at
      0-indexed steps 0..39; ``t_death = 41`` in the reference), the others live to step 80. The
      states of target 0 after its death are the forward recursion's (never measured; the
      reference sets them to zero).

    The truth is a pure JAX function of the key (``jax.random.split(key, 3)`` for the midpoint,
    forward and backward draws), so the same key gives the same scenario.

    **Arguments:**

    - ``key``: the PRNG key (Threefry) or an int seed of the truth; default 0.
    - ``max_measurements``: the slots of a scan (static int); default 40. A scan holds
      ``Poisson(10)`` clutter points plus ``Binomial(≤ 4, 0.9)`` detections: more than 40 with
      probability 3.3e-11 per scan (2.7e-7 over the reference's 100 runs of 81 scans; 5.8e-7 per
      scan for more than 32). An overflow is counted and warned about
      (:class:`~jaxtrack.multitarget.CapacityWarning`), as for any :class:`Scenario`.

    **Returns:** ``(scenario, settings)``: the :class:`Scenario` (``N = 4`` targets, ``n = 4``,
    ``m = 2``, ``truth_states`` ``(81, 4, 4)``; its model's prior is the birth component) and the
    reference's filter and metric settings (:class:`Williams15Settings`).

    **Raises:** ``InputError`` for a bad ``key`` or ``max_measurements``.
    """
    key = as_key(key)
    max_measurements = _positive_int("max_measurements", max_measurements)
    birth_mean = np.array([100.0, 100.0, 0.0, 0.0])
    birth_cov = np.diag([150.0**2, 150.0**2, 1.0, 1.0])
    model = constant_velocity(
        WILLIAMS15_SAMPLE_PERIOD, dim=2, accel_psd=WILLIAMS15_ACCEL_PSD,
        measurement_std=WILLIAMS15_MEASUREMENT_STD, initial_mean=birth_mean, initial_cov=birth_cov,
    )
    dtype = model.initial_mean.dtype
    N, T = WILLIAMS15_NUM_TARGETS, WILLIAMS15_NUM_STEPS
    truth = _midpoint_truth(
        key, model.F, model.Q, jnp.asarray(WILLIAMS15_MIDPOINT_MEAN, dtype),
        WILLIAMS15_MIDPOINT_VAR * jnp.eye(4, dtype=dtype), num_targets=N, num_steps=T,
    )
    death = np.full(N, T, np.int64)
    death[0] = WILLIAMS15_DEATH_STEP_0
    scenario = Scenario(
        model, None, np.zeros(N, np.int64), death,
        detection_probability=0.9,
        clutter_rate=10.0,
        clutter_region=np.array([[0.0, WILLIAMS15_AREA], [0.0, WILLIAMS15_AREA]]),
        max_measurements=max_measurements,
        num_steps=T,
        truth_states=truth,
    )
    settings = Williams15Settings(
        prob_survival=jnp.asarray(0.99, dtype),
        prob_detect=jnp.asarray(0.9, dtype),
        clutter_rate=jnp.asarray(10.0, dtype),
        clutter_density=jnp.asarray(10.0 / WILLIAMS15_AREA**2, dtype),
        birth_weights=jnp.asarray([0.005], dtype),
        birth_means=jnp.asarray(birth_mean[None], dtype),
        birth_covs=jnp.asarray(birth_cov[None], dtype),
        initial_weights=jnp.asarray([3.0], dtype),
        initial_means=jnp.asarray(birth_mean[None], dtype),
        initial_covs=jnp.asarray(birth_cov[None], dtype),
        gospa_cutoff=10.0,
        gospa_order=2.0,
        gospa_alpha=2.0,
        num_runs=100,
    )
    return scenario, settings


@eqx.filter_jit
def _midpoint_truth(
    key: PRNGKeyArray,
    F: Float[Array, "n n"],
    Q: Float[Array, "n n"],
    midpoint_mean: Float[Array, " n"],
    midpoint_cov: Float[Array, "n n"],
    *,
    num_targets: int,
    num_steps: int,
) -> Float[Array, "T N n"]:
    """Trajectories drawn from the midpoint outwards (``TrajectoryWilliams15.m``).

    With ``h = (T − 1) / 2`` (``T`` odd): ``x_h ~ N(midpoint_mean, midpoint_cov)`` per target, then
    ``x_{k+1} = F x_k + w_k`` for ``k = h, …, T − 2`` and ``x_{k−1} = F⁻¹ (x_k + w'_k)`` for
    ``k = h, …, 1``, every ``w ~ N(0, Q)`` independent. ``jax.random.split(key, 3)`` gives the
    midpoint, forward and backward keys. ``Q`` positive definite (a Cholesky factor).

    **Returns:** ``(T, N, n)``, in the units of ``midpoint_mean``.
    """
    n = F.shape[0]
    half = (num_steps - 1) // 2
    dtype = midpoint_mean.dtype
    k_mid, k_fwd, k_bwd = jax.random.split(key, 3)
    mid_factor = jnp.linalg.cholesky(midpoint_cov)
    x_mid = midpoint_mean[None, :] + jax.random.normal(k_mid, (num_targets, n), dtype) @ mid_factor.T
    L = jnp.linalg.cholesky(Q)
    w_fwd = jax.random.normal(k_fwd, (half, num_targets, n), dtype) @ L.T
    w_bwd = jax.random.normal(k_bwd, (half, num_targets, n), dtype) @ L.T

    def forward(x, w):
        x = x @ F.T + w
        return x, x

    def backward(x, w):
        x = jnp.linalg.solve(F, (x + w).T).T
        return x, x

    _, after = jax.lax.scan(forward, x_mid, w_fwd)  # steps h + 1, …, T − 1
    _, before = jax.lax.scan(backward, x_mid, w_bwd)  # steps h − 1, …, 0
    return jnp.concatenate([before[::-1], x_mid[None], after], axis=0)


def crossing_targets(
    num_targets: int = 4,
    num_steps: int = 100,
    sample_period: float = 1.0,
    *,
    centre_range: float = 5_000.0,
    speed: float = 20.0,
    miss_distance: float = 50.0,
    noise_intensity: float = 0.01,
    noise_std: tuple[float, float] = (10.0, 0.002),
    detection_probability: float = 0.9,
    clutter_rate: float = 10.0,
    max_measurements: int | None = None,
    staggered: bool = True,
) -> Scenario:
    """The standard test scenario: targets crossing near the centre of a range–bearing radar's field.

    A 2-D radar at the origin (:class:`~jaxtrack.models.RangeBearing`, ``z = [r, φ]``, bearing
    counter-clockwise from +x) watches the sector ``r ∈ [0, 2·centre_range]``,
    ``φ ∈ [−π/4, π/4]``. Target ``j`` of ``N`` moves with nearly constant velocity
    (:class:`~jaxtrack.models.ConstantVelocity`, state ``[x, y, vx, vy]``) at ``speed`` along the
    heading ``π j / N``, on a line passing the field's centre ``(centre_range, 0)`` at the signed
    perpendicular offset ``miss_distance·(j/(N−1) − 1/2)``; without plant noise it passes the
    closest point at step ``num_steps/2``, so every pair of paths crosses near the centre around
    the middle of the run. With ``staggered`` (default) the births are spread over the first fifth
    of the run and the deaths over the last fifth (``birth_j = ⌊0.2 T j / N⌋``,
    ``death_j = T − birth_j``); otherwise every target lives for the whole run. ``P_D`` is the same
    for every target and step; clutter is ``Poisson(clutter_rate)`` per scan, uniform over the
    sector in range and bearing.

    **Arguments:**

    - ``num_targets``: ``N``; ``num_steps``: ``T``; ``sample_period``: τ, seconds (> 0).
    - ``centre_range``: m; ``speed``: m/s; ``miss_distance``: m.
    - ``noise_intensity``: the CV model's ``q``, m²/s³; ``noise_std``: ``(σ_r, σ_φ)``, m and rad.
    - ``detection_probability``, ``clutter_rate``: ``P_D`` and ``λ`` (defaults 0.9 and 10).
    - ``max_measurements``: the scan's slots; default ``N + ⌈λ + 8√λ⌉ + 8``, for which an
      overflow has probability below 1e-14 per scan (the clutter alone exceeds it with
      probability 5e-16 at λ = 10, at most 2e-15 for 0 < λ ≤ 1000).
    - ``staggered``: stagger the births and deaths (default True).

    **Returns:** a :class:`Scenario`. Its model's prior (mean at the centre, standard deviations
    1 km and ``2·speed``) is a broad birth prior for a tracker; the simulation does not use it.

    **Raises:** ``InputError`` naming the argument for a non-positive count, period or range.
    """
    num_targets = _positive_int("num_targets", num_targets)
    num_steps = _positive_int("num_steps", num_steps)
    for name, value in (("sample_period", sample_period), ("centre_range", centre_range), ("speed", speed)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise InputError(f"`{name}` must be a positive finite number; got {value!r}.")
    if max_measurements is None:
        max_measurements = num_targets + math.ceil(clutter_rate + 8.0 * math.sqrt(max(clutter_rate, 0.0))) + 8
    tau = float(sample_period)
    model = TrackingModel(
        ConstantVelocity(tau, noise_intensity=noise_intensity, dim=2),
        RangeBearing(noise_std=noise_std, sensor_position=(0.0, 0.0)),
        initial_mean=np.array([centre_range, 0.0, 0.0, 0.0]),
        initial_cov=np.diag([1e3**2, 1e3**2, (2 * speed) ** 2, (2 * speed) ** 2]),
    )
    j = np.arange(num_targets)
    if staggered:
        birth = np.floor(0.2 * num_steps * j / num_targets).astype(np.int64)
        death = num_steps - birth
    else:
        birth = np.zeros(num_targets, np.int64)
        death = np.full(num_targets, num_steps, np.int64)
    heading = np.pi * j / num_targets
    direction = np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    normal = np.stack([-np.sin(heading), np.cos(heading)], axis=-1)
    offset = miss_distance * (j / max(num_targets - 1, 1) - 0.5) if num_targets > 1 else np.zeros(1)
    # Position at birth: back along the heading by the distance flown until the middle step.
    centre = np.array([centre_range, 0.0])
    back = speed * tau * (0.5 * num_steps - birth)
    position = centre + offset[:, None] * normal - back[:, None] * direction
    initial_states = np.concatenate([position, speed * direction], axis=-1)
    return Scenario(
        model, initial_states, birth, death,
        detection_probability=detection_probability,
        clutter_rate=clutter_rate,
        clutter_region=np.array([[0.0, 2.0 * centre_range], [-np.pi / 4, np.pi / 4]]),
        max_measurements=max_measurements,
        num_steps=num_steps,
    )


# Vo & Vo's linear benchmark: the numbers of the labelled-RFS toolbox's gen_model.m / gen_truth.m
# (B.-T. Vo's MATLAB code, folders glmb/gms and jointglmb/gms), MATLAB's state [x; vx; y; vy]
# converted to jaxtrack's [x, y, vx, vy]. Each xstart is the state one step BEFORE the first scan
# the target is alive in (gen_truth.m moves it once before storing it).
VO_VO_NUM_STEPS = 100  # truth.K
VO_VO_SAMPLE_PERIOD = 1.0  # model.T, s
VO_VO_SIGMA_V = 5.0  # model.sigma_v, m/s²: Q = σ_v² G Gᵀ, G = [T²/2; T] per axis
VO_VO_MEASUREMENT_STD = 10.0  # model.D = diag([10; 10]) m
VO_VO_PROB_SURVIVAL = 0.99  # model.P_S
VO_VO_PROB_DETECT = 0.98  # model.P_D
VO_VO_CLUTTER_RATE = 66.0  # Vo, Vo & Phung 2014, Sec. V (the toolbox's gen_model.m has 30)
VO_VO_REGION = 1000.0  # model.range_c = [-1000 1000; -1000 1000] m
VO_VO_BIRTH_R = 0.03  # model.r_birth
VO_VO_BIRTH_MEANS = ((0.1, 0.1, 0.0, 0.0), (400.0, -600.0, 0.0, 0.0), (-800.0, -200.0, 0.0, 0.0),
                     (-200.0, 800.0, 0.0, 0.0))  # model.m_birth{1..4} as [x, y, vx, vy]
VO_VO_BIRTH_STD = 10.0  # model.B_birth = diag([10; 10; 10; 10]): P = B Bᵀ = 100 I₄ (m², m²/s²)
# (xstart as [x, y, vx, vy], tbirth, tdeath), 1-indexed as in gen_truth.m: alive at scans
# tbirth..min(tdeath, K).
VO_VO_TRUTH = (
    ((0.0, 0.0, 0.0, -10.0), 1, 70), ((400.0, -600.0, -10.0, 5.0), 1, 101), ((-800.0, -200.0, 20.0, -5.0), 1, 70),
    ((400.0, -600.0, -7.0, -4.0), 20, 101), ((400.0, -600.0, -2.5, 10.0), 20, 101), ((0.0, 0.0, 7.5, -5.0), 20, 101),
    ((-800.0, -200.0, 12.0, 7.0), 40, 101), ((-200.0, 800.0, 15.0, -10.0), 40, 101),
    ((-800.0, -200.0, 3.0, 15.0), 60, 101), ((-200.0, 800.0, -3.0, -15.0), 60, 101),
    ((0.0, 0.0, -20.0, -15.0), 80, 101), ((-200.0, 800.0, 15.0, -5.0), 80, 101),
)


class VoVoLinearSettings(eqx.Module):
    """The filter and metric settings of Vo & Vo's linear benchmark (:func:`vo_vo_linear`), in
    jaxtrack's state layout ``[x, y, vx, vy]`` (m, m, m/s, m/s).

    **Fields:**

    - ``prob_survival``: ``P_S = 0.99``; ``prob_detect``: ``P_D = 0.98`` (``()``).
    - ``clutter_rate``: ``λ = 66`` per scan; ``clutter_density``: ``66 / 2000²`` = 1.65e-5 per m².
    - ``birth_weights`` ``(4,)``: ``r_B = 0.03`` each; ``birth_means`` ``(4, 4)``: ``[0.1, 0.1, 0,
      0]``, ``[400, −600, 0, 0]``, ``[−800, −200, 0, 0]``, ``[−200, 800, 0, 0]``; ``birth_covs``
      ``(4, 4, 4)``: ``100·I₄`` (m², m²/s²). :attr:`birth` is the LMB birth as
      :class:`~jaxtrack.multitarget.GLMB` and :class:`~jaxtrack.multitarget.LMB` take it.
    - ``ospa_cutoff``: ``c = 100`` m, ``ospa_order``: ``p = 1`` (the toolbox's ``plot_results.m``).
    """

    prob_survival: Float[Array, ""]
    prob_detect: Float[Array, ""]
    clutter_rate: Float[Array, ""]
    clutter_density: Float[Array, ""]
    birth_weights: Float[Array, " B"]
    birth_means: Float[Array, "B n"]
    birth_covs: Float[Array, "B n n"]
    ospa_cutoff: float = eqx.field(static=True)
    ospa_order: float = eqx.field(static=True)

    @property
    def birth(self) -> GaussianMixture:
        """The LMB birth (weights = ``r_B``), as ``GLMB(birth=...)`` takes it."""
        return GaussianMixture(self.birth_weights, self.birth_means, self.birth_covs)


def vo_vo_linear(key: PRNGKeyArray | int = 0, *, max_measurements: int = 128,
                 num_steps: int = VO_VO_NUM_STEPS) -> tuple[Scenario, VoVoLinearSettings]:
    r"""Vo & Vo's linear multi-target benchmark of the labelled random-finite-set filters.

    B.-T. Vo & B.-N. Vo (2013), "Labeled random finite sets and multi-object conjugate priors",
    IEEE TSP 61(13), Sec. V; B.-N. Vo, B.-T. Vo & D. Phung (2014), "Labeled random finite sets and
    the Bayes multi-target tracking filter", IEEE TSP 62(24), Sec. V-A; also the δ-GLMB and LMB
    demos of Vo & Vo's MATLAB toolbox, whose ``gen_model.m`` and ``gen_truth.m`` give every number
    below (read, not copied; folder ``glmb/gms``). jaxtrack's state is ``[x, y, vx, vy]`` (m, m/s;
    ``model.state_layout``); MATLAB's is ``[x; vx; y; vy]`` and every number is converted.

    - ``T = 100`` scans, sampling period 1 s (``model.T``); nearly constant velocity with
      discrete white acceleration: ``F = [[I₂, I₂], [0, I₂]]``, ``Q = σ_v² G Gᵀ`` with
      ``G = [[½ I₂], [I₂]]``, ``σ_v = 5`` m/s² (``model.sigma_v``) — *not* the continuous-noise
      ``Q`` of :func:`~jaxtrack.models.constant_velocity`; ``z = [x, y] + v``, ``R = 10²·I₂`` m².
    - ``P_S = 0.99``, ``P_D = 0.98``; clutter ``Poisson(66)`` a scan, uniform over
      ``[−1000, 1000]²`` m (density 1.65e-5 m⁻²). ``λ = 66`` is the papers' value (VVP14 Sec. V;
      the brief's); the toolbox's ``gen_model.m`` we read sets ``lambda_c = 30`` — not confirmed
      against the published PDF here.
    - The truth (``gen_truth.m``): 12 tracks, noise-free (``'noiseless'``), born at scans 1, 1, 1,
      20, 20, 20, 40, 40, 60, 60, 80, 80 (1-indexed); tracks 1 and 3 die after scan 70, the others
      live to the end, so at most 10 targets are alive at once ("10 targets" in the papers' text
      means this maximum). Target ``j`` is alive at 0-indexed scans ``tbirth_j − 1 …
      min(tdeath_j, 100) − 1`` and its state at the first of them is ``F·xstart_j`` (the toolbox
      moves the start state once before storing it).
    - The LMB birth (:class:`VoVoLinearSettings`): four labels a scan, ``r_B = 0.03``, means
      ``[0.1, 0.1, 0, 0]``, ``[400, −600, 0, 0]``, ``[−800, −200, 0, 0]``, ``[−200, 800, 0, 0]``,
      covariance ``10²·I₄``.

    **Arguments:**

    - ``key``: accepted for the named-scenario signature (the truth is fixed, so it is unused;
      the detections and clutter are drawn per run by the simulation's key).
    - ``max_measurements``: the slots of a scan (static int); default 128: at most 10 detections plus
      ``Poisson(66)`` clutter exceed it with probability 2.9e-9 per scan (1.5e-5 for 112) (an overflow is
      counted and warned, as for any :class:`Scenario`).
    - ``num_steps``: the first ``num_steps`` scans of the 100 (default 100), for short tests.

    **Returns:** ``(scenario, settings)``: the :class:`Scenario` (``N = 12`` targets, ``n = 4``,
    ``m = 2``, noise-free truth; its model's prior is the first birth component) and
    :class:`VoVoLinearSettings`.

    **Raises:** ``InputError`` for a bad ``key``, ``max_measurements`` or ``num_steps``.
    """
    as_key(key)
    max_measurements = _positive_int("max_measurements", max_measurements)
    num_steps = _positive_int("num_steps", num_steps)
    if num_steps > VO_VO_NUM_STEPS:
        raise InputError(f"`num_steps` must be at most {VO_VO_NUM_STEPS} (the benchmark's scans); got {num_steps}.")
    T = VO_VO_SAMPLE_PERIOD
    I2, Z2 = np.eye(2), np.zeros((2, 2))
    F = np.block([[I2, T * I2], [Z2, I2]])
    G = np.vstack([0.5 * T**2 * I2, T * I2])
    Q = VO_VO_SIGMA_V**2 * G @ G.T
    H = np.hstack([I2, Z2])
    R = VO_VO_MEASUREMENT_STD**2 * I2
    birth_means = np.asarray(VO_VO_BIRTH_MEANS)
    birth_cov = VO_VO_BIRTH_STD**2 * np.eye(4)
    model = LinearGaussianModel(F, Q, H, R, birth_means[0], birth_cov, state_layout=("x", "y", "vx", "vy"))
    dtype = model.initial_mean.dtype
    start = np.array([x for x, _, _ in VO_VO_TRUTH])
    birth = np.array([b - 1 for _, b, _ in VO_VO_TRUTH], np.int64)
    death = np.array([min(d, VO_VO_NUM_STEPS) for _, _, d in VO_VO_TRUTH], np.int64)
    # Targets born after the run's end are padded slots (birth_step >= num_steps is never alive).
    death = np.minimum(death, num_steps)
    death = np.maximum(death, birth + 1)
    scenario = Scenario(
        model, start @ F.T, birth, death,
        detection_probability=VO_VO_PROB_DETECT,
        clutter_rate=VO_VO_CLUTTER_RATE,
        clutter_region=np.array([[-VO_VO_REGION, VO_VO_REGION], [-VO_VO_REGION, VO_VO_REGION]]),
        max_measurements=max_measurements,
        num_steps=num_steps,
        process_noise=False,
    )
    B = birth_means.shape[0]
    settings = VoVoLinearSettings(
        prob_survival=jnp.asarray(VO_VO_PROB_SURVIVAL, dtype),
        prob_detect=jnp.asarray(VO_VO_PROB_DETECT, dtype),
        clutter_rate=jnp.asarray(VO_VO_CLUTTER_RATE, dtype),
        clutter_density=jnp.asarray(VO_VO_CLUTTER_RATE / (2.0 * VO_VO_REGION) ** 2, dtype),
        birth_weights=jnp.full((B,), VO_VO_BIRTH_R, dtype),
        birth_means=jnp.asarray(birth_means, dtype),
        birth_covs=jnp.broadcast_to(jnp.asarray(birth_cov, dtype), (B, 4, 4)),
        ospa_cutoff=100.0,
        ospa_order=1.0,
    )
    return scenario, settings

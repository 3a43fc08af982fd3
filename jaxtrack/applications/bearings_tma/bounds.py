"""Bearings-only TMA: the posterior Cramér–Rao bound next to the estimators' Monte Carlo RMSE, and the
observer maneuver designed by gradient on it — an extension, not in the report (Lindgren & Gong 1977
compare estimators without a bound).

**The bound.** The relative-state model of the study's EKF (:class:`~jaxtrack.models.RelativeBearingModel`:
constant velocity, no plant noise, observer input ``u(k)`` of eq. 67b, compass bearing with σ_ν)
with a bearing at every sample ``k = 0, …, K`` (``first_step="update"``) and the prior
``x_R(0) ~ N(x_R,true(0), diag(σ_p², σ_p², σ_v², σ_v²))`` (σ_p = 250 m, σ_v = 0.5 m/s around each
geometry's truth, stated, not in the report). :func:`jaxtrack.bounds.pcrlb` (Tichavský, Muravchik &
Nehorai 1998, eq. 21) averages over truths drawn from that prior. It is a Bayesian bound: it holds
for **any** estimator (EKF, PLKF with any initial range guess, even one that uses β_m(0) to
initialise) on the Monte Carlo in which run ``i``'s truth and bearings are
``simulate(model, fold_in(key, i))`` — :func:`bayes_monte_carlo`, which runs the study's own
estimator functions (:func:`~.estimators.bearing_ekf` with :func:`~.estimators.ekf_prior`, and
:func:`~.estimators.normalized_pseudolinear_filter`) on those runs. (The study's own Monte Carlo keeps
one fixed truth, for which no bound holds for estimators with a prior guess: an EKF started at the
true range beats any bound at ``k = 0``.) With no plant noise the averaged information of
truths seen under slightly different bearings is better conditioned than any one truth's (Jensen),
so this bound is below the bound linearised along the nominal truth (:func:`jaxtrack.bounds.pcrlb_along`):
valid, but not tight.

**The design.** :func:`design_study`: from geometry R2 (the study's 3°/s maneuvers at the study's
speed), the observer's per-interval turn rates (limit 3°/s by ``ω = ω_max tanh(c)``) optimised with
optax to minimise the trace of the position block of the terminal PCRLB
(:func:`jaxtrack.design.bearing_position_bound`, m², fixed truths: common random numbers), against the
study's maneuver and a brute-force grid of one-turn maneuvers (turn start × new heading at the full
rate); then validated by the Monte Carlo RMSE of the EKF and the PLKF on both paths (paired runs).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ...bounds import PosteriorCRB, pcrlb, pcrlb_along
from ...filters import ParticleFilter, Regularization, run_filter
from ...design import (
    ObserverDesign,
    bearing_position_bound,
    design_observer_path,
    observer_states,
)
from ...models import RelativeBearingModel, constant_velocity_transition
from ...montecarlo import monte_carlo_map, simulate, time_averaged_rmse_ratio
from .estimators import bearing_ekf, ekf_prior, normalized_pseudolinear_filter
from .scenario import AVERAGED_BEARING_STD, SAMPLE_PERIOD, SPEED, TURN_RATE, Scenario, geometry, geometry_spec

PRIOR_POSITION_STD = 250.0  # m: σ of the prior on each relative position component (stated; not in the report)
PRIOR_VELOCITY_STD = 0.5  # m/s: σ of the prior on each relative velocity component
FILTER_INITIAL_RANGE = 10_000.0  # m: the EKF's and the PLKF's r̂_s(0) (the study's Fig. 6 guess)
PF_STREAM = 0x5046  # fold_in tag of a run's particle-filter key (apart from its truth draws)


def prior_cov(position_std: float = PRIOR_POSITION_STD, velocity_std: float = PRIOR_VELOCITY_STD) -> Array:
    """``diag(σ_p², σ_p², σ_v², σ_v²)`` (m², m²/s²), ``(4, 4)`` float64."""
    return jnp.diag(jnp.asarray([position_std, position_std, velocity_std, velocity_std], jnp.float64) ** 2)


def _relative_model(observer, target0, cov, bearing_std, sample_period) -> RelativeBearingModel:
    """The bound's model for an observer track ``(K+1, 4)``: ``u(k) = x_O(k+1) − Φ x_O(k)``, entry 0 unused."""
    phi = constant_velocity_transition(sample_period, dtype=observer.dtype)
    u = jnp.concatenate([jnp.zeros((1, 4), observer.dtype), observer[1:] - observer[:-1] @ phi.T], axis=0)
    return RelativeBearingModel(u, sample_period, bearing_std**2, target0 - observer[0], cov)


def bound_model(scenario: Scenario, *, bearing_std: float = AVERAGED_BEARING_STD,
                cov: Array | None = None) -> RelativeBearingModel:
    """The relative-state model of ``scenario`` for the bound (module docstring), the prior centred on its truth.

    **Arguments:** ``scenario``: a :class:`~.scenario.Scenario`; ``bearing_std``: σ_ν (rad, the
    simulated and assumed one); ``cov``: the prior covariance ``(4, 4)`` (default :func:`prior_cov`).

    **Returns:** a :class:`~jaxtrack.models.RelativeBearingModel` with ``K+1`` steps.
    """
    cov = prior_cov() if cov is None else cov
    u = jnp.concatenate([jnp.zeros((1, 4), scenario.target.dtype), scenario.observer_input], axis=0)
    return RelativeBearingModel(u, scenario.sample_period, bearing_std**2, scenario.relative[0], cov)


class BayesMonteCarlo(eqx.Module):
    """Per-run squared position errors on truths drawn from the bound's prior (:func:`bayes_monte_carlo`).

    ``ekf_se`` / ``plkf_se``: ``(N, K+1)`` ``‖r̂_R(k|k) − r_R(k)‖²`` (m²) of the EKF and the PLKF;
    ``ekf_ok`` ``(N,)``: False where the EKF went non-finite (its errors are then ``inf``);
    ``pf_se`` ``(N, K+1)``: the particle filter's (None when not run).
    """

    ekf_se: Float[Array, "N K1"]
    plkf_se: Float[Array, "N K1"]
    ekf_ok: Array
    pf_se: Float[Array, "N K1"] | None = None


def particle_filter(num_particles: int) -> ParticleFilter:
    """The study's particle filter: bootstrap, systematic resampling below ESS N/2, and the
    regularised move (:class:`~jaxtrack.filters.Regularization`, Musso et al.'s bandwidth) that a
    model without plant noise needs (resampling alone would leave copies that never spread again).
    It runs on the bound's own model and prior (:func:`bound_model`): the information the PCRLB
    assumes, which the EKF (Appendix D prior, ``r̂(0)`` = 10 km) and the PLKF do not use."""
    return ParticleFilter(num_particles, regularization=Regularization())


def _bayes_run(key, args):
    model, vo0, filter_std, r0, pf = args
    traj = simulate(model, key)  # run i: the truths pcrlb(model, key, N) averages over
    beta = traj.measurements[:, 0]
    u = model.observer_input[1:]
    ts = model.sample_period
    m0, P0 = ekf_prior(beta[0], r0, vo0)
    ekf = bearing_ekf(beta, u, ts, filter_std, m0, P0, throw=False)
    plkf = normalized_pseudolinear_filter(beta, u, ts, filter_std, r0, with_gain=False)

    def se(mean):
        return jnp.sum((mean[:, :2] - traj.states[:, :2]) ** 2, axis=-1)

    ekf_se = jnp.where(ekf.ok, se(ekf.mean), jnp.inf)
    if pf is None:
        return ekf_se, se(plkf.mean), ekf.ok
    pf = eqx.tree_at(lambda f: f.key, pf, jax.random.fold_in(key, PF_STREAM))
    res = run_filter(pf, model, traj.measurements, save="mean", throw=False)
    return ekf_se, se(plkf.mean), ekf.ok, jnp.where(res.ok, se(res.filtered_mean), jnp.inf)


def bayes_monte_carlo(model: RelativeBearingModel, observer_velocity0, key, num_runs: int, *,
                      filter_std: float = AVERAGED_BEARING_STD,
                      initial_range: float = FILTER_INITIAL_RANGE,
                      particles: int | None = None) -> BayesMonteCarlo:
    """The study's EKF (Appendix D prior) and Table 2 PLKF on truths drawn from ``model``'s prior.

    Run ``i`` is ``simulate(model, fold_in(key, i))`` (truth and bearings), on
    :func:`jaxtrack.montecarlo.monte_carlo_map` — the truths :func:`jaxtrack.bounds.pcrlb` averages
    over with the same key.

    **Arguments:** ``model``: e.g. :func:`bound_model`; ``observer_velocity0``: ``(2,)`` m/s (the
    EKF prior's velocity, Appendix D); ``key``; ``num_runs``; ``filter_std``: the filters' σ_ν
    (rad); ``initial_range``: both filters' ``r̂_s(0)`` (m); ``particles``: None, or run
    :func:`particle_filter` with this many particles too (on ``model`` itself, each run with its own
    key ``fold_in(run key, PF_STREAM)``).

    **Returns:** :class:`BayesMonteCarlo`.
    """
    dtype = model.initial_mean.dtype
    pf = None if particles is None else particle_filter(particles)
    args = (model, jnp.asarray(observer_velocity0, dtype), jnp.asarray(filter_std, dtype),
            jnp.asarray(initial_range, dtype), pf)
    # Blocks of 16 runs with a particle filter (16 × N particles at once), else one block.
    block = {} if pf is None else {"block_size": 16}
    out = monte_carlo_map(_bayes_run, key, num_runs, args=args, reduce="stack", **block)
    return BayesMonteCarlo(*(jnp.asarray(a) for a in out))


class BoundComparison(eqx.Module):
    """PCRLB vs Monte Carlo position MSE on one geometry (:func:`bound_comparison`).

    - ``name``; ``times`` ``(K+1,)`` s; ``bound`` the :class:`~jaxtrack.bounds.PosteriorCRB`;
      ``position_bound`` ``(K+1,)`` m², the trace of its position block.
    - ``ekf_mse``, ``plkf_mse`` ``(K+1,)`` m² and ``ekf_se_mean``, ``plkf_se_mean`` ``(K+1,)`` m²,
      their standard errors (per-run spread / √N); ``ekf_ok`` ``()`` the fraction of finite EKF runs.
    - ``num_runs``: Monte Carlo runs (the bound averages over the same truths).
    - ``pf_mse``, ``pf_se_mean`` ``(K+1,)`` m²: the particle filter's (:func:`particle_filter`), None
      when it was not run; ``num_particles`` (0 when not run).
    """

    name: str = eqx.field(static=True)
    times: Float[Array, " K1"]
    bound: PosteriorCRB
    position_bound: Float[Array, " K1"]
    ekf_mse: Float[Array, " K1"]
    ekf_se_mean: Float[Array, " K1"]
    plkf_mse: Float[Array, " K1"]
    plkf_se_mean: Float[Array, " K1"]
    ekf_ok: Float[Array, ""]
    num_runs: int = eqx.field(static=True)
    pf_mse: Float[Array, " K1"] | None = None
    pf_se_mean: Float[Array, " K1"] | None = None
    num_particles: int = eqx.field(static=True, default=0)

    def efficiency(self, which: str = "ekf") -> Array:
        """RMSE / √bound per step (≥ 1 up to Monte Carlo error), ``(K+1,)``; ``which``: ``"ekf"``,
        ``"plkf"`` or ``"pf"`` (when the particle filter ran)."""
        mse = {"ekf": self.ekf_mse, "plkf": self.plkf_mse, "pf": self.pf_mse}[which]
        if mse is None:
            raise ValueError("no particle filter in this comparison: pass `particles` to bound_comparison.")
        return jnp.sqrt(mse / self.position_bound)


def _mean_and_se(se):
    se = np.asarray(se)
    return se.mean(0), se.std(0, ddof=1) / math.sqrt(se.shape[0])


def bound_comparison(name: str, key, num_runs: int, *, bearing_std: float = AVERAGED_BEARING_STD,
                     particles: int | None = None) -> BoundComparison:
    """The PCRLB of geometry ``name`` and the EKF's and PLKF's Monte Carlo position MSE on the same truths.

    **Arguments:** ``name``: ``"R1"``, ``"R2"`` or ``"R3"``; ``key``; ``num_runs`` (the bound and
    the Monte Carlo use the same ``num_runs`` truths); ``bearing_std``: σ_ν of both the
    simulation and the filters (config A), rad; ``particles``: None, or also run
    :func:`particle_filter` with this many particles on the same truths.

    **Returns:** :class:`BoundComparison`.
    """
    s = geometry(name)
    model = bound_model(s, bearing_std=bearing_std)
    crb = pcrlb(model, key, num_runs)
    mc = bayes_monte_carlo(model, s.observer[0, 2:], key, num_runs, filter_std=bearing_std, particles=particles)
    ok = np.asarray(mc.ekf_ok)
    e_m, e_s = _mean_and_se(mc.ekf_se)
    p_m, p_s = _mean_and_se(mc.plkf_se)
    f_m, f_s = (None, None) if mc.pf_se is None else (jnp.asarray(a) for a in _mean_and_se(mc.pf_se))
    pos = crb.bound[:, 0, 0] + crb.bound[:, 1, 1]
    return BoundComparison(name, s.times, crb, pos, jnp.asarray(e_m), jnp.asarray(e_s), jnp.asarray(p_m),
                           jnp.asarray(p_s), jnp.asarray(ok.mean()), int(num_runs), f_m, f_s,
                           0 if particles is None else int(particles))


def mean_per_truth_bound(name: str, key, num_runs: int, *, bearing_std: float = AVERAGED_BEARING_STD) -> Array:
    """``E[J(x)⁻¹]``: the position bound linearised along each of the ``num_runs`` truths of
    :func:`bound_comparison` (same ``key``: run ``i``'s truth is ``simulate(model, fold_in(key, i))``;
    :func:`jaxtrack.bounds.pcrlb_along`), averaged over them — the tighter reference next to the
    PCRLB ``E[J]⁻¹``, which it exceeds by Jensen's inequality (no plant noise keeps each truth's
    information apart).

    **Returns:** the trace of the position block, m², ``(K+1,)``.
    """
    model = bound_model(geometry(name), bearing_std=bearing_std)

    def one(k, _):
        b = pcrlb_along(model, simulate(model, k).states).bound
        return b[:, 0, 0] + b[:, 1, 1]

    return jnp.mean(monte_carlo_map(one, key, num_runs, reduce="stack"), axis=0)


def bound_table(comparisons, times=(240.0, 480.0, 720.0, 960.0)) -> str:
    """The printed table "extra (not in the paper): PCRLB vs Monte Carlo RMSE", per geometry and time.

    **Arguments:** ``comparisons``: :class:`BoundComparison` s; ``times``: sample instants (s).

    **Returns:** the table (str): the position RMSE bound, the EKF's, PLKF's (and the particle
    filter's, when run) RMSE ± 2 s.e. (m) and their efficiencies RMSE/√bound.
    """
    pf = any(c.pf_mse is not None for c in comparisons)
    head = f"{'geometry':>8} {'t [s]':>6} {'PCRLB':>9} {'EKF RMSE':>18} {'PLKF RMSE':>18}"
    head += f" {'PF RMSE':>18} {'EKF eff.':>9} {'PF eff.':>8}" if pf else f" {'EKF eff.':>9}"
    lines = ["extra (not in the paper): PCRLB vs Monte Carlo RMSE (position, m; truths from the prior "
             f"σ_p = {PRIOR_POSITION_STD:g} m, σ_v = {PRIOR_VELOCITY_STD:g} m/s; ± = 2 s.e.)", head]
    for c in comparisons:
        t = np.asarray(c.times)
        estimators = [(c.ekf_mse, c.ekf_se_mean), (c.plkf_mse, c.plkf_se_mean)]
        if pf:
            estimators.append((c.pf_mse, c.pf_se_mean))
        for tt in times:
            k = int(np.argmin(np.abs(t - tt)))
            b = math.sqrt(float(c.position_bound[k]))
            cells = []
            for m, se in estimators:
                if m is None:
                    cells.append("-")
                    continue
                m, se = float(m[k]), float(se[k])
                # RMSE ± 2 s.e. by the delta method: s.e.(√m) = s.e.(m) / (2√m).
                cells.append(f"{math.sqrt(m):9.1f} ± {se / math.sqrt(m):5.1f}")
            line = f"{c.name:>8} {tt:6.0f} {b:9.1f} " + " ".join(f"{x:>18}" for x in cells)
            line += f" {math.sqrt(float(c.ekf_mse[k])) / b:9.2f}"
            if pf:
                line += f" {math.sqrt(float(c.pf_mse[k])) / b:8.2f}" if c.pf_mse is not None else f" {'-':>8}"
            lines.append(line)
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# observer-trajectory design


def grid_turn_rates(turn_starts, new_headings, *, initial_heading: float, num_intervals: int,
                    max_turn_rate: float = TURN_RATE, sample_period: float = SAMPLE_PERIOD) -> np.ndarray:
    """Turn-rate sequences of one-turn maneuvers: from ``initial_heading``, at interval ``j`` turn the
    short way to each new heading at the full rate (the remainder of the turn in its last interval).

    **Arguments:** ``turn_starts``: interval indices; ``new_headings``: rad (compass);
    ``initial_heading``: rad; ``num_intervals``: ``K``; ``max_turn_rate``: rad/s; ``sample_period``: s.

    **Returns:** ``(len(turn_starts)·len(new_headings), K)`` rad/s, NumPy, turn-start-major.
    """
    out = []
    per = max_turn_rate * sample_period
    for j in turn_starts:
        for h in new_headings:
            turn = float(np.angle(np.exp(1j * (h - initial_heading))))
            w = np.zeros(num_intervals)
            left, k = abs(turn), int(j)
            while left > 1e-12 and k < num_intervals:
                step = min(per, left)
                w[k] = math.copysign(step / sample_period, turn)
                left -= step
                k += 1
            out.append(w)
    return np.asarray(out)


class DesignStudy(eqx.Module):
    """The designed observer path against the study's maneuver and a brute-force grid (:func:`design_study`).

    - ``design``: the :class:`~jaxtrack.design.ObserverDesign` (``objective``, ``history`` in m²).
    - ``study_observer`` ``(K+1, 4)`` and ``study_objective`` ``()`` m²: geometry R2's path and its
      terminal position bound; ``factor = study_objective / design.objective``.
    - ``grid_objective`` ``(G,)`` m² and ``grid_rates`` ``(G, K)`` rad/s: the grid of one-turn
      maneuvers; ``grid_best`` ``()`` m², their minimum.
    """

    design: ObserverDesign
    study_observer: Float[Array, "K1 4"]
    study_objective: Float[Array, ""]
    grid_rates: Float[Array, "G K"]
    grid_objective: Float[Array, " G"]
    grid_best: Float[Array, ""]

    @property
    def factor(self) -> float:
        """How many times lower the designed path's terminal position bound is than the study's (dimensionless)."""
        return float(self.study_objective / self.design.objective)


def design_objective(key, num_runs: int, *, geometry_name: str = "R2", bearing_std: float = AVERAGED_BEARING_STD):
    """The design's objective ``observer (K+1, 4) -> m²``: :func:`jaxtrack.design.bearing_position_bound`
    for geometry ``geometry_name``'s target and the prior of :func:`prior_cov`, over ``num_runs`` fixed truths."""
    spec = geometry_spec(geometry_name)
    vt = SPEED * np.array([math.sin(spec.target_course), math.cos(spec.target_course)])
    target0 = jnp.asarray([*spec.target_position, *vt], jnp.float64)
    cov = prior_cov()

    def objective(observer):
        return bearing_position_bound(observer, target0, cov, bearing_std, SAMPLE_PERIOD, key, num_runs)

    return objective


def design_study(key, num_runs: int = 64, *, num_steps: int = 150, turn_starts=None, new_headings=None,
                 learning_rate: float = 0.05) -> DesignStudy:
    """Design the observer's turn rates on geometry R2 (start heading 90°, 5.626 m/s, ≤ 3°/s) by gradient.

    The gradient design starts from R2's own maneuver (its per-interval turn rates, clipped inside
    the limit) and minimises the terminal position PCRLB of :func:`design_objective` with
    ``optax.adam(learning_rate)``. The grid: one turn at the full rate, starting at each of
    ``turn_starts`` (interval indices, default every other interval) to each of ``new_headings``
    (default every 15°) — a restricted family inside the design's (every grid path is a feasible
    turn-rate sequence), so the design can be below the grid optimum.

    **Arguments:** ``key``, ``num_runs``: the fixed truths of the objective; ``num_steps``: optimiser
    steps; ``turn_starts``, ``new_headings`` (rad): the grid; ``learning_rate``.

    **Returns:** :class:`DesignStudy`.
    """
    import optax

    s = geometry("R2")
    spec = geometry_spec("R2")
    K = s.times.shape[0] - 1
    psi0 = float(spec.path.courses[0])
    objective = eqx.filter_jit(design_objective(key, num_runs))
    # R2's own turn rates per interval (heading change / t_s), as the starting controls.
    psi = np.unwrap(np.arctan2(np.asarray(s.observer[:, 2]), np.asarray(s.observer[:, 3])))
    rates = np.diff(psi) / SAMPLE_PERIOD
    c0 = np.arctanh(np.clip(rates / TURN_RATE, -0.95, 0.95))
    design = design_observer_path(objective, jnp.asarray(c0), max_turn_rate=TURN_RATE, initial_heading=psi0,
                                  speed=SPEED, sample_period=SAMPLE_PERIOD, optimizer=optax.adam(learning_rate),
                                  num_steps=num_steps)
    turn_starts = np.arange(0, K, 2) if turn_starts is None else turn_starts
    new_headings = np.radians(np.arange(0, 360, 15)) if new_headings is None else new_headings
    grid = grid_turn_rates(turn_starts, new_headings, initial_heading=psi0, num_intervals=K)

    def grid_value(w):
        return objective(observer_states(w, initial_heading=psi0, speed=SPEED, sample_period=SAMPLE_PERIOD))

    grid_obj = jax.lax.map(grid_value, jnp.asarray(grid))
    return DesignStudy(design, s.observer, objective(s.observer), jnp.asarray(grid), grid_obj, jnp.min(grid_obj))


class DesignValidation(eqx.Module):
    """Monte Carlo of the EKF and the PLKF on the designed path vs the study's (paired runs, same truths' draws).

    ``ekf`` / ``plkf``: terminal RMSE ratio designed/study, the
    :class:`~jaxtrack.montecarlo.Interval` of :func:`jaxtrack.montecarlo.time_averaged_rmse_ratio`
    over the last ``window`` samples; ``designed``, ``study``: the :class:`BayesMonteCarlo` runs.
    """

    ekf: tuple
    plkf: tuple
    designed: BayesMonteCarlo
    study: BayesMonteCarlo


def validate_design(observer, key, num_runs: int, *, window: int = 1, confidence: float = 0.95) -> DesignValidation:
    """Monte Carlo RMSE of the EKF and the PLKF on ``observer`` (designed) vs geometry R2's path.

    Run ``i`` of both uses ``fold_in(key, i)``: the same standardised prior draw and bearing noise
    (common random numbers), so the paired interval on the RMSE ratio is narrow.

    **Arguments:** ``observer`` ``(K+1, 4)``; ``key``; ``num_runs``; ``window``: terminal samples
    averaged (1: the terminal RMSE); ``confidence``.

    **Returns:** :class:`DesignValidation` (ratio < 1: the designed path is better).
    """
    spec = geometry_spec("R2")
    s = geometry("R2")
    vt = SPEED * np.array([math.sin(spec.target_course), math.cos(spec.target_course)])
    target0 = jnp.asarray([*spec.target_position, *vt], jnp.float64)
    observer = jnp.asarray(observer, jnp.float64)
    cov = prior_cov()
    ts = jnp.asarray(SAMPLE_PERIOD, jnp.float64)
    runs = {}
    for label, obs in (("designed", observer), ("study", s.observer)):
        model = _relative_model(obs, target0, cov, jnp.asarray(AVERAGED_BEARING_STD, jnp.float64), ts)
        runs[label] = bayes_monte_carlo(model, obs[0, 2:], key, num_runs)
    d, st = runs["designed"], runs["study"]
    ekf = time_averaged_rmse_ratio(np.asarray(d.ekf_se)[:, -window:], np.asarray(st.ekf_se)[:, -window:], confidence)
    plkf = time_averaged_rmse_ratio(np.asarray(d.plkf_se)[:, -window:], np.asarray(st.plkf_se)[:, -window:],
                                    confidence)
    return DesignValidation(tuple(map(float, ekf)), tuple(map(float, plkf)), d, st)


__all__ = [
    "PRIOR_POSITION_STD", "PRIOR_VELOCITY_STD", "FILTER_INITIAL_RANGE", "prior_cov", "bound_model",
    "BayesMonteCarlo", "bayes_monte_carlo", "BoundComparison", "bound_comparison", "mean_per_truth_bound",
    "bound_table",
    "grid_turn_rates", "DesignStudy", "design_objective", "design_study", "DesignValidation", "validate_design",
]

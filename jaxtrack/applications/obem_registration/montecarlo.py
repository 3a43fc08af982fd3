"""The paper's Monte Carlo (Sec. 3, Figs 8–10; spec §4.4) and the consistency check on data from
the linear model (S6), on :func:`jaxtrack.montecarlo.monte_carlo_map` and
:func:`jaxtrack.montecarlo.monte_carlo`."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from ..._validation import InputError
from ...montecarlo import MonteCarloResult, monte_carlo as _filter_monte_carlo, monte_carlo_map
from .estimators import filter_means, prior_cov, rectify, registration_model
from .frames import merged_columns, obem_columns
from .scenario import RegistrationInputs, Scenario, registration_inputs, simulate_run

__all__ = ["MODELS", "CORRECTIONS", "RegistrationMonteCarlo", "RunArgs", "RunErrors", "run_squared_errors", "monte_carlo",
           "linear_model_consistency"]

MODELS = ("AAM", "OBEM")
"""The two estimators, in the order of the first axis of :class:`RegistrationMonteCarlo`'s bias curves."""
CORRECTIONS = ("raw", "OBEM", "AAM-all", "AAM-no-pitch/roll")
"""Fig. 10's four curves, in the order of :attr:`RegistrationMonteCarlo.position`."""


class RegistrationMonteCarlo(eqx.Module):
    """RMSE curves of a Monte Carlo run over ``K`` scans (Figs 8–10; spec §4.4).

    - ``gross_range`` ``(2, 2, K)``, m: model (AAM, OBEM) × radar; ``Δr̂ + k̂_r r_m`` against
      ``Δr + k_r r_t`` (spec §6 item 20 [R]).
    - ``elevation`` ``(2, 2, K)``, rad: Δε̂_i against Δε_i (item 21 [R]).
    - ``azimuth_minus_yaw`` ``(2, 2, K)``, rad: ``(Δθ_i − Δφ_i)^`` against its truth.
    - ``pitch_roll`` ``(2, 2, K)``, rad: AAM's (pitch, roll) of platforms 1, 2 (Fig. 9).
    - ``position`` ``(4, K, 3)``, m: rectified radar-1 position per :data:`CORRECTIONS`, ENU axes.
    - ``num_runs`` (static).
    """

    gross_range: Float[Array, "2 2 K"]
    elevation: Float[Array, "2 2 K"]
    azimuth_minus_yaw: Float[Array, "2 2 K"]
    pitch_roll: Float[Array, "2 2 K"]
    position: Float[Array, "4 K 3"]
    num_runs: int = eqx.field(static=True)


class RunArgs(eqx.Module):
    """What every run of :func:`run_squared_errors` shares: the scenario and the AAM (14×14) and
    OBEM (8×8) priors P_0."""

    scenario: Scenario
    prior_aam: Float[Array, "14 14"]
    prior_obem: Float[Array, "8 8"]


class RunErrors(eqx.Module):
    """Squared estimation errors of one run, per scan (the summands of :class:`RegistrationMonteCarlo`)."""

    gross_range: Float[Array, "2 2 K"]
    elevation: Float[Array, "2 2 K"]
    azimuth_minus_yaw: Float[Array, "2 2 K"]
    pitch_roll: Float[Array, "2 2 K"]
    position: Float[Array, "4 K 3"]


def run_squared_errors(key: PRNGKeyArray, args: RunArgs) -> RunErrors:
    """One Monte Carlo run: simulate, run AAM and OBEM, return per-scan squared estimation errors.

    **Arguments:** ``key`` (run ``i`` of :func:`monte_carlo` uses ``fold_in(key, i)``); ``args``.

    **Returns:** :class:`RunErrors` (m², rad²).
    """
    scenario = args.scenario
    scans = simulate_run(scenario, key, True, True)
    inputs = registration_inputs(scans, scenario.noise_std)
    aam = filter_means(inputs.Z, inputs.H, inputs.R, args.prior_aam)
    obem = filter_means(inputs.Z, obem_columns(inputs.H), inputs.R, args.prior_obem)
    ob, att = scenario.offset_bias, scenario.attitude_bias
    r_meas = scans.raw[:, :, 0]  # (2, K)
    r_true = jnp.linalg.norm(scans.target_enu, axis=-1)
    # Per model: offsets (K, 2, 4) with the azimuth entry already merged (Δθ − Δφ).
    aam_off = jnp.stack([aam[:, 0:4], aam[:, 4:8]], axis=1)
    aam_off = aam_off.at[:, :, 2].add(-jnp.stack([aam[:, 8], aam[:, 11]], axis=1))
    obem_off = jnp.stack([obem[:, 0:4], obem[:, 4:8]], axis=1)
    offs = jnp.swapaxes(jnp.stack([aam_off, obem_off]), 1, 2)  # (2 models, 2 radars, K, 4)
    shape = offs.shape[:-1]
    truth_range = ob[:, 0:1] + ob[:, 1:2] * r_true  # (2, K)
    gross = offs[..., 0] + offs[..., 1] * jnp.broadcast_to(r_meas, shape) - jnp.broadcast_to(truth_range, shape)
    elev = offs[..., 3] - jnp.broadcast_to(ob[:, 3:4], shape)
    az = offs[..., 2] - jnp.broadcast_to((ob[:, 2] - att[:, 0])[:, None], shape)
    pr_est = jnp.stack([aam[:, 9:11], aam[:, 12:14]])  # (2 platforms, K, 2)
    pr_err = jnp.swapaxes(pr_est - jnp.broadcast_to(att[:, None, 1:3], pr_est.shape), 1, 2)  # (2, 2, K)
    raw1 = scans.raw[0]
    zeros2 = jnp.zeros((raw1.shape[0], 2), raw1.dtype)
    rect = jnp.stack([
        rectify(raw1, jnp.zeros((raw1.shape[0], 4), raw1.dtype), zeros2),
        rectify(raw1, obem_off[:, 0], zeros2),
        rectify(raw1, aam_off[:, 0], aam[:, 9:11]),
        rectify(raw1, aam_off[:, 0], zeros2),
    ])
    pos_err = rect - jnp.broadcast_to(scans.target_enu[0], rect.shape)
    return RunErrors(gross**2, elev**2, az**2, pr_err**2, pos_err**2)


def monte_carlo(scenario: Scenario, key: PRNGKeyArray, num_runs: int = 100, *, prior: str = "big",
                block_size: int = 512, chunk_size: int = 1000, progress: bool = False) -> RegistrationMonteCarlo:
    """The paper's Monte Carlo (Sec. 3, spec §4): ``num_runs`` runs of AAM and OBEM on independent tracks.

    Run ``i`` uses ``jax.random.fold_in(key, i)`` to draw ship and target tracks (regenerated
    every run, spec §6 item 15 [R]) and measurement noise; :func:`jaxtrack.montecarlo.monte_carlo_map`
    runs :func:`run_squared_errors` in blocks of ``block_size`` runs (one compilation) and keeps
    only sums of squared errors.

    **Arguments:** ``scenario`` (:func:`paper_scenario`, :func:`unequal_tilt_scenario`, …); ``key``;
    ``num_runs``; ``prior``: a key of :data:`PRIORS`; ``block_size``: runs per compiled block;
    ``chunk_size``, ``progress``: the progress bar (results do not depend on them).

    **Returns:** a :class:`RegistrationMonteCarlo` of RMSE curves.
    """
    if not isinstance(scenario, Scenario):
        raise InputError(f"`scenario` must be a Scenario; got {type(scenario).__name__}.")
    if not isinstance(num_runs, int) or num_runs < 1:
        raise InputError(f"`num_runs` must be a positive int; got {num_runs!r}.")
    dtype = scenario.ship_sites.dtype
    args = RunArgs(scenario, prior_cov("aam", prior, dtype=dtype), prior_cov("obem", prior, dtype=dtype))
    sums = monte_carlo_map(run_squared_errors, key, num_runs, args=args, block_size=block_size,
                           chunk_size=chunk_size, progress=progress, desc="registration Monte Carlo")
    rmse = jax.tree_util.tree_map(lambda s: jnp.sqrt(s / num_runs), sums)
    return RegistrationMonteCarlo(rmse.gross_range, rmse.elevation, rmse.azimuth_minus_yaw, rmse.pitch_roll,
                                  rmse.position, num_runs=num_runs)


def linear_model_consistency(inputs: RegistrationInputs, key: PRNGKeyArray, model: str = "obem",
                             num_runs: int = 100, *, prior: str = "big") -> MonteCarloResult:
    """NEES of the registration KF on data drawn from the linear model itself (S6).

    H(k) and R(k) are the given :class:`RegistrationInputs` (the §4 geometry); each run draws the
    bias from the prior ``N(0, P_0)`` and ``Z = Hβ + Gw`` (eq. 17), so the filter is matched and its
    NEES is χ²(n). Uses :func:`jaxtrack.montecarlo.monte_carlo` (run ``i`` from
    ``fold_in(key, i)``) on :func:`registration_model`. On the real, nonlinear data the models are
    misspecified and no such check applies (spec §5.2 S6).

    **Arguments:** ``inputs``; ``key``; ``model`` ∈ {"aam", "obem", "merged"}; ``num_runs``;
    ``prior``: a key of :data:`PRIORS`.

    **Returns:** the :class:`~jaxtrack.montecarlo.MonteCarloResult`.
    """
    columns = {"aam": lambda h: h, "obem": obem_columns, "merged": merged_columns}
    if model not in columns:
        raise InputError(f"`model` must be 'aam', 'obem' or 'merged'; got {model!r}.")
    if not isinstance(inputs, RegistrationInputs):
        raise InputError(f"`inputs` must be RegistrationInputs; got {type(inputs).__name__}.")
    lin = registration_model(columns[model](inputs.H), inputs.R, prior_cov(model, prior, dtype=inputs.H.dtype))
    return _filter_monte_carlo(lin, key, num_runs, progress=False)

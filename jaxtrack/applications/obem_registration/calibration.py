"""Offline sensor calibration by maximum likelihood: the complement of the online AAM/OBEM filters.

The registration study estimates the two radars' biases *online*, inside the state of a Kalman
filter started from a prior (eqs 17, 20, 47, 49). A radar engineer calibrating the sensors from
one recorded track asks for the maximum-likelihood estimate of the same biases with a confidence
interval. This module builds it from the study's pieces and :func:`jaxtrack.learning.fit`:

**Model (the registration equation, exact in the biases).** The target is eliminated by equating
both radars' bias-corrected positions in ECEF (eqs 12–14), so no target state is needed:

    Z(k) = h_k(β) + v(k),   v(k) ~ N(0, R(k)),

with ``Z(k) = X_2s − X_1s + T_2X_2 − T_1X_1`` (eq. 18), ``h_k`` the exact nonlinear registration
map of spec §2.6 (:func:`~.frames.nonlinear_pseudo_measurement`; ``jacfwd(h_k)(0)`` is eq. 17's
``H``) and ``R(k) = G Σ Gᵀ`` (spec §2.2 [R]). Passing ``linearised=True`` replaces ``h_k(β)`` by
the first-order ``H(k) β`` of eq. (47), the OBEM filter's own measurement model. The
log-likelihood ``ℓ(β) = Σ_k log N(Z(k); h_k(β), R(k))`` is the prediction-error decomposition
(Harvey 1989, eq. 3.4.2) of a :class:`~jaxtrack.models.LinearGaussianModel` whose 1-dimensional
state is the known constant 1 (prior variance 1e-30, ``F = 1``, ``Q = 0``) seen through
``H(k) = h_k(β)`` as a ``(3, 1)`` column: its innovations are ``Z(k) − h_k(β)`` and their
covariances ``R(k) + 1e-30 h hᵀ`` — the exact likelihood to 1e-30 relative — so
:func:`~jaxtrack.learning.fit` and :class:`~jaxtrack.learning.MLEFit`'s observed-information
standard errors apply unchanged.

**Parameters (what one track identifies).** The 8 OBEM states ``[Δr_i, k_ri, Δθ_i − Δφ_i, Δε_i]``
(eq. 46, :data:`~.frames.OBEM_STATES`): the azimuth and yaw columns are exact negatives (eq. 27,
Proposition 1), so only ``Δθ − Δφ`` is identifiable; pitch and roll are known inputs
(``pitch_roll``, default 0), because the two platforms' common rotation about the baseline is not
identifiable from one track (spec §2.4 [X], caveat 2). With zero pitch and roll the 8-state model
is exact (a yaw is a pure azimuth rotation); :func:`yaw_only_scenario` is the paper's scenario
with that choice. The range convention is the paper's ``r_t = r_m − Δr − k_r r_m`` (§1.7), an
exact reparametrisation of the simulator's ``r_m = (1 + k_r) r_t + Δr``: the true values in the
model's convention are ``Δr/(1 + k_r)`` and ``k_r/(1 + k_r)`` (:func:`calibration_truth`).

Unconstrained (plain-array) parameters are scaled to O(1) (100 m, 0.01, 1°, 1°) so that L-BFGS
sees a well-conditioned problem; estimates, standard errors and intervals are returned in SI
units and radians.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ..._validation import InputError, check_shape
from ... import geometry
from ...learning import MLEFit, fit
from ...models import LinearGaussianModel
from .estimators import filter_means, prior_cov
from .frames import DEG, OBEM_STATES, attitude_matrix, obem_columns, obem_truth, offset_corrected_position
from .scenario import Scans, Scenario, paper_scenario, registration_inputs

__all__ = [
    "CALIBRATION_STATES",
    "CALIBRATION_SCALE",
    "CalibrationResult",
    "RegistrationLikelihood",
    "calibrate",
    "calibration_truth",
    "likelihood_model",
    "obem_final_estimate",
    "yaw_only_scenario",
]

CALIBRATION_STATES = OBEM_STATES
"""The estimated biases, in order: ``[Δr1, kr1, Δθ1−Δφ1, Δε1, Δr2, kr2, Δθ2−Δφ2, Δε2]`` (eq. 46)."""

CALIBRATION_SCALE = (100.0, 0.01, DEG, DEG) * 2
"""Units of the fitted unconstrained leaves (m, 1, rad, rad per radar): O(1) steps for L-BFGS."""

# Prior variance of the known unit state: small enough that H P Hᵀ (≤ 1e-30·|h|² ≈ 1e-23 m²)
# vanishes against R (≈ 1e5–1e6 m²) in float64, positive so the model's prior check passes.
_UNIT_PRIOR_VAR = 1e-30


def yaw_only_scenario(num_scans: int = 200, *, dtype=None) -> Scenario:
    """The paper's scenario (:func:`~.scenario.paper_scenario`) with zero pitch and roll biases.

    Yaw stays 2° and the azimuth offset 2° (so ``Δθ − Δφ = 0``): then a yaw is an exact azimuth
    rotation and the 8 OBEM states are exactly the identifiable biases (eq. 27), which makes the
    calibration model of :func:`calibrate` correctly specified.

    **Arguments:** ``num_scans`` K (default 200); ``dtype`` (default JAX's default float).

    **Returns:** a :class:`~.scenario.Scenario`.
    """
    s = paper_scenario(num_scans, dtype=dtype)
    return eqx.tree_at(lambda sc: sc.attitude_bias, s, s.attitude_bias.at[:, 1:].set(0.0))


def calibration_truth(scenario: Scenario) -> Float[Array, "8"]:
    """The true biases in :func:`calibrate`'s parametrisation (eq. 46, range convention of §1.7).

    ``obem_truth`` (``Δθ_i − Δφ_i`` merged) with the range pair mapped from the simulator's
    ``r_m = (1 + k) r_t + Δr`` to the paper's ``r_t = (1 − k') r_m − Δr'``: ``k' = k/(1 + k)``,
    ``Δr' = Δr/(1 + k)`` (an exact identity, not an approximation).

    **Arguments:** ``scenario``: a :class:`~.scenario.Scenario`.

    **Returns:** ``(8,)`` ordered as :data:`CALIBRATION_STATES` (m, 1, rad, rad per radar).
    """
    if not isinstance(scenario, Scenario):
        raise InputError(f"`scenario` must be a Scenario; got {type(scenario).__name__}.")
    t = jnp.reshape(obem_truth(scenario.offset_bias, scenario.attitude_bias), (2, 4))
    k = t[:, 1]
    t = t.at[:, 0].set(t[:, 0] / (1.0 + k)).at[:, 1].set(k / (1.0 + k))
    return jnp.reshape(t, (8,))


class RegistrationLikelihood(eqx.Module):
    """``build`` for :func:`jaxtrack.learning.fit`: the registration equation of one recorded track
    as a linear-Gaussian model of a known unit state (module docstring).

    An equinox Module (its arrays are leaves), so :func:`~jaxtrack.learning.fit` traces the data
    instead of baking them into the compiled loop, and one compilation serves every track and a
    ``jax.vmap`` over tracks. Everything that does not depend on β is computed once, here
    (:func:`likelihood_model`): with ``M_i(k) = T_i(k) T_p2ENU(0, Δη_i, Δψ_i)``,

        h_k(β) = [M_1 X_p(raw_1; β_1) − T_1 X_p(raw_1; 0)] − [M_2 X_p(raw_2; β_2) − T_2 X_p(raw_2; 0)],

    which is :func:`~.frames.nonlinear_pseudo_measurement` with the yaw merged into the azimuth
    (the sites ``X_is`` cancel), evaluated with one spherical-to-Cartesian map and one 3×3 product
    per radar and scan — a small graph, which keeps the compilation of the fit short.

    **Fields:**

    - ``raw`` ``(2, K, 3)``: both radars' raw ``[r, θ, ε]`` (m, rad, rad).
    - ``rotation`` ``(2, K, 3, 3)``: ``M_i(k)``, platform frame to ECEF axes.
    - ``offset`` ``(2, K, 3)``: ``T_i(k) X_p(raw_i(k); 0)``, m (the attitude-free terms of eq. 18).
    - ``H`` ``(K, 3, 8)``: eq. (47)'s ``H_OBEM(k)`` (used when ``linearised``).
    - ``R`` ``(K, 3, 3)``: pseudo-measurement noise covariance (m²).
    - ``linearised`` (static): ``H(k) β`` instead of the exact ``h_k(β)``.
    """

    raw: Float[Array, "2 K 3"]
    rotation: Float[Array, "2 K 3 3"]
    offset: Float[Array, "2 K 3"]
    H: Float[Array, "K 3 8"]
    R: Float[Array, "K 3 3"]
    linearised: bool = eqx.field(static=True)

    def biases(self, params: dict) -> Float[Array, "8"]:
        """The natural biases ``β`` (SI, rad) from the fitted leaves: ``params["bias"] * CALIBRATION_SCALE``."""
        u = params["bias"]
        return u * jnp.asarray(CALIBRATION_SCALE, u.dtype)

    def mean(self, beta: Array) -> Float[Array, "K 3"]:
        """``h_k(β)`` (exact, spec §2.6) or ``H(k) β`` (eq. 47) at every scan, ``(K, 3)`` m.

        **Arguments:** ``beta`` ``(8,)`` ordered as :data:`CALIBRATION_STATES` (m, 1, rad, rad).
        """
        if self.linearised:
            return jnp.einsum("kij,j->ki", self.H, beta)
        b = jnp.reshape(beta, (2, 4))
        g = []
        for i in range(2):
            x_p = jax.vmap(offset_corrected_position, in_axes=(0, None))(self.raw[i], b[i])
            g.append(jnp.einsum("kij,kj->ki", self.rotation[i], x_p) - self.offset[i])
        return g[0] - g[1]

    def __call__(self, params: dict) -> LinearGaussianModel:
        """The model whose Kalman-filter log-likelihood is ``Σ_k log N(Z(k); h_k(β), R(k))``.

        **Arguments:** ``params``: ``{"bias": (8,)}`` scaled biases (see :data:`CALIBRATION_SCALE`).

        **Returns:** a :class:`~jaxtrack.models.LinearGaussianModel` with state ``(1,)`` = 1,
        ``H`` ``(K, 3, 1)`` = ``h_k(β)``, ``R`` ``(K, 3, 3)``.
        """
        h = self.mean(self.biases(params))
        dtype = h.dtype
        one = jnp.ones((1, 1), dtype)
        return LinearGaussianModel(one, jnp.zeros((1, 1), dtype), h[..., None], self.R, jnp.ones((1,), dtype),
                                   _UNIT_PRIOR_VAR * one)


class CalibrationResult(eqx.Module):
    """Output of :func:`calibrate`; every vector is ordered as :data:`CALIBRATION_STATES`
    (units m, 1, rad, rad per radar).

    - ``estimate`` ``(8,)``: the maximum-likelihood biases β̂.
    - ``standard_error`` ``(8,)``: from the observed information ``−∇²ℓ(β̂)`` (Harvey 1989 §3.5).
    - ``lower``, ``upper`` ``(8,)``: Wald intervals ``β̂ ∓ z σ`` at ``level``.
    - ``covariance`` ``(8, 8)``: the asymptotic covariance of β̂.
    - ``log_likelihood`` ``()``: ``ℓ(β̂)``, nats.
    - ``num_iterations`` ``()``, ``converged`` ``()``, ``ok`` ``()``: :class:`~jaxtrack.learning.MLEFit`'s diagnostics.
    """

    estimate: Float[Array, "8"]
    standard_error: Float[Array, "8"]
    lower: Float[Array, "8"]
    upper: Float[Array, "8"]
    covariance: Float[Array, "8 8"]
    log_likelihood: Float[Array, ""]
    num_iterations: Int[Array, ""]
    converged: Bool[Array, ""]
    ok: Bool[Array, ""]


def likelihood_model(scans: Scans, scenario: Scenario, *, pitch_roll: ArrayLike | None = None,
                     linearised: bool = False) -> tuple[RegistrationLikelihood, Float[Array, "K 3"]]:
    """The ``build`` and the data ``Z`` of :func:`calibrate` for one recorded track.

    **Arguments:** as :func:`calibrate`.

    **Returns:** ``(build, Z)``: a :class:`RegistrationLikelihood` and the pseudo-measurements ``(K, 3)`` (m).
    """
    if not isinstance(scans, Scans):
        raise InputError(f"`scans` must be Scans (from simulate_scans); got {type(scans).__name__}.")
    if not isinstance(scenario, Scenario):
        raise InputError(f"`scenario` must be a Scenario; got {type(scenario).__name__}.")
    inputs = registration_inputs(scans, scenario.noise_std)
    dtype = inputs.Z.dtype
    if pitch_roll is None:
        pr = jnp.zeros((2, 2), dtype)
    else:
        pr = jnp.asarray(pitch_roll, dtype)
        check_shape("pitch_roll", pr, [(2, 2)])
    # β-independent pieces of h_k, once per track: M_i(k) = T_i(k) T_p2ENU(0, Δη_i, Δψ_i).
    att = jnp.concatenate([jnp.zeros((2, 1), dtype), pr], axis=1)
    enu_to_ecef = jnp.swapaxes(geometry.ecef_to_enu_rotation(scans.sites[..., 0], scans.sites[..., 1]), -1, -2)
    rotation = enu_to_ecef @ attitude_matrix(att)[:, None]
    x0 = jax.vmap(jax.vmap(offset_corrected_position, in_axes=(0, None)), in_axes=(0, None))(
        scans.raw, jnp.zeros(4, dtype))
    # Z = g_2(0) − g_1(0) is formed without attitude (eq. 18), so the offset is T_i X_p(raw_i; 0).
    offset = jnp.einsum("ikab,ikb->ika", enu_to_ecef, x0)
    build = RegistrationLikelihood(scans.raw, rotation, offset, obem_columns(inputs.H), inputs.R, bool(linearised))
    return build, inputs.Z


def calibrate(scans: Scans, scenario: Scenario, *, pitch_roll: ArrayLike | None = None, linearised: bool = False,
              level: float = 0.95, num_iterations: int = 100, initial: ArrayLike | None = None) -> CalibrationResult:
    """Maximum-likelihood calibration of both radars' biases from one recorded track, with intervals.

    Maximises ``ℓ(β) = Σ_k log N(Z(k); h_k(β), R(k))`` (module docstring; registration equation,
    eqs 12–18, exact map of spec §2.6) with :func:`jaxtrack.learning.fit` (L-BFGS), and reports
    the observed-information standard errors and Wald intervals of :class:`~jaxtrack.learning.MLEFit`.
    Works under ``jax.vmap`` over tracks (one compilation for many).

    **Arguments:**

    - ``scans``: the recorded track, :class:`~.scenario.Scans` (from
      :func:`~.scenario.simulate_scans` or real data in the same layout).
    - ``scenario``: supplies the noise standard deviations ``noise_std`` (the radars' data sheet);
      no truth is read from it.
    - ``pitch_roll``: known platform pitch and roll ``(2, 2)`` rad, ``[[Δη1, Δψ1], [Δη2, Δψ2]]``
      (default 0: not identifiable from one track, module docstring).
    - ``linearised``: use eq. (47)'s ``H(k) β`` (the OBEM filter's model) instead of ``h_k(β)``.
    - ``level``: interval coverage, in (0, 1) (default 0.95).
    - ``num_iterations``: L-BFGS iteration cap.
    - ``initial``: starting biases ``(8,)`` in natural units (default 0: the uncalibrated sensor).

    **Returns:** a :class:`CalibrationResult`.

    **Raises:** ``InputError`` for a wrong ``scans``/``scenario`` type, a wrong ``pitch_roll`` or
    ``initial`` shape, or a ``level`` outside (0, 1).
    """
    if not (0.0 < float(level) < 1.0):
        raise InputError(f"`level` must be in (0, 1); got {level}.")
    build, z = likelihood_model(scans, scenario, pitch_roll=pitch_roll, linearised=linearised)
    dtype = z.dtype
    scale = jnp.asarray(CALIBRATION_SCALE, dtype)
    if initial is None:
        u0 = jnp.zeros(8, dtype)
    else:
        b0 = jnp.asarray(initial, dtype)
        check_shape("initial", b0, [(8,)])
        u0 = b0 / scale
    res: MLEFit = fit(build, {"bias": u0}, z, num_iterations=num_iterations)
    # The leaves are plain arrays (natural = unconstrained up to the fixed scale), so MLEFit's
    # delta-method intervals are θ̂ ± z σ: formed here from one covariance, so that the Hessian
    # is traced once (confidence_intervals would evaluate it a second time).
    cov = res.covariance("unconstrained") * jnp.outer(scale, scale)
    est = res.params["bias"] * scale
    se = jnp.sqrt(jnp.diag(cov))
    zq = jax.scipy.special.ndtri(0.5 + 0.5 * float(level))
    return CalibrationResult(
        estimate=est,
        standard_error=se,
        lower=est - zq * se,
        upper=est + zq * se,
        covariance=cov,
        log_likelihood=res.log_likelihood,
        num_iterations=res.num_iterations,
        converged=res.converged,
        ok=res.ok,
    )


def obem_final_estimate(scans: Scans, scenario: Scenario, prior: str = "big") -> Float[Array, "8"]:
    """The OBEM filter's final online estimate β̂(K) on the same track (eqs 47, 49; the study's
    :func:`~.estimators.filter_means` as :func:`~.montecarlo.run_squared_errors` runs it).

    **Arguments:** ``scans``; ``scenario`` (for ``noise_std``); ``prior``: a key of
    :data:`~.estimators.PRIORS` (default ``"big"``, the study's).

    **Returns:** ``(8,)`` ordered as :data:`CALIBRATION_STATES`; the range pair is in the paper's
    convention, like :func:`calibration_truth`.
    """
    if not isinstance(scans, Scans):
        raise InputError(f"`scans` must be Scans (from simulate_scans); got {type(scans).__name__}.")
    inputs = registration_inputs(scans, scenario.noise_std)
    p0 = prior_cov("obem", prior, dtype=inputs.Z.dtype)
    return filter_means(inputs.Z, obem_columns(inputs.H), inputs.R, p0)[-1]

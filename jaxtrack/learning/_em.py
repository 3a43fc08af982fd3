"""Expectation–maximisation for a linear-Gaussian state-space model (Shumway & Stoffer 1982).

Shumway & Stoffer (1982, "An approach to time series smoothing and forecasting using the EM
algorithm", *J. Time Series Analysis* 3(4)) and Ghahramani & Hinton (1996, "Parameter
estimation for linear dynamical systems", Tech. Rep. CRG-TR-96-2) maximise the measurement
likelihood of ``x_k = F x_{k-1} + b_k + w_k``, ``z_k = H x_k + v_k`` by alternating

- **E-step:** the RTS smoother (:func:`~jaxtrack.filters.rts_smoother`) and its lag-one
  cross-covariances (:func:`~jaxtrack.filters._smoother.lag_one_covariances`) give the expected
  complete-data sufficient statistics ``E[x_k x_kᵀ]``, ``E[x_{k+1} x_kᵀ]``, ``E[z_k x_kᵀ]``,
  ``E[z_k z_kᵀ]`` given all measurements, at the current parameters;
- **M-step:** the closed-form maximisers of the expected complete-data log-likelihood
  (Shumway & Stoffer 2017, *Time Series Analysis and Its Applications*, 4th ed., eqs.
  (6.70)–(6.73); Ghahramani & Hinton 1996, eqs. (13)–(17)):
  ``F = S₁₀ S₀₀⁻¹``, ``Q = (S₁₁ − F S₁₀ᵀ − S₁₀ Fᵀ + F S₀₀ Fᵀ)/N_t``, ``H = S_zx S_xx⁻¹``,
  ``R = Σ E[(z − Hx)(z − Hx)ᵀ]/N_z``, ``m₀ = x̂_{0/N}``, ``P₀ = P_{0/N} + (x̂_{0/N} − m₀)(…)ᵀ``.

A parameter named in ``fixed`` keeps its value; the others are maximised given it. The
expected log-likelihood separates into (m₀, P₀), (F, Q) and (H, R) blocks, and within a block
the regression matrix's maximiser does not depend on the covariance (ordinary least squares
with a common covariance), so the update of the free ones given the fixed ones is the exact
conditional maximiser: every iteration is a true EM step and the measurement log-likelihood
cannot decrease (Dempster, Laird & Rubin 1977, Theorem 1).

Missing measurements (``mask``, whole steps or single components) are treated as latent data:
with ``z = Hx + v`` and ``v ~ N(0, R)``, the missing components given ``x`` and the observed ones
are ``N(Hx + K(z_o − H_o x), R − K R)`` with ``K = R_{·o} R_{oo}⁻¹`` (the Gaussian conditional),
so ``E[z xᵀ]`` and ``E[z zᵀ]`` stay linear in the smoothed moments. This is the partial-observation
M-step of Shumway & Stoffer (2017, §6.4, eqs. (6.78)–(6.80)), written for a full (not
block-diagonal) ``R`` and also used for ``H``.

What is ours: many recorded runs (statistics summed over runs, one vmapped smoother per run),
the prior's placement (``first_step="predict"``: the prior sits one transition before the
first measurement, handled by one prepended step without a measurement), a known transition
offset ``b`` and fixed per-step matrices, the whole iteration as one jitted ``lax.while_loop``
and a stopping rule on the log-likelihood's relative change (``tol``).
"""

from __future__ import annotations

from typing import Iterable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._validation import InputError
from ..filters._base import FirstStep
from ..filters._smoother import lag_one_covariances, rts_smoother
from ..filters._updates import symmetrize
from ..models._base import LinearGaussianModel
from ._loop import Move, optimise, progress_bar, tick
from ._runs import any_observed, prepare_runs, select

# The EM parameters, in the order they are carried, and the model fields that hold them.
_NAMES = ("F", "Q", "H", "R", "initial_mean", "initial_cov")
# fit_em's default `tol`: a relative change of 1e-10 in ℓ is far below any statistical meaning
# (ℓ ~ 10³–10⁵ nats: 10⁻⁷–10⁻⁵ nats) yet above the rounding of the E-step's sums.
_DEFAULT_TOL = 1e-10
_NDIM = {"F": 2, "Q": 2, "H": 2, "R": 2, "initial_mean": 1, "initial_cov": 2}


class EMFit(eqx.Module):
    """Result of :func:`fit_em`.

    **Fields:**

    - ``model``: the fitted :class:`~jaxtrack.models.LinearGaussianModel`: the input model with
      its free parameters replaced by the last iterate whose log-likelihood was finite (the
      fixed ones are the input arrays themselves).
    - ``log_likelihood_history`` ``(num_iterations,)``: the total measurement log-likelihood
      (nats, summed over runs and steps) of iterate ``i`` (entry 0: the starting model), i.e.
      **before** the ``i``-th M-step — dynamax's ``fit_em`` convention. After a non-finite
      evaluation the fit stops and the entries from there on repeat the last finite value.
    - ``log_likelihood`` ``()``: the log-likelihood of the returned ``model`` (one more E-step
      after the last M-step), in nats.
    - ``num_steps_taken`` ``()`` int: the number of M-steps that led to ``model``
      (``num_iterations`` unless the fit converged or stopped at a failure). The E-steps run
      are one more.
    - ``converged`` ``()`` bool: the fit stopped because the log-likelihood's relative change
      met ``tol`` (:func:`fit_em`), not at the iteration cap or a failure.
    - ``ok`` ``()`` bool: False if an iterate had a non-finite log-likelihood or invalid
      covariances (the fit then stopped and ``model`` is the last valid iterate).
    """

    model: LinearGaussianModel
    log_likelihood_history: Float[Array, " I"]
    log_likelihood: Float[Array, ""]
    num_steps_taken: Int[Array, ""]
    converged: Bool[Array, ""]
    ok: Bool[Array, ""]


def _check_fixed(fixed) -> tuple[str, ...]:
    if isinstance(fixed, str):
        fixed = (fixed,)
    try:
        names = tuple(fixed)
    except TypeError:
        raise InputError(f"`fixed` must be an iterable of parameter names; got {fixed!r}.") from None
    bad = [n for n in names if n not in _NAMES]
    if bad:
        raise InputError(f"`fixed` names must be among {sorted(_NAMES)}; got {bad}.")
    return tuple(n for n in _NAMES if n in names)


def _check_model(model, fixed: tuple[str, ...]) -> None:
    if not isinstance(model, LinearGaussianModel):
        raise InputError(f"`model` must be a LinearGaussianModel; got {type(model).__name__}.")
    if model.angle_components:
        # The M-step is linear in z − Hx; wrapped angle residuals would make it inexact.
        raise InputError(
            f"`model` has angle components {model.angle_components}; EM needs a linear "
            "measurement without wrapped residuals."
        )
    for name in ("F", "Q", "H", "R"):
        per_step = getattr(model, name).ndim == 3
        if per_step and name not in fixed:
            raise InputError(
                f"`model`.{name} varies per step (shape {getattr(model, name).shape}); EM fits "
                f"time-invariant parameters only: hold it with fixed=(..., {name!r})."
            )
    # With a per-step noise covariance the maximiser of the regression matrix is a weighted
    # least squares, not the closed form used here.
    for mat, cov in (("F", "Q"), ("H", "R")):
        if mat not in fixed and getattr(model, cov).ndim == 3:
            raise InputError(
                f"`model`.{cov} varies per step, so {mat} has no closed-form M-step here; hold "
                f"{mat} fixed too or make {cov} time-invariant."
            )


def _pad_front(a: Array | None, matrix_ndim: int) -> Array | None:
    """A per-step array with its first entry repeated in front (the prepended step's slot)."""
    if a is None or a.ndim == matrix_ndim:
        return a
    return jnp.concatenate([a[:1], a])


def _at(a: Array, j, matrix_ndim: int) -> Array:
    return a if a.ndim == matrix_ndim else a[j]


def _emission_moments(H, R, z, obs, x, Pxx):
    """``E[z xᵀ]`` ``(m, n)`` and ``E[z zᵀ]`` ``(m, m)`` given the observed components (one step).

    Missing components are latent: given ``x`` and the observed ``z_o``, ``z = a + C x + e`` with
    ``K = R_{·o} R_{oo}⁻¹``, ``a = K z_o``, ``C = H − K H_o``, ``e ~ N(0, R − K R_{o·})`` independent
    of ``x`` (Shumway & Stoffer 2017, §6.4). Observed rows of ``K`` are set to the identity
    exactly, so a fully observed step gives ``E[z xᵀ] = z x̂ᵀ`` and ``E[z zᵀ] = z zᵀ`` to the bit.
    """
    m = R.shape[-1]
    eye = jnp.eye(m, dtype=R.dtype)
    both = obs[:, None] & obs[None, :]
    R_oo = jnp.where(both, R, eye)  # R_oo on the observed block, identity elsewhere
    K = jnp.linalg.solve(R_oo, (R * obs[None, :]).T).T
    K = jnp.where(obs[:, None], eye, K * obs[None, :])
    a = K @ z
    C = H - K @ H
    missing = ~obs[:, None] & ~obs[None, :]
    Rc = jnp.where(missing, symmetrize(R - K @ R), 0.0)
    Exx = Pxx + jnp.outer(x, x)
    Cx = C @ x
    Ezx = jnp.outer(a, x) + C @ Exx
    Ezz = jnp.outer(a, a) + jnp.outer(a, Cx) + jnp.outer(Cx, a) + C @ Exx @ C.T + Rc
    return Ezx, Ezz


def _e_step(params, base, z, obs, has_meas):
    """One run: log-likelihood, ok, and the per-step expected sufficient statistics."""
    F, Q, H, R, m0, P0 = params
    model = eqx.tree_at(lambda md: (md.F, md.Q, md.H, md.R, md.initial_mean, md.initial_cov),
                        base, (F, Q, H, R, m0, P0))
    sm = rts_smoother(model, z, mask=obs, first_step="update", throw=False)
    xs, Ps = sm.smoothed_mean, sm.smoothed_cov
    L = xs.shape[0]
    steps = jnp.arange(L)
    # Transition stats for j -> j+1 (j = 0 … L-2), with the known offset b_{j+1} taken off x_{j+1}.
    xn = xs[1:]
    if base.b is not None:
        xn = xn - (jnp.broadcast_to(base.b, xn.shape) if base.b.ndim == 1 else base.b[1:])
    xp = xs[:-1]
    outer = lambda u, v: u[:, :, None] * v[:, None, :]  # noqa: E731  (batched outer products)
    S00 = Ps[:-1] + outer(xp, xp)
    S10 = lag_one_covariances(sm) + outer(xn, xp)
    S11 = Ps[1:] + outer(xn, xn)
    Exx = Ps + outer(xs, xs)
    Ezx, Ezz = jax.vmap(
        lambda j, zj, oj, x, P: _emission_moments(_at(H, j, 2), _at(R, j, 2), zj, oj, x, P)
    )(steps, z, obs, xs, Ps)
    w = has_meas.astype(Exx.dtype)
    stats = (xs[0], Ps[0], S00, S10, S11, Exx * w[:, None, None], Ezx * w[:, None, None],
             Ezz * w[:, None, None])
    ll = sm.filtered.log_likelihood
    return ll, sm.ok & jnp.isfinite(ll), stats


def _m_step(params, stats, fixed, num_trans, num_meas):
    """Closed-form maximisers of the expected complete-data log-likelihood (module docstring)."""
    F, Q, H, R, m0, P0 = params
    x0, P00, S00, S10, S11, Exx, Ezx, Ezz = stats  # leading axes (runs, steps)
    num_runs = x0.shape[0]
    if "initial_mean" not in fixed:
        m0 = jnp.mean(x0, axis=0)
    if "initial_cov" not in fixed:
        d0 = x0 - m0[None, :]
        # Runs' smoothed x̂_0 spread around the common m₀ adds to the mean smoothed P_0.
        P0 = symmetrize(jnp.mean(P00, axis=0) + d0.T @ d0 / num_runs)
    S00, S10, S11 = (jnp.sum(s, axis=0) for s in (S00, S10, S11))  # per step, summed over runs
    if "F" not in fixed:
        # S00 is symmetric: F = S10 S00⁻¹ = (S00⁻¹ S10ᵀ)ᵀ.
        F = jnp.linalg.solve(jnp.sum(S00, axis=0), jnp.sum(S10, axis=0).T).T
    if "Q" not in fixed:
        # Per step, so a fixed per-step F_k enters with its own step; F (new or fixed) is used.
        # F_{j+1} maps step j to j+1 (a per-step F has one entry per step, S00 one per transition).
        Fk = F[1:] if F.ndim == 3 else jnp.broadcast_to(F, S00.shape)
        FS10t = Fk @ jnp.swapaxes(S10, -1, -2)
        resid = S11 - FS10t - jnp.swapaxes(FS10t, -1, -2) + Fk @ S00 @ jnp.swapaxes(Fk, -1, -2)
        Q = symmetrize(jnp.sum(resid, axis=0) / num_trans)
    Exx, Ezx, Ezz = (jnp.sum(s, axis=0) for s in (Exx, Ezx, Ezz))
    if "H" not in fixed:
        H = jnp.linalg.solve(jnp.sum(Exx, axis=0), jnp.sum(Ezx, axis=0).T).T
    if "R" not in fixed:
        Hk = H if H.ndim == 3 else jnp.broadcast_to(H, Ezx.shape)
        HEzx = Hk @ jnp.swapaxes(Ezx, -1, -2)
        resid = Ezz - HEzx - jnp.swapaxes(HEzx, -1, -2) + Hk @ Exx @ jnp.swapaxes(Hk, -1, -2)
        R = symmetrize(jnp.sum(resid, axis=0) / num_meas)
    return F, Q, H, R, m0, P0


class _EMStepper(eqx.Module):
    """EM as a stepper of the shared loop (``_loop``): the next trial is the M-step of the last
    E-step's statistics; a non-finite E-step fails the fit at the last valid iterate."""

    fixed: tuple[str, ...] = eqx.field(static=True)
    num_trans: int = eqx.field(static=True)
    num_meas: int = eqx.field(static=True)

    def init(self, params, aux_dtype):
        return params  # the next parameters to evaluate

    def trial(self, p_next, first):
        return p_next, p_next

    def advance(self, p_next, p, f, ll, stats, good, first):
        # Symmetrised already; a non-finite M-step is caught by the next E-step's `ok`.
        stepped = _m_step(p, stats, self.fixed, self.num_trans, self.num_meas)
        return select(good, stepped, p_next), Move(good, p, ll, None, jnp.zeros((), bool), ~good)


@eqx.filter_jit
def _fit(base, params, z, obs, has_meas, fixed, num_iterations, num_meas, tol, progress):
    num_runs, L, _ = z.shape
    num_trans = num_runs * (L - 1)
    e_step = jax.vmap(_e_step, in_axes=(None, None, 0, 0, None))

    def evaluate(p):
        lls, oks, stats = e_step(p, base, z, obs, has_meas)
        ll = jnp.sum(lls)
        return -ll, ll, stats, jnp.all(oks) & jnp.isfinite(ll)

    def converged_fn(ll1, ll, _):
        # The relative change of the log-likelihood between consecutive iterates (fit_em's `tol`).
        return jnp.abs(ll1 - ll) <= tol * jnp.abs(ll1)

    dtype = params[-1].dtype
    # num_iterations + 1 E-steps at most: iterates 0 … num_iterations, the last one only evaluated.
    out = optimise(evaluate, params, _EMStepper(fixed, num_trans, num_meas), num_iterations, converged_fn, dtype,
                   tick if progress else None)
    # A non-finite start has no finite log-likelihood to report: NaN history.
    history = jnp.where(out.start_ok, out.aux_history, jnp.nan)
    return out.x, history[:-1], history[-1], out.num_steps, out.converged, out.ok


def fit_em(
    model: LinearGaussianModel,
    measurements: ArrayLike,
    *,
    mask: ArrayLike | None = None,
    num_iterations: int = 50,
    fixed: Iterable[str] = ("H",),
    first_step: FirstStep = "update",
    tol: float = _DEFAULT_TOL,
    progress: bool = False,
) -> EMFit:
    """Fit ``F``, ``H``, ``Q``, ``R``, ``initial_mean``, ``initial_cov`` of a linear-Gaussian model by EM.

    Shumway & Stoffer (1982) / Ghahramani & Hinton (1996) expectation–maximisation (module
    docstring: E-step, M-step, missing data, what is ours): each iteration runs the RTS smoother
    on every run at the current parameters, then replaces every parameter not in ``fixed`` by
    its closed-form maximiser. The measurement log-likelihood never decreases. The whole loop is
    one jitted ``lax.while_loop`` (the learning module's one loop, shared with
    :func:`~jaxtrack.learning.fit` and :func:`~jaxtrack.learning.fit_imm`); it stops after
    ``num_iterations`` M-steps or as soon as the log-likelihood stops changing:

    .. math::

        |ℓ_i − ℓ_{i−1}| ≤ \\mathrm{tol}\\,|ℓ_i|,

    with ``ℓ_i`` the total measurement log-likelihood of iterate ``i`` (after ``i`` M-steps); the
    same relative-change rule as :func:`~jaxtrack.learning.fit`'s ``tol``.

    **Arguments:**

    - ``model``: the starting :class:`~jaxtrack.models.LinearGaussianModel` (no angle components).
      Free parameters must be time-invariant; per-step (``(T, ·, ·)``) ``F``/``H``/``Q``/``R`` are
      allowed when held fixed (and ``F``/``H`` free needs ``Q``/``R`` time-invariant). A
      transition offset ``b`` is a known input and is kept.
    - ``measurements``: ``(T, m)`` (one run) or ``(R, T, m)`` (``R`` recorded runs of the same
      system, whose statistics are summed), in the model's measurement units.
    - ``mask``: optional boolean, ``(T,)`` or ``(T, m)`` (one run), ``(R, T)`` or ``(R, T, m)``;
      True = observed. Whole steps and single components may be missing (latent in the M-step).
    - ``num_iterations``: EM iterations (M-steps), a Python int ≥ 1 (static).
    - ``fixed``: names among ``"F"``, ``"H"``, ``"Q"``, ``"R"``, ``"initial_mean"``,
      ``"initial_cov"`` held at their starting values bit for bit. Default ``("H",)``: in tracking
      the measurement matrix is known from the sensor, and with ``F`` and ``H`` both free the
      state's basis is not identified (any invertible ``T`` gives the same likelihood with
      ``T F T⁻¹``, ``H T⁻¹``). Pass ``()`` to fit everything (dynamax's ``fit_em``).
    - ``first_step``: ``"update"`` (the prior is on the state at the first measurement; dynamax's
      convention) or ``"predict"`` (one transition before it), as in
      :func:`~jaxtrack.filters.run_filter`.
    - ``tol``: stop when ``|ℓ_i − ℓ_{i−1}| ≤ tol·|ℓ_i|`` (dimensionless, ≥ 0; default
      ``1e-10``). ``tol=0`` stops only when an iteration leaves ``ℓ`` exactly unchanged, i.e.
      runs all ``num_iterations`` in practice (dynamax's ``fit_em`` has no stopping rule).
    - ``progress``: show a tqdm bar of the iterations (from inside the jitted loop).

    **Returns:** an :class:`EMFit` (fitted model, ``log_likelihood_history`` ``(num_iterations,)``
    before each M-step (entries after a stop repeat the final value), the final
    ``log_likelihood``, ``num_steps_taken``, ``converged``, ``ok``).

    **Raises:** ``InputError`` naming the argument: ``model`` not a ``LinearGaussianModel``, with
    angle components, or with a free per-step parameter; ``fixed`` with an unknown name;
    ``measurements``/``mask`` of the wrong shape or step count (``mask`` not boolean), observed
    non-finite measurements; ``num_iterations`` not an int ≥ 1; ``tol`` negative or not a
    number; a wrong ``first_step``; a single step (no transition) with ``F`` or ``Q`` free.
    """
    if isinstance(num_iterations, bool) or not isinstance(num_iterations, (int, np.integer)):
        raise InputError(f"`num_iterations` must be a Python int ≥ 1; got {num_iterations!r}.")
    if num_iterations < 1:
        raise InputError(f"`num_iterations` must be ≥ 1; got {num_iterations}.")
    if first_step not in ("update", "predict"):
        raise InputError(f"`first_step` must be 'update' or 'predict'; got {first_step!r}.")
    try:
        tol = float(tol)
    except (TypeError, ValueError):
        raise InputError(f"`tol` must be a number ≥ 0; got {tol!r}.") from None
    if not tol >= 0.0:  # also rejects NaN
        raise InputError(f"`tol` must be ≥ 0; got {tol}.")
    fixed = _check_fixed(fixed)
    _check_model(model, fixed)
    z, obs = prepare_runs(model.meas_dim, model.initial_cov.dtype, measurements, mask)
    num_runs, T, m = z.shape
    if model.num_steps is not None and model.num_steps != T:
        raise InputError(
            f"`measurements` has {T} steps but the model's per-step arrays have {model.num_steps}."
        )
    z = z.astype(model.initial_cov.dtype)
    has_meas = jnp.ones((T,), bool)
    base = model
    if first_step == "predict":
        # The prior sits at a step without a measurement, one transition before z_0: prepend it
        # (fully missing, and outside the measurement statistics), then run with the prior at
        # step 0. Per-step arrays get a placeholder first entry (never used: no transition into
        # step 0, and no measurement there).
        z = jnp.concatenate([jnp.zeros((num_runs, 1, m), z.dtype), z], axis=1)
        obs = jnp.concatenate([jnp.zeros((num_runs, 1, m), bool), obs], axis=1)
        has_meas = jnp.concatenate([jnp.zeros((1,), bool), has_meas])
        base = eqx.tree_at(
            lambda md: (md.F, md.Q, md.H, md.R, md.b), model,
            tuple(_pad_front(getattr(model, k), 1 if k == "b" else 2) for k in ("F", "Q", "H", "R", "b")),
            is_leaf=lambda x: x is None,
        )
    if z.shape[1] < 2 and not {"F", "Q"} <= set(fixed):
        raise InputError(
            "`measurements` has a single step and the prior sits at it: there is no transition to "
            "fit F or Q from; hold them fixed or use first_step='predict'."
        )
    params = tuple(getattr(base, k) for k in _NAMES)
    with progress_bar(bool(progress), int(num_iterations), "fit_em") as finish:
        fitted, history, ll, steps, converged, ok = _fit(
            base, params, z, obs, has_meas, fixed, int(num_iterations), num_runs * T, tol, bool(progress)
        )
        finish(steps)
    free = [k for k in _NAMES if k not in fixed]
    out = model
    if free:
        # Fixed arrays stay the input's own objects (bit for bit, per-step ones unpadded).
        out = eqx.tree_at(lambda md: tuple(getattr(md, k) for k in free), model,
                          tuple(fitted[_NAMES.index(k)] for k in free))
    return EMFit(out, history, ll, steps, converged, ok & any_observed(obs))

"""The paper's estimators: the registration Kalman filter (F = I, Q = 0; eqs 17, 20 for AAM,
47, 49 for OBEM) as a :class:`~jaxtrack.models.LinearGaussianModel` run by
:func:`jaxtrack.filters.run_filter`, the priors (spec §6 item 17 [R]), and rectification (Fig. 10).

Batch weighted least squares (V12) is :func:`jaxtrack.estimation.weighted_least_squares`.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ... import geometry
from ..._validation import InputError, check_covariance, check_shape
from ...filters import AbstractUpdateForm, JosephForm, KalmanFilter, StandardForm, run_filter
from ...models import LinearGaussianModel
from .frames import DEG, attitude_matrix, offset_corrected_position

__all__ = [
    "PRIORS",
    "prior_cov",
    "registration_model",
    "RegistrationEstimate",
    "registration_filter",
    "rectify",
]

PRIORS = {
    "big": ((1000.0, 0.05, 5 * DEG, 5 * DEG), (5 * DEG, 5 * DEG, 5 * DEG)),
    "twice_truth": ((600.0, 0.02, 4 * DEG, 4 * DEG), (4 * DEG, 2 * DEG, 2 * DEG)),
}
"""Prior standard deviations σ0 (spec §6 item 17 [R], §4.6): per radar ``(Δr m, k_r, Δθ, Δε)`` and
per platform ``(Δφ, Δη, Δψ)`` (rad). The paper gives none."""

_FORMS = {"joseph": JosephForm(), "standard": StandardForm()}


def prior_cov(model: str = "obem", prior: str = "big", *, dtype=None) -> Float[Array, "n n"]:
    """``P_0 = diag(σ0²)`` for ``model`` ∈ {"aam", "obem", "merged"} and ``prior`` ∈ :data:`PRIORS`.

    OBEM's ``Δθ−Δφ`` state takes the azimuth σ0. β̂_0 = 0 throughout.

    **Arguments:** ``model``, ``prior`` as above; ``dtype`` (default JAX's default float).

    **Returns:** ``(n, n)`` with n = 14, 8 or 12, in (m², 1, rad²).
    """
    if prior not in PRIORS:
        raise InputError(f"`prior` must be one of {sorted(PRIORS)}; got {prior!r}.")
    offset, att = PRIORS[prior]
    if model == "aam":
        std = offset * 2 + att * 2
    elif model == "obem":
        std = offset * 2
    elif model == "merged":
        std = offset * 2 + att[1:] * 2
    else:
        raise InputError(f"`model` must be 'aam', 'obem' or 'merged'; got {model!r}.")
    return jnp.diag(jnp.asarray(std, jnp.result_type(float) if dtype is None else dtype) ** 2)


def registration_model(H: ArrayLike, R: ArrayLike, prior_cov: ArrayLike,
                       prior_mean: ArrayLike | None = None) -> LinearGaussianModel:
    """The registration model as a linear-Gaussian state-space model: a constant bias
    (``F = I``, ``Q = 0``; eqs 20, 49) seen through per-scan ``H(k)``, ``R(k)`` (eqs 17, 47).

    **Arguments:** ``H`` ``(K, 3, n)``; ``R`` ``(K, 3, 3)`` (m²); ``prior_cov`` P_0 ``(n, n)``;
    ``prior_mean`` β̂_0 ``(n,)`` (default 0).

    **Returns:** a :class:`~jaxtrack.models.LinearGaussianModel` whose prior sits at the first scan
    (run it with ``first_step="update"``, the default).
    """
    h = jnp.asarray(H)
    p0 = jnp.asarray(prior_cov)
    n = h.shape[-1]
    m0 = jnp.zeros(n, p0.dtype) if prior_mean is None else jnp.asarray(prior_mean, p0.dtype)
    return LinearGaussianModel(jnp.eye(n, dtype=p0.dtype), jnp.zeros((n, n), p0.dtype), h, R, m0, p0)


class RegistrationEstimate(eqx.Module):
    """Output of :func:`registration_filter`.

    - ``mean`` ``(K, n)``: β̂(k) after each scan.
    - ``cov`` ``(K, n, n)``: P(k) after each scan, or ``None`` unless ``save_cov``.
    - ``final_cov`` ``(n, n)``: P(K).
    """

    mean: Float[Array, "K n"]
    cov: Float[Array, "K n n"] | None
    final_cov: Float[Array, "n n"]


def filter_means(Z: Array, H: Array, R: Array, prior_cov: Array) -> Float[Array, "K n"]:
    """β̂(k) of the Joseph-form registration filter from β̂_0 = 0, without input checks and
    without raising on non-finite values (for use inside ``vmap``).

    **Arguments:**

    - ``Z``: pseudo-measurements, ``(K, 3)``, m; ``H``: measurement matrices, ``(K, 3, n)``.
    - ``R``: pseudo-measurement noise covariances, ``(K, 3, 3)``, m²; ``prior_cov``: ``P_0``, ``(n, n)``.

    **Returns:** the filtered bias estimates β̂(k), ``(K, n)``, in the units of the bias components.
    """
    model = registration_model(H, R, prior_cov)
    return run_filter(KalmanFilter(), model, Z, save="mean", throw=False).filtered_mean


def registration_filter(Z: ArrayLike, H: ArrayLike, R: ArrayLike, prior_cov: ArrayLike, *,
                        prior_mean: ArrayLike | None = None, form: AbstractUpdateForm | str = JosephForm(),
                        save_cov: bool = False) -> RegistrationEstimate:
    """The paper's Kalman filter over scans, F = I and Q = 0 (eqs 17, 20 for AAM; 47, 49 for OBEM).

    :func:`jaxtrack.filters.run_filter` with :class:`~jaxtrack.filters.KalmanFilter` on
    :func:`registration_model`: with a constant bias the prediction is the identity, and each scan
    is one update ``S = HPHᵀ + R``, ``K = PHᵀS⁻¹``, ``β̂ ← β̂ + K(Z − Hβ̂)``, with
    ``P ← (I − KH)P(I − KH)ᵀ + KRKᵀ`` (Joseph, default) or ``P ← (I − KH)P`` (standard form). AAM
    and OBEM differ only in the columns of H: pass ``H_AAM`` or :func:`obem_columns` of it.

    **Arguments:**

    - ``Z`` ``(K, 3)`` pseudo-measurements (m); ``H`` ``(K, 3, n)``; ``R`` ``(K, 3, 3)`` (m²).
    - ``prior_cov`` P_0 ``(n, n)`` (see :func:`prior_cov`); ``prior_mean`` β̂_0 (default 0).
    - ``form``: :class:`~jaxtrack.filters.JosephForm` (default) or
      :class:`~jaxtrack.filters.StandardForm` (V12), or their names ``"joseph"``, ``"standard"``.
    - ``save_cov``: keep P(k) at every scan.

    **Returns:** a :class:`RegistrationEstimate`. Vectorise over runs with ``jax.vmap``.
    """
    if isinstance(form, str):
        if form not in _FORMS:
            raise InputError(f"`form` must be 'joseph', 'standard' or an update form; got {form!r}.")
        form = _FORMS[form]
    z = jnp.asarray(Z)
    z = z.astype(jnp.result_type(z, float))
    h, r = jnp.asarray(H, z.dtype), jnp.asarray(R, z.dtype)
    check_shape("Z", z, [(None, 3)])
    k = z.shape[0]
    check_shape("H", h, [(k, 3, None)])
    n = h.shape[-1]
    check_shape("R", r, [(k, 3, 3)])
    p0 = jnp.asarray(prior_cov, z.dtype)
    check_shape("prior_cov", p0, [(n, n)])
    check_covariance("prior_cov", p0)
    if prior_mean is not None:
        check_shape("prior_mean", prior_mean, [(n,)])
    model = registration_model(h, r, p0, prior_mean)
    res = run_filter(KalmanFilter(form=form), model, z, save="all" if save_cov else "mean")
    return RegistrationEstimate(res.filtered_mean, res.filtered_cov if save_cov else None, res.final_cov)


def rectify(raw: ArrayLike, offset_estimate: ArrayLike, pitch_roll: ArrayLike) -> Float[Array, "... 3"]:
    """Rectified radar position in its ENU frame (Fig. 10; spec §2.6):
    ``T_p2ENU(0, Δη̂, Δψ̂) · sph2cart(r − Δr̂ − k̂_r r, θ − (Δθ−Δφ)^, ε − Δε̂)``.

    **Arguments:** ``raw`` ``(..., 3)`` (m, rad, rad); ``offset_estimate`` ``(..., 4)`` whose
    azimuth entry is the merged ``Δθ−Δφ``; ``pitch_roll`` ``(..., 2)`` rad, 0 for OBEM and for
    AAM without pitch and roll. Yaw is 0. At most one leading (scan) axis.

    **Returns:** ``(..., 3)`` ENU position, m.
    """
    raw = jnp.asarray(raw)
    raw = raw.astype(jnp.result_type(raw, float))
    pr = jnp.asarray(pitch_roll, raw.dtype)
    att = jnp.concatenate([jnp.zeros(pr.shape[:-1] + (1,), raw.dtype), pr], axis=-1)
    x_p = jax.vmap(offset_corrected_position)(jnp.atleast_2d(raw), jnp.atleast_2d(offset_estimate))
    x_p = jnp.reshape(x_p, jnp.shape(raw))
    return geometry.rotate(attitude_matrix(att), x_p)

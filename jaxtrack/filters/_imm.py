"""Interacting multiple model (IMM) filter over any Gaussian member filter of jaxtrack.

The IMM of Blom & Bar-Shalom (1988, IEEE TAC 33(8), 780–783), in the notation of Bar-Shalom,
Li & Kirubarajan (2001), *Estimation with Applications to Tracking and Navigation*, §11.6.6
("the IMM estimator", eqs. 11.6.6-1 … 11.6.6-21 for the cycle below). One cycle at step ``k``,
with ``p_ij = P(mode j at k | mode i at k−1)`` and ``μ_i`` the mode probabilities at ``k − 1``:

1. predicted mode probabilities ``c̄_j = Σ_i p_ij μ_i`` and mixing probabilities
   ``μ_{i|j} = p_ij μ_i / c̄_j`` (eqs. 11.6.6-6, -7);
2. mixed initial conditions for member ``j`` (eqs. 11.6.6-8, -9):
   ``x̂⁰_j = Σ_i μ_{i|j} x̂_i``, ``P⁰_j = Σ_i μ_{i|j} [P_i + (x̂_i − x̂⁰_j)(x̂_i − x̂⁰_j)ᵀ]``
   (the second term is the *spread of the means*);
3. member ``j``'s own ``predict`` and ``update`` from ``(x̂⁰_j, P⁰_j)`` (eq. 11.6.6-10), giving
   its innovation likelihood ``Λ_j = N(ν_j; 0, S_j)`` (eq. 11.6.6-11), read from the member's
   :class:`~jaxtrack.filters.Conditioned` ``log_likelihood``;
4. mode probabilities ``μ_j = Λ_j c̄_j / Σ_l Λ_l c̄_l`` (eqs. 11.6.6-12, -13), computed in log
   space with ``logsumexp`` so that very unlikely modes do not underflow to 0/0; the step's
   log-likelihood is ``log Σ_l Λ_l c̄_l`` (the normaliser);
5. the combined output (eqs. 11.6.6-14, -15): ``x̂ = Σ_j μ_j x̂_j``,
   ``P = Σ_j μ_j [P_j + (x̂_j − x̂)(x̂_j − x̂)ᵀ]``; it is output only, never fed back.

Members of different state dimension (e.g. constant velocity ``[x, y, vx, vy]`` and the
nearly-constant turn ``[x, y, vx, vy, ω]``) are mixed in a **common state** of ``N``
components. Which common component each member component is comes from the members'
:attr:`~jaxtrack.models.AbstractStateSpaceModel.state_layout` (:mod:`jaxtrack.models._layout`):
the common layout is the longest member's, followed by the components the others add, and a
member's ``vx`` is the common ``vx`` wherever the two layouts put it (a 2-D and a 3-D
constant-velocity member: the 2-D member's ``[x, y, vx, vy]`` are common components
``0, 1, 3, 4`` of ``[x, y, z, vx, vy, vz]``). ``state_indices=`` declares the embedding
instead; a member without a declared layout falls back to the *prefix rule* (its state is the
first ``n_i`` common components), which is checked against the layouts that are declared. For
mixing and for the combined output a member's mean is *augmented* with ``augment_mean`` on the
common components it lacks and its covariance with ``diag(augment_var)`` there (zero
cross-covariance); after mixing, a member takes its own components of the mixed moments (the
*projection*). The defaults ``augment_mean = 0``, ``augment_var = 0`` say that a CV
target is a CT target with turn rate exactly 0 — the usual choice for CV + CT (e.g. Granström,
Willett & Bar-Shalom 2015 discuss alternatives; pass your own to use them).

Square-root members (:class:`~jaxtrack.filters.SquareRootKalmanFilter`,
:class:`~jaxtrack.filters.SquareRootUnscentedKalmanFilter`) run their predict and update on
Cholesky factors; the interaction and the combination are moment matching, a weighted sum of
covariances plus the spread of the means, which has no factor form of the same cost. So the IMM
keeps every member's covariance, factors the mixed covariance ``P⁰_j`` once per step
(``cholesky``) before the member's predict, and squares the updated factor after its update.
The member's own recursion keeps the square-root filter's numerics; the mixing is in covariance
form, as in the covariance-form IMM.
"""

from __future__ import annotations

from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._deprecation import renamed
from .._export import Exportable
from .._validation import (
    InputError,
    check_finite,
    check_shape,
    is_concrete,
    throw_unless_ok,
)
from ..models import AbstractStateSpaceModel
from ..models._layout import common_layout
from ._base import AbstractFilter, FirstStep, _outer_factor, prepare_measurements
from ._linalg import all_rows, cholesky
from ._updates import symmetrize


def _is_prefix(idx: tuple[int, ...]) -> bool:
    return idx == tuple(range(len(idx)))


def _embed_mean(x: Array, aug: Array, idx: tuple[int, ...]) -> Array:
    """Member mean ``(n_i,)`` → common ``(N,)``: component ``j`` at ``idx[j]``, the rest from ``aug``."""
    n, N = x.shape[0], aug.shape[0]
    if _is_prefix(idx):  # the common case (CV + turn models): slices, no scatter
        return x if n == N else jnp.concatenate([x, aug[n:].astype(x.dtype)])
    return aug.astype(x.dtype).at[np.asarray(idx)].set(x)


def _embed_cov(P: Array, var: Array, idx: tuple[int, ...]) -> Array:
    """Member covariance ``(n_i, n_i)`` → ``(N, N)``: ``P`` on ``idx``, ``diag(var)`` elsewhere, 0 across."""
    n, N = P.shape[0], var.shape[0]
    if n == N and _is_prefix(idx):
        return P
    if _is_prefix(idx):
        out = jnp.zeros((N, N), P.dtype).at[:n, :n].set(P)
        return out.at[n:, n:].set(jnp.diag(var[n:].astype(P.dtype)))
    rest = np.setdiff1d(np.arange(N), idx)
    out = jnp.zeros((N, N), P.dtype).at[np.ix_(idx, idx)].set(P)
    return out.at[rest, rest].set(var[rest].astype(P.dtype))


def _project(x: Array, P: Array, idx: tuple[int, ...]) -> tuple[Array, Array]:
    """Common moments ``(N,)``, ``(N, N)`` → a member's components ``idx``."""
    if _is_prefix(idx):
        n = len(idx)
        return x[:n], P[:n, :n]
    i = np.asarray(idx)
    return x[i], P[np.ix_(i, i)]


def _project_columns(P: Array, idx: tuple[int, ...]) -> Array:
    """The columns ``idx`` of a common ``(N, N)`` matrix: ``(N, n_i)``."""
    return P[:, : len(idx)] if _is_prefix(idx) else P[:, np.asarray(idx)]


def _member_indices(models, state_indices) -> tuple[tuple[tuple[int, ...], ...], tuple[str, ...] | None, int]:
    """Where each member's components sit in the common state: ``(indices, common layout, N)``.

    Declared ``state_indices`` win; else the members' layouts when all declare one; else the
    prefix rule, checked against the layouts that are declared.
    """
    dims = [m.state_dim for m in models]
    if state_indices is not None:
        idx = tuple(tuple(int(i) for i in row) for row in state_indices)
        if len(idx) != len(models):
            raise InputError(f"`state_indices` must hold one index tuple per member ({len(models)}); got {len(idx)}.")
        for j, (row, n) in enumerate(zip(idx, dims)):
            if len(row) != n or len(set(row)) != n or min(row) < 0:
                raise InputError(f"`state_indices[{j}]` must be {n} distinct non-negative indices (member {j}'s "
                                 f"state has {n} components); got {row}.")
        N = max(max(row) for row in idx) + 1
        missing = set(range(N)) - set().union(*map(set, idx))
        if missing:
            raise InputError(f"`state_indices` leave common components {sorted(missing)} to no member.")
        return idx, None, N
    layouts = [m.state_layout for m in models]
    if all(lay is not None for lay in layouts):
        common, idx = common_layout(layouts)
        return idx, common, len(common)
    N = max(dims)
    known = [(j, lay) for j, lay in enumerate(layouts) if lay is not None]
    longest = max((lay for _, lay in known), key=len, default=())
    for j, lay in known:
        if lay != longest[: len(lay)]:
            raise InputError(
                f"`members[{j}]`'s state {lay} is not a prefix of {longest}, and a member without a "
                f"declared state layout makes the IMM use the prefix rule (module docstring): declare "
                f"every member's layout (e.g. LinearTransition(..., state_layout=...)) or pass state_indices."
            )
    return tuple(tuple(range(n)) for n in dims), None, N


def _native_cov(f: AbstractFilter, P: Array) -> Array:
    """A covariance in the form member ``f`` carries: its Cholesky factor for a square-root filter."""
    return cholesky(P) if f.square_root else P


def _covariance(f: AbstractFilter, C: Array) -> Array:
    """Member ``f``'s carried covariance form ``C`` as a covariance (``C Cᵀ`` for a factor)."""
    return _outer_factor(C) if f.square_root else C


# The traced twin of the constructor's concrete checks of `transition_probs` and `initial_probs`
# (a matrix built inside jit/vmap/grad is not seen there). Tolerance 1e-6 on the sums: the dtype
# the rows were computed in (a float32 softmax sums to 1 ± 3e-8) is not known here; a real
# error (a row summing to 0.95) is far outside it.
_TRACED_SUM_TOL = 1e-6


def _probabilities_ok(P: Array, mu: Array) -> Array:
    """Scalar bool: ``P`` row-stochastic and ``mu`` a distribution (finite, ≥ 0, sums 1 ± 1e-6)."""
    ok = jnp.all(jnp.isfinite(P)) & jnp.all(P >= 0) & jnp.all(jnp.abs(P.sum(axis=1) - 1) <= _TRACED_SUM_TOL)
    return ok & jnp.all(jnp.isfinite(mu)) & jnp.all(mu >= 0) & (jnp.abs(mu.sum() - 1) <= _TRACED_SUM_TOL)


def _moment_match(weights: Array, means: Array, covs: Array) -> tuple[Array, Array]:
    """``Σ_i w_i x_i`` and ``Σ_i w_i [P_i + (x_i − x̄)(x_i − x̄)ᵀ]`` (BLK 2001 eqs. 11.6.6-8, -9).

    ``weights`` ``(M,)``, ``means`` ``(M, N)``, ``covs`` ``(M, N, N)``.

    The sums over the ``M`` members are unrolled into element-wise adds (``M`` is small and
    static): under ``vmap`` over runs a reduction over a short middle axis is a strided loop,
    while the unrolled adds fuse into one pass (measured 1.8–2.6× on the 3-member filter job of
    ``benchmarks/imm.py``, same results to 1e-11 m).
    """
    M = means.shape[0]
    mean = weights[0] * means[0]
    for i in range(1, M):
        mean = mean + weights[i] * means[i]
    cov = None
    for i in range(M):
        d = means[i] - mean
        term = weights[i] * (covs[i] + d[:, None] * d[None, :])
        cov = term if cov is None else cov + term
    return mean, symmetrize(cov)


class IMMState(eqx.Module):
    """What the IMM carries from one measurement to the next (one trajectory).

    **Fields:** ``means``, ``covs``: tuples of the members' filtered ``x̂_j`` ``(n_j,)`` and
    ``P_j`` ``(n_j, n_j)`` (before the first step: their priors); ``mode_probs`` ``(M,)``: ``μ_j``;
    ``log_likelihood`` ``()``: the sum of the steps' ``log Σ_j Λ_j c̄_j``; ``step`` ``()`` int;
    ``ok`` ``()`` bool: False once something became non-finite.
    """

    means: tuple
    covs: tuple
    mode_probs: Float[Array, " M"]
    log_likelihood: Float[Array, ""]
    step: Int[Array, ""]
    ok: Bool[Array, ""]


class IMMStepOutput(eqx.Module):
    """One IMM step's outputs besides the new state.

    ``filtered_mean`` ``(N,)``, ``filtered_cov`` ``(N, N)``: the combined estimate (eqs.
    11.6.6-14, -15); ``mode_probs`` ``(M,)``; ``member_log_likelihoods`` ``(M,)``: ``log Λ_j``;
    ``log_likelihood`` ``()``: this step's ``log Σ_j Λ_j c̄_j``. (``mean`` and ``cov``: deprecated
    aliases of the first two.)
    """

    filtered_mean: Float[Array, " N"]
    filtered_cov: Float[Array, "N N"]
    mode_probs: Float[Array, " M"]
    member_log_likelihoods: Float[Array, " M"]
    log_likelihood: Float[Array, ""]

    mean = renamed("mean", "filtered_mean")
    cov = renamed("cov", "filtered_cov")


class InteractingMultipleModel(eqx.Module):
    """Interacting multiple model estimator (Blom & Bar-Shalom 1988; BLK 2001 §11.6.6).

    **Arguments:**

    - ``members``: a sequence of ``(filter, model)`` pairs, ``M ≥ 1``: any jaxtrack filter
      (:class:`~jaxtrack.filters.KalmanFilter`,
      :class:`~jaxtrack.filters.ExtendedKalmanFilter`,
      :class:`~jaxtrack.filters.UnscentedKalmanFilter`,
      :class:`~jaxtrack.filters.IteratedExtendedKalmanFilter`, the square-root filters (module
      docstring), …) with its
      :class:`~jaxtrack.models.AbstractStateSpaceModel`. All models share the measurement
      dimension; each model's prior is its member's state before the first step.
    - ``transition_probs``: the Markov mode-transition matrix ``p_ij`` ``(M, M)``, row ``i`` the
      distribution of the next mode given mode ``i`` (rows sum to 1, entries ≥ 0). An array
      leaf: differentiate through it, or build it with :meth:`from_logits` so that rows stay
      stochastic under gradient steps.
    - ``initial_probs``: the mode probabilities ``(M,)`` where the priors sit (``first_step``:
      at the first measurement, or one transition before it). Default uniform.
    - ``augment_mean``, ``augment_var``: ``(N,)``, only for members of different layouts: the
      mean and variance given to the common components a member lacks (module docstring;
      default 0 and 0).
    - ``state_indices``: optional, one tuple per member: ``state_indices[j][c]`` is the common
      component of member ``j``'s component ``c`` (declares the embedding; default: derived from
      the members' ``state_layout``, module docstring).

    The common state's layout is ``state_layout`` (None when not derived from layouts) and the
    embedding ``member_indices``.

    **Raises:** ``InputError`` naming the argument: not a (filter, model) pair, different
    measurement dimensions, members whose layouts cannot be embedded (a declared layout that is
    not a prefix of another while some member declares none), bad ``state_indices``,
    ``transition_probs`` not ``(M, M)``, negative, or (when concrete) rows not summing to 1,
    ``initial_probs`` not ``(M,)`` / negative / not summing to 1.
    """

    filters: tuple
    models: tuple
    transition_probs: Float[Array, "M M"]
    initial_probs: Float[Array, " M"]
    augment_mean: Float[Array, " N"]
    augment_var: Float[Array, " N"]
    member_indices: tuple[tuple[int, ...], ...] = eqx.field(static=True)
    state_layout: tuple[str, ...] | None = eqx.field(static=True)

    def __init__(
        self,
        members: Sequence,
        transition_probs: ArrayLike | Sequence,
        initial_probs: ArrayLike | Sequence | None = None,
        *,
        augment_mean: ArrayLike | Sequence | None = None,
        augment_var: ArrayLike | Sequence | None = None,
        state_indices: Sequence[Sequence[int]] | None = None,
    ):
        members = tuple(members)
        if len(members) == 0:
            raise InputError("`members` must hold at least one (filter, model) pair; got none.")
        filters, models = [], []
        for i, pair in enumerate(members):
            if not (isinstance(pair, (tuple, list)) and len(pair) == 2):
                raise InputError(f"`members[{i}]` must be a (filter, model) pair; got {pair!r}.")
            f, m = pair
            if not isinstance(f, AbstractFilter):
                raise InputError(f"`members[{i}]`'s filter must be a jaxtrack filter; got {type(f).__name__}.")
            if not isinstance(m, AbstractStateSpaceModel):
                raise InputError(
                    f"`members[{i}]`'s model must be a jaxtrack state-space model; got {type(m).__name__}."
                )
            f.check_model(m)
            filters.append(f)
            models.append(m)
        meas = {m.meas_dim for m in models}
        if len(meas) > 1:
            raise InputError(f"`members`' models must share the measurement dimension; got {sorted(meas)}.")
        M = len(models)
        member_indices, common, N = _member_indices(models, state_indices)
        dtype = jnp.result_type(*(m.initial_cov.dtype for m in models))
        P = jnp.asarray(transition_probs)
        given = P.dtype  # the row-sum tolerance follows the precision the rows were computed in
        P = P.astype(jnp.result_type(P, dtype))
        check_shape("transition_probs", P, [(M, M)])
        if is_concrete(P):
            Pn = np.asarray(P)
            if not np.all(np.isfinite(Pn)) or np.any(Pn < 0):
                raise InputError("`transition_probs` must be finite and non-negative.")
            rows = Pn.sum(axis=1)
            # 1e-8, or a few rounding units of a narrower type (float32 softmax rows sum to 1 ± 3e-8).
            tol = max(1e-8, 16 * float(jnp.finfo(given).eps))
            if not np.allclose(rows, 1.0, rtol=0, atol=tol):
                raise InputError(
                    f"`transition_probs` rows must sum to 1 (row i: the next mode's distribution "
                    f"given mode i); got row sums {rows}."
                )
        mu = jnp.full((M,), 1.0 / M, P.dtype) if initial_probs is None else jnp.asarray(initial_probs)
        given = mu.dtype
        mu = mu.astype(jnp.result_type(mu, P.dtype))
        check_shape("initial_probs", mu, [(M,)])
        if is_concrete(mu):
            mun = np.asarray(mu)
            tol = max(1e-8, 16 * float(jnp.finfo(given).eps))
            if not np.all(np.isfinite(mun)) or np.any(mun < 0) or not np.isclose(mun.sum(), 1.0, rtol=0, atol=tol):
                raise InputError(f"`initial_probs` must be non-negative and sum to 1; got {mun}.")
        am = jnp.zeros((N,), P.dtype) if augment_mean is None else jnp.asarray(augment_mean).astype(P.dtype)
        av = jnp.zeros((N,), P.dtype) if augment_var is None else jnp.asarray(augment_var).astype(P.dtype)
        check_shape("augment_mean", am, [(N,)])
        check_shape("augment_var", av, [(N,)])
        check_finite("augment_mean", am)
        if is_concrete(av) and np.any(np.asarray(av) < 0):
            raise InputError("`augment_var` must be non-negative.")
        self.filters = tuple(filters)
        self.models = tuple(models)
        self.transition_probs = P
        self.initial_probs = mu
        self.augment_mean = am
        self.augment_var = av
        self.member_indices = member_indices
        self.state_layout = common

    @classmethod
    def from_logits(
        cls,
        members: Sequence,
        logits: ArrayLike | Sequence,
        initial_probs: ArrayLike | Sequence | None = None,
        **kwargs,
    ) -> "InteractingMultipleModel":
        """Build the IMM with ``p_ij = softmax_j(logits_ij)``: rows stochastic for any logits.

        **Arguments:** ``members``, ``initial_probs``, ``**kwargs`` as for the constructor;
        ``logits``: ``(M, M)`` unconstrained reals (a gradient step on them keeps every row a
        distribution). **Returns:** an :class:`InteractingMultipleModel`.
        """
        logits = jnp.asarray(logits)
        check_shape("logits", logits, [(None, None)])
        return cls(members, jax.nn.softmax(logits, axis=-1), initial_probs, **kwargs)

    @property
    def num_modes(self) -> int:
        """``M``, the number of members."""
        return len(self.models)

    @property
    def state_dim(self) -> int:
        """``N``, the common (largest) state dimension."""
        return self.augment_mean.shape[0]

    def init(self) -> IMMState:
        """The state before the first measurement: the members' priors and ``initial_probs``."""
        dtype = self.transition_probs.dtype
        return IMMState(
            tuple(m.initial_mean for m in self.models),
            tuple(m.initial_cov for m in self.models),
            self.initial_probs,
            jnp.zeros((), dtype),
            jnp.zeros((), jnp.int32),
            _probabilities_ok(self.transition_probs, self.initial_probs),
        )

    def _common(self, means, covs):
        X = jnp.stack([_embed_mean(x, self.augment_mean, i) for x, i in zip(means, self.member_indices)])
        P = jnp.stack([_embed_cov(c, self.augment_var, i) for c, i in zip(covs, self.member_indices)])
        return X, P

    def step(
        self,
        state: IMMState,
        z: ArrayLike,
        observed: ArrayLike | None = None,
        *,
        first_step: FirstStep = "update",
    ) -> tuple[IMMState, IMMStepOutput]:
        """One IMM cycle (interaction, member predict + update, mode update, combination).

        **Arguments:**

        - ``state``: the :class:`IMMState` after measurement ``k − 1`` (from :meth:`init` first).
        - ``z``: measurement ``k``, ``(m,)``; ``observed``: optional boolean ``(m,)``.
        - ``first_step``: ``"update"``: the priors and ``initial_probs`` sit at the first
          measurement, so step 0 neither mixes nor predicts (``c̄ = initial_probs``);
          ``"predict"``: they sit one transition before it, so step 0 is a full cycle.

        **Returns:** ``(new_state, IMMStepOutput)``.
        """
        k = state.step
        dtype = state.mode_probs.dtype
        z = jnp.asarray(z, dtype)
        observed = jnp.ones(z.shape, bool) if observed is None else jnp.asarray(observed)
        z = jnp.where(observed, z, 0.0)
        mu = state.mode_probs
        p = self.transition_probs
        # 1. c̄_j = Σ_i p_ij μ_i, μ_{i|j} = p_ij μ_i / c̄_j (BLK eqs. 11.6.6-6, -7). A mode no
        # one can enter has c̄_j = 0: its mixing weights are set to 0 (guarded divisor, so that
        # gradients stay finite); its likelihood weight is then 0 as well.
        cbar = mu @ p
        safe = jnp.where(cbar > 0, cbar, 1.0)
        mix = jnp.where(cbar[None, :] > 0, p * mu[:, None] / safe[None, :], 0.0)  # (i, j)
        X, P = self._common(state.means, state.covs)
        at_start = (k == 0) if first_step == "update" else jnp.zeros((), bool)
        log_cbar = jnp.log(jnp.where(at_start, mu, cbar))
        posts = []
        for j, (f, model) in enumerate(zip(self.filters, self.models)):
            # 2. mixed initial condition of member j (eqs. 11.6.6-8, -9), projected to its components.
            x0, P0 = _project(*_moment_match(mix[:, j], X, P), self.member_indices[j])
            # 3. the member's own predict and update (eq. 11.6.6-10).
            pm, pc = f.predict(model, x0, _native_cov(f, P0), k)
            if first_step == "update":
                # The priors already sit at the first measurement: no mixing, no transition.
                pm = jnp.where(at_start, state.means[j], pm)
                pc = jnp.where(at_start, _native_cov(f, state.covs[j]), pc)
            posts.append(f.update(model, pm, pc, z, observed, k))
        # 4. μ_j ∝ Λ_j c̄_j in log space (eqs. 11.6.6-11 … -13).
        loglam = jnp.stack([c.log_likelihood for c in posts])
        joint = loglam + log_cbar
        step_ll = jax.scipy.special.logsumexp(joint)
        new_mu = jnp.exp(joint - step_ll)
        # 5. combined output (eqs. 11.6.6-14, -15).
        post_covs = [_covariance(f, c.cov) for f, c in zip(self.filters, posts)]
        Xp, Pp = self._common([c.mean for c in posts], post_covs)
        mean, cov = _moment_match(new_mu, Xp, Pp)
        ll = state.log_likelihood + step_ll
        # Finite members, mode probabilities and log-likelihood (the combination of finite
        # members is finite). Checking the combined mean and covariance instead recomputed the
        # whole moment match inside the check under vmap (XLA fuses it into every element):
        # a quarter of the IMM Monte Carlo step (3 members, 2,048 runs a block).
        finite = jnp.isfinite(ll) & all_rows(jnp.isfinite(new_mu))
        for c, c_cov in zip(posts, post_covs):
            finite = finite & all_rows(jnp.isfinite(c.mean)) & all_rows(all_rows(jnp.isfinite(c_cov)))
        new_state = IMMState(
            tuple(c.mean for c in posts), tuple(post_covs), new_mu, ll, k + 1, state.ok & finite
        )
        return new_state, IMMStepOutput(mean, cov, new_mu, loglam, step_ll)


class IMMResult(Exportable, eqx.Module):
    """Output of :func:`run_imm` for one trajectory of ``T`` steps.

    **Fields:** ``filtered_mean`` ``(T, N)``, ``filtered_cov`` ``(T, N, N)``: the combined
    ``x̂_{k/k}``, ``P_{k/k}`` (named as in :class:`~jaxtrack.filters.FilterResult`; ``mean`` and
    ``cov`` are deprecated aliases); ``mode_probs`` ``(T, M)``; ``member_means``,
    ``member_covs``: tuples of ``(T, n_j)`` and ``(T, n_j, n_j)`` (each member's filtered
    moments); ``member_log_likelihoods`` ``(T, M)``: ``log Λ_j`` per step; ``log_likelihood``
    ``()``: ``Σ_k log Σ_j Λ_j c̄_j``; ``ok`` ``()`` bool.

    **Export** (:mod:`jaxtrack._export`): ``to_dict()``, ``save(path)`` / ``IMMResult.load(path)``
    (one ``.npz``, bit for bit), ``to_xarray()`` and ``to_pandas()`` (one row per step) with the
    optional ``export`` extra.
    """

    filtered_mean: Float[Array, "T N"]
    filtered_cov: Float[Array, "T N N"]
    mode_probs: Float[Array, "T M"]
    member_means: tuple
    member_covs: tuple
    member_log_likelihoods: Float[Array, "T M"]
    log_likelihood: Float[Array, ""]
    ok: Bool[Array, ""]

    mean = renamed("mean", "filtered_mean")
    cov = renamed("cov", "filtered_cov")

    _export_kind = "jaxtrack.IMMResult"
    _export_renamed = {"mean": "filtered_mean", "cov": "filtered_cov"}
    _export_dims = {"filtered_mean": ("time", "state"), "filtered_cov": ("time", "state", "state_col"),
                    "mode_probs": ("time", "mode"),
                    "member_means": ("time", "state"), "member_covs": ("time", "state", "state_col"),
                    "member_log_likelihoods": ("time", "mode"), "log_likelihood": (), "ok": ()}
    _export_units = {"filtered_mean": "state units", "filtered_cov": "state units squared",
                     "mode_probs": "probability", "member_means": "state units", "member_covs": "state units squared",
                     "member_log_likelihoods": "nats", "log_likelihood": "nats"}


@eqx.filter_jit
def _run_imm_jit(imm, z, observed, first_step):
    def body(state, inputs):
        zk, ok = inputs
        state, out = imm.step(state, zk, ok, first_step=first_step)
        return state, (out, state.means, state.covs)

    # Rematerialised step (no effect without `grad`): a gradient through the IMM (fit_imm,
    # imm_log_likelihood) recomputes each step from its carry instead of storing ~10³
    # intermediates per step: a smaller program to compile and less memory traffic.
    final, (out, means, covs) = jax.lax.scan(jax.checkpoint(body, prevent_cse=False), imm.init(), (z, observed))
    result = IMMResult(
        out.filtered_mean, out.filtered_cov, out.mode_probs, means, covs, out.member_log_likelihoods,
        final.log_likelihood, final.ok,
    )
    # `throw` is applied by run_imm, outside this program (no host callback in it: the persistent
    # compilation cache keeps it).
    return result


_IMM_FAILED = (
    "jaxtrack: the IMM produced a non-finite mean, covariance, mode probability or "
    "log-likelihood, or its `transition_probs` / `initial_probs` (built under jit, vmap or "
    "grad, so not checked by the constructor) are not stochastic: entries >= 0, rows "
    "summing to 1. Pass throw=False to get the result with ok=False instead."
)


def run_imm(
    imm: InteractingMultipleModel,
    measurements: ArrayLike,
    *,
    mask: ArrayLike | None = None,
    first_step: FirstStep = "update",
    nan_as_missing: bool = False,
    throw: bool = True,
) -> IMMResult:
    """Run the IMM over ``measurements`` with one jitted ``lax.scan`` of :meth:`InteractingMultipleModel.step`.

    **Arguments:**

    - ``imm``: an :class:`InteractingMultipleModel`.
    - ``measurements``: ``(T, m)`` (or ``(T,)`` when ``m = 1``), in the models' units.
    - ``mask``: optional boolean ``(T,)`` or ``(T, m)``, True = observed (each member's update
      drops the missing components; a fully missing step leaves ``μ = c̄``).
    - ``first_step``: ``"update"`` (default; priors and ``initial_probs`` at the first
      measurement) or ``"predict"`` (one transition before it), as in
      :func:`~jaxtrack.filters.run_filter`.
    - ``nan_as_missing``, ``throw``: as in :func:`~jaxtrack.filters.run_filter`.

    **Returns:** an :class:`IMMResult`.

    **Raises:** ``InputError`` for a wrong ``imm``, ``first_step``, shapes or mask.
    """
    if not isinstance(imm, InteractingMultipleModel):
        raise InputError(f"`imm` must be an InteractingMultipleModel; got {type(imm).__name__}.")
    if first_step not in ("update", "predict"):
        raise InputError(f"`first_step` must be 'update' or 'predict'; got {first_step!r}.")
    z = observed = None
    for model in imm.models:
        z, observed = prepare_measurements(model, measurements, mask, nan_as_missing)
    result = _run_imm_jit(imm, z, observed, first_step)
    return throw_unless_ok(result, result.ok, _IMM_FAILED) if throw else result

"""How :func:`~jaxtrack.filters.run_filter` and :func:`~jaxtrack.filters.rts_smoother` traverse
time: one sequential ``lax.scan``, or a parallel-in-time associative (all-prefix-sums) scan.

A strategy object (``scan=``), like the covariance strategies of
:func:`~jaxtrack.filters.run_filter_batch`: :class:`Sequential` (the step function scanned over
time, every filter), :class:`ParallelInTime` (Särkkä & García-Fernández 2021: the Kalman filter and
the RTS smoother as all-prefix-sums, ``O(log T)`` depth on parallel hardware; Kalman filter on a
linear model only) and :class:`AutoScan` (the default: picks one of the two).

The parallel filter combines per-step conditional densities with the paper's associative
operator; once the filtered moments are known, everything else a :class:`FilterResult` holds
(predicted moments, innovations, their covariances, the log-likelihood) is one element-wise
(``vmap``-ped) :meth:`~jaxtrack.filters.AbstractFilter.predict` and
:meth:`~jaxtrack.filters.AbstractFilter.update` per step, the very functions the sequential
step calls, so both strategies return the same fields with the same meaning (tested to 1e-10).
"""

from __future__ import annotations

import abc
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from .._validation import InputError
from ..models import AbstractStateSpaceModel, LinearGaussianModel
from ._base import AbstractFilter, FilterResult, _scan_filter
from ._linalg import cholesky_and_inverse, matmul
from ._updates import symmetrize

# AutoScan on a GPU/TPU: parallel from this many steps on. A rule, not a measurement (no
# accelerator was available when it was set): a sequential step on a GPU is a few kernel
# launches (several µs) whatever the state size, T of them in a row; the parallel scan is
# ~3·log2(T) loop iterations of one batched operator (~30 at T = 256, ~50 at T = 100,000), a few
# times the kernels of a step each. They cross at a few hundred steps for small states; 256 errs
# towards the sequential scan, which does less work. Measure with benchmarks/parallel_kalman.py
# on the device and adjust.
ACCELERATOR_MIN_STEPS = 256


class AbstractTimeScan(eqx.Module):
    """How a filter run and the RTS smoother traverse the ``T`` steps (the ``scan=`` argument).

    A strategy object of :func:`~jaxtrack.filters.run_filter` and
    :func:`~jaxtrack.filters.rts_smoother`: :class:`Sequential` scans the filter's step over time
    (any filter); :class:`ParallelInTime` computes the same result as an associative
    (all-prefix-sums) scan, ``O(log T)`` deep (the Kalman filter on a linear model);
    :class:`AutoScan` picks one of them. Every strategy returns the same result type with the
    same fields, so the choice changes the cost and rounding only, never the meaning.

    ``resolve`` turns a strategy into the concrete one for a filter, model and number of steps
    (raising ``InputError`` where it does not apply); ``filter_pass`` and ``smoother_pass`` run
    inside the entry points' ``jit`` on validated arrays.
    """

    @abc.abstractmethod
    def resolve(
        self, filter: AbstractFilter | None, model: AbstractStateSpaceModel, num_steps: int
    ) -> AbstractTimeScan:
        """The concrete strategy for ``filter`` (None: the backward pass only) on ``model``, ``T`` steps."""

    @abc.abstractmethod
    def filter_pass(self, filter, model, measurements, observed, first_step, save) -> FilterResult:
        """The forward pass: a :class:`FilterResult` (``ok`` from the run's own values only)."""

    @abc.abstractmethod
    def smoother_pass(self, model, filtered: FilterResult) -> tuple[Array, Array, Array]:
        """The RTS backward pass: ``(smoothed_mean (T, n), smoothed_cov (T, n, n), gains (T-1, n, n))``."""


class Sequential(AbstractTimeScan):
    """One ``lax.scan`` of the filter's step forward, one reverse ``lax.scan`` for the smoother.

    Any filter, any model; ``O(T)`` work and ``O(T)`` depth. The path every run took before the
    ``scan`` argument existed, unchanged to the last bit.
    """

    def resolve(self, filter, model, num_steps):
        return self

    def filter_pass(self, filter, model, measurements, observed, first_step, save):
        return _scan_filter(filter, model, measurements, observed, first_step, save)

    def smoother_pass(self, model, filtered):
        from ._smoother import _rts_scan

        return _rts_scan(model, filtered)


class ParallelInTime(AbstractTimeScan):
    r"""The Kalman filter and RTS smoother as associative scans (Särkkä & García-Fernández 2021).

    **Filter** (§IV-A, Lemmas 7–8, eqs. (12)–(15)). Step ``k`` is the element
    ``a_k = (A_k, b_k, C_k, η_k, J_k)`` of ``p(x_k | z_k, x_{k-1}) = N(A_k x_{k-1} + b_k, C_k)``
    and ``p(z_k | x_{k-1}) ∝ N_I(x_{k-1}; η_k, J_k)`` (information form). With the transition
    ``x_k = F_k x_{k-1} + u_k + w_k``:

    .. math::

        S_k = H_k Q_k H_kᵀ + R_k,\quad K_k = Q_k H_kᵀ S_k^{-1},\quad
        A_k = (I − K_k H_k) F_k,\quad b_k = u_k + K_k (z_k − H_k u_k),

        C_k = (I − K_k H_k) Q_k (I − K_k H_k)ᵀ + K_k R_k K_kᵀ,\quad
        η_k = F_kᵀ H_kᵀ S_k^{-1} (z_k − H_k u_k),\quad J_k = F_kᵀ H_kᵀ S_k^{-1} H_k F_k

    (``C_k`` in the filter's update form, Joseph by default: equal to the paper's
    ``(I − K_k H_k) Q_k``; the element is the filter's own ``update`` of ``N(u_k, Q_k)``), and at ``k = 0``
    ``A = 0``, ``η = 0``, ``J = 0`` with ``b``, ``C`` the update of the prior (or, with
    ``first_step="predict"``, of its prediction). The operator, for ``i`` before ``j``:

    .. math::

        A_{ij} = A_j (I + C_i J_j)^{-1} A_i,\quad
        b_{ij} = A_j (I + C_i J_j)^{-1} (b_i + C_i η_j) + b_j,\quad
        C_{ij} = A_j (I + C_i J_j)^{-1} C_i A_jᵀ + C_j,

        η_{ij} = A_iᵀ (I + J_j C_i)^{-1} (η_j − J_j b_i) + η_i,\quad
        J_{ij} = A_iᵀ (I + J_j C_i)^{-1} J_j A_i + J_i .

    The prefix ``a_0 ⊗ … ⊗ a_k`` has ``b = x̂_{k/k}``, ``C = P_{k/k}``. Missing measurement
    components contribute nothing: their rows of ``H_k`` are zeroed and ``R_k`` has a unit
    variance there (:func:`~jaxtrack.filters._updates.masked_noise`, the same update the
    sequential filter makes), so ``K_k`` has zero columns and ``η_k``, ``J_k`` no terms there.

    **Smoother** (§IV-B, eqs. (16)–(20), Lemma 10). With the filtered and predicted moments,
    ``E_k = G_k = P_{k/k} F_{k+1}ᵀ P_{k+1/k}^{-1}`` (the sequential smoother's gain, pseudo-inverse
    included), ``g_k = x̂_{k/k} − E_k x̂_{k+1/k}``, ``L_k = P_{k/k} − E_k P_{k+1/k} E_kᵀ``, and
    ``(E, g, L) = (0, x̂_{T-1/T-1}, P_{T-1/T-1})`` at the last step; combined from the end by
    ``E_{ij} = E_i E_j``, ``g_{ij} = E_i g_j + g_i``, ``L_{ij} = E_i L_j E_iᵀ + L_i``, whose
    suffixes hold ``x̂_{k/T-1}`` and ``P_{k/T-1}``.

    The predicted moments, innovations, their covariances and the log-likelihood are then the
    filter's own ``predict``/``update`` applied at every step at once (``vmap``).

    The prefix sums are one loop in which the operator appears once (blocks of ``log2 T`` steps
    reduced and rescanned, their totals scanned by recursive doubling: ``O(T)`` work, ``O(log T)``
    depth), not ``jax.lax.associative_scan``, which unrolls ``~2 log2 T`` copies of the operator:
    on 2 loaded CPU cores the whole parallel filter compiled in 27–42 s at T = 10,000 with it, in
    4–7 s with this loop (the same results to rounding). Differentiable in forward and reverse
    mode.

    Applies to :class:`~jaxtrack.filters.KalmanFilter` (optimal gain: no ``gain=``; either
    update form) on a :class:`~jaxtrack.models.LinearGaussianModel`, per-step matrices and
    offsets included; any other filter or model raises ``InputError``. Each combination costs
    more than a sequential step (an ``n × n`` LU solve and about ten products): faster only where
    the hardware runs the ``B`` combinations of an iteration in parallel (see :class:`AutoScan`).

    ??? cite "Reference"

        ```bibtex
        @article{sarkka2021temporal,
          author  = {S{\"a}rkk{\"a}, Simo and Garc{\'\i}a-Fern{\'a}ndez, {\'A}ngel F.},
          title   = {Temporal Parallelization of {B}ayesian Smoothers},
          journal = {IEEE Transactions on Automatic Control},
          volume  = {66}, number = {1}, pages = {299--306}, year = {2021},
          doi     = {10.1109/TAC.2020.2976316},
        }
        ```
    """

    def resolve(self, filter, model, num_steps):
        reason = _unsupported(filter, model)
        if reason is not None:
            raise InputError(
                f"`scan=ParallelInTime()` supports the KalmanFilter (optimal gain, no `gain=`) on a "
                f"LinearGaussianModel, with per-step matrices and masks; {reason}. Use "
                f"scan=Sequential() or the default AutoScan(), which runs every filter."
            )
        return self

    def filter_pass(self, filter, model, measurements, observed, first_step, save):
        return _parallel_filter(filter, model, measurements, observed, first_step, save)

    def smoother_pass(self, model, filtered):
        return _parallel_rts(model, filtered)


class AutoScan(AbstractTimeScan):
    """Pick :class:`ParallelInTime` only where it is faster, else :class:`Sequential` (the default).

    - **CPU: always** :class:`Sequential`. Measured (``benchmarks/parallel_kalman.py``, output in
      ``benchmarks/measured/parallel_kalman.txt``: 2-D constant-velocity model, ``n = 4``,
      ``m = 2``, float64, 2 cores, best of 5, load average 4–5), the parallel filter took
      3.3–4.8× the sequential filter's time and the parallel smoother 1.3–1.7× the sequential
      smoother's at T = 100, 1,000, 10,000 and 100,000 (sequential against parallel filter:
      0.27 against 0.88 ms at T = 100, 0.24 against 0.91 s at T = 100,000; compilation 1–2 s
      against 2–7 s): a CPU does not run
      the combinations of one iteration in parallel, and each does more than a step (an ``n × n``
      LU solve and about ten products against one predict and update).
    - **GPU/TPU:** :class:`ParallelInTime` when the filter and model support it and
      ``T ≥ min_steps`` (default ``ACCELERATOR_MIN_STEPS = 256``), else :class:`Sequential`.
      This threshold is a rule, not a measurement: no accelerator was at hand when it was set. A
      sequential step on a GPU is a few kernel launches whatever ``n``, ``T`` of them in a row;
      the parallel scan is ``~3 log2 T`` iterations of one batched operator, so the crossing
      lies at a few hundred steps. Run the benchmark on the device to measure it.

    The backend is ``jax.default_backend()`` at trace time. A single trajectory only: runs
    batched by ``vmap`` already fill the device and are usually better served sequentially
    (pass ``scan=Sequential()`` there).

    **Arguments:** ``min_steps``: the number of steps from which an accelerator runs in parallel.
    """

    min_steps: int = eqx.field(static=True, default=ACCELERATOR_MIN_STEPS)

    def resolve(self, filter, model, num_steps):
        if jax.default_backend() == "cpu" or num_steps < self.min_steps:
            return Sequential()
        return ParallelInTime() if _unsupported(filter, model) is None else Sequential()

    def filter_pass(self, filter, model, measurements, observed, first_step, save):
        scan = self.resolve(filter, model, measurements.shape[0])
        return scan.filter_pass(filter, model, measurements, observed, first_step, save)

    def smoother_pass(self, model, filtered):
        return self.resolve(None, model, filtered.filtered_mean.shape[0]).smoother_pass(model, filtered)


def resolve_scan(scan, filter, model, num_steps: int) -> AbstractTimeScan:
    """The concrete :class:`AbstractTimeScan` for ``scan`` (checked, trace time).

    **Arguments:** ``scan``: the user's strategy; ``filter``: the filter (None: the smoother's
    backward pass only); ``model``: the state-space model; ``num_steps``: ``T``.

    **Returns:** :class:`Sequential` or :class:`ParallelInTime`.

    **Raises:** ``InputError`` naming ``scan`` if it is not a strategy, or does not apply.
    """
    if not isinstance(scan, AbstractTimeScan):
        raise InputError(
            f"`scan` must be Sequential(), ParallelInTime() or AutoScan() (jaxtrack.filters); got {scan!r}."
        )
    return scan.resolve(filter, model, num_steps)


def _unsupported(filter, model) -> str | None:
    """Why :class:`ParallelInTime` cannot run ``filter`` on ``model`` (None: it can).

    ``filter`` None asks for the smoother's backward pass only, which needs a linear transition.
    """
    from ._kalman import KalmanFilter

    if not isinstance(model, LinearGaussianModel):
        return f"got a {type(model).__name__}"
    if filter is None:
        return None
    if not isinstance(filter, KalmanFilter):
        return f"got the filter {type(filter).__name__}"
    if filter.gain is not None:
        return "got a KalmanFilter with a supplied `gain` (the parallel form is the optimal filter's)"
    return None


# ---------------------------------------------------------------------------------------------
# All-prefix-sums
# ---------------------------------------------------------------------------------------------


def _tree_where(keep: Array, new, old):
    """``new`` where ``keep`` (a scalar, or a vector over the leading axis), else ``old``, per leaf."""
    return jax.tree_util.tree_map(
        lambda a, b: jnp.where(keep.reshape(keep.shape + (1,) * (a.ndim - keep.ndim)), a, b), new, old
    )


def _prefix_scan(op, elements, identity, *, reverse: bool = False):
    """All-prefix-sums ``a_0 ⊗ … ⊗ a_k`` (``reverse``: suffixes ``a_k ⊗ … ⊗ a_{T-1}``) of ``elements``.

    The same result as ``jax.lax.associative_scan`` (with ``op`` vmapped), scheduled so that
    ``op`` appears once in the program instead of ``~2 log2 T`` times: the ``T`` elements are cut
    into ``B ≈ T / log2 T`` blocks of ``L = ceil(log2 T)`` steps, and one loop of ``2L + log2 B``
    iterations, each one ``op`` on ``B`` pairs, (1) reduces every block to its total, ``L``
    steps, all blocks at once; (2) scans the ``B`` totals by recursive doubling (Hillis & Steele
    1986), ``log2 B`` levels; (3) rescans every block from the total of the blocks before it,
    ``L`` steps. ``O(T)`` work (``2T + B log2 B`` operations), ``O(log T)`` depth: a scan on
    fewer processors than elements (Blelloch 1990, "Prefix sums and their applications"). Why
    not ``associative_scan``: XLA compiles every copy of the operator, and its unrolled levels of
    the filter operator (an LU solve and ten products) took 25–32 s to compile at T = 10,000 on 2
    loaded CPU cores, this scan about 2 s.

    **Arguments:** ``op(earlier, later)``: the associative operator on single elements;
    ``elements``: a pytree of arrays with a leading axis ``T``; ``identity``: the operator's
    identity element (unbatched): the start of every block and the padding of the last.

    **Returns:** the prefixes (suffixes), the same pytree and shapes as ``elements``.
    """
    tmap = jax.tree_util.tree_map
    if reverse:
        # Suffixes are the prefixes of the reversed sequence under the mirrored operator.
        flip = lambda t: tmap(lambda a: jnp.flip(a, 0), t)  # noqa: E731
        return flip(_prefix_scan(lambda acc, nxt: op(nxt, acc), flip(elements), identity))
    num = jax.tree_util.tree_leaves(elements)[0].shape[0]
    size = max(1, (num - 1).bit_length())  # L
    blocks = -(-num // size)  # B
    levels = (blocks - 1).bit_length()  # log2 B, rounded up
    pad = blocks * size - num
    # (L, B, ...): step-major, so that step l of every block is one slice.
    x = tmap(
        lambda e, a: jnp.swapaxes(
            jnp.concatenate([a, jnp.broadcast_to(e, (pad,) + e.shape)]).reshape((blocks, size) + e.shape), 0, 1
        ),
        identity,
        elements,
    )
    first = tmap(lambda e: jnp.broadcast_to(e[None], (1,) + e.shape), identity)
    block = jnp.arange(blocks)
    vop = jax.vmap(op)

    def body(i, state):
        carry, out = state  # carry: (B, ...): a running block prefix, or the block totals
        doubling = (i >= size) & (i < size + levels)  # stage (2)
        step = jnp.where(i < size, i, jnp.clip(i - size - levels, 0, size - 1))
        shift = jnp.left_shift(1, jnp.clip(i - size, 0, max(levels - 1, 0)))
        x_l = tmap(lambda a: jax.lax.dynamic_index_in_dim(a, step, keepdims=False), x)
        rolled = tmap(lambda a: jnp.roll(a, shift, axis=0), carry)
        new = vop(_tree_where(doubling, rolled, carry), _tree_where(doubling, carry, x_l))
        # Doubling leaves the first `shift` totals alone (they combined with wrapped-around ones).
        new = _tree_where(doubling & (block < shift), carry, new)
        # After stage (2): the total of the blocks *before* each block (identity for the first).
        exclusive = tmap(lambda e, a: jnp.concatenate([e, a[:-1]]), first, new)
        new = _tree_where(i == size + levels - 1, exclusive, new)
        # Stage (3) writes every step last; what stages (1) and (2) write here is overwritten.
        out = tmap(lambda o, a: jax.lax.dynamic_update_index_in_dim(o, a, step, 0), out, new)
        return new, out

    start = tmap(lambda e: jnp.broadcast_to(e, (blocks,) + e.shape), identity)
    _, out = jax.lax.fori_loop(0, 2 * size + levels, body, (start, tmap(jnp.zeros_like, x)))
    return tmap(lambda a: jnp.swapaxes(a, 0, 1).reshape((blocks * size,) + a.shape[2:])[:num], out)


# ---------------------------------------------------------------------------------------------
# Filter
# ---------------------------------------------------------------------------------------------


class _FilterElement(NamedTuple):
    """``(A, b, C, η, J)`` of one step or one span of steps (leading axis ``T`` when stacked)."""

    A: Array  # (n, n)
    b: Array  # (n,)
    C: Array  # (n, n)
    eta: Array  # (n,)
    J: Array  # (n, n)


def _filter_element(filter, model, k, z, observed) -> _FilterElement:
    """The element of step ``k ≥ 1`` (the update of ``N(F_k x + u_k, Q_k)`` by ``z_k``)."""
    n = model.state_dim
    F = model.transition_matrix(k)
    u = model.transition(jnp.zeros((n,), F.dtype), k)  # the offset b_k (0 without one)
    # The filter's own update of N(u_k, Q_k): b_k = u + K y, C_k (the filter's form), K, S, y.
    post = filter.update(model, u, model.process_noise_cov(k), z, observed, k)
    H = jnp.where(observed[:, None], model.measurement_matrix(k), 0.0)  # missing rows: nothing
    HF = matmul(H, F)
    _, chol_inv = cholesky_and_inverse(post.innovation_cov)
    whitened = matmul(chol_inv, HF)  # L⁻¹ H F with S = L Lᵀ, so J = (L⁻¹HF)ᵀ(L⁻¹HF) is symmetric
    A = F - matmul(post.gain, HF)
    eta = matmul(whitened.T, matmul(chol_inv, post.innovation))
    return _FilterElement(A, post.mean, post.cov, eta, matmul(whitened.T, whitened))


def _filter_operator(earlier: _FilterElement, later: _FilterElement) -> _FilterElement:
    """``a_i ⊗ a_j`` for ``i`` before ``j`` (Särkkä & García-Fernández 2021, Lemma 8).

    Written with one solve: ``Z = (I + C_i J_j)⁻¹ C_i = C_i (I + J_j C_i)⁻¹`` (symmetric), so that
    ``(I + C_i J_j)⁻¹ = I − Z J_j`` and ``(I + J_j C_i)⁻¹ = I − J_j Z`` (push-through identity):
    ``A_ij = A_j (A_i − Z J_j A_i)``, ``b_ij = A_j (b_i + Z v) + b_j``, ``C_ij = A_j Z A_jᵀ + C_j``,
    ``η_ij = A_iᵀ (v − J_j Z v) + η_i``, ``J_ij = A_iᵀ (J_j A_i − J_j Z J_j A_i) + J_i`` with
    ``v = η_j − J_j b_i``: the operator of the docstring of :class:`ParallelInTime`, term by term.
    ``I + C_i J_j`` is invertible (its eigenvalues are those of ``I + C_i^{1/2} J_j C_i^{1/2}``,
    all ≥ 1) but not symmetric, hence an LU solve.
    """
    A1, b1, C1, eta1, J1 = earlier
    A2, b2, C2, eta2, J2 = later
    M = jnp.eye(A1.shape[-1], dtype=A1.dtype) + C1 @ J2
    # Z, C_ij and J_ij are symmetric in exact arithmetic; the solve and the products round
    # asymmetrically, and an asymmetric C would feed its asymmetry to every later combination.
    Z = symmetrize(jnp.linalg.solve(M, C1))
    v = eta2 - J2 @ b1
    JA = J2 @ A1
    ZJA = Z @ JA
    Zv = Z @ v
    A = A2 @ (A1 - ZJA)
    b = A2 @ (b1 + Zv) + b2
    C = symmetrize(A2 @ Z @ A2.T) + C2
    eta = A1.T @ (v - J2 @ Zv) + eta1
    J = symmetrize(A1.T @ (JA - J2 @ ZJA)) + J1
    return _FilterElement(A, b, C, eta, J)


def _parallel_filter(filter, model, z, observed, first_step, save) -> FilterResult:
    """:class:`ParallelInTime`'s forward pass (traced inside ``run_filter``'s jit)."""
    T, n = z.shape[0], model.state_dim
    dtype = model.initial_cov.dtype
    ks = jnp.arange(T, dtype=jnp.int32)
    m0, P0 = model.initial_mean, model.initial_cov
    k0 = ks[0]
    if first_step == "predict":
        pm0, pc0 = filter.predict(model, m0, P0, k0)
    else:
        pm0, pc0 = m0, P0
    first = filter.update(model, pm0, pc0, z[0], observed[0], k0)
    zeros = jnp.zeros((n, n), dtype)
    head = _FilterElement(zeros, first.mean, first.cov, jnp.zeros((n,), dtype), zeros)
    rest = jax.vmap(lambda k, zk, ok: _filter_element(filter, model, k, zk, ok))(ks[1:], z[1:], observed[1:])
    elements = jax.tree_util.tree_map(lambda h, r: jnp.concatenate([h[None], r]), head, rest)
    eye = jnp.eye(n, dtype=dtype)
    identity = _FilterElement(eye, jnp.zeros((n,), dtype), zeros, jnp.zeros((n,), dtype), zeros)
    prefix = _prefix_scan(_filter_operator, elements, identity)
    fm, fc = prefix.b, prefix.C
    # Everything else, element-wise: the prediction into each step from the previous filtered
    # moments (the prior at k = 0), and the update of that prediction, of which only the
    # innovation, its covariance and its log-likelihood are kept (the filtered moments are the
    # scan's).
    prev_m = jnp.concatenate([m0[None], fm[:-1]])
    prev_P = jnp.concatenate([P0[None], fc[:-1]])
    pm, pc = jax.vmap(lambda m, P, k: filter.predict(model, m, P, k))(prev_m, prev_P, ks)
    pm, pc = pm.at[0].set(pm0), pc.at[0].set(pc0)
    post = jax.vmap(lambda m, P, zk, ok, k: filter.update(model, m, P, zk, ok, k))(pm, pc, z, observed, ks)
    ll = jnp.sum(post.log_likelihood)
    ok = jnp.all(jnp.isfinite(fm)) & jnp.all(jnp.isfinite(fc)) & jnp.isfinite(ll)
    hist = (fm, fc, pm, pc, post.innovation, post.innovation_cov, jnp.sum(observed.astype(dtype), axis=-1))
    if save == "final":
        hist = (None,) * 7
    elif save == "mean":
        hist = (fm,) + (None,) * 6
    return FilterResult(*hist, ll, fm[-1], fc[-1], ok)


# ---------------------------------------------------------------------------------------------
# Smoother
# ---------------------------------------------------------------------------------------------


class _SmootherElement(NamedTuple):
    """``(E, g, L)``: ``x_k | x_{k+1}, z ~ N(E x_{k+1} + g, L)`` (leading axis when stacked)."""

    E: Array  # (n, n)
    g: Array  # (n,)
    L: Array  # (n, n)


def _smoother_operator(earlier: _SmootherElement, later: _SmootherElement) -> _SmootherElement:
    """``s_i ⊗ s_j`` for ``i`` before ``j`` (Särkkä & García-Fernández 2021, Lemma 10)."""
    E1, g1, L1 = earlier
    E2, g2, L2 = later
    return _SmootherElement(E1 @ E2, E1 @ g2 + g1, symmetrize(E1 @ L2 @ E1.T) + L1)  # L: as C above


def _parallel_rts(model, filtered) -> tuple[Array, Array, Array]:
    """:class:`ParallelInTime`'s backward pass (traced inside ``rts_smoother``'s jit)."""
    from ._smoother import _smoother_gain

    fm, fc = filtered.filtered_mean, filtered.filtered_cov
    pm, pc = filtered.predicted_mean, filtered.predicted_cov

    def element(k, m_f, P_f, m_p_next, P_p_next):
        F = model.transition_jacobian(m_f, k + 1)  # Φ_{k+1} (the matrix: the model is linear)
        G = _smoother_gain(P_f, F, P_p_next)
        # L_k = P_{k/k} − G P_{k+1/k} Gᵀ: symmetric in exact arithmetic, not after rounding.
        L = symmetrize(P_f - matmul(matmul(G, P_p_next), G.T))
        return _SmootherElement(G, m_f - matmul(G, m_p_next), L)

    T = fm.shape[0]
    body = jax.vmap(element)(jnp.arange(T - 1), fm[:-1], fc[:-1], pm[1:], pc[1:])
    last = _SmootherElement(jnp.zeros_like(fc[-1]), fm[-1], fc[-1])
    elements = jax.tree_util.tree_map(lambda b, t: jnp.concatenate([b, t[None]]), body, last)
    identity = _SmootherElement(jnp.eye(fm.shape[-1], dtype=fm.dtype), jnp.zeros_like(fm[-1]), jnp.zeros_like(fc[-1]))
    suffix = _prefix_scan(_smoother_operator, elements, identity, reverse=True)
    return suffix.g, suffix.L, body.E

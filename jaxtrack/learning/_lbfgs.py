"""L-BFGS with a Wolfe line search in which every loop iteration evaluates the objective once.

The default optimiser of :func:`~jaxtrack.learning.fit`. It is the same method as optax's
``lbfgs()`` with its zoom line search (Nocedal & Wright 2006, *Numerical Optimization*, 2nd ed.,
Alg. 7.4–7.5 for the two-loop recursion, Alg. 3.5–3.6 for the line search), written as the
stepper of the learning module's one loop (``_loop.optimise``: one ``lax.while_loop``) whose body
makes exactly one objective-and-gradient evaluation at a trial point; :meth:`LBFGS.advance` then decides, with ``jnp.where`` only, what the evaluation was for (the start, a
bracketing step, a zoom step) and what comes next.

**Why a state machine.** optax's line search is a ``while_loop`` nested in the optimiser's update,
with a ``cond`` between its bracketing and zoom phases; each of those places calls the
objective, so a fit loop built on it holds four copies of the objective's value-and-gradient
program (the first evaluation, the loop's own, and the line search's two) and XLA compiles each:
for the registration calibration model, 10 s of the fit's first call. Here the program holds
one copy (about 3 s), and the same loop vmaps over data sets.

**Line search** (on ``φ(α) = f(x + α d)``, ``φ'(α) = ∇f · d``): first trial ``α = 1``
(``1/‖∇f‖`` on the first iteration, a unit-length steepest-descent step). Bracketing (Alg. 3.5):
a trial that fails the sufficient-decrease condition ``φ(α) ≤ φ(0) + c₁ α φ'(0)``, or does not
improve on the previous trial, or has ``φ'(α) ≥ 0``, closes a bracket; a trial that meets the
strong curvature condition ``|φ'(α)| ≤ c₂ |φ'(0)|`` is accepted; otherwise ``α`` doubles. Zoom
(Alg. 3.6): the minimiser of the cubic through the bracket's ends (values and slopes), kept at
least 10 % of the bracket away from either end (bisection when the cubic is not finite).
Near the optimum ``φ`` differences reach rounding before slopes do, so a trial whose value is
within ``10⁻¹² |φ(0)|`` of ``φ(0)`` and that meets the curvature condition is accepted too (the
approximate Wolfe conditions of Hager & Zhang 2005, *SIAM J. Optim.* 16(1), eq. 23).
A non-finite trial counts as ``φ = +∞`` (the step shrinks); a non-finite start stops the fit
with ``ok = False``. ``max_linesearch_steps`` trials without an acceptable point stop the fit
(``converged = False``) at the last accepted iterate.

**Update** (Alg. 7.4): pairs ``s = Δx``, ``y = Δ∇f`` with ``sᵀy > 0`` enter the memory (others are
skipped, which keeps the inverse-Hessian estimate positive definite); the initial matrix is
``γ I`` with ``γ = sᵀy / yᵀy`` of the newest pair (eq. 7.20). A direction that is not a descent
direction resets the memory to steepest descent.
"""

from __future__ import annotations

from typing import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from ._loop import Move, optimise


class LBFGS(eqx.Module):
    """Limited-memory BFGS with a strong-Wolfe line search, one evaluation per loop iteration.

    The default ``optimizer`` of :func:`~jaxtrack.learning.fit` (module docstring: the method,
    Nocedal & Wright 2006 Alg. 7.4–7.5 and 3.5–3.6, and why it is written as a state machine).

    **Fields:**

    - ``memory_size``: the number of ``(s, y)`` pairs kept, ≥ 1 (default 10, as optax's ``lbfgs``).
    - ``c1``: the sufficient-decrease constant, in (0, c2) (default 1e-4).
    - ``c2``: the curvature constant, in (c1, 1) (default 0.9, the usual quasi-Newton choice).
    - ``max_linesearch_steps``: trials per line search before the fit stops, ≥ 1 (default 30).
    """

    memory_size: int = eqx.field(static=True, default=10)
    c1: float = eqx.field(static=True, default=1e-4)
    c2: float = eqx.field(static=True, default=0.9)
    max_linesearch_steps: int = eqx.field(static=True, default=30)

    def __check_init__(self):
        from .._validation import InputError

        if not (isinstance(self.memory_size, int) and self.memory_size >= 1):
            raise InputError(f"`memory_size` must be an int ≥ 1; got {self.memory_size!r}.")
        if not (0.0 < self.c1 < self.c2 < 1.0):
            raise InputError(f"`c1` and `c2` must satisfy 0 < c1 < c2 < 1; got {self.c1}, {self.c2}.")
        if not (isinstance(self.max_linesearch_steps, int) and self.max_linesearch_steps >= 1):
            raise InputError(f"`max_linesearch_steps` must be an int ≥ 1; got {self.max_linesearch_steps!r}.")

    def minimise(
        self,
        evaluate: Callable[[Array], tuple[Array, Array, Array, Array]],
        x0: Array,
        num_iterations: int,
        converged_fn: Callable[[Array, Array, Array], Array],
        value_dtype,
        tick: Callable[[Array, Array], None] | None = None,
    ):
        """Minimise ``f`` from ``x0`` (flat ``(k,)``) in one ``while_loop`` (the shared loop, ``_loop``).

        **Arguments:**

        - ``evaluate``: ``x -> (f, aux, ∇f, good)``: the objective, a scalar carried along
          (the log-likelihood), the gradient ``(k,)`` and whether all three are usable.
        - ``num_iterations``: the cap on accepted iterations.
        - ``converged_fn``: ``(aux_new, aux_old, ∇f_new) -> bool``, the stopping rule, applied
          after each accepted step (and at the start, with ``aux_old`` NaN).
        - ``value_dtype``: the dtype of ``f`` and ``aux``.
        - ``tick``: optional ``(iteration, aux) -> None`` for a progress bar (host callback).

        **Returns:** ``(x, aux_history (I + 1,), grad_norm_history (I + 1,), iterations,
        converged, ok)``: the last accepted iterate; the histories at each accepted iterate
        (entries after the stop repeat the final value); ``ok`` False only when the start is
        not finite.
        """
        return optimise(evaluate, x0, self, num_iterations, converged_fn, value_dtype, tick)[:6]

    # The stepper protocol of the shared loop (``_loop.optimise``): every loop iteration
    # evaluates the objective once at ``trial``; ``advance`` decides what the evaluation was for.

    def init(self, x0: Array, value_dtype) -> dict:
        """The line-search state before the start is evaluated (``phase`` 0: the start)."""
        M, k, dtype = self.memory_size, x0.shape[0], x0.dtype
        inf = jnp.asarray(jnp.inf, value_dtype)
        z = jnp.zeros((), dtype)
        # State: iterate (x, f, aux, g), direction d, memory (S, Y, count), line search
        # (phase 0 start / 1 bracket / 2 zoom, trial step a, previous trial, bracket lo/hi with
        # values and slopes, lo's gradient and aux).
        return dict(
            x=x0, f=inf, aux=jnp.full((), jnp.nan, value_dtype), g=jnp.zeros(k, dtype),
            d=jnp.zeros(k, dtype), S=jnp.zeros((M, k), dtype), Y=jnp.zeros((M, k), dtype),
            count=jnp.zeros((), jnp.int32), phase=jnp.zeros((), jnp.int32), a=z, ls=jnp.zeros((), jnp.int32),
            a_prev=z, f_prev=inf, lo=z, f_lo=inf, dphi_lo=z, g_lo=jnp.zeros(k, dtype), aux_lo=inf,
            hi=z, f_hi=inf, dphi_hi=z,
        )

    def trial(self, s: dict, first) -> tuple[Array, dict]:
        """The point to evaluate: ``x + a d`` (the start itself: ``a = 0``, ``d = 0``)."""
        return s["x"] + s["a"] * s["d"], s

    def advance(self, s: dict, x_trial, f_t, aux_t, g_t, good_t, first):
        """One line-search decision on the evaluation at ``x_trial`` (module docstring)."""
        M, dtype = self.memory_size, s["x"].dtype
        c1, c2 = self.c1, self.c2
        value_dtype = s["f"].dtype
        inf = jnp.asarray(jnp.inf, value_dtype)

        def direction(g, S, Y, count):
            """Two-loop recursion: ``−H g`` with the memory's newest ``count`` pairs (Alg. 7.4)."""
            # Slots are ordered oldest … newest; empty slots (index < M − count) are skipped.
            valid = jnp.arange(M) >= M - count
            sy = jnp.sum(S * Y, axis=1)
            rho = jnp.where(valid, 1.0 / jnp.where(valid, sy, 1.0), 0.0)

            def back(q, i):
                a = rho[i] * jnp.dot(S[i], q)
                return q - a * Y[i], a

            q, alphas = jax.lax.scan(back, g, jnp.arange(M - 1, -1, -1))
            yy = jnp.dot(Y[-1], Y[-1])
            gamma = jnp.where(count > 0, sy[-1] / jnp.where(count > 0, yy, 1.0), 1.0)
            r = gamma * q

            def fwd(r, ia):
                i, a = ia
                b = rho[i] * jnp.dot(Y[i], r)
                return r + S[i] * (a - b), None

            r, _ = jax.lax.scan(fwd, r, (jnp.arange(M), alphas[::-1]))
            return -r

        def cubic_min(a0, f0, d0, a1, f1, d1):
            """Minimiser of the cubic through (a0, f0, d0), (a1, f1, d1); safeguarded (Alg. 3.6)."""
            w = a1 - a0
            d1_ = d0 + d1 - 3.0 * (f1 - f0) / w
            disc = d1_ * d1_ - d0 * d1
            d2 = jnp.sign(w) * jnp.sqrt(jnp.maximum(disc, 0.0))
            t = a1 - w * (d1 + d2 - d1_) / (d1 - d0 + 2.0 * d2)
            lo_, hi_ = jnp.minimum(a0, a1), jnp.maximum(a0, a1)
            margin = 0.1 * (hi_ - lo_)
            good = jnp.isfinite(t) & (disc >= 0) & jnp.isfinite(f1) & jnp.isfinite(d1)
            t = jnp.where(good, t, 0.5 * (a0 + a1))
            return jnp.clip(t, lo_ + margin, hi_ - margin)

        f_t = jnp.where(good_t, f_t, inf).astype(value_dtype)
        aux_t = aux_t.astype(value_dtype)
        g_t = jnp.where(good_t, g_t, 0.0).astype(dtype)
        dphi = jnp.where(good_t, jnp.dot(g_t, s["d"]), jnp.inf).astype(dtype)
        start = s["phase"] == 0
        bracket = s["phase"] == 1
        zoom = s["phase"] == 2

        # The slope and value at α = 0, from the current iterate.
        f0, dphi0 = s["f"], jnp.dot(s["g"], s["d"])
        armijo = f_t <= f0 + c1 * s["a"] * dphi0
        curvature = jnp.abs(dphi) <= -c2 * dphi0
        approx = (f_t <= f0 + 1e-12 * jnp.abs(f0)) & curvature
        accept_b = bracket & ((armijo & ~((s["ls"] > 0) & (f_t >= s["f_prev"])) & curvature) | approx)
        close_hi = bracket & ~accept_b & (~armijo | ((s["ls"] > 0) & (f_t >= s["f_prev"])))
        close_lo = bracket & ~accept_b & ~close_hi & (dphi >= 0)
        expand = bracket & ~accept_b & ~close_hi & ~close_lo
        worse_z = ~armijo | (f_t >= s["f_lo"])
        accept_z = zoom & ((~worse_z & curvature) | approx)
        zoom_hi = zoom & ~accept_z & worse_z
        zoom_lo = zoom & ~accept_z & ~worse_z
        flip = zoom_lo & (dphi * (s["hi"] - s["lo"]) >= 0)
        accept = accept_b | accept_z

        # Bracket ends after this trial (bracketing: lo = previous trial; zoom: Alg. 3.6).
        # While bracketing, (lo, f_lo, dphi_lo, g_lo, aux_lo) is the previous trial (α = 0:
        # the iterate), which is also the best Armijo point so far.
        new_lo = close_lo | zoom_lo | expand
        lo = jnp.where(close_hi, s["a_prev"], jnp.where(new_lo, s["a"], s["lo"]))
        f_lo = jnp.where(close_hi, s["f_prev"], jnp.where(new_lo, f_t, s["f_lo"]))
        dphi_lo = jnp.where(new_lo, dphi, s["dphi_lo"])
        g_lo = jnp.where(new_lo, g_t, s["g_lo"])
        aux_lo = jnp.where(new_lo, aux_t, s["aux_lo"])
        hi = jnp.where(close_hi, s["a"], jnp.where(close_lo, s["a_prev"], jnp.where(
            zoom_hi, s["a"], jnp.where(flip, s["lo"], s["hi"]))))
        f_hi = jnp.where(close_hi, f_t, jnp.where(close_lo, s["f_prev"], jnp.where(
            zoom_hi, f_t, jnp.where(flip, s["f_lo"], s["f_hi"]))))
        dphi_hi = jnp.where(close_hi, dphi, jnp.where(close_lo, s["dphi_lo"], jnp.where(
            zoom_hi, dphi, jnp.where(flip, s["dphi_lo"], s["dphi_hi"]))))

        # Line search exhausted without an acceptable point: keep the best Armijo point
        # (lo, if it moved) or stop.
        ls = s["ls"] + 1
        exhausted = (bracket | zoom) & ~accept & (ls >= self.max_linesearch_steps)
        fallback = exhausted & (lo > 0) & (f_lo < f0)
        failed = exhausted & ~fallback

        # The point that becomes the new iterate (start, accepted trial, or fallback lo).
        take_trial = start | accept
        new_step = accept | fallback
        x_new = jnp.where(take_trial, x_trial, jnp.where(fallback, s["x"] + lo * s["d"], s["x"]))
        f_new = jnp.where(take_trial, f_t, jnp.where(fallback, f_lo, s["f"]))
        g_new = jnp.where(take_trial, g_t, jnp.where(fallback, g_lo, s["g"]))
        aux_new = jnp.where(take_trial, aux_t, jnp.where(fallback, aux_lo, s["aux"]))

        # Memory update with the accepted pair (skipped unless sᵀy > 0).
        sv, yv = x_new - s["x"], g_new - s["g"]
        store = new_step & (jnp.dot(sv, yv) > 1e-10 * jnp.sqrt(jnp.dot(sv, sv) * jnp.dot(yv, yv)))
        S = jnp.where(store, jnp.concatenate([s["S"][1:], sv[None]]), s["S"])
        Y = jnp.where(store, jnp.concatenate([s["Y"][1:], yv[None]]), s["Y"])
        count = jnp.where(store, jnp.minimum(s["count"] + 1, M), s["count"])
        d_new = direction(g_new, S, Y, count)
        descent = jnp.dot(d_new, g_new) < 0
        count = jnp.where(descent, count, 0)
        d_new = jnp.where(descent, d_new, -g_new)
        gn = jnp.sqrt(jnp.dot(g_new, g_new))
        # First step of a fresh (or reset) memory: unit length along −∇f.
        a_first = jnp.where(count == 0, 1.0 / jnp.maximum(gn, jnp.finfo(dtype).tiny), 1.0)

        moved = start | new_step
        # The next trial: a new line search after a new iterate; else the bracketing or zoom step.
        zoom_next = (close_hi | close_lo | zoom) & ~moved
        a_zoom = cubic_min(lo, f_lo, dphi_lo, hi, f_hi, dphi_hi)
        a_next = jnp.where(moved, a_first, jnp.where(zoom_next, a_zoom, 2.0 * s["a"]))
        phase = jnp.where(moved, 1, jnp.where(zoom_next, 2, s["phase"]))
        state = dict(
            x=x_new, f=f_new, aux=aux_new, g=g_new,
            d=jnp.where(moved, d_new, s["d"]), S=S, Y=Y, count=count, phase=phase, a=a_next,
            ls=jnp.where(moved, 0, ls),
            a_prev=jnp.where(moved, 0.0, jnp.where(expand, s["a"], s["a_prev"])),
            f_prev=jnp.where(moved, f_new, jnp.where(expand, f_t, s["f_prev"])),
            lo=jnp.where(moved, 0.0, lo), f_lo=jnp.where(moved, f_new, f_lo),
            dphi_lo=jnp.where(moved, jnp.dot(g_new, jnp.where(moved, d_new, s["d"])), dphi_lo),
            g_lo=jnp.where(moved, g_new, g_lo), aux_lo=jnp.where(moved, aux_new, aux_lo),
            hi=hi, f_hi=f_hi, dphi_hi=dphi_hi,
        )
        # The start is an iterate even when not finite (the loop then stops with ok = False);
        # a line search that found nothing stops the fit at the last iterate.
        return state, Move(moved, x_new, aux_new, g_new, failed, jnp.zeros((), bool))


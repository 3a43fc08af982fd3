"""The one optimisation loop of :func:`~jaxtrack.learning.fit`, :func:`~jaxtrack.learning.fit_imm`
and :func:`~jaxtrack.learning.fit_em`: iteration count, stopping rule, histories, progress bar.

What differs between the fits is how the next point to evaluate is chosen (a *stepper*):
L-BFGS's line-search state machine (:class:`~jaxtrack.learning.LBFGS`), an optax
transformation (:class:`OptaxStepper`) or the EM M-step (``_em``). What they share lives here,
once: one ``lax.while_loop`` whose body evaluates the objective at one trial point, lets the
stepper decide whether that point is a new iterate, and then

- counts the iterates (``it``: optimiser steps since the start; the start is iterate 0),
- applies the caller's stopping rule ``converged_fn(aux_new, aux_old, grad_new)`` to each new
  iterate (to the start with ``aux_old`` NaN),
- writes the histories of ``aux`` (the log-likelihood) and of the gradient norm ``‖∇f‖₂`` at
  each iterate (entries after the stop repeat the final value),
- ticks the progress bar (a host callback),
- stops at the cap of ``num_iterations`` steps, on convergence, when the stepper can go no
  further, or at a non-finite evaluation the stepper cannot recover from (``ok = False``; the
  returned point is then the last finite iterate). A non-finite start stops with ``ok = False``
  whatever the stepper.

The objective appears once in the loop body, so the compiled fit holds one copy of it (for the
optax line searches, which call ``value_fn`` themselves, once more there).
"""

from __future__ import annotations

import contextlib
from typing import Any, Callable, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import optax
from jaxtyping import Array, Bool, PyTree

from ._runs import select


class Move(NamedTuple):
    """What a stepper makes of one evaluation.

    - ``moved`` ``()`` bool: the evaluation gave a new iterate (or was the start);
    - ``x``, ``aux`` ``()``, ``grad``: the current iterate after it, its log-likelihood and its
      gradient (for the stopping rule and the norm history; ``None`` where there is none);
    - ``stop`` ``()`` bool: the stepper can go no further (e.g. a line search found no point);
    - ``fail`` ``()`` bool: a non-finite evaluation it does not recover from (``ok`` becomes False).
    """

    moved: Bool[Array, ""]
    x: PyTree
    aux: Array
    grad: PyTree
    stop: Bool[Array, ""]
    fail: Bool[Array, ""]


class LoopResult(NamedTuple):
    """The loop's output: ``x``, ``aux_history`` ``(I + 1,)``, ``grad_norm_history`` ``(I + 1,)``,
    ``num_steps`` (iterates after the start that led to ``x``), ``converged``, ``ok``,
    ``start_ok`` (the start itself was finite)."""

    x: PyTree
    aux_history: Array
    grad_norm_history: Array
    num_steps: Array
    converged: Array
    ok: Array
    start_ok: Array


def grad_norm(tree) -> Array:
    """``‖g‖₂`` over all leaves of a pytree (0 for ``None``)."""
    return jnp.sqrt(sum(jnp.sum(x**2) for x in jax.tree_util.tree_leaves(tree)))


def optimise(
    evaluate: Callable[[PyTree], tuple[Array, Array, PyTree, Array]],
    x0: PyTree,
    stepper: Any,
    num_iterations: int,
    converged_fn: Callable[[Array, Array, PyTree], Array] | None,
    aux_dtype,
    tick: Callable[[Array, Array], None] | None = None,
) -> LoopResult:
    """Run ``stepper`` from ``x0`` in one ``lax.while_loop`` (module docstring).

    **Arguments:**

    - ``evaluate``: ``x -> (f, aux, g, good)``: the objective (minimised), a scalar carried
      along (the log-likelihood), the gradient (or any statistics the stepper needs) and whether
      all are finite.
    - ``stepper``: has ``init(x0, aux_dtype) -> state``, ``trial(state, first) -> (x, state)``
      and ``advance(state, x, f, aux, g, good, first) -> (state, Move)`` (``first``: this is the
      start's evaluation; a traced bool, or a Python bool where it is known at trace time); an
      optional ``start_outside`` True evaluates the start before the loop.
    - ``num_iterations``: the cap on steps after the start (a Python int ≥ 1).
    - ``converged_fn``: the stopping rule, or ``None`` (never converged: run to the cap).
    - ``aux_dtype``: the dtype of ``aux`` and the histories.
    - ``tick``: optional ``(iteration, aux) -> None`` host callback (a progress bar).

    **Returns:** a :class:`LoopResult`.
    """
    nan_hist = jnp.full((num_iterations + 1,), jnp.nan, aux_dtype)
    nan = jnp.full((), jnp.nan, aux_dtype)
    carry = dict(
        it=jnp.zeros((), jnp.int32), first=jnp.ones((), bool), state=stepper.init(x0, aux_dtype), x=x0, aux=nan,
        hist=nan_hist, ghist=nan_hist, running=jnp.ones((), bool), converged=jnp.zeros((), bool),
        ok=jnp.ones((), bool), start_ok=jnp.zeros((), bool),
    )

    def cond(c):
        return c["running"] & (c["it"] < num_iterations)

    def record(c, x_t, state, evaluation):
        """The shared bookkeeping of one evaluation at ``x_t`` (module docstring)."""
        first = c["first"]
        f_t, aux_t, g_t, good_t = evaluation
        state, mv = stepper.advance(state, x_t, f_t, aux_t, g_t, good_t, first)
        aux_new = jnp.asarray(mv.aux).astype(aux_dtype)
        bad_start = first & ~good_t
        it_new = jnp.where(mv.moved & ~first, c["it"] + 1, c["it"])
        conv = jnp.zeros((), bool) if converged_fn is None else converged_fn(aux_new, c["aux"], mv.grad)
        conv = mv.moved & ~bad_start & conv
        hist = jnp.where(mv.moved, c["hist"].at[it_new].set(aux_new), c["hist"])
        ghist = jnp.where(mv.moved, c["ghist"].at[it_new].set(grad_norm(mv.grad).astype(aux_dtype)), c["ghist"])
        if tick is not None:
            jax.debug.callback(tick, it_new, aux_new)
        return dict(
            it=it_new, first=jnp.zeros((), bool), state=state, x=select(mv.moved, mv.x, c["x"]),
            aux=jnp.where(mv.moved, aux_new, c["aux"]), hist=hist, ghist=ghist,
            running=c["running"] & ~conv & ~mv.stop & ~mv.fail & ~bad_start,
            converged=conv, ok=c["ok"] & ~mv.fail & ~bad_start, start_ok=c["start_ok"] | (first & good_t),
        )

    start_outside = bool(getattr(stepper, "start_outside", False))

    def body(c):
        # With the start evaluated before the loop, `first` is known to be False in it: a Python
        # bool lets the stepper skip its start branch at trace time.
        x_t, state = stepper.trial(c["state"], False if start_outside else c["first"])
        return record(c, x_t, state, evaluate(x_t))

    if start_outside:
        # The start evaluated before the loop (a second compiled copy of the objective; fit's
        # optax path has always done this, and its compilation count is pinned by the tests).
        x_t, state = stepper.trial(carry["state"], True)
        carry = record(carry, x_t, state, evaluate(x_t))

    out = jax.lax.while_loop(cond, body, carry)
    i = out["it"]
    # Entries past the last iterate repeat the final value (the fit stopped there).
    idx = jnp.arange(num_iterations + 1)
    hist = jnp.where(idx > i, out["aux"], out["hist"])
    ghist = jnp.where(idx > i, out["ghist"][i], out["ghist"])
    return LoopResult(out["x"], hist, ghist, i, out["converged"], out["ok"], out["start_ok"])


class OptaxStepper(eqx.Module):
    """An optax transformation as a stepper: every finite evaluation is the next iterate.

    The update is made at the start of the next loop body (``trial``), from the iterate's
    gradient, so the loop that stops never computes an update it does not use. A non-finite
    evaluation fails the fit (``ok = False``) at the last finite iterate.

    **Fields:** ``optimizer`` (an optax ``GradientTransformation``); ``value_fn``: ``None``
    (``optimizer.update(g, state, params)``) or the objective, passed with ``value=`` and
    ``grad=`` (optax's line searches, e.g. ``optax.lbfgs()``, need it; the transformation must
    then accept extra arguments: ``optax.with_extra_args_support``); ``start_outside``: evaluate
    the start before the loop rather than in its first iteration (same numbers, one more
    compiled copy of the objective).
    """

    optimizer: Any = eqx.field(static=True)
    value_fn: Callable | None = eqx.field(static=True, default=None)
    start_outside: bool = eqx.field(static=True, default=False)

    def init(self, x0, aux_dtype):
        # (current iterate, its value and gradient, optimiser state); the gradient and value
        # are placeholders until the start has been evaluated.
        return (x0, jnp.zeros((), aux_dtype), jax.tree_util.tree_map(jnp.zeros_like, x0), self.optimizer.init(x0))

    def trial(self, state, first):
        p, v, g, opt_state = state

        def step(_):
            if self.value_fn is None:
                updates, new_state = self.optimizer.update(g, opt_state, p)
            else:
                updates, new_state = self.optimizer.update(g, opt_state, p, value=v, grad=g, value_fn=self.value_fn)
            return optax.apply_updates(p, updates), new_state

        # The start is evaluated as given; every later trial is one optimiser step on. When
        # `first` is a Python bool the branch is chosen here, so the other is never traced.
        if isinstance(first, bool):
            p_t, new_state = (p, opt_state) if first else step(None)
        else:
            p_t, new_state = jax.lax.cond(first, lambda _: (p, opt_state), step, None)
        return p_t, (p, v, g, new_state, opt_state)

    def advance(self, state, x_t, f_t, aux_t, g_t, good_t, first):
        p, v, g, new_state, old_state = state
        keep = lambda a, b: select(good_t, a, b)  # noqa: E731
        state = (keep(x_t, p), jnp.where(good_t, f_t, v).astype(v.dtype), keep(g_t, g), keep(new_state, old_state))
        return state, Move(good_t, x_t, aux_t, g_t, jnp.zeros((), bool), ~good_t)


# The progress bar of the running fit (ticked from inside the jitted loop through
# jax.debug.callback): a module-level holder keeps the callback one function, so turning the bar
# on does not recompile per call.
_PROGRESS: dict[str, Any] = {"bar": None}


def tick(i, aux):
    """Move the running fit's progress bar to iteration ``i``, showing the log-likelihood ``aux``."""
    bar = _PROGRESS["bar"]
    if bar is not None:
        bar.update(int(i) - bar.n)
        bar.set_postfix(log_likelihood=f"{float(aux):.6g}")


@contextlib.contextmanager
def progress_bar(enabled: bool, total: int, desc: str):
    """A tqdm bar for a fit of ``total`` iterations (nothing when not ``enabled``).

    Yields a function ``finish(steps)`` to call with the iterations actually run once the
    result is ready: an early stop (converged or failed) ends the bar there.
    """
    if not enabled:
        yield lambda steps: None
        return
    from .._progress import tqdm  # the text bar where ipywidgets is missing (no warning)

    bar = tqdm(total=int(total), desc=desc, unit="it")
    _PROGRESS["bar"] = bar

    def finish(steps):
        bar.total = int(steps)
        bar.refresh()

    try:
        yield finish
    finally:
        bar.close()
        _PROGRESS["bar"] = None

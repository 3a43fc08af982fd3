"""State-space models as equinox Modules.

Conventions used everywhere in jaxtrack
--------------------------------------
A model describes, for measurement steps ``k = 0, …, T-1``,

.. math::

    x_k = f_k(x_{k-1}) + w_k,\\quad w_k \\sim N(0, Q_k)
    \\qquad z_k = h_k(x_k) + v_k,\\quad v_k \\sim N(0, R_k)

with a Gaussian prior ``N(initial_mean, initial_cov)``.

*Every per-step quantity is indexed by the measurement step it leads into*: ``F[k]``, ``Q[k]`` and a
sampling period ``tau[k]`` describe the interval that **ends** at measurement ``k``. Where the prior
sits is chosen by the filter's ``first_step`` argument (see :func:`jaxtrack.filters.run_filter`):

- ``first_step="update"`` (default; Ho 1968, dynamax): the prior is on ``x_0``, the state at the
  first measurement. ``F[0]``, ``Q[0]`` and ``tau[0]`` are not used.
- ``first_step="predict"`` (FilterPy's ``predict(); update(z)`` loop): the prior is on ``x_{-1}``,
  one transition before the first measurement, and ``F[0]``, ``Q[0]`` take it to ``x_0``.

Matrices may be constant, shape ``(n, n)``, or given per step, shape ``(T, n, n)``; the step index
``k`` picks the right one inside the scan. Everything that a researcher may differentiate (τ, Q, R,
the prior, biases) is an array leaf of the Module; static fields hold sizes and flags only.
"""

from __future__ import annotations

import abc
from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from .._validation import InputError, check_covariance, check_finite, check_shape
from ._layout import check_layout


def wrap_angle(angle: ArrayLike) -> Array:
    """Wrap an angle (radians) to the interval (−π, π].

    Written with ``jnp.where`` so the derivative is 1 everywhere except at the wrap point.

    **Arguments:**

    - ``angle``: the angle (rad), shape ``(...)``.

    **Returns:** the wrapped angle (rad), shape ``(...)``.
    """
    angle = jnp.asarray(angle)
    wrapped = jnp.remainder(angle + jnp.pi, 2 * jnp.pi) - jnp.pi
    # remainder maps +π to −π; the convention for bearings is (−π, π].
    return jnp.where(wrapped == -jnp.pi, jnp.pi, wrapped)


def affine_in_state(fn):
    """Mark a transition function as ``x ↦ F_k x (+ b_k)`` with ``F_k = transition_matrix(k)``.

    The mark is read from the class (:func:`~jaxtrack.models._components.affine_transition_matrix`),
    so a subclass that overrides the marked method loses it unless it marks its own. Filters use it
    to propagate moments exactly where sigma points would only reproduce ``F P Fᵀ`` (the
    unscented filter's prediction).

    **Arguments:** ``fn`` the method. **Returns:** ``fn``, marked.
    """
    fn.affine_in_state = True
    return fn


def at_step(a: Array, k, matrix_ndim: int) -> Array:
    """Return ``a`` if it is constant (``a.ndim == matrix_ndim``) or ``a[k]`` if given per step.

    **Arguments:**

    - ``a``: a matrix (``a.ndim == matrix_ndim``) or a per-step stack with a leading axis ``T``.
    - ``k``: the step index; ``matrix_ndim``: the rank of one step's value (e.g. 2 for ``(n, n)``).

    **Returns:** the value at step ``k``, of rank ``matrix_ndim``.
    """
    return a if a.ndim == matrix_ndim else a[k]


def _num_steps_of(**arrays_and_ndims) -> int | None:
    """The common leading length of the per-step arrays (``name=(array, matrix_ndim)``)."""
    steps = {
        name: a.shape[0]
        for name, (a, nd) in arrays_and_ndims.items()
        if a is not None and a.ndim == nd + 1
    }
    if len(set(steps.values())) > 1:
        listing = ", ".join(f"`{name}` has {t}" for name, t in steps.items())
        raise InputError(f"per-step model arrays disagree on the number of steps: {listing}.")
    return next(iter(steps.values()), None)


def _as_float_arrays(*arrays):
    """The arrays as jax arrays of one floating dtype (the promotion of theirs and ``float``)."""
    arrays = [jnp.asarray(a) for a in arrays]
    dtype = jnp.result_type(*arrays, float)
    return tuple(a.astype(dtype) for a in arrays)


def _check_noise_and_prior(Q, R, m0, P0, angle_components) -> None:
    """Shape and value checks shared by every model: prior, plant noise, measurement noise.

    The state dimension ``n`` is read from the square ``initial_cov`` and ``process_noise_cov``
    together, so a wrong-length ``initial_mean`` is blamed on ``initial_mean`` (not on the
    covariance it fails to match), and a wrong-size ``initial_cov`` on ``initial_cov``.
    """
    check_shape("initial_mean", m0, [(None,)])
    check_shape("initial_cov", P0, [(None, None)])
    check_shape("process_noise_cov", Q, [(None, None), (None, None, None)])
    if P0.shape[0] != P0.shape[1]:
        raise InputError(f"`initial_cov` must be square (n, n); got shape {P0.shape}.")
    if Q.shape[-1] != Q.shape[-2]:
        raise InputError(f"`process_noise_cov` must be square (n, n) or (T, n, n); got shape {Q.shape}.")
    n_mean, n_cov, n_q = m0.shape[0], P0.shape[0], Q.shape[-1]
    if n_mean != n_cov:
        if n_cov == n_q:
            raise InputError(
                f"`initial_mean` must have shape ({n_cov},) to match `initial_cov` {P0.shape} and "
                f"`process_noise_cov` {Q.shape}; got shape {m0.shape}."
            )
        raise InputError(
            f"`initial_cov` must have shape ({n_mean}, {n_mean}) to match `initial_mean` "
            f"{m0.shape}; got shape {P0.shape}."
        )
    n = n_mean
    check_shape("process_noise_cov", Q, [(n, n), (None, n, n)])
    check_shape("measurement_noise_cov", R, [(None, None), (None, None, None)])
    m = R.shape[-1]
    if R.shape[-2] != m:
        raise InputError(f"`measurement_noise_cov` must be square; got shape {R.shape}.")
    for idx in angle_components:
        if not 0 <= idx < m:
            raise InputError(f"`angle_components` entry {idx} is not a measurement index (m = {m}).")
    check_finite("initial_mean", m0)
    check_covariance("initial_cov", P0)
    check_covariance("process_noise_cov", Q, definite=False)
    check_covariance("measurement_noise_cov", R)


def _check_function_shape(name, fn, x, k, expected) -> None:
    """Raise ``InputError`` unless ``fn(x, k)`` (abstractly evaluated) has shape ``expected``."""
    try:
        out = jax.eval_shape(fn, x, k)
    except InputError:
        raise
    except Exception as error:  # noqa: BLE001  (any failure inside the user's function)
        raise InputError(
            f"`{name}` failed on a state of shape {x.shape} and a step index: "
            f"{type(error).__name__}: {error}"
        ) from error
    shape = getattr(out, "shape", None)
    if shape != tuple(expected):
        raise InputError(
            f"`{name}` must return shape {tuple(expected)} for a state of shape {x.shape}; "
            f"it returns {shape if shape is not None else type(out).__name__}."
        )


# Structures of models whose functions passed check_functions (see there).
_CHECKED_MODELS: set = set()


class AbstractStateSpaceModel(eqx.Module):
    """Base class of every state-space model: a Gaussian prior, dynamics and a measurement model.

    Subclasses provide :meth:`transition`, :meth:`measurement`, :meth:`process_noise_cov` and
    :meth:`measurement_noise_cov`. The Jacobians default to ``jax.jacfwd`` of the mean functions;
    a subclass may override them with analytic ones. :meth:`residual` subtracts measurements and
    wraps the components listed in ``angle_components`` to (−π, π].

    To write your own nonlinear model, subclass this and implement the four methods as ordinary
    methods (not lambdas in fields), so that rebuilding the model does not recompile.
    """

    initial_mean: eqx.AbstractVar[Float[Array, " n"]]
    initial_cov: eqx.AbstractVar[Float[Array, "n n"]]
    angle_components: eqx.AbstractVar[tuple[int, ...]]

    @abc.abstractmethod
    def transition(self, x: Float[Array, " n"], k: Int[Array, ""]) -> Float[Array, " n"]:
        """Mean of ``x_k`` given ``x_{k-1} = x``: ``f_k(x)``."""

    @abc.abstractmethod
    def measurement(self, x: Float[Array, " n"], k: Int[Array, ""]) -> Float[Array, " m"]:
        """Mean of ``z_k`` given ``x_k = x``: ``h_k(x)``."""

    @abc.abstractmethod
    def process_noise_cov(self, k: Int[Array, ""]) -> Float[Array, "n n"]:
        """``Q_k``, the covariance of the plant noise on the interval ending at step ``k``."""

    @abc.abstractmethod
    def measurement_noise_cov(self, k: Int[Array, ""]) -> Float[Array, "m m"]:
        """``R_k``, the measurement-noise covariance at step ``k``."""

    @property
    @abc.abstractmethod
    def num_steps(self) -> int | None:
        """Number of steps the per-step arrays cover, or ``None`` if the model is time-invariant."""

    def transition_jacobian(self, x: Float[Array, " n"], k) -> Float[Array, "n n"]:
        """``Φ_k = ∂f_k/∂x`` at ``x`` (by ``jax.jacfwd`` unless overridden)."""
        return jax.jacfwd(self.transition)(x, k)

    def measurement_jacobian(self, x: Float[Array, " n"], k) -> Float[Array, "m n"]:
        """``H_k = ∂h_k/∂x`` at ``x`` (by ``jax.jacfwd`` unless overridden)."""
        return jax.jacfwd(self.measurement)(x, k)

    def residual(self, z: Float[Array, " m"], z_pred: Float[Array, " m"]) -> Float[Array, " m"]:
        """``z − ẑ`` with the components in ``angle_components`` wrapped to (−π, π]."""
        diff = z - z_pred
        if not self.angle_components:
            return diff
        # A static 0/1 pattern and `where` rather than a scatter (`.at[idx].set`): under `vmap`
        # the scatter is a per-element kernel on CPU, the `where` fuses with its neighbours.
        is_angle = np.zeros(diff.shape[-1], bool)
        is_angle[list(self.angle_components)] = True
        return jnp.where(is_angle, wrap_angle(diff), diff)

    def check_functions(self) -> None:
        """Raise ``InputError`` if the model's functions return the wrong shapes (trace-time).

        ``transition(x, k)`` must return ``(n,)`` and ``measurement(x, k)`` ``(m,)`` for a state
        ``x`` of shape ``(n,)`` and a step index ``k``; otherwise the failure would surface deep
        inside a ``jnp`` operation (or broadcast silently) without naming the function. Checked
        with ``jax.eval_shape``, which costs one abstract trace and no arithmetic; called by the
        entry points (:func:`~jaxtrack.filters.run_filter`,
        :func:`~jaxtrack.montecarlo.simulate`, …).

        **Returns:** ``None``.

        **Raises:** ``InputError`` naming the function, the expected and the actual shape.
        """
        # The abstract trace costs ~10-25 ms; a model of the same structure (types, functions,
        # static fields, leaf shapes and dtypes) returns the same shapes, so check it once.
        leaves, treedef = jax.tree_util.tree_flatten(self)
        key = (treedef, tuple((jnp.shape(a), jnp.result_type(a)) for a in leaves))
        try:
            if key in _CHECKED_MODELS:
                return
        except TypeError:  # an unhashable static field: check every time
            key = None
        n = self.initial_mean.shape[-1]
        x = jax.ShapeDtypeStruct((n,), self.initial_mean.dtype)
        k = jax.ShapeDtypeStruct((), jnp.int32)
        m = self.meas_dim
        for name, fn, expected in self._function_specs(n, m):
            _check_function_shape(name, fn, x, k, expected)
        if key is not None:
            if len(_CHECKED_MODELS) > 4096:
                _CHECKED_MODELS.clear()
            _CHECKED_MODELS.add(key)

    def _function_specs(self, n: int, m: int):
        """``(name, function, expected output shape)`` for :meth:`check_functions`."""
        return (("model.transition", self.transition, (n,)), ("model.measurement", self.measurement, (m,)))

    @property
    def state_dim(self) -> int:
        return self.initial_mean.shape[-1]

    @property
    def state_layout(self) -> tuple[str, ...] | None:
        """What each state component is (e.g. ``("x", "y", "vx", "vy")``), or None if not declared.

        See :mod:`jaxtrack.models._layout`; IMM members are embedded in the common state by it.
        """
        return None

    @property
    def meas_dim(self) -> int:
        return self.measurement_noise_cov(0).shape[-1]


class LinearGaussianModel(AbstractStateSpaceModel):
    r"""Linear-Gaussian model ``x_k = F_k x_{k-1} + b_k + w_k``, ``z_k = H_k x_k + v_k``.

    **Arguments** (``n`` states, ``m`` measurement components, ``T`` steps when per-step):

    - ``transition_matrix``: ``F``, shape ``(n, n)`` or ``(T, n, n)``. ``F[k]`` maps the state at
      step ``k-1`` to step ``k`` (the paper's Φ_{k-1}).
    - ``process_noise_cov``: ``Q``, shape ``(n, n)`` or ``(T, n, n)``, positive semidefinite.
    - ``measurement_matrix``: ``H``, shape ``(m, n)`` or ``(T, m, n)``.
    - ``measurement_noise_cov``: ``R``, shape ``(m, m)`` or ``(T, m, m)``, positive definite.
    - ``initial_mean``, ``initial_cov``: the prior, shapes ``(n,)`` and ``(n, n)``; where it sits
      (at the first measurement or one step before) is set by the filter's ``first_step``.
    - ``transition_offset``: optional known input ``b``, shape ``(n,)`` or ``(T, n)`` (e.g. the
      observer's displacement in a relative-state bearings-only model).
    - ``angle_components``: indices of measurement components that are angles (radians); their
      residuals are wrapped to (−π, π].
    - ``state_layout``: optional names of the ``n`` state components, e.g. ``("x", "y", "vx",
      "vy")`` (:mod:`jaxtrack.models._layout`; set by :func:`~jaxtrack.models.constant_velocity`
      and the other kinematic builders); IMM members are embedded in the common state by it.

    Units are the caller's; the library only requires them to be consistent (SI and radians in
    all built-in models, except Ho's plant in feet).

    The arrays are stored as the fields ``F``, ``Q``, ``H``, ``R`` and ``b``; read them per step
    with :meth:`transition_matrix`, :meth:`process_noise_cov`, :meth:`measurement_matrix` and
    :meth:`measurement_noise_cov`. All arrays are leaves, so ``jax.grad`` with respect to any of them (or to a sampling schedule
    that built them) works. Values are checked at construction when they are concrete.
    """

    F: Float[Array, "*T n n"]
    Q: Float[Array, "*T n n"]
    H: Float[Array, "*T m n"]
    R: Float[Array, "*T m m"]
    initial_mean: Float[Array, " n"]
    initial_cov: Float[Array, "n n"]
    b: Float[Array, "*T n"] | None
    angle_components: tuple[int, ...] = eqx.field(static=True)
    _layout: tuple[str, ...] | None = eqx.field(static=True, default=None)

    def __init__(
        self,
        transition_matrix: ArrayLike,
        process_noise_cov: ArrayLike,
        measurement_matrix: ArrayLike,
        measurement_noise_cov: ArrayLike,
        initial_mean: ArrayLike,
        initial_cov: ArrayLike,
        *,
        transition_offset: ArrayLike | None = None,
        angle_components: tuple[int, ...] = (),
        state_layout: Sequence | None = None,
    ):
        F, Q, H, R, m0, P0 = _as_float_arrays(
            transition_matrix, process_noise_cov, measurement_matrix, measurement_noise_cov, initial_mean,
            initial_cov)
        dtype = F.dtype

        _check_noise_and_prior(Q, R, m0, P0, angle_components)
        n, m = m0.shape[0], R.shape[-1]
        check_shape("transition_matrix", F, [(n, n), (None, n, n)])
        check_shape("measurement_matrix", H, [(m, n), (None, m, n)])
        check_finite("transition_matrix", F)
        check_finite("measurement_matrix", H)
        b = None
        if transition_offset is not None:
            b = jnp.asarray(transition_offset).astype(dtype)
            check_shape("transition_offset", b, [(n,), (None, n)])
            check_finite("transition_offset", b)

        self.F = F
        self.Q = Q
        self.H = H
        self.R = R
        self.initial_mean = m0
        self.initial_cov = P0
        self.b = b
        self.angle_components = tuple(int(i) for i in angle_components)
        self._layout = check_layout("state_layout", state_layout, n)
        _num_steps_of(
            transition_matrix=(F, 2),
            process_noise_cov=(Q, 2),
            measurement_matrix=(H, 2),
            measurement_noise_cov=(R, 2),
            transition_offset=(b, 1),
        )

    @property
    def num_steps(self) -> int | None:
        return _num_steps_of(F=(self.F, 2), Q=(self.Q, 2), H=(self.H, 2), R=(self.R, 2), b=(self.b, 1))

    @property
    def meas_dim(self) -> int:
        return self.H.shape[-2]

    @property
    def state_layout(self) -> tuple[str, ...] | None:
        return self._layout

    def check_functions(self) -> None:
        """Nothing to trace: the shapes of ``F``, ``H`` and ``b`` were checked at construction."""

    def transition_matrix(self, k) -> Float[Array, "n n"]:
        """``F_k``: maps the state at step ``k-1`` to step ``k``."""
        return at_step(self.F, k, 2)

    def measurement_matrix(self, k) -> Float[Array, "m n"]:
        """``H_k``."""
        return at_step(self.H, k, 2)

    def process_noise_cov(self, k) -> Float[Array, "n n"]:
        return at_step(self.Q, k, 2)

    def measurement_noise_cov(self, k) -> Float[Array, "m m"]:
        return at_step(self.R, k, 2)

    @affine_in_state
    def transition(self, x, k):
        fx = self.transition_matrix(k) @ x
        if self.b is not None:
            fx = fx + at_step(self.b, k, 1)
        return fx

    def measurement(self, x, k):
        return self.measurement_matrix(k) @ x

    # Linear: the Jacobians are the matrices themselves (jacfwd would give the same, at n JVPs).
    def transition_jacobian(self, x, k):
        return self.transition_matrix(k)

    def measurement_jacobian(self, x, k):
        return self.measurement_matrix(k)


class NonlinearGaussianModel(AbstractStateSpaceModel):
    r"""Nonlinear model with additive Gaussian noise from user callables.

    ``x_k = f(x_{k-1}, k) + w_k``, ``z_k = h(x_k, k) + v_k``.

    **Arguments:**

    - ``transition_fn``: ``f(x, k) -> x'``, shapes ``(n,), () -> (n,)``.
    - ``measurement_fn``: ``h(x, k) -> z``, shapes ``(n,), () -> (m,)``.
    - ``process_noise_cov``: ``Q``, shape ``(n, n)`` or ``(T, n, n)``.
    - ``measurement_noise_cov``: ``R``, shape ``(m, m)`` or ``(T, m, m)``.
    - ``initial_mean``, ``initial_cov``: the prior, shapes ``(n,)`` and ``(n, n)``.
    - ``transition_jacobian_fn``, ``measurement_jacobian_fn``: optional analytic Jacobians with the
      same signature as ``f`` and ``h``; ``jax.jacfwd`` is used when they are not given.
    - ``angle_components``: measurement indices that are angles (radians), wrapped to (−π, π].
    - ``state_layout``: optional names of the ``n`` state components (as for
      :class:`LinearGaussianModel`).

    !!! note
        The callables are compared by identity under ``jit``: define them once (a ``def`` at
        module level), not as a fresh ``lambda`` per call, or every call recompiles. For a model
        with parameters you want to differentiate, subclass :class:`AbstractStateSpaceModel`
        instead and keep the parameters as array fields.
    """

    transition_fn: Callable = eqx.field(static=True)
    measurement_fn: Callable = eqx.field(static=True)
    Q: Float[Array, "*T n n"]
    R: Float[Array, "*T m m"]
    initial_mean: Float[Array, " n"]
    initial_cov: Float[Array, "n n"]
    transition_jacobian_fn: Callable | None = eqx.field(static=True)
    measurement_jacobian_fn: Callable | None = eqx.field(static=True)
    angle_components: tuple[int, ...] = eqx.field(static=True)
    _layout: tuple[str, ...] | None = eqx.field(static=True, default=None)

    def __init__(
        self,
        transition_fn: Callable,
        measurement_fn: Callable,
        process_noise_cov: ArrayLike,
        measurement_noise_cov: ArrayLike,
        initial_mean: ArrayLike,
        initial_cov: ArrayLike,
        *,
        transition_jacobian_fn: Callable | None = None,
        measurement_jacobian_fn: Callable | None = None,
        angle_components: tuple[int, ...] = (),
        state_layout: Sequence | None = None,
    ):
        Q, R, m0, P0 = _as_float_arrays(process_noise_cov, measurement_noise_cov, initial_mean, initial_cov)
        for name, fn in (("transition_fn", transition_fn), ("measurement_fn", measurement_fn)):
            if not callable(fn):
                raise InputError(f"`{name}` must be a callable f(x, k); got {type(fn).__name__}.")
        _check_noise_and_prior(Q, R, m0, P0, angle_components)
        self.transition_fn = transition_fn
        self.measurement_fn = measurement_fn
        self.Q = Q
        self.R = R
        self.initial_mean = m0
        self.initial_cov = P0
        self.transition_jacobian_fn = transition_jacobian_fn
        self.measurement_jacobian_fn = measurement_jacobian_fn
        self.angle_components = tuple(int(i) for i in angle_components)
        self._layout = check_layout("state_layout", state_layout, m0.shape[0])
        _num_steps_of(process_noise_cov=(Q, 2), measurement_noise_cov=(R, 2))

    @property
    def num_steps(self) -> int | None:
        return _num_steps_of(Q=(self.Q, 2), R=(self.R, 2))

    @property
    def state_layout(self) -> tuple[str, ...] | None:
        return self._layout

    def _function_specs(self, n: int, m: int):
        specs = [("transition_fn", self.transition_fn, (n,)), ("measurement_fn", self.measurement_fn, (m,))]
        if self.transition_jacobian_fn is not None:
            specs.append(("transition_jacobian_fn", self.transition_jacobian_fn, (n, n)))
        if self.measurement_jacobian_fn is not None:
            specs.append(("measurement_jacobian_fn", self.measurement_jacobian_fn, (m, n)))
        return tuple(specs)

    def transition(self, x, k):
        return self.transition_fn(x, k)

    def measurement(self, x, k):
        return self.measurement_fn(x, k)

    def process_noise_cov(self, k):
        return at_step(self.Q, k, 2)

    def measurement_noise_cov(self, k):
        return at_step(self.R, k, 2)

    def transition_jacobian(self, x, k):
        if self.transition_jacobian_fn is not None:
            return self.transition_jacobian_fn(x, k)
        return jax.jacfwd(self.transition_fn)(x, k)

    def measurement_jacobian(self, x, k):
        if self.measurement_jacobian_fn is not None:
            return self.measurement_jacobian_fn(x, k)
        return jax.jacfwd(self.measurement_fn)(x, k)

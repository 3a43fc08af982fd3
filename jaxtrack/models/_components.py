"""Model components: a transition model and a measurement model, composed into a state-space model.

A tracking problem is usually assembled from parts a researcher picks separately: a motion model
(constant velocity, coordinated turn, …) and a sensor model (range–bearing radar, bearings-only
sonar, …). The two abstract classes here are those parts, and :class:`TrackingModel` joins one
of each with a Gaussian prior into an :class:`~jaxtrack.models.AbstractStateSpaceModel` that every
filter, smoother and Monte Carlo routine of jaxtrack accepts::

    model = TrackingModel(
        transition=CoordinatedTurn(1.0, turn_rate=0.05, noise_intensity=0.1),
        measurement=RangeBearing(noise_std=(10.0, 0.01), sensor_position=(0.0, 0.0)),
        initial_mean=m0, initial_cov=P0,
    )

Components are equinox Modules: every parameter (noise levels, turn rate, sensor pose, biases) is
an array leaf, so ``jax.grad`` with respect to it works through any filter.
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
from jaxtyping import Array, ArrayLike, Float, Int

from .._validation import InputError, check_covariance, check_finite, check_shape
from ._base import AbstractStateSpaceModel, _as_float_arrays


class AbstractTransitionModel(eqx.Module):
    """A motion model ``x_k = f_k(x_{k-1}) + w_k``, ``w_k ~ N(0, Q_k)``.

    Subclasses implement :meth:`mean`, :meth:`noise_cov` and :attr:`state_dim`; :meth:`jacobian`
    defaults to ``jax.jacfwd`` of :meth:`mean` and should be overridden with the analytic one.
    """

    @abc.abstractmethod
    def mean(self, x: Float[Array, " n"], k: Int[ArrayLike, ""]) -> Float[Array, " n"]:
        """``f_k(x)``: the mean of ``x_k`` given ``x_{k-1} = x``."""

    @abc.abstractmethod
    def noise_cov(self, k: Int[ArrayLike, ""]) -> Float[Array, "n n"]:
        """``Q_k``: the plant-noise covariance on the interval ending at step ``k``."""

    @property
    @abc.abstractmethod
    def state_dim(self) -> int:
        """The state dimension ``n``."""

    def jacobian(self, x: Float[Array, " n"], k: Int[ArrayLike, ""]) -> Float[Array, "n n"]:
        """``∂f_k/∂x`` at ``x`` (``jax.jacfwd`` unless overridden)."""
        return jax.jacfwd(self.mean)(x, k)

    @property
    def num_steps(self) -> int | None:
        """Steps covered by per-step parameters, or ``None`` if time-invariant."""
        return None

    @property
    def state_layout(self) -> tuple[str, ...] | None:
        """What each state component is, e.g. ``("x", "y", "vx", "vy")``; None if not declared.

        See :mod:`jaxtrack.models._layout` for the names. Sensors and IMM members are checked
        against it (:class:`TrackingModel`, :class:`~jaxtrack.filters.InteractingMultipleModel`).
        """
        return None


class AbstractMeasurementModel(eqx.Module):
    """A sensor model ``z_k = h_k(x_k) + v_k``, ``v_k ~ N(0, R_k)``.

    Subclasses implement :meth:`mean`, :meth:`noise_cov`, :attr:`meas_dim` and
    ``angle_components`` (indices of measurement components in radians, whose residuals wrap to
    (−π, π]); :meth:`jacobian` defaults to ``jax.jacfwd`` of :meth:`mean`.
    """

    angle_components: eqx.AbstractVar[tuple[int, ...]]

    @abc.abstractmethod
    def mean(self, x: Float[Array, " n"], k: Int[ArrayLike, ""]) -> Float[Array, " m"]:
        """``h_k(x)``: the noise-free measurement of state ``x`` at step ``k``."""

    @abc.abstractmethod
    def noise_cov(self, k: Int[ArrayLike, ""]) -> Float[Array, "m m"]:
        """``R_k``: the measurement-noise covariance at step ``k``."""

    @property
    @abc.abstractmethod
    def meas_dim(self) -> int:
        """The measurement dimension ``m``."""

    def jacobian(self, x: Float[Array, " n"], k: Int[ArrayLike, ""]) -> Float[Array, "m n"]:
        """``∂h_k/∂x`` at ``x`` (``jax.jacfwd`` unless overridden)."""
        return jax.jacfwd(self.mean)(x, k)

    @property
    def num_steps(self) -> int | None:
        """Steps covered by per-step parameters, or ``None`` if time-invariant."""
        return None

    def check_state_layout(self, layout: tuple[str, ...]) -> None:
        """Raise ``InputError`` if this sensor cannot read a state of ``layout`` (default: no check).

        Called by :class:`TrackingModel` with the transition model's
        :attr:`~AbstractTransitionModel.state_layout` when it is declared.
        """


class TrackingModel(AbstractStateSpaceModel):
    """A state-space model assembled from a transition model, a measurement model and a prior.

    **Arguments:**

    - ``transition``: an :class:`AbstractTransitionModel` (``n`` states).
    - ``measurement``: an :class:`AbstractMeasurementModel` (``m`` components) of the same state.
    - ``initial_mean`` ``(n,)``, ``initial_cov`` ``(n, n)``: the Gaussian prior (where it sits is
      set by the filter's ``first_step``, see :mod:`jaxtrack.models`).

    The model's Jacobians are the components' (analytic where they provide them), and its
    ``angle_components`` are the measurement model's. Its ``state_layout`` is the transition
    model's; when declared, the measurement model is checked against it
    (:meth:`AbstractMeasurementModel.check_state_layout`: e.g. a 3-D radar on a 2-D state).

    **Raises:** ``InputError`` naming the argument on a wrong type, shape, a non-finite or
    non-positive-definite prior, or a sensor that reads the wrong state components.
    """

    transition_model: AbstractTransitionModel
    measurement_model: AbstractMeasurementModel
    initial_mean: Float[Array, " n"]
    initial_cov: Float[Array, "n n"]

    def __init__(
        self,
        transition: AbstractTransitionModel,
        measurement: AbstractMeasurementModel,
        initial_mean: ArrayLike,
        initial_cov: ArrayLike,
    ):
        if not isinstance(transition, AbstractTransitionModel):
            raise InputError(
                f"`transition` must be a jaxtrack transition model (AbstractTransitionModel); "
                f"got {type(transition).__name__}."
            )
        if not isinstance(measurement, AbstractMeasurementModel):
            raise InputError(
                f"`measurement` must be a jaxtrack measurement model (AbstractMeasurementModel); "
                f"got {type(measurement).__name__}."
            )
        m0, P0 = _as_float_arrays(initial_mean, initial_cov)
        n = transition.state_dim
        check_shape("initial_mean", m0, [(n,)])
        check_shape("initial_cov", P0, [(n, n)])
        check_finite("initial_mean", m0)
        check_covariance("initial_cov", P0)
        layout = transition.state_layout
        if layout is not None:
            measurement.check_state_layout(layout)
        self.transition_model = transition
        self.measurement_model = measurement
        self.initial_mean = m0
        self.initial_cov = P0

    @property
    def angle_components(self) -> tuple[int, ...]:
        return tuple(self.measurement_model.angle_components)

    @property
    def num_steps(self) -> int | None:
        steps = {s for s in (self.transition_model.num_steps, self.measurement_model.num_steps) if s is not None}
        if len(steps) > 1:
            raise InputError(f"the transition and measurement models disagree on the number of steps: {steps}.")
        return next(iter(steps), None)

    @property
    def meas_dim(self) -> int:
        return self.measurement_model.meas_dim

    @property
    def state_layout(self) -> tuple[str, ...] | None:
        return self.transition_model.state_layout

    def transition(self, x, k):
        return self.transition_model.mean(x, k)

    def measurement(self, x, k):
        return self.measurement_model.mean(x, k)

    def transition_jacobian(self, x, k):
        return self.transition_model.jacobian(x, k)

    def measurement_jacobian(self, x, k):
        return self.measurement_model.jacobian(x, k)

    def process_noise_cov(self, k):
        return self.transition_model.noise_cov(k)

    def measurement_noise_cov(self, k):
        return self.measurement_model.noise_cov(k)


def affine_transition_matrix(model: AbstractStateSpaceModel, k) -> Array | None:
    """``F_k`` when ``model.transition`` is ``x ↦ F_k x (+ b_k)`` by construction, else None.

    Decided at trace time from the classes alone: a :class:`~jaxtrack.models.LinearGaussianModel`,
    or a :class:`TrackingModel` whose motion model's ``mean`` carries the
    :func:`~jaxtrack.models._base.affine_in_state` mark (``LinearTransition``, ``ConstantVelocity``,
    ``ConstantAcceleration``, ``CoordinatedTurn`` with its known turn rate). A subclass that
    overrides the function is not affine unless it marks its own.

    **Arguments:** ``model``; ``k`` the step index. **Returns:** ``F_k`` ``(n, n)`` or None.
    """
    if getattr(type(model).transition, "affine_in_state", False):
        return model.transition_matrix(k)
    if isinstance(model, TrackingModel) and type(model).transition is TrackingModel.transition:
        motion = model.transition_model
        if getattr(type(motion).mean, "affine_in_state", False):
            return motion.transition_matrix(k)
    return None

"""jaxtrack: differentiable state estimation for target tracking and navigation research.

Importing jaxtrack switches JAX to float64 (see :mod:`jaxtrack._config` for why and how to opt
out with ``JAXTRACK_ENABLE_X64=0``).

The subpackages are imported on first use (PEP 562 module ``__getattr__``): ``import jaxtrack``
itself does not import JAX, so ``jaxtrack --help`` and ``--version`` answer at once. When JAX is
not imported yet, float64 is requested through ``JAX_ENABLE_X64`` (JAX reads it when it is
first imported); when it is, ``jax.config`` is updated.
"""

from __future__ import annotations

import importlib

from ._config import _request_x64

_request_x64()

__version__ = "0.1.0"

_SUBPACKAGES = (
    "filters", "models", "montecarlo", "covariance", "sensitivity", "learning", "bounds",
    "association", "fusion", "multitarget",
)
__all__ = [*_SUBPACKAGES, "InputError", "__version__"]


def __getattr__(name: str):
    if name in _SUBPACKAGES:
        return importlib.import_module(f".{name}", __name__)
    if name == "InputError":
        from ._validation import InputError

        return InputError
    raise AttributeError(f"module 'jaxtrack' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))

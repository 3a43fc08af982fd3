"""Numerical precision policy.

jaxtrack switches JAX to 64-bit floats when it is imported, because several of the reference
studies lose their meaning in float32 (the pseudo-linear bearings-only filter of
``specs/bearings-tma.md`` §6 produces indefinite covariances and errors of hundreds of km; Ho's
covariances span 1e-2 to 1e6 ft² in one matrix).

To opt out, set the environment variable ``JAXTRACK_ENABLE_X64=0`` *before* importing jaxtrack
(then JAX's own ``JAX_ENABLE_X64`` setting is left as it is), or call
``jax.config.update("jax_enable_x64", False)`` after the import. Every function in the library
follows the dtype of its inputs, so float32 works wherever the arithmetic allows it.
"""

from __future__ import annotations

import os
import sys

_OPT_OUT_VALUES = {"0", "false", "no", "off"}


def _opted_out() -> bool:
    return os.environ.get("JAXTRACK_ENABLE_X64", "1").strip().lower() in _OPT_OUT_VALUES


def _request_x64() -> None:
    """Ask for float64 unless the user opted out, without importing JAX.

    JAX already imported: ``jax.config.update`` (cheap, the module is there). Not yet: set
    ``JAX_ENABLE_X64=1``, which JAX reads when it is first imported, so that importing jaxtrack
    stays free of the JAX import (the command line's ``--help`` and ``--version``). The
    variable is inherited by child processes: a child that should run in float32 needs
    ``JAX_ENABLE_X64=0`` as well as ``JAXTRACK_ENABLE_X64=0``.
    """
    if _opted_out():
        return
    jax = sys.modules.get("jax")
    if jax is not None and hasattr(jax, "config"):
        jax.config.update("jax_enable_x64", True)
    else:
        os.environ["JAX_ENABLE_X64"] = "1"


def float_dtype():
    """The default float dtype under the current JAX configuration (float64 or float32)."""
    import jax

    return jax.numpy.float64 if jax.config.jax_enable_x64 else jax.numpy.float32

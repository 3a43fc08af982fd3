"""`import jaxtrack` does not import JAX; float64 is still switched on; the CLI's --help and
--version answer without JAX (issue 23); the test suite's shape checking is really on."""

from __future__ import annotations

import os
import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest


def _run(code: str, **env) -> str:
    full = {k: v for k, v in os.environ.items() if k not in ("JAX_ENABLE_X64", "JAXTRACK_ENABLE_X64")}
    full.update(env)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=full, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


@pytest.mark.parametrize("flag", ["--version", "--help"])
def test_cli_flags_do_not_import_jax(flag):
    code = ("import sys\nfrom jaxtrack.cli import main\nrc = main([%r])\n"
            "print('RC', rc, 'JAX', 'jax' in sys.modules, 'JAXLIB', 'jaxlib' in sys.modules)") % flag
    last = _run(code).splitlines()[-1]
    assert last == "RC 0 JAX False JAXLIB False", last


def test_import_jaxtrack_is_float64_before_and_after_jax():
    assert _run("import jaxtrack, jax.numpy as jnp; print(jnp.zeros(1).dtype)") == "float64"
    assert _run("import jax.numpy as jnp; import jaxtrack; print(jnp.zeros(1).dtype)") == "float64"
    assert _run("import jaxtrack, jax.numpy as jnp; print(jnp.zeros(1).dtype)", JAXTRACK_ENABLE_X64="0") == "float32"
    # subpackages and InputError on first use
    assert _run("import jaxtrack; print(jaxtrack.filters.KalmanFilter.__name__, jaxtrack.InputError.__name__)") \
        == "KalmanFilter InputError"


@pytest.mark.skipif(os.environ.get("JAXTRACK_TYPECHECK", "1") == "0", reason="shape checking switched off")
def test_shape_checking_is_active_in_the_suite():
    """conftest decorates the numeric modules although jaxtrack imports them lazily."""
    from jaxtrack.filters._linalg import cholesky

    with pytest.raises(Exception, match="(?i)type-check|typecheck"):
        cholesky(jnp.asarray(np.ones((2, 3))))

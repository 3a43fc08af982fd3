"""JAX's persistent compilation cache for the command line: on by default, in a user cache folder.

A study compiles the same programs every time it runs; JAX can keep the compiled executables on
disk (its *persistent compilation cache*) and load them instead of compiling again. The command
line turns that cache on, so a second ``jaxtrack reproduce`` (or ``demo``, ``design``) mostly
skips XLA's compiler (``benchmarks/first_call.py`` measures cold against warm).

Where (first that applies):

1. ``--no-compilation-cache`` or ``JAXTRACK_CACHE_DIR=off`` (also ``0``, ``no``, ``false``, or
   empty): no persistent cache.
2. ``JAXTRACK_CACHE_DIR=PATH``: that folder.
3. ``JAX_COMPILATION_CACHE_DIR`` already set (JAX's own variable): JAX's setting, left alone.
4. Otherwise ``$XDG_CACHE_HOME/jaxtrack/jax`` (``~/.cache/jaxtrack/jax`` when
   ``XDG_CACHE_HOME`` is unset).

The entries are keyed by JAX on the program, the jax/jaxlib versions, the compile options and
the device, so a stale entry is never used; deleting the folder is always safe. Every
compilation is written, however short (JAX's default writes only those of at least 1 s): a
study also compiles hundreds of small programs (its eager array operations, ~40 ms each), and
with them cached a warm ``reproduce tma`` takes 18.8 s instead of 26.2 s (cold 30-38 s;
``benchmarks/first_call.py``). The entries are small (about 7 kB each). The library itself
(``import jaxtrack``) never turns the cache on: that is JAX's setting, and a user's to choose.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

# Values of JAXTRACK_CACHE_DIR (and the suite's JAXTRACK_TEST_CACHE_DIR) that mean "no cache".
OFF_VALUES = frozenset({"", "0", "off", "no", "false", "none"})
# Write compilations that took at least this long (seconds): all of them (JAX's default is 1.0).
MIN_COMPILE_TIME_S = 0.0


def cache_dir(disabled: bool = False, environ=os.environ) -> Path | None:
    """The folder the command line uses as JAX's persistent compilation cache, or None for none.

    **Arguments:** ``disabled``: ``--no-compilation-cache`` was given; ``environ``: the
    environment to read (default ``os.environ``).

    **Returns:** the folder (not created here), or None when the cache is off or when JAX's own
    ``JAX_COMPILATION_CACHE_DIR`` is set (then JAX uses it, and this module leaves it alone).
    """
    if disabled:
        return None
    setting = environ.get("JAXTRACK_CACHE_DIR")
    if setting is not None:
        return None if setting.strip().lower() in OFF_VALUES else Path(setting).expanduser()
    if environ.get("JAX_COMPILATION_CACHE_DIR"):
        return None
    base = environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "jaxtrack" / "jax"


def configure(disabled: bool = False) -> Path | None:
    """Turn JAX's persistent compilation cache on for this process (and the children it starts).

    Called by the command line before any computation. Works whether or not JAX has been
    imported yet: before, through JAX's environment variables (read at its import, and inherited
    by child processes such as a sharded run's workers); after, through ``jax.config``.

    **Returns:** the cache folder in use, or None (off, or JAX's own setting left in place).
    """
    path = cache_dir(disabled)
    if disabled or (path is None and os.environ.get("JAXTRACK_CACHE_DIR") is not None):
        # Off: make sure an inherited JAX setting does not turn it back on.
        os.environ.pop("JAX_COMPILATION_CACHE_DIR", None)
        jax = sys.modules.get("jax")
        if jax is not None and hasattr(jax, "config"):
            jax.config.update("jax_compilation_cache_dir", None)
        return None
    if path is None:
        return None
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a read-only home: run without the cache rather than fail
        print(f"jaxtrack: compilation cache off ({path}: {exc.strerror})", file=sys.stderr)
        return None
    os.environ["JAX_COMPILATION_CACHE_DIR"] = str(path)
    os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = str(MIN_COMPILE_TIME_S)
    jax = sys.modules.get("jax")
    if jax is not None and hasattr(jax, "config"):
        jax.config.update("jax_compilation_cache_dir", str(path))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_TIME_S)
    return path

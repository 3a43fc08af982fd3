"""The command line's persistent compilation cache (jaxtrack/cli/_cache.py): where, and off."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from jaxtrack.cli import _cache


@pytest.mark.parametrize(
    "environ, disabled, expected",
    [
        ({"HOME": "/h"}, False, Path("/h/.cache/jaxtrack/jax")),
        ({"HOME": "/h", "XDG_CACHE_HOME": "/x"}, False, Path("/x/jaxtrack/jax")),
        ({"HOME": "/h", "JAXTRACK_CACHE_DIR": "/c"}, False, Path("/c")),
        ({"HOME": "/h", "JAXTRACK_CACHE_DIR": "off"}, False, None),
        ({"HOME": "/h", "JAXTRACK_CACHE_DIR": ""}, False, None),
        ({"HOME": "/h", "JAX_COMPILATION_CACHE_DIR": "/j"}, False, None),  # JAX's own: left alone
        ({"HOME": "/h", "JAXTRACK_CACHE_DIR": "/c"}, True, None),  # --no-compilation-cache
    ],
)
def test_cache_dir_rules(environ, disabled, expected, monkeypatch):
    monkeypatch.setattr(Path, "home", classmethod(lambda cls: Path(environ["HOME"])))
    assert _cache.cache_dir(disabled, environ) == expected


def test_off_clears_an_inherited_jax_setting(monkeypatch):
    import jax

    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", "/somewhere")
    before = jax.config.jax_compilation_cache_dir
    try:
        assert _cache.configure(disabled=True) is None
        assert "JAX_COMPILATION_CACHE_DIR" not in os.environ
        assert jax.config.jax_compilation_cache_dir is None
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


def test_a_cli_run_writes_its_compilations_to_the_cache(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    env["JAXTRACK_CACHE_DIR"] = str(tmp_path / "cache")
    cmd = [sys.executable, "-m", "jaxtrack.cli", "demo", "--runs", "50", "--steps", "5", "--no-progress", "--json",
           "--out", str(tmp_path / "out")]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert p.returncode == 0, p.stderr[-2000:]
    entries = list((tmp_path / "cache").iterdir())
    assert entries, "the demo wrote nothing to JAXTRACK_CACHE_DIR"
    # The same run again loads every program it compiles from the cache, the short ones included
    # (_cache.MIN_COMPILE_TIME_S = 0: a study's hundreds of ~40 ms eager-op compilations were
    # compiled again on every warm run). JAX_LOG_COMPILES logs each compilation ("Compiling ...",
    # then "Finished XLA compilation of NAME") and, in between, each hit. No exception: run_filter's
    # program once held an eqx.error_if (a host callback, which JAX never caches); `throw` is now
    # applied outside it (tests/test_cacheable_programs.py).
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env={**env, "JAX_LOG_COMPILES": "1"})
    assert p.returncode == 0, p.stderr[-2000:]
    compiled, missed, hit = 0, [], False
    for line in p.stderr.splitlines():
        if line.startswith("Compiling "):
            hit = False
        elif "Persistent compilation cache hit" in line:
            hit = True
        elif line.startswith("Finished XLA compilation of "):
            compiled += 1
            if not hit:
                missed.append(line.split()[4])
    assert compiled > 10 and missed == [], (compiled, missed)

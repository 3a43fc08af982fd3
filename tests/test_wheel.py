"""A wheel built from the repository installs into a fresh venv and works outside the repository
(issue 23): `jaxtrack --version` and `jaxtrack demo --runs 100` from a temporary directory.

The wheel is built without build isolation (setuptools comes from the test extra) and installed
with `--no-deps --no-index`, so nothing is downloaded at test time. The fresh venv reaches the
dependencies (jax, equinox, …) through a `.pth` line naming this venv's site-packages; a path in
a `.pth` is appended to `sys.path` without running the `.pth` files it holds, so the editable
install of the checkout is not seen, and the test asserts that `jaxtrack` is imported from the
wheel's copy.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _run(args, cwd, timeout=600):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "JAX_ENABLE_X64", "MPLBACKEND")}
    return subprocess.run(args, cwd=cwd, capture_output=True, text=True, env=env, timeout=timeout)


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("wheel")
    # Built from a copy of the sources a wheel is made of: an in-tree build reuses build/lib, which
    # in a working checkout may still hold modules deleted since.
    src = tmp / "src"
    shutil.copytree(ROOT / "jaxtrack", src / "jaxtrack", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, src / name)
    dist = tmp / "dist"
    p = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index",
              "-w", str(dist), str(src)], cwd=tmp)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    (wheel,) = dist.glob("jaxtrack-*.whl")
    venv = tmp / "venv"
    p = _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], cwd=tmp)
    assert p.returncode == 0, p.stderr
    py = venv / "bin" / "python"
    p = _run([sys.executable, "-m", "pip", "--python", str(py), "install", "--no-deps", "--no-index",
              "--quiet", str(wheel)], cwd=tmp)
    assert p.returncode == 0, p.stderr[-2000:]
    site = Path(_run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=tmp).stdout.strip())
    (site / "_jaxtrack_test_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    outside = tmp / "elsewhere"
    outside.mkdir()
    return wheel, venv, outside


def test_wheel_holds_the_package_data(installed):
    wheel, _, _ = installed
    names = set(zipfile.ZipFile(wheel).namelist())
    assert "jaxtrack/py.typed" in names
    assert {n for n in names if n.startswith("jaxtrack/cli/schemas/") and n.endswith(".json")}
    assert not any(n.startswith(("tests/", "notebooks/", "docs/", "benchmarks/")) for n in names)


def test_version_and_import_come_from_the_wheel(installed):
    _, venv, outside = installed
    p = _run([str(venv / "bin" / "jaxtrack"), "--version"], cwd=outside)
    assert p.returncode == 0, p.stderr
    import jaxtrack

    assert p.stdout.strip().endswith(jaxtrack.__version__)
    p = _run([str(venv / "bin" / "python"), "-c", "import jaxtrack; print(jaxtrack.__file__)"], cwd=outside)
    assert Path(p.stdout.strip()).is_relative_to(venv), p.stdout + p.stderr


def test_demo_runs_outside_the_repository(installed):
    _, venv, outside = installed
    p = _run([str(venv / "bin" / "jaxtrack"), "demo", "--runs", "100", "--json", "--out", "demo"], cwd=outside)
    assert p.returncode == 0, p.stderr[-3000:]
    out = json.loads(p.stdout)
    assert out["schema_version"] == 1
    assert (outside / "demo" / "demo.png").stat().st_size > 10_000

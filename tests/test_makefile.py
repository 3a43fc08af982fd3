"""The Makefile's venv step: a clear message for a too-old Python, and recovery from a half-made
venv without `make clean` (issue 23).

The real targets install from the package index; here `PYTHON` is a stand-in interpreter (a
shell script) that answers the version check as Python 3.10 or 3.11 would and records every
`venv` and `pip` call, so the Makefile's own logic is what is tested, offline, in a second.
"""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="needs make")

# The stand-in: `-c CODE` succeeds iff it claims >= 3.11 (the Makefile's only use of -c is the
# version check); `--version` prints it; `-m venv DIR` makes DIR/bin/python as a copy of itself
# (so the venv's python answers the same way); `-m pip ...` is logged and succeeds, and a pip
# install that names uv leaves the venv a bin/uv stand-in that logs its calls the same way.
FAKE = """#!/bin/sh
LOG="{log}"
case "$1" in
  -c) [ "{minor}" -ge 11 ] ;;
  --version) echo "Python 3.{minor}.9" ;;
  -m)
    if [ "$2" = venv ]; then mkdir -p "$3/bin" && cp "$0" "$3/bin/python" && echo "venv $3" >> "$LOG";
    elif [ "$2" = pip ]; then shift 2; echo "pip $*" >> "$LOG";
      case " $* " in *" uv "*)
        printf '#!/bin/sh\necho "uv $*" >> "%s"\n' "$LOG" > "$(dirname "$0")/uv"; chmod +x "$(dirname "$0")/uv" ;; esac
    else exit 3; fi ;;
  *) exit 3 ;;
esac
"""


def _fake_python(tmp_path: Path, minor: int) -> Path:
    path = tmp_path / f"python3.{minor}"
    path.write_text(FAKE.format(log=tmp_path / "calls.log", minor=minor))
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return path


def _make(work: Path, python: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("MAKE")}
    return subprocess.run(["make", "-f", str(ROOT / "Makefile"), "-C", str(work), "install", f"PYTHON={python}"],
                          capture_output=True, text=True, env=env, timeout=60)


@pytest.fixture
def work(tmp_path):
    w = tmp_path / "clone"
    w.mkdir()
    shutil.copy(ROOT / "pyproject.toml", w / "pyproject.toml")
    shutil.copy(ROOT / "requirements.lock", w / "requirements.lock")
    return w


def test_old_python_is_refused_with_a_clear_message(work, tmp_path):
    p = _make(work, _fake_python(tmp_path, 10))
    assert p.returncode != 0
    assert "jaxtrack needs Python >= 3.11" in p.stderr and "Python 3.10.9" in p.stderr
    assert "make PYTHON=python3.11" in p.stderr
    assert not (work / ".venv").exists()  # nothing half made


def test_half_made_venv_is_remade(work, tmp_path):
    # What a failed attempt leaves: a venv folder without a working interpreter, and no stamp.
    (work / ".venv" / "bin").mkdir(parents=True)
    (work / ".venv" / "leftover").write_text("from the failed attempt")
    p = _make(work, _fake_python(tmp_path, 11))
    assert p.returncode == 0, p.stderr
    assert "incomplete or made by another Python" in p.stdout
    assert not (work / ".venv" / "leftover").exists()
    assert (work / ".venv" / ".installed").exists()
    calls = (tmp_path / "calls.log").read_text().splitlines()
    assert calls[0] == "venv .venv"
    assert calls[-1] == "uv pip install --quiet --compile-bytecode --python .venv/bin/python -c requirements.lock -e .[test,notebooks,docs,export]"
    # Every install is constrained by the lock file (pip's own upgrade and uv's too).
    installs = [c for c in calls if " install " in f" {c} "]
    assert len(installs) == 2 and all("-c requirements.lock" in c for c in installs), installs
    assert installs[0].startswith("pip install") and " uv " in f"{installs[0]} "


def test_venv_of_an_old_python_is_remade(work, tmp_path):
    old = _fake_python(tmp_path, 10)
    (work / ".venv" / "bin").mkdir(parents=True)
    shutil.copy(old, work / ".venv" / "bin" / "python")
    p = _make(work, _fake_python(tmp_path, 11))
    assert p.returncode == 0, p.stderr
    assert "incomplete or made by another Python" in p.stdout


def test_finished_venv_is_kept_when_pyproject_changes(work, tmp_path):
    py = _fake_python(tmp_path, 11)
    assert _make(work, py).returncode == 0
    (work / ".venv" / "kept").write_text("a finished venv is updated, not remade")
    os.utime(work / ".venv" / ".installed", (0, 0))  # pyproject.toml is now newer than the stamp
    p = _make(work, py)
    assert p.returncode == 0, p.stderr
    assert (work / ".venv" / "kept").exists() and "removing" not in p.stdout


def test_a_changed_lock_file_reinstalls(work, tmp_path):
    py = _fake_python(tmp_path, 11)
    assert _make(work, py).returncode == 0
    os.utime(work / ".venv" / ".installed", (0, 0))  # requirements.lock is now newer than the stamp
    (tmp_path / "calls.log").write_text("")
    (work / "pyproject.toml").touch()
    os.utime(work / "pyproject.toml", (0, 0))
    p = _make(work, py)
    assert p.returncode == 0, p.stderr
    assert "uv pip install --quiet --compile-bytecode --python .venv/bin/python -c requirements.lock" in (tmp_path / "calls.log").read_text()


def _requirement_names(specs):
    import re

    return {re.split(r"[<>=!~\[; ]", s, maxsplit=1)[0].lower().replace("_", "-") for s in specs}


def test_the_lock_pins_every_dependency_of_pyproject():
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    wanted = _requirement_names(project["dependencies"])
    # What make install installs, and the bench extra (make lock locks it: the benchmarks'
    # peers run at pinned versions too).
    for extra in ("test", "notebooks", "docs", "export", "bench"):
        wanted |= _requirement_names(project["optional-dependencies"][extra])
    pins = {}
    for line in (ROOT / "requirements.lock").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, _, version = line.partition("==")
            assert version, f"requirements.lock: {line!r} is not an exact pin"
            pins[name.lower().replace("_", "-")] = version
    assert not wanted - set(pins), f"not pinned in requirements.lock: {sorted(wanted - set(pins))}"
    # The installer itself and the test oracles are pinned too.
    assert {"pip", "uv", "setuptools", "jax", "jaxlib", "numpy", "scipy", "statsmodels"} <= set(pins)

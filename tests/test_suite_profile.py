"""tools/suite_profile.py sums the per-test lines tests/conftest.py writes under JAXTRACK_TEST_PROFILE."""

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).parent.parent
_spec = importlib.util.spec_from_file_location("_suite_profile", ROOT / "tools" / "suite_profile.py")
suite_profile = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(suite_profile)


def test_sums_by_module_and_reports_peak_memory(tmp_path, capsys):
    (tmp_path / "11.tsv").write_text("tests/test_a.py::x\t2.0\t1.5\t0.25\t900\ntests/test_b.py::y\t4.0\t3.0\t0.5\t1200\n")
    (tmp_path / "12.tsv").write_text("tests/test_a.py::z\t1.0\t0.5\t0.25\t700\n")
    suite_profile.main([str(tmp_path), "--tests", "1"])
    out = capsys.readouterr().out
    assert "3 tests: wall 7 s, XLA compile 5 s, trace+lower 1 s" in out
    assert "(MB): 700, 1200" in out
    line_a = next(ln for ln in out.splitlines() if ln.startswith("tests/test_a.py"))
    assert line_a.split()[1:] == ["3.0", "2.0", "0.5", "2"]
    assert out.strip().splitlines()[-1].split() == ["4.0", "3.0", "0.5", "tests/test_b.py::y"]


def test_the_suite_writes_one_line_per_test(tmp_path):
    """A real pytest run with JAXTRACK_TEST_PROFILE: one line per test, with compile seconds."""
    case = tmp_path / "test_case.py"
    case.write_text("import jax, jax.numpy as jnp\n\ndef test_jit():\n    jax.jit(lambda x: x + 1)(jnp.ones(3))\n\n"
                    "def test_plain():\n    assert True\n")
    env = dict(os.environ, JAXTRACK_TEST_PROFILE=str(tmp_path / "prof"))
    # The suite's conftest as a plugin (-p conftest, importable from tests/), on a file outside it.
    p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "conftest",
                        "--rootdir", str(tmp_path), str(case)], capture_output=True, text=True, env=env,
                       cwd=ROOT / "tests")
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    rows = suite_profile.read(tmp_path / "prof")
    assert sorted(r[0].rsplit("::", 1)[-1] for r in rows) == ["test_jit", "test_plain"]
    assert all(r[1] >= r[2] >= 0 and r[4] > 0 for r in rows)

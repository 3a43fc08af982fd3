"""`jaxtrack --version` (issue 23): prints ``jaxtrack <__version__>`` on stdout and exits 0."""

import subprocess
import sys

import jaxtrack
from jaxtrack.cli import main


def test_version_flag_prints_version_and_returns_0(capsys):
    # argparse's version action raises SystemExit(0); main turns it into the status, as for --help.
    assert main(["--version"]) == 0
    out = capsys.readouterr()
    assert out.out == f"jaxtrack {jaxtrack.__version__}\n" and out.err == ""
    assert jaxtrack.__version__ == "0.1.0"


def test_version_flag_wins_over_missing_subcommand_and_extra_args(capsys):
    # The subcommand is required, but --version answers first (before the required check).
    assert main(["--version", "demo", "--runs", "5"]) == 0
    assert capsys.readouterr().out == f"jaxtrack {jaxtrack.__version__}\n"


def test_entry_point_version():
    proc = subprocess.run([sys.executable, "-m", "jaxtrack", "--version"], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0 and proc.stdout == f"jaxtrack {jaxtrack.__version__}\n"

"""Start-up time of the command line: ``jaxtrack --help`` / ``--version`` against ``import jax``.

``import jaxtrack`` does not import JAX (subpackages load on first use), so the flags that need
no computation answer in the time of the Python interpreter plus argparse. Each command is a
fresh interpreter, the best of ``--repeats`` runs. Target (issue 23): ``--help`` under 1 s.

Usage::

    python benchmarks/cli_startup.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

COMMANDS = {
    "python -c pass": [sys.executable, "-c", "pass"],
    "jaxtrack --version": [sys.executable, "-m", "jaxtrack", "--version"],
    "jaxtrack --help": [sys.executable, "-m", "jaxtrack", "--help"],
    "python -c 'import jax' (reference)": [sys.executable, "-c", "import jax"],
}


def best_time(cmd, repeats):
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        best = min(best, time.perf_counter() - t0)
    return best


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    times = {name: best_time(cmd, args.repeats) for name, cmd in COMMANDS.items()}
    ref = times["python -c 'import jax' (reference)"]
    print(f"command-line start-up, best of {args.repeats} fresh interpreters")
    for name, t in times.items():
        print(f"  {name:<38} {t:6.3f} s   ({t / ref:5.2f} × import jax)")
    ok = times["jaxtrack --help"] < 1.0
    print(f"--help under 1 s: {'yes' if ok else 'NO'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

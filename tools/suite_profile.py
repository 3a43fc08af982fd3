"""Sum a profiled test run by module: where the suite's time goes (wall, XLA compile, tracing).

Usage::

    rm -rf .cache/jax && JAXTRACK_TEST_PROFILE=.cache/profile make test
    python tools/suite_profile.py .cache/profile [--tests 30]

Each line of ``FOLDER/<pid>.tsv`` (written by ``tests/conftest.py`` when
``JAXTRACK_TEST_PROFILE=FOLDER``) is one test: nodeid, wall s, XLA compile s, trace+lower s and
the process's resident memory after it (MB). The notebooks and the CLI, sharded and wheel
subprocesses compile in processes of their own: their compile time shows as wall time only.
"""

from __future__ import annotations

import argparse
import collections
from pathlib import Path


def read(folder) -> list[tuple]:
    """``[(nodeid, wall, compile, trace, rss_mb, pid), ...]`` of every test in ``folder``."""
    rows = []
    for f in sorted(Path(folder).glob("[0-9]*[0-9].tsv")):
        for line in f.read_text(encoding="utf-8").splitlines():
            nodeid, wall, comp, trace, rss = line.split("\t")
            rows.append((nodeid, float(wall), float(comp), float(trace), float(rss), f.stem))
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder")
    parser.add_argument("--tests", type=int, default=30, help="also list the N slowest tests")
    args = parser.parse_args(argv)
    rows = read(args.folder)
    by_module = collections.defaultdict(lambda: [0.0, 0.0, 0.0, 0])
    for nodeid, wall, comp, trace, _, _ in rows:
        m = by_module[nodeid.split("::")[0]]
        m[0] += wall
        m[1] += comp
        m[2] += trace
        m[3] += 1
    total = [sum(r[i] for r in rows) for i in (1, 2, 3)]
    print(f"{len(rows)} tests: wall {total[0]:.0f} s, XLA compile {total[1]:.0f} s, trace+lower {total[2]:.0f} s "
          "(worker-seconds, all processes together)")
    peak = collections.defaultdict(float)
    for *_, rss, pid in rows:
        peak[pid] = max(peak[pid], rss)
    print("peak resident memory per process (MB):", ", ".join(f"{v:.0f}" for v in sorted(peak.values())))
    print(f"{'module':55s} {'wall s':>8s} {'compile':>8s} {'trace':>8s} {'tests':>6s}")
    for name, (wall, comp, trace, n) in sorted(by_module.items(), key=lambda kv: -kv[1][0]):
        print(f"{name:55s} {wall:8.1f} {comp:8.1f} {trace:8.1f} {n:6d}")
    uncached = collections.defaultdict(lambda: [0.0, 0, set()])
    for f in sorted(Path(args.folder).glob("*.uncached.tsv")):
        for line in f.read_text(encoding="utf-8").splitlines():
            nodeid, name, secs = line.split("\t")
            u = uncached[name]
            u[0] += float(secs)
            u[1] += 1
            u[2].add(nodeid.split("::")[0])
    if uncached:
        total_u = sum(u[0] for u in uncached.values())
        print(f"\nprograms not written to the persistent cache (host callbacks): {total_u:.0f} s of XLA compile")
        print(f"{'program':55s} {'compile':>8s} {'times':>6s}  modules")
        for name, (secs, n, mods) in sorted(uncached.items(), key=lambda kv: -kv[1][0])[:25]:
            print(f"{name[:55]:55s} {secs:8.1f} {n:6d}  {len(mods)}")
    if args.tests:
        print(f"\n{args.tests} slowest tests (wall, compile, trace s)")
        for nodeid, wall, comp, trace, _, _ in sorted(rows, key=lambda r: -r[1])[: args.tests]:
            print(f"{wall:8.1f} {comp:8.1f} {trace:8.1f}  {nodeid}")


if __name__ == "__main__":
    main()

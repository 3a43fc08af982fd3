"""The README's Speed table, from the JSON that ``benchmarks/peers.py --json`` writes.

Usage::

    python benchmarks/peers.py --json benchmarks/measured/peers.json | tee benchmarks/measured/peers.txt
    python benchmarks/readme_table.py benchmarks/measured/peers.json

Prints a Markdown table: M filter steps per second of every contender, then how many times
faster jaxtrack is than dynamax and than FilterPy, one row per job and benchmark point.
"""

from __future__ import annotations

import argparse
import json

_LINEAR_JOBS = (
    ("shared schedule, loglik", "shared schedule, log-likelihood"),
    ("shared schedule, means", "shared schedule, every filtered mean"),
    ("per-run masks, loglik", "per-run masks (own covariances), log-likelihood"),
)


def _rate(r: float | None) -> str:
    if r is None:
        return "–"
    r /= 1e6
    return f"{r:.3f}" if r < 0.1 else f"{r:.2f}" if r < 10 else f"{r:.1f}"


def _ratio(a: float, b: float | None) -> str:
    if b is None:
        return "–"
    x = a / b
    return f"{x:.2f}" if x < 1 else f"{x:.1f}" if x < 10 else f"{x:.0f}"


def rows(report: dict) -> list[str]:
    """Markdown rows, one per (point, job), then the EKF and the full Monte Carlo rows."""
    out = [
        "| job | states | runs × steps | jaxtrack | dynamax | simdkalman | FilterPy | × dynamax | × FilterPy |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|",
    ]

    def row(job, states, runs, steps, ours, rates, dynamax="dynamax"):
        dx, sk, fp = (rates.get(k) for k in (dynamax, "simdkalman", "FilterPy"))
        out.append(
            f"| {job} | {states} | {runs:,} × {steps:,} | {_rate(ours)} | {_rate(dx)} | {_rate(sk)} | "
            f"{_rate(fp)} | {_ratio(ours, dx)} | {_ratio(ours, fp)} |"
        )

    for point in report["linear"]:
        for key, label in _LINEAR_JOBS:
            rates = point["steps_per_s"][key]
            row(label, point["states"], point["runs"], point["steps"], rates["jaxtrack"], rates)
    ekf = report.get("ekf")
    if ekf:
        row("EKF, range-bearing", 4, ekf["runs"], ekf["steps"], ekf["steps_per_s"]["jaxtrack"], ekf["steps_per_s"])
    mc = report.get("monte_carlo")
    if mc:
        rates = mc["steps_per_s"]
        row("full Monte Carlo: simulate, filter, RMSE/NEES", mc["states"], mc["runs"], mc["steps"],
            rates["jaxtrack monte_carlo"], rates, dynamax="dynamax job")
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("json", help="the file peers.py --json wrote")
    args = parser.parse_args()
    with open(args.json) as f:
        report = json.load(f)
    print("\n".join(rows(report)))


if __name__ == "__main__":
    main()

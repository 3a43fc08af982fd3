"""``jaxtrack reproduce STUDY``: reproduce a paper's printed numbers and figures."""

from __future__ import annotations

import importlib
import json
import sys
import time
from pathlib import Path

from ..applications._report import format_rows

# study name → (module with `reproduce(out_dir) -> (rows, figures)`, table title)
STUDIES = {
    "ho": ("jaxtrack.applications.ho_sensitivity", "Ho 1968, Kalman filter sensitivity (specs/ho-sensitivity.md)"),
    "bias": ("jaxtrack.applications.radar_bias", "Radar bias: absolute from relative bias, reduced-state filter (specs/radar-bias.md)"),
    "sar": ("jaxtrack.applications.sar_navigation", "Layne & Blasch 1997, SAR + INS targeting (specs/sar-navigation.md)"),
    "registration": ("jaxtrack.applications.obem_registration", "Mobile radar registration, AAM vs OBEM (specs/obem-registration.md)"),
    "tma": ("jaxtrack.applications.bearings_tma", "Lindgren & Gong 1977, bearings-only TMA (specs/bearings-tma.md)"),
}


def run(study: str, out: str, as_json: bool) -> int:
    names = list(STUDIES) if study == "all" else [study]
    results = {}
    total = passed = 0
    for name in names:
        module_name, title = STUDIES[name]
        module = importlib.import_module(module_name)
        t0 = time.perf_counter()
        rows, figures = module.reproduce(Path(out) / name)
        elapsed = time.perf_counter() - t0
        results[name] = [r.as_dict() for r in rows]
        total += len(rows)
        passed += sum(r.ok for r in rows)
        if not as_json:
            print(format_rows(rows, f"{title} — {elapsed:.1f} s"))
            for path in figures:
                print(f"figure: {path}")
            print()
    if as_json:
        print(json.dumps(results[study] if study != "all" else results, indent=2))
    else:
        print(f"{passed}/{total} paper numbers reproduced within tolerance across {len(names)} "
              f"stud{'y' if len(names) == 1 else 'ies'}")
    return 0 if passed == total else 1


def add_parser(sub) -> None:
    p = sub.add_parser("reproduce", help="reproduce a study's printed numbers (table) and figures (PNG)")
    p.add_argument("study", choices=[*STUDIES, "all"], help="which study, or all of them")
    p.add_argument("--json", action="store_true", help="print the rows as JSON (keys id, quantity, paper, value, rtol, ok)")
    p.add_argument("--out", default="results", help="folder for figures (one subfolder per study)")


def main(args) -> int:
    try:
        return run(args.study, args.out, args.json)
    except KeyboardInterrupt:  # pragma: no cover
        print("interrupted", file=sys.stderr)
        return 130

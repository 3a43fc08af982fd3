"""The command line: `jaxtrack demo` end to end at a small size."""

import json
import subprocess
import sys

from jaxtrack.cli import main


def test_demo_writes_table_and_figure(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--runs", "400", "--steps", "30", "--out", str(out), "--json", "--no-progress"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["filter"] for r in rows] == ["matched", "Q/10"]
    matched, small_q = rows
    # 400 runs: the matched filter's ANEES sits inside its 95% bounds, the Q/10 filter's far above.
    assert matched["anees_lo"] < matched["anees"] < matched["anees_hi"]
    assert small_q["anees"] > 2 * small_q["anees_hi"]
    # The matched filter's RMSE agrees with its own √tr P within Monte Carlo error (~5% at 400 runs).
    assert abs(matched["final_position_rmse_m"] / matched["filter_position_sigma_m"] - 1) < 0.1
    assert (out / "demo.png").stat().st_size > 10_000
    assert json.loads((out / "demo.json").read_text()) == rows


def test_entry_point_help():
    proc = subprocess.run([sys.executable, "-m", "jaxtrack.cli", "--help"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "demo" in proc.stdout


def test_design_cli_prints_schedules_and_writes_figure(tmp_path, capsys):
    import json as _json

    from jaxtrack.cli import main as _main

    assert _main(["design", "uniform", "--samples", "50", "--out", str(tmp_path), "--json"]) == 0
    rows = _json.loads(capsys.readouterr().out)
    newton = next(r for r in rows if r["design"].startswith("Newton"))
    assert abs(newton["schedule"][0] - 0.13715278) < 1e-7 and abs(newton["J"] - 1000.0) < 1e-5
    assert _main(["design", "gradient", "--out", str(tmp_path), "--json"]) == 0
    rows = {r["design"]: r for r in _json.loads(capsys.readouterr().out)}
    assert rows["Ho's rule"]["schedule"] == [10, 5, 5, 10, 10]
    assert rows["gradient, rounded + local search"]["schedule"] == [8, 1, 1, 10, 20]
    assert rows["per-step τ_k (optax)"]["J"] < rows["uniform"]["J"] / 3
    assert {"design_uniform.png", "design_gradient.png"} <= {p.name for p in tmp_path.glob("*.png")}
    assert _main(["design", "ho", "--samples", "3", "--out", str(tmp_path)]) == 2

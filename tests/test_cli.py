"""The command line: `jaxtrack demo` end to end at a small size."""

import json
import subprocess
import sys
from importlib.resources import files

import jsonschema
import pytest

from jaxtrack.cli import main


def test_demo_writes_table_and_figure(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--runs", "400", "--steps", "30", "--out", str(out), "--json", "--no-progress"]) == 0
    document = json.loads(capsys.readouterr().out)
    # The printed document follows its published schema (version 1), and so does demo.json.
    schema = json.loads((files("jaxtrack.cli") / "schemas" / "demo.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.validate(document, schema, cls=jsonschema.Draft202012Validator)
    assert document["schema_version"] == 1
    rows = document["rows"]
    assert [r["filter"] for r in rows] == ["matched", "Q/10"]
    matched, small_q = rows
    # 400 runs: the matched filter's ANEES sits inside its 95% bounds, the Q/10 filter's far above.
    assert matched["anees_lo"] < matched["anees"] < matched["anees_hi"]
    assert small_q["anees"] > 2 * small_q["anees_hi"]
    # The matched filter's RMSE agrees with its own √tr P within Monte Carlo error (~5% at 400 runs).
    assert abs(matched["final_position_rmse_m"] / matched["filter_position_sigma_m"] - 1) < 0.1
    assert (out / "demo.png").stat().st_size > 10_000
    assert json.loads((out / "demo.json").read_text()) == document


def test_demo_schema_rejects_what_it_does_not_describe():
    """The schema is not vacuous: a missing version, an unknown key or a negative RMSE fail it."""
    schema = json.loads((files("jaxtrack.cli") / "schemas" / "demo.schema.json").read_text())
    row = {"filter": "matched", "runs": 400, "failed": 0, "final_position_rmse_m": 7.6,
           "filter_position_sigma_m": 7.9, "final_velocity_rmse_mps": 2.2, "filter_velocity_sigma_mps": 2.2,
           "anees": 1.0, "anees_lo": 0.93, "anees_hi": 1.07, "consistent": True, "nees_steps_inside": 0.95,
           "seconds": 3.0}
    jsonschema.validate({"schema_version": 1, "rows": [row]}, schema)
    for bad in ({"rows": [row]}, {"schema_version": 2, "rows": [row]},
                {"schema_version": 1, "rows": [{**row, "extra": 1}]},
                {"schema_version": 1, "rows": [{**row, "final_position_rmse_m": -1.0}]},
                {"schema_version": 1, "rows": [{k: v for k, v in row.items() if k != "anees"}]}):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(bad, schema)
    # Every field says what it is and in which unit.
    assert all(p.get("description") for p in schema["$defs"]["row"]["properties"].values())


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


def test_design_unreachable_target_names_the_command_line_options(tmp_path, capsys):
    """Issue 37: `design uniform --target 1e-9` suggested `step_factor` and `tau0`, which the
    command line does not have."""
    assert main(["design", "uniform", "--target", "1e-9", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "--target 1e-09 ft² is out of reach" in err and "--samples" in err, err
    assert "J = 1062 ft²" in err  # the uniform period's own J, the nearest reachable value

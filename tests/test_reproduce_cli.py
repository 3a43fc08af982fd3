"""`jaxtrack reproduce`: table rows, the schema-versioned JSON document, figures, and the summary
counts by source (printed in the papers / derived in the specifications / stated claims)."""

import json
import math
import sys
import types

import jsonschema
import pytest

from jaxtrack.applications._report import PaperRow, count_by_source, format_rows, summary_line
from jaxtrack.cli import main
from jaxtrack.cli._reproduce import SCHEMA_VERSION, json_schema

ROW_KEYS = {"id", "quantity", "source", "bound", "paper", "lo", "hi", "value", "rtol", "ok"}


def test_reproduce_json_of_a_real_study(tmp_path, capsys):
    """The JSON path end to end on a real study: the radar bias study, the cheapest (1.3 s; Ho's
    took 26 s here and its rows are computed and checked in test_ho_study.py)."""
    code = main(["reproduce", "bias", "--json", "--out", str(tmp_path)])
    doc = json.loads(capsys.readouterr().out)
    assert code == 0
    jsonschema.validate(doc, json_schema())
    assert doc["schema_version"] == SCHEMA_VERSION == 1 and list(doc["studies"]) == ["bias"]
    study = doc["studies"]["bias"]
    assert study["title"].startswith("Radar bias") and study["seconds"] > 0
    rows = study["rows"]
    assert rows and all(set(r) == ROW_KEYS for r in rows)
    assert all(r["ok"] for r in rows), [r for r in rows if not r["ok"]]
    ids = [r["id"] for r in rows]
    assert ids.count("V7") == 24 and ids.count("V8") == 4 and ids.count("V19") == 18
    v7 = rows[0]
    assert v7["id"] == "V7" and abs(v7["value"] + 176.7767) < 1e-4 and v7["paper"] == -176.78
    assert v7["source"] == "paper" and v7["bound"] == "close" and v7["rtol"] == 1e-4 and v7["lo"] is None
    assert doc["summary"] == {"paper": [46, 46], "spec": [0, 0], "claim": [0, 0], "total": [46, 46]}
    pngs = sorted(p.name for p in (tmp_path / "bias").glob("*.png"))
    assert pngs == ["sec2_costs.png", "sec3_alpha_beta_plane.png", "sec3_gain_transient.png"]


def _fake_studies(monkeypatch, miss: bool = False):
    """Two registered studies whose `reproduce` returns fixed rows of every source and bound: the
    aggregation of `all` is checked without recomputing real studies (each has its own test)."""
    from jaxtrack.cli import _reproduce

    def rows_a():
        return [PaperRow("A1", "printed number", 10.0, 10.01, 5e-3, source="paper"),
                PaperRow.interval("A2", "margin", 0.0, 0.5, 0.6 if miss else 0.2, source="spec"),
                PaperRow("A3", "claim", 0.9, 0.5, 0.0, "at_most", source="claim")]

    def rows_b():
        return [PaperRow("B1", "derived number", 2.0, 2.0, 1e-9, source="spec"),
                PaperRow("B2", "claimed floor", 0.7, 0.8, 0.0, "at_least", source="claim")]

    for name, make in (("fake_a", rows_a), ("fake_b", rows_b)):
        module = types.ModuleType(f"_jaxtrack_test_{name}")
        module.reproduce = lambda out_dir, make=make: (make(), [])
        monkeypatch.setitem(sys.modules, module.__name__, module)
    monkeypatch.setattr(_reproduce, "STUDIES", {"fake_a": ("_jaxtrack_test_fake_a", "Fake A"),
                                                "fake_b": ("_jaxtrack_test_fake_b", "Fake B")})
    monkeypatch.setattr(_reproduce, "NEEDS_FLOAT64", {"fake_a": "test", "fake_b": "test"})


def test_reproduce_all_prints_counts_by_source(tmp_path, capsys, monkeypatch):
    _fake_studies(monkeypatch)
    code = main(["reproduce", "all", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0
    assert out.strip().splitlines()[-1] == ("printed in the papers: 1/1 · derived in the specifications: 2/2 · "
                                           "stated claims: 2/2 · 5/5 within tolerance across 2 studies")
    assert "src" in out.splitlines()[1]  # each table has a source column
    line = next(l for l in out.splitlines() if l.startswith("A2"))
    assert line.split()[1] == "spec" and "[0, 0.5]" in line  # an interval shows its bounds, no midpoint
    assert "≤ 0.9" in next(l for l in out.splitlines() if l.startswith("A3"))
    assert "≥ 0.7" in next(l for l in out.splitlines() if l.startswith("B2"))


def test_reproduce_all_json_follows_the_schema_and_counts_misses(tmp_path, capsys, monkeypatch):
    _fake_studies(monkeypatch, miss=True)
    code = main(["reproduce", "all", "--json", "--out", str(tmp_path)])
    doc = json.loads(capsys.readouterr().out)
    assert code == 1  # the spec interval row misses
    jsonschema.validate(doc, json_schema())
    assert list(doc["studies"]) == ["fake_a", "fake_b"]
    assert doc["summary"] == {"paper": [1, 1], "spec": [1, 2], "claim": [2, 2], "total": [4, 5]}
    a2 = doc["studies"]["fake_a"]["rows"][1]
    assert (a2["bound"], a2["paper"], a2["lo"], a2["hi"], a2["rtol"], a2["ok"]) == ("interval", None, 0.0, 0.5, None, False)
    # the schema rejects what it documents as impossible: a close row without rtol, an unknown source
    bad = json.loads(json.dumps(doc))
    bad["studies"]["fake_a"]["rows"][0]["rtol"] = None
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, json_schema())
    bad = json.loads(json.dumps(doc))
    bad["studies"]["fake_b"]["rows"][0]["source"] = "unknown"
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, json_schema())


def test_paper_row_refuses_wide_close_rows_and_checks_intervals():
    with pytest.raises(ValueError, match="`rtol`"):
        PaperRow("X", "cannot fail", 80.0, 47.0, 1.0, source="spec")
    with pytest.raises(ValueError, match="`rtol`"):
        PaperRow("X", "too wide", 10.0, 10.0, 0.51, source="paper")
    PaperRow("X", "widest allowed", 10.0, 14.9, 0.5, source="paper")
    with pytest.raises(ValueError, match="`source`"):
        PaperRow("X", "no honest source", 1.0, 1.0, 0.0, source="papers")
    with pytest.raises(TypeError):
        PaperRow("X", "source is required", 1.0, 1.0, 0.0)
    with pytest.raises(ValueError, match="`lo`"):
        PaperRow.interval("X", "reversed", 2.0, 1.0, 1.5, source="spec")
    row = PaperRow.interval("X", "margin", 0.5, 20.0, 0.4, source="spec")
    assert not row.ok and PaperRow.interval("X", "margin", 0.5, 20.0, 20.0, source="spec").ok
    assert (row.paper, row.reference_text()) == (None, "[0.5, 20]")
    nan = PaperRow("X", "not finite", 1.0, math.nan, 0.1, source="spec")
    assert not nan.ok and nan.as_dict()["value"] is None
    table = format_rows([row], "t")
    assert "[0.5, 20]" in table and table.splitlines()[-1] == "derived in the specifications: 0/1 · 0/1 within tolerance"
    assert summary_line(count_by_source([row.as_dict()]), 1) == ("derived in the specifications: 0/1 · "
                                                                 "0/1 within tolerance across 1 study")


def test_every_study_is_registered_and_reproducible():
    import importlib

    from jaxtrack.cli._reproduce import STUDIES

    assert set(STUDIES) == {"ho", "bias", "sar", "registration", "tma", "maneuvering", "multitarget", "williams15",
                            "labelled"}
    for module_name, title in STUDIES.values():
        assert callable(importlib.import_module(module_name).reproduce) and title

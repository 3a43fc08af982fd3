"""tools/update_readme.py: the README's reproduction summary is rendered from the JSON of
`jaxtrack reproduce all --json` (here a small fixture), and `--check` catches a stale README."""

import importlib.util
import json
import pathlib

import jsonschema
import pytest

from jaxtrack.cli._reproduce import json_schema

ROOT = pathlib.Path(__file__).resolve().parents[1]
FIXTURE = ROOT / "tests" / "data" / "reproduce_small.json"
_spec = importlib.util.spec_from_file_location("update_readme", ROOT / "tools" / "update_readme.py")
update_readme = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(update_readme)

EXPECTED_TABLE = """\
| study | `jaxtrack reproduce` | printed in the paper | derived in the spec | stated claims | all rows | figures |
|---|---|---:|---:|---:|---:|---:|
| Ho 1968, Kalman filter sensitivity (specs/ho-sensitivity.md) | `ho` | 2/2 | 1/1 | – | 3/3 | 2 |
| Mobile radar registration, AAM vs OBEM (specs/obem-registration.md) | `registration` | 1/1 | 0/1 | – | 1/2 | 1 |
| Maneuvering target (own scenario; claims with margins) | `maneuvering` | – | – | 1/1 | 1/1 | 0 |
| **3 studies** | `all` | **3/3** | **1/2** | **1/1** | **5/6** | 3 |
"""


def test_fixture_follows_the_reproduce_schema():
    jsonschema.validate(json.loads(FIXTURE.read_text(encoding="utf-8")), json_schema())


def test_render_counts_per_study_and_source():
    block = update_readme.render(json.loads(FIXTURE.read_text(encoding="utf-8")))
    lines = block.splitlines()
    assert lines[0] == update_readme.BEGIN and lines[-1] == update_readme.END
    assert EXPECTED_TABLE in block
    with pytest.raises(ValueError, match="schema_version"):
        update_readme.render({"schema_version": 2, "studies": {}})


def test_rewrites_between_markers_and_check_detects_a_stale_readme(tmp_path, capsys):
    readme = tmp_path / "README.md"
    readme.write_text(f"# title\n\nbefore\n{update_readme.BEGIN}\n| typed | 400/400 |\n{update_readme.END}\nafter\n",
                      encoding="utf-8")
    args = [str(FIXTURE), "--readme", str(readme)]
    assert update_readme.main([*args, "--check"]) == 1
    assert "differs" in capsys.readouterr().err
    assert update_readme.main(args) == 0
    text = readme.read_text(encoding="utf-8")
    assert text.startswith("# title\n\nbefore\n") and text.endswith(f"{update_readme.END}\nafter\n")
    assert "400/400" not in text and EXPECTED_TABLE in text
    assert update_readme.main([*args, "--check"]) == 0  # now up to date
    readme.write_text("no markers\n", encoding="utf-8")
    assert update_readme.main(args) == 2

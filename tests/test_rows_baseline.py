"""Each study's rows test holds its rows to c1ffaca's (``tests/rows_baseline.py``).

The check runs where the rows are computed anyway; this test only makes sure no study's test
drops it (a study with c1ffaca rows whose test no longer calls the check fails here)."""

from __future__ import annotations

import pathlib
import re

from rows_baseline import BASELINE

from jaxtrack.cli._reproduce import STUDIES


def test_every_study_with_c1ffaca_rows_is_checked_by_its_rows_test():
    calls = set()
    for path in pathlib.Path(__file__).parent.glob("test_*.py"):
        calls |= set(re.findall(r'assert_rows_match_c1ffaca\(\s*"(\w+)"', path.read_text()))
    assert set(BASELINE) <= set(STUDIES)
    assert calls == set(BASELINE), (sorted(calls), sorted(BASELINE))

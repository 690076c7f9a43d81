"""Report tables: columns empty in every row (None, "", NaN) are left out of the markdown; the CSV
keeps them; cells escape ``|``."""

import csv

import numpy as np
import pytest

from polar_sim.runner.report import is_empty, markdown_table, nonempty_columns, write_csv_table

ROWS = [{"method": "w6", "t_100m": float("nan"), "t_50m": 1.25, "note": "", "rot": None, "n": 0},
        {"method": "u|6", "t_100m": np.nan, "t_50m": float("nan"), "note": None, "n": 3}]
COLS = ["method", "t_100m", "t_50m", "note", "rot", "n"]


def _header(md):
    return [c.strip() for c in md.splitlines()[0].strip("|").split("|")]


# A column of NaN, None, "" or a missing key in every row is dropped; one value keeps it (a zero too).
def test_all_empty_columns_are_dropped():
    md = markdown_table(ROWS, COLS)
    assert _header(md) == ["method", "t_50m", "n"]
    lines = md.splitlines()
    assert lines[1] == "|---|---|---|" and len(lines) == 4
    assert lines[2] == "| w6 | 1.25 | 0 |" and lines[3] == "| u\\|6 | nan | 3 |"
    assert "t_100m" in markdown_table(ROWS, COLS, drop_empty=False)


# Headers follow their columns when some are dropped, and must be one per column.
def test_headers_follow_their_columns():
    md = markdown_table(ROWS, COLS, headers=["M", "100 m", "50 m", "Note", "rot (deg/m)", "N"])
    assert _header(md) == ["M", "50 m", "N"]
    with pytest.raises(ValueError, match="headers"):
        markdown_table(ROWS, COLS, headers=["M"])


# With no rows, or nothing in any column, the table keeps its columns (a header is still a table).
def test_nothing_to_drop_when_nothing_is_there():
    assert _header(markdown_table([], ["a", "b"])) == ["a", "b"]
    assert nonempty_columns([{"a": None}], ["a", "b"]) == (["a", "b"], ["a", "b"])
    assert [is_empty(x) for x in (None, "", "  ", float("nan"), np.float32("nan"), 0, 0.0, "x", False)] == \
        [True, True, True, True, True, False, False, False, False]


# The CSV keeps one schema at every size: no column is dropped.
def test_csv_keeps_every_column(tmp_path):
    write_csv_table(ROWS, COLS, tmp_path / "t.csv")
    with open(tmp_path / "t.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == COLS and len(rows) == 3

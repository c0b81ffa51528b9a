"""recon.io.batch: one case's folder and record, and the results table (no cluster here)."""

from __future__ import annotations

import csv
import json

import pyarrow.parquet as pq
from support import DEMO

from recon.io.batch import (
    CASE_RECORD,
    FFR_KEYS,
    RESULT_COLUMNS,
    failed_record,
    read_record,
    run_case,
    write_case_folder,
    write_results,
)
from recon.io.manifest import BatchCase


def test_a_failed_case_is_a_record_with_its_one_line_error(tmp_path):
    case = BatchCase(id="c1", a=str(DEMO / "a.dcm"), b=str(tmp_path / "missing.dcm"),
                     seeds=str(DEMO / "seeds.json"), line=2)
    record = run_case(case, str(tmp_path / "out"), ("stl",), sr=False)
    assert record["status"] == "failed"
    assert record["error"] == f"{tmp_path / 'missing.dcm'}: no such file"
    assert set(record) == set(RESULT_COLUMNS) and record["worker_peak_rss_mb"] > 0
    assert sorted(p.name for p in (tmp_path / "out" / "c1").iterdir()) == [CASE_RECORD]
    assert read_record(tmp_path / "out", "c1") == record


def test_a_case_folder_is_replaced_whole_and_leaves_no_temporary(tmp_path):
    write_case_folder(tmp_path, "c1", {"old.txt": b"old"}, failed_record("c1", "first"))
    write_case_folder(tmp_path, "c1", {"new.txt": b"new"}, {"id": "c1", "status": "done"})
    assert sorted(p.name for p in (tmp_path / "c1").iterdir()) == [CASE_RECORD, "new.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["c1"]  # no hidden .c1.* folder left
    (tmp_path / "c2").mkdir()
    (tmp_path / "c2" / CASE_RECORD).write_text('{"status": "half"')
    assert read_record(tmp_path, "c2") is None and read_record(tmp_path, "c3") is None


def test_results_csv_and_parquet_hold_one_row_per_case(tmp_path):
    done = dict.fromkeys(RESULT_COLUMNS, None) | {
        "id": "a", "status": "done", "error": "", "mld_mm": 1.25, "calibration_iterations": 7,
    }
    records = [done, failed_record("b", "b.dcm: no such\nfile")]
    paths = write_results(tmp_path, records)
    assert [p.name for p in paths] == ["results.csv", "results.parquet"]
    rows = list(csv.DictReader((tmp_path / "results.csv").open()))
    assert tuple(rows[0]) == RESULT_COLUMNS
    assert [(r["id"], r["status"], r["error"]) for r in rows] == [
        ("a", "done", ""), ("b", "failed", "b.dcm: no such file")
    ]
    assert float(rows[0]["mld_mm"]) == 1.25 and rows[1]["mld_mm"] == ""
    table = pq.read_table(tmp_path / "results.parquet").to_pylist()
    assert table[0]["mld_mm"] == 1.25 and table[0]["calibration_iterations"] == 7
    assert table[1]["mld_mm"] is None and table[1]["status"] == "failed"
    assert json.loads(json.dumps(table))  # plain values


def test_the_ffr_columns_are_each_branchs_and_empty_where_it_was_not_computed(tmp_path):
    """ffr_distal, ffr_ci95_lo, ffr_ci95_hi per branch row; a branch without an FFR (or
    without its interval) and a failed case have empty cells (CSV) and nulls (Parquet)."""
    assert RESULT_COLUMNS[RESULT_COLUMNS.index("segment_length_mm") + 1:][:3] == FFR_KEYS
    done = dict.fromkeys(RESULT_COLUMNS, None) | {"id": "t", "status": "done", "error": ""}
    done["branches"] = [
        {"branch_id": 0, "branch": "main", "parent": None, "mld_mm": 1.4,
         "ffr_distal": 0.8587, "ffr_ci95_lo": 0.8141, "ffr_ci95_hi": 0.9034},
        {"branch_id": 1, "branch": "D1", "parent": "main", "mld_mm": 1.1,
         "ffr_distal": None, "ffr_ci95_lo": None, "ffr_ci95_hi": None},
        {"branch_id": 2, "branch": "D2", "parent": "main", "mld_mm": 1.0,
         "ffr_distal": 0.91, "ffr_ci95_lo": None, "ffr_ci95_hi": None},
    ]
    write_results(tmp_path, [done, failed_record("f", "f.dcm: no such file")])
    rows = list(csv.DictReader((tmp_path / "results.csv").open()))
    assert [[r[k] for k in FFR_KEYS] for r in rows] == [
        ["0.8587", "0.8141", "0.9034"], ["", "", ""], ["0.91", "", ""], ["", "", ""]]
    table = pq.read_table(tmp_path / "results.parquet")
    assert all(str(table.schema.field(k).type) == "double" for k in FFR_KEYS)
    assert [[r[k] for k in FFR_KEYS] for r in table.to_pylist()] == [
        [0.8587, 0.8141, 0.9034], [None] * 3, [0.91, None, None], [None] * 3]


def test_a_done_cases_ffr_columns_are_its_report_json_ffr(tmp_path):
    """The demo case reconstructed for real in its own process (run_case): the record and
    the table carry report.json's ffr.distal and ffr.ci95."""
    from recon.io.batch import ffr_columns

    case = BatchCase(id="demo", a=str(DEMO / "a.dcm"), b=str(DEMO / "b.dcm"),
                     seeds=str(DEMO / "seeds.json"), line=2)
    record = run_case(case, str(tmp_path / "out"), ("stl",), sr=False)
    assert record["status"] == "done", record["error"]
    report = json.loads((tmp_path / "out" / "demo" / "report.json").read_text())
    block = report["ffr"]
    assert block is not None and block["ci95"] is not None  # the demo has its FFR
    assert 0.0 < block["distal"] <= 1.0 and block["ci95"][0] <= block["distal"]
    expected = [block["distal"], *block["ci95"]]
    assert [record[k] for k in FFR_KEYS] == expected
    assert [record["branches"][0][k] for k in FFR_KEYS] == expected
    write_results(tmp_path, [record])
    (row,) = csv.DictReader((tmp_path / "results.csv").open())
    assert [float(row[k]) for k in FFR_KEYS] == expected
    assert ffr_columns({"ffr": None}) == dict.fromkeys(FFR_KEYS)  # not computed

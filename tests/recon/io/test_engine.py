"""recon.io.engine through `coronary3d batch`: a local Dask cluster, and a scheduler with
two workers started here on 127.0.0.1."""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import highdicom as hd
import pyarrow.parquet as pq
import pytest
from support import DEMO, assert_one_line_error, run_cli

from recon.io.batch import CASE_RECORD


def _manifest(folder: Path, good: int, bad_rows: list[str]) -> Path:
    """A manifest of ``good`` copies of the demo case (relative paths) plus ``bad_rows``."""
    inputs = folder / "inputs"
    inputs.mkdir(parents=True)
    for name in ("a.dcm", "b.dcm", "seeds.json"):
        shutil.copy(DEMO / name, inputs / name)
    (inputs / "notes.txt").write_text("not an image\n")
    lines = ["id,a,b,seeds"]
    lines += [f"case{k:02d},inputs/a.dcm,inputs/b.dcm,inputs/seeds.json" for k in range(good)]
    path = folder / "manifest.csv"
    path.write_text("\n".join(lines + bad_rows) + "\n")
    return path


def _rows(out: Path) -> list[dict]:
    return list(csv.DictReader((out / "results.csv").open()))


def test_twelve_cases_two_bad_finish_ten_done_and_a_rerun_does_no_work(tmp_path):
    bad = ["missing,inputs/a.dcm,inputs/nope.dcm,inputs/seeds.json",
           "notimage,inputs/a.dcm,inputs/notes.txt,inputs/seeds.json"]
    manifest = _manifest(tmp_path, 10, bad)
    out = tmp_path / "out"
    proc = run_cli("batch", str(manifest), "--out", str(out), "--workers", "2", "--sr")
    assert proc.returncode == 0, proc.stderr
    assert "12 to run on a local cluster of 2 worker(s)" in proc.stderr
    assert "Dask dashboard: http" in proc.stderr
    assert "[##############################] 12/12" in proc.stderr
    assert "10 done, 2 failed (12 run now, 0 skipped)" in proc.stderr
    rows = _rows(out)
    assert [r["id"] for r in rows] == [f"case{k:02d}" for k in range(10)] + ["missing", "notimage"]
    assert [r["status"] for r in rows] == ["done"] * 10 + ["failed"] * 2
    errors = {r["id"]: r["error"] for r in rows[10:]}
    assert errors["missing"] == f"{tmp_path / 'inputs' / 'nope.dcm'}: no such file"
    assert errors["notimage"].startswith(str(tmp_path / "inputs" / "notes.txt"))
    workers = {r["worker"] for r in rows if r["status"] == "done"}
    assert len(workers) == 2  # both worker processes took cases
    report = json.loads((out / "case03" / "report.json").read_text())
    assert float(rows[3]["mld_mm"]) == report["measurements"]["mld_mm"]
    assert sorted(p.name for p in (out / "case03").iterdir()) == [
        CASE_RECORD, "centerline.csv", "centerline.vtp", "measurements-sr.dcm", "mesh.stl",
        "report.json",
    ]
    sr = hd.sr.srread(out / "case03" / "measurements-sr.dcm")
    assert sr.content.get_image_measurement_groups()[0].get_measurements()[0].value == \
        pytest.approx(report["measurements"]["mld_mm"])
    assert [r["status"] for r in pq.read_table(out / "results.parquet").to_pylist()] == \
        ["done"] * 10 + ["failed"] * 2
    assert not [p for p in out.iterdir() if p.name.startswith(".")]

    # the rerun finds every case recorded: no cluster, no case touched, the same table
    stamps = {p: p.stat().st_mtime_ns for p in out.glob("*/*")}
    table = (out / "results.csv").read_text()
    again = run_cli("batch", str(manifest), "--out", str(out), "--workers", "2")
    assert again.returncode == 0, again.stderr
    assert "12 already recorded, 0 to run" in again.stderr
    assert "Dask dashboard" not in again.stderr
    assert "(0 run now, 12 skipped)" in again.stderr
    assert {p: p.stat().st_mtime_ns for p in out.glob("*/*")} == stamps
    assert (out / "results.csv").read_text() == table

    # --retry-failed runs the two failed cases only
    (tmp_path / "inputs" / "nope.dcm").write_bytes((DEMO / "b.dcm").read_bytes())
    retry = run_cli("batch", str(manifest), "--out", str(out), "--retry-failed", "--quiet")
    assert retry.returncode == 0, retry.stderr
    rows = _rows(out)
    assert [r["status"] for r in rows[10:]] == ["done", "failed"]
    assert (out / "case03" / "report.json").stat().st_mtime_ns == \
        stamps[out / "case03" / "report.json"]


def test_a_bad_manifest_is_one_line_and_exit_2(tmp_path):
    manifest = tmp_path / "m.csv"
    manifest.write_text("id,a,b\nx,a.dcm,b.dcm\n")
    proc = run_cli("batch", str(manifest), "--out", str(tmp_path / "out"))
    assert_one_line_error(proc, str(manifest), "line 1", "id,a,b,seeds")
    assert not (tmp_path / "out").exists()


def test_an_unreachable_scheduler_is_one_line_and_exit_2(tmp_path):
    manifest = _manifest(tmp_path, 1, [])
    proc = run_cli("batch", str(manifest), "--out", str(tmp_path / "out"), "--scheduler",
                   "tcp://127.0.0.1:9", "--quiet")
    assert_one_line_error(proc, "tcp://127.0.0.1:9", "cannot reach the Dask scheduler")


def _start(args: list[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", *args], stdout=log.open("w"),
                            stderr=subprocess.STDOUT, cwd=log.parent)


def _wait_for(predicate, what: str, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.2)


def test_a_scheduler_and_two_workers_on_127_0_0_1(tmp_path):
    manifest = _manifest(tmp_path, 2, ["gone,inputs/a.dcm,inputs/gone.dcm,inputs/seeds.json"])
    scheduler_file = tmp_path / "scheduler.json"
    procs = []
    try:
        procs.append(_start(["distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                             "--port", "0", "--no-dashboard", "--scheduler-file",
                             str(scheduler_file)], tmp_path / "scheduler.log"))
        _wait_for(scheduler_file.exists, "the scheduler file")
        address = json.loads(scheduler_file.read_text())["address"]
        for k in range(2):
            procs.append(_start(["distributed.cli.dask_worker", address, "--nthreads", "1",
                                 "--no-nanny", "--no-dashboard", "--host", "127.0.0.1"],
                                tmp_path / f"worker{k}.log"))
        from distributed import Client

        with Client(address, timeout="20s") as client:
            _wait_for(lambda: len(client.scheduler_info()["workers"]) == 2, "two workers")
        out = tmp_path / "out"
        proc = run_cli("batch", str(manifest), "--out", str(out), "--scheduler", address)
        assert proc.returncode == 0, proc.stderr
        assert f"3 to run on {address}" in proc.stderr
        assert "2 done, 1 failed" in proc.stderr
        rows = _rows(out)
        assert [r["status"] for r in rows] == ["done", "done", "failed"]
        worker_pids = {str(p.pid) for p in procs[1:]}
        assert {r["worker"].rsplit(":", 1)[1] for r in rows} <= worker_pids
        assert str(os.getpid()) not in {r["worker"].rsplit(":", 1)[1] for r in rows}
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


def test_a_batch_case_past_its_cpu_limit_fails_saying_which_and_the_batch_goes_on(tmp_path):
    manifest = _manifest(tmp_path, 2, [])
    out = tmp_path / "out"
    # a case takes ~0.4 s of CPU on a fast idle machine: 0.1 s is surely passed
    proc = run_cli("batch", str(manifest), "--out", str(out), "--max-cpu-s", "0.1")
    assert proc.returncode == 0, proc.stderr
    rows = _rows(out)
    assert [r["status"] for r in rows] == ["failed", "failed"]
    for row in rows:
        assert row["error"] == ("the reconstruction used more than its CPU-time limit of "
                                "0.1 s (--max-cpu-s)")
    assert "0 done, 2 failed" in proc.stderr  # one worker: it outlived both cases


def test_a_tree_case_is_reconstructed_whole_with_a_row_per_branch(tmp_path):
    import numpy as np

    from recon.io.seeds_file import save_seeds
    from recon.synth import make_phantom
    from recon.synth.tree_case import tree_seeds

    manifest = _manifest(tmp_path, 0, ["tree,inputs/a.dcm,inputs/b.dcm,inputs/tree.json,",
                                       "side,inputs/a.dcm,inputs/b.dcm,inputs/tree.json,1",
                                       "far,inputs/a.dcm,inputs/b.dcm,inputs/tree.json,5"])
    text = manifest.read_text().replace("id,a,b,seeds", "id,a,b,seeds,segment")
    manifest.write_text(text)
    seeds, _, _ = tree_seeds(np.random.default_rng(1), make_phantom("static", 7, render=False))
    save_seeds(seeds, tmp_path / "inputs" / "tree.json")
    out = tmp_path / "out"
    proc = run_cli("batch", str(manifest), "--out", str(out), "--workers", "2")
    assert proc.returncode == 0, proc.stderr
    rows = _rows(out)
    assert [(r["id"], r["branch_id"], r["branch"], r["parent"]) for r in rows] == [
        ("tree", "0", "main", ""), ("tree", "1", "branch 1", "main"),
        ("side", "1", "branch 1", ""), ("far", "", "", ""),
    ]
    assert rows[3]["status"] == "failed" and "no segment 5" in rows[3]["error"]
    report = json.loads((out / "tree" / "report.json").read_text())
    assert [b["inputs"]["segment"] for b in report["branches"]] == ["main", "branch 1"]
    assert report["bifurcations"][0]["gap_mm"] <= 0.1
    for row, branch in zip(rows[:2], report["branches"], strict=True):
        assert float(row["mld_mm"]) == branch["measurements"]["mld_mm"]
        assert float(row["segment_length_mm"]) == branch["measurements"]["segment_length_mm"]
        ffr = branch["ffr"]  # the FFR solved over the tree, each branch's own
        assert [float(row[k]) for k in ("ffr_distal", "ffr_ci95_lo", "ffr_ci95_hi")] == \
            [ffr["distal"], *ffr["ci95"]]
    assert rows[0]["calibration_error_after_px"] == rows[1]["calibration_error_after_px"]
    branch_ids = {int(v) for v in
                  np.loadtxt(out / "tree" / "centerline.csv", delimiter=",", skiprows=1)[:, -1]}
    assert branch_ids == {0, 1}
    side = json.loads((out / "side" / "report.json").read_text())
    assert "branches" not in side and side["inputs"]["segment"] == "branch 1"
    assert [r["branch"] for r in pq.read_table(out / "results.parquet").to_pylist()] == \
        ["main", "branch 1", "branch 1", None]

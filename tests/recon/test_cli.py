"""The `coronary3d` command as a user runs it: real processes, real files."""

import csv
import io
import json
import re
import shutil

import numpy as np
import pytest
import trimesh
from support import DATA, DEMO, assert_one_line_error, run_cli


def test_help_lists_every_command():
    proc = run_cli("--help")
    assert proc.returncode == 0
    for command in ("info", "phantom", "reconstruct", "view", "bench"):
        assert command in proc.stdout


def test_info_on_real_files_prints_geometry_without_patient_data():
    proc = run_cli("info", str(DATA / "IM7.dcm"), str(DATA / "rca-cine-ecg.dcm"))
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "-29.3" in out and "25.5" in out and "976" in out and "720" in out
    assert "0.390625" in out
    assert "96" in out and "missing" in out  # the cine's frames and its missing distances
    for private in ("fantom", "Rubo", "556342B"):  # the files' patient names and ID
        assert private not in out


def test_info_json_and_show_patient():
    proc = run_cli("info", "--json", "--show-patient", str(DATA / "IM8.dcm"))
    assert proc.returncode == 0, proc.stderr
    (desc,) = json.loads(proc.stdout)
    assert desc["n_frames"] == 8
    assert "fantom" in json.dumps(desc)  # asked for: the patient name is shown


def test_info_bad_file_is_one_line_and_exit_2(tmp_path):
    bad = tmp_path / "notes.dcm"
    bad.write_bytes(b"this is not an angiogram" * 10)
    proc = run_cli("info", str(bad))
    assert_one_line_error(proc, str(bad))


def test_reconstruct_missing_geometry_names_file_and_tag(tmp_path):
    cine = str(DATA / "rca-cine-ecg.dcm")
    proc = run_cli("reconstruct", cine, cine, "--seeds", str(DEMO / "seeds.json"),
                   "--out", str(tmp_path / "out"))
    assert_one_line_error(proc, "rca-cine-ecg.dcm", "DistanceSourceToDetector")
    assert not (tmp_path / "out").exists()


def test_reconstruct_bad_seeds_leaves_no_output(tmp_path):
    seeds = tmp_path / "seeds.json"
    seeds.write_text('{"segments": [{"a": [[1, 2]], "b": [[1, 2], [3, 4]]}]}')
    out = tmp_path / "out"
    proc = run_cli("reconstruct", str(DEMO / "a.dcm"), str(DEMO / "b.dcm"),
                   "--seeds", str(seeds), "--out", str(out))
    assert_one_line_error(proc, str(seeds))
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("allow", [False, True])
def test_reconstruct_one_view_paired_with_itself_is_refused_in_one_line(tmp_path, allow):
    seeds = json.loads((DEMO / "seeds.json").read_text())
    for seg in seeds["segments"]:
        seg["b"] = seg["a"]
    for feature in seeds["features"]:
        feature["b"] = feature["a"]
    path = tmp_path / "seeds.json"
    path.write_text(json.dumps(seeds))
    proc = run_cli("reconstruct", str(DEMO / "a.dcm"), str(DEMO / "a.dcm"), "--seeds",
                   str(path), "--out", str(tmp_path / "out"),
                   *(["--allow-close-views"] if allow else []))
    assert_one_line_error(proc, "same place")
    assert not (tmp_path / "out").exists()


def test_reconstruct_click_off_vessel_names_the_click(tmp_path):
    seeds = json.loads((DEMO / "seeds.json").read_text())
    seeds["segments"][0]["b"][-1] = [30.0, 480.0]  # far from any vessel
    path = tmp_path / "seeds.json"
    path.write_text(json.dumps(seeds))
    proc = run_cli("reconstruct", str(DEMO / "a.dcm"), str(DEMO / "b.dcm"),
                   "--seeds", str(path), "--out", str(tmp_path / "out"))
    assert_one_line_error(proc, "view B")
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_reconstruct_demo_writes_the_documented_files(tmp_path):
    out = tmp_path / "demo"
    proc = run_cli("reconstruct", "--demo", "--out", str(out), "--format", "stl,glb")
    assert proc.returncode == 0, proc.stderr
    assert "tracing" in proc.stderr  # progress on stderr
    names = sorted(p.name for p in out.iterdir())
    assert names == ["centerline.csv", "centerline.vtp", "mesh.glb", "mesh.stl", "outputs.json",
                     "report.json"]
    manifest = json.loads((out / "outputs.json").read_text())
    assert manifest["complete"] is True and len(manifest["files"]) == 5

    rows = list(csv.DictReader(io.StringIO((out / "centerline.csv").read_text())))
    for column in ("s_mm", "x_mm", "y_mm", "z_mm", "radius_mm"):
        assert column in rows[0]
    s = np.array([float(r["s_mm"]) for r in rows])
    assert s[0] == 0.0 and np.all(np.diff(s) > 0)

    mesh = trimesh.load(out / "mesh.stl")
    assert mesh.is_watertight and mesh.volume > 0
    report = json.loads((out / "report.json").read_text())
    for key in ("inputs", "geometry", "calibration", "matching", "measurements", "timings_ms",
                "software"):
        assert key in report
    assert report["calibration"]["method"] == "palm"
    assert report["matching"]["method"] == "match3"

    # The demo's ground truth: the reconstruction measures the stenosis it was made with.
    truth = json.loads((DEMO / "truth.json").read_text())
    m = report["measurements"]
    assert abs(m["mld_mm"] - truth["stenosis"]["mld_mm"]) <= 0.15
    assert abs(m["diameter_stenosis_pct"] - truth["stenosis"]["diameter_pct"]) <= 5.0


def test_reconstruct_unknown_format_is_refused(tmp_path):
    proc = run_cli("reconstruct", "--demo", "--out", str(tmp_path / "o"), "--format", "vrml")
    assert_one_line_error(proc, "vrml")


def test_phantom_command_is_deterministic(tmp_path):
    for name in ("one", "two"):
        proc = run_cli("phantom", "--out", str(tmp_path / name), "--preset", "data2",
                       "--seed", "3")
        assert proc.returncode == 0, proc.stderr
    for file in ("seeds.json",):
        assert (tmp_path / "one" / file).read_text() == (tmp_path / "two" / file).read_text()
    truth_one = json.loads((tmp_path / "one" / "truth.json").read_text())
    truth_two = json.loads((tmp_path / "two" / "truth.json").read_text())
    assert truth_one == truth_two
    proc = run_cli("phantom", "--out", str(tmp_path / "x"), "--preset", "nope")
    assert_one_line_error(proc, "nope")


def test_reconstruct_does_not_need_the_source_tree(tmp_path):
    """A copied case reconstructs from any working directory (no hidden paths)."""
    case = tmp_path / "case"
    case.mkdir()
    for name in ("a.dcm", "b.dcm", "seeds.json"):
        shutil.copy(DEMO / name, case / name)
    proc = run_cli("reconstruct", "a.dcm", "b.dcm", "--seeds", "seeds.json", "--out", "out",
                   "--quiet", "--matcher", "match2", cwd=case)
    assert proc.returncode == 0, proc.stderr
    assert (case / "out" / "mesh.stl").exists()
    # nothing but the reconstruction's own warnings (no traceback, no path complaint)
    assert all(line.startswith("coronary3d: warning: ") for line in proc.stderr.splitlines())


@pytest.mark.parametrize("name", ["centerline", "calibration", "matching", "reconstruct"])
def test_bench_modules_expose_run_and_format_table(name):
    import importlib

    module = importlib.import_module(f"recon.bench.{name}")
    assert callable(module.run) and callable(module.format_table)


def test_view_port_0_asks_for_any_free_port_and_out_of_range_ports_are_refused() -> None:
    from recon.cli import build_parser

    assert build_parser().parse_args(["view", "--port", "0"]).port == 0
    for bad in ("-1", "65536"):
        proc = run_cli("view", "--port", bad)
        assert_one_line_error(proc, "--port")


def test_reconstruct_geometry_per_file_and_a_replaced_header_value_is_said(tmp_path):
    geo_b = tmp_path / "b-geometry.json"
    geo_b.write_text(json.dumps({"sid_mm": 990}))
    out = tmp_path / "out"
    proc = run_cli("reconstruct", "--demo", "--geometry-b", str(geo_b), "--out", str(out),
                   "--quiet")
    assert proc.returncode == 0, proc.stderr
    warnings = [ln for ln in proc.stderr.splitlines() if "warning" in ln and "header says" in ln]
    assert len(warnings) == 1 and "b.dcm" in warnings[0] and "990" in warnings[0], proc.stderr
    report = json.loads((out / "report.json").read_text())
    text = json.dumps(report)
    assert "990" in text  # view B used the file's JSON ...
    assert "a.dcm: " not in proc.stderr  # ... and view A kept its header


def test_reconstruct_report_writes_the_pdf_without_patient_data(tmp_path):
    out = tmp_path / "out"
    a, b = str(DATA / "IM1.dcm"), str(DATA / "IM2.dcm")
    proc = run_cli("reconstruct", a, b, "--seeds", str(DATA / "im1_im2_seeds.json"),
                   "--out", str(out), "--report", "--quiet")
    assert proc.returncode == 0, proc.stderr
    pdf = (out / "report.pdf").read_bytes()
    # the overview and the one segment's page (issue 46: the whole reconstruction)
    assert pdf.startswith(b"%PDF") and len(re.findall(rb"/Type\s*/Page[^s]", pdf)) == 2
    report = json.loads((out / "report.json").read_text())
    best = report["optimal_view"]
    assert len(best["angles_deg"]) == 2 and 0.0 <= best["foreshortening_pct"] < 100.0
    assert 0.0 <= best["overlap_pct"] <= 100.0
    grid = best["grid"]
    assert np.asarray(grid["foreshortening_pct"]).shape == (len(grid["beta_deg"]),
                                                           len(grid["alpha_deg"]))

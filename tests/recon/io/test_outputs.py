"""recon.io.outputs: mesh export, and the output files written whole or not at all."""

import io
import json

import numpy as np
import pytest
import trimesh
from support import centerline_3d, straight

from recon.errors import OutputError
from recon.geometry import ViewGeometry
from recon.io.angiogram import load_angiogram
from recon.io.demo import demo_paths
from recon.io.outputs import (
    CENTERLINE_COLUMNS,
    MESH_FORMATS,
    centerline_csv,
    export_mesh,
    outputs_as_bytes,
    write_outputs,
)
from recon.io.seeds_file import load_seeds
from recon.lumen.surface import build_surface
from recon.pipeline import reconstruct_pair

VIEW_A = ViewGeometry(-30.0, 0.0, 1000.0, 750.0, (0.39, 0.39), 512, 512)
VIEW_B = ViewGeometry(30.0, 0.0, 1000.0, 750.0, (0.39, 0.39), 512, 512)


# ---------------------------------------------------------------- export
@pytest.fixture(scope="module")
def tube_mesh():
    return build_surface(centerline_3d(straight(length=20.0), 1.5), VIEW_A, VIEW_B).mesh


@pytest.mark.parametrize("fmt", MESH_FORMATS)
def test_export_round_trip(tube_mesh, fmt):
    data = export_mesh(tube_mesh, fmt)
    assert isinstance(data, bytes) and len(data) > 0
    loaded = trimesh.load(io.BytesIO(data), file_type=fmt, force="mesh")
    loaded.merge_vertices()
    assert loaded.is_watertight
    assert len(loaded.faces) == len(tube_mesh.faces)
    assert loaded.volume == pytest.approx(tube_mesh.volume, rel=1e-5)
    if fmt == "stl":
        assert data[:80] != b"solid" and len(data) == 84 + 50 * len(tube_mesh.faces)
        assert len(loaded.vertices) == len(tube_mesh.vertices)


def test_export_unknown_format_lists_the_formats(tube_mesh):
    with pytest.raises(ValueError, match="stl, obj, ply, glb"):
        export_mesh(tube_mesh, "vtk")


# ---------------------------------------------------------------- files
@pytest.fixture(scope="module")
def demo_rec():
    paths = demo_paths()
    return reconstruct_pair(
        load_angiogram(paths["a"]), load_angiogram(paths["b"]), load_seeds(paths["seeds"])
    )


def test_outputs_as_bytes_and_the_centerline_table(demo_rec):
    files = outputs_as_bytes(demo_rec, ("stl", "glb"))
    assert set(files) == {
        "centerline.csv", "centerline.vtp", "mesh.stl", "mesh.glb", "report.json", "seeds.json"
    }
    assert files["centerline.csv"] == centerline_csv(demo_rec)
    lines = files["centerline.csv"].decode().splitlines()
    assert lines[0] == ",".join(CENTERLINE_COLUMNS)
    table = np.loadtxt(lines[1:], delimiter=",")
    assert table.shape == (len(demo_rec.centerline_3d.s_mm), len(CENTERLINE_COLUMNS))
    assert json.loads(files["report.json"])["mesh"]["watertight"] is True
    assert files["mesh.stl"] == export_mesh(demo_rec.surface.mesh, "stl")


def test_write_outputs_writes_every_file_but_the_seeds(demo_rec, tmp_path):
    out = tmp_path / "new" / "folder"
    paths = write_outputs(demo_rec, out, formats=("stl", "obj"))
    names = ["centerline.csv", "centerline.vtp", "mesh.obj", "mesh.stl", "report.json"]
    assert sorted(p.name for p in paths) == names
    files = outputs_as_bytes(demo_rec, ("stl", "obj"))
    for path in paths:
        assert path.parent == out and path.read_bytes() == files[path.name]
    assert not list(out.glob(".*tmp"))
    manifest = json.loads((out / "outputs.json").read_text())
    assert manifest["complete"] is True and sorted(manifest["files"]) == names
    assert sorted(p.name for p in out.iterdir()) == sorted([*names, "outputs.json"])


def test_out_path_that_is_a_file_is_an_output_error(demo_rec, tmp_path):
    out = tmp_path / "out"
    out.write_text("a file, not a folder")
    with pytest.raises(OutputError) as err:
        write_outputs(demo_rec, out)
    message = str(err.value)
    assert message.startswith(f"{out}: is a file, not a folder") and "\n" not in message
    assert out.read_text() == "a file, not a folder"


def test_the_report_and_the_table_carry_the_95_pct_intervals(demo_rec):
    files = outputs_as_bytes(demo_rec, ("stl",))
    report = json.loads(files["report.json"])
    numbers = {k for k, v in report["measurements"].items() if not isinstance(v, bool)}
    assert set(report["measurements_ci95"]) == numbers
    for key, (lo, hi) in report["measurements_ci95"].items():
        assert lo <= report["measurements"][key] <= hi, key
    assert report["uncertainty"]["samples"] >= 16
    obs = report["calibration"]["observability"]
    assert obs["summary"] and set(obs["directions"]) >= {"translation_baseline",
                                                         "rotation_normal"}
    assert report["calibration"]["correction"] in ("header", "translation", "full")
    lines = files["centerline.csv"].decode().splitlines()
    table = np.loadtxt(lines[1:], delimiter=",")
    col = {name: i for i, name in enumerate(CENTERLINE_COLUMNS)}
    radius = table[:, col["radius_mm"]]
    lo, hi = table[:, col["radius_lo95_mm"]], table[:, col["radius_hi95_mm"]]
    assert np.all(np.isfinite(lo)) and np.all(lo <= radius + 1e-4) and np.all(radius <= hi + 1e-4)
    assert np.median(hi - lo) > 0


def test_a_folder_in_place_of_an_output_leaves_no_part_behind(demo_rec, tmp_path):
    out = tmp_path / "out"
    write_outputs(demo_rec, out, formats=("obj",))
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    (out / "mesh.obj").unlink()
    (out / "mesh.obj").mkdir()  # a folder where the mesh should go
    before.pop("mesh.obj")
    with pytest.raises(OutputError, match=r"mesh\.obj: is a folder"):
        write_outputs(demo_rec, out, formats=("obj",))
    # nothing was written or removed: the earlier files are as they were, no temporary
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before
    assert not list(out.glob(".*tmp"))


def test_the_sr_name_is_the_sr_modules():
    from recon.io.outputs import SR_NAME
    from recon.io.sr import SR_FILE_NAME

    assert SR_NAME == SR_FILE_NAME

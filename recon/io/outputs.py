"""The output files of a reconstruction: centerline CSV and VTP, report JSON, meshes, SR.

``outputs_as_bytes`` renders every file in memory (the viewer's downloads);
``write_outputs`` writes them into a folder as one set (:mod:`recon.io.output_set`:
temporary names, a manifest written last, nothing half-written left).
Mesh formats are the ones of :data:`MESH_FORMATS`, the one list of the
project (the command line's ``--format`` and the viewer's menu use it).
The DICOM SR (:mod:`recon.io.sr`) joins the set when its sources are given.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import trimesh

from recon import __version__
from recon.io.output_set import check_output_folder, write_file_set

if TYPE_CHECKING:
    from recon.io.sr import SRSources
    from recon.pipeline import Reconstruction
    from recon.tree import TreeReconstruction

__all__ = [
    "MESH_FORMATS",
    "CENTERLINE_COLUMNS",
    "export_mesh",
    "centerline_csv",
    "centerline_vtp",
    "outputs_as_bytes",
    "write_outputs",
    "output_names",
    "check_output_dir",
]

MESH_FORMATS: tuple[str, ...] = ("stl", "obj", "ply", "glb")

SR_NAME = "measurements-sr.dcm"  # recon.io.sr.SR_FILE_NAME, without loading highdicom
REPORT_PDF_NAME = "report.pdf"  # recon.io.report_pdf, drawn only when asked for

CENTERLINE_COLUMNS = (
    "s_mm",
    "x_mm",
    "y_mm",
    "z_mm",
    "radius_mm",
    "diameter_mm",
    "area_mm2",
    "radius_a_mm",
    "radius_b_mm",
    "radius_lo95_mm",
    "radius_hi95_mm",
    "branch",
)


def export_mesh(mesh: trimesh.Trimesh, fmt: str) -> bytes:
    """Serialise a mesh to bytes: "stl" (binary), "obj", "ply" (binary) or "glb".

    Raises ValueError naming the supported formats for any other ``fmt``.
    """
    key = str(fmt).lower().lstrip(".")
    if key not in MESH_FORMATS:
        raise ValueError(
            f"unknown mesh format {fmt!r}; supported formats: {', '.join(MESH_FORMATS)}"
        )
    if key == "ply":
        data = mesh.export(file_type="ply", encoding="binary")
    elif key == "obj":
        data = mesh.export(file_type="obj", include_normals=True)
    else:
        data = mesh.export(file_type=key)
    if isinstance(data, str):
        data = data.encode("utf-8")
    return bytes(data)


def _segments(rec: Reconstruction | TreeReconstruction) -> list[tuple[int, Reconstruction]]:
    """(segment index in the seeds, its reconstruction) of every segment reconstructed."""
    branches = getattr(rec, "branches", None)
    if branches is None:
        return [(rec.options.segment, rec)]
    return [(b.options.segment, b) for b in branches]


def _mesh(rec: Reconstruction | TreeReconstruction) -> trimesh.Trimesh:
    """The mesh written: a tree's union of branches, else the segment's surface."""
    tree_surface = getattr(rec, "tree_surface", None)
    return rec.surface.mesh if tree_surface is None else tree_surface.mesh


def centerline_csv(rec: Reconstruction | TreeReconstruction) -> bytes:
    """centerline.csv: header line then one row per point, each segment proximal to
    distal, segments in the seeds' order; ``branch`` is the segment's 0-based index
    in seeds.json.

    radius_lo95_mm / radius_hi95_mm: the 95 % interval of radius_mm
    (:mod:`recon.pose.uncertainty`); nan when the reconstruction has no intervals.
    diameter_mm: the measured lumen profile, nan before a branch's carina (its
    measurements start there)."""
    buf = io.StringIO()
    buf.write(",".join(CENTERLINE_COLUMNS) + "\n")
    for branch_id, seg in _segments(rec):
        cl = seg.centerline_3d
        area = seg.surface.sections.area_mm2
        iv = getattr(seg, "intervals", None)
        nan = np.full(len(cl.s_mm), np.nan)
        lo, hi = (nan, nan) if iv is None else (iv.radius_lo_mm, iv.radius_hi_mm)
        table = np.column_stack([cl.s_mm, cl.X_world, np.sqrt(area / np.pi),
                                 np.interp(cl.s_mm, seg.profile.s_mm, seg.profile.diameter_mm,
                                           left=np.nan, right=np.nan),
                                 area, cl.radius_a_mm,
                                 cl.radius_b_mm, lo, hi, np.full(len(cl.s_mm), branch_id)])
        np.savetxt(buf, table, delimiter=",", fmt=["%.4f"] * 11 + ["%d"])
    return buf.getvalue().encode()


def centerline_vtp(rec: Reconstruction | TreeReconstruction) -> bytes:
    """centerline.vtp: the points of centerline.csv with its radius_mm as ``Radius``,
    one polyline per segment and its ``branch`` as ``BranchId``."""
    from recon.io.vtp import centerline_polydata_bytes

    parts = _segments(rec)
    X = np.vstack([seg.centerline_3d.X_world for _, seg in parts])
    radius_mm = np.concatenate([np.sqrt(seg.surface.sections.area_mm2 / np.pi)
                                for _, seg in parts])
    s_mm = np.concatenate([seg.centerline_3d.s_mm for _, seg in parts])
    branch_id = np.concatenate([np.full(len(seg.centerline_3d.s_mm), k) for k, seg in parts])
    return centerline_polydata_bytes(X, radius_mm, s_mm, branch_id)


def outputs_as_bytes(
    rec: Reconstruction | TreeReconstruction,
    formats: tuple[str, ...] = ("stl",),
    sr_sources: SRSources | None = None,
) -> dict[str, bytes]:
    """Every output file as bytes, keyed by file name (the viewer's downloads).

    With ``sr_sources`` (the two DICOM inputs' headers) the DICOM SR
    measurements-sr.dcm is among them.
    """
    files = {"centerline.csv": centerline_csv(rec), "centerline.vtp": centerline_vtp(rec)}
    for fmt in formats:
        files[f"mesh.{fmt}"] = export_mesh(_mesh(rec), fmt)
    report = json.dumps(rec.report(), indent=2, default=_json_default)
    files["report.json"] = (report + "\n").encode()
    if sr_sources is not None:
        from recon.io.sr import SR_FILE_NAME, measurement_report_sr

        # from the JSON text, so that the SR's values are report.json's to the digit
        files[SR_FILE_NAME] = measurement_report_sr(json.loads(report), sr_sources)
    files["seeds.json"] = (json.dumps(rec.seeds.to_dict(), indent=2) + "\n").encode()
    return files


def output_names(formats: tuple[str, ...] = ("stl",), sr: bool = False,
                 report: bool = False) -> list[str]:
    """The file names :func:`write_outputs` writes for these mesh formats (and the SR,
    and report.pdf)."""
    names = ["centerline.csv", "centerline.vtp", *(f"mesh.{f}" for f in formats), "report.json"]
    return names + [SR_NAME] * sr + [REPORT_PDF_NAME] * report


def known_output_names() -> list[str]:
    """Every file name a reconstruction's output folder can hold (any format, the SR)."""
    return output_names(MESH_FORMATS, sr=True, report=True)


def check_output_dir(
    out_dir: Path,
    formats: tuple[str, ...] = ("stl",),
    sr: bool = False,
    inputs: Sequence[tuple[str, str | os.PathLike]] = (),
    report: bool = False,
) -> None:
    """Refuse, before any work, a folder the outputs must not go to (see
    :func:`recon.io.output_set.check_output_folder`); ``inputs`` are (role, path)."""
    check_output_folder(out_dir, output_names(formats, sr, report), inputs,
                        known_output_names())


def write_outputs(
    rec: Reconstruction | TreeReconstruction,
    out_dir: Path,
    formats: tuple[str, ...] = ("stl",),
    sr_sources: SRSources | None = None,
    inputs: Sequence[tuple[str, str | os.PathLike]] = (),
    extra: Mapping[str, bytes] | None = None,
) -> list[Path]:
    """Write the outputs into ``out_dir`` as one set (:mod:`recon.io.output_set`).

    ``extra`` adds files rendered elsewhere to the set (report.pdf).

    Every file is rendered to bytes first, written under a temporary name, and
    renamed into place; the manifest ``outputs.json`` is written last. A folder
    holding anything but an earlier coronary3d output is refused, and so is an
    output that would replace one of ``inputs`` ((role, path) pairs, e.g.
    ("seeds file", path)). ``sr_sources`` adds the DICOM SR
    (:func:`outputs_as_bytes`). Raises :class:`~recon.errors.OutputError`
    naming the folder or the file; on an error the folder is as it was.
    """
    files = outputs_as_bytes(rec, formats, sr_sources)
    files.pop("seeds.json")
    files.update(extra or {})
    return write_file_set(Path(out_dir), files, inputs, known_output_names(), __version__)


def _json_default(value: object) -> object:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple):
        return list(value)
    return str(value)

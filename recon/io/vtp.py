"""centerline.vtp: the 3D centerline as VTK XML polydata.

One polyline cell per branch through its points, proximal to distal, in
view A's world frame (DICOM LPS, mm), the same points as centerline.csv.
Point arrays: ``Radius`` (mm, the equivalent circular radius of the
elliptic section, centerline.csv's ``radius_mm``; the name VMTK and
3D Slicer look for), ``Abscissas`` (mm of arc length from the branch's
proximal end, centerline.csv's ``s_mm``; VMTK's name for it) and
``BranchId`` (integer, centerline.csv's ``branch``: the segment's index in
seeds.json).

The file is written here as text (VTK's XML format for polydata, "VTK File
Formats", VTK User's Guide, Kitware: a ``Piece`` with its ``PointData``,
``Points`` and ``Lines`` (``connectivity`` and ``offsets``), ASCII data arrays)
rather than through the vtk library, whose import costs more than the whole
writing (the cold ``coronary3d reconstruct`` pays it); the values are written
with 17 significant digits, so they read back exactly.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["RADIUS_ARRAY", "ABSCISSA_ARRAY", "BRANCH_ARRAY", "centerline_polydata_bytes"]

RADIUS_ARRAY = "Radius"
ABSCISSA_ARRAY = "Abscissas"
BRANCH_ARRAY = "BranchId"


def centerline_polydata_bytes(
    X_world: ArrayLike, radius_mm: ArrayLike, s_mm: ArrayLike,
    branch_id: ArrayLike | None = None,
) -> bytes:
    """The .vtp file's bytes: points (N, 3) mm, Radius and Abscissas (N,) mm, BranchId (N,).

    ``branch_id`` (N,) integers, each branch's points contiguous; one
    polyline per run of equal ids (None: one branch, id 0). Raises
    ValueError when the arrays disagree in length or a branch has fewer than
    two points.
    """
    points_mm = np.ascontiguousarray(X_world, dtype=np.float64)
    radius = np.ascontiguousarray(radius_mm, dtype=np.float64)
    s = np.ascontiguousarray(s_mm, dtype=np.float64)
    n = len(points_mm)
    if points_mm.ndim != 2 or points_mm.shape[1] != 3 or n < 2:
        raise ValueError(f"centerline points must be (N >= 2, 3), got {points_mm.shape}")
    ids = (np.zeros(n, dtype=np.int32) if branch_id is None
           else np.ascontiguousarray(branch_id, dtype=np.int32))
    if radius.shape != (n,) or s.shape != (n,) or ids.shape != (n,):
        raise ValueError(
            f"Radius {radius.shape}, Abscissas {s.shape} and BranchId {ids.shape} must have "
            f"one value per point ({n})"
        )
    starts = np.flatnonzero(np.concatenate([[True], ids[1:] != ids[:-1]]))
    stops = np.concatenate([starts[1:], [n]])
    if np.any(stops - starts < 2):
        raise ValueError("every branch of the centerline needs at least two points")
    arrays = "".join(_data_array(values, name=name)
                     for name, values in ((RADIUS_ARRAY, radius), (ABSCISSA_ARRAY, s),
                                          (BRANCH_ARRAY, ids)))
    text = (
        '<?xml version="1.0"?>\n'
        '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" '
        'header_type="UInt64">\n'
        "  <PolyData>\n"
        f'    <Piece NumberOfPoints="{n}" NumberOfVerts="0" NumberOfLines="{len(starts)}" '
        'NumberOfStrips="0" NumberOfPolys="0">\n'
        f'      <PointData Scalars="{RADIUS_ARRAY}">\n{arrays}      </PointData>\n'
        f"      <Points>\n{_data_array(points_mm)}      </Points>\n"
        "      <Lines>\n"
        f'{_data_array(np.arange(n, dtype=np.int64), name="connectivity")}'
        f'{_data_array(stops.astype(np.int64), name="offsets")}'
        "      </Lines>\n"
        "    </Piece>\n"
        "  </PolyData>\n"
        "</VTKFile>\n"
    )
    return text.encode("ascii")


def _data_array(values: np.ndarray, name: str | None = None) -> str:
    """One ``DataArray`` element (ASCII) of (N,) or (N, C) float64 or integer values."""
    kind = {np.dtype(np.float64): ("Float64", "%.17g"), np.dtype(np.int32): ("Int32", "%d"),
            np.dtype(np.int64): ("Int64", "%d")}[values.dtype]
    components = 1 if values.ndim == 1 else values.shape[1]
    named = "" if name is None else f' Name="{name}"'
    body = " ".join(kind[1] % v for v in values.ravel().tolist())
    return (f'        <DataArray type="{kind[0]}"{named} NumberOfComponents="{components}" '
            f'format="ascii">\n          {body}\n        </DataArray>\n')

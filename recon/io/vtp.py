"""centerline.vtp: the 3D centerline as VTK XML polydata (the vtk library).

One polyline cell per branch through its points, proximal to distal, in
view A's world frame (DICOM LPS, mm), the same points as centerline.csv.
Point arrays: ``Radius`` (mm, the equivalent circular radius of the
elliptic section, centerline.csv's ``radius_mm``; the name VMTK and
3D Slicer look for), ``Abscissas`` (mm of arc length from the branch's
proximal end, centerline.csv's ``s_mm``; VMTK's name for it) and
``BranchId`` (integer, centerline.csv's ``branch``: the segment's index in
seeds.json).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from vtkmodules.util.numpy_support import numpy_to_vtk
from vtkmodules.vtkCommonCore import vtkPoints
from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData, vtkPolyLine
from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

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
    points = vtkPoints()
    points.SetData(numpy_to_vtk(points_mm, deep=True))
    cells = vtkCellArray()
    for start, stop in zip(starts, stops, strict=True):
        line = vtkPolyLine()
        line.GetPointIds().SetNumberOfIds(int(stop - start))
        for k, i in enumerate(range(int(start), int(stop))):
            line.GetPointIds().SetId(k, i)
        cells.InsertNextCell(line)
    poly = vtkPolyData()
    poly.SetPoints(points)
    poly.SetLines(cells)
    for name, values in ((RADIUS_ARRAY, radius), (ABSCISSA_ARRAY, s), (BRANCH_ARRAY, ids)):
        array = numpy_to_vtk(values, deep=True)
        array.SetName(name)
        poly.GetPointData().AddArray(array)
    poly.GetPointData().SetActiveScalars(RADIUS_ARRAY)
    writer = vtkXMLPolyDataWriter()
    writer.SetInputData(poly)
    writer.SetDataModeToBinary()  # base64 inline, zlib-compressed: the file is ASCII
    writer.WriteToOutputStringOn()
    if not writer.Write():
        raise ValueError("vtk could not serialise the centerline polydata")
    return writer.GetOutputString().encode("ascii")

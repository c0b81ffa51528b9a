"""centerline.vtp: the 3D centerline as VTK XML polydata (the vtk library).

One polyline cell through the centerline's points, proximal to distal, in
view A's world frame (DICOM LPS, mm), the same points as centerline.csv.
Point arrays: ``Radius`` (mm, the equivalent circular radius of the
elliptic section, centerline.csv's ``radius_mm``; the name VMTK and
3D Slicer look for) and ``Abscissas`` (mm of arc length from the proximal
end, centerline.csv's ``s_mm``; VMTK's name for it).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from vtkmodules.util.numpy_support import numpy_to_vtk
from vtkmodules.vtkCommonCore import vtkPoints
from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData, vtkPolyLine
from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

__all__ = ["RADIUS_ARRAY", "ABSCISSA_ARRAY", "centerline_polydata_bytes"]

RADIUS_ARRAY = "Radius"
ABSCISSA_ARRAY = "Abscissas"


def centerline_polydata_bytes(
    X_world: ArrayLike, radius_mm: ArrayLike, s_mm: ArrayLike
) -> bytes:
    """The .vtp file's bytes: points (N, 3) mm, one polyline, Radius and Abscissas (N,) mm.

    Raises ValueError when the arrays disagree in length or there are fewer
    than two points.
    """
    points_mm = np.ascontiguousarray(X_world, dtype=np.float64)
    radius = np.ascontiguousarray(radius_mm, dtype=np.float64)
    s = np.ascontiguousarray(s_mm, dtype=np.float64)
    n = len(points_mm)
    if points_mm.ndim != 2 or points_mm.shape[1] != 3 or n < 2:
        raise ValueError(f"centerline points must be (N >= 2, 3), got {points_mm.shape}")
    if radius.shape != (n,) or s.shape != (n,):
        raise ValueError(
            f"Radius {radius.shape} and Abscissas {s.shape} must have one value per point ({n})"
        )
    points = vtkPoints()
    points.SetData(numpy_to_vtk(points_mm, deep=True))
    line = vtkPolyLine()
    line.GetPointIds().SetNumberOfIds(n)
    for i in range(n):
        line.GetPointIds().SetId(i, i)
    cells = vtkCellArray()
    cells.InsertNextCell(line)
    poly = vtkPolyData()
    poly.SetPoints(points)
    poly.SetLines(cells)
    for name, values in ((RADIUS_ARRAY, radius), (ABSCISSA_ARRAY, s)):
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

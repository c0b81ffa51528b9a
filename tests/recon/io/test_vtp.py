"""recon.io.vtp: centerline.vtp of `coronary3d reconstruct`, read back with vtk."""

from __future__ import annotations

import numpy as np
import pytest
from support import run_cli
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

from recon.io.vtp import centerline_polydata_bytes


def _read(path) -> object:
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    return reader.GetOutput()


def test_reconstruct_writes_a_vtp_that_matches_the_csv(tmp_path):
    out = tmp_path / "demo"
    proc = run_cli("reconstruct", "--demo", "--quiet", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    table = np.genfromtxt(out / "centerline.csv", delimiter=",", names=True)
    poly = _read(out / "centerline.vtp")
    n = len(table)
    assert poly.GetNumberOfPoints() == n and poly.GetNumberOfLines() == 1
    assert poly.GetCell(0).GetNumberOfPoints() == n  # one polyline, proximal to distal
    ids = [poly.GetCell(0).GetPointId(i) for i in range(n)]
    assert ids == list(range(n))
    points = vtk_to_numpy(poly.GetPoints().GetData())
    xyz = np.column_stack([table["x_mm"], table["y_mm"], table["z_mm"]])
    np.testing.assert_allclose(points, xyz, atol=6e-5)  # the CSV has 4 decimals
    radius = vtk_to_numpy(poly.GetPointData().GetArray("Radius"))
    np.testing.assert_allclose(radius, table["radius_mm"], atol=6e-5)
    s = vtk_to_numpy(poly.GetPointData().GetArray("Abscissas"))
    np.testing.assert_allclose(s, table["s_mm"], atol=6e-5)
    assert poly.GetPointData().GetScalars().GetName() == "Radius"


def test_the_writer_refuses_arrays_that_disagree():
    X = np.zeros((5, 3))
    with pytest.raises(ValueError, match="one value per point"):
        centerline_polydata_bytes(X, np.ones(4), np.arange(5.0))
    with pytest.raises(ValueError, match="N >= 2"):
        centerline_polydata_bytes(X[:1], np.ones(1), np.zeros(1))


def test_branches_become_one_polyline_each_with_their_branch_id(tmp_path):
    X = np.column_stack([np.arange(7.0), np.zeros(7), np.zeros(7)])
    ids = np.array([0, 0, 0, 0, 2, 2, 2])
    path = tmp_path / "tree.vtp"
    path.write_bytes(centerline_polydata_bytes(X, np.ones(7), np.arange(7.0), ids))
    poly = _read(path)
    assert poly.GetNumberOfLines() == 2
    assert [poly.GetCell(k).GetNumberOfPoints() for k in range(2)] == [4, 3]
    assert poly.GetCell(1).GetPointId(0) == 4
    np.testing.assert_array_equal(vtk_to_numpy(poly.GetPointData().GetArray("BranchId")), ids)
    with pytest.raises(ValueError, match="at least two points"):
        centerline_polydata_bytes(X, np.ones(7), np.arange(7.0), [0, 0, 0, 1, 2, 2, 2])

#!/usr/bin/python3
"""Writes tests/data/legacy_{ascii,binary}_{42,51}.vtk with VTK's own legacy writer
(vtkUnstructuredGridWriter, VTK 9.1; run with /usr/bin/python3): reference files for
tests/io/test_vtk_legacy.cpp.

Content (the test relies on it):
  cells, in this order, each with its own points: VTK types
      10 12 13 5 14 24 25 26 3 27 29 32 71(p=3) 72(p=2) 73(p=2) 11
  (5 = triangle and 3 = line are lower-dimensional). Cell c's nodes are at
  A_c(VTK parametric coordinates of the node) with A_c affine, det A_c > 0, chosen per
  cell (the quadratic pyramid's lateral edge nodes at their edges' midpoints); for the
  types whose parametric cell VTK itself considers inside-out (its faces' right-hand
  normals point inwards) the parametric r and s are swapped first, so every 3-D cell is a
  valid VTK cell.
  point data: "analytic" (double, active scalars) = sin(3x) cos(2y) + 0.5 sin(4z + xy);
      "vel" (float, active vectors) = (x, 2y, 3z); FIELD arrays "analytic_f" (float) =
      analytic, "pair" (double, 2 components named "sum" and "diff") = (x + y, x - y),
      "idx" (int) = point index.
  cell data: "cellid" (int, active scalars) = cell index in the file; FIELD "weight"
      (double) = 0.25 * cell index.
Files of version 4.2 hold VTK_LAGRANGE_HEXAHEDRON in the pre-VTK-9 node order, which is
how VTK's reader interprets them (it swaps the node blocks of edges 10 and 11); every file
is read back with VTK's reader and checked to give the intended cells.

Usage: /usr/bin/python3 scripts/gen_legacy_fixtures.py [OUTPUT_DIR]
"""
import math
import os
import sys

import numpy as np
import vtk
from vtk.util.numpy_support import numpy_to_vtk

CELLS = [(10, 4), (12, 8), (13, 6), (5, 3), (14, 5), (24, 10), (25, 20), (26, 15), (3, 2),
         (27, 13), (29, 27), (32, 18), (71, 20), (72, 27), (73, 18), (11, 8)]


def analytic(p):
    x, y, z = p
    return math.sin(3 * x) * math.cos(2 * y) + 0.5 * math.sin(4 * z + x * y)


def make_cell(vtk_type, n):
    ug = vtk.vtkUnstructuredGrid()
    pts = vtk.vtkPoints()
    for i in range(n):
        pts.InsertNextPoint(0, 0, 0)
    ug.SetPoints(pts)
    ug.InsertNextCell(vtk_type, n, list(range(n)))
    return ug.GetCell(0)


def pcoords(vtk_type, n):
    if vtk_type == 5:
        return np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    if vtk_type == 3:
        return np.array([[0, 0, 0], [1, 0, 0]], float)
    cell = make_cell(vtk_type, n)
    pc = cell.GetParametricCoords()
    return np.array([[pc[3 * i], pc[3 * i + 1], pc[3 * i + 2]] for i in range(n)])


def faces_outward(vtk_type, x):
    """VTK's rule for 3-D cells: the faces' right-hand normals point out of the cell."""
    n = len(x)
    ug = vtk.vtkUnstructuredGrid()
    pts = vtk.vtkPoints()
    for p in x:
        pts.InsertNextPoint(*p)
    ug.SetPoints(pts)
    ug.InsertNextCell(vtk_type, n, list(range(n)))
    cell = ug.GetCell(0)
    centre = x.mean(axis=0)
    signs = []
    for f in range(cell.GetNumberOfFaces()):
        face = cell.GetFace(f)
        ids = [face.GetPointId(i) for i in range(3)]
        a, b, c = (x[i] for i in ids)
        normal = np.cross(b - a, c - a)
        fc = np.mean([x[face.GetPointId(i)] for i in range(face.GetNumberOfPoints())],
                     axis=0)
        signs.append(np.sign(np.dot(normal, fc - centre)))
    return all(s > 0 for s in signs), all(s < 0 for s in signs)


def legacy_hex_ids(p):
    """VTK node m of an order-p VTK_LAGRANGE_HEXAHEDRON is pre-VTK-9 file node ids[m]."""
    e = p - 1
    e10, e11 = 8 + 10 * e, 8 + 11 * e
    ids = list(range((p + 1) ** 3))
    for k in range(e):
        ids[e10 + k], ids[e11 + k] = e11 + k, e10 + k
    return ids


def build(version):
    rng = np.random.default_rng(7)
    points, cells, expected = [], [], []
    for c, (t, n) in enumerate(CELLS):
        xi = pcoords(t, n)
        if t == 27:
            # VTK's parametric pyramid is a hex collapsed at the top: the parametric
            # coordinates of nodes 9..12 are not on the straight edges (i, 4) VTK
            # documents them on; put them at those edges' midpoints.
            for i in range(4):
                xi[9 + i] = 0.5 * (xi[i] + xi[4])
        if t in (5, 3):
            geometry = xi
        else:
            out, inward = faces_outward(t, xi)
            if not out:
                assert inward, t
                xi = xi[:, [1, 0, 2]]
                assert faces_outward(t, xi)[0], t
            geometry = xi
        a = np.eye(3) + 0.2 * rng.uniform(-1, 1, (3, 3))
        if np.linalg.det(a) < 0:
            a[:, 0] *= -1
        assert np.linalg.det(a) > 0
        x = geometry @ a.T + np.array([2.0 * c, 0.1 * c, -0.05 * c])
        base = len(points)
        points.extend(x)
        expected.append((t, x))
        ids = list(range(base, base + n))
        if t == 72 and version == 42:
            order = legacy_hex_ids(2)  # file node ids[m] holds VTK node m
            file_ids = [0] * n
            for m in range(n):
                file_ids[order[m]] = ids[m]
            ids = file_ids
        cells.append((t, ids))
    return np.array(points), cells, expected


def write(path, version, binary):
    points, cells, expected = build(version)
    ug = vtk.vtkUnstructuredGrid()
    pts = vtk.vtkPoints()
    pts.SetDataTypeToDouble()
    for p in points:
        pts.InsertNextPoint(*p)
    ug.SetPoints(pts)
    for t, ids in cells:
        ug.InsertNextCell(t, len(ids), ids)
    pd = ug.GetPointData()
    f = np.array([analytic(p) for p in points])
    arr = numpy_to_vtk(f, deep=1)
    arr.SetName("analytic")
    pd.SetScalars(arr)
    vel = numpy_to_vtk(np.ascontiguousarray(points * [1, 2, 3], dtype=np.float32), deep=1)
    vel.SetName("vel")
    pd.SetVectors(vel)
    ff = numpy_to_vtk(f.astype(np.float32), deep=1)
    ff.SetName("analytic_f")
    pd.AddArray(ff)
    pair = numpy_to_vtk(np.ascontiguousarray(np.stack([points[:, 0] + points[:, 1],
                                                       points[:, 0] - points[:, 1]], 1)),
                        deep=1)
    pair.SetName("pair")
    pair.SetComponentName(0, "sum")
    pair.SetComponentName(1, "diff")
    pd.AddArray(pair)
    idx = numpy_to_vtk(np.arange(len(points), dtype=np.int32), deep=1)
    idx.SetName("idx")
    pd.AddArray(idx)
    cd = ug.GetCellData()
    cid = numpy_to_vtk(np.arange(len(cells), dtype=np.int32), deep=1)
    cid.SetName("cellid")
    cd.SetScalars(cid)
    wgt = numpy_to_vtk(0.25 * np.arange(len(cells), dtype=np.float64), deep=1)
    wgt.SetName("weight")
    cd.AddArray(wgt)

    w = vtk.vtkUnstructuredGridWriter()
    w.SetInputData(ug)
    w.SetFileName(path)
    w.SetFileVersion(version)
    if binary:
        w.SetFileTypeToBinary()
    else:
        w.SetFileTypeToASCII()
    assert w.Write() == 1

    # Read back with VTK: every cell's VTK node m must be at A_c(pcoords[m]).
    r = vtk.vtkUnstructuredGridReader()
    r.SetFileName(path)
    r.Update()
    out = r.GetOutput()
    assert out.GetNumberOfCells() == len(cells)
    for c, (t, x) in enumerate(expected):
        cell = out.GetCell(c)
        assert cell.GetCellType() == t, (c, t)
        for m in range(cell.GetNumberOfPoints()):
            got = np.array(out.GetPoint(cell.GetPointId(m)))
            assert np.allclose(got, x[m], atol=1e-9), (path, c, t, m)


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "..", "tests", "data")
    for version in (42, 51):
        for binary in (False, True):
            name = "legacy_%s_%d.vtk" % ("binary" if binary else "ascii", version)
            write(os.path.join(out, name), version, binary)


if __name__ == "__main__":
    main()

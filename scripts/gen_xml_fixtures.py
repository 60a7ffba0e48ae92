#!/usr/bin/python3
"""Writes the VTK XML fixtures tests/data/xml_* with VTK's own writers (VTK 9.1, Debian's
python3-vtk9; run with /usr/bin/python3), so the reader is checked against files it did not
write. Every value in them is a closed form the C++ test recomputes:

  map(r, s, t, c) = (r + 0.1 s^2 + 2 c, s + 0.1 t r, t + 0.05 r s t)   (cell c's geometry)
  f(x, y, z)      = x + 2 y + 3 z

- xml_vtk_grid.vts: StructuredGrid, extent [0,3]x[0,2]x[0,4], point (i,j,k) at
  grid(i,j,k) = (i + 0.1 sin(j), 0.5 j + 0.05 k, 0.25 k + 0.02 i j); point fields "f"
  (Float64) and "g" = 2 (x, y, z) (Float32, 3 components); cell field "cid" (Int32) = VTK
  cell index. Appended base64, zlib, UInt64 headers.
- xml_vtk_lagrange.vtu: one cell each of VTK_LAGRANGE_HEXAHEDRON orders 2 and 3,
  VTK_LAGRANGE_TETRAHEDRON order 3 and VTK_LAGRANGE_WEDGE order 2, cell c's node n at
  map(VTK's parametric coordinates of node n, c); private points; point field "f";
  cell arrays HigherOrderDegrees and "cid" = c. Appended raw, no compression, Float64.
- xml_vtk_bigendian.vtu: the same cells written BigEndian, appended raw, zlib, UInt32
  headers, Float32 points, Int8/UInt16/Int64/UInt32 cell fields "i8" = -c - 1,
  "u16" = 1000 c, "i64" = -(2^40) c, "u32" = 7 c.
- xml_vtk_pieces.pvtu with xml_vtk_pieces_0.vtu (ascii) and xml_vtk_pieces_1.vtu (inline
  base64, zlib): piece q holds the unit-cube linear hexahedra of a 2x1x1 (piece 0) and
  1x1x1 (piece 1) lattice shifted by 3 q along x, points shared within a piece; point
  field "f", cell field "cid" = 10 q + cell index.

Usage: /usr/bin/python3 scripts/gen_xml_fixtures.py [OUTPUT_DIR]
"""
import math
import os
import sys

import vtk


def mapped(r, s, t, c):
    return (r + 0.1 * s * s + 2 * c, s + 0.1 * t * r, t + 0.05 * r * s * t)


def f(x, y, z):
    return x + 2 * y + 3 * z


def lagrange_cell(cls, n):
    cell = cls()
    cell.GetPointIds().SetNumberOfIds(n)
    cell.GetPoints().SetNumberOfPoints(n)
    if hasattr(cell, "SetUniformOrderFromNumPoints"):
        cell.SetUniformOrderFromNumPoints(n)
    else:
        cell.Initialize()
    pc = cell.GetParametricCoords()
    return [(pc[3 * i], pc[3 * i + 1], pc[3 * i + 2]) for i in range(n)]


def array(cls, name, comps, values):
    a = cls()
    a.SetName(name)
    a.SetNumberOfComponents(comps)
    for v in values:
        if comps == 1:
            a.InsertNextValue(v)
        else:
            a.InsertNextTuple(v)
    return a


def lagrange_grid(point_type):
    cells = [(vtk.VTK_LAGRANGE_HEXAHEDRON, vtk.vtkLagrangeHexahedron, 27, 2),
             (vtk.VTK_LAGRANGE_HEXAHEDRON, vtk.vtkLagrangeHexahedron, 64, 3),
             (vtk.VTK_LAGRANGE_TETRAHEDRON, vtk.vtkLagrangeTetra, 20, 3),
             (vtk.VTK_LAGRANGE_WEDGE, vtk.vtkLagrangeWedge, 18, 2)]
    grid = vtk.vtkUnstructuredGrid()
    points = vtk.vtkPoints()
    points.SetDataType(point_type)
    fvals = []
    degrees = vtk.vtkIntArray()
    degrees.SetName("HigherOrderDegrees")
    degrees.SetNumberOfComponents(3)
    for c, (vtk_type, cls, n, p) in enumerate(cells):
        ids = vtk.vtkIdList()
        for pc in lagrange_cell(cls, n):
            x = mapped(*pc, c)
            ids.InsertNextId(points.InsertNextPoint(x))
            fvals.append(f(*x))
        grid.InsertNextCell(vtk_type, ids)
        degrees.InsertNextTuple((p, p, p))
    grid.SetPoints(points)
    grid.GetPointData().AddArray(array(vtk.vtkDoubleArray, "f", 1, fvals))
    grid.GetCellData().AddArray(array(vtk.vtkIntArray, "cid", 1, range(len(cells))))
    grid.GetCellData().SetHigherOrderDegrees(degrees)
    return grid, len(cells)


def write(writer, data, path):
    writer.SetInputData(data)
    writer.SetFileName(path)
    if not writer.Write():
        raise RuntimeError("VTK could not write " + path)


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        os.path.dirname(os.path.abspath(__file__)), "..", "tests", "data")

    # Structured grid.
    nx, ny, nz = 4, 3, 5
    sg = vtk.vtkStructuredGrid()
    sg.SetDimensions(nx, ny, nz)
    pts = vtk.vtkPoints()
    pts.SetDataTypeToDouble()
    fv, gv = [], []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                x = (i + 0.1 * math.sin(j), 0.5 * j + 0.05 * k, 0.25 * k + 0.02 * i * j)
                pts.InsertNextPoint(x)
                fv.append(f(*x))
                gv.append(tuple(2 * v for v in x))
    sg.SetPoints(pts)
    sg.GetPointData().AddArray(array(vtk.vtkDoubleArray, "f", 1, fv))
    sg.GetPointData().AddArray(array(vtk.vtkFloatArray, "g", 3, gv))
    sg.GetCellData().AddArray(array(vtk.vtkIntArray, "cid", 1,
                                    range((nx - 1) * (ny - 1) * (nz - 1))))
    w = vtk.vtkXMLStructuredGridWriter()
    w.SetDataModeToAppended()
    w.EncodeAppendedDataOn()
    w.SetCompressorTypeToZLib()
    w.SetHeaderTypeToUInt64()
    write(w, sg, os.path.join(out, "xml_vtk_grid.vts"))

    # Lagrange cells, appended raw.
    grid, ncells = lagrange_grid(vtk.VTK_DOUBLE)
    w = vtk.vtkXMLUnstructuredGridWriter()
    w.SetDataModeToAppended()
    w.EncodeAppendedDataOff()
    w.SetCompressorTypeToNone()
    write(w, grid, os.path.join(out, "xml_vtk_lagrange.vtu"))

    # Big-endian, zlib, UInt32 headers, Float32 points, integer cell fields.
    grid, ncells = lagrange_grid(vtk.VTK_FLOAT)
    cd = grid.GetCellData()
    cd.AddArray(array(vtk.vtkSignedCharArray, "i8", 1, [-c - 1 for c in range(ncells)]))
    cd.AddArray(array(vtk.vtkUnsignedShortArray, "u16", 1, [1000 * c for c in range(ncells)]))
    cd.AddArray(array(vtk.vtkTypeInt64Array, "i64", 1, [-(2 ** 40) * c for c in range(ncells)]))
    cd.AddArray(array(vtk.vtkTypeUInt32Array, "u32", 1, [7 * c for c in range(ncells)]))
    w = vtk.vtkXMLUnstructuredGridWriter()
    w.SetDataModeToAppended()
    w.EncodeAppendedDataOff()
    w.SetCompressorTypeToZLib()
    w.SetBlockSize(256)   # several blocks per array, with a partial last one
    w.SetHeaderTypeToUInt32()
    w.SetByteOrderToBigEndian()
    write(w, grid, os.path.join(out, "xml_vtk_bigendian.vtu"))

    # Two pieces and their index.
    pieces = []
    for q, (cx, mode) in enumerate([(2, "ascii"), (1, "binary")]):
        ug = vtk.vtkUnstructuredGrid()
        pts = vtk.vtkPoints()
        pts.SetDataTypeToDouble()
        fv = []
        for k in range(2):
            for j in range(2):
                for i in range(cx + 1):
                    x = (i + 3.0 * q, float(j), float(k))
                    pts.InsertNextPoint(x)
                    fv.append(f(*x))
        ug.SetPoints(pts)
        for i in range(cx):
            idx = lambda a, b, d: a + (cx + 1) * (b + 2 * d)
            ids = [idx(i, 0, 0), idx(i + 1, 0, 0), idx(i + 1, 1, 0), idx(i, 1, 0),
                   idx(i, 0, 1), idx(i + 1, 0, 1), idx(i + 1, 1, 1), idx(i, 1, 1)]
            ug.InsertNextCell(vtk.VTK_HEXAHEDRON, 8, ids)
        ug.GetPointData().AddArray(array(vtk.vtkDoubleArray, "f", 1, fv))
        ug.GetCellData().AddArray(array(vtk.vtkIntArray, "cid", 1,
                                        [10 * q + i for i in range(cx)]))
        w = vtk.vtkXMLUnstructuredGridWriter()
        if mode == "ascii":
            w.SetDataModeToAscii()
        else:
            w.SetDataModeToBinary()
            w.SetCompressorTypeToZLib()
        name = "xml_vtk_pieces_%d.vtu" % q
        write(w, ug, os.path.join(out, name))
        pieces.append(name)
    with open(os.path.join(out, "xml_vtk_pieces.pvtu"), "w") as pv:
        pv.write('<?xml version="1.0"?>\n'
                 '<VTKFile type="PUnstructuredGrid" version="1.0" byte_order="LittleEndian"'
                 ' header_type="UInt32">\n  <PUnstructuredGrid GhostLevel="0">\n'
                 '    <PPointData>\n      <PDataArray type="Float64" Name="f"/>\n'
                 '    </PPointData>\n    <PCellData>\n'
                 '      <PDataArray type="Int32" Name="cid"/>\n    </PCellData>\n'
                 '    <PPoints>\n      <PDataArray type="Float64" NumberOfComponents="3"/>\n'
                 '    </PPoints>\n')
        for name in pieces:
            pv.write('    <Piece Source="%s"/>\n' % name)
        pv.write('  </PUnstructuredGrid>\n</VTKFile>\n')


if __name__ == "__main__":
    main()

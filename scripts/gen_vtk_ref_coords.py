#!/usr/bin/python3
"""Writes tests/data/vtk_ref_coords.json: what VTK itself says about the 3-D cell types
hpray reads, as reference truth for tests/io/test_vtk_cells.cpp. Needs Debian's
python3-vtk9 (VTK 9.1); run with /usr/bin/python3.

For every cell type (10, 12, 13, 14, 24, 25, 26, 27, 29, 32, and the Lagrange types 71,
72, 73 of orders 1..6) it records
  - "pcoords": VTK's parametric coordinates of each node, in VTK's node order
    (vtkCell::GetParametricCoords on a cell with exactly that many points; for Lagrange
    cells the order VTK derived from the point count is checked);
  - "valid_geometry": which of two affine images of VTK's reference cell VTK itself
    considers correctly oriented, by VTK's documented rule for 3-D cells that the faces
    returned by vtkCell::GetFace have outward normals (right-hand rule on the first three
    face points). "identity" puts node n at pcoords[n]; "mirror_rs" at pcoords[n] with r
    and s swapped. Exactly one of the two has every face outward, or the script fails;
  - "face_signs": for each of the two geometries, the sign of
    (face normal . (face centre - cell centre)) of every face;
  - "validator": vtkCellValidator::Check state of both geometries, and "volume":
    vtkCellSizeFilter's signed volume of both. Informational only: VTK 9.1 disagrees with
    itself here. The validator hard-codes the opposite expectation for 26 and 32, and the
    size filter's volumes of 27, 29 and 32 are wrong in magnitude. The face rule decides.
VTK 9.1 has no class for VTK_LAGRANGE_PYRAMID (74), so there is nothing to record for it.

"legacy_hex" records how VTK's own readers renumber a VTK_LAGRANGE_HEXAHEDRON of order 2,
3, 4 read from a file version that predates VTK 9: a one-cell file with connectivity
0..N-1 is read back and the cell's point ids are stored ("ids": VTK's node m is file node
ids[m]). "legacy_hex_versions" says, per XML and legacy-.vtk file version, whether VTK
applied that renumbering.

Usage: /usr/bin/python3 scripts/gen_vtk_ref_coords.py [OUTPUT]
"""
import json
import os
import sys

import numpy as np
import vtk

LAGRANGE_ORDERS = range(1, 7)


def lagrange_count(vtk_type, p):
    if vtk_type == vtk.VTK_LAGRANGE_TETRAHEDRON:
        return (p + 1) * (p + 2) * (p + 3) // 6
    if vtk_type == vtk.VTK_LAGRANGE_HEXAHEDRON:
        return (p + 1) ** 3
    if vtk_type == vtk.VTK_LAGRANGE_WEDGE:
        return (p + 1) * (p + 1) * (p + 2) // 2
    raise ValueError(vtk_type)


def make_cell(cls, n=None, p=None):
    """A cell of class `cls` with n points (ids 0..n-1). For Lagrange cells the order VTK
    derives from the point count must equal p."""
    cell = cls()
    if n is not None:
        cell.GetPointIds().SetNumberOfIds(n)
        cell.GetPoints().SetNumberOfPoints(n)
        if hasattr(cell, "SetUniformOrderFromNumPoints"):   # hexahedron, wedge
            cell.SetUniformOrderFromNumPoints(n)
            order = [cell.GetOrder(i) for i in range(4)]
            assert order == [p, p, p, n], (cls.__name__, n, order)
        else:                                               # tetrahedron
            cell.Initialize()
            assert cell.GetOrder() == p, (cls.__name__, n, cell.GetOrder())
    for i in range(cell.GetNumberOfPoints()):
        cell.GetPointIds().SetId(i, i)
    return cell


def parametric_coords(cell):
    n = cell.GetNumberOfPoints()
    pc = cell.GetParametricCoords()
    coords = np.array([[pc[3 * i + d] for d in range(3)] for i in range(n)])
    assert len({tuple(np.round(x, 12)) for x in coords}) == n, "coincident nodes"
    return coords


def face_signs(cell, x):
    """Sign of (normal of the first three face points) . (face centre - cell centre)."""
    centre = x.mean(axis=0)
    signs = []
    for f in range(cell.GetNumberOfFaces()):
        face = cell.GetFace(f)
        ids = [face.GetPointId(i) for i in range(face.GetNumberOfPoints())]
        normal = np.cross(x[ids[1]] - x[ids[0]], x[ids[2]] - x[ids[0]])
        face_centre = x[ids].mean(axis=0)
        signs.append(int(np.sign(np.dot(normal, face_centre - centre))))
    return signs


def one_cell_grid(vtk_type, x):
    grid = vtk.vtkUnstructuredGrid()
    points = vtk.vtkPoints()
    points.SetDataTypeToDouble()
    for p in x:
        points.InsertNextPoint(*p)
    grid.SetPoints(points)
    ids = vtk.vtkIdList()
    for i in range(len(x)):
        ids.InsertNextId(i)
    grid.InsertNextCell(vtk_type, ids)
    return grid


def signed_volume(vtk_type, x):
    size = vtk.vtkCellSizeFilter()
    size.SetInputData(one_cell_grid(vtk_type, x))
    size.Update()
    return size.GetOutput().GetCellData().GetArray("Volume").GetValue(0)


def describe(vtk_type, cls, n=None, p=None):
    cell = make_cell(cls, n, p)
    assert cell.GetCellType() == vtk_type
    pc = parametric_coords(cell)
    geometries = {"identity": pc, "mirror_rs": pc[:, [1, 0, 2]]}
    signs, validator, volume = {}, {}, {}
    for name, x in geometries.items():
        for i, xi in enumerate(x):
            cell.GetPoints().SetPoint(i, *xi)
        signs[name] = face_signs(cell, x)
        validator[name] = int(vtk.vtkCellValidator.Check(cell, 1e-9))
        volume[name] = signed_volume(vtk_type, x)
    valid = [g for g in geometries if all(s > 0 for s in signs[g])]
    assert len(valid) == 1, (vtk_type, signs)
    return {"vtk_type": vtk_type, "class": cls.__name__, "order": p or 0,
            "nodes": len(pc), "pcoords": pc.tolist(), "valid_geometry": valid[0],
            "face_signs": signs, "validator": validator, "volume": volume}


def read_xml_hex(p, version):
    n = (p + 1) ** 3
    points = " ".join("%d 0 0" % i for i in range(n))
    conn = " ".join(str(i) for i in range(n))
    text = f"""<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="{version}" byte_order="LittleEndian">
<UnstructuredGrid><Piece NumberOfPoints="{n}" NumberOfCells="1">
<Points>
<DataArray type="Float64" NumberOfComponents="3" format="ascii">{points}</DataArray>
</Points><Cells>
<DataArray type="Int64" Name="connectivity" format="ascii">{conn}</DataArray>
<DataArray type="Int64" Name="offsets" format="ascii">{n}</DataArray>
<DataArray type="UInt8" Name="types" format="ascii">72</DataArray>
</Cells></Piece></UnstructuredGrid></VTKFile>
"""
    reader = vtk.vtkXMLUnstructuredGridReader()
    reader.ReadFromInputStringOn()
    reader.SetInputString(text)
    reader.Update()
    cell = reader.GetOutput().GetCell(0)
    return [cell.GetPointId(i) for i in range(cell.GetNumberOfPoints())]


def read_legacy_hex(p, major, minor):
    n = (p + 1) ** 3
    points = "\n".join("%d 0 0" % i for i in range(n))
    conn = " ".join(str(i) for i in range(n))
    if (major, minor) >= (5, 0):
        cells = (f"CELLS 2 {n}\nOFFSETS vtktypeint64\n0 {n}\n"
                 f"CONNECTIVITY vtktypeint64\n{conn}")
    else:
        cells = f"CELLS 1 {n + 1}\n{n} {conn}"
    text = (f"# vtk DataFile Version {major}.{minor}\nhex\nASCII\n"
            f"DATASET UNSTRUCTURED_GRID\nPOINTS {n} double\n{points}\n{cells}\n"
            f"CELL_TYPES 1\n72\n")
    reader = vtk.vtkUnstructuredGridReader()
    reader.ReadFromInputStringOn()
    reader.SetInputString(text)
    reader.Update()
    cell = reader.GetOutput().GetCell(0)
    return [cell.GetPointId(i) for i in range(cell.GetNumberOfPoints())]


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        here, "..", "tests", "data", "vtk_ref_coords.json")

    vtk.vtkObject.GlobalWarningDisplayOff()  # vtkCellSizeFilter warns on some types
    cells = [describe(vtk_type, cls, None, p) for vtk_type, cls, p in [
        (vtk.VTK_TETRA, vtk.vtkTetra, 1),
        (vtk.VTK_HEXAHEDRON, vtk.vtkHexahedron, 1),
        (vtk.VTK_WEDGE, vtk.vtkWedge, 1),
        (vtk.VTK_PYRAMID, vtk.vtkPyramid, 1),
        (vtk.VTK_QUADRATIC_TETRA, vtk.vtkQuadraticTetra, 2),
        (vtk.VTK_QUADRATIC_HEXAHEDRON, vtk.vtkQuadraticHexahedron, 2),
        (vtk.VTK_QUADRATIC_WEDGE, vtk.vtkQuadraticWedge, 2),
        (vtk.VTK_QUADRATIC_PYRAMID, vtk.vtkQuadraticPyramid, 2),
        (vtk.VTK_TRIQUADRATIC_HEXAHEDRON, vtk.vtkTriQuadraticHexahedron, 2),
        (vtk.VTK_BIQUADRATIC_QUADRATIC_WEDGE, vtk.vtkBiQuadraticQuadraticWedge, 2)]]
    for vtk_type, cls in [(vtk.VTK_LAGRANGE_TETRAHEDRON, vtk.vtkLagrangeTetra),
                          (vtk.VTK_LAGRANGE_HEXAHEDRON, vtk.vtkLagrangeHexahedron),
                          (vtk.VTK_LAGRANGE_WEDGE, vtk.vtkLagrangeWedge)]:
        for p in LAGRANGE_ORDERS:
            cells.append(describe(vtk_type, cls, lagrange_count(vtk_type, p), p))

    legacy_hex = [{"order": p, "xml_version": "0.1", "ids": read_xml_hex(p, "0.1")}
                  for p in (2, 3, 4)]
    identity = list(range(27))
    versions = {
        "xml": {v: read_xml_hex(2, v) != identity
                for v in ["0.1", "1.0", "2.0", "2.1", "2.2", "2.3"]},
        "legacy": {f"{a}.{b}": read_legacy_hex(2, a, b) != identity
                   for a, b in [(3, 0), (4, 2), (5, 0), (5, 1)]},
    }

    result = {"generator": "scripts/gen_vtk_ref_coords.py with VTK " +
              vtk.vtkVersion.GetVTKVersion(),
              "cells": cells, "legacy_hex": legacy_hex, "legacy_hex_versions": versions}
    with open(out, "w") as f:
        json.dump(result, f, separators=(",", ":"))
        f.write("\n")


if __name__ == "__main__":
    main()

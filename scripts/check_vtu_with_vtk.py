#!/usr/bin/python3
"""Reads .vtu files with VTK's own reader (VTK 9.1, Debian's python3-vtk9; run with
/usr/bin/python3) as an outside check of hpray's writer: every cell must be one VTK knows,
its HigherOrderDegrees must match its node count, and VTK's cell size filter must find a
positive volume for every cell (a node-order mistake turns cells inside out or folds them).

Usage: /usr/bin/python3 scripts/check_vtu_with_vtk.py FILE.vtu [...]
Exit status 0 when every file passes; cells of VTK_LAGRANGE_PYRAMID (74), for which VTK
9.1 has no class, are counted and reported, not failed.
"""
import sys

import vtk


def check(path):
    reader = vtk.vtkXMLUnstructuredGridReader()
    reader.SetFileName(path)
    reader.Update()
    grid = reader.GetOutput()
    n = grid.GetNumberOfCells()
    problems = []
    unknown_pyramids = 0
    degrees = grid.GetCellData().GetHigherOrderDegrees()
    for c in range(n):
        vtk_type = grid.GetCellType(c)
        if vtk_type == 74:
            unknown_pyramids += 1
            continue
        cell = grid.GetCell(c)
        if cell is None:
            problems.append("cell %d: VTK cannot make a cell of type %d" % (c, vtk_type))
            continue
        if degrees is not None and vtk_type in (71, 72, 73):
            p = [int(v) for v in degrees.GetTuple3(c)]
            count = {71: (p[0] + 1) * (p[0] + 2) * (p[0] + 3) // 6,
                     72: (p[0] + 1) ** 3,
                     73: (p[0] + 1) * (p[0] + 1) * (p[0] + 2) // 2}[vtk_type]
            if count != cell.GetNumberOfPoints():
                problems.append("cell %d: degrees %s but %d nodes" %
                                (c, p, cell.GetNumberOfPoints()))
    sizes = vtk.vtkCellSizeFilter()
    sizes.SetInputData(grid)
    sizes.ComputeVolumeOn()
    sizes.Update()
    volume = sizes.GetOutput().GetCellData().GetArray("Volume")
    for c in range(n):
        if grid.GetCellType(c) != 74 and not volume.GetValue(c) > 0:
            problems.append("cell %d (type %d): VTK volume %g" %
                            (c, grid.GetCellType(c), volume.GetValue(c)))
    print("%s: %d points, %d cells, %d type-74 cells skipped, %d problems" %
          (path, grid.GetNumberOfPoints(), n, unknown_pyramids, len(problems)))
    for p in problems[:20]:
        print("  " + p)
    return not problems


def main():
    ok = all([check(path) for path in sys.argv[1:]])
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()

#!/usr/bin/python3
"""Reads .vtu files with VTK's own reader (VTK 9.1, Debian's python3-vtk9; run with
/usr/bin/python3) as an outside check of hpray's writer: every cell must be one VTK knows,
its HigherOrderDegrees must match its node count, and VTK's cell size filter must find a
positive volume for every cell (a node-order mistake turns cells inside out or folds them).

Usage: /usr/bin/python3 scripts/check_vtu_with_vtk.py FILE.vtu [...]
       /usr/bin/python3 scripts/check_vtu_with_vtk.py --types INPUT PARTITION_DIR

Exit status 0 when every file passes; cells of VTK_LAGRANGE_PYRAMID (74), for which VTK
9.1 has no class, are counted and reported, not failed.

--types compares the cell types of a partition with those of its input, all read by VTK:
the 3-D cells of INPUT (.vtu, .pvtu or legacy .vtk; cells VTK's vtkGhostType marks as
duplicates left out, as `hpray partition` leaves them out) per VTK cell type, against the
owned cells (vtkGhostType 0) per type of the bricks that PARTITION_DIR/manifest.json
lists, read one by one and again through bricks.pvtu. Every brick also gets the checks
above. The partition keeps the input's types when all three columns agree. (VTK cannot
read gmsh files: for a .msh input compare against a .vtu of it.)
"""
import json
import os
import sys

import vtk

# vtkDataSetAttributes::DUPLICATECELL: a ghost copy of a cell owned elsewhere.
DUPLICATE_CELL = 1


def read(path):
    """The unstructured grid in `path`, read by the VTK reader for its extension."""
    if path.endswith(".pvtu"):
        reader = vtk.vtkXMLPUnstructuredGridReader()
    elif path.endswith(".vtk"):
        reader = vtk.vtkUnstructuredGridReader()
        reader.ReadAllScalarsOn()
        reader.ReadAllVectorsOn()
        reader.ReadAllFieldsOn()
    else:
        reader = vtk.vtkXMLUnstructuredGridReader()
    reader.SetFileName(path)
    reader.Update()
    return reader.GetOutput()


def check_grid(grid, label):
    """The checks of the module docstring for one grid; prints a line, returns success."""
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
          (label, grid.GetNumberOfPoints(), n, unknown_pyramids, len(problems)))
    for p in problems[:20]:
        print("  " + p)
    return not problems


def check(path):
    return check_grid(read(path), path)


def is_3d(vtk_type, grid, c, cache={}):
    """Whether VTK type `vtk_type` (of cell c of grid) is a 3-D cell (asked once per type;
    74, which VTK 9.1 cannot instantiate, is a pyramid)."""
    if vtk_type not in cache:
        cell = grid.GetCell(c) if vtk_type != 74 else None
        cache[vtk_type] = vtk_type == 74 or (cell is not None and
                                              cell.GetCellDimension() == 3)
    return cache[vtk_type]


def owned_types(grid, only_3d):
    """{VTK type: number of cells} over the cells that are not duplicates."""
    ghost = grid.GetCellData().GetArray("vtkGhostType")
    counts = {}
    for c in range(grid.GetNumberOfCells()):
        if ghost is not None and int(ghost.GetValue(c)) & DUPLICATE_CELL:
            continue
        t = grid.GetCellType(c)
        if only_3d and not is_3d(t, grid, c):
            continue
        counts[t] = counts.get(t, 0) + 1
    return counts


def type_name(t):
    name = vtk.vtkCellTypes.GetClassNameFromTypeId(t)
    return name if name else "?"


def compare_types(mesh, folder):
    with open(os.path.join(folder, "manifest.json")) as f:
        manifest = json.load(f)
    source = read(mesh)
    # The input's own cells get the same checks, to tell problems VTK has with the
    # input's cells (which the bricks copy) from problems the partition made.
    check_grid(source, mesh + " (input)")
    cells_ok = True
    types_ok = True
    expected = owned_types(source, only_3d=True)
    bricks = {}
    every = set()  # types in any brick, ghosts included
    for b in manifest["bricks"]:
        path = os.path.join(folder, b["file"])
        grid = read(path)
        cells_ok &= check_grid(grid, path)
        for t in range(grid.GetNumberOfCells()):
            every.add(grid.GetCellType(t))
        for t, n in owned_types(grid, only_3d=False).items():
            bricks[t] = bricks.get(t, 0) + n
    index = owned_types(read(os.path.join(folder, "bricks.pvtu")), only_3d=False)
    print("%-6s %-36s %10s %10s %12s" % ("type", "VTK class", "input", "bricks",
                                          "bricks.pvtu"))
    for t in sorted(set(expected) | set(bricks) | set(index) | every):
        row = (expected.get(t, 0), bricks.get(t, 0), index.get(t, 0))
        same = row[0] == row[1] == row[2] and (t in expected or t not in every)
        types_ok &= same
        print("%-6d %-36s %10d %10d %12d%s" % ((t, type_name(t)) + row +
                                               ("" if same else "   MISMATCH",)))
    print("%s vs %s (%d bricks): cell types %s; brick cell checks %s" %
          (mesh, folder, len(manifest["bricks"]), "kept" if types_ok else "DIFFER",
           "passed" if cells_ok else "found problems (compare with the input's)"))
    return types_ok and cells_ok


def main():
    args = sys.argv[1:]
    if args[:1] == ["--types"]:
        if len(args) != 3:
            sys.exit("usage: check_vtu_with_vtk.py --types INPUT PARTITION_DIR")
        ok = compare_types(args[1], args[2])
    else:
        if not args:
            sys.exit(__doc__)
        ok = all([check(path) for path in args])
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()

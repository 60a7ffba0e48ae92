#!/usr/bin/python3
"""Writes tests/data/gmsh_partitioned_{binary,ascii}.msh (+ gmsh_partitioned.json) with
gmsh's own writer (Debian's python3-gmsh, gmsh 4.8; run with /usr/bin/python3): reference
files for tests/io/test_gmsh.cpp that exercise what the hand-written test files do not -
MSH 4.1 files as gmsh writes them, binary and ASCII, split into 3 partitions ($PartitionedEntities, node and
element blocks per partitioned entity, $Periodic-free), of quadratic tetrahedra (type 11)
with the lower-dimensional elements gmsh adds, and a binary $NodeData 'analytic' =
sin(3x) cos(2y) + 0.5 sin(4z + xy) at every node.

The .json records what gmsh's API reports for the mesh: the number of nodes and
of elements of each type, and the coordinates of the node with the smallest tag.

Usage: /usr/bin/python3 scripts/gen_gmsh_fixtures.py [OUTPUT_DIR]
"""
import json
import math
import os
import sys

import gmsh


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "..", "tests", "data")
    gmsh.initialize()
    gmsh.option.setNumber("General.Verbosity", 1)
    gmsh.model.add("partitioned")
    gmsh.model.occ.addBox(0, 0, 0, 1, 1, 0.5)
    gmsh.model.occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMin", 0.5)
    gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5)
    gmsh.model.mesh.generate(3)
    gmsh.model.mesh.setOrder(2)
    gmsh.model.mesh.partition(3)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    values = [[math.sin(3 * coords[3 * i]) * math.cos(2 * coords[3 * i + 1]) +
               0.5 * math.sin(4 * coords[3 * i + 2] + coords[3 * i] * coords[3 * i + 1])]
              for i in range(len(tags))]
    view = gmsh.view.add("analytic")
    gmsh.view.addModelData(view, 0, "partitioned", "NodeData", list(tags), values)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.option.setNumber("PostProcessing.SaveMesh", 0)
    for binary in (1, 0):
        msh = os.path.join(out, "gmsh_partitioned_%s.msh" % ("binary" if binary else "ascii"))
        gmsh.option.setNumber("Mesh.Binary", binary)
        gmsh.write(msh)
        gmsh.view.write(view, msh, append=True)
    counts = {}
    for dim in range(4):
        types, elements, _ = gmsh.model.mesh.getElements(dim)
        for t, e in zip(types, elements):
            counts[str(int(t))] = counts.get(str(int(t)), 0) + len(e)
    first = min(range(len(tags)), key=lambda i: tags[i])
    info = {"generator": "gmsh " + gmsh.__version__, "nodes": len(set(tags)),
            "elements_by_type": counts, "partitions": 3,
            "first_node": {"tag": int(tags[first]),
                           "xyz": [coords[3 * first + k] for k in range(3)]}}
    gmsh.finalize()
    with open(os.path.join(out, "gmsh_partitioned.json"), "w") as f:
        json.dump(info, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()

#!/usr/bin/python3
"""Writes tests/data/gmsh_reference_nodes.json: gmsh's own reference coordinates of the
nodes of every 3-D element type hpray reads, in gmsh's node order, as reported by gmsh's
API (gmsh.model.mesh.getElementProperties). Needs Debian's python3-gmsh (gmsh 4.8).

Prisms of order >= 3 (types 90, 91, 106-110) are absent: gmsh 4.8 cannot build them.

Usage: /usr/bin/python3 scripts/gen_gmsh_reference_nodes.py [OUTPUT]
"""
import json
import os
import sys

import gmsh

TYPES = [4, 11, 29, 30, 31, 71, 72, 73, 74, 75,          # tetrahedra, orders 1..10
         5, 12, 92, 93, 94, 95, 96, 97, 98, 17,          # hexahedra 1..9, 20-node
         6, 13, 18,                                      # prisms 1, 2, 15-node
         7, 14, 118, 119, 120, 121, 122, 123, 124, 19]   # pyramids 1..9, 13-node


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        here, "..", "tests", "data", "gmsh_reference_nodes.json")
    gmsh.initialize()
    gmsh.option.setNumber("General.Verbosity", 0)
    result = {"generator": "gmsh " + gmsh.__version__ +
              " getElementProperties (localNodeCoord)", "element_types": {}}
    for t in TYPES:
        name, dim, order, count, coords, _ = gmsh.model.mesh.getElementProperties(t)
        assert dim == 3 and len(coords) == 3 * count
        result["element_types"][str(t)] = {
            "name": name, "order": order, "nodes_per_element": count,
            "coords": [float(c) for c in coords]}
    gmsh.finalize()
    with open(out, "w") as f:
        json.dump(result, f, separators=(",", ":"))
        f.write("\n")


if __name__ == "__main__":
    main()

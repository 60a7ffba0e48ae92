// Gmsh MSH element types: node counts, the 3-D types hpray reads, gmsh's reference node
// coordinates in gmsh's node order, and the permutation to the internal node order.
//
// Gmsh reference cells (gmsh's MElement getNode):
//   tetrahedron  unit simplex, vertices (0,0,0) (1,0,0) (0,1,0) (0,0,1)
//   hexahedron   [-1,1]^3, vertices in VTK_HEXAHEDRON order
//   prism        unit triangle x [-1,1], vertices (0,0,-1) (1,0,-1) (0,1,-1), then z = 1
//   pyramid      base [-1,1]^2 at z = 0 (counter-clockwise from (-1,-1)), apex (0,0,1)
// Each maps affinely onto the internal reference cell of mesh/cell.h (GmshRefToInternal),
// and the order-p gmsh nodes onto the internal order-p lattice.
//
// Gmsh's high-order node order is recursive: vertices; the interior nodes of each edge
// (gmsh's edge list, from its first to its second vertex); the interior nodes of each
// face (gmsh's face list and orientation, each face numbered like a lower-order triangle
// or quadrangle); then the interior nodes, numbered as a lower-order element of the same
// kind (prisms of order >= 3: a triangle x line product instead).
#pragma once

#include <array>
#include <optional>
#include <vector>

#include "mesh/cell.h"

namespace hpray {

/// Gmsh type ids of the 3-D elements hpray reads (GmshDefines.h MSH_*).
enum GmshType : int {
    kGmshTet4 = 4,
    kGmshHex8 = 5,
    kGmshPrism6 = 6,
    kGmshPyramid5 = 7,
    kGmshTet10 = 11,
    kGmshHex27 = 12,
    kGmshPrism18 = 13,
    kGmshPyramid14 = 14,
    kGmshHex20 = 17,
    kGmshPrism15 = 18,
    kGmshPyramid13 = 19,
    kGmshTet20 = 29,
    kGmshHex64 = 92,
    kGmshPrism40 = 90,
    kGmshPyramid30 = 118,
};

/// A gmsh 3-D element type that hpray reads.
struct GmshCellType {
    int type = 0;  ///< gmsh element type id
    CellShape shape = CellShape::Tet;
    int order = 1;
    CellFamily family = CellFamily::Lagrange;  ///< Serendipity for types 17, 18, 19
    int nodeCount = 0;
};

/// Number of nodes of any fixed-size gmsh element type (all dimensions, ids 1..140), or
/// -1 for an unknown id or a type without a fixed node count (polygons, polyhedra).
int GmshTypeNodeCount(int type);
/// Dimension (0..3) of a gmsh element type, or -1 for an unknown id.
int GmshTypeDimension(int type);

/// The shape, order and family of a 3-D gmsh type hpray reads: complete tetrahedra of
/// orders 1..10, complete hexahedra, prisms and pyramids of orders 1..9, and the
/// serendipity hex20, prism15 and pyramid13. std::nullopt for any other type (including
/// incomplete and order-0 3-D types).
std::optional<GmshCellType> ClassifyGmshType(int type);

/// Internal lattice indices (mesh/cell.h, order = the type's order) of the nodes of a
/// type accepted by ClassifyGmshType, in gmsh's node order. Cached; thread-safe. Throws
/// InternalError for other types.
const std::vector<LatticeIndex>& GmshNodeLattice(int type);

/// The faces as gmsh's node numbering walks them (its order of faces and the corner each
/// starts from), as cycles of corner lattice positions of order 1 in the internal frame.
/// They are the faces of mesh/cell.h Topology(shape), with the same orientation; a test
/// checks that.
std::vector<std::vector<LatticeIndex>> GmshFaceCorners(CellShape shape);

/// Gmsh's reference coordinates of the nodes, in gmsh's node order and gmsh's reference
/// cell (see the file comment), computed as gmsh computes them.
std::vector<std::array<double, 3>> GmshReferenceCoords(int type);

/// `perm` with internal[k] = file[perm[k]] for a cell of this type. Cached; thread-safe.
const std::vector<int>& GmshToInternal(int type);

/// Maps a point of gmsh's reference cell of `shape` to the internal reference cell
/// (affine; identity for tetrahedra).
std::array<double, 3> GmshRefToInternal(CellShape shape, const std::array<double, 3>& x);

}  // namespace hpray

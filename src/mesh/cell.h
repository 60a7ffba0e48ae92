// Cell shapes, orders and the one internal node ordering every reader converts to.
//
// Internal reference domains (also the `ref` coordinates `hpray probe` reports):
//   Tet      {r, s, t >= 0, r + s + t <= 1}, vertices (0,0,0) (1,0,0) (0,1,0) (0,0,1)
//   Hex      [0,1]^3
//   Wedge    triangle {r, s >= 0, r + s <= 1} x t in [0,1]
//   Pyramid  base [0,1]^2 at t = 0, apex (1/2, 1/2, 1); the square at height t is
//            [t/2, 1 - t/2]^2
//
// Internal node ordering: a cell of order p places its nodes on the order-p lattice of its
// shape, node (i, j, k) at
//   Tet, Hex, Wedge: (i, j, k) / p
//   Pyramid:         (i + k/2, j + k/2, k) / p
// with the lattice
//   Tet      i, j, k >= 0, i + j + k <= p
//   Hex      0 <= i, j, k <= p
//   Wedge    i, j >= 0, i + j <= p, 0 <= k <= p
//   Pyramid  0 <= k <= p, 0 <= i, j <= p - k
// Nodes are stored sorted by (k, j, i) lexicographically, i fastest. Serendipity cells
// (20-node hex, 15-node wedge, 13-node pyramid) keep the subset of the order-2 lattice they
// use (vertices and edge midpoints), in the same sorted order.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace hpray {

enum class CellShape : std::uint8_t { Tet = 0, Hex = 1, Wedge = 2, Pyramid = 3 };
inline constexpr int kNumCellShapes = 4;

/// Lagrange: the full order-p lattice. Serendipity: vertices and edge midpoints, order 2.
enum class CellFamily : std::uint8_t { Lagrange = 0, Serendipity = 1 };

inline constexpr int kMaxOrder = 10;

using LatticeIndex = std::array<int, 3>;

/// "tet", "hex", "wedge", "pyramid".
const char* ShapeName(CellShape shape);
/// Number of vertices of the linear shape (4, 8, 6, 5).
int VertexCount(CellShape shape);

/// Number of nodes of a cell of this shape, order and family.
int NodeCount(CellShape shape, int order, CellFamily family = CellFamily::Lagrange);

/// The lattice indices of the nodes, in internal order. Cached; thread-safe.
/// Throws InternalError for an unsupported (shape, order, family).
const std::vector<LatticeIndex>& LatticeNodes(CellShape shape, int order,
                                              CellFamily family = CellFamily::Lagrange);

/// Position in internal order of the node with lattice index `ijk`, or -1 if the cell has
/// no such node. O(1) for Hex, O(log n) otherwise.
int InternalNodeIndex(CellShape shape, int order, CellFamily family, const LatticeIndex& ijk);

/// Reference coordinates of a lattice node (see the file comment).
std::array<double, 3> LatticeRefCoords(CellShape shape, int order, const LatticeIndex& ijk);

/// The corners and faces of a reference cell, the one table every part uses (traversal,
/// cost model; the gmsh node numbering is checked against it). Corners are lattice
/// positions in units of the order (the internal node frame above), in the order of the
/// internal corner nodes; each face is a cycle of corners, counter-clockwise seen from
/// outside a positively oriented cell.
struct CellTopology {
    int corners;
    int lattice[8][3];
    int faces;
    int faceSize[6];
    int face[6][4];
};
const CellTopology& Topology(CellShape shape);

/// Lattice indices of the linear vertices in the VTK linear vertex order
/// (VTK_TETRA, VTK_HEXAHEDRON, VTK_LAGRANGE_WEDGE winding, VTK_PYRAMID), scaled to order p.
/// Wedge: (0,0,0) (p,0,0) (0,p,0) then the same at k = p.
std::vector<LatticeIndex> VertexLattice(CellShape shape, int order);

}  // namespace hpray

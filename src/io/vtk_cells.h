// VTK cell types: classification into (shape, order, family) and node-order conversion.
//
// Node orders (VTK node n of a cell; "lattice" is the internal lattice of mesh/cell.h):
//   10, 24, 71  VTK tetrahedra; VTK's reference tet is the internal one (identity).
//   12, 25, 29, 72  VTK hexahedra; VTK's [0,1]^3 is the internal one (identity).
//   73  VTK_LAGRANGE_WEDGE: VTK's reference wedge is the internal one (identity). A
//       geometrically valid cell has a positive Jacobian in VTK's parameters.
//   13, 26, 32  VTK_WEDGE, VTK_QUADRATIC_WEDGE, VTK_BIQUADRATIC_QUADRATIC_WEDGE wind the
//       first triangle the other way: vtkCell::GetFace of all three returns the faces of
//       vtkWedge ((0,1,2), (3,5,4), (0,3,4,1), ...), which point outward only when the
//       parametric Jacobian is negative. They are read with VTK's r and s exchanged
//       (internal (r, s, t) = VTK (s, r, t)), so a valid file cell becomes a positively
//       oriented internal cell. (VTK 9.1's vtkCellValidator hard-codes the opposite
//       expectation for 26 and 32 "for backwards compatibility", and gmsh writes 26/32
//       without the swap it applies to 13; such files come out inverted; a reader that
//       finds a negative Jacobian can fix the cell with InternalReflection.)
//   14, 27  VTK pyramids. VTK's parameters (r, s, t) are those of a collapsed hexahedron:
//       internal (x, y, z) = ((1 - t) r + t/2, (1 - t) s + t/2, t); VTK lists the apex
//       at (0, 0, 1).
//   74  VTK_LAGRANGE_PYRAMID. VTK defines no node order for it (VTK 9.1 has no class), so
//       hpray uses this one, in the style of the other VTK Lagrange cells (vertices,
//       edges, faces, interior), of the full order-p pyramid lattice,
//       (p+1)(p+2)(2p+3)/6 nodes; lattice (i, j, k) as in mesh/cell.h:
//       1. the 5 vertices in VTK_PYRAMID order: (0,0,0) (p,0,0) (p,p,0) (0,p,0), then
//          the apex (0,0,p);
//       2. p-1 nodes per edge, edges in VTK_QUADRATIC_PYRAMID order: base edges 0-1 (i
//          increasing), 1-2 (j increasing), 3-2 (i increasing), 0-3 (j increasing), so
//          the base is numbered like a VTK Lagrange quadrilateral; then the lateral edges
//          0-4, 1-4, 2-4, 3-4, each from its base vertex to the apex;
//       3. face-interior nodes: first the base (k = 0), 1 <= i, j <= p-1, i fastest; then
//          the triangles 0-1-4 (j = 0), 1-2-4 (i = p-k), 2-3-4 (j = p-k), 3-0-4 (i = 0),
//          each by level k = 1..p-2 (slowest) and along the base-parallel lattice axis
//          (i for the first and third, j for the others) increasing;
//       4. interior nodes (k >= 1, 1 <= i, j <= p-k-1) sorted by (k, j, i), i fastest.
//       Order 1 is VTK_PYRAMID; at order 2 the first 13 nodes are VTK_QUADRATIC_PYRAMID's
//       and node 13 is the base centre. VtkParametricCoords reports 74 in VTK's pyramid
//       parameters (as 14 and 27).
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

#include "mesh/cell.h"

namespace hpray {

struct CellKind {
    CellShape shape = CellShape::Tet;
    int order = 1;
    CellFamily family = CellFamily::Lagrange;
};

/// VTK cell type ids hpray reads (vtkCellType.h).
enum VtkCellType : int {
    kVtkTetra = 10,
    /// Read as a linear hexahedron: its node order (i fastest) is the internal one.
    kVtkVoxel = 11,
    kVtkHexahedron = 12,
    kVtkWedge = 13,
    kVtkPyramid = 14,
    kVtkQuadraticTetra = 24,
    kVtkQuadraticHexahedron = 25,
    kVtkQuadraticWedge = 26,
    kVtkQuadraticPyramid = 27,
    kVtkTriquadraticHexahedron = 29,
    kVtkBiquadraticQuadraticWedge = 32,
    kVtkLagrangeTetrahedron = 71,
    kVtkLagrangeHexahedron = 72,
    kVtkLagrangeWedge = 73,
    kVtkLagrangePyramid = 74,
};

/// Classifies a 3-D VTK cell from its type and node count. `degrees` (VTK's
/// HigherOrderDegrees for this cell, 3 values) is used for Lagrange types when given
/// (non-null); anisotropic degrees are rejected. Returns std::nullopt when the type is
/// not a supported 3-D cell or the node count does not fit it; `why` then says which. 24
/// -> Lagrange tet order 2; 25/26/27 -> serendipity hex/wedge/pyramid order 2; 29 ->
/// Lagrange hex order 2; 32 -> Lagrange wedge order 2; 71-74 -> Lagrange, order
/// 1..kMaxOrder from the node count (or the degrees).
std::optional<CellKind> ClassifyVtkCell(int vtkType, long long nodeCount,
                                        const int* degrees, std::string* why = nullptr);

/// `perm` with internal[k] = file[perm[k]] for a cell of VTK type `vtkType` and kind
/// `kind` (a pair ClassifyVtkCell returns; anything else is an InternalError).
/// `legacyLagrangeHex`: the file predates VTK 9's VTK_LAGRANGE_HEXAHEDRON order (see
/// VtkXmlHasLegacyLagrangeHex), whose node blocks of edges 10 and 11 (p-1 nodes each,
/// starting at 8+10(p-1) and 8+11(p-1)) are swapped; ignored for other types.
/// Cached; thread-safe; the reference stays valid for the life of the program.
const std::vector<int>& VtkToInternal(int vtkType, const CellKind& kind,
                                      bool legacyLagrangeHex = false);

/// The VTK type hpray writes for a cell kind of no known source type: 71-74 for
/// Lagrange, 25/26/27 for serendipity; and the inverse permutation file[k] =
/// internal[perm[k]].
int VtkTypeFor(const CellKind& kind);
const std::vector<int>& InternalToVtk(const CellKind& kind);

/// Whether a cell of `kind` can be stored as VTK type `vtkType`: a pair ClassifyVtkCell
/// returns, or VTK_VOXEL (11) for a linear hexahedron.
bool VtkTypeHolds(int vtkType, const CellKind& kind);

/// The VTK type a converter would choose for `kind` when the source format has no VTK
/// type (gmsh): the fixed-node type VTK has for it (10, 12, 13, 14; 24, 29 for quadratic
/// Lagrange tet and hex; 25, 26, 27 for serendipity), else the Lagrange type 71-74 (VTK
/// has no fixed type for the 14-node pyramid or for order 3 and up). The 18-node wedge
/// goes to 73, not 32: VTK 9.1's cell-size and validity filters give type 32 negative
/// volumes for cells its own face lists call positive, and 73 reads the same nodes.
int FixedVtkTypeFor(const CellKind& kind);

/// The VTK type WriteVtu stores a cell of `kind` as, given the type it was read with
/// (`sourceType`, 0 = unknown): `sourceType` itself when VtkTypeHolds, so a file read and
/// written again keeps its cell types; otherwise linear Lagrange cells as 10, 12, 13, 14
/// (the types every VTK reader knows) and other kinds as VtkTypeFor(kind).
int VtkTypeToWrite(const CellKind& kind, int sourceType);

/// Whether cells of VTK type `vtkType` need VTK's HigherOrderDegrees (the Lagrange types
/// 71-74; VTK derives the order of the others from the type).
inline bool VtkTypeNeedsDegrees(int vtkType) {
    return vtkType >= kVtkLagrangeTetrahedron && vtkType <= kVtkLagrangePyramid;
}

/// `perm` with file[k] = internal[perm[k]] for a cell of `kind` written as VTK type
/// `vtkType` (VtkTypeHolds must be true, else InternalError): the inverse of
/// VtkToInternal(vtkType, kind) in VTK 9 order, so reading the file back gives the same
/// internal cell, whatever winding the type has (13, 26 and 32 exchange r and s); the
/// identity for VTK_VOXEL. Cached; thread-safe.
const std::vector<int>& InternalToVtk(int vtkType, const CellKind& kind);

/// VTK's parametric coordinates of node n of a cell of this type and kind, in VTK's own
/// reference cell (for tests that compare with VTK's GetParametricCoords).
std::vector<std::array<double, 3>> VtkParametricCoords(int vtkType, const CellKind& kind);

/// The mirror image of a cell in internal order: reflected[k] = internal[m[k]] exchanges
/// the lattice indices i and j (a reflection that keeps the reference domain, turning a
/// negatively oriented cell into a positively oriented one). An involution. Cached.
const std::vector<int>& InternalReflection(const CellKind& kind);

/// Whether VTK reads VTK_LAGRANGE_HEXAHEDRON of a file of this version in the pre-VTK-9
/// order (pass legacyLagrangeHex = true then). VTK 9.1's readers: XML (.vtu) version
/// below 2.1; legacy .vtk "DataFile Version" below 5.1.
bool VtkXmlHasLegacyLagrangeHex(int major, int minor);
bool VtkLegacyHasLegacyLagrangeHex(int major, int minor);

}  // namespace hpray

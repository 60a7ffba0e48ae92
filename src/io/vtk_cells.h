// VTK cell types: classification into (shape, order, family) and node-order conversion.
#pragma once

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
    kVtkTetra = 10, kVtkHexahedron = 12, kVtkWedge = 13, kVtkPyramid = 14,
    kVtkQuadraticTetra = 24, kVtkQuadraticHexahedron = 25, kVtkQuadraticWedge = 26,
    kVtkQuadraticPyramid = 27, kVtkTriquadraticHexahedron = 29,
    kVtkBiquadraticQuadraticWedge = 32,
    kVtkLagrangeTetrahedron = 71, kVtkLagrangeHexahedron = 72, kVtkLagrangeWedge = 73,
    kVtkLagrangePyramid = 74,
};

/// Classifies a 3-D VTK cell from its type and node count. `degrees` (VTK's
/// HigherOrderDegrees for this cell, 3 values) is used for Lagrange types when given
/// (non-null); anisotropic degrees are rejected. Returns std::nullopt when the type is not
/// a supported 3-D cell or the node count does not fit it; `why` then says which.
std::optional<CellKind> ClassifyVtkCell(int vtkType, long long nodeCount, const int* degrees,
                                        std::string* why = nullptr);

/// `perm` with internal[k] = file[perm[k]] for a cell of VTK type `vtkType` and kind `kind`.
/// `legacyLagrangeHex`: the file's version is below 2.2, so VTK_LAGRANGE_HEXAHEDRON edge
/// node blocks 10 and 11 are swapped (pre-VTK-9 order; see ../shared/data/README.md).
/// Cached; thread-safe.
const std::vector<int>& VtkToInternal(int vtkType, const CellKind& kind,
                                      bool legacyLagrangeHex = false);

/// The VTK type hpray writes for a cell kind: 71-74 for Lagrange, 25/26/27 for
/// serendipity; and the inverse permutation file[k] = internal[perm[k]].
int VtkTypeFor(const CellKind& kind);
const std::vector<int>& InternalToVtk(const CellKind& kind);

/// VTK's parametric coordinates of node n of a cell of this type and kind, in VTK's own
/// reference cell (for tests that compare with VTK's GetParametricCoords).
std::vector<std::array<double, 3>> VtkParametricCoords(int vtkType, const CellKind& kind);

}  // namespace hpray

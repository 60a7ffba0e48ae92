// Per-cell geometry of a whole mesh, computed once: gathered node coordinates, the
// classified CellGeometry (affine or curved, Newton start) and the guaranteed box.
#pragma once

#include <cstdint>
#include <vector>

#include "elements/bounds.h"
#include "elements/geometry.h"
#include "mesh/mesh.h"

namespace hpray {

/// Room for the geometry of one cell derived on request (MeshGeometry::Cell): its
/// CellGeometry and the node coordinates that CellGeometry::nodes points to.
struct CellScratch {
    CellGeometry geometry;
    double xyz[3 * 4] = {};
};

/// Geometry of every cell of a mesh. Linear tetrahedra (the bulk of large unstructured
/// meshes) keep nothing: their four corners are the mesh's points, and their CellGeometry
/// (the same MakeCellGeometry of the same coordinates, so bitwise the same numbers) and
/// box are derived when asked, which costs less than reading 400 stored bytes per cell.
/// Every other cell keeps its gathered node coordinates, CellGeometry and box. Stored
/// cells' `nodes` point into this object's buffers: it is move-only (moving keeps them).
class MeshGeometry {
  public:
    MeshGeometry() = default;
    MeshGeometry(MeshGeometry&&) = default;
    MeshGeometry& operator=(MeshGeometry&&) = default;
    MeshGeometry(const MeshGeometry&) = delete;
    MeshGeometry& operator=(const MeshGeometry&) = delete;

    /// Builds the geometry of every cell (parallel over cells). The mesh is borrowed: it
    /// must outlive this object and not change.
    static MeshGeometry Build(const Mesh& mesh);

    /// The geometry of cell c: a stored one, or one derived into `scratch` (then valid
    /// until `scratch` is reused). Thread-safe with a scratch per thread.
    const CellGeometry& Cell(std::int64_t c, CellScratch& scratch) const {
        const std::int64_t k = stored_.empty() ? (allStored_ ? c : -1) : stored_[c];
        return k >= 0 ? cells_[k] : Derive(c, scratch);
    }
    /// True when cell c is a linear tetrahedron whose geometry is derived on request.
    bool IsDerived(std::int64_t c) const {
        return stored_.empty() ? !allStored_ : stored_[c] < 0;
    }
    /// The basis of cell c.
    const BasisTable& Basis(std::int64_t c) const;
    /// A guaranteed world box of cell c (Bernstein hull of its nodes).
    Box CellBox(std::int64_t c) const;

    Box bounds;  ///< union of the cells' boxes
    /// Cells whose map is affine (CellGeometry::affine); derives every linear
    /// tetrahedron's geometry to tell (a pass over the mesh: for reports, not rendering).
    std::int64_t AffineCells() const;
    std::int64_t derivedCells = 0;  ///< linear tetrahedra, derived on request
    std::int64_t reducedMapCells = 0;  ///< curved hexahedra mapped at a lower order

    /// Bytes held per the whole mesh.
    std::size_t Bytes() const;

  private:
    const CellGeometry& Derive(std::int64_t c, CellScratch& scratch) const;

    const Mesh* mesh_ = nullptr;
    std::int64_t storedAffine_ = 0;    ///< stored cells with an affine map
    std::vector<double> nodeXyz_;      ///< x y z per node of each stored cell
    std::vector<CellGeometry> cells_;  ///< stored cells
    std::vector<Box> boxes_;           ///< stored cells' boxes
    /// Stored cells' reduced map nodes (CellGeometry::mapNodes), empty where none.
    std::vector<std::vector<double>> mapNodes_;
    /// Cell -> index in cells_, -1 for derived cells; empty when every cell is stored
    /// (allStored_: index = cell) or none is.
    std::vector<std::int64_t> stored_;
    bool allStored_ = false;
};

/// The nodal values of point-field component `component` (-1: magnitude) of cell c,
/// gathered in internal node order into `out` (resized).
void GatherCellValues(const Mesh& mesh, const Field& field, int component, std::int64_t c,
                      std::vector<double>& out);

/// Finds the cell containing a world point: a uniform grid over the cells' guaranteed
/// boxes, then inversion in each candidate. Thread-safe queries.
class PointLocator {
public:
    PointLocator(const Mesh& mesh, const MeshGeometry& geometry);

    struct Hit {
        std::int64_t cell = -1;  ///< -1: outside the mesh
        std::array<double, 3> ref{};
        int inversions = 0;      ///< inversions tried
        int failures = 0;        ///< inversions that neither converged nor left the cell
    };
    /// Among the cells whose reference point lies within `options.insideTolerance` of
    /// their reference cell, the one with the smallest outside distance (ties: lowest
    /// index), so points on shared faces get one deterministic cell.
    Hit Locate(const double world[3], EvalWorkspace& ws,
               const InversionOptions& options = {}) const;

private:
    const MeshGeometry& geometry_;
    std::vector<Box> boxes_;  ///< of every cell
    std::array<double, 3> lo_{}, cellSize_{};
    std::array<int, 3> dims_{1, 1, 1};
    std::vector<std::int64_t> start_;  ///< CSR over grid cells
    std::vector<std::int64_t> items_;
};

}  // namespace hpray

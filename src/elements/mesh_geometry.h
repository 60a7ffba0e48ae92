// Per-cell geometry of a whole mesh, computed once: gathered node coordinates, the
// classified CellGeometry (affine or curved, Newton start) and the guaranteed box.
#pragma once

#include <cstdint>
#include <vector>

#include "elements/bounds.h"
#include "elements/geometry.h"
#include "mesh/mesh.h"

namespace hpray {

/// Geometry of every cell of a mesh. `cells[c].nodes` points into `nodeXyz`, so the
/// object must not be copied after Build (it is move-only; moving keeps the buffers).
struct MeshGeometry {
    std::vector<double> nodeXyz;         ///< x y z per node of each cell, cell by cell
    std::vector<std::int64_t> offsets;   ///< cell c's nodes start at nodeXyz[3 * offsets[c]]
    std::vector<CellGeometry> cells;
    std::vector<Box> boxes;             ///< guaranteed world boxes (Bernstein hull)
    Box bounds;                         ///< union of the boxes
    std::int64_t affineCells = 0;

    MeshGeometry() = default;
    MeshGeometry(MeshGeometry&&) = default;
    MeshGeometry& operator=(MeshGeometry&&) = default;
    MeshGeometry(const MeshGeometry&) = delete;
    MeshGeometry& operator=(const MeshGeometry&) = delete;

    /// Builds the geometry of every cell (parallel over cells).
    static MeshGeometry Build(const Mesh& mesh);
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
    std::array<double, 3> lo_{}, cellSize_{};
    std::array<int, 3> dims_{1, 1, 1};
    std::vector<std::int64_t> start_;  ///< CSR over grid cells
    std::vector<std::int64_t> items_;
};

}  // namespace hpray

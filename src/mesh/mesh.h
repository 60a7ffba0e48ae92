// The unstructured, mixed-element, mixed-order mesh model: flat arrays with offsets.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "geom/box.h"
#include "mesh/cell.h"

namespace hpray {

enum class Association : std::uint8_t { Point = 0, Cell = 1 };

/// A field: `components` interleaved values per point or per cell, in double precision.
struct Field {
    std::string name;
    Association association = Association::Point;
    int components = 1;
    std::vector<double> values;  ///< size components * (points or cells)

    /// [min, max] of one component (component == -1: of the Euclidean magnitude).
    /// Returns {+inf, -inf} for an empty field.
    std::array<double, 2> Range(int component = 0) const;
};

/// A mixed-element mesh. Nodes of each cell are in the internal order of mesh/cell.h.
/// Invariants (checked by Validate): cellOffsets.size() == cells + 1, starts at 0, each
/// cell has NodeCount(shape, order, family) nodes, connectivity indexes points, point
/// fields have points * components values, cell fields cells * components.
struct Mesh {
    std::vector<double> points;              ///< x, y, z interleaved, world units
    std::vector<std::int64_t> cellOffsets{0};  ///< into connectivity; size cells + 1
    std::vector<std::int64_t> connectivity;  ///< point indices, internal node order
    std::vector<CellShape> cellShape;
    std::vector<std::uint8_t> cellOrder;
    std::vector<CellFamily> cellFamily;
    std::vector<Field> pointFields;
    std::vector<Field> cellFields;
    /// Optional per-cell ghost flags (VTK vtkGhostType; 1 = duplicate cell); empty = none.
    std::vector<std::uint8_t> ghost;
    /// Optional per-cell VTK cell type the cell was read as (io/vtk_cells.h; for gmsh
    /// input the type a converter would choose), so a writer can keep the input's types;
    /// 0 or an empty array = unknown (meshes built in memory). One byte per cell: every
    /// 3-D VTK type id is below 256. Like `ghost`, AddCell leaves it alone.
    std::vector<std::uint8_t> vtkType;

    std::int64_t PointCount() const { return static_cast<std::int64_t>(points.size() / 3); }
    std::int64_t CellCount() const { return static_cast<std::int64_t>(cellShape.size()); }

    /// Appends a cell whose `nodes` are already in internal order.
    void AddCell(CellShape shape, int order, CellFamily family, const std::int64_t* nodes,
                 int count);

    /// Points of cell c (internal order): [begin, end) into connectivity.
    const std::int64_t* CellNodes(std::int64_t c) const {
        return connectivity.data() + cellOffsets[c];
    }
    int CellNodeCount(std::int64_t c) const {
        return static_cast<int>(cellOffsets[c + 1] - cellOffsets[c]);
    }

    const Field* FindPointField(const std::string& name) const;
    const Field* FindCellField(const std::string& name) const;
    /// Point field first, then cell field; nullptr if neither.
    const Field* FindField(const std::string& name) const;

    /// Axis-aligned bounds of the points: {{xmin,ymin,zmin},{xmax,ymax,zmax}}.
    Box Bounds() const;

    /// Bytes held by the arrays (for `hpray info`).
    std::size_t MemoryBytes() const;

    /// Throws InputError(source, ...) describing the first broken invariant, including
    /// out-of-range connectivity and NaN/Inf in points or fields.
    void Validate(const std::string& source) const;
};

/// A scalar view of a (possibly vector) field selected by name: "u" (a scalar field, or the
/// magnitude of a vector field), "u.x"/"u.y"/"u.z" or "u[i]" for one component,
/// "u.magnitude" for the magnitude.
struct ScalarSelector {
    const Field* field = nullptr;
    int component = 0;  ///< -1: magnitude
};
/// Resolves a scalar name; std::nullopt if no field matches.
std::optional<ScalarSelector> SelectScalar(const Mesh& mesh, const std::string& name);

/// The value of a selected scalar at entry `index` (a point or a cell index).
inline double ScalarValue(const ScalarSelector& s, std::int64_t index) {
    const double* v = s.field->values.data() + index * s.field->components;
    if (s.component >= 0) return v[s.component];
    double sum = 0;
    for (int c = 0; c < s.field->components; ++c) sum += v[c] * v[c];
    return std::sqrt(sum);
}

}  // namespace hpray

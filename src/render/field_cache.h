// Per-field preparation of one mesh, kept across scenes (see FieldCache).
#pragma once

#include <map>
#include <memory>
#include <utility>
#include <vector>

#include "elements/bounds.h"
#include "elements/field.h"
#include "elements/mesh_geometry.h"
#include "render/ray_field.h"

namespace hpray {

/// What a field needs before rays can use it, computed once per field of a mesh and
/// shared by every scene set up on that mesh: a scene that changes an isovalue, a
/// transfer function or the camera reuses it; a field used for the first time computes
/// its own. Not thread-safe (used while setting a scene up; each build is parallel).
class FieldCache {
  public:
    /// The mesh and geometry are borrowed and must outlive the cache.
    FieldCache(const Mesh& mesh, const MeshGeometry& geometry)
        : mesh_(&mesh), geometry_(&geometry) {}

    /// The guaranteed range of the field over each cell (Bernstein hull of its nodal
    /// values; a cell field's value).
    std::shared_ptr<const std::vector<Interval>> Ranges(const ScalarSelector& field);
    /// The field's nodal values gathered per cell and its derivative bounds (ray_field.h).
    std::shared_ptr<const FieldCellData> Data(const ScalarSelector& field);
    /// The field's sub-cell bounds (ray_field.h), for the fields isosurfaces use, with
    /// the boxes of the cells with need[c] != 0 computed (those of earlier calls kept).
    std::shared_ptr<const SubCellBounds> SubBounds(const ScalarSelector& field,
                                                   const std::vector<std::uint8_t>& need);

    /// Per cell, for the linear tetrahedra (derived geometry) of a point field with
    /// per-point values (FieldCellData::PointValues), a bound of the field's gradient
    /// norm (VolumeSetup::gradientBound; NaN elsewhere); empty when the field has no
    /// per-point values or the mesh no such cells.
    std::shared_ptr<const std::vector<float>> GradientBounds(const ScalarSelector& field);

    /// How many ranges, data sets and gradient bounds were computed (not reused) so far.
    int RangesBuilt() const { return rangesBuilt_; }
    int DataBuilt() const { return dataBuilt_; }
    int GradientBoundsBuilt() const { return gradientBoundsBuilt_; }

  private:
    using Key = std::pair<const Field*, int>;
    const Mesh* mesh_;
    const MeshGeometry* geometry_;
    std::map<Key, std::shared_ptr<const std::vector<Interval>>> ranges_;
    std::map<Key, std::shared_ptr<const FieldCellData>> data_;
    std::map<Key, std::shared_ptr<SubCellBounds>> subBounds_;
    std::map<Key, std::shared_ptr<const std::vector<float>>> gradientBounds_;
    int rangesBuilt_ = 0, dataBuilt_ = 0, gradientBoundsBuilt_ = 0;
};

}  // namespace hpray

// FieldCache: per-field ranges and cell data built once per mesh.
#include "render/field_cache.h"

#include <tbb/parallel_for.h>

#include <limits>

#include "render/volume_ray.h"

namespace hpray {

std::shared_ptr<const std::vector<Interval>> FieldCache::Ranges(const ScalarSelector& sel) {
    const Key key{sel.field, sel.component};
    if (const auto it = ranges_.find(key); it != ranges_.end()) return it->second;
    const std::int64_t cells = mesh_->CellCount();
    auto ranges = std::make_shared<std::vector<Interval>>(cells);
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, cells, 512),
                      [&](const tbb::blocked_range<std::int64_t>& range) {
                          std::vector<double> nodal;
                          for (std::int64_t c = range.begin(); c < range.end(); ++c) {
                              if (sel.field->association == Association::Cell) {
                                  const double v = ScalarValue(sel, c);
                                  (*ranges)[c] = {v, v};
                                  continue;
                              }
                              GatherCellValues(*mesh_, *sel.field, sel.component, c, nodal);
                              (*ranges)[c] =
                                  FieldBounds(geometry_->Basis(c), nodal.data());
                          }
                      });
    ++rangesBuilt_;
    ranges_[key] = ranges;
    return ranges;
}

std::shared_ptr<const FieldCellData> FieldCache::Data(const ScalarSelector& sel) {
    const Key key{sel.field, sel.component};
    if (const auto it = data_.find(key); it != data_.end()) return it->second;
    auto data = std::make_shared<const FieldCellData>(
        FieldCellData::Build(*mesh_, *geometry_, sel));
    ++dataBuilt_;
    data_[key] = data;
    return data;
}

std::shared_ptr<const SubCellBounds> FieldCache::SubBounds(
    const ScalarSelector& sel, const std::vector<std::uint8_t>& need) {
    const Key key{sel.field, sel.component};
    if (const auto it = subBounds_.find(key); it != subBounds_.end()) {
        it->second->Extend(*mesh_, *geometry_, *Data(sel), &need);
        return it->second;
    }
    auto bounds = std::make_shared<SubCellBounds>(
        SubCellBounds::Build(*mesh_, *geometry_, *Data(sel), &need));
    subBounds_[key] = bounds;
    return bounds;
}

std::shared_ptr<const std::vector<float>> FieldCache::GradientBounds(
    const ScalarSelector& sel) {
    const Key key{sel.field, sel.component};
    if (const auto it = gradientBounds_.find(key); it != gradientBounds_.end())
        return it->second;
    auto bounds = std::make_shared<std::vector<float>>();
    const double* u =
        sel.field->association == Association::Point ? Data(sel)->PointValues() : nullptr;
    if (u && geometry_->derivedCells > 0) {
        const std::int64_t cells = mesh_->CellCount();
        bounds->assign(cells, std::numeric_limits<float>::quiet_NaN());
        tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, cells, 4096),
                          [&](const tbb::blocked_range<std::int64_t>& range) {
                              for (std::int64_t c = range.begin(); c < range.end(); ++c) {
                                  if (!geometry_->IsDerived(c)) continue;
                                  const std::int64_t* ids =
                                      mesh_->connectivity.data() + mesh_->cellOffsets[c];
                                  (*bounds)[c] = LinearTetGradientBound(
                                      mesh_->points.data(), u, ids);
                              }
                          });
    }
    ++gradientBoundsBuilt_;
    gradientBounds_[key] = bounds;
    return bounds;
}

}  // namespace hpray

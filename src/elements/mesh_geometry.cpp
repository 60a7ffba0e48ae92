// Whole-mesh geometry cache and the point locator (see mesh_geometry.h).
#include "elements/mesh_geometry.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>

namespace hpray {

namespace {
/// Cells whose geometry is derived on request: linear tetrahedra.
bool Derived(const Mesh& mesh, std::int64_t c) {
    return mesh.cellShape[c] == CellShape::Tet && mesh.cellOrder[c] == 1 &&
           mesh.CellNodeCount(c) == 4;
}
}  // namespace

MeshGeometry MeshGeometry::Build(const Mesh& mesh) {
    MeshGeometry g;
    g.mesh_ = &mesh;
    const std::int64_t n = mesh.CellCount();
    // Which cells are stored, and where their nodes go.
    std::vector<std::int64_t> index(n, -1), nodeStart;
    std::int64_t stored = 0, nodes = 0;
    for (std::int64_t c = 0; c < n; ++c) {
        if (Derived(mesh, c)) continue;
        index[c] = stored++;
        nodeStart.push_back(nodes);
        nodes += mesh.CellNodeCount(c);
    }
    g.derivedCells = n - stored;
    g.allStored_ = stored == n;
    if (stored > 0 && stored < n) g.stored_ = std::move(index);
    g.nodeXyz_.resize(3 * nodes);
    g.cells_.resize(stored);
    g.boxes_.resize(stored);
    g.mapNodes_.resize(stored);
    struct Partial {
        Box box{{INFINITY, INFINITY, INFINITY}, {-INFINITY, -INFINITY, -INFINITY}};
        std::int64_t affine = 0, reduced = 0;
    };
    tbb::enumerable_thread_specific<Partial> partials;
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, n, 256),
                      [&](const tbb::blocked_range<std::int64_t>& range) {
        Partial& part = partials.local();
        CellScratch scratch;
        for (std::int64_t c = range.begin(); c < range.end(); ++c) {
            const std::int64_t k = g.stored_.empty() ? (g.allStored_ ? c : -1) : g.stored_[c];
            Box box;
            if (k < 0) {
                // A derived cell's geometry is not needed here (AffineCells derives it
                // when asked): its corners only.
                const std::int64_t* cellNodes = mesh.CellNodes(c);
                for (int m = 0; m < 4; ++m)
                    for (int d = 0; d < 3; ++d)
                        scratch.xyz[3 * m + d] = mesh.points[3 * cellNodes[m] + d];
                // The box only widens the bounds: not needed where its enclosure stays
                // strictly inside them (NaN compares false: then it is computed).
                const BasisTable& basis = g.Basis(c);
                const Box outer = GeometryBoxEnclosure(basis, scratch.xyz);
                bool inside = true;
                for (int d = 0; d < 3; ++d)
                    inside = inside && outer.lo[d] > part.box.lo[d] &&
                             outer.hi[d] < part.box.hi[d];
                if (inside) continue;
                box = GeometryBox(basis, scratch.xyz);  // CellBox(c), not gathered again
            } else {
                const BasisTable& basis = g.Basis(c);
                double* xyz = g.nodeXyz_.data() + 3 * nodeStart[k];
                const std::int64_t* cellNodes = mesh.CellNodes(c);
                for (int m = 0; m < basis.nodeCount; ++m)
                    for (int d = 0; d < 3; ++d) xyz[3 * m + d] = mesh.points[3 * cellNodes[m] + d];
                CellGeometry& cell = g.cells_[k] = MakeCellGeometry(basis, xyz);
                g.boxes_[k] = GeometryBox(basis, xyz);
                // A curved hexahedron whose map is of a lower order (at most half the
                // basis order, where it pays) is evaluated at that order: same map, within
                // the affine test's tolerance, for an eighth of the work or less.
                if (!cell.affine && basis.kind == BasisKind::HexLagrange && basis.order >= 2) {
                    std::vector<double>& reduced = g.mapNodes_[k];
                    const int q = ReducedHexMapOrder(basis, xyz, kAffineTolerance * cell.size,
                                                     basis.order / 2, reduced);
                    if (q > 0) {
                        cell.hexMap = &HexKernelsFor(q);
                        cell.mapOrder = q;
                        cell.mapNodes = reduced.data();
                        ++part.reduced;
                    }
                }
                part.affine += g.cells_[k].affine;
                box = g.boxes_[k];
            }
            for (int d = 0; d < 3; ++d) {
                part.box.lo[d] = std::min(part.box.lo[d], box.lo[d]);
                part.box.hi[d] = std::max(part.box.hi[d], box.hi[d]);
            }
        }
    });
    const double inf = std::numeric_limits<double>::infinity();
    g.bounds.lo = {inf, inf, inf};
    g.bounds.hi = {-inf, -inf, -inf};
    for (const Partial& part : partials) {
        g.storedAffine_ += part.affine;
        g.reducedMapCells += part.reduced;
        for (int d = 0; d < 3; ++d) {
            g.bounds.lo[d] = std::min(g.bounds.lo[d], part.box.lo[d]);
            g.bounds.hi[d] = std::max(g.bounds.hi[d], part.box.hi[d]);
        }
    }
    return g;
}

std::int64_t MeshGeometry::AffineCells() const {
    if (derivedCells == 0) return storedAffine_;
    const std::int64_t n = mesh_->CellCount();
    return storedAffine_ +
           tbb::parallel_reduce(
               tbb::blocked_range<std::int64_t>(0, n, 4096), std::int64_t{0},
               [&](const tbb::blocked_range<std::int64_t>& range, std::int64_t count) {
                   CellScratch scratch;
                   for (std::int64_t c = range.begin(); c < range.end(); ++c)
                       if (IsDerived(c)) count += Derive(c, scratch).affine;
                   return count;
               },
               std::plus<>());
}

const BasisTable& MeshGeometry::Basis(std::int64_t c) const {
    return GetBasis(mesh_->cellShape[c], mesh_->cellOrder[c], mesh_->cellFamily[c]);
}

const CellGeometry& MeshGeometry::Derive(std::int64_t c, CellScratch& scratch) const {
    const std::int64_t* cellNodes = mesh_->CellNodes(c);
    for (int m = 0; m < 4; ++m)
        for (int d = 0; d < 3; ++d) scratch.xyz[3 * m + d] = mesh_->points[3 * cellNodes[m] + d];
    scratch.geometry = MakeCellGeometry(Basis(c), scratch.xyz);
    return scratch.geometry;
}

Box MeshGeometry::CellBox(std::int64_t c) const {
    const std::int64_t k = stored_.empty() ? (allStored_ ? c : -1) : stored_[c];
    if (k >= 0) return boxes_[k];
    double xyz[12];
    const std::int64_t* cellNodes = mesh_->CellNodes(c);
    for (int m = 0; m < 4; ++m)
        for (int d = 0; d < 3; ++d) xyz[3 * m + d] = mesh_->points[3 * cellNodes[m] + d];
    return GeometryBox(Basis(c), xyz);
}

std::size_t MeshGeometry::Bytes() const {
    std::size_t reduced = mapNodes_.size() * sizeof(std::vector<double>);
    for (const auto& v : mapNodes_) reduced += v.size() * sizeof(double);
    return reduced + nodeXyz_.size() * sizeof(double) + cells_.size() * sizeof(CellGeometry) +
           boxes_.size() * sizeof(Box) + stored_.size() * sizeof(std::int64_t);
}

void GatherCellValues(const Mesh& mesh, const Field& field, int component, std::int64_t c,
                      std::vector<double>& out) {
    const int count = mesh.CellNodeCount(c);
    out.resize(count);
    const std::int64_t* nodes = mesh.CellNodes(c);
    const ScalarSelector sel{&field, component};
    for (int m = 0; m < count; ++m) out[m] = ScalarValue(sel, nodes[m]);
}

PointLocator::PointLocator(const Mesh& mesh, const MeshGeometry& geometry)
    : geometry_(geometry) {
    const std::int64_t n = mesh.CellCount();
    boxes_.resize(n);
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, n, 1024),
                      [&](const tbb::blocked_range<std::int64_t>& range) {
                          for (std::int64_t c = range.begin(); c < range.end(); ++c)
                              boxes_[c] = geometry.CellBox(c);
                      });
    if (n == 0) {
        start_.assign(2, 0);
        return;
    }
    // About two cells per grid cell along each axis, proportional to the extent.
    std::array<double, 3> ext;
    for (int d = 0; d < 3; ++d) {
        lo_[d] = geometry.bounds.lo[d];
        ext[d] = std::max(geometry.bounds.hi[d] - geometry.bounds.lo[d], 1e-300);
    }
    const double volume = ext[0] * ext[1] * ext[2];
    const double h = std::cbrt(volume / std::max<double>(1.0, n / 2.0));
    for (int d = 0; d < 3; ++d) {
        dims_[d] = static_cast<int>(std::clamp(std::ceil(ext[d] / h), 1.0, 512.0));
        cellSize_[d] = ext[d] / dims_[d];
    }
    const std::int64_t gridCells = std::int64_t(dims_[0]) * dims_[1] * dims_[2];
    auto range = [&](const Box& b, std::array<int, 3>& i0, std::array<int, 3>& i1) {
        for (int d = 0; d < 3; ++d) {
            i0[d] = std::clamp(static_cast<int>(std::floor((b.lo[d] - lo_[d]) / cellSize_[d])), 0,
                               dims_[d] - 1);
            i1[d] = std::clamp(static_cast<int>(std::floor((b.hi[d] - lo_[d]) / cellSize_[d])), 0,
                               dims_[d] - 1);
        }
    };
    std::vector<std::int64_t> counts(gridCells + 1, 0);
    std::array<int, 3> i0, i1;
    for (int pass = 0; pass < 2; ++pass) {
        if (pass == 1) {
            start_.assign(gridCells + 1, 0);
            for (std::int64_t k = 0; k < gridCells; ++k) start_[k + 1] = start_[k] + counts[k];
            items_.resize(start_.back());
            std::fill(counts.begin(), counts.end(), 0);
        }
        for (std::int64_t c = 0; c < n; ++c) {
            range(boxes_[c], i0, i1);
            for (int z = i0[2]; z <= i1[2]; ++z)
                for (int y = i0[1]; y <= i1[1]; ++y)
                    for (int x = i0[0]; x <= i1[0]; ++x) {
                        const std::int64_t k = x + std::int64_t(dims_[0]) * (y + std::int64_t(dims_[1]) * z);
                        if (pass == 1) items_[start_[k] + counts[k]] = c;
                        ++counts[k];
                    }
        }
    }
}

PointLocator::Hit PointLocator::Locate(const double world[3], EvalWorkspace& ws,
                                       const InversionOptions& options) const {
    Hit hit;
    if (items_.empty()) return hit;
    std::array<int, 3> idx;
    for (int d = 0; d < 3; ++d) {
        if (world[d] < geometry_.bounds.lo[d] || world[d] > geometry_.bounds.hi[d]) return hit;
        idx[d] = std::clamp(static_cast<int>(std::floor((world[d] - lo_[d]) / cellSize_[d])), 0,
                            dims_[d] - 1);
    }
    const std::int64_t k = idx[0] + std::int64_t(dims_[0]) * (idx[1] + std::int64_t(dims_[1]) * idx[2]);
    double best = std::numeric_limits<double>::infinity();
    for (std::int64_t i = start_[k]; i < start_[k + 1]; ++i) {
        const std::int64_t c = items_[i];
        const Box& b = boxes_[c];
        bool inBox = true;
        for (int d = 0; d < 3; ++d) inBox &= world[d] >= b.lo[d] && world[d] <= b.hi[d];
        if (!inBox) continue;
        CellScratch scratch;
        const InversionResult r =
            RefFromWorld(geometry_.Cell(c, scratch), world, ws, options);
        ++hit.inversions;
        if (r.status == InversionStatus::NotConverged || r.status == InversionStatus::Singular)
            ++hit.failures;
        if (!r.inside) continue;
        if (r.outsideDistance < best || (r.outsideDistance == best && c < hit.cell)) {
            best = r.outsideDistance;
            hit.cell = c;
            hit.ref = r.ref;
        }
    }
    return hit;
}

}  // namespace hpray

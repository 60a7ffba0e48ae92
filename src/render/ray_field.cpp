// SegmentField: the true field along a ray inside one cell.
#include "render/ray_field.h"

#if defined(__AVX2__)
#include <immintrin.h>
#endif
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "elements/bounds.h"
#include "elements/field.h"
#include "elements/tensor_eval.h"
#include "elements/tet_kernels.h"
#include "mesh/cell.h"
#include "util/check.h"
#include "util/lanes.h"

namespace hpray {

namespace {
// Lebesgue constants of equispaced 1-D interpolation of order p (rounded up): an interpolant
// of nodal values within d of zero stays within Lambda_p^3 d on the hexahedron.
constexpr double kLebesgue[kMaxOrder + 1] = {1.0, 1.0,  1.25, 1.64, 2.21, 3.11,
                                             4.55, 6.93, 10.95, 17.85, 29.9};

// FieldCellData::reducedOrder: for each Lagrange hexahedron of order p >= 2, the lowest
// order q <= p / 2 whose interpolant reproduces the cell's nodal values to rounding (16 ulp
// of their magnitude): the two interpolants then differ by the interpolant of that
// rounding, at most Lambda_p^3 times it anywhere in the cell, as the stored values' own
// rounding does.
void ReduceHexOrders(const Mesh& mesh, const ScalarSelector& field, FieldCellData& d) {
    const std::int64_t cells = mesh.CellCount();
    bool any = false;
    for (std::int64_t c = 0; c < cells && !any; ++c)
        any = mesh.cellShape[c] == CellShape::Hex && mesh.cellOrder[c] >= 2 &&
              mesh.cellFamily[c] == CellFamily::Lagrange;
    if (!any || field.field->association != Association::Point) return;
    d.reducedOrder.assign(cells, 0);
    d.reducedValues.resize(cells);
    struct Partial {
        std::int64_t count = 0;
        double margin = 0;
    };
    tbb::enumerable_thread_specific<Partial> partials;
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, cells, 16),
                      [&](const tbb::blocked_range<std::int64_t>& range) {
        Partial& part = partials.local();
        std::vector<double> reduced, deviation;
        for (std::int64_t c = range.begin(); c < range.end(); ++c) {
            if (mesh.cellShape[c] != CellShape::Hex || mesh.cellOrder[c] < 2 ||
                mesh.cellFamily[c] != CellFamily::Lagrange)
                continue;
            const int p = mesh.cellOrder[c];
            const int n = (p + 1) * (p + 1) * (p + 1);
            const double* values = d.values.data() + mesh.cellOffsets[c];
            double magnitude = 0;
            for (int m = 0; m < n; ++m) magnitude = std::max(magnitude, std::abs(values[m]));
            const double tolerance =
                16 * std::numeric_limits<double>::epsilon() * magnitude;
            for (int q = 1; q <= p / 2; ++q) {
                HexResample(p, 1, values, q, reduced);
                HexReductionDeviation(p, 1, values, q, reduced.data(), deviation);
                double worst = 0;
                for (double v : deviation) worst = std::max(worst, std::abs(v));
                if (worst <= tolerance) {
                    d.reducedOrder[c] = static_cast<std::uint8_t>(q);
                    d.reducedValues[c] = reduced;
                    part.count += 1;
                    const double l = kLebesgue[p];
                    part.margin = std::max(part.margin, l * l * l * worst);
                    break;
                }
            }
        }
    });
    for (const Partial& part : partials) {
        d.reducedCells += part.count;
        d.reductionTolerance = std::max(d.reductionTolerance, part.margin);
    }
    if (d.reducedCells == 0) {
        d.reducedOrder.clear();
        d.reducedValues.clear();
    }
}
}  // namespace

namespace {
// Whether SegmentField::BeginLinearTet has no closed form for linear tetrahedron c: its
// determinant from the same edges by the same EdgeCofactors (so bitwise the same number).
bool LinearTetDegenerate(const Mesh& mesh, std::int64_t c) {
    const std::int64_t* nodes = mesh.CellNodes(c);
    const double* p0 = &mesh.points[3 * nodes[0]];
    double e[3][3], cof[3][3];
    for (int i = 0; i < 3; ++i) {
        const double* p = &mesh.points[3 * nodes[i + 1]];
        for (int d = 0; d < 3; ++d) e[i][d] = p[d] - p0[d];
    }
    const double det = EdgeCofactors(e, cof);
    return det == 0 || !std::isfinite(det);
}

// Per-thread scratch of CellRefGradBound.
struct BoundScratch {
    std::vector<double> deriv[3];
    EvalWorkspace ws;
    CellScratch cell;
};

// A guaranteed bound of |df/dref_d| over cell c from its nodal values, for affine cells
// of polynomial spaces (the derivatives' nodal interpolants are exact and their
// Bernstein hull bounds them); +inf elsewhere.
std::array<double, 3> CellRefGradBound(const MeshGeometry& geometry, std::int64_t c,
                                       const double* nodal, BoundScratch& s) {
    const double inf = std::numeric_limits<double>::infinity();
    std::array<double, 3> bound = {inf, inf, inf};
    const CellGeometry& cell = geometry.Cell(c, s.cell);
    const BasisTable& basis = *cell.basis;
    if (!cell.affine || !basis.polynomial) return bound;
    auto& deriv = s.deriv;
    // Reference derivatives at the nodes: exact nodal interpolants of dF/dref_d.
    const int n = basis.nodeCount;
    for (auto& v : deriv) v.assign(n, 0.0);
    if (basis.kind == BasisKind::HexLagrange) {
        // Tensor product: the 1-D differentiation matrix along each direction.
        const int p = basis.order, q = p + 1;
        double D[(kMaxOrder + 1) * (kMaxOrder + 1)], l[kMaxOrder + 1];
        for (int i = 0; i < q; ++i)
            LagrangeEquispaced1D(p, double(i) / p, l, D + q * i);  // D[i][j] = l_j'(x_i)
        for (int k = 0; k < q; ++k)
            for (int j = 0; j < q; ++j)
                for (int i = 0; i < q; ++i) {
                    double dr = 0, ds = 0, dt = 0;
                    for (int m = 0; m < q; ++m) {
                        dr += D[q * i + m] * nodal[m + q * (j + q * k)];
                        ds += D[q * j + m] * nodal[i + q * (m + q * k)];
                        dt += D[q * k + m] * nodal[i + q * (j + q * m)];
                    }
                    const int node = i + q * (j + q * k);
                    deriv[0][node] = dr;
                    deriv[1][node] = ds;
                    deriv[2][node] = dt;
                }
    } else {
        for (int m = 0; m < n; ++m) {
            const double ref[3] = {basis.refNodes[m][0], basis.refNodes[m][1],
                                   basis.refNodes[m][2]};
            EvalBasis(basis, ref, s.ws.values.data(), s.ws.dRef.data());
            for (int q = 0; q < n; ++q)
                for (int a = 0; a < 3; ++a)
                    deriv[a][m] += nodal[q] * s.ws.dRef[3 * q + a];
        }
    }
    for (int a = 0; a < 3; ++a) {
        const Interval i = FieldBounds(basis, deriv[a].data());
        bound[a] = std::max(std::abs(i.lo), std::abs(i.hi));
    }
    return bound;
}
}  // namespace

namespace {
// SubCellBounds: hexahedra in kSubdivision^3 boxes, tetrahedra in the
// sub-tetrahedra of TetSubLevels(p) uniform refinements, fewer on large meshes.
constexpr int kSubdivision = 4;

// A float at most x (at least x): bounds kept in floats stay bounds. Where the rounded
// value lies on the wrong side it steps out by |f| 2^-23 + 1e-38, at least one unit in
// the last place of f (and past zero), and at most three.
float FloatDown(double x) {
    const float f = static_cast<float>(x);
    return f > x ? f - (std::abs(f) * 0x1p-23f + 1e-38f) : f;
}
float FloatUp(double x) {
    const float f = static_cast<float>(x);
    return f < x ? f + (std::abs(f) * 0x1p-23f + 1e-38f) : f;
}

}  // namespace

SubCellBounds SubCellBounds::Build(const Mesh& mesh, const MeshGeometry& geometry,
                                   const FieldCellData& data,
                                   const std::vector<std::uint8_t>* need,
                                   std::int64_t budget) {
    SubCellBounds d;
    const std::int64_t cells = mesh.CellCount();
    // Which cells get boxes: Lagrange hexahedra and tetrahedra above the linear ones.
    auto eligible = [&](std::int64_t c) {
        const int p = mesh.cellOrder[c];
        return mesh.cellFamily[c] == CellFamily::Lagrange && p >= 2 &&
               !geometry.IsDerived(c) &&
               (mesh.cellShape[c] == CellShape::Hex ||
                (mesh.cellShape[c] == CellShape::Tet && TetSubLevels(p) > 0));
    };
    std::int64_t count = 0;
    for (std::int64_t c = 0; c < cells; ++c) count += eligible(c);
    // At most `budget` bytes (32 per box): 64 boxes per cell where that fits (up to
    // 131072 cells by default), else 8, else none.
    const int perCell = count * 64 * 32 <= budget ? 64 : count * 8 * 32 <= budget ? 8 : 0;
    if (perCell == 0) return d;
    d.subN = perCell == 64 ? kSubdivision : 2;
    d.tetLevels_ = perCell == 64 ? 2 : 1;
    auto boxesOf = [&](std::int64_t c) {
        if (!eligible(c)) return 0;
        if (mesh.cellShape[c] == CellShape::Hex) return d.subN * d.subN * d.subN;
        return TetSubCount(d.TetLevels(mesh.cellOrder[c]));
    };
    std::vector<std::int64_t> start(cells + 1, 0);
    for (std::int64_t c = 0; c < cells; ++c) start[c + 1] = start[c] + boxesOf(c);
    if (start[cells] == 0) return SubCellBounds{};
    d.subStart = std::move(start);
    d.subData.reset(new float[static_cast<std::size_t>(8 * d.subStart[cells])]);
    d.built.assign(cells, 0);
    d.Extend(mesh, geometry, data, need);
    return d;
}

void SubCellBounds::Extend(const Mesh& mesh, const MeshGeometry& geometry,
                           const FieldCellData& data,
                           const std::vector<std::uint8_t>* need) {
    if (subStart.empty()) return;
    const std::int64_t cells = static_cast<std::int64_t>(built.size());
    const int hexN = subN;
    SubCellBounds& d = *this;
    tbb::enumerable_thread_specific<std::int64_t> kept(0);
    tbb::parallel_for(
        tbb::blocked_range<std::int64_t>(0, cells, 64),
        [&](const tbb::blocked_range<std::int64_t>& range) {
            CellScratch scratch;
            std::vector<double> nodal;
            std::vector<Interval> geo, field, both;
            std::vector<double> packed;
            for (std::int64_t c = range.begin(); c < range.end(); ++c) {
                const int boxes = static_cast<int>(d.subStart[c + 1] - d.subStart[c]);
                if (boxes == 0 || d.built[c] || (need && !(*need)[c])) continue;
                const CellGeometry& g = geometry.Cell(c, scratch);
                geo.resize(3 * boxes);
                field.resize(boxes);
                if (mesh.cellShape[c] == CellShape::Hex) {
                    HPRAY_CHECK(g.hexMap != nullptr);
                    // The map and the values the rays evaluate: the reduced ones if any.
                    const bool reduced =
                        !data.reducedOrder.empty() && data.reducedOrder[c] > 0;
                    HexSubBounds(g.mapOrder, hexN, g.mapNodes, 3, geo.data());
                    HexSubBounds(reduced ? data.reducedOrder[c] : g.basis->order, hexN,
                                 reduced ? data.reducedValues[c].data()
                                         : data.CellValues(c, nodal),
                                 1, field.data());
                } else {
                    // The node coordinates and the field in one pass (four lanes).
                    const int n = g.basis->nodeCount;
                    const double* values = data.CellValues(c, nodal);
                    packed.resize(4 * n);
                    for (int m = 0; m < n; ++m) {
                        for (int k = 0; k < 3; ++k)
                            packed[4 * m + k] = g.nodes[3 * m + k];
                        packed[4 * m + 3] = values[m];
                    }
                    both.resize(4 * boxes);
                    TetSubBounds(*g.basis, d.TetLevels(g.basis->order), packed.data(), 4,
                                 both.data());
                    for (int b = 0; b < boxes; ++b) {
                        for (int k = 0; k < 3; ++k) geo[3 * b + k] = both[4 * b + k];
                        field[b] = both[4 * b + 3];
                    }
                }
                float* out = d.subData.get() + 8 * d.subStart[c];
                const double pad = 1e-9 * g.size;
                for (int b = 0; b < boxes; ++b) {
                    for (int k = 0; k < 3; ++k) {
                        out[k * boxes + b] = FloatDown(geo[3 * b + k].lo - pad);
                        out[(3 + k) * boxes + b] = FloatUp(geo[3 * b + k].hi + pad);
                    }
                    out[6 * boxes + b] = FloatDown(field[b].lo);
                    out[7 * boxes + b] = FloatUp(field[b].hi);
                }
                d.built[c] = 1;
                kept.local() += 1;
            }
        });
    for (std::int64_t k : kept) d.subCells += k;
}

std::uint64_t SubCellBounds::Holding(std::int64_t c, const double* values,
                                     int count) const {
    if (subStart.empty() || subStart[c + 1] == subStart[c]) return 0;
    const int boxes = static_cast<int>(subStart[c + 1] - subStart[c]);
    // A cell whose boxes are not built: every box may hold anything.
    if (!built[c])
        return boxes == 64 ? ~std::uint64_t(0) : (std::uint64_t(1) << boxes) - 1;
    const float* data = subData.get() + 8 * subStart[c];
    const float* fieldLo = data + 6 * boxes;
    const float* fieldHi = data + 7 * boxes;
    // The boxes whose interval holds a value (at most 64 per cell), compared in float
    // against the value rounded up (lower bounds) and down (upper bounds), so a box that
    // holds it in exact arithmetic is never left out.
    std::uint64_t holding = 0;
    for (int k = 0; k < count; ++k) {
        const float up = FloatUp(values[k]), down = FloatDown(values[k]);
#if defined(__AVX2__)
        const __m256 vu = _mm256_set1_ps(up), vd = _mm256_set1_ps(down);
        for (int b = 0; b < boxes; b += 8) {
            const __m256 in = _mm256_and_ps(
                _mm256_cmp_ps(_mm256_loadu_ps(fieldLo + b), vu, _CMP_LE_OQ),
                _mm256_cmp_ps(vd, _mm256_loadu_ps(fieldHi + b), _CMP_LE_OQ));
            holding |= std::uint64_t(unsigned(_mm256_movemask_ps(in))) << b;
        }
#else
        for (int b = 0; b < boxes; ++b)
            holding |= std::uint64_t(fieldLo[b] <= up && down <= fieldHi[b]) << b;
#endif
    }
    return holding;
}

std::vector<std::uint64_t> SubCellBounds::HoldingMasks(const double* values,
                                                       int count) const {
    const std::int64_t cells =
        subStart.empty() ? 0 : static_cast<std::int64_t>(subStart.size()) - 1;
    std::vector<std::uint64_t> masks(cells);
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, cells, 4096),
                      [&](const tbb::blocked_range<std::int64_t>& range) {
                          for (std::int64_t c = range.begin(); c < range.end(); ++c)
                              masks[c] = Holding(c, values, count);
                      });
    return masks;
}

bool SubCellBounds::Clip(std::int64_t c, const Ray& ray, std::uint64_t holding,
                         double& t0, double& t1) const {
    if (subStart.empty() || subStart[c + 1] == subStart[c]) return true;
    const int boxes = static_cast<int>(subStart[c + 1] - subStart[c]);
    const float* data = subData.get() + 8 * subStart[c];
    if (holding == 0) return false;
    // Where three boxes in four or more hold a value, their world boxes nearly always
    // cover the segment (all of them do): not worth the slabs.
    if (4 * __builtin_popcountll(holding) >= 3 * boxes) return true;
    // The hull of the ray's parameter intervals in the world boxes of those (slabs, in
    // double, four boxes at a time; the boxes' padding is far above the rounding of
    // these products).
    double inv[3];
    for (int k = 0; k < 3; ++k) inv[k] = 1.0 / ray.dir[k];
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (int b0 = 0; b0 < boxes; b0 += 4) {
        const unsigned lanes = unsigned(holding >> b0) & 0xfu;
        if (lanes == 0) continue;
        alignas(32) double a[4], e[4];
#if defined(__AVX2__)
        __m256d va = _mm256_set1_pd(t0), ve = _mm256_set1_pd(t1);
        for (int k = 0; k < 3; ++k) {
            const __m256d bl = _mm256_cvtps_pd(_mm_loadu_ps(data + k * boxes + b0));
            const __m256d bh = _mm256_cvtps_pd(_mm_loadu_ps(data + (3 + k) * boxes + b0));
            const __m256d o = _mm256_set1_pd(ray.origin[k]);
            if (ray.dir[k] == 0) {  // inside the slab: no limit; outside: nothing
                const __m256d in = _mm256_and_pd(_mm256_cmp_pd(o, bl, _CMP_GE_OQ),
                                                 _mm256_cmp_pd(o, bh, _CMP_LE_OQ));
                ve = _mm256_blendv_pd(
                    _mm256_set1_pd(-std::numeric_limits<double>::infinity()), ve, in);
                continue;
            }
            const __m256d s = _mm256_set1_pd(inv[k]);
            const __m256d u = _mm256_mul_pd(_mm256_sub_pd(bl, o), s);
            const __m256d v = _mm256_mul_pd(_mm256_sub_pd(bh, o), s);
            va = _mm256_max_pd(va, _mm256_min_pd(u, v));
            ve = _mm256_min_pd(ve, _mm256_max_pd(u, v));
        }
        _mm256_store_pd(a, va);
        _mm256_store_pd(e, ve);
#else
        for (int j = 0; j < 4; ++j) a[j] = t0, e[j] = t1;
        for (int k = 0; k < 3; ++k) {
            const double o = ray.origin[k];
            const float* bl = data + k * boxes + b0;
            const float* bh = data + (3 + k) * boxes + b0;
            if (ray.dir[k] == 0) {  // inside the slab: no limit; outside: nothing
                for (int j = 0; j < 4; ++j)
                    if (!(o >= bl[j] && o <= bh[j]))
                        e[j] = -std::numeric_limits<double>::infinity();
                continue;
            }
            for (int j = 0; j < 4; ++j) {
                const double u = (double(bl[j]) - o) * inv[k],
                             v = (double(bh[j]) - o) * inv[k];
                a[j] = std::max(a[j], std::min(u, v));
                e[j] = std::min(e[j], std::max(u, v));
            }
        }
#endif
        for (int j = 0; j < 4; ++j)
            if ((lanes >> j & 1u) && a[j] <= e[j]) {
                lo = std::min(lo, a[j]);
                hi = std::max(hi, e[j]);
            }
        if (lo <= t0 && hi >= t1) return true;  // already the whole segment
    }
    if (!(lo <= hi)) return false;
    t0 = std::max(t0, lo);
    t1 = std::min(t1, hi);
    return true;
}

const double* FieldCellData::CellValues(std::int64_t c,
                                        std::vector<double>& scratch) const {
    const double* points = PointValues();
    if (!values.empty() || !points) return values.data() + mesh->cellOffsets[c];
    const int count = mesh->CellNodeCount(c);
    scratch.resize(count);
    const std::int64_t* nodes = mesh->CellNodes(c);
    for (int m = 0; m < count; ++m) scratch[m] = points[nodes[m]];
    return scratch.data();
}

const std::array<double, 3>* FieldCellData::RefGradBound(std::int64_t c) const {
    if (!refGradBound.empty()) return &refGradBound[c];
    const auto it = std::lower_bound(fallbackCells.begin(), fallbackCells.end(), c);
    if (it == fallbackCells.end() || *it != c) return nullptr;
    return &fallbackBounds[it - fallbackCells.begin()];
}

FieldCellData FieldCellData::Build(const Mesh& mesh, const MeshGeometry& geometry,
                                   const ScalarSelector& field) {
    FieldCellData d;
    d.mesh = &mesh;
    const std::int64_t cells = mesh.CellCount();
    const double inf = std::numeric_limits<double>::infinity();
    if (field.field->association != Association::Point) {
        d.values.resize(mesh.connectivity.size());
        d.refGradBound.assign(cells, {inf, inf, inf});
        return d;
    }
    if (field.field->components == 1 && field.component == 0) {
        d.pointField = field.field->values.data();
    } else {
        d.pointStorage.resize(mesh.PointCount());
        tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, mesh.PointCount(), 4096),
                          [&](const tbb::blocked_range<std::int64_t>& range) {
                              for (std::int64_t i = range.begin(); i < range.end(); ++i)
                                  d.pointStorage[i] = ScalarValue(field, i);
                          });
    }
    if (cells > 0 && geometry.derivedCells == cells) {
        // Linear tetrahedra only: the field per point, and the bounds of the tetrahedra
        // without a closed form.
        tbb::enumerable_thread_specific<std::vector<std::int64_t>> found;
        tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, cells, 4096),
                          [&](const tbb::blocked_range<std::int64_t>& range) {
                              for (std::int64_t c = range.begin(); c < range.end(); ++c)
                                  if (LinearTetDegenerate(mesh, c))
                                      found.local().push_back(c);
                          });
        for (const auto& part : found)
            d.fallbackCells.insert(d.fallbackCells.end(), part.begin(), part.end());
        std::sort(d.fallbackCells.begin(), d.fallbackCells.end());
        BoundScratch scratch;
        std::vector<double> nodal;
        for (std::int64_t c : d.fallbackCells)
            d.fallbackBounds.push_back(
                CellRefGradBound(geometry, c, d.CellValues(c, nodal), scratch));
        return d;
    }
    d.values.resize(mesh.connectivity.size());
    d.refGradBound.assign(cells, {inf, inf, inf});
    tbb::parallel_for(
        tbb::blocked_range<std::int64_t>(0, cells, 256),
        [&](const tbb::blocked_range<std::int64_t>& range) {
            std::vector<double> nodal;
            BoundScratch scratch;
            for (std::int64_t c = range.begin(); c < range.end(); ++c) {
                GatherCellValues(mesh, *field.field, field.component, c, nodal);
                std::copy(nodal.begin(), nodal.end(),
                          d.values.begin() + mesh.cellOffsets[c]);
                // A derived tetrahedron's bound is read only where BeginLinearTet fails.
                if (geometry.IsDerived(c) && !LinearTetDegenerate(mesh, c)) continue;
                d.refGradBound[c] = CellRefGradBound(geometry, c, nodal.data(), scratch);
            }
        });
    ReduceHexOrders(mesh, field, d);
    return d;
}

bool SegmentField::BeginLinearTet(const Mesh& mesh, std::int64_t c, const double* nodal,
                                  const Ray& ray) {
    const std::int64_t* nodes = mesh.CellNodes(c);
    const double* p0 = &mesh.points[3 * nodes[0]];
    double e[3][3], du[3];
    for (int i = 0; i < 3; ++i) {
        const double* p = &mesh.points[3 * nodes[i + 1]];
        for (int d = 0; d < 3; ++d) e[i][d] = p[d] - p0[d];
        du[i] = nodal[i + 1] - nodal[0];
    }
    // Solve E g = du (rows of E: the edges from corner 0) by Cramer's rule.
    double cof[3][3];
    const double det = EdgeCofactors(e, cof);
    if (det == 0 || !std::isfinite(det)) return false;
    const double* c0 = cof[0];
    const double* c1 = cof[1];
    const double* c2 = cof[2];
    const double inv = 1.0 / det;
    double rel = 0, slope = 0;
    for (int d = 0; d < 3; ++d) {
        worldGradient_[d] = (c0[d] * du[0] + c1[d] * du[1] + c2[d] * du[2]) * inv;
        rel += worldGradient_[d] * (ray.origin[d] - p0[d]);
        slope += worldGradient_[d] * ray.dir[d];
    }
    lineA_ = nodal[0] + rel;
    lineB_ = slope;
    linearTet_ = affine_ = exact_ = true;
    lineDegree_ = 1;
    gradBound_ = nullptr;
    reductionMargin_ = 0;
    hexOrder_ = 0;
    scalar_.nodal = nodal;
    scalar_.hexOrder = 0;
    return true;
}

void SegmentField::Begin(const FieldCellData& data, const MeshGeometry& geometry,
                         const ScalarSelector& field, std::int64_t c, const Ray& ray,
                         const InversionOptions& inversion) {
    (void)field;  // `data` was built for this field
    linearTet_ = false;
    if (geometry.IsDerived(c) &&
        BeginLinearTet(*data.mesh, c, data.CellValues(c, nodal_), ray))
        return;
    BeginCommon(geometry, c, ray, inversion);
    scalar_.nodal = data.CellValues(c, nodal_);
    gradBound_ = data.RefGradBound(c);
    lineDegree_ = cell_->basis->lineDegree;
    if (!data.reducedOrder.empty() && data.reducedOrder[c] > 0) {
        // Evaluated at its own lower order: along a line in an affine cell that is a
        // polynomial of degree 3 q.
        hexOrder_ = data.reducedOrder[c];
        scalar_.nodal = data.reducedValues[c].data();
        scalar_.hexOrder = hexOrder_;
        lineDegree_ = 3 * hexOrder_;
        reductionMargin_ = data.reductionTolerance;
    }
}

bool SegmentField::MayReach(const double* isovalues, int count, double t0, double t1) {
    if (linearTet_) {
        // Linear along the ray: its range on [t0, t1] is that of its end values.
        const double v0 = (*this)(t0), v1 = (*this)(t1);
        const double margin = 1e-13 * std::max(std::abs(v0), std::abs(v1));
        const double lo = std::min(v0, v1) - margin, hi = std::max(v0, v1) + margin;
        for (int k = 0; k < count; ++k)
            if (isovalues[k] >= lo && isovalues[k] <= hi) return true;
        return false;
    }
    if (!gradBound_ || !affine_ || !scalar_.nodal) return true;
    // |df/dt| = |grad_ref f . dref/dt| <= sum_d M_d |dref_d|.
    double lipschitz = 0;
    for (int a = 0; a < 3; ++a) lipschitz += (*gradBound_)[a] * std::abs(dref_[a]);
    if (!std::isfinite(lipschitz)) return true;
    auto excluded = [&](double value, double halfWidth) {
        // A small relative margin covers the rounding of the evaluation.
        // (The derivative bound is the cell's own; a reduced field is within
        // reductionMargin_ of it, which moves a difference of two values by twice that.)
        const double reach = lipschitz * halfWidth * (1 + 1e-12) + 1e-13 * std::abs(value) +
                             2 * reductionMargin_;
        for (int k = 0; k < count; ++k)
            if (std::abs(value - isovalues[k]) <= reach) return false;
        return true;
    };
    const double h = 0.5 * (t1 - t0);
    if (excluded((*this)(t0 + h), h)) return false;
    return !(excluded((*this)(t0 + 0.5 * h), 0.5 * h) &&
             excluded((*this)(t1 - 0.5 * h), 0.5 * h));
}

void SegmentField::BeginCommon(const MeshGeometry& geometry, std::int64_t c, const Ray& ray,
                               const InversionOptions& inversion) {
    cell_ = &geometry.Cell(c, cellScratch_);
    hexOrder_ = cell_->basis->kind == BasisKind::HexLagrange ? cell_->basis->order : 0;
    scalar_.hexOrder = 0;
    reductionMargin_ = 0;
    ray_ = ray;
    inversion_ = inversion;
    gradBound_ = nullptr;
    affine_ = cell_->affine && cell_->linearInvertible;
    exact_ = affine_ && cell_->basis->polynomial;
    histCount_ = 0;
    seedCount_ = 0;
    contraction_ = 0;
    if (affine_) {
        // ref(t) = L^-1 (o + t d - origin): linear in t.
        const auto& inv = cell_->inverseLinear;
        double rel[3];
        for (int i = 0; i < 3; ++i) rel[i] = ray.origin[i] - cell_->origin[i];
        for (int i = 0; i < 3; ++i) {
            ref0_[i] = inv[3 * i] * rel[0] + inv[3 * i + 1] * rel[1] + inv[3 * i + 2] * rel[2];
            dref_[i] = inv[3 * i] * ray.dir[0] + inv[3 * i + 1] * ray.dir[1] +
                       inv[3 * i + 2] * ray.dir[2];
        }
    }
}

bool SegmentField::RationalPole(double t0, double t1, double& pole, double& gap,
                                double& residue) const {
    if (linearTet_ || !affine_ || !scalar_.nodal || scalar_.hexOrder != 0 ||
        cell_->basis->kind != BasisKind::PyramidLagrange || cell_->basis->order != 1)
        return false;
    // With u = 1 - t, R = r - t / 2 and S = s - t / 2 (all affine along the ray) the
    // linear pyramid's field is v0 u + (v1 - v0) R + (v2 - v0) S + v4 t + k R S / u,
    // k = v0 - v1 - v2 + v3 (LinearPyramidValue's basis expanded). R S / u = R(p) S(p) /
    // (du/dx (x - p)) + a linear part, where u(p) = 0, so t = 1 and R(p) = r(p) - 1/2.
    const double* v = scalar_.nodal;
    const double twist = v[0] - v[1] - v[2] + v[3];
    const double mid = 0.5 * (t0 + t1), half = 0.5 * (t1 - t0);
    const double slope = -dref_[2] * half;  // du/dx
    if (!(half > 0)) return false;
    const double uMid = 1.0 - (ref0_[2] + mid * dref_[2]);
    // The nearer end's u, computed directly: |p| - 1 = uMin / |slope| without the
    // cancellation of uMid / |slope| - 1.
    const double uMin =
        std::min(1.0 - (ref0_[2] + t0 * dref_[2]), 1.0 - (ref0_[2] + t1 * dref_[2]));
    if (!(uMin > 0) || !std::isfinite(uMid)) return false;
    if (twist == 0 || slope == 0) {
        // No rational part: the field is linear in the reference point (no twist), or
        // 1 - t is constant along the line and R S / u a quadratic. A polynomial of
        // degree at most 2 along the ray: the pole at infinity.
        pole = gap = std::numeric_limits<double>::infinity();
        residue = 0;
        return true;
    }
    pole = -uMid / slope;
    gap = uMin / std::abs(slope);
    const double xp = pole;
    const double rp = ref0_[0] + (mid + xp * half) * dref_[0];
    const double sp = ref0_[1] + (mid + xp * half) * dref_[1];
    residue = twist * (rp - 0.5) * (sp - 0.5) / slope;
    return std::isfinite(pole) && std::isfinite(gap) && std::isfinite(residue);
}

bool SegmentField::PyramidLineOn(double t0, double t1, PyramidLine& out) const {
    if (linearTet_ || !affine_ || !scalar_.nodal || scalar_.hexOrder != 0 ||
        cell_->basis->kind != BasisKind::PyramidLagrange || cell_->basis->order != 1)
        return false;
    const double mid = 0.5 * (t0 + t1), half = 0.5 * (t1 - t0);
    if (!(half > 0)) return false;
    // The reference point at x: m + h x.
    double m[3], h[3];
    for (int d = 0; d < 3; ++d) {
        m[d] = ref0_[d] + mid * dref_[d];
        h[d] = half * dref_[d];
    }
    const double* v = scalar_.nodal;
    out.mid = mid;
    out.half = half;
    out.inverseHalf = 1 / half;
    out.u0 = 1.0 - m[2];
    out.u1 = -h[2];
    out.r0 = m[0] - 0.5 * m[2];
    out.r1 = h[0] - 0.5 * h[2];
    out.s0 = m[1] - 0.5 * m[2];
    out.s1 = h[1] - 0.5 * h[2];
    const double d1 = v[1] - v[0], d2 = v[2] - v[0];
    out.l0 = v[0] * out.u0 + d1 * out.r0 + d2 * out.s0 + v[4] * m[2];
    out.l1 = v[0] * out.u1 + d1 * out.r1 + d2 * out.s1 + v[4] * h[2];
    out.k = v[0] - v[1] - v[2] + v[3];
    // Below the apex plane at both ends (and so between them).
    const double uLo = 1.0 - (ref0_[2] + t0 * dref_[2]),
                 uHi = 1.0 - (ref0_[2] + t1 * dref_[2]);
    return uLo > 0 && uHi > 0 && std::isfinite(out.l0) && std::isfinite(out.l1) &&
           std::isfinite(out.k) && std::isfinite(out.u1);
}

bool SegmentField::LinearCellLine(double t0, double t1, double mono[4], int& degree,
                                  double& magnitude) const {
    if (linearTet_ || !affine_ || !scalar_.nodal || cell_->basis->order != 1)
        return false;
    const bool hex = cell_->basis->kind == BasisKind::HexLagrange && hexOrder_ == 1;
    const bool wedge = cell_->basis->kind == BasisKind::WedgeLagrange;
    if (!hex && !wedge) return false;
    const double* v = scalar_.nodal;
    const double mid = 0.5 * (t0 + t1), half = 0.5 * (t1 - t0);
    // Reference coordinate d along the segment: m[d] + h[d] x.
    double m[3], h[3];
    for (int d = 0; d < 3; ++d) {
        m[d] = ref0_[d] + mid * dref_[d];
        h[d] = half * dref_[d];
    }
    // One linear factor along axis d: out = a (1 - y) + b y = a + (b - a) y with y = md +
    // hd x, for a and b polynomials in x of degree deg (out of degree deg + 1).
    auto lerp = [](const double* a, const double* b, int deg, double md, double hd,
                   double* out) {
        double diff[4];
        for (int k = 0; k <= deg; ++k) diff[k] = b[k] - a[k];
        for (int k = 0; k <= deg + 1; ++k) out[k] = k <= deg ? a[k] : 0.0;
        for (int k = 0; k <= deg; ++k) {
            out[k] += diff[k] * md;
            out[k + 1] += diff[k] * hd;
        }
    };
    magnitude = 0;
    if (hex) {
        for (int q = 0; q < 8; ++q) magnitude = std::max(magnitude, std::abs(v[q]));
        // Lattice order, i fastest: along reference x, then y, then z.
        double g[4][2], q2[2][3];
        for (int jk = 0; jk < 4; ++jk)
            lerp(v + 2 * jk, v + 2 * jk + 1, 0, m[0], h[0], g[jk]);
        for (int k = 0; k < 2; ++k) lerp(g[2 * k], g[2 * k + 1], 1, m[1], h[1], q2[k]);
        lerp(q2[0], q2[1], 2, m[2], h[2], mono);
        degree = 3;
        return true;
    }
    for (int q = 0; q < 6; ++q) magnitude = std::max(magnitude, std::abs(v[q]));
    // LinearWedgeValue's basis: (1 - r - s, r, s) on each triangle, (1 - t, t) between.
    double g[2][2];
    for (int j = 0; j < 2; ++j) {
        const double* w = v + 3 * j;
        // w0 + (w1 - w0) r + (w2 - w0) s
        g[j][0] = w[0] + (w[1] - w[0]) * m[0] + (w[2] - w[0]) * m[1];
        g[j][1] = (w[1] - w[0]) * h[0] + (w[2] - w[0]) * h[1];
    }
    lerp(g[0], g[1], 1, m[2], h[2], mono);
    degree = 2;
    return true;
}

void SegmentField::Begin(const Mesh& mesh, const MeshGeometry& geometry,
                         const ScalarSelector& field, std::int64_t c, const Ray& ray,
                         const InversionOptions& inversion) {
    linearTet_ = false;
    if (field.field->association == Association::Point && geometry.IsDerived(c)) {
        GatherCellValues(mesh, *field.field, field.component, c, nodal_);
        if (BeginLinearTet(mesh, c, nodal_.data(), ray)) return;
    }
    BeginCommon(geometry, c, ray, inversion);
    if (field.field->association == Association::Point) {
        GatherCellValues(mesh, *field.field, field.component, c, nodal_);
        scalar_.nodal = nodal_.data();
    } else {
        scalar_.nodal = nullptr;
        scalar_.constant = ScalarValue(field, c);
    }
    lineDegree_ = scalar_.nodal ? cell_->basis->lineDegree : 0;
}

void SegmentField::Seed(double tEnter, const double enter[3], double tExit,
                        const double exit[3]) {
    seedCount_ = 0;
    if (affine_) return;
    seedReach_ = 1e-9 * std::abs(tExit - tEnter);
    const double* refs[2] = {enter, exit};
    const double ts[2] = {tEnter, tExit};
    for (int k = 0; k < 2; ++k) {
        if (!(std::isfinite(refs[k][0]) && std::isfinite(refs[k][1]) &&
              std::isfinite(refs[k][2])))
            continue;
        seedT_[seedCount_] = ts[k];
        for (int d = 0; d < 3; ++d) seedRef_[seedCount_][d] = refs[k][d];
        ++seedCount_;
    }
}

void SegmentField::RefAt(double t, double ref[3]) {
    if (affine_) {
        for (int i = 0; i < 3; ++i) ref[i] = ref0_[i] + t * dref_[i];
        return;
    }
    double world[3];
    for (int i = 0; i < 3; ++i) world[i] = ray_.origin[i] + t * ray_.dir[i];
    InversionOptions options = inversion_;
    // Start Newton from the Hermite interpolant (values and slopes d ref / dt = J^-1 d)
    // through the inverted points nearest t, those that bracket it first: the reference
    // path is smooth, and between samples the prediction is far closer than extrapolated
    // from the last ones. Quintic through three points, cubic through two, the tangent
    // line at one.
    double start[3];
    const int n = histCount_;
    // The points in order of t are histT_[histOrder_[k]] (stored in the order they came,
    // indexed in order of t). First rank with a larger t than this one (binary search).
    const std::uint8_t* order = histOrder_;
    int hi = 0;
    for (int len = n; len > 0;) {
        const int half = len / 2;
        if (histT_[order[hi + half]] > t) {
            len = half;
        } else {
            hi += half + 1;
            len -= half + 1;
        }
    }
    if (n >= 3) {
        // The three nearest: the bracketing pair and the nearer of their outer
        // neighbours.
        int i0 = hi == 0 ? 0 : hi == n ? n - 2 : hi - 1;
        if (i0 + 2 >= n ||
            (i0 > 0 && t - histT_[order[i0 - 1]] < histT_[order[i0 + 2]] - t))
            --i0;
        i0 = std::max(0, std::min(i0, n - 3));
        // H_k = (1 - 2 L_k'(t_k) (t - t_k)) L_k^2 and K_k = (t - t_k) L_k^2 with L_k the
        // quadratic Lagrange basis on the three points.
        const int k0 = order[i0], k1 = order[i0 + 1], k2 = order[i0 + 2];
        const double t0 = histT_[k0], t1 = histT_[k1], t2 = histT_[k2];
        if (t0 != t1 && t1 != t2 && t0 != t2) {
            const double d01 = t0 - t1, d02 = t0 - t2, d12 = t1 - t2;
            const double inv = 1 / (d01 * d02 * d12);
            const double r01 = d02 * d12 * inv, r02 = d01 * d12 * inv,
                         r12 = d01 * d02 * inv;
            const double a0 = t - t0, a1 = t - t1, a2 = t - t2;
            // (Scalars, not arrays: stored lane by lane and reloaded as vectors, those
            // stalled on store forwarding.)
            const double l0 = a1 * a2 * r01 * r02, l1 = -a0 * a2 * r01 * r12,
                         l2 = a0 * a1 * r02 * r12;
            const double q0 = l0 * l0, q1 = l1 * l1, q2 = l2 * l2;
            const double wv0 = (1 - 2 * (r01 + r02) * a0) * q0,
                         wv1 = (1 - 2 * (r12 - r01) * a1) * q1,
                         wv2 = (1 - 2 * (-r02 - r12) * a2) * q2;  // L_k'(t_k) inside
            const double ws0 = a0 * q0, ws1 = a1 * q1, ws2 = a2 * q2;
            const double* R0 = histRef_[k0];
            const double* R1 = histRef_[k1];
            const double* R2 = histRef_[k2];
            const double* S0 = histSlope_[k0];
            const double* S1 = histSlope_[k1];
            const double* S2 = histSlope_[k2];
            for (int i = 0; i < 3; ++i)
                start[i] = wv0 * R0[i] + ws0 * S0[i] + wv1 * R1[i] + ws1 * S1[i] +
                           wv2 * R2[i] + ws2 * S2[i];
            options.initialGuess = start;
        }
    } else if (n == 2) {
        const int i0 = order[0], i1 = order[1];
        const double h = histT_[i1] - histT_[i0];
        if (h != 0) {
            const double s = (t - histT_[i0]) / h;
            const double s2 = s * s, s3 = s2 * s;
            const double h00 = 2 * s3 - 3 * s2 + 1, h10 = (s3 - 2 * s2 + s) * h,
                         h01 = -2 * s3 + 3 * s2, h11 = (s3 - s2) * h;
            for (int i = 0; i < 3; ++i)
                start[i] = h00 * histRef_[i0][i] + h10 * histSlope_[i0][i] +
                           h01 * histRef_[i1][i] + h11 * histSlope_[i1][i];
            options.initialGuess = start;
        }
    } else if (n == 1) {
        for (int i = 0; i < 3; ++i)
            start[i] = histRef_[0][i] + (t - histT_[0]) * histSlope_[0][i];
        options.initialGuess = start;
    }
    // At a seeded end of the segment (within rounding of it), the cell's point on the
    // face the ray crosses there starts Newton: far closer than an extrapolation or the
    // affine guess.
    for (int k = 0; k < seedCount_; ++k)
        if (std::abs(t - seedT_[k]) <= seedReach_) options.initialGuess = seedRef_[k];
    // Newton's contraction measured in this cell along this ray, with a margin of 4.
    options.contraction = 4 * contraction_;
    // Curved hexahedra and tetrahedra from a predicted start: the common path of
    // RefFromWorld (full Newton steps) without its general set-up, else RefFromWorld.
    double outRef[3], outInverse[9];
    int outIterations = 0;
    double outContraction = 0;
    bool converged;
    if ((cell_->hexMap || cell_->tetMap) && options.initialGuess &&
        NewtonFullSteps(*cell_, world, options.initialGuess, options, outRef,
                        outIterations, outContraction, outInverse)) {
        converged = true;
    } else {
        const InversionResult r = RefFromWorld(*cell_, world, ws_, options);
        converged = r.converged;
        outIterations = r.iterations;
        outContraction = r.contraction;
        std::copy(r.ref.begin(), r.ref.end(), outRef);
        std::copy(r.inverseJacobian.begin(), r.inverseJacobian.end(), outInverse);
    }
    contraction_ = std::max(contraction_, outContraction);
    inversions_ += 1;
    iterations_ += outIterations;
    if (!converged) failures_ += 1;
    for (int i = 0; i < 3; ++i) ref[i] = outRef[i];
    if (converged && n < kHistory && (hi == 0 || histT_[order[hi - 1]] != t)) {
        // Stored at n, its rank inserted at hi.
        for (int k = n; k > hi; --k) histOrder_[k] = histOrder_[k - 1];
        histOrder_[hi] = static_cast<std::uint8_t>(n);
        histT_[n] = t;
        const double* inv = outInverse;
        for (int i = 0; i < 3; ++i) {
            histRef_[n][i] = outRef[i];
            histSlope_[n][i] = inv[3 * i] * ray_.dir[0] + inv[3 * i + 1] * ray_.dir[1] +
                               inv[3 * i + 2] * ray_.dir[2];
        }
        histCount_ = n + 1;
    }
}

double SegmentField::operator()(double t) {
    evaluations_ += 1;
    if (linearTet_) return lineA_ + lineB_ * t;
    if (!scalar_.nodal) return scalar_.constant;
    double ref[3];
    RefAt(t, ref);
    return FieldValue(*cell_, scalar_, ref, ws_);
}

void SegmentField::SampleBatch(const double* t, int n, double* out) {
    if (!linearTet_ && scalar_.nodal && hexOrder_ > 0) {
        const int p = hexOrder_;
        batchScratch_.resize(HexLineScratchSize(p, n) + 3 * n);
        if (affine_) {
            HexFieldValuesAlongLine(p, scalar_.nodal, ref0_, dref_, t, n, out,
                                    batchScratch_.data());
        } else {
            // Invert the points in order along the ray (each warm-starts the next), then
            // evaluate them together.
            double* refs = batchScratch_.data() + HexLineScratchSize(p, n);
            if (seedCount_ > 0 && n > 2) {
                // The seeded ends first: the points between are then interpolated.
                RefAt(t[0], refs);
                RefAt(t[n - 1], refs + 3 * (n - 1));
                for (int s = 1; s < n - 1; ++s) RefAt(t[s], refs + 3 * s);
            } else {
                for (int s = 0; s < n; ++s) RefAt(t[s], refs + 3 * s);
            }
            HexFieldValuesAt(p, scalar_.nodal, refs, n, out, batchScratch_.data());
        }
        evaluations_ += n;
        return;
    }
    if (!linearTet_ && scalar_.nodal && affine_ && cell_->basis->order == 1 &&
        (cell_->basis->kind == BasisKind::PyramidLagrange ||
         cell_->basis->kind == BasisKind::WedgeLagrange)) {
        // Affine linear pyramids and wedges: the point as RefAt gives it and the value as
        // FieldValue computes it (the same functions), without the per-point dispatch.
        const bool pyramid = cell_->basis->kind == BasisKind::PyramidLagrange;
        int first = 0;
#if defined(HPRAY_LANES)
        if (pyramid) {
            // Four points at a time in the lanes of vectors (lanes.h):
            // LinearPyramidValue's products, sums and quotients in the same order,
            // nothing fused, so bitwise its values (the apex plane's lanes take a = b =
            // 0.5, as it does).
            using lanes::D;
            const double* v = scalar_.nodal;
            const D<4> half = lanes::Splat<4>(0.5);
            for (; first + 4 <= n; first += 4) {
                const D<4> ts = lanes::Load<4>(t + first);
                const D<4> r0 = ref0_[0] + ts * dref_[0], r1 = ref0_[1] + ts * dref_[1],
                           r2 = ref0_[2] + ts * dref_[2];
                const D<4> u = 1.0 - r2;
                const lanes::I<4> apex = u == 0.0;
                const D<4> a = lanes::Select(apex, half, (r0 - 0.5 * r2) / u);
                const D<4> b = lanes::Select(apex, half, (r1 - 0.5 * r2) / u);
                const D<4> la0 = 1.0 - a, lb0 = 1.0 - b;
                D<4> f = 0.0 + v[0] * ((la0 * lb0) * u);
                f += v[1] * ((a * lb0) * u);
                f += v[2] * ((la0 * b) * u);
                f += v[3] * ((a * b) * u);
                f += v[4] * r2;
                std::memcpy(out + first, &f, sizeof f);
            }
        }
#endif
        for (int s = first; s < n; ++s) {
            double ref[3];
            for (int i = 0; i < 3; ++i) ref[i] = ref0_[i] + t[s] * dref_[i];
            out[s] = pyramid ? LinearPyramidValue(scalar_.nodal, ref)
                             : LinearWedgeValue(scalar_.nodal, ref);
        }
        evaluations_ += n;
        return;
    }
    if (!linearTet_ && scalar_.nodal && cell_->basis->kind == BasisKind::TetLagrange &&
        cell_->basis->order >= 2) {
        // Curved (or high-order) tetrahedra: the points inverted in order, as one by one,
        // then their values together (bitwise FieldValue's, four at a time).
        batchScratch_.resize(3 * std::size_t(n));
        double* refs = batchScratch_.data();
        for (int s = 0; s < n; ++s) RefAt(t[s], refs + 3 * s);
        TetKernelsFor(cell_->basis->order).values(scalar_.nodal, refs, n, out);
        evaluations_ += n;
        return;
    }
    for (int s = 0; s < n; ++s) out[s] = (*this)(t[s]);
}

bool SegmentField::ValueGradient(double t, double& value, double gradient[3]) {
    evaluations_ += 1;
    if (linearTet_) {
        value = lineA_ + lineB_ * t;
        for (int d = 0; d < 3; ++d) gradient[d] = worldGradient_[d];
        return true;
    }
    double ref[3];
    RefAt(t, ref);
    return FieldValueGradient(*cell_, scalar_, ref, ws_, value, gradient);
}

void SegmentField::AddCountersTo(RenderCounters& counters) {
    counters.inversions += inversions_;
    counters.inversionIterations += iterations_;
    counters.inversionFailures += failures_;
    counters.fieldEvaluations += evaluations_;
    inversions_ = iterations_ = failures_ = evaluations_ = 0;
}

}  // namespace hpray

// Hull surface areas for the cost model (see cost_model.h).
#include "cost_model.h"

#if defined(__AVX__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <mutex>
#include <tuple>
#include <vector>

#include "elements/basis.h"
#include "elements/geometry.h"
#include "util/check.h"

namespace hpray::partition {
namespace {

/// The squared length of (p1 - p0) x (q1 - q0): a triangle's area from two edges, or a
/// planar-ish quadrilateral's from its diagonals, is half its square root.
inline double CrossNorm2(const double* p0, const double* p1, const double* q0,
                         const double* q1) {
    double u[3], v[3];
    for (int d = 0; d < 3; ++d) {
        u[d] = p1[d] - p0[d];
        v[d] = q1[d] - q0[d];
    }
    const double x = u[1] * v[2] - u[2] * v[1], y = u[2] * v[0] - u[0] * v[2],
                 z = u[0] * v[1] - u[1] * v[0];
    return x * x + y * y + z * z;
}

/// The corners' internal node indices of a cell kind, and whether they are 0..corners-1
/// (every order-1 cell), so the nodes can be used as they are.
struct Corners {
    std::vector<int> index;
    bool leading = false;
};

}  // namespace

namespace {

/// HullSurfaceArea for a topology of `Faces` faces (so that the loops unroll).
template <int Faces>
double HullArea(const CellTopology& t, const double* v) {
    auto P = [v](int i) { return v + 3 * i; };
    // Triangles from two edges, quadrilaterals from their diagonals; the square roots of
    // all faces are independent of each other (so they overlap), the sum is in face
    // order.
    double norm2[Faces];
    for (int f = 0; f < Faces; ++f) {
        const int* c = t.face[f];
        norm2[f] = t.faceSize[f] == 3 ? CrossNorm2(P(c[0]), P(c[1]), P(c[0]), P(c[2]))
                                      : CrossNorm2(P(c[0]), P(c[2]), P(c[1]), P(c[3]));
    }
    double half[Faces];
    int f = 0;
#if defined(__AVX__)
    // Four faces per instruction (the same correctly rounded square roots and halving),
    // gathered in registers.
    for (; f + 4 <= Faces; f += 4)
        _mm256_storeu_pd(
            half + f, _mm256_mul_pd(_mm256_set1_pd(0.5), _mm256_sqrt_pd(_mm256_set_pd(
                                                             norm2[f + 3], norm2[f + 2],
                                                             norm2[f + 1], norm2[f]))));
#endif
    for (; f < Faces; ++f) half[f] = 0.5 * std::sqrt(norm2[f]);
    double area = 0;
    for (int k = 0; k < Faces; ++k) area += half[k];
    return area;
}

}  // namespace

double HullSurfaceArea(CellShape shape, const double* v) {
    const CellTopology& t = Topology(shape);
    switch (t.faces) {
        case 4:
            return HullArea<4>(t, v);
        case 5:
            return HullArea<5>(t, v);
        case 6:
            return HullArea<6>(t, v);
    }
    HPRAY_CHECK_MSG(false, "a cell shape with " << t.faces << " faces");
    return 0;
}

double CellHullSurfaceArea(CellShape shape, int order, CellFamily family,
                           const double* nodeXyz) {
    // Internal indices of the corners (mesh/cell.h Topology), cached per (shape, order,
    // family); each thread also remembers the last kind it asked for (cells of one kind
    // tend to follow each other), which skips the lock.
    static std::mutex mutex;
    static std::map<std::tuple<int, int, int>, Corners> cache;
    const std::tuple<int, int, int> key{static_cast<int>(shape), order,
                                        static_cast<int>(family)};
    thread_local std::tuple<int, int, int> lastKey{-1, -1, -1};
    thread_local const Corners* lastCorners = nullptr;
    const Corners* corners = lastKey == key ? lastCorners : nullptr;
    if (!corners) {
        std::lock_guard<std::mutex> lock(mutex);
        Corners& entry = cache[key];
        if (entry.index.empty()) {
            const CellTopology& t = Topology(shape);
            entry.leading = true;
            for (int k = 0; k < t.corners; ++k) {
                const LatticeIndex ijk{order * t.lattice[k][0], order * t.lattice[k][1],
                                       order * t.lattice[k][2]};
                const int index = InternalNodeIndex(shape, order, family, ijk);
                HPRAY_CHECK_GE(index, 0);
                entry.index.push_back(index);
                entry.leading &= index == k;
            }
        }
        corners = &entry;  // map entries stay where they are
        lastKey = key;
        lastCorners = corners;
    }
    if (corners->leading) return HullSurfaceArea(shape, nodeXyz);
    double v[8 * 3];
    for (std::size_t k = 0; k < corners->index.size(); ++k)
        for (int d = 0; d < 3; ++d) v[3 * k + d] = nodeXyz[3 * corners->index[k] + d];
    return HullSurfaceArea(shape, v);
}

CellCostInput CellCostFromNodes(CellShape shape, int order, CellFamily family,
                                const double* nodeXyz) {
    // Order-1 tets are always affine; the others by the renderer's own test.
    const bool curved =
        !(shape == CellShape::Tet && order == 1 && family == CellFamily::Lagrange) &&
        !MakeCellGeometry(GetBasis(shape, order, family), nodeXyz).affine;
    // The model's parts depend on the kind only: remembered for the last kind per thread.
    const std::tuple<int, int, int, bool> key{static_cast<int>(shape), order,
                                              static_cast<int>(family), curved};
    thread_local std::tuple<int, int, int, bool> lastKey{-1, -1, -1, false};
    thread_local CellCostParts lastParts;
    if (key != lastKey) {
        lastParts = CellCostModel(shape, order, family, curved);
        lastKey = key;
    }
    return {lastParts, CellHullSurfaceArea(shape, order, family, nodeXyz)};
}

namespace {

/// The faces of the tet of mesh/cell.h Topology, written out (checked against it once)
/// so that the loops below hold no lookups; the corners of an order-1 tet are its nodes,
/// in order (CellHullSurfaceArea).
constexpr int kTetFaces[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};

const CellCostParts& LinearTetParts() {
    static const CellCostParts parts = [] {
        const CellTopology& t = Topology(CellShape::Tet);
        HPRAY_CHECK_EQ(t.faces, 4);
        for (int f = 0; f < 4; ++f) {
            HPRAY_CHECK_EQ(t.faceSize[f], 3);
            for (int k = 0; k < 3; ++k) HPRAY_CHECK_EQ(t.face[f][k], kTetFaces[f][k]);
        }
        return CellCostModel(CellShape::Tet, 1, CellFamily::Lagrange, /*curved=*/false);
    }();
    return parts;
}

/// HullArea<4>'s squared cross products of a tet's faces.
void TetFaceNorms(const double* xyz, double* norm2) {
    auto P = [xyz](int i) { return xyz + 3 * i; };
    for (int f = 0; f < 4; ++f) {
        const int* c = kTetFaces[f];
        norm2[f] = CrossNorm2(P(c[0]), P(c[1]), P(c[0]), P(c[2]));
    }
}

/// half[i] = 0.5 * sqrt(norm2[i]) for i < n.
void HalfRoots(const double* norm2, double* half, std::size_t n) {
    std::size_t i = 0;
#if defined(__AVX__)
    for (; i + 4 <= n; i += 4)
        _mm256_storeu_pd(half + i,
                         _mm256_mul_pd(_mm256_set1_pd(0.5),
                                       _mm256_sqrt_pd(_mm256_loadu_pd(norm2 + i))));
#endif
    for (; i < n; ++i) half[i] = 0.5 * std::sqrt(norm2[i]);
}

}  // namespace

CellCostInput LinearTetCost(const double* nodeXyz) {
    CellCostInput out;
    LinearTetCosts(&nodeXyz, 1, &out);
    return out;
}

void LinearTetCosts(const double* const* nodeXyz, std::size_t count, CellCostInput* out) {
    const CellCostParts& parts = LinearTetParts();
    constexpr std::size_t kGroup = 64;
    double norm2[4 * kGroup], half[4 * kGroup];
    for (std::size_t first = 0; first < count; first += kGroup) {
        const std::size_t n = std::min(kGroup, count - first);
        for (std::size_t i = 0; i < n; ++i)
            TetFaceNorms(nodeXyz[first + i], norm2 + 4 * i);
        HalfRoots(norm2, half, 4 * n);
        for (std::size_t i = 0; i < n; ++i) {
            double area = 0;
            for (int f = 0; f < 4; ++f) area += half[4 * i + f];
            out[first + i] = {parts, area};
        }
    }
}

}  // namespace hpray::partition

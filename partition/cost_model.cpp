// Hull surface areas for the cost model (see cost_model.h).
#include "cost_model.h"

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

/// Half the length of (p1 - p0) x (q1 - q0): a triangle's area from two edges, or a
/// planar-ish quadrilateral's from its diagonals.
double HalfCrossNorm(const double* p0, const double* p1, const double* q0, const double* q1) {
    double u[3], v[3];
    for (int d = 0; d < 3; ++d) {
        u[d] = p1[d] - p0[d];
        v[d] = q1[d] - q0[d];
    }
    const double x = u[1] * v[2] - u[2] * v[1], y = u[2] * v[0] - u[0] * v[2],
                 z = u[0] * v[1] - u[1] * v[0];
    return 0.5 * std::sqrt(x * x + y * y + z * z);
}

double TriangleArea(const double* a, const double* b, const double* c) {
    return HalfCrossNorm(a, b, a, c);
}

double QuadArea(const double* a, const double* b, const double* c, const double* d) {
    return HalfCrossNorm(a, c, b, d);
}

}  // namespace

double HullSurfaceArea(CellShape shape, const double* v) {
    auto P = [v](int i) { return v + 3 * i; };
    const CellTopology& t = Topology(shape);
    double area = 0;
    for (int f = 0; f < t.faces; ++f) {
        const int* c = t.face[f];
        area += t.faceSize[f] == 3 ? TriangleArea(P(c[0]), P(c[1]), P(c[2]))
                                   : QuadArea(P(c[0]), P(c[1]), P(c[2]), P(c[3]));
    }
    return area;
}

double CellHullSurfaceArea(CellShape shape, int order, CellFamily family,
                           const double* nodeXyz) {
    // Internal indices of the corners (mesh/cell.h Topology), cached per (shape, order,
    // family); each thread also remembers the last kind it asked for (cells of one kind
    // tend to follow each other), which skips the lock.
    static std::mutex mutex;
    static std::map<std::tuple<int, int, int>, std::vector<int>> cache;
    const std::tuple<int, int, int> key{static_cast<int>(shape), order,
                                        static_cast<int>(family)};
    thread_local std::tuple<int, int, int> lastKey{-1, -1, -1};
    thread_local const std::vector<int>* lastCorners = nullptr;
    const std::vector<int>* corners = lastKey == key ? lastCorners : nullptr;
    if (!corners) {
        std::lock_guard<std::mutex> lock(mutex);
        auto& entry = cache[key];
        if (entry.empty()) {
            const CellTopology& t = Topology(shape);
            for (int k = 0; k < t.corners; ++k) {
                const LatticeIndex ijk{order * t.lattice[k][0], order * t.lattice[k][1],
                                       order * t.lattice[k][2]};
                const int index = InternalNodeIndex(shape, order, family, ijk);
                HPRAY_CHECK_GE(index, 0);
                entry.push_back(index);
            }
        }
        corners = &entry;  // map entries stay where they are
        lastKey = key;
        lastCorners = corners;
    }
    double v[8 * 3];
    for (std::size_t k = 0; k < corners->size(); ++k)
        for (int d = 0; d < 3; ++d) v[3 * k + d] = nodeXyz[3 * (*corners)[k] + d];
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

}  // namespace hpray::partition

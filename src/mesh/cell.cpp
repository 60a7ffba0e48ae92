// Lattices of the internal node ordering (see cell.h).
#include "mesh/cell.h"

#include <algorithm>
#include <array>
#include <map>
#include <mutex>

#include "util/check.h"

namespace hpray {
namespace {

bool InLattice(CellShape shape, int p, int i, int j, int k) {
    if (i < 0 || j < 0 || k < 0) return false;
    switch (shape) {
        case CellShape::Tet: return i + j + k <= p;
        case CellShape::Hex: return i <= p && j <= p && k <= p;
        case CellShape::Wedge: return i + j <= p && k <= p;
        case CellShape::Pyramid: return k <= p && i <= p - k && j <= p - k;
    }
    return false;
}

// A serendipity node is a vertex or an edge midpoint of the order-2 lattice.
bool OnSerendipityLattice(CellShape shape, int i, int j, int k) {
    switch (shape) {
        case CellShape::Hex: {
            // vertex or edge midpoint: at most one coordinate equals 1.
            int ones = (i == 1) + (j == 1) + (k == 1);
            return ones <= 1;
        }
        case CellShape::Wedge: {
            // triangle vertices/edge-midpoints at k = 0 and 2; vertical edge midpoints at k = 1.
            if (k == 1) return (i == 0 && j == 0) || (i == 2 && j == 0) || (i == 0 && j == 2);
            return true;  // the 6 nodes of a quadratic triangle
        }
        case CellShape::Pyramid: {
            // Base: the 8 quad nodes (no centre); level 1: the 4 corners; apex.
            if (k == 0) return !(i == 1 && j == 1);
            return true;
        }
        case CellShape::Tet: return true;
    }
    return false;
}

std::vector<LatticeIndex> BuildLattice(CellShape shape, int p, CellFamily family) {
    std::vector<LatticeIndex> nodes;
    for (int k = 0; k <= p; ++k)
        for (int j = 0; j <= p; ++j)
            for (int i = 0; i <= p; ++i) {
                if (!InLattice(shape, p, i, j, k)) continue;
                if (family == CellFamily::Serendipity && !OnSerendipityLattice(shape, i, j, k))
                    continue;
                nodes.push_back({i, j, k});
            }
    return nodes;
}

void CheckSupported(CellShape shape, int order, CellFamily family) {
    HPRAY_CHECK_MSG(order >= 1 && order <= kMaxOrder, "cell order " << order);
    if (family == CellFamily::Serendipity)
        HPRAY_CHECK_MSG(order == 2 && shape != CellShape::Tet,
                        "serendipity " << ShapeName(shape) << " of order " << order);
}

}  // namespace

const char* ShapeName(CellShape shape) {
    switch (shape) {
        case CellShape::Tet: return "tet";
        case CellShape::Hex: return "hex";
        case CellShape::Wedge: return "wedge";
        case CellShape::Pyramid: return "pyramid";
    }
    return "?";
}

int VertexCount(CellShape shape) {
    static constexpr int kCounts[] = {4, 8, 6, 5};
    return kCounts[static_cast<int>(shape)];
}

int NodeCount(CellShape shape, int order, CellFamily family) {
    // Called per cell (mesh validation, readers): the counts of every supported
    // combination from one table built once, without LatticeNodes' lock and lookup.
    static const auto kCounts = [] {
        std::array<std::array<std::array<int, 2>, kMaxOrder + 1>, kNumCellShapes> t{};
        for (int s = 0; s < kNumCellShapes; ++s)
            for (int p = 1; p <= kMaxOrder; ++p)
                for (int f = 0; f < 2; ++f) {
                    const auto sh = static_cast<CellShape>(s);
                    const auto fa = static_cast<CellFamily>(f);
                    if (fa == CellFamily::Serendipity && (p != 2 || sh == CellShape::Tet))
                        continue;
                    t[s][p][f] = static_cast<int>(LatticeNodes(sh, p, fa).size());
                }
        return t;
    }();
    const int s = static_cast<int>(shape), f = static_cast<int>(family);
    if (s >= 0 && s < kNumCellShapes && order >= 1 && order <= kMaxOrder && f >= 0 &&
        f < 2 && kCounts[s][order][f] > 0)
        return kCounts[s][order][f];
    // Not supported: LatticeNodes reports it.
    return static_cast<int>(LatticeNodes(shape, order, family).size());
}

const std::vector<LatticeIndex>& LatticeNodes(CellShape shape, int order, CellFamily family) {
    CheckSupported(shape, order, family);
    static std::mutex mutex;
    static std::map<std::tuple<int, int, int>, std::vector<LatticeIndex>> cache;
    std::lock_guard<std::mutex> lock(mutex);
    auto key = std::make_tuple(static_cast<int>(shape), order, static_cast<int>(family));
    auto it = cache.find(key);
    if (it == cache.end()) it = cache.emplace(key, BuildLattice(shape, order, family)).first;
    return it->second;  // std::map nodes are stable, so the reference outlives the lock.
}

int InternalNodeIndex(CellShape shape, int order, CellFamily family, const LatticeIndex& ijk) {
    if (shape == CellShape::Hex && family == CellFamily::Lagrange) {
        const int n = order + 1;
        if (!InLattice(shape, order, ijk[0], ijk[1], ijk[2])) return -1;
        return ijk[0] + n * (ijk[1] + n * ijk[2]);
    }
    const auto& nodes = LatticeNodes(shape, order, family);
    auto less = [](const LatticeIndex& a, const LatticeIndex& b) {
        return std::tie(a[2], a[1], a[0]) < std::tie(b[2], b[1], b[0]);
    };
    auto it = std::lower_bound(nodes.begin(), nodes.end(), ijk, less);
    if (it == nodes.end() || *it != ijk) return -1;
    return static_cast<int>(it - nodes.begin());
}

std::array<double, 3> LatticeRefCoords(CellShape shape, int order, const LatticeIndex& ijk) {
    const double p = order;
    if (shape == CellShape::Pyramid)
        return {(ijk[0] + 0.5 * ijk[2]) / p, (ijk[1] + 0.5 * ijk[2]) / p, ijk[2] / p};
    return {ijk[0] / p, ijk[1] / p, ijk[2] / p};
}

const CellTopology& Topology(CellShape shape) {
    static const CellTopology kShapes[kNumCellShapes] = {
    {4,
     {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}},
     4,
     {3, 3, 3, 3},
     {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}}},
    {8,
     {{0, 0, 0},
      {1, 0, 0},
      {0, 1, 0},
      {1, 1, 0},
      {0, 0, 1},
      {1, 0, 1},
      {0, 1, 1},
      {1, 1, 1}},
     6,
     {4, 4, 4, 4, 4, 4},
     {{0, 2, 3, 1},
      {4, 5, 7, 6},
      {0, 1, 5, 4},
      {2, 6, 7, 3},
      {0, 4, 6, 2},
      {1, 3, 7, 5}}},
    {6,
     {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {0, 1, 1}},
     5,
     {3, 3, 4, 4, 4},
     {{0, 2, 1}, {3, 4, 5}, {0, 1, 4, 3}, {0, 3, 5, 2}, {1, 2, 5, 4}}},
    {5,
     {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {0, 0, 1}},
     5,
     {4, 3, 3, 3, 3},
     {{0, 2, 3, 1}, {0, 1, 4}, {1, 3, 4}, {3, 2, 4}, {2, 0, 4}}},
};
    return kShapes[static_cast<int>(shape)];
}

std::vector<LatticeIndex> VertexLattice(CellShape shape, int p) {
    switch (shape) {
        case CellShape::Tet: return {{0, 0, 0}, {p, 0, 0}, {0, p, 0}, {0, 0, p}};
        case CellShape::Hex:
            return {{0, 0, 0}, {p, 0, 0}, {p, p, 0}, {0, p, 0},
                    {0, 0, p}, {p, 0, p}, {p, p, p}, {0, p, p}};
        case CellShape::Wedge:
            return {{0, 0, 0}, {p, 0, 0}, {0, p, 0}, {0, 0, p}, {p, 0, p}, {0, p, p}};
        case CellShape::Pyramid:
            return {{0, 0, 0}, {p, 0, 0}, {p, p, 0}, {0, p, 0}, {0, 0, p}};
    }
    return {};
}

}  // namespace hpray

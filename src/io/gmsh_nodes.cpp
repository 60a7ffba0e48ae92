// Gmsh element type table and gmsh's recursive high-order node order (see gmsh_nodes.h).
#include "io/gmsh_nodes.h"

#include <map>
#include <mutex>

#include "util/check.h"

namespace hpray {
namespace {

// Dimension and node count of gmsh element types 1..140 (GmshDefines.h MSH_*); node count
// -1: unknown id or variable size.
struct TypeEntry {
    int dim;
    int nodes;
};
constexpr int kMaxGmshType = 140;
// clang-format off
constexpr TypeEntry kTypes[kMaxGmshType + 1] = {
    {-1, -1},                                                   // 0
    {1, 2},    {2, 3},    {2, 4},   {3, 4},   {3, 8},           // 1-5
    {3, 6},    {3, 5},    {1, 3},   {2, 6},   {2, 9},           // 6-10
    {3, 10},   {3, 27},   {3, 18},  {3, 14},  {0, 1},           // 11-15
    {2, 8},    {3, 20},   {3, 15},  {3, 13},  {2, 9},           // 16-20
    {2, 10},   {2, 12},   {2, 15},  {2, 15},  {2, 21},          // 21-25
    {1, 4},    {1, 5},    {1, 6},   {3, 20},  {3, 35},          // 26-30
    {3, 56},   {3, 22},   {3, 28},  {2, -1},  {3, -1},          // 31-35
    {2, 16},   {2, 25},   {2, 36},  {2, 12},  {2, 16},          // 36-40
    {2, 20},   {2, 28},   {2, 36},  {2, 45},  {2, 55},          // 41-45
    {2, 66},   {2, 49},   {2, 64},  {2, 81},  {2, 100},         // 46-50
    {2, 121},  {2, 18},   {2, 21},  {2, 24},  {2, 27},          // 51-55
    {2, 30},   {2, 24},   {2, 28},  {2, 32},  {2, 36},          // 56-60
    {2, 40},   {1, 7},    {1, 8},   {1, 9},   {1, 10},          // 61-65
    {1, 11},   {-1, -1},  {-1, -1}, {-1, -1}, {-1, -1},         // 66-70
    {3, 84},   {3, 120},  {3, 165}, {3, 220}, {3, 286},         // 71-75
    {-1, -1},  {-1, -1},  {-1, -1}, {3, 34},  {3, 40},          // 76-80
    {3, 46},   {3, 52},   {3, 58},  {1, 1},   {2, 1},           // 81-85
    {2, 1},    {3, 1},    {3, 1},   {3, 1},   {3, 40},          // 86-90
    {3, 75},   {3, 64},   {3, 125}, {3, 216}, {3, 343},         // 91-95
    {3, 512},  {3, 729},  {3, 1000}, {3, 32}, {3, 44},          // 96-100
    {3, 56},   {3, 68},   {3, 80},  {3, 92},  {3, 104},         // 101-105
    {3, 126},  {3, 196},  {3, 288}, {3, 405}, {3, 550},         // 106-110
    {3, 24},   {3, 33},   {3, 42},  {3, 51},  {3, 60},          // 111-115
    {3, 69},   {3, 78},   {3, 30},  {3, 55},  {3, 91},          // 116-120
    {3, 140},  {3, 204},  {3, 285}, {3, 385}, {3, 21},          // 121-125
    {3, 29},   {3, 37},   {3, 45},  {3, 53},  {3, 61},          // 126-130
    {3, 69},   {3, 1},    {0, -1},  {1, -1},  {2, -1},          // 131-135
    {3, -1},   {3, 16},   {-1, -1}, {-1, -1}, {3, 4},           // 136-140
};
// clang-format on

// The 3-D types hpray reads: gmsh id -> shape, order, family.
const std::map<int, GmshCellType>& SupportedTypes() {
    static const std::map<int, GmshCellType> table = [] {
        std::map<int, GmshCellType> t;
        auto add = [&t](int type, CellShape shape, int order, CellFamily family) {
            t[type] = GmshCellType{type, shape, order, family, kTypes[type].nodes};
        };
        const int tets[] = {4, 11, 29, 30, 31, 71, 72, 73, 74, 75};
        for (int p = 1; p <= 10; ++p)
            add(tets[p - 1], CellShape::Tet, p, CellFamily::Lagrange);
        const int hexes[] = {5, 12, 92, 93, 94, 95, 96, 97, 98};
        const int prisms[] = {6, 13, 90, 91, 106, 107, 108, 109, 110};
        const int pyramids[] = {7, 14, 118, 119, 120, 121, 122, 123, 124};
        for (int p = 1; p <= 9; ++p) {
            add(hexes[p - 1], CellShape::Hex, p, CellFamily::Lagrange);
            add(prisms[p - 1], CellShape::Wedge, p, CellFamily::Lagrange);
            add(pyramids[p - 1], CellShape::Pyramid, p, CellFamily::Lagrange);
        }
        add(17, CellShape::Hex, 2, CellFamily::Serendipity);
        add(18, CellShape::Wedge, 2, CellFamily::Serendipity);
        add(19, CellShape::Pyramid, 2, CellFamily::Serendipity);
        return t;
    }();
    return table;
}

// ---- gmsh's integer node positions ("monomials"), generated as gmsh generates them ----
// Tet, hex, prism: the position is the internal lattice index. Pyramid: (i, j, p - k),
// the third coordinate counting down from the base (gmsh's convention).
// The edge and face tables below are gmsh's numbering convention (which corner each edge
// and face starts from, in which order they are walked), in gmsh's corner numbering; the
// faces are those of the reference cells of mesh/cell.h (GmshFaceCorners, checked by a
// test).

using M2 = std::array<int, 2>;
using M3 = std::array<int, 3>;

constexpr int kTriEdges[3][2] = {{0, 1}, {1, 2}, {2, 0}};
constexpr int kQuadEdges[4][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}};
constexpr int kTetEdges[6][2] = {{0, 1}, {1, 2}, {2, 0}, {3, 0}, {3, 2}, {3, 1}};
constexpr int kTetFaces[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {3, 1, 2}};
constexpr int kHexEdges[12][2] = {{0, 1}, {0, 3}, {0, 4}, {1, 2}, {1, 5}, {2, 3},
                                  {2, 6}, {3, 7}, {4, 5}, {4, 7}, {5, 6}, {6, 7}};
constexpr int kHexFaces[6][4] = {{0, 3, 2, 1}, {0, 1, 5, 4}, {0, 4, 7, 3},
                                 {1, 2, 6, 5}, {2, 3, 7, 6}, {4, 5, 6, 7}};
constexpr int kPrismEdges[9][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 4},
                                   {2, 5}, {3, 4}, {3, 5}, {4, 5}};
constexpr int kPrismFaces[5][4] = {
    {0, 2, 1, -1}, {3, 4, 5, -1}, {0, 1, 4, 3}, {0, 3, 5, 2}, {1, 2, 5, 4}};
constexpr int kPyramidEdges[8][2] = {{0, 1}, {0, 3}, {0, 4}, {1, 2},
                                     {1, 4}, {2, 3}, {2, 4}, {3, 4}};
constexpr int kPyramidFaces[5][4] = {
    {0, 1, 4, -1}, {3, 0, 4, -1}, {1, 2, 4, -1}, {2, 3, 4, -1}, {0, 3, 2, 1}};

std::vector<int> LineNodes(int p) {
    std::vector<int> m{0};
    if (p == 0) return m;
    m.push_back(p);
    for (int i = 1; i < p; ++i) m.push_back(i);
    return m;
}

template <typename V, std::size_t N>
void AddEdgeNodes(std::vector<V>& m, int p, const int (&edges)[N][2]) {
    for (const auto& e : edges) {
        const V a = m[e[0]];  // copies: push_back below may reallocate
        const V b = m[e[1]];
        for (int i = 1; i < p; ++i) {
            V v;
            for (std::size_t c = 0; c < v.size(); ++c)
                v[c] = a[c] + (b[c] - a[c]) / p * i;
            m.push_back(v);
        }
    }
}

std::vector<M2> TriangleNodes(int p) {
    if (p == 0) return {{0, 0}};
    std::vector<M2> m{{0, 0}, {p, 0}, {0, p}};
    if (p > 1) AddEdgeNodes(m, p, kTriEdges);
    if (p > 2)
        for (M2 v : TriangleNodes(p - 3)) m.push_back({v[0] + 1, v[1] + 1});
    return m;
}

std::vector<M2> QuadNodes(int p) {
    if (p == 0) return {{0, 0}};
    std::vector<M2> m{{0, 0}, {p, 0}, {p, p}, {0, p}};
    if (p > 1) {
        AddEdgeNodes(m, p, kQuadEdges);
        for (M2 v : QuadNodes(p - 2)) m.push_back({v[0] + 1, v[1] + 1});
    }
    return m;
}

// Face nodes: m[i0] + u * d[0] + v * d[1] with u = (m[i1] - m[i0]) / p, v = (m[i2] -
// m[i0]) / p.
void AddFaceNodes(std::vector<M3>& m, int p, int i0, int i1, int i2,
                  const std::vector<M2>& faceNodes) {
    M3 u, v;
    for (int c = 0; c < 3; ++c) {
        u[c] = (m[i1][c] - m[i0][c]) / p;
        v[c] = (m[i2][c] - m[i0][c]) / p;
    }
    const M3 o = m[i0];
    for (M2 d : faceNodes) {
        // Faces are interior: their local positions start at (1, 1).
        const int a = d[0] + 1, b = d[1] + 1;
        m.push_back({o[0] + u[0] * a + v[0] * b, o[1] + u[1] * a + v[1] * b,
                     o[2] + u[2] * a + v[2] * b});
    }
}

std::vector<M3> TetNodes(int p) {
    if (p == 0) return {{0, 0, 0}};
    std::vector<M3> m{{0, 0, 0}, {p, 0, 0}, {0, p, 0}, {0, 0, p}};
    if (p > 1) AddEdgeNodes(m, p, kTetEdges);
    if (p > 2) {
        const std::vector<M2> tri = TriangleNodes(p - 3);
        for (const auto& f : kTetFaces) AddFaceNodes(m, p, f[0], f[1], f[2], tri);
    }
    if (p > 3)
        for (M3 v : TetNodes(p - 4)) m.push_back({v[0] + 1, v[1] + 1, v[2] + 1});
    return m;
}

std::vector<M3> HexNodes(int p, bool serendipity) {
    if (p == 0) return {{0, 0, 0}};
    std::vector<M3> m{{0, 0, 0}, {p, 0, 0}, {p, p, 0}, {0, p, 0},
                      {0, 0, p}, {p, 0, p}, {p, p, p}, {0, p, p}};
    if (p > 1) {
        AddEdgeNodes(m, p, kHexEdges);
        if (!serendipity) {
            const std::vector<M2> quad = QuadNodes(p - 2);
            for (const auto& f : kHexFaces) AddFaceNodes(m, p, f[0], f[1], f[3], quad);
            for (M3 v : HexNodes(p - 2, false))
                m.push_back({v[0] + 1, v[1] + 1, v[2] + 1});
        }
    }
    return m;
}

std::vector<M3> PrismNodes(int p, bool serendipity) {
    if (p == 0) return {{0, 0, 0}};
    std::vector<M3> m{{0, 0, 0}, {p, 0, 0}, {0, p, 0}, {0, 0, p}, {p, 0, p}, {0, p, p}};
    if (p > 1) {
        AddEdgeNodes(m, p, kPrismEdges);
        if (!serendipity) {
            const std::vector<M2> quad = QuadNodes(p - 2);
            const std::vector<M2> tri = p > 2 ? TriangleNodes(p - 3) : std::vector<M2>{};
            for (const auto& f : kPrismFaces) {
                if (f[3] != -1)
                    AddFaceNodes(m, p, f[0], f[1], f[3], quad);
                else if (p > 2)
                    AddFaceNodes(m, p, f[0], f[1], f[2], tri);
            }
            // Interior: not a recursive prism but (triangle of order p-3) x (line p-2).
            if (p > 2)
                for (M2 t : tri)
                    for (int l : LineNodes(p - 2))
                        m.push_back({t[0] + 1, t[1] + 1, l + 1});
        }
    }
    return m;
}

std::vector<M3> PyramidNodes(int p, bool serendipity) {
    if (p == 0) return {{0, 0, 0}};
    std::vector<M3> m{{0, 0, p}, {p, 0, p}, {p, p, p}, {0, p, p}, {0, 0, 0}};
    if (p > 1) {
        AddEdgeNodes(m, p, kPyramidEdges);
        if (!serendipity) {
            const std::vector<M2> quad = QuadNodes(p - 2);
            const std::vector<M2> tri = p > 2 ? TriangleNodes(p - 3) : std::vector<M2>{};
            for (const auto& f : kPyramidFaces) {
                if (f[3] != -1)
                    AddFaceNodes(m, p, f[0], f[1], f[3], quad);
                else if (p > 2)
                    AddFaceNodes(m, p, f[0], f[1], f[2], tri);
            }
            if (p > 2)
                for (M3 v : PyramidNodes(p - 3, false))
                    m.push_back({v[0] + 1, v[1] + 1, v[2] + 2});
        }
    }
    return m;
}

std::vector<LatticeIndex> BuildLattice(const GmshCellType& t) {
    const bool ser = t.family == CellFamily::Serendipity;
    const int p = t.order;
    switch (t.shape) {
        case CellShape::Tet:
            return TetNodes(p);
        case CellShape::Hex:
            return HexNodes(p, ser);
        case CellShape::Wedge:
            return PrismNodes(p, ser);
        case CellShape::Pyramid: {
            std::vector<LatticeIndex> nodes = PyramidNodes(p, ser);
            for (LatticeIndex& n : nodes) n[2] = p - n[2];
            return nodes;
        }
    }
    return {};
}

const GmshCellType& RequireSupported(int type) {
    const auto& table = SupportedTypes();
    auto it = table.find(type);
    HPRAY_CHECK_MSG(it != table.end(),
                    "gmsh element type " << type << " is not supported");
    return it->second;
}

}  // namespace

int GmshTypeNodeCount(int type) {
    if (type < 1 || type > kMaxGmshType) return -1;
    return kTypes[type].nodes;
}

int GmshTypeDimension(int type) {
    if (type < 1 || type > kMaxGmshType) return -1;
    return kTypes[type].dim;
}

std::optional<GmshCellType> ClassifyGmshType(int type) {
    const auto& table = SupportedTypes();
    auto it = table.find(type);
    if (it == table.end()) return std::nullopt;
    return it->second;
}

const std::vector<LatticeIndex>& GmshNodeLattice(int type) {
    const GmshCellType& t = RequireSupported(type);
    static std::mutex mutex;
    static std::map<int, std::vector<LatticeIndex>> cache;
    std::lock_guard<std::mutex> lock(mutex);
    auto it = cache.find(type);
    if (it == cache.end()) {
        std::vector<LatticeIndex> nodes = BuildLattice(t);
        HPRAY_CHECK_EQ(static_cast<int>(nodes.size()), t.nodeCount);
        it = cache.emplace(type, std::move(nodes)).first;
    }
    return it->second;
}

std::vector<std::vector<LatticeIndex>> GmshFaceCorners(CellShape shape) {
    const int firstOrder[kNumCellShapes] = {4, 5, 6, 7};  // gmsh types of order 1
    const std::vector<LatticeIndex>& corner =
        GmshNodeLattice(firstOrder[static_cast<int>(shape)]);
    std::vector<std::vector<LatticeIndex>> faces;
    auto add = [&](const int* f, int n) {
        std::vector<LatticeIndex> cycle;
        for (int k = 0; k < n && f[k] >= 0; ++k) cycle.push_back(corner[f[k]]);
        faces.push_back(cycle);
    };
    switch (shape) {
        case CellShape::Tet:
            for (const auto& f : kTetFaces) add(f, 3);
            break;
        case CellShape::Hex:
            for (const auto& f : kHexFaces) add(f, 4);
            break;
        case CellShape::Wedge:
            for (const auto& f : kPrismFaces) add(f, 4);
            break;
        case CellShape::Pyramid:
            for (const auto& f : kPyramidFaces) add(f, 4);
            break;
    }
    return faces;
}

std::vector<std::array<double, 3>> GmshReferenceCoords(int type) {
    const GmshCellType& t = RequireSupported(type);
    const int p = t.order;
    std::vector<std::array<double, 3>> coords;
    for (const LatticeIndex& n : GmshNodeLattice(type)) {
        // The same floating-point operations as gmsh's points generators.
        switch (t.shape) {
            case CellShape::Tet:
                coords.push_back({n[0] * (1. / p), n[1] * (1. / p), n[2] * (1. / p)});
                break;
            case CellShape::Hex:
                coords.push_back(
                    {n[0] * (2. / p) - 1., n[1] * (2. / p) - 1., n[2] * (2. / p) - 1.});
                break;
            case CellShape::Wedge:
                coords.push_back(
                    {n[0] * (1. / p), n[1] * (1. / p), n[2] * (2. / p) - 1.});
                break;
            case CellShape::Pyramid: {
                const double z = static_cast<double>(n[2]) / p;  // gmsh: (p - c) / p
                const double duv = 1. - z;
                const double scale = 2. / p;
                coords.push_back({-duv + n[0] * scale, -duv + n[1] * scale, z});
                break;
            }
        }
    }
    return coords;
}

const std::vector<int>& GmshToInternal(int type) {
    const GmshCellType& t = RequireSupported(type);
    const std::vector<LatticeIndex>& lattice = GmshNodeLattice(type);
    static std::mutex mutex;
    static std::map<int, std::vector<int>> cache;
    std::lock_guard<std::mutex> lock(mutex);
    auto it = cache.find(type);
    if (it == cache.end()) {
        std::vector<int> perm(lattice.size(), -1);
        for (std::size_t n = 0; n < lattice.size(); ++n) {
            const int k = InternalNodeIndex(t.shape, t.order, t.family, lattice[n]);
            HPRAY_CHECK_MSG(k >= 0 && perm[k] == -1,
                            "gmsh type " << type << " node " << n << " off the lattice");
            perm[k] = static_cast<int>(n);
        }
        it = cache.emplace(type, std::move(perm)).first;
    }
    return it->second;
}

std::array<double, 3> GmshRefToInternal(CellShape shape, const std::array<double, 3>& x) {
    switch (shape) {
        case CellShape::Tet:
            return x;
        case CellShape::Hex:
            return {(x[0] + 1) / 2, (x[1] + 1) / 2, (x[2] + 1) / 2};
        case CellShape::Wedge:
            return {x[0], x[1], (x[2] + 1) / 2};
        case CellShape::Pyramid:
            return {(x[0] + 1) / 2, (x[1] + 1) / 2, x[2]};
    }
    return x;
}

}  // namespace hpray

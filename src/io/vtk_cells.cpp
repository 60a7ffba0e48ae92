// VTK cell types: classification, node-order permutations, VTK parametric coordinates.
//
// Every VTK node order is expressed the same way: the internal lattice index
// (mesh/cell.h) of each VTK node n. The Lagrange orders follow VTK's numbering algorithms
// (vtkHigherOrderHexahedron/Wedge::PointIndexFromIJK, vtkHigherOrderTetra::Index); the
// fixed quadratic cells are listed as averages of their vertices, as VTK documents them.
#include "io/vtk_cells.h"

#include <algorithm>
#include <map>
#include <mutex>
#include <sstream>
#include <tuple>

#include "util/check.h"

namespace hpray {
namespace {

using Lattice = std::vector<LatticeIndex>;

// ---------------------------------------------------------------------------------------
// VTK Lagrange numbering: VTK node index of the node at lattice (i, j, k), order p.

// vtkHigherOrderHexahedron::PointIndexFromIJK with equal orders on the three axes.
int HexVtkIndex(int i, int j, int k, int p) {
    const bool ib = i == 0 || i == p, jb = j == 0 || j == p, kb = k == 0 || k == p;
    const int boundaries = ib + jb + kb;
    const int e = p - 1;  // nodes inside an edge
    if (boundaries == 3) return (i ? (j ? 2 : 1) : (j ? 3 : 0)) + (k ? 4 : 0);
    int offset = 8;
    if (boundaries == 2) {  // edges 0-3 (k = 0), 4-7 (k = p), then 8-11 along k
        if (!ib) return offset + (i - 1) + (j ? 2 * e : 0) + (k ? 4 * e : 0);
        if (!jb) return offset + (j - 1) + (i ? e : 3 * e) + (k ? 4 * e : 0);
        offset += 8 * e;
        return offset + (k - 1) + e * (i ? (j ? 2 : 1) : (j ? 3 : 0));
    }
    offset += 12 * e;
    if (boundaries == 1) {  // faces i = 0, i = p, j = 0, j = p, k = 0, k = p
        if (ib) return offset + (j - 1) + e * (k - 1) + (i ? e * e : 0);
        offset += 2 * e * e;
        if (jb) return offset + (i - 1) + e * (k - 1) + (j ? e * e : 0);
        offset += 2 * e * e;
        return offset + (i - 1) + e * (j - 1) + (k ? e * e : 0);
    }
    offset += 6 * e * e;
    return offset + (i - 1) + e * ((j - 1) + e * (k - 1));
}

// Offset of the triangle-interior node (i, j) among the interior nodes of an order-p
// triangle, rows of constant j, i fastest (vtkHigherOrderWedge's triangleDOFOffset).
int TriangleInteriorOffset(int p, int i, int j) {
    return i + p * (j - 1) - j * (j + 1) / 2;
}

// vtkHigherOrderWedge::PointIndexFromIJK with equal orders in the triangle and along k.
int WedgeVtkIndex(int i, int j, int k, int p) {
    const bool ib = i == 0, jb = j == 0, ijb = i + j == p, kb = k == 0 || k == p;
    const int boundaries = ib + jb + ijb + kb;
    const int e = p - 1;
    // Triangle corner 0 = (0,0), 1 = (p,0), 2 = (0,p).
    const int corner = (ib && jb) ? 0 : (jb && ijb ? 1 : 2);
    if (boundaries == 3) return corner + (k ? 3 : 0);
    int offset = 6;
    if (boundaries == 2) {
        if (!kb) return offset + 6 * e + (k - 1) + corner * e;  // vertical edges
        offset += (k == p ? 3 * e : 0);                         // triangle edges
        if (jb) return offset + i - 1;                          // 0 -> 1
        offset += e;
        if (ijb) return offset + j - 1;  // 1 -> 2
        offset += e;
        return offset + (p - j - 1);  // 2 -> 0
    }
    offset += 9 * e;
    const int triangleInterior = (e - 1) * e / 2;
    const int quadInterior = e * e;
    if (boundaries == 1) {
        if (kb)
            return offset + (k > 0 ? triangleInterior : 0) +
                   TriangleInteriorOffset(p, i, j);
        offset += 2 * triangleInterior;
        if (jb) return offset + (i - 1) + e * (k - 1);
        offset += quadInterior;
        if (ijb) return offset + (j - 1) + e * (k - 1);
        offset += quadInterior;
        return offset + (p - j - 1) + e * (k - 1);
    }
    offset += 2 * triangleInterior + 3 * quadInterior;
    return offset + TriangleInteriorOffset(p, i, j) + triangleInterior * (k - 1);
}

// vtkHigherOrderTriangle::Index: barycentric index b (sum = order) to VTK node index.
// Vertices, edges, then the interior recursively as a triangle of order - 3.
int TriangleVtkIndex(const int b[3], int order) {
    int index = 0, max = order, min = 0;
    const int bmin = std::min({b[0], b[1], b[2]});
    while (bmin > min) {
        index += 3 * order;
        max -= 2;
        ++min;
        order -= 3;
    }
    for (int dim = 0; dim < 3; ++dim) {
        if (b[(dim + 2) % 3] == max) return index;
        ++index;
    }
    for (int dim = 0; dim < 3; ++dim) {
        if (b[(dim + 1) % 3] == min) return index + b[dim] - (min + 1);
        index += max - (min + 1);
    }
    return index;
}

// vtkHigherOrderTetra::Index: barycentric index b = (i, j, k, p-i-j-k) to VTK node index.
// Vertices, edges, faces, then the interior recursively as a tet of order - 4.
int TetVtkIndex(const int b[4], int order) {
    static constexpr int kVertexMaxCoord[4] = {3, 0, 1, 2};
    static constexpr int kEdgeMinCoords[6][2] = {{1, 2}, {2, 3}, {0, 2},
                                                 {0, 1}, {1, 3}, {0, 3}};
    static constexpr int kEdgeCountingCoord[6] = {0, 1, 3, 2, 2, 2};
    static constexpr int kFaceMinCoord[4] = {1, 3, 0, 2};
    static constexpr int kFaceCoords[4][3] = {{0, 2, 3}, {2, 0, 1}, {2, 1, 3}, {1, 0, 3}};
    int index = 0, max = order, min = 0;
    const int bmin = std::min({b[0], b[1], b[2], b[3]});
    while (bmin > min) {
        index +=
            2 * (order * order + 1);  // nodes on the boundary of an order-`order` tet
        max -= 3;
        ++min;
        order -= 4;
    }
    for (int vertex = 0; vertex < 4; ++vertex) {
        if (b[kVertexMaxCoord[vertex]] == max) return index;
        ++index;
    }
    for (int edge = 0; edge < 6; ++edge) {
        if (b[kEdgeMinCoords[edge][0]] == min && b[kEdgeMinCoords[edge][1]] == min)
            return index + b[kEdgeCountingCoord[edge]] - (min + 1);
        index += max - (min + 1);
    }
    for (int face = 0; face < 4; ++face) {
        if (b[kFaceMinCoord[face]] == min) {
            int projected[3];
            for (int c = 0; c < 3; ++c) projected[c] = b[kFaceCoords[face][c]] - min;
            return index + TriangleVtkIndex(projected, order) - 3 * order;
        }
        index += (order + 1) * (order + 2) / 2 - 3 * order;
    }
    return index;
}

// Inverts a "VTK index of lattice node" function over the internal lattice.
template <typename IndexOf>
Lattice FromIndexFunction(CellShape shape, int p, IndexOf indexOf) {
    const Lattice& nodes = LatticeNodes(shape, p);
    Lattice out(nodes.size(), LatticeIndex{-1, -1, -1});
    for (const LatticeIndex& ijk : nodes) {
        const int n = indexOf(ijk);
        HPRAY_CHECK_MSG(n >= 0 && n < static_cast<int>(out.size()) && out[n][0] < 0,
                        ShapeName(shape) << " order " << p << " node index " << n);
        out[n] = ijk;
    }
    return out;
}

// hpray's VTK_LAGRANGE_PYRAMID order (documented in vtk_cells.h).
Lattice LagrangePyramidNodes(int p) {
    Lattice out = VertexLattice(CellShape::Pyramid, p);
    for (int t = 1; t < p; ++t) out.push_back({t, 0, 0});          // 0-1
    for (int t = 1; t < p; ++t) out.push_back({p, t, 0});          // 1-2
    for (int t = 1; t < p; ++t) out.push_back({t, p, 0});          // 3-2
    for (int t = 1; t < p; ++t) out.push_back({0, t, 0});          // 0-3
    for (int t = 1; t < p; ++t) out.push_back({0, 0, t});          // 0-4
    for (int t = 1; t < p; ++t) out.push_back({p - t, 0, t});      // 1-4
    for (int t = 1; t < p; ++t) out.push_back({p - t, p - t, t});  // 2-4
    for (int t = 1; t < p; ++t) out.push_back({0, p - t, t});      // 3-4
    for (int j = 1; j < p; ++j)
        for (int i = 1; i < p; ++i) out.push_back({i, j, 0});  // base
    for (int k = 1; k < p; ++k)
        for (int a = 1; a < p - k; ++a) out.push_back({a, 0, k});  // 0-1-4
    for (int k = 1; k < p; ++k)
        for (int a = 1; a < p - k; ++a) out.push_back({p - k, a, k});  // 1-2-4
    for (int k = 1; k < p; ++k)
        for (int a = 1; a < p - k; ++a) out.push_back({a, p - k, k});  // 2-3-4
    for (int k = 1; k < p; ++k)
        for (int a = 1; a < p - k; ++a) out.push_back({0, a, k});  // 3-0-4
    for (int k = 1; k < p; ++k)
        for (int j = 1; j < p - k; ++j)
            for (int i = 1; i < p - k; ++i) out.push_back({i, j, k});  // interior
    return out;
}

// ---------------------------------------------------------------------------------------
// Fixed-node cells: each node is the average of a set of VTK vertices.

using NodeTable = std::vector<std::vector<int>>;

NodeTable Vertices(int count) {
    NodeTable table;
    for (int v = 0; v < count; ++v) table.push_back({v});
    return table;
}

NodeTable Concat(NodeTable a, const NodeTable& b) {
    a.insert(a.end(), b.begin(), b.end());
    return a;
}

const NodeTable& FixedTable(int vtkType) {
    static const NodeTable kHexEdges = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6},
                                        {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
    static const NodeTable kWedgeEdges = {{0, 1}, {1, 2}, {2, 0}, {3, 4}, {4, 5},
                                          {5, 3}, {0, 3}, {1, 4}, {2, 5}};
    static const NodeTable kTet = Vertices(4), kHex = Vertices(8), kWedge = Vertices(6),
                           kPyramid = Vertices(5);
    static const NodeTable kQuadraticTet =
        Concat(kTet, {{0, 1}, {1, 2}, {2, 0}, {0, 3}, {1, 3}, {2, 3}});
    static const NodeTable kQuadraticHex = Concat(kHex, kHexEdges);
    static const NodeTable kTriquadraticHex =
        Concat(kQuadraticHex, {{0, 4, 7, 3},
                               {1, 2, 6, 5},
                               {0, 1, 5, 4},
                               {3, 2, 6, 7},
                               {0, 1, 2, 3},
                               {4, 5, 6, 7},
                               {0, 1, 2, 3, 4, 5, 6, 7}});
    static const NodeTable kQuadraticWedge = Concat(kWedge, kWedgeEdges);
    static const NodeTable kBiquadraticWedge =
        Concat(kQuadraticWedge, {{0, 1, 4, 3}, {1, 2, 5, 4}, {2, 0, 3, 5}});
    static const NodeTable kQuadraticPyramid = Concat(
        kPyramid, {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {0, 4}, {1, 4}, {2, 4}, {3, 4}});
    switch (vtkType) {
        case kVtkTetra:
            return kTet;
        case kVtkHexahedron:
            return kHex;
        case kVtkWedge:
            return kWedge;
        case kVtkPyramid:
            return kPyramid;
        case kVtkQuadraticTetra:
            return kQuadraticTet;
        case kVtkQuadraticHexahedron:
            return kQuadraticHex;
        case kVtkQuadraticWedge:
            return kQuadraticWedge;
        case kVtkQuadraticPyramid:
            return kQuadraticPyramid;
        case kVtkTriquadraticHexahedron:
            return kTriquadraticHex;
        case kVtkBiquadraticQuadraticWedge:
            return kBiquadraticWedge;
    }
    HPRAY_CHECK_MSG(false, "no fixed node table for VTK type " << vtkType);
    return kTet;
}

// The VTK wedges that wind their first triangle like vtkWedge (see vtk_cells.h).
bool IsVtkWedgeWinding(int vtkType) {
    return vtkType == kVtkWedge || vtkType == kVtkQuadraticWedge ||
           vtkType == kVtkBiquadraticQuadraticWedge;
}

// Internal lattice index of every VTK vertex, for order p.
Lattice VtkVertexLattice(int vtkType, CellShape shape, int p) {
    if (IsVtkWedgeWinding(vtkType))
        return {{0, 0, 0}, {0, p, 0}, {p, 0, 0}, {0, 0, p}, {0, p, p}, {p, 0, p}};
    return VertexLattice(shape, p);
}

Lattice FromFixedTable(int vtkType, const CellKind& kind) {
    const Lattice vertices = VtkVertexLattice(vtkType, kind.shape, kind.order);
    Lattice out;
    for (const std::vector<int>& node : FixedTable(vtkType)) {
        LatticeIndex sum{0, 0, 0};
        for (int v : node)
            for (int d = 0; d < 3; ++d) sum[d] += vertices[v][d];
        const int count = static_cast<int>(node.size());
        for (int d = 0; d < 3; ++d) {
            HPRAY_CHECK(sum[d] % count == 0);
            sum[d] /= count;
        }
        out.push_back(sum);
    }
    return out;
}

// ---------------------------------------------------------------------------------------
// Type facts.

const char* VtkTypeName(int vtkType) {
    switch (vtkType) {
        case kVtkTetra:
            return "VTK_TETRA";
        case kVtkHexahedron:
            return "VTK_HEXAHEDRON";
        case kVtkWedge:
            return "VTK_WEDGE";
        case kVtkPyramid:
            return "VTK_PYRAMID";
        case kVtkQuadraticTetra:
            return "VTK_QUADRATIC_TETRA";
        case kVtkQuadraticHexahedron:
            return "VTK_QUADRATIC_HEXAHEDRON";
        case kVtkQuadraticWedge:
            return "VTK_QUADRATIC_WEDGE";
        case kVtkQuadraticPyramid:
            return "VTK_QUADRATIC_PYRAMID";
        case kVtkTriquadraticHexahedron:
            return "VTK_TRIQUADRATIC_HEXAHEDRON";
        case kVtkBiquadraticQuadraticWedge:
            return "VTK_BIQUADRATIC_QUADRATIC_WEDGE";
        case kVtkLagrangeTetrahedron:
            return "VTK_LAGRANGE_TETRAHEDRON";
        case kVtkLagrangeHexahedron:
            return "VTK_LAGRANGE_HEXAHEDRON";
        case kVtkLagrangeWedge:
            return "VTK_LAGRANGE_WEDGE";
        case kVtkLagrangePyramid:
            return "VTK_LAGRANGE_PYRAMID";
    }
    return nullptr;
}

// The kind of a fixed-node type; std::nullopt for Lagrange and unsupported types.
std::optional<CellKind> FixedKind(int vtkType) {
    constexpr auto L = CellFamily::Lagrange;
    constexpr auto S = CellFamily::Serendipity;
    switch (vtkType) {
        case kVtkTetra:
            return CellKind{CellShape::Tet, 1, L};
        case kVtkHexahedron:
            return CellKind{CellShape::Hex, 1, L};
        case kVtkWedge:
            return CellKind{CellShape::Wedge, 1, L};
        case kVtkPyramid:
            return CellKind{CellShape::Pyramid, 1, L};
        case kVtkQuadraticTetra:
            return CellKind{CellShape::Tet, 2, L};
        case kVtkQuadraticHexahedron:
            return CellKind{CellShape::Hex, 2, S};
        case kVtkQuadraticWedge:
            return CellKind{CellShape::Wedge, 2, S};
        case kVtkQuadraticPyramid:
            return CellKind{CellShape::Pyramid, 2, S};
        case kVtkTriquadraticHexahedron:
            return CellKind{CellShape::Hex, 2, L};
        case kVtkBiquadraticQuadraticWedge:
            return CellKind{CellShape::Wedge, 2, L};
    }
    return std::nullopt;
}

std::optional<CellShape> LagrangeShape(int vtkType) {
    switch (vtkType) {
        case kVtkLagrangeTetrahedron:
            return CellShape::Tet;
        case kVtkLagrangeHexahedron:
            return CellShape::Hex;
        case kVtkLagrangeWedge:
            return CellShape::Wedge;
        case kVtkLagrangePyramid:
            return CellShape::Pyramid;
    }
    return std::nullopt;
}

// Node count of the full order-p lattice, in closed form (no allocation, any p >= 1).
long long LagrangeCount(CellShape shape, long long p) {
    switch (shape) {
        case CellShape::Tet:
            return (p + 1) * (p + 2) * (p + 3) / 6;
        case CellShape::Hex:
            return (p + 1) * (p + 1) * (p + 1);
        case CellShape::Wedge:
            return (p + 1) * (p + 1) * (p + 2) / 2;
        case CellShape::Pyramid:
            return (p + 1) * (p + 2) * (2 * p + 3) / 6;
    }
    return 0;
}

bool SameKind(const CellKind& a, const CellKind& b) {
    return a.shape == b.shape && a.order == b.order && a.family == b.family;
}

// InternalError unless (vtkType, kind) is a pair ClassifyVtkCell can return.
void CheckPair(int vtkType, const CellKind& kind) {
    if (auto fixed = FixedKind(vtkType)) {
        HPRAY_CHECK_MSG(SameKind(*fixed, kind),
                        VtkTypeName(vtkType) << " cannot hold a " << ShapeName(kind.shape)
                                             << " of order " << kind.order);
        return;
    }
    auto shape = LagrangeShape(vtkType);
    HPRAY_CHECK_MSG(shape.has_value(), "unsupported VTK cell type " << vtkType);
    HPRAY_CHECK_MSG(*shape == kind.shape && kind.family == CellFamily::Lagrange &&
                        kind.order >= 1 && kind.order <= kMaxOrder,
                    VtkTypeName(vtkType) << " cannot hold a " << ShapeName(kind.shape)
                                         << " of order " << kind.order);
}

// Internal lattice index of every VTK node n (VTK 9 order).
Lattice VtkNodeLattice(int vtkType, const CellKind& kind) {
    CheckPair(vtkType, kind);
    const int p = kind.order;
    switch (vtkType) {
        case kVtkLagrangeHexahedron:
            return FromIndexFunction(CellShape::Hex, p, [p](const LatticeIndex& n) {
                return HexVtkIndex(n[0], n[1], n[2], p);
            });
        case kVtkLagrangeWedge:
            return FromIndexFunction(CellShape::Wedge, p, [p](const LatticeIndex& n) {
                return WedgeVtkIndex(n[0], n[1], n[2], p);
            });
        case kVtkLagrangeTetrahedron:
            return FromIndexFunction(CellShape::Tet, p, [p](const LatticeIndex& n) {
                const int b[4] = {n[0], n[1], n[2], p - n[0] - n[1] - n[2]};
                return TetVtkIndex(b, p);
            });
        case kVtkLagrangePyramid:
            return LagrangePyramidNodes(p);
    }
    return FromFixedTable(vtkType, kind);
}

// VTK 8 -> 9 renumbering of VTK_LAGRANGE_HEXAHEDRON: VTK node m is legacy file node
// LegacyHexFileNode(m). Exchanges the node blocks of edges 10 and 11 (an involution).
int LegacyHexFileNode(int m, int p) {
    const int e = p - 1;
    const int edge10 = 8 + 10 * e, edge11 = 8 + 11 * e;
    if (m >= edge10 && m < edge11) return m + e;
    if (m >= edge11 && m < edge11 + e) return m - e;
    return m;
}

using PermKey = std::tuple<int, int, int, int, bool>;

PermKey MakeKey(int vtkType, const CellKind& kind, bool flag) {
    return {vtkType, static_cast<int>(kind.shape), kind.order,
            static_cast<int>(kind.family), flag};
}

std::vector<int> BuildVtkToInternal(int vtkType, const CellKind& kind, bool legacy) {
    const Lattice lattice = VtkNodeLattice(vtkType, kind);
    const int count = NodeCount(kind.shape, kind.order, kind.family);
    HPRAY_CHECK_EQ(static_cast<int>(lattice.size()), count);
    std::vector<int> perm(count, -1);
    for (int n = 0; n < count; ++n) {
        const int k = InternalNodeIndex(kind.shape, kind.order, kind.family, lattice[n]);
        HPRAY_CHECK_MSG(k >= 0 && perm[k] < 0, VtkTypeName(vtkType)
                                                   << " node " << n << " maps to " << k);
        perm[k] = n;
    }
    if (legacy && vtkType == kVtkLagrangeHexahedron)
        for (int& n : perm) n = LegacyHexFileNode(n, kind.order);
    return perm;
}

std::mutex gCacheMutex;

template <typename Build>
const std::vector<int>& Cached(std::map<PermKey, std::vector<int>>& cache,
                               const PermKey& key, Build build) {
    {
        std::lock_guard<std::mutex> lock(gCacheMutex);
        auto it = cache.find(key);
        if (it != cache.end()) return it->second;
    }
    // Built outside the lock: building may call other cached functions.
    std::vector<int> perm = build();
    std::lock_guard<std::mutex> lock(gCacheMutex);
    return cache.emplace(key, std::move(perm)).first->second;  // map nodes are stable
}

bool Fail(std::string* why, const std::string& message) {
    if (why) *why = message;
    return false;
}

}  // namespace

std::optional<CellKind> ClassifyVtkCell(int vtkType, long long nodeCount,
                                        const int* degrees, std::string* why) {
    std::ostringstream os;
    if (auto fixed = FixedKind(vtkType)) {
        const long long expected = NodeCount(fixed->shape, fixed->order, fixed->family);
        if (nodeCount == expected) return fixed;
        os << VtkTypeName(vtkType) << " (type " << vtkType << ") has " << expected
           << " nodes, the cell has " << nodeCount;
        Fail(why, os.str());
        return std::nullopt;
    }
    auto shape = LagrangeShape(vtkType);
    if (!shape) {
        os << "VTK cell type " << vtkType
           << " is not a supported 3-D cell type (supported: 10, 12, 13, 14, 24, 25, 26, "
              "27, "
              "29, 32, 71, 72, 73, 74)";
        Fail(why, os.str());
        return std::nullopt;
    }
    const char* name = VtkTypeName(vtkType);
    if (degrees) {
        if (degrees[0] != degrees[1] || degrees[1] != degrees[2]) {
            os << name << " with anisotropic HigherOrderDegrees (" << degrees[0] << ", "
               << degrees[1] << ", " << degrees[2] << ") is not supported";
            Fail(why, os.str());
            return std::nullopt;
        }
        const int p = degrees[0];
        if (p < 1 || p > kMaxOrder) {
            os << name << " of HigherOrderDegrees " << p << ": the order must be 1.."
               << kMaxOrder;
            Fail(why, os.str());
            return std::nullopt;
        }
        const long long expected = LagrangeCount(*shape, p);
        if (nodeCount != expected) {
            os << name << ": HigherOrderDegrees say order " << p << " (" << expected
               << " nodes), the cell has " << nodeCount << " nodes";
            Fail(why, os.str());
            return std::nullopt;
        }
        return CellKind{*shape, p, CellFamily::Lagrange};
    }
    // Order from the node count. Counts grow like p^3, so p <= 2000 covers every count a
    // file can hold in memory; larger counts are rejected without searching further.
    for (int p = 1; p <= 2000; ++p) {
        const long long count = LagrangeCount(*shape, p);
        if (count == nodeCount) {
            if (p <= kMaxOrder) return CellKind{*shape, p, CellFamily::Lagrange};
            os << name << " with " << nodeCount << " nodes is of order " << p
               << ", above the supported maximum " << kMaxOrder;
            Fail(why, os.str());
            return std::nullopt;
        }
        if (count > nodeCount) break;
    }
    os << name << " with " << nodeCount
       << " nodes: no order has that many nodes (order p has "
       << (*shape == CellShape::Tet     ? "(p+1)(p+2)(p+3)/6"
           : *shape == CellShape::Hex   ? "(p+1)^3"
           : *shape == CellShape::Wedge ? "(p+1)^2(p+2)/2"
                                        : "(p+1)(p+2)(2p+3)/6")
       << ")";
    if (vtkType == kVtkLagrangeTetrahedron && nodeCount == 15)
        os << "; VTK's special 15-node tetrahedron is not supported";
    if (vtkType == kVtkLagrangeWedge && nodeCount == 21)
        os << "; VTK's special 21-node wedge is not supported";
    Fail(why, os.str());
    return std::nullopt;
}

const std::vector<int>& VtkToInternal(int vtkType, const CellKind& kind,
                                      bool legacyLagrangeHex) {
    static std::map<PermKey, std::vector<int>> cache;
    const bool legacy = legacyLagrangeHex && vtkType == kVtkLagrangeHexahedron;
    return Cached(cache, MakeKey(vtkType, kind, legacy),
                  [&] { return BuildVtkToInternal(vtkType, kind, legacy); });
}

int VtkTypeFor(const CellKind& kind) {
    if (kind.family == CellFamily::Serendipity) {
        HPRAY_CHECK_MSG(kind.order == 2, "serendipity order " << kind.order);
        switch (kind.shape) {
            case CellShape::Hex:
                return kVtkQuadraticHexahedron;
            case CellShape::Wedge:
                return kVtkQuadraticWedge;
            case CellShape::Pyramid:
                return kVtkQuadraticPyramid;
            case CellShape::Tet:
                break;
        }
        HPRAY_CHECK_MSG(false, "no serendipity tetrahedron");
    }
    HPRAY_CHECK_MSG(kind.order >= 1 && kind.order <= kMaxOrder, "order " << kind.order);
    switch (kind.shape) {
        case CellShape::Tet:
            return kVtkLagrangeTetrahedron;
        case CellShape::Hex:
            return kVtkLagrangeHexahedron;
        case CellShape::Wedge:
            return kVtkLagrangeWedge;
        case CellShape::Pyramid:
            return kVtkLagrangePyramid;
    }
    HPRAY_CHECK_MSG(false, "unknown cell shape");
    return 0;
}

const std::vector<int>& InternalToVtk(const CellKind& kind) {
    return InternalToVtk(VtkTypeFor(kind), kind);
}

bool VtkTypeHolds(int vtkType, const CellKind& kind) {
    if (vtkType == kVtkVoxel)
        return SameKind(kind, CellKind{CellShape::Hex, 1, CellFamily::Lagrange});
    if (auto fixed = FixedKind(vtkType)) return SameKind(*fixed, kind);
    auto shape = LagrangeShape(vtkType);
    return shape && *shape == kind.shape && kind.family == CellFamily::Lagrange &&
           kind.order >= 1 && kind.order <= kMaxOrder;
}

int FixedVtkTypeFor(const CellKind& kind) {
    // The fixed-node types, tried in order; 25 is a serendipity hex, 29 a Lagrange one,
    // so at most one matches.
    for (int type :
         {kVtkTetra, kVtkHexahedron, kVtkWedge, kVtkPyramid, kVtkQuadraticTetra,
          kVtkQuadraticHexahedron, kVtkQuadraticWedge, kVtkQuadraticPyramid,
          kVtkTriquadraticHexahedron})
        if (SameKind(*FixedKind(type), kind)) return type;
    return VtkTypeFor(kind);
}

int VtkTypeToWrite(const CellKind& kind, int sourceType) {
    if (sourceType != 0 && VtkTypeHolds(sourceType, kind)) return sourceType;
    if (kind.order == 1 && kind.family == CellFamily::Lagrange)
        return FixedVtkTypeFor(kind);
    return VtkTypeFor(kind);
}

const std::vector<int>& InternalToVtk(int vtkType, const CellKind& kind) {
    static std::map<PermKey, std::vector<int>> cache;
    HPRAY_CHECK_MSG(VtkTypeHolds(vtkType, kind),
                    "VTK type " << vtkType << " cannot hold a " << ShapeName(kind.shape)
                                << " of order " << kind.order);
    return Cached(cache, MakeKey(vtkType, kind, false), [&] {
        if (vtkType == kVtkVoxel) return std::vector<int>{0, 1, 2, 3, 4, 5, 6, 7};
        const std::vector<int>& toInternal = VtkToInternal(vtkType, kind);
        std::vector<int> inverse(toInternal.size());
        for (size_t k = 0; k < toInternal.size(); ++k)
            inverse[toInternal[k]] = static_cast<int>(k);
        return inverse;
    });
}

std::vector<std::array<double, 3>> VtkParametricCoords(int vtkType,
                                                       const CellKind& kind) {
    const Lattice lattice = VtkNodeLattice(vtkType, kind);
    const double p = kind.order;
    std::vector<std::array<double, 3>> coords;
    coords.reserve(lattice.size());
    for (const LatticeIndex& n : lattice) {
        if (kind.shape == CellShape::Pyramid) {
            // Collapsed hexahedron: the square at level k has p - k lattice steps per
            // side.
            const int steps = kind.order - n[2];
            coords.push_back({steps > 0 ? double(n[0]) / steps : 0.0,
                              steps > 0 ? double(n[1]) / steps : 0.0, n[2] / p});
        } else if (IsVtkWedgeWinding(vtkType)) {
            coords.push_back({n[1] / p, n[0] / p, n[2] / p});
        } else {
            coords.push_back({n[0] / p, n[1] / p, n[2] / p});
        }
    }
    return coords;
}

const std::vector<int>& InternalReflection(const CellKind& kind) {
    static std::map<PermKey, std::vector<int>> cache;
    return Cached(cache, MakeKey(-1, kind, false), [&] {
        const Lattice& nodes = LatticeNodes(kind.shape, kind.order, kind.family);
        std::vector<int> m(nodes.size());
        for (size_t k = 0; k < nodes.size(); ++k) {
            m[k] = InternalNodeIndex(kind.shape, kind.order, kind.family,
                                     {nodes[k][1], nodes[k][0], nodes[k][2]});
            HPRAY_CHECK(m[k] >= 0);
        }
        return m;
    });
}

bool VtkXmlHasLegacyLagrangeHex(int major, int minor) {
    return major < 2 || (major == 2 && minor < 1);
}

bool VtkLegacyHasLegacyLagrangeHex(int major, int minor) {
    return major < 5 || (major == 5 && minor < 1);
}

}  // namespace hpray

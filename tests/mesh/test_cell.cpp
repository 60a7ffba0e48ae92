// Internal lattices: node counts against closed forms, reference positions, index lookup.
#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <tuple>

#include "mesh/cell.h"

namespace hpray {
namespace {

const CellShape kShapes[] = {CellShape::Tet, CellShape::Hex, CellShape::Wedge,
                             CellShape::Pyramid};

TEST(CellLattice, NodeCountsMatchClosedForms) {
    for (int p = 1; p <= kMaxOrder; ++p) {
        EXPECT_EQ(NodeCount(CellShape::Tet, p), (p + 1) * (p + 2) * (p + 3) / 6) << p;
        EXPECT_EQ(NodeCount(CellShape::Hex, p), (p + 1) * (p + 1) * (p + 1)) << p;
        EXPECT_EQ(NodeCount(CellShape::Wedge, p), (p + 1) * (p + 1) * (p + 2) / 2) << p;
        EXPECT_EQ(NodeCount(CellShape::Pyramid, p), (p + 1) * (p + 2) * (2 * p + 3) / 6) << p;
    }
    // Counts of the VTK / gmsh serendipity cells.
    EXPECT_EQ(NodeCount(CellShape::Hex, 2, CellFamily::Serendipity), 20);
    EXPECT_EQ(NodeCount(CellShape::Wedge, 2, CellFamily::Serendipity), 15);
    EXPECT_EQ(NodeCount(CellShape::Pyramid, 2, CellFamily::Serendipity), 13);
}

// A point is inside the closed reference cell documented in cell.h.
bool InsideRef(CellShape shape, const std::array<double, 3>& x) {
    const double e = 1e-15;
    const double r = x[0], s = x[1], t = x[2];
    switch (shape) {
        case CellShape::Tet: return r >= -e && s >= -e && t >= -e && r + s + t <= 1 + e;
        case CellShape::Hex: return r >= -e && s >= -e && t >= -e && r <= 1 + e && s <= 1 + e && t <= 1 + e;
        case CellShape::Wedge: return r >= -e && s >= -e && r + s <= 1 + e && t >= -e && t <= 1 + e;
        case CellShape::Pyramid:
            return t >= -e && t <= 1 + e && r >= t / 2 - e && r <= 1 - t / 2 + e &&
                   s >= t / 2 - e && s <= 1 - t / 2 + e;
    }
    return false;
}

TEST(CellLattice, NodesAreDistinctInsideAndSorted) {
    for (CellShape shape : kShapes)
        for (int p = 1; p <= kMaxOrder; ++p) {
            const auto& nodes = LatticeNodes(shape, p);
            std::set<std::array<long long, 3>> seen;
            for (std::size_t k = 0; k < nodes.size(); ++k) {
                const auto x = LatticeRefCoords(shape, p, nodes[k]);
                EXPECT_TRUE(InsideRef(shape, x)) << ShapeName(shape) << p << " node " << k;
                seen.insert({std::llround(x[0] * 2 * p), std::llround(x[1] * 2 * p),
                             std::llround(x[2] * 2 * p)});
                if (k > 0) {
                    const auto& a = nodes[k - 1];
                    const auto& b = nodes[k];
                    EXPECT_TRUE(std::tie(a[2], a[1], a[0]) < std::tie(b[2], b[1], b[0]));
                }
                EXPECT_EQ(InternalNodeIndex(shape, p, CellFamily::Lagrange, nodes[k]),
                          static_cast<int>(k));
            }
            EXPECT_EQ(seen.size(), nodes.size()) << ShapeName(shape) << p;
            EXPECT_EQ(InternalNodeIndex(shape, p, CellFamily::Lagrange, {p + 1, 0, 0}), -1);
        }
}

TEST(CellLattice, VerticesAreReferenceVertices) {
    // Reference vertices as documented in cell.h.
    const std::vector<std::array<double, 3>> tet = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    const std::vector<std::array<double, 3>> pyr = {
        {0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.5, 0.5, 1}};
    for (int p = 1; p <= kMaxOrder; ++p) {
        auto vt = VertexLattice(CellShape::Tet, p);
        for (int v = 0; v < 4; ++v)
            EXPECT_EQ(LatticeRefCoords(CellShape::Tet, p, vt[v]), tet[v]);
        auto vp = VertexLattice(CellShape::Pyramid, p);
        for (int v = 0; v < 5; ++v)
            EXPECT_EQ(LatticeRefCoords(CellShape::Pyramid, p, vp[v]), pyr[v]);
        for (CellShape shape : kShapes)
            for (const auto& v : VertexLattice(shape, p))
                EXPECT_GE(InternalNodeIndex(shape, p, CellFamily::Lagrange, v), 0);
    }
}

TEST(CellLattice, SerendipityKeepsVerticesAndEdgeMidpoints) {
    // Every serendipity node is a vertex or the midpoint of two vertices joined by an edge:
    // at distance 0 or sharing the segment between two reference vertices.
    for (CellShape shape : {CellShape::Hex, CellShape::Wedge, CellShape::Pyramid}) {
        const auto& nodes = LatticeNodes(shape, 2, CellFamily::Serendipity);
        const auto verts = VertexLattice(shape, 2);
        int vertexCount = 0;
        for (const auto& n : nodes)
            for (const auto& v : verts) vertexCount += (n == v);
        EXPECT_EQ(vertexCount, VertexCount(shape)) << ShapeName(shape);
        for (const auto& n : nodes) {
            bool vertexOrMid = false;
            for (std::size_t a = 0; a < verts.size(); ++a)
                for (std::size_t b = a; b < verts.size(); ++b) {
                    const auto ra = LatticeRefCoords(shape, 2, verts[a]);
                    const auto rb = LatticeRefCoords(shape, 2, verts[b]);
                    const auto rn = LatticeRefCoords(shape, 2, n);
                    bool mid = true;
                    for (int d = 0; d < 3; ++d) mid &= std::abs(rn[d] - 0.5 * (ra[d] + rb[d])) < 1e-15;
                    vertexOrMid |= mid;
                }
            EXPECT_TRUE(vertexOrMid) << ShapeName(shape);
        }
    }
}

}  // namespace
}  // namespace hpray

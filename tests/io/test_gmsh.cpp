// Tests of gmsh node orderings (against gmsh's own reference coordinates) and the MSH 4.1
// reader (real gmsh meshes, hand-written ASCII and binary files, malformed inputs).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <numeric>
#include <set>
#include <string>
#include <vector>

#include "io/gmsh_nodes.h"
#include "io/mesh_io.h"
#include "mesh/cell.h"
#include "util/error.h"

namespace hpray {
namespace {

using Vec3 = std::array<double, 3>;
using nlohmann::json;

const double kPi = 3.14159265358979323846;

// The analytic field of ../shared/data/README.md.
double Analytic(double x, double y, double z) {
    return std::sin(3 * x) * std::cos(2 * y) + 0.5 * std::sin(4 * z + x * y);
}

json LoadJson(const std::string& path) {
    std::ifstream in(path);
    EXPECT_TRUE(in.good()) << path;
    return json::parse(in);
}

// gmsh's reference coordinates per type, from gmsh's API
// (scripts/gen_gmsh_reference_nodes.py).
std::map<int, std::vector<Vec3>> GmshTruth() {
    std::map<int, std::vector<Vec3>> out;
    const json j = LoadJson(HPRAY_TEST_DATA "/gmsh_reference_nodes.json");
    for (const auto& [key, value] : j.at("element_types").items()) {
        const std::vector<double> c = value.at("coords").get<std::vector<double>>();
        std::vector<Vec3>& v = out[std::stoi(key)];
        for (std::size_t i = 0; i + 2 < c.size(); i += 3)
            v.push_back({c[i], c[i + 1], c[i + 2]});
        EXPECT_EQ(static_cast<int>(v.size()), value.at("nodes_per_element").get<int>());
    }
    return out;
}

// Maps gmsh's reference cell onto hpray's (cell.h): hex [-1,1]^3 -> [0,1]^3, prism
// z in [-1,1] -> [0,1], pyramid base [-1,1]^2 -> [0,1]^2 (apex (0,0,1) -> (1/2,1/2,1)).
Vec3 ToInternalRef(CellShape shape, const Vec3& x) {
    switch (shape) {
        case CellShape::Tet:
            return x;
        case CellShape::Hex:
            return {0.5 * (x[0] + 1), 0.5 * (x[1] + 1), 0.5 * (x[2] + 1)};
        case CellShape::Wedge:
            return {x[0], x[1], 0.5 * (x[2] + 1)};
        case CellShape::Pyramid:
            return {0.5 * (x[0] + 1), 0.5 * (x[1] + 1), x[2]};
    }
    return x;
}

std::vector<int> AllSupportedTypes() {
    std::vector<int> types;
    for (int t = 1; t <= 140; ++t)
        if (ClassifyGmshType(t)) types.push_back(t);
    return types;
}

// ---------------------------------------------------------------- node orderings

TEST(GmshNodes, SupportedTypesAreTheDocumentedOnes) {
    const std::vector<int> expect = {4,   5,   6,   7,   11,  12,  13,  14,  17,  18,
                                     19,  29,  30,  31,  71,  72,  73,  74,  75,  90,
                                     91,  92,  93,  94,  95,  96,  97,  98,  106, 107,
                                     108, 109, 110, 118, 119, 120, 121, 122, 123, 124};
    EXPECT_EQ(AllSupportedTypes(), expect);
    // Incomplete, order-0 and lower-dimensional types are not cells hpray reads.
    for (int t : {1, 2, 3, 8, 9, 10, 15, 16, 32, 33, 79, 87, 88, 99, 111, 125, 132, 137})
        EXPECT_FALSE(ClassifyGmshType(t)) << t;
    EXPECT_EQ(GmshTypeNodeCount(15), 1);   // point
    EXPECT_EQ(GmshTypeNodeCount(1), 2);    // line
    EXPECT_EQ(GmshTypeNodeCount(2), 3);    // triangle
    EXPECT_EQ(GmshTypeNodeCount(3), 4);    // quadrangle
    EXPECT_EQ(GmshTypeNodeCount(21), 10);  // cubic triangle
    EXPECT_EQ(GmshTypeDimension(36), 2);   // 16-node quadrangle
    EXPECT_EQ(GmshTypeNodeCount(0), -1);
    EXPECT_EQ(GmshTypeNodeCount(999), -1);
    EXPECT_EQ(GmshTypeNodeCount(34), -1);  // polygon: no fixed size
}

// gmsh walks the faces of the reference cells in its own order and from its own first
// corners; as sets of oriented cycles they are the faces of the one table (Topology).
TEST(GmshNodes, FacesAreTheReferenceCellsFacesWithTheirOrientation) {
    for (CellShape shape :
         {CellShape::Tet, CellShape::Hex, CellShape::Wedge, CellShape::Pyramid}) {
        const CellTopology& t = Topology(shape);
        const auto gmsh = GmshFaceCorners(shape);
        ASSERT_EQ(static_cast<int>(gmsh.size()), t.faces);
        std::vector<int> matched(t.faces, 0);
        for (const auto& cycle : gmsh) {
            int found = -1;
            for (int f = 0; f < t.faces && found < 0; ++f) {
                if (t.faceSize[f] != static_cast<int>(cycle.size())) continue;
                const int n = t.faceSize[f];
                for (int r = 0; r < n && found < 0; ++r) {
                    bool same = true;
                    for (int k = 0; k < n; ++k) {
                        const int* c = t.lattice[t.face[f][(r + k) % n]];
                        same &= cycle[k] == LatticeIndex{c[0], c[1], c[2]};
                    }
                    if (same) found = f;
                }
            }
            ASSERT_GE(found, 0) << "shape " << static_cast<int>(shape);
            ++matched[found];
        }
        for (int f = 0; f < t.faces; ++f) EXPECT_EQ(matched[f], 1) << f;
    }
}

TEST(GmshNodes, NodeCountsMatchShapeOrderAndFamily) {
    for (int t : AllSupportedTypes()) {
        const GmshCellType k = *ClassifyGmshType(t);
        EXPECT_EQ(k.nodeCount, NodeCount(k.shape, k.order, k.family)) << t;
        EXPECT_EQ(k.nodeCount, GmshTypeNodeCount(t)) << t;
        EXPECT_EQ(GmshTypeDimension(t), 3) << t;
    }
    // Closed forms of the complete Lagrange counts.
    for (int p = 1; p <= 9; ++p) {
        const int prism = (p + 1) * (p + 1) * (p + 2) / 2;
        const int pyramid = (p + 1) * (p + 2) * (2 * p + 3) / 6;
        bool foundPrism = false, foundPyramid = false;
        for (int t : AllSupportedTypes()) {
            const GmshCellType k = *ClassifyGmshType(t);
            if (k.order != p || k.family != CellFamily::Lagrange) continue;
            if (k.shape == CellShape::Wedge) foundPrism = k.nodeCount == prism;
            if (k.shape == CellShape::Pyramid) foundPyramid = k.nodeCount == pyramid;
        }
        EXPECT_TRUE(foundPrism && foundPyramid) << p;
    }
}

TEST(GmshNodes, ReferenceCoordsEqualGmshApi) {
    const auto truth = GmshTruth();
    EXPECT_EQ(truth.size(), 33u);
    for (const auto& [type, expect] : truth) {
        ASSERT_TRUE(ClassifyGmshType(type)) << type;
        const auto got = GmshReferenceCoords(type);
        ASSERT_EQ(got.size(), expect.size()) << type;
        for (std::size_t n = 0; n < got.size(); ++n)
            for (int c = 0; c < 3; ++c)
                ASSERT_NEAR(got[n][c], expect[n][c], 1e-14)
                    << "type " << type << " node " << n << " coordinate " << c;
    }
}

// The nodes.json files beside the real meshes store gmsh's coordinates rounded to 12
// decimals, so "equal" means equal after that rounding (|difference| <= 0.5e-12).
TEST(GmshNodes, ReferenceCoordsEqualSharedNodesJson) {
    int checked = 0;
    for (const char* name :
         {"gmsh_pripyrtet_p2.nodes.json", "gmsh_hybrid_pyr_p3.nodes.json"}) {
        const json j = LoadJson(std::string(HPRAY_SHARED_DATA) + "/" + name);
        for (const auto& [key, value] : j.at("element_types").items()) {
            const int type = std::stoi(key);
            const auto got = GmshReferenceCoords(type);
            const auto& expect = value.at("gmsh_reference_node_coords");
            ASSERT_EQ(got.size(), expect.size()) << name << " type " << type;
            EXPECT_EQ(ClassifyGmshType(type)->order, value.at("order").get<int>());
            for (std::size_t n = 0; n < got.size(); ++n)
                for (int c = 0; c < 3; ++c)
                    ASSERT_NEAR(got[n][c], expect[n][c].get<double>(), 0.5e-12 + 1e-16)
                        << name << " type " << type << " node " << n;
            ++checked;
        }
    }
    EXPECT_EQ(checked, 6);
}

TEST(GmshNodes, PermutationsAreBijectionsOntoTheInternalLattice) {
    for (int t : AllSupportedTypes()) {
        const GmshCellType k = *ClassifyGmshType(t);
        const std::vector<int>& perm = GmshToInternal(t);
        ASSERT_EQ(static_cast<int>(perm.size()), k.nodeCount) << t;
        std::vector<int> sorted = perm;
        std::sort(sorted.begin(), sorted.end());
        for (int i = 0; i < k.nodeCount; ++i) ASSERT_EQ(sorted[i], i) << t;
        // Internal node i sits where gmsh's node perm[i] sits: compare gmsh's reference
        // coordinates (mapped to hpray's reference cell) with the internal lattice point.
        const auto& lattice = LatticeNodes(k.shape, k.order, k.family);
        const auto gmshRef = GmshReferenceCoords(t);
        for (int i = 0; i < k.nodeCount; ++i) {
            const Vec3 want = LatticeRefCoords(k.shape, k.order, lattice[i]);
            const Vec3 got = ToInternalRef(k.shape, gmshRef[perm[i]]);
            const Vec3 viaLib = GmshRefToInternal(k.shape, gmshRef[perm[i]]);
            for (int c = 0; c < 3; ++c) {
                ASSERT_NEAR(got[c], want[c], 1e-14)
                    << "type " << t << " internal node " << i;
                ASSERT_NEAR(viaLib[c], want[c], 1e-14) << t;
            }
            EXPECT_EQ(GmshNodeLattice(t)[perm[i]], lattice[i]) << t;
        }
    }
}

// Properties of gmsh's node order that hold for every type (including the prisms of order
// >= 3, which gmsh 4.8 cannot generate): vertices first in gmsh's vertex order, then the
// interior nodes of each edge, equispaced from the edge's first vertex to its second.
TEST(GmshNodes, VerticesThenEdgesForEveryType) {
    const std::map<CellShape, std::vector<Vec3>> vertices = {
        {CellShape::Tet, {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}},
        {CellShape::Hex,
         {{-1, -1, -1},
          {1, -1, -1},
          {1, 1, -1},
          {-1, 1, -1},
          {-1, -1, 1},
          {1, -1, 1},
          {1, 1, 1},
          {-1, 1, 1}}},
        {CellShape::Wedge,
         {{0, 0, -1}, {1, 0, -1}, {0, 1, -1}, {0, 0, 1}, {1, 0, 1}, {0, 1, 1}}},
        {CellShape::Pyramid,
         {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}, {0, 0, 1}}}};
    const std::map<CellShape, std::vector<std::array<int, 2>>> edges = {
        {CellShape::Tet, {{0, 1}, {1, 2}, {2, 0}, {3, 0}, {3, 2}, {3, 1}}},
        {CellShape::Hex,
         {{0, 1},
          {0, 3},
          {0, 4},
          {1, 2},
          {1, 5},
          {2, 3},
          {2, 6},
          {3, 7},
          {4, 5},
          {4, 7},
          {5, 6},
          {6, 7}}},
        {CellShape::Wedge,
         {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 4}, {2, 5}, {3, 4}, {3, 5}, {4, 5}}},
        {CellShape::Pyramid,
         {{0, 1}, {0, 3}, {0, 4}, {1, 2}, {1, 4}, {2, 3}, {2, 4}, {3, 4}}}};
    for (int t : AllSupportedTypes()) {
        const GmshCellType k = *ClassifyGmshType(t);
        const auto x = GmshReferenceCoords(t);
        const auto& v = vertices.at(k.shape);
        for (std::size_t i = 0; i < v.size(); ++i)
            for (int c = 0; c < 3; ++c) ASSERT_NEAR(x[i][c], v[i][c], 1e-15) << t;
        std::size_t n = v.size();
        for (const auto& e : edges.at(k.shape))
            for (int i = 1; i < k.order; ++i, ++n)
                for (int c = 0; c < 3; ++c) {
                    const double s = static_cast<double>(i) / k.order;
                    ASSERT_NEAR(x[n][c], v[e[0]][c] + s * (v[e[1]][c] - v[e[0]][c]),
                                1e-14)
                        << "type " << t << " node " << n;
                }
        // Distinct nodes.
        std::set<std::array<long long, 3>> seen;
        for (const Vec3& p : x)
            seen.insert({std::llround(p[0] * 1e9), std::llround(p[1] * 1e9),
                         std::llround(p[2] * 1e9)});
        EXPECT_EQ(seen.size(), x.size()) << t;
    }
}

// ---------------------------------------------------------------- real gmsh meshes

struct Counts {
    std::int64_t points = 0;
    std::map<std::pair<CellShape, int>, std::int64_t> cells;  // (shape, node count) -> n
};

Counts Count(const Mesh& m) {
    Counts c;
    c.points = m.PointCount();
    for (std::int64_t i = 0; i < m.CellCount(); ++i)
        ++c.cells[{m.cellShape[i], m.CellNodeCount(i)}];
    return c;
}

void ExpectAnalytic(const Mesh& m) {
    const Field* f = m.FindPointField("analytic");
    ASSERT_NE(f, nullptr);
    ASSERT_EQ(f->components, 1);
    double worst = 0;
    for (std::int64_t i = 0; i < m.PointCount(); ++i) {
        const double* x = &m.points[3 * i];
        worst = std::max(worst, std::abs(f->values[i] - Analytic(x[0], x[1], x[2])));
    }
    EXPECT_LT(worst, 1e-12);
}

// Affine map fitted on four internal vertices; returns max |x_k - (A xi_k + b)| over
// nodes.
struct Affine {
    double a[3][3];
    Vec3 b;
    double det;
};

Affine FitAffine(const std::array<Vec3, 4>& xi, const std::array<Vec3, 4>& x) {
    // Solve A [xi1-xi0, xi2-xi0, xi3-xi0] = [x1-x0, x2-x0, x3-x0].
    double m[3][3], q[3][3];
    for (int j = 0; j < 3; ++j)
        for (int r = 0; r < 3; ++r) {
            m[r][j] = xi[j + 1][r] - xi[0][r];
            q[r][j] = x[j + 1][r] - x[0][r];
        }
    const double dm = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
                      m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                      m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    double inv[3][3];
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) {
            const int r1 = (c + 1) % 3, r2 = (c + 2) % 3, c1 = (r + 1) % 3,
                      c2 = (r + 2) % 3;
            inv[r][c] = (m[r1][c1] * m[r2][c2] - m[r1][c2] * m[r2][c1]) / dm;
        }
    Affine f{};
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) {
            f.a[r][c] = 0;
            for (int k = 0; k < 3; ++k) f.a[r][c] += q[r][k] * inv[k][c];
        }
    for (int r = 0; r < 3; ++r) {
        f.b[r] = x[0][r];
        for (int c = 0; c < 3; ++c) f.b[r] -= f.a[r][c] * xi[0][c];
    }
    f.det = f.a[0][0] * (f.a[1][1] * f.a[2][2] - f.a[1][2] * f.a[2][1]) -
            f.a[0][1] * (f.a[1][0] * f.a[2][2] - f.a[1][2] * f.a[2][0]) +
            f.a[0][2] * (f.a[1][0] * f.a[2][1] - f.a[1][1] * f.a[2][0]);
    return f;
}

Vec3 Apply(const Affine& f, const Vec3& xi) {
    Vec3 r;
    for (int i = 0; i < 3; ++i)
        r[i] = f.b[i] + f.a[i][0] * xi[0] + f.a[i][1] * xi[1] + f.a[i][2] * xi[2];
    return r;
}

// Four affinely independent vertices of each shape, as internal lattice indices.
std::array<LatticeIndex, 4> FrameVertices(CellShape s, int p) {
    (void)s;  // the same lattice indices are vertices of every shape
    return {{{0, 0, 0}, {p, 0, 0}, {0, p, 0}, {0, 0, p}}};
}

// For each cell: the affine map through four of its vertices, applied to the internal
// lattice, against the cell's nodes `x` (given by `position`). Returns the worst distance
// relative to the cell's size, and checks the orientation is positive.
template <typename Position>
double WorstAffineDeviation(const Mesh& m, Position position) {
    double worst = 0;
    for (std::int64_t c = 0; c < m.CellCount(); ++c) {
        const CellShape s = m.cellShape[c];
        const int p = m.cellOrder[c];
        const CellFamily fam = m.cellFamily[c];
        const auto& lattice = LatticeNodes(s, p, fam);
        const std::int64_t* nodes = m.CellNodes(c);
        std::array<Vec3, 4> xi, x;
        const auto frame = FrameVertices(s, p);
        for (int v = 0; v < 4; ++v) {
            xi[v] = LatticeRefCoords(s, p, frame[v]);
            x[v] = position(nodes[InternalNodeIndex(s, p, fam, frame[v])]);
        }
        const Affine f = FitAffine(xi, x);
        EXPECT_GT(f.det, 0) << "cell " << c << " is inverted";
        double size = 0;
        for (int v = 1; v < 4; ++v)
            size = std::max(size, std::hypot(x[v][0] - x[0][0], x[v][1] - x[0][1],
                                             x[v][2] - x[0][2]));
        for (std::size_t k = 0; k < lattice.size(); ++k) {
            const Vec3 want = Apply(f, LatticeRefCoords(s, p, lattice[k]));
            const Vec3 got = position(nodes[k]);
            worst = std::max(
                worst,
                std::hypot(got[0] - want[0], got[1] - want[1], got[2] - want[2]) / size);
        }
    }
    return worst;
}

// The order-1 map of a cell through its vertices (internal reference coordinates xi):
// barycentric (tet), trilinear (hex), linear x linear (wedge), and for the pyramid the
// bilinear base square shrunk towards the apex.
Vec3 VertexMap(CellShape s, const Vec3& xi, const std::vector<Vec3>& v) {
    std::vector<double> w;
    const double r = xi[0], q = xi[1], t = xi[2];
    switch (s) {
        case CellShape::Tet:
            w = {1 - r - q - t, r, q, t};
            break;
        case CellShape::Hex:  // v in lattice order (0,0,0) (1,0,0) (0,1,0) (1,1,0) ...
            w = {(1 - r) * (1 - q) * (1 - t),
                 r * (1 - q) * (1 - t),
                 (1 - r) * q * (1 - t),
                 r * q * (1 - t),
                 (1 - r) * (1 - q) * t,
                 r * (1 - q) * t,
                 (1 - r) * q * t,
                 r * q * t};
            break;
        case CellShape::Wedge:
            w = {(1 - r - q) * (1 - t), r * (1 - t), q * (1 - t),
                 (1 - r - q) * t,       r * t,       q * t};
            break;
        case CellShape::Pyramid: {
            const double u = t < 1 ? (r - t / 2) / (1 - t) : 0.5;
            const double z = t < 1 ? (q - t / 2) / (1 - t) : 0.5;
            w = {(1 - u) * (1 - z) * (1 - t), u * (1 - z) * (1 - t),
                 (1 - u) * z * (1 - t), u * z * (1 - t), t};
            break;
        }
    }
    Vec3 x{0, 0, 0};
    for (std::size_t i = 0; i < w.size(); ++i)
        for (int c = 0; c < 3; ++c) x[c] += w[i] * v[i][c];
    return x;
}

// Worst distance, relative to the cell's longest vertex-to-vertex distance, of a node
// from the position the cell's vertices alone give it.
double WorstVertexMapDeviation(const Mesh& m) {
    double worst = 0;
    for (std::int64_t c = 0; c < m.CellCount(); ++c) {
        const CellShape s = m.cellShape[c];
        const int p = m.cellOrder[c];
        const auto& lattice = LatticeNodes(s, p, m.cellFamily[c]);
        const std::int64_t* nodes = m.CellNodes(c);
        std::vector<Vec3> v;  // vertices in the order of the order-1 lattice
        for (const LatticeIndex& l1 : LatticeNodes(s, 1)) {
            const LatticeIndex l{l1[0] * p, l1[1] * p, l1[2] * p};
            const std::int64_t i = nodes[InternalNodeIndex(s, p, m.cellFamily[c], l)];
            v.push_back({m.points[3 * i], m.points[3 * i + 1], m.points[3 * i + 2]});
        }
        double size = 0;
        for (const Vec3& a : v)
            for (const Vec3& b : v)
                size = std::max(size, std::hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]));
        for (std::size_t k = 0; k < lattice.size(); ++k) {
            const Vec3 want = VertexMap(s, LatticeRefCoords(s, p, lattice[k]), v);
            const double* got = &m.points[3 * nodes[k]];
            worst = std::max(
                worst,
                std::hypot(got[0] - want[0], got[1] - want[1], got[2] - want[2]) / size);
        }
    }
    return worst;
}

// A minimal reader of ASCII MSH 4.1 nodes and 3-D elements, for checking the reader's
// node order against gmsh's reference coordinates of the nodes.json files.
struct RawMsh {
    std::map<long long, Vec3> nodes;
    std::vector<std::pair<int, std::vector<long long>>> elements;  // 3-D: type, node tags
};

RawMsh ReadRawMsh(const std::string& path) {
    std::ifstream in(path);
    RawMsh raw;
    std::string word;
    while (in >> word) {
        if (word == "$Nodes") {
            long long blocks, n, lo, hi;
            in >> blocks >> n >> lo >> hi;
            for (long long b = 0; b < blocks; ++b) {
                int dim, tag, parametric;
                long long count;
                in >> dim >> tag >> parametric >> count;
                std::vector<long long> tags(count);
                for (auto& t : tags) in >> t;
                for (long long t : tags) {
                    Vec3& x = raw.nodes[t];
                    in >> x[0] >> x[1] >> x[2];
                    double skip;
                    for (int i = 0; i < (parametric ? dim : 0); ++i) in >> skip;
                }
            }
        } else if (word == "$Elements") {
            long long blocks, n, lo, hi;
            in >> blocks >> n >> lo >> hi;
            for (long long b = 0; b < blocks; ++b) {
                int dim, tag, type;
                long long count;
                in >> dim >> tag >> type >> count;
                const int nodes = GmshTypeNodeCount(type);
                for (long long e = 0; e < count; ++e) {
                    long long elementTag;
                    std::vector<long long> v(nodes);
                    in >> elementTag;
                    for (auto& t : v) in >> t;
                    if (dim == 3) raw.elements.push_back({type, v});
                }
            }
        }
    }
    return raw;
}

// Each internal node k of each cell is the file node whose gmsh reference coordinates
// (nodes.json, mapped to hpray's reference cell) are the lattice point of k.
void ExpectOrderMatchesNodesJson(const Mesh& m, const std::string& msh,
                                 const std::string& nodesJson) {
    const RawMsh raw = ReadRawMsh(msh);
    const json j = LoadJson(nodesJson);
    ASSERT_EQ(static_cast<std::int64_t>(raw.elements.size()), m.CellCount());
    for (std::int64_t c = 0; c < m.CellCount(); ++c) {
        const auto& [type, tags] = raw.elements[c];
        const auto& ref = j.at("element_types")
                              .at(std::to_string(type))
                              .at("gmsh_reference_node_coords");
        const CellShape s = m.cellShape[c];
        const auto& lattice = LatticeNodes(s, m.cellOrder[c], m.cellFamily[c]);
        ASSERT_EQ(ref.size(), lattice.size());
        for (std::size_t n = 0; n < ref.size(); ++n) {
            const Vec3 r =
                ToInternalRef(s, {ref[n][0].get<double>(), ref[n][1].get<double>(),
                                  ref[n][2].get<double>()});
            std::size_t k = 0;
            for (; k < lattice.size(); ++k) {
                const Vec3 l = LatticeRefCoords(s, m.cellOrder[c], lattice[k]);
                if (std::abs(l[0] - r[0]) + std::abs(l[1] - r[1]) +
                        std::abs(l[2] - r[2]) <
                    1e-9)
                    break;
            }
            ASSERT_LT(k, lattice.size()) << "type " << type << " node " << n;
            const Vec3& want = raw.nodes.at(tags[n]);
            const double* got = &m.points[3 * m.CellNodes(c)[k]];
            ASSERT_EQ(got[0], want[0]) << "cell " << c << " gmsh node " << n;
            ASSERT_EQ(got[1], want[1]) << "cell " << c << " gmsh node " << n;
            ASSERT_EQ(got[2], want[2]) << "cell " << c << " gmsh node " << n;
        }
    }
}

TEST(GmshReader, PriPyrTetP2) {
    const std::string path = std::string(HPRAY_SHARED_DATA) + "/gmsh_pripyrtet_p2.msh";
    const Mesh m = ReadGmsh(path, {});
    const Counts c = Count(m);
    EXPECT_EQ(c.points, 805);
    EXPECT_EQ(m.CellCount(), 12 + 135 + 15);
    EXPECT_EQ((c.cells.at({CellShape::Tet, 10})), 12);
    EXPECT_EQ((c.cells.at({CellShape::Wedge, 18})), 135);
    EXPECT_EQ((c.cells.at({CellShape::Pyramid, 14})), 15);
    EXPECT_EQ(c.cells.size(), 3u);
    for (std::int64_t i = 0; i < m.CellCount(); ++i) EXPECT_EQ(m.cellOrder[i], 2);
    ExpectAnalytic(m);
    ExpectOrderMatchesNodesJson(
        m, path, std::string(HPRAY_SHARED_DATA) + "/gmsh_pripyrtet_p2.nodes.json");
    // Curved, but every node is near where the cell's vertices alone put it, and every
    // cell is positively oriented. (Some thin pyramids on the curved boundary are bent so
    // much that a node sits nearer to a neighbour's straight-sided position than to its
    // own: nearest-position matching cannot test the order on this file.)
    EXPECT_LT(WorstVertexMapDeviation(m), 0.2);
    WorstAffineDeviation(m, [&](std::int64_t i) {
        return Vec3{m.points[3 * i], m.points[3 * i + 1], m.points[3 * i + 2]};
    });
}

// The inverse of the bending map of gmsh_hybrid_pyr.geo (README): (x, y, z) with
// theta = -(pi/4) x, r = 1.5 + y maps to (r cos theta, r sin theta, z + 0.15 sin(pi x)).
Vec3 Unbend(const double* X) {
    const double r = std::hypot(X[0], X[1]);
    const double theta = std::atan2(X[1], X[0]);
    const double x = -4 * theta / kPi;
    return {x, r - 1.5, X[2] - 0.15 * std::sin(kPi * x)};
}

TEST(GmshReader, HybridPyrP3) {
    const std::string path = std::string(HPRAY_SHARED_DATA) + "/gmsh_hybrid_pyr_p3.msh";
    const Mesh m = ReadGmsh(path, {});
    const Counts c = Count(m);
    EXPECT_EQ(c.points, 19609);
    EXPECT_EQ((c.cells.at({CellShape::Tet, 20})), 1779);
    EXPECT_EQ((c.cells.at({CellShape::Hex, 64})), 324);
    EXPECT_EQ((c.cells.at({CellShape::Pyramid, 30})), 36);
    EXPECT_EQ(c.cells.size(), 3u);
    for (std::int64_t i = 0; i < m.CellCount(); ++i) EXPECT_EQ(m.cellOrder[i], 3);
    ExpectAnalytic(m);
    // Every node is in the image of the bent box [0,2] x [0,1] x [0,1.3].
    for (std::int64_t i = 0; i < m.PointCount(); ++i) {
        const double r = std::hypot(m.points[3 * i], m.points[3 * i + 1]);
        ASSERT_GE(r, 1.5 - 1e-12) << i;
        ASSERT_LE(r, 2.5 + 1e-12) << i;
        const Vec3 q = Unbend(&m.points[3 * i]);
        ASSERT_GE(q[0], -1e-12);
        ASSERT_LE(q[0], 2 + 1e-12);
        ASSERT_GE(q[2], -1e-12);
        ASSERT_LE(q[2], 1.3 + 1e-12);
    }
    ExpectOrderMatchesNodesJson(
        m, path, std::string(HPRAY_SHARED_DATA) + "/gmsh_hybrid_pyr_p3.nodes.json");
    // The pre-image mesh is straight-sided, so the pulled-back nodes of each cell, in
    // internal order, are an affine image of the internal lattice.
    const double worst =
        WorstAffineDeviation(m, [&](std::int64_t i) { return Unbend(&m.points[3 * i]); });
    EXPECT_LT(worst, 1e-9);
}

// Files as gmsh writes them when partitioned (scripts/gen_gmsh_fixtures.py): counts from
// gmsh's API, straight-sided quadratic tetrahedra of a box, the analytic field.
void CheckPartitioned(const std::string& name) {
    SCOPED_TRACE(name);
    const json info = LoadJson(HPRAY_TEST_DATA "/gmsh_partitioned.json");
    const Mesh m = ReadGmsh(std::string(HPRAY_TEST_DATA) + "/" + name, {});
    EXPECT_EQ(m.PointCount(), info.at("nodes").get<std::int64_t>());
    EXPECT_EQ(m.CellCount(), info.at("elements_by_type").at("11").get<std::int64_t>());
    for (std::int64_t c = 0; c < m.CellCount(); ++c) {
        EXPECT_EQ(m.cellShape[c], CellShape::Tet);
        EXPECT_EQ(m.cellOrder[c], 2);
    }
    const std::vector<double> first =
        info.at("first_node").at("xyz").get<std::vector<double>>();
    bool found = false;
    for (std::int64_t i = 0; i < m.PointCount(); ++i)
        found =
            found || (m.points[3 * i] == first[0] && m.points[3 * i + 1] == first[1] &&
                      m.points[3 * i + 2] == first[2]);
    EXPECT_TRUE(found);
    ExpectAnalytic(m);
    const double worst = WorstAffineDeviation(m, [&](std::int64_t i) {
        return Vec3{m.points[3 * i], m.points[3 * i + 1], m.points[3 * i + 2]};
    });
    EXPECT_LT(worst, 1e-12);
}

TEST(GmshReader, PartitionedBinaryWrittenByGmsh) {
    CheckPartitioned("gmsh_partitioned_binary.msh");
}
TEST(GmshReader, PartitionedAsciiWrittenByGmsh) {
    CheckPartitioned("gmsh_partitioned_ascii.msh");
}

TEST(GmshReader, FieldSelection) {
    const std::string path = std::string(HPRAY_SHARED_DATA) + "/gmsh_pripyrtet_p2.msh";
    ReadOptions none;
    none.fields = std::set<std::string>{"u"};
    EXPECT_TRUE(ReadGmsh(path, none).pointFields.empty());
    ReadOptions one;
    one.fields = std::set<std::string>{"analytic"};
    EXPECT_EQ(ReadGmsh(path, one).pointFields.size(), 1u);
    // Through the dispatcher too.
    EXPECT_EQ(ReadMesh(path).PointCount(), 805);
}

// ---------------------------------------------------------------- files made here

// Writes MSH 4.1 content as ASCII or binary (optionally byte-swapped: a big-endian file).
class MshWriter {
  public:
    MshWriter(bool binary, bool swap = false) : binary_(binary), swap_(swap) {}
    void Text(const std::string& s) { out_ += s; }
    void Size(std::uint64_t v) { binary_ ? Raw(v) : Word(std::to_string(v)); }
    void Int(std::int32_t v) { binary_ ? Raw(v) : Word(std::to_string(v)); }
    void Double(double v) {
        if (binary_) return Raw(v);
        char b[40];
        std::snprintf(b, sizeof b, "%.17g", v);
        Word(b);
    }
    void Eol() {
        if (!binary_) out_ += '\n';
    }
    void Header(const std::string& section) { out_ += "$" + section + "\n"; }
    void Footer(const std::string& section) {
        if (binary_) out_ += "\n";
        out_ += "$End" + section + "\n";
    }
    void Format() {
        out_ += binary_ ? "$MeshFormat\n4.1 1 8\n" : "$MeshFormat\n4.1 0 8\n";
        if (binary_) {
            Int(1);
            out_ += "\n";
        }
        out_ += "$EndMeshFormat\n";
    }
    const std::string& str() const { return out_; }
    bool binary() const { return binary_; }

  private:
    template <typename T>
    void Raw(T v) {
        char b[sizeof(T)];
        std::memcpy(b, &v, sizeof(T));
        if (swap_) std::reverse(b, b + sizeof(T));
        out_.append(b, sizeof(T));
    }
    void Word(const std::string& w) {
        if (!out_.empty() && out_.back() != '\n') out_ += ' ';
        out_ += w;
    }
    bool binary_, swap_;
    std::string out_;
};

std::string WriteTemp(const std::string& name, const std::string& content) {
    const std::string path = testing::TempDir() + "hpray_" + name;
    std::ofstream out(path, std::ios::binary);
    out << content;
    return path;
}

// One element of every type gmsh reports coordinates for, its nodes at gmsh's reference
// coordinates mapped to hpray's reference cell and shifted by 3 * (element index) in x.
// Node tags are sparse (17 + 5 * i); lower-dimensional elements, a parametric curve node
// block, entities, physical names and an unknown section are mixed in.
struct AllTypesFile {
    std::string content;
    std::vector<int> types;                // per 3-D element
    std::vector<std::vector<Vec3>> nodes;  // per 3-D element, gmsh order
    std::int64_t pointCount = 0;
};

AllTypesFile MakeAllTypes(bool binary, bool swap = false) {
    const auto truth = GmshTruth();
    AllTypesFile f;
    std::vector<Vec3> points;
    for (const auto& [type, ref] : truth) {
        const CellShape shape = ClassifyGmshType(type)->shape;
        std::vector<Vec3> x;
        for (const Vec3& r : ref) {
            Vec3 p = ToInternalRef(shape, r);
            p[0] += 3.0 * f.types.size();
            x.push_back(p);
            points.push_back(p);
        }
        f.types.push_back(type);
        f.nodes.push_back(x);
    }
    const std::size_t volumeNodes = points.size();
    points.push_back({-1, -1, -1});  // nodes of a line element on a curve entity
    points.push_back({-2, -1, -1});
    f.pointCount = static_cast<std::int64_t>(points.size());
    auto tagOf = [](std::size_t i) { return static_cast<std::uint64_t>(17 + 5 * i); };

    MshWriter w(binary, swap);
    w.Format();
    w.Text("$PhysicalNames\n1\n3 1 \"volume\"\n$EndPhysicalNames\n");
    // Entities: 1 point, 1 curve, 1 surface, 1 volume, with physical and bounding tags.
    w.Header("Entities");
    w.Size(1), w.Size(1), w.Size(1), w.Size(1), w.Eol();
    w.Int(1), w.Double(0), w.Double(0), w.Double(0), w.Size(1), w.Int(5), w.Eol();
    w.Int(1);
    for (int i = 0; i < 6; ++i) w.Double(i);
    w.Size(0), w.Size(2), w.Int(1), w.Int(-1), w.Eol();
    w.Int(1);
    for (int i = 0; i < 6; ++i) w.Double(i);
    w.Size(2), w.Int(7), w.Int(8), w.Size(1), w.Int(1), w.Eol();
    w.Int(1);
    for (int i = 0; i < 6; ++i) w.Double(i);
    w.Size(1), w.Int(1), w.Size(1), w.Int(1), w.Eol();
    w.Footer("Entities");
    w.Text("$Foo\nsomething hpray does not know\n$EndFoo\n");

    // Nodes: one block per 3-D element, then the curve block with parametric coordinates.
    w.Header("Nodes");
    w.Size(f.types.size() + 1), w.Size(points.size()), w.Size(tagOf(0)),
        w.Size(tagOf(points.size() - 1)), w.Eol();
    std::size_t next = 0;
    for (std::size_t e = 0; e < f.types.size(); ++e) {
        w.Int(3), w.Int(1), w.Int(0), w.Size(f.nodes[e].size()), w.Eol();
        for (std::size_t i = 0; i < f.nodes[e].size(); ++i)
            w.Size(tagOf(next + i)), w.Eol();
        for (std::size_t i = 0; i < f.nodes[e].size(); ++i) {
            const Vec3& p = f.nodes[e][i];
            w.Double(p[0]), w.Double(p[1]), w.Double(p[2]), w.Eol();
        }
        next += f.nodes[e].size();
    }
    w.Int(1), w.Int(1), w.Int(1), w.Size(2), w.Eol();
    w.Size(tagOf(volumeNodes)), w.Eol(), w.Size(tagOf(volumeNodes + 1)), w.Eol();
    for (std::size_t i = volumeNodes; i < points.size(); ++i) {
        w.Double(points[i][0]), w.Double(points[i][1]), w.Double(points[i][2]);
        w.Double(0.25 * (i - volumeNodes)), w.Eol();  // parametric u on the curve
    }
    w.Footer("Nodes");

    // Elements: a line block, a triangle block (on 3-D nodes), then one block per type.
    w.Header("Elements");
    w.Size(f.types.size() + 2), w.Size(f.types.size() + 2), w.Size(1),
        w.Size(f.types.size() + 2), w.Eol();
    w.Int(1), w.Int(1), w.Int(1), w.Size(1), w.Eol();
    w.Size(1), w.Size(tagOf(volumeNodes)), w.Size(tagOf(volumeNodes + 1)), w.Eol();
    w.Int(2), w.Int(1), w.Int(2), w.Size(1), w.Eol();
    w.Size(2), w.Size(tagOf(0)), w.Size(tagOf(1)), w.Size(tagOf(2)), w.Eol();
    next = 0;
    for (std::size_t e = 0; e < f.types.size(); ++e) {
        w.Int(3), w.Int(1), w.Int(f.types[e]), w.Size(1), w.Eol();
        w.Size(100 + e);
        for (std::size_t i = 0; i < f.nodes[e].size(); ++i) w.Size(tagOf(next + i));
        w.Eol();
        next += f.nodes[e].size();
    }
    w.Footer("Elements");

    // Point data: 'analytic' at time steps 0 (wrong values) and 1 (the truth); 'vel' (3).
    auto nodeData = [&](const std::string& name, int step, int comps, auto value) {
        w.Header("NodeData");
        w.Text("1\n\"" + name + "\"\n1\n" + std::to_string(0.5 * step) + "\n3\n" +
               std::to_string(step) + "\n" + std::to_string(comps) + "\n" +
               std::to_string(points.size()) + "\n");
        // Reverse order: data need not follow the node order.
        for (std::size_t i = points.size(); i-- > 0;) {
            w.Int(static_cast<std::int32_t>(tagOf(i)));
            for (int c = 0; c < comps; ++c) w.Double(value(points[i], c));
            w.Eol();
        }
        w.Footer("NodeData");
    };
    nodeData("analytic", 0, 1, [](const Vec3&, int) { return 7.0; });
    nodeData("analytic", 1, 1,
             [](const Vec3& p, int) { return Analytic(p[0], p[1], p[2]); });
    nodeData("vel", 0, 3, [](const Vec3& p, int c) { return p[c] * (c + 1); });
    // Cell data: 'id' = 0.5 * element tag, including the line and triangle.
    w.Header("ElementData");
    w.Text("1\n\"id\"\n0\n3\n0\n1\n" + std::to_string(f.types.size() + 2) + "\n");
    for (std::uint64_t tag : {std::uint64_t(1), std::uint64_t(2)}) {
        w.Int(static_cast<std::int32_t>(tag)), w.Double(0.5 * tag), w.Eol();
    }
    for (std::size_t e = 0; e < f.types.size(); ++e) {
        w.Int(static_cast<std::int32_t>(100 + e)), w.Double(0.5 * (100 + e)), w.Eol();
    }
    w.Footer("ElementData");
    f.content = w.str();
    return f;
}

void CheckAllTypes(const AllTypesFile& f, const Mesh& m) {
    ASSERT_EQ(m.PointCount(), f.pointCount);
    ASSERT_EQ(m.CellCount(), static_cast<std::int64_t>(f.types.size()));
    for (std::size_t e = 0; e < f.types.size(); ++e) {
        const GmshCellType k = *ClassifyGmshType(f.types[e]);
        ASSERT_EQ(m.cellShape[e], k.shape);
        ASSERT_EQ(m.cellOrder[e], k.order);
        ASSERT_EQ(m.cellFamily[e], k.family);
        const auto& lattice = LatticeNodes(k.shape, k.order, k.family);
        ASSERT_EQ(m.CellNodeCount(e), static_cast<int>(lattice.size()));
        for (std::size_t n = 0; n < lattice.size(); ++n) {
            Vec3 want = LatticeRefCoords(k.shape, k.order, lattice[n]);
            want[0] += 3.0 * e;
            const double* got = &m.points[3 * m.CellNodes(e)[n]];
            for (int c = 0; c < 3; ++c)
                ASSERT_NEAR(got[c], want[c], 1e-14)
                    << "type " << f.types[e] << " internal node " << n;
        }
    }
    const Field* a = m.FindPointField("analytic");
    ASSERT_NE(a, nullptr);
    for (std::int64_t i = 0; i < m.PointCount(); ++i)
        ASSERT_EQ(a->values[i],
                  Analytic(m.points[3 * i], m.points[3 * i + 1], m.points[3 * i + 2]));
    const Field* v = m.FindPointField("vel");
    ASSERT_NE(v, nullptr);
    ASSERT_EQ(v->components, 3);
    for (std::int64_t i = 0; i < m.PointCount(); ++i)
        for (int c = 0; c < 3; ++c)
            ASSERT_EQ(v->values[3 * i + c], m.points[3 * i + c] * (c + 1));
    const Field* id = m.FindCellField("id");
    ASSERT_NE(id, nullptr);
    for (std::size_t e = 0; e < f.types.size(); ++e)
        EXPECT_EQ(id->values[e], 0.5 * (100 + e));
}

TEST(GmshReader, AllTypesAscii) {
    const AllTypesFile f = MakeAllTypes(false);
    const std::string path = WriteTemp("all_types_ascii.msh", f.content);
    CheckAllTypes(f, ReadGmsh(path, {}));
}

TEST(GmshReader, AllTypesBinary) {
    const AllTypesFile f = MakeAllTypes(true);
    const std::string path = WriteTemp("all_types_binary.msh", f.content);
    CheckAllTypes(f, ReadGmsh(path, {}));
}

TEST(GmshReader, AllTypesBinaryOtherEndianness) {
    const AllTypesFile f = MakeAllTypes(true, true);
    const std::string path = WriteTemp("all_types_swapped.msh", f.content);
    CheckAllTypes(f, ReadGmsh(path, {}));
}

TEST(GmshReader, FieldsOptionSelectsArrays) {
    const AllTypesFile f = MakeAllTypes(true);
    const std::string path = WriteTemp("all_types_fields.msh", f.content);
    ReadOptions o;
    o.fields = std::set<std::string>{"vel.y", "id"};
    const Mesh m = ReadGmsh(path, o);
    ASSERT_EQ(m.pointFields.size(), 1u);
    EXPECT_EQ(m.pointFields[0].name, "vel");
    ASSERT_EQ(m.cellFields.size(), 1u);
    EXPECT_EQ(m.cellFields[0].name, "id");
}

// A small hand-written file: two cells, tags sparse and out of order.
const char* kSmall =
    "$MeshFormat\n"
    "4.1 0 8\n"
    "$EndMeshFormat\n"
    "$Nodes\n"
    "2 9 5 900000\n"
    "3 1 0 4\n"
    "900000\n"
    "5\n"
    "70\n"
    "12\n"
    "0 0 0\n"
    "1 0 0\n"
    "0 1 0\n"
    "0 0 1\n"
    "3 2 0 5\n"
    "600\n"
    "601\n"
    "602\n"
    "603\n"
    "604\n"
    "1 0 1\n"
    "1 1 1\n"
    "0 1 1\n"
    "0.5 0.5 2\n"
    "9 9 9\n"
    "$EndNodes\n"
    "$Elements\n"
    "2 2 1 41\n"
    "3 1 4 1\n"
    "41 900000 5 70 12\n"
    "3 2 7 1\n"
    "7 12 600 601 602 603\n"
    "$EndElements\n";

TEST(GmshReader, SmallSparseTags) {
    const std::string path = WriteTemp("small.msh", kSmall);
    const Mesh m = ReadGmsh(path, {});
    EXPECT_EQ(m.PointCount(), 9);
    ASSERT_EQ(m.CellCount(), 2);
    EXPECT_EQ(m.cellShape[0], CellShape::Tet);
    EXPECT_EQ(m.cellShape[1], CellShape::Pyramid);
    // Tet vertices in file order are points 0..3; the pyramid's base is tags 12 600 601
    // 602 (points 3, 4, 5, 6), apex 603 (point 7); internal order: lattice sorted by (k,
    // j, i), i.e. base (0,0) (1,0) (0,1) (1,1) then the apex.
    const std::vector<std::int64_t> tet(m.CellNodes(0), m.CellNodes(0) + 4);
    EXPECT_EQ(tet, (std::vector<std::int64_t>{0, 1, 2, 3}));
    const std::vector<std::int64_t> pyr(m.CellNodes(1), m.CellNodes(1) + 5);
    EXPECT_EQ(pyr, (std::vector<std::int64_t>{3, 4, 6, 5, 7}));
}

// ---------------------------------------------------------------- malformed input

void ExpectInputError(const std::string& name, const std::string& content,
                      const std::string& mustContain, const std::string& whereKind) {
    const std::string path = WriteTemp(name, content);
    try {
        ReadGmsh(path, {});
        ADD_FAILURE() << name << ": no error";
    } catch (const InputError& e) {
        EXPECT_EQ(e.source(), path) << name;
        EXPECT_NE(std::string(e.what()).find(mustContain), std::string::npos)
            << name << ": " << e.what();
        EXPECT_EQ(e.where().rfind(whereKind, 0), 0u) << name << ": " << e.what();
    }
}

std::string Replace(std::string s, const std::string& from, const std::string& to) {
    const std::size_t at = s.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    return s.replace(at, from.size(), to);
}

TEST(GmshReader, MalformedAscii) {
    const std::string small = kSmall;
    ExpectInputError("truncated_nodes.msh", small.substr(0, small.find("0.5 0.5 2")),
                     "left in the file", "line 15");
    ExpectInputError("truncated_elements.msh", small.substr(0, small.find("602 603")),
                     "unexpected end of file", "line 32");
    ExpectInputError("no_end_nodes.msh", Replace(small, "$EndNodes\n", ""),
                     "expected $EndNodes", "line 26");
    ExpectInputError("bad_type.msh", Replace(small, "3 2 7 1", "3 2 999 1"),
                     "element type 999", "line 31");
    ExpectInputError("incomplete_type.msh",
                     Replace(small, "3 2 7 1\n7 12 600 601 602 603",
                             "3 2 137 1\n7 12 600 601 602 603 1 2 3 4 5 6 7 8 9 10 11"),
                     "type 137", "line 31");
    ExpectInputError("undefined_tag.msh",
                     Replace(small, "41 900000 5 70 12", "41 900000 5 71 12"),
                     "element 41 references undefined node tag 71", "line 30");
    ExpectInputError("nan.msh", Replace(small, "1 1 1\n", "1 nan 1\n"), "NaN", "line 22");
    ExpectInputError("huge_count.msh",
                     Replace(small, "2 9 5 900000", "2 1000000000000 5 900000"),
                     "node count 1000000000000", "line 5");
    ExpectInputError("huge_block.msh",
                     Replace(small, "3 1 0 4\n", "3 1 0 1000000000000\n"),
                     "more nodes than the declared", "line 6");
    ExpectInputError("duplicate_tag.msh", Replace(small, "601\n", "600\n"),
                     "defined twice", "line 17");
    ExpectInputError("tag_out_of_range.msh", Replace(small, "604\n", "900001\n"),
                     "outside the declared range", "line 20");
    ExpectInputError("msh22.msh", Replace(small, "4.1 0 8", "2.2 0 8"), "MSH version 2.2",
                     "line 2");
    ExpectInputError("not_msh.msh", "hello\n", "must start with $MeshFormat", "line 1");
    ExpectInputError("empty.msh", "", "empty file", "line 1");
    ExpectInputError("no_elements.msh", small.substr(0, small.find("$Elements")),
                     "no $Elements", "line");
    ExpectInputError("unterminated_section.msh",
                     Replace(small, "$Elements", "$Foo\nbar\n$Elements"), "no $EndFoo",
                     "line 27");
    ExpectInputError("node_data_partial.msh",
                     small + "$NodeData\n1\n\"u\"\n0\n3\n0\n1\n1\n5 1.0\n$EndNodeData\n",
                     "gives values for 1 of the 9 nodes", "line 34");
    ExpectInputError("node_data_bad_tag.msh",
                     small + "$NodeData\n1\n\"u\"\n0\n3\n0\n1\n1\n6 1.0\n$EndNodeData\n",
                     "undefined node tag 6", "line 42");
    ExpectInputError("node_data_nan.msh",
                     small + "$NodeData\n1\n\"u\"\n0\n3\n0\n1\n1\n5 nan\n$EndNodeData\n",
                     "NaN", "line 42");
}

TEST(GmshReader, ElementNodeDataIsSkippedOrRejected) {
    const std::string content =
        std::string(kSmall) +
        "$ElementNodeData\n1\n\"en\"\n0\n3\n0\n1\n1\n41 4 1 2 3 4\n$EndElementNodeData\n";
    const std::string path = WriteTemp("element_node_data.msh", content);
    EXPECT_TRUE(ReadGmsh(path, {}).pointFields.empty());
    ReadOptions o;
    o.fields = std::set<std::string>{"en"};
    try {
        ReadGmsh(path, o);
        ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("ElementNodeData"), std::string::npos);
        EXPECT_EQ(e.where(), "line 34");
    }
}

TEST(GmshReader, MalformedBinary) {
    const AllTypesFile f = MakeAllTypes(true);
    const std::string& s = f.content;
    // Cut inside the node coordinates, inside the elements, inside the data.
    for (const char* marker : {"$EndNodes", "$EndElements", "$EndNodeData"}) {
        const std::size_t at = s.find(marker);
        ASSERT_NE(at, std::string::npos);
        ExpectInputError(std::string("cut_") + (marker + 1) + ".msh",
                         s.substr(0, at - 100), "left in the file", "byte");
    }
    // A node count of 10^12 in the binary $Nodes header.
    std::string huge = s;
    const std::size_t nodes = huge.find("$Nodes\n") + 7;
    const std::uint64_t n = 1000000000000ull;
    std::memcpy(&huge[nodes + 8], &n, 8);
    ExpectInputError("binary_huge.msh", huge, "node count 1000000000000",
                     "byte " + std::to_string(nodes + 8));
    // A wrong endianness check integer.
    std::string endian = s;
    const std::size_t one = endian.find("4.1 1 8\n") + 8;
    endian[one] = 2;
    ExpectInputError("binary_endian.msh", endian, "endianness", "byte");
}

// Truncated and corrupted files: each read either succeeds or throws InputError.
TEST(GmshReader, FuzzedInputNeverCrashes) {
    const std::string ascii = MakeAllTypes(false).content.substr(0, 60000);
    const std::string binary = MakeAllTypes(true).content;
    std::uint64_t state = 12345;
    auto next = [&state] {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return state >> 33;
    };
    int errors = 0;
    for (int i = 0; i < 120; ++i) {
        std::string s = (i % 2 ? binary : ascii);
        if (i % 3 == 0) s.resize(next() % s.size());
        for (int k = 0; k < 1 + i % 4; ++k)
            s[next() % s.size()] = static_cast<char>(next());
        const std::string path = WriteTemp("fuzz.msh", s);
        try {
            ReadGmsh(path, {});
        } catch (const InputError&) {
            ++errors;
        }
    }
    EXPECT_GT(errors, 30);
}

}  // namespace
}  // namespace hpray

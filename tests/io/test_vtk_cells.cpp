// VTK cell classification and node orders, checked against VTK 9.1's own answers
// (tests/data/vtk_ref_coords.json, written by scripts/gen_vtk_ref_coords.py).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numeric>
#include <string>
#include <vector>

#include "io/vtk_cells.h"
#include "util/error.h"

namespace hpray {
namespace {

using Vec3 = std::array<double, 3>;
using nlohmann::json;

const json& Reference() {
    static const json data = [] {
        std::ifstream in(std::string(HPRAY_TEST_DATA) + "/vtk_ref_coords.json");
        EXPECT_TRUE(in.good()) << "missing tests/data/vtk_ref_coords.json";
        return json::parse(in);
    }();
    return data;
}

std::vector<Vec3> Coords(const json& entry) {
    std::vector<Vec3> out;
    for (const json& x : entry.at("pcoords")) out.push_back({x[0], x[1], x[2]});
    return out;
}

const json& ReferenceCell(int vtkType, int order) {
    for (const json& c : Reference().at("cells"))
        if (c.at("vtk_type") == vtkType && c.at("order") == order) return c;
    ADD_FAILURE() << "no reference for type " << vtkType << " order " << order;
    static const json empty;
    return empty;
}

bool Same(const CellKind& a, const CellKind& b) {
    return a.shape == b.shape && a.order == b.order && a.family == b.family;
}

// What each fixed VTK type is, as the VTK documentation and the task statement define it.
struct FixedType {
    int vtkType;
    int nodes;
    CellKind kind;
};
const std::vector<FixedType>& FixedTypes() {
    static const std::vector<FixedType> types = {
        {10, 4, {CellShape::Tet, 1, CellFamily::Lagrange}},
        {12, 8, {CellShape::Hex, 1, CellFamily::Lagrange}},
        {13, 6, {CellShape::Wedge, 1, CellFamily::Lagrange}},
        {14, 5, {CellShape::Pyramid, 1, CellFamily::Lagrange}},
        {24, 10, {CellShape::Tet, 2, CellFamily::Lagrange}},
        {25, 20, {CellShape::Hex, 2, CellFamily::Serendipity}},
        {26, 15, {CellShape::Wedge, 2, CellFamily::Serendipity}},
        {27, 13, {CellShape::Pyramid, 2, CellFamily::Serendipity}},
        {29, 27, {CellShape::Hex, 2, CellFamily::Lagrange}},
        {32, 18, {CellShape::Wedge, 2, CellFamily::Lagrange}},
    };
    return types;
}

CellShape LagrangeShapeOf(int vtkType) {
    switch (vtkType) {
        case 71:
            return CellShape::Tet;
        case 72:
            return CellShape::Hex;
        case 73:
            return CellShape::Wedge;
        default:
            return CellShape::Pyramid;
    }
}

// Node count of the order-p lattice, closed forms (counting lattice points).
long long LatticeCount(CellShape shape, long long p) {
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

CellKind KindOf(const json& entry) {
    std::string why;
    auto kind = ClassifyVtkCell(entry.at("vtk_type"), entry.at("nodes"), nullptr, &why);
    EXPECT_TRUE(kind.has_value()) << why;
    return kind.value_or(CellKind{});
}

// The change of reference cell from VTK's parameters (r, s, t) to internal reference
// coordinates (mesh/cell.h), per type:
//  - tetrahedra (10, 24, 71), hexahedra (12, 25, 29, 72), VTK_LAGRANGE_WEDGE (73): VTK's
//    reference cell is the internal one: identity.
//  - VTK_WEDGE (13), 26, 32: (s, r, t). VTK lists node 1 at (1,0,0) and node 2 at (0,1,0)
//    like 73, but these types' faces are outward only for a negative parametric Jacobian
//    (see WedgeWindingFollowsVtkFaces); exchanging r and s is the orientation-reversing
//    affine map that makes valid cells positive.
//  - pyramids (14, 27, 74): VTK's pyramid interpolates with (1-r)(1-s)(1-t), r(1-s)(1-t),
//    rs(1-t), (1-r)s(1-t) at the base vertices and t at the apex; applied to the internal
//    pyramid's vertices (0,0,0) (1,0,0) (1,1,0) (0,1,0) (1/2,1/2,1) that is
//    ((1-t) r + t/2, (1-t) s + t/2, t). Not affine: the exact map of VTK's own cell.
Vec3 VtkToInternalRef(int vtkType, CellShape shape, const Vec3& v) {
    if (shape == CellShape::Pyramid)
        return {(1 - v[2]) * v[0] + v[2] / 2, (1 - v[2]) * v[1] + v[2] / 2, v[2]};
    if (vtkType == 13 || vtkType == 26 || vtkType == 32) return {v[1], v[0], v[2]};
    return v;
}

double Det(const Vec3& a, const Vec3& b, const Vec3& c) {
    return a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
           a[2] * (b[0] * c[1] - b[1] * c[0]);
}

Vec3 Sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }

// Orientation of a cell from its internal-order nodes: det of the edges from vertex
// (0,0,0) to the vertices at lattice (p,0,0), (0,p,0) and the top one ((0,0,p): the apex
// of a pyramid). Positive for the internal reference cell of every shape.
double InternalOrientation(const CellKind& kind, const std::vector<Vec3>& internalNodes) {
    const int p = kind.order;
    auto at = [&](const LatticeIndex& ijk) {
        const int k = InternalNodeIndex(kind.shape, p, kind.family, ijk);
        EXPECT_GE(k, 0);
        return internalNodes.at(k);
    };
    const Vec3 o = at({0, 0, 0});
    return Det(Sub(at({p, 0, 0}), o), Sub(at({0, p, 0}), o), Sub(at({0, 0, p}), o));
}

void ExpectPermutation(const std::vector<int>& perm, size_t n, const std::string& what) {
    ASSERT_EQ(perm.size(), n) << what;
    std::vector<int> sorted = perm;
    std::sort(sorted.begin(), sorted.end());
    for (size_t i = 0; i < n; ++i) ASSERT_EQ(sorted[i], static_cast<int>(i)) << what;
}

// ---------------------------------------------------------------------------------------

TEST(VtkCells, ReferenceCoversEveryTypeAndOrder) {
    const json& cells = Reference().at("cells");
    EXPECT_EQ(cells.size(), 10u + 3u * 6u);
    for (int type : {71, 72, 73})
        for (int p = 1; p <= 6; ++p) {
            const json& c = ReferenceCell(type, p);
            EXPECT_EQ(c.at("nodes"), LatticeCount(LagrangeShapeOf(type), p));
            EXPECT_EQ(c.at("pcoords").size(), c.at("nodes"));
        }
}

TEST(VtkCells, ClassifiesEveryReferenceCell) {
    for (const FixedType& t : FixedTypes()) {
        std::string why;
        auto kind = ClassifyVtkCell(t.vtkType, t.nodes, nullptr, &why);
        ASSERT_TRUE(kind) << t.vtkType << ": " << why;
        EXPECT_TRUE(Same(*kind, t.kind)) << t.vtkType;
        EXPECT_EQ(ReferenceCell(t.vtkType, t.kind.order).at("nodes"), t.nodes);
    }
    for (const json& c : Reference().at("cells")) {
        const int type = c.at("vtk_type");
        if (type < 71) continue;
        const CellKind kind = KindOf(c);
        EXPECT_EQ(kind.shape, LagrangeShapeOf(type));
        EXPECT_EQ(kind.order, c.at("order").get<int>());
        EXPECT_EQ(kind.family, CellFamily::Lagrange);
    }
}

// (a) VtkParametricCoords reproduces VTK's GetParametricCoords, node by node.
TEST(VtkCells, ParametricCoordsMatchVtk) {
    for (const json& c : Reference().at("cells")) {
        const int type = c.at("vtk_type");
        const std::vector<Vec3> expected = Coords(c);
        const auto actual = VtkParametricCoords(type, KindOf(c));
        ASSERT_EQ(actual.size(), expected.size()) << type;
        for (size_t n = 0; n < expected.size(); ++n)
            for (int d = 0; d < 3; ++d)
                EXPECT_NEAR(actual[n][d], expected[n][d], 1e-12)
                    << "type " << type << " order " << c.at("order") << " node " << n;
    }
}

// (b) VtkToInternal sends every VTK node to the internal node at the same reference
// point.
TEST(VtkCells, PermutationPlacesEveryVtkNodeAtItsReferencePosition) {
    for (const json& c : Reference().at("cells")) {
        const int type = c.at("vtk_type");
        const CellKind kind = KindOf(c);
        const std::vector<Vec3> vtkCoords = Coords(c);
        const std::vector<int>& perm = VtkToInternal(type, kind);
        const auto& lattice = LatticeNodes(kind.shape, kind.order, kind.family);
        ASSERT_EQ(perm.size(), lattice.size()) << type;
        for (size_t k = 0; k < lattice.size(); ++k) {
            const Vec3 want = LatticeRefCoords(kind.shape, kind.order, lattice[k]);
            const Vec3 got = VtkToInternalRef(type, kind.shape, vtkCoords.at(perm[k]));
            for (int d = 0; d < 3; ++d)
                EXPECT_NEAR(got[d], want[d], 1e-12)
                    << "type " << type << " order " << kind.order << " internal node "
                    << k;
        }
    }
}

// VTK's rule for 3-D cells: the faces vtkCell::GetFace returns point outward. The
// generator found, per type, which of the two affine images of VTK's reference cell
// (identity, or r and s exchanged) satisfies it. Read through VtkToInternal, that
// geometrically valid cell must be positively oriented.
TEST(VtkCells, GeometricallyValidVtkCellsBecomePositiveInternalCells) {
    for (const json& c : Reference().at("cells")) {
        const int type = c.at("vtk_type");
        const CellKind kind = KindOf(c);
        std::vector<Vec3> x = Coords(c);
        const std::string valid = c.at("valid_geometry");
        ASSERT_TRUE(valid == "identity" || valid == "mirror_rs");
        if (valid == "mirror_rs")
            for (Vec3& v : x) std::swap(v[0], v[1]);
        const std::vector<int>& perm = VtkToInternal(type, kind);
        std::vector<Vec3> internal(perm.size());
        for (size_t k = 0; k < perm.size(); ++k) internal[k] = x[perm[k]];
        EXPECT_GT(InternalOrientation(kind, internal), 0.0)
            << "type " << type << " order " << kind.order;
    }
}

// Trap 2 and the question for 26 and 32, as VTK 9.1 answers it: VTK_WEDGE's faces are
// outward only for the r/s-mirrored geometry (negative parametric Jacobian), the Lagrange
// wedge's for the identity; 26 and 32 share vtkWedge's faces and so its convention.
TEST(VtkCells, WedgeWindingFollowsVtkFaces) {
    EXPECT_EQ(ReferenceCell(13, 1).at("valid_geometry"), "mirror_rs");
    EXPECT_EQ(ReferenceCell(26, 2).at("valid_geometry"), "mirror_rs");
    EXPECT_EQ(ReferenceCell(32, 2).at("valid_geometry"), "mirror_rs");
    for (int p = 1; p <= 6; ++p)
        EXPECT_EQ(ReferenceCell(73, p).at("valid_geometry"), "identity");
    // VTK's own signed volume agrees for 13 and 26 (the mirrored cell has volume +1/2).
    EXPECT_NEAR(ReferenceCell(13, 1).at("volume").at("mirror_rs").get<double>(), 0.5,
                1e-12);
    EXPECT_NEAR(ReferenceCell(26, 2).at("volume").at("mirror_rs").get<double>(), 0.5,
                1e-12);
    EXPECT_NEAR(ReferenceCell(73, 2).at("volume").at("identity").get<double>(), 0.5,
                1e-12);

    // Hence VTK_WEDGE vertex 1 goes to internal (0,1,0) and vertex 2 to (1,0,0); the
    // Lagrange wedge keeps them.
    const CellKind wedge1{CellShape::Wedge, 1, CellFamily::Lagrange};
    EXPECT_EQ(VtkToInternal(13, wedge1), (std::vector<int>{0, 2, 1, 3, 5, 4}));
    EXPECT_EQ(VtkToInternal(73, wedge1), (std::vector<int>{0, 1, 2, 3, 4, 5}));
}

// A 26 cell written with the Lagrange winding (as gmsh does) reads inverted; the
// reflection repairs it.
TEST(VtkCells, ReflectionRepairsAnOppositelyWoundCell) {
    const json& c = ReferenceCell(26, 2);
    const CellKind kind = KindOf(c);
    const std::vector<Vec3> x = Coords(c);  // identity geometry: not VTK's convention
    const std::vector<int>& perm = VtkToInternal(26, kind);
    std::vector<Vec3> internal(perm.size());
    for (size_t k = 0; k < perm.size(); ++k) internal[k] = x[perm[k]];
    EXPECT_LT(InternalOrientation(kind, internal), 0.0);
    const std::vector<int>& m = InternalReflection(kind);
    std::vector<Vec3> reflected(m.size());
    for (size_t k = 0; k < m.size(); ++k) reflected[k] = internal[m[k]];
    EXPECT_GT(InternalOrientation(kind, reflected), 0.0);
}

TEST(VtkCells, ReflectionExchangesLatticeIAndJ) {
    for (int s = 0; s < kNumCellShapes; ++s)
        for (int p = 1; p <= kMaxOrder; ++p) {
            const CellKind kind{static_cast<CellShape>(s), p, CellFamily::Lagrange};
            const auto& nodes = LatticeNodes(kind.shape, p);
            const std::vector<int>& m = InternalReflection(kind);
            ExpectPermutation(m, nodes.size(), ShapeName(kind.shape));
            for (size_t k = 0; k < m.size(); ++k) {
                EXPECT_EQ(nodes[m[k]][0], nodes[k][1]);
                EXPECT_EQ(nodes[m[k]][1], nodes[k][0]);
                EXPECT_EQ(nodes[m[k]][2], nodes[k][2]);
                EXPECT_EQ(m[m[k]], static_cast<int>(k));
            }
        }
}

// Every permutation of every type and order is a bijection; writing inverts reading.
TEST(VtkCells, PermutationsAreBijectionsAndWritingInvertsReading) {
    for (const FixedType& t : FixedTypes())
        ExpectPermutation(VtkToInternal(t.vtkType, t.kind), t.nodes,
                          std::to_string(t.vtkType));
    for (int type : {71, 72, 73, 74})
        for (int p = 1; p <= kMaxOrder; ++p) {
            const CellKind kind{LagrangeShapeOf(type), p, CellFamily::Lagrange};
            const size_t n = LatticeCount(kind.shape, p);
            for (bool legacy : {false, true}) {
                const std::vector<int>& perm = VtkToInternal(type, kind, legacy);
                ExpectPermutation(perm, n,
                                  std::to_string(type) + " p" + std::to_string(p));
            }
            EXPECT_EQ(VtkTypeFor(kind), type);
            const std::vector<int>& toVtk = InternalToVtk(kind);
            const std::vector<int>& toInternal = VtkToInternal(type, kind);
            ExpectPermutation(toVtk, n, "InternalToVtk");
            for (size_t k = 0; k < n; ++k)
                EXPECT_EQ(toVtk[toInternal[k]], static_cast<int>(k));
        }
    const struct {
        CellShape shape;
        int type;
    } serendipity[] = {
        {CellShape::Hex, 25}, {CellShape::Wedge, 26}, {CellShape::Pyramid, 27}};
    for (const auto& s : serendipity) {
        const CellKind kind{s.shape, 2, CellFamily::Serendipity};
        EXPECT_EQ(VtkTypeFor(kind), s.type);
        const std::vector<int>& toVtk = InternalToVtk(kind);
        const std::vector<int>& toInternal = VtkToInternal(s.type, kind);
        ExpectPermutation(toVtk, toInternal.size(), "serendipity");
        for (size_t k = 0; k < toVtk.size(); ++k)
            EXPECT_EQ(toVtk[toInternal[k]], static_cast<int>(k));
    }
}

// Writing then reading any cell returns the same nodes: file[k] = internal[toVtk[k]],
// reread[k] = file[toInternal[k]].
TEST(VtkCells, WriteReadRoundTripIsIdentity) {
    for (int s = 0; s < kNumCellShapes; ++s)
        for (int p = 1; p <= kMaxOrder; ++p) {
            const CellKind kind{static_cast<CellShape>(s), p, CellFamily::Lagrange};
            const std::vector<int>& toVtk = InternalToVtk(kind);
            std::vector<int> file(toVtk.size());
            for (size_t k = 0; k < file.size(); ++k) file[k] = 1000 + toVtk[k];
            std::string why;
            auto reread = ClassifyVtkCell(VtkTypeFor(kind), file.size(), nullptr, &why);
            ASSERT_TRUE(reread) << why;
            ASSERT_TRUE(Same(*reread, kind));
            const std::vector<int>& toInternal = VtkToInternal(VtkTypeFor(kind), *reread);
            for (size_t k = 0; k < file.size(); ++k)
                EXPECT_EQ(file[toInternal[k]], 1000 + static_cast<int>(k));
        }
}

// The Lagrange types at low order coincide with VTK's fixed types, as VTK's coordinates
// show (the reference test above); here directly.
TEST(VtkCells, LagrangeTypesAgreeWithFixedTypes) {
    const CellKind tet2{CellShape::Tet, 2, CellFamily::Lagrange};
    const CellKind hex2{CellShape::Hex, 2, CellFamily::Lagrange};
    EXPECT_EQ(VtkToInternal(71, tet2), VtkToInternal(24, tet2));
    EXPECT_EQ(VtkToInternal(72, hex2), VtkToInternal(29, hex2));
    for (auto [lagrange, linear, shape] :
         {std::tuple{71, 10, CellShape::Tet}, std::tuple{72, 12, CellShape::Hex},
          std::tuple{74, 14, CellShape::Pyramid}}) {
        const CellKind kind{shape, 1, CellFamily::Lagrange};
        EXPECT_EQ(VtkToInternal(lagrange, kind), VtkToInternal(linear, kind)) << linear;
    }
}

// ---------------------------------------------------------------------------------------
// VTK_LAGRANGE_PYRAMID (74): hpray's convention (vtk_cells.h), checked geometrically.

TEST(VtkCells, LagrangePyramidExtendsVtkPyramids) {
    const CellKind p1{CellShape::Pyramid, 1, CellFamily::Lagrange};
    const CellKind p2{CellShape::Pyramid, 2, CellFamily::Lagrange};
    const auto linear = Coords(ReferenceCell(14, 1));
    const auto quadratic = Coords(ReferenceCell(27, 2));
    const auto c1 = VtkParametricCoords(74, p1);
    const auto c2 = VtkParametricCoords(74, p2);
    ASSERT_EQ(c1.size(), 5u);
    ASSERT_EQ(c2.size(), 14u);
    for (size_t n = 0; n < 5; ++n)
        for (int d = 0; d < 3; ++d) EXPECT_NEAR(c1[n][d], linear[n][d], 1e-15);
    for (size_t n = 0; n < 13; ++n)
        for (int d = 0; d < 3; ++d) EXPECT_NEAR(c2[n][d], quadratic[n][d], 1e-15) << n;
    EXPECT_NEAR(c2[13][0], 0.5, 1e-15);
    EXPECT_NEAR(c2[13][1], 0.5, 1e-15);
    EXPECT_NEAR(c2[13][2], 0.0, 1e-15);
}

// Vertices; p-1 nodes per edge, equally spaced from the first to the second vertex; the
// base interior (i fastest); the four triangles, each by level then along its base edge;
// then the interior by (k, j, i). Positions in internal reference coordinates.
TEST(VtkCells, LagrangePyramidFollowsTheDocumentedOrder) {
    const Vec3 v[5] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.5, 0.5, 1}};
    const int edges[8][2] = {{0, 1}, {1, 2}, {3, 2}, {0, 3},
                             {0, 4}, {1, 4}, {2, 4}, {3, 4}};
    // Triangles: (first base vertex, second base vertex): nodes sorted by height, then by
    // distance from the first base vertex's edge end along the base direction.
    const int triangles[4][2] = {{0, 1}, {1, 2}, {3, 2}, {0, 3}};
    const int tris[4][3] = {{0, 1, 4}, {1, 2, 4}, {2, 3, 4}, {3, 0, 4}};
    for (int p = 1; p <= kMaxOrder; ++p) {
        const CellKind kind{CellShape::Pyramid, p, CellFamily::Lagrange};
        const std::vector<int>& perm = VtkToInternal(74, kind);
        const auto& lattice = LatticeNodes(CellShape::Pyramid, p);
        std::vector<Vec3> x(perm.size());  // reference position of VTK node n
        for (size_t k = 0; k < perm.size(); ++k)
            x[perm[k]] = LatticeRefCoords(CellShape::Pyramid, p, lattice[k]);
        auto near = [](const Vec3& a, const Vec3& b) {
            return std::abs(a[0] - b[0]) + std::abs(a[1] - b[1]) + std::abs(a[2] - b[2]) <
                   1e-12;
        };
        size_t n = 0;
        for (int i = 0; i < 5; ++i)
            EXPECT_TRUE(near(x[n++], v[i])) << "p" << p << " vertex";
        for (const auto& e : edges)
            for (int t = 1; t < p; ++t) {
                Vec3 want;
                for (int d = 0; d < 3; ++d)
                    want[d] = v[e[0]][d] + (v[e[1]][d] - v[e[0]][d]) * t / p;
                EXPECT_TRUE(near(x[n++], want)) << "p" << p << " edge node " << n - 1;
            }
        for (int j = 1; j < p; ++j)
            for (int i = 1; i < p; ++i)
                EXPECT_TRUE(near(x[n++], Vec3{double(i) / p, double(j) / p, 0}))
                    << "p" << p << " base node " << n - 1;
        for (int f = 0; f < 4; ++f) {
            const Vec3& a = v[triangles[f][0]];
            const Vec3& b = v[triangles[f][1]];
            for (int k = 1; k < p; ++k)
                for (int s = 1; s < p - k; ++s) {
                    // Level k: the triangle's section runs from a + (apex - a) k/p
                    // parallel to (b - a), with p - k steps of (b - a)/p.
                    Vec3 want;
                    for (int d = 0; d < 3; ++d)
                        want[d] = a[d] + (v[4][d] - a[d]) * k / p + (b[d] - a[d]) * s / p;
                    EXPECT_TRUE(near(x[n], want))
                        << "p" << p << " face " << tris[f][0] << tris[f][1] << tris[f][2]
                        << " node " << n;
                    ++n;
                }
        }
        std::vector<Vec3> interior;
        for (int k = 1; k < p; ++k)
            for (int j = 1; j < p - k; ++j)
                for (int i = 1; i < p - k; ++i)
                    interior.push_back(
                        {(i + 0.5 * k) / p, (j + 0.5 * k) / p, double(k) / p});
        for (const Vec3& want : interior) EXPECT_TRUE(near(x[n++], want)) << "p" << p;
        EXPECT_EQ(n, perm.size());
    }
}

// ---------------------------------------------------------------------------------------
// Pre-VTK-9 Lagrange hexahedra (trap 1).

// VTK's own readers, given a version-0.1 file with connectivity 0..N-1, produce a cell
// whose VTK node m is file node ids[m]; reading with the legacy flag must agree.
TEST(VtkCells, LegacyHexMatchesVtkReader) {
    const json& entries = Reference().at("legacy_hex");
    ASSERT_EQ(entries.size(), 3u);
    for (const json& e : entries) {
        const int p = e.at("order");
        const std::vector<int> ids = e.at("ids");
        const CellKind kind{CellShape::Hex, p, CellFamily::Lagrange};
        const std::vector<int>& modern = VtkToInternal(72, kind, false);
        const std::vector<int>& legacy = VtkToInternal(72, kind, true);
        ASSERT_EQ(ids.size(), modern.size());
        for (size_t k = 0; k < modern.size(); ++k) EXPECT_EQ(legacy[k], ids[modern[k]]);
    }
}

// Closed form from ../shared/data/README.md: the legacy blocks at 8+10(p-1) and 8+11(p-1)
// hold the edges at (i,j) = (0,p) and (p,p), i.e. VTK 9's edges 11 and 10.
TEST(VtkCells, LegacyHexSwapsEdgeBlocks10And11) {
    for (int p = 2; p <= 4; ++p) {
        const CellKind kind{CellShape::Hex, p, CellFamily::Lagrange};
        const std::vector<int>& modern = VtkToInternal(72, kind, false);
        const std::vector<int>& legacy = VtkToInternal(72, kind, true);
        const int block10 = 8 + 10 * (p - 1), block11 = 8 + 11 * (p - 1);
        int changed = 0;
        for (int k = 1; k < p; ++k) {
            const int onEdge11 =
                InternalNodeIndex(CellShape::Hex, p, kind.family, {0, p, k});
            const int onEdge10 =
                InternalNodeIndex(CellShape::Hex, p, kind.family, {p, p, k});
            EXPECT_EQ(legacy[onEdge11], block10 + k - 1) << "p" << p;
            EXPECT_EQ(legacy[onEdge10], block11 + k - 1) << "p" << p;
            EXPECT_EQ(modern[onEdge10], block10 + k - 1) << "p" << p;
            EXPECT_EQ(modern[onEdge11], block11 + k - 1) << "p" << p;
        }
        for (size_t k = 0; k < modern.size(); ++k) changed += modern[k] != legacy[k];
        EXPECT_EQ(changed, 2 * (p - 1));
    }
    // Nothing to swap at order 1, and only VTK_LAGRANGE_HEXAHEDRON is affected.
    const CellKind hex1{CellShape::Hex, 1, CellFamily::Lagrange};
    EXPECT_EQ(VtkToInternal(72, hex1, true), VtkToInternal(72, hex1, false));
    const CellKind hex2{CellShape::Hex, 2, CellFamily::Lagrange};
    EXPECT_EQ(VtkToInternal(29, hex2, true), VtkToInternal(29, hex2, false));
    const CellKind tet3{CellShape::Tet, 3, CellFamily::Lagrange};
    EXPECT_EQ(VtkToInternal(71, tet3, true), VtkToInternal(71, tet3, false));
}

TEST(VtkCells, LegacyHexVersionRuleMatchesVtkReaders) {
    const json& versions = Reference().at("legacy_hex_versions");
    auto check = [](const json& table, bool (*rule)(int, int)) {
        ASSERT_FALSE(table.empty());
        for (const auto& [version, swapped] : table.items()) {
            const size_t dot = version.find('.');
            const int major = std::stoi(version.substr(0, dot));
            const int minor = std::stoi(version.substr(dot + 1));
            EXPECT_EQ(rule(major, minor), swapped.get<bool>()) << version;
        }
    };
    check(versions.at("xml"), VtkXmlHasLegacyLagrangeHex);
    check(versions.at("legacy"), VtkLegacyHasLegacyLagrangeHex);
    // The two files of ../shared/data with Lagrange hexahedra of both conventions.
    EXPECT_TRUE(VtkXmlHasLegacyLagrangeHex(0, 1));   // deal.II
    EXPECT_FALSE(VtkXmlHasLegacyLagrangeHex(2, 2));  // MFEM
}

// ---------------------------------------------------------------------------------------
// Classification.

TEST(VtkCells, LagrangeOrderFromNodeCount) {
    for (int type : {71, 72, 73, 74})
        for (int p = 1; p <= kMaxOrder; ++p) {
            const CellShape shape = LagrangeShapeOf(type);
            std::string why;
            auto kind = ClassifyVtkCell(type, LatticeCount(shape, p), nullptr, &why);
            ASSERT_TRUE(kind) << type << " p" << p << ": " << why;
            EXPECT_TRUE(Same(*kind, CellKind{shape, p, CellFamily::Lagrange}));
            EXPECT_EQ(static_cast<long long>(NodeCount(shape, p)),
                      LatticeCount(shape, p));
            // One node more or less fits no order.
            for (long long off : {-1, 1}) {
                if (LatticeCount(shape, p) + off == LatticeCount(shape, p - 1)) continue;
                why.clear();
                EXPECT_FALSE(
                    ClassifyVtkCell(type, LatticeCount(shape, p) + off, nullptr, &why))
                    << type << " p" << p << " " << off;
                EXPECT_NE(why.find("no order"), std::string::npos) << why;
            }
        }
}

TEST(VtkCells, LagrangeOrderFromDegrees) {
    const int cubic[3] = {3, 3, 3};
    auto hex = ClassifyVtkCell(72, 64, cubic);
    ASSERT_TRUE(hex);
    EXPECT_TRUE(Same(*hex, CellKind{CellShape::Hex, 3, CellFamily::Lagrange}));
    auto wedge = ClassifyVtkCell(73, 40, cubic);
    ASSERT_TRUE(wedge);
    EXPECT_TRUE(Same(*wedge, CellKind{CellShape::Wedge, 3, CellFamily::Lagrange}));

    std::string why;
    const int anisotropic[3] = {2, 2, 3};
    EXPECT_FALSE(ClassifyVtkCell(72, 36, anisotropic, &why));  // (3)(3)(4) nodes
    EXPECT_NE(why.find("anisotropic"), std::string::npos) << why;
    const int wedgeAniso[3] = {2, 2, 1};
    EXPECT_FALSE(ClassifyVtkCell(73, 12, wedgeAniso, &why));
    EXPECT_NE(why.find("anisotropic"), std::string::npos) << why;
    EXPECT_FALSE(ClassifyVtkCell(72, 27, cubic, &why));  // degrees say 64 nodes
    EXPECT_NE(why.find("64"), std::string::npos) << why;
    const int zero[3] = {0, 0, 0};
    EXPECT_FALSE(ClassifyVtkCell(72, 1, zero, &why));
    const int eleven[3] = {11, 11, 11};
    EXPECT_FALSE(ClassifyVtkCell(72, 12 * 12 * 12, eleven, &why));
    const int negative[3] = {-2, -2, -2};
    EXPECT_FALSE(ClassifyVtkCell(72, 8, negative, &why));
}

TEST(VtkCells, RejectsWrongCountsAndUnknownTypes) {
    for (const FixedType& t : FixedTypes())
        for (int off : {-1, 1}) {
            std::string why;
            EXPECT_FALSE(ClassifyVtkCell(t.vtkType, t.nodes + off, nullptr, &why))
                << t.vtkType;
            EXPECT_NE(why.find(std::to_string(t.nodes)), std::string::npos) << why;
        }
    // 2-D and other cells, and nonsense ids.
    for (int type :
         {-1, 0, 1, 3, 5, 9, 11, 28, 33, 37, 67, 68, 70, 75, 79, 255, 1 << 30}) {
        std::string why;
        EXPECT_FALSE(ClassifyVtkCell(type, 8, nullptr, &why)) << type;
        EXPECT_NE(why.find("not a supported"), std::string::npos) << why;
    }
    // VTK's special 15-node tetrahedron and 21-node wedge are named as such.
    std::string why;
    EXPECT_FALSE(ClassifyVtkCell(71, 15, nullptr, &why));
    EXPECT_NE(why.find("15-node"), std::string::npos) << why;
    EXPECT_FALSE(ClassifyVtkCell(73, 21, nullptr, &why));
    EXPECT_NE(why.find("21-node"), std::string::npos) << why;
    // Orders above the maximum say so; absurd counts are rejected without work.
    EXPECT_FALSE(ClassifyVtkCell(72, 12 * 12 * 12, nullptr, &why));
    EXPECT_NE(why.find("order 11"), std::string::npos) << why;
    for (long long count : {0LL, -8LL, 1LL << 40, 9223372036854775807LL})
        EXPECT_FALSE(ClassifyVtkCell(72, count, nullptr, &why)) << count;
    EXPECT_FALSE(ClassifyVtkCell(72, 7, nullptr));  // `why` is optional
}

TEST(VtkCells, MismatchedKindIsAnInternalError) {
    const CellKind hex2{CellShape::Hex, 2, CellFamily::Lagrange};
    EXPECT_THROW(VtkToInternal(25, hex2), InternalError);  // 25 is serendipity
    EXPECT_THROW(VtkToInternal(71, hex2), InternalError);
    EXPECT_THROW(VtkToInternal(5, hex2), InternalError);
    const CellKind tet11{CellShape::Tet, 11, CellFamily::Lagrange};
    EXPECT_THROW(VtkToInternal(71, tet11), InternalError);
    EXPECT_THROW(VtkTypeFor(CellKind{CellShape::Tet, 2, CellFamily::Serendipity}),
                 InternalError);
}

}  // namespace
}  // namespace hpray

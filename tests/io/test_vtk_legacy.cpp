// Tests of the legacy VTK reader: files written by VTK's own writer (tests/data/legacy_*,
// scripts/gen_legacy_fixtures.py), files written here for every cell type VTK defines
// node coordinates for, in ASCII and BINARY and both CELLS layouts, and malformed inputs.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "io/mesh_io.h"
#include "io/vtk_cells.h"
#include "mesh/cell.h"
#include "util/error.h"

namespace hpray {
namespace {

using Vec3 = std::array<double, 3>;
using nlohmann::json;

double Analytic(double x, double y, double z) {
    return std::sin(3 * x) * std::cos(2 * y) + 0.5 * std::sin(4 * z + x * y);
}

std::string WriteTemp(const std::string& name, const std::string& content) {
    const std::string path = testing::TempDir() + "hpray_legacy_" + name;
    std::ofstream out(path, std::ios::binary);
    out << content;
    return path;
}

std::string ReadFile(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    EXPECT_TRUE(in.good()) << path;
    std::ostringstream os;
    os << in.rdbuf();
    return os.str();
}

// ---- geometry check: a cell's nodes in internal order are an affine image of the
// internal lattice, with positive orientation.

double Det(const double m[3][3]) {
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
           m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
           m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

// Worst distance (relative to the cell size) of a node from the affine map through the
// lattice vertices (0,0,0) (p,0,0) (0,p,0) (0,0,p), which are vertices of every shape.
double AffineDeviation(const Mesh& m, std::int64_t c, double* det) {
    const CellShape s = m.cellShape[c];
    const int p = m.cellOrder[c];
    const CellFamily fam = m.cellFamily[c];
    const std::int64_t* nodes = m.CellNodes(c);
    auto pos = [&](const LatticeIndex& l) {
        const double* x = &m.points[3 * nodes[InternalNodeIndex(s, p, fam, l)]];
        return Vec3{x[0], x[1], x[2]};
    };
    const LatticeIndex frame[4] = {{0, 0, 0}, {p, 0, 0}, {0, p, 0}, {0, 0, p}};
    Vec3 x[4], xi[4];
    for (int v = 0; v < 4; ++v) {
        x[v] = pos(frame[v]);
        xi[v] = LatticeRefCoords(s, p, frame[v]);
    }
    double a[3][3], q[3][3];  // x - x0 = Q Xi^-1 (xi - xi0)
    for (int j = 0; j < 3; ++j)
        for (int r = 0; r < 3; ++r) {
            a[r][j] = xi[j + 1][r] - xi[0][r];
            q[r][j] = x[j + 1][r] - x[0][r];
        }
    const double da = Det(a);
    double inv[3][3];
    for (int r = 0; r < 3; ++r)
        for (int col = 0; col < 3; ++col) {
            const int r1 = (col + 1) % 3, r2 = (col + 2) % 3, c1 = (r + 1) % 3,
                      c2 = (r + 2) % 3;
            inv[r][col] = (a[r1][c1] * a[r2][c2] - a[r1][c2] * a[r2][c1]) / da;
        }
    double map[3][3];
    for (int r = 0; r < 3; ++r)
        for (int col = 0; col < 3; ++col) {
            map[r][col] = 0;
            for (int k = 0; k < 3; ++k) map[r][col] += q[r][k] * inv[k][col];
        }
    *det = Det(map);
    double size = 0;
    for (int v = 1; v < 4; ++v)
        size = std::max(size, std::hypot(q[0][v - 1], q[1][v - 1], q[2][v - 1]));
    double worst = 0;
    const auto& lattice = LatticeNodes(s, p, fam);
    for (std::size_t k = 0; k < lattice.size(); ++k) {
        const Vec3 l = LatticeRefCoords(s, p, lattice[k]);
        Vec3 want = x[0];
        for (int r = 0; r < 3; ++r)
            for (int col = 0; col < 3; ++col)
                want[r] += map[r][col] * (l[col] - xi[0][col]);
        const double* got = &m.points[3 * nodes[k]];
        worst = std::max(
            worst,
            std::hypot(got[0] - want[0], got[1] - want[1], got[2] - want[2]) / size);
    }
    return worst;
}

void ExpectAffineCells(const Mesh& m, double tolerance) {
    for (std::int64_t c = 0; c < m.CellCount(); ++c) {
        double det = 0;
        const double dev = AffineDeviation(m, c, &det);
        EXPECT_LT(dev, tolerance) << "cell " << c << " (" << ShapeName(m.cellShape[c])
                                  << ", order " << int(m.cellOrder[c]) << ")";
        EXPECT_GT(det, 0) << "cell " << c << " is inside out";
    }
}

// ---------------------------------------------------------------- VTK's own files

struct Kind {
    CellShape shape;
    int order;
    CellFamily family;
};

// The cells of scripts/gen_legacy_fixtures.py: VTK type per file cell, and what hpray
// makes of the 3-D ones.
const int kFixtureTypes[] = {10, 12, 13, 5,  14, 24, 25, 26,
                             3,  27, 29, 32, 71, 72, 73, 11};

Kind ExpectedKind(int vtkType) {
    constexpr auto L = CellFamily::Lagrange;
    constexpr auto S = CellFamily::Serendipity;
    switch (vtkType) {
        case 10:
            return {CellShape::Tet, 1, L};
        case 11:
        case 12:
            return {CellShape::Hex, 1, L};
        case 13:
            return {CellShape::Wedge, 1, L};
        case 14:
            return {CellShape::Pyramid, 1, L};
        case 24:
            return {CellShape::Tet, 2, L};
        case 25:
            return {CellShape::Hex, 2, S};
        case 26:
            return {CellShape::Wedge, 2, S};
        case 27:
            return {CellShape::Pyramid, 2, S};
        case 29:
            return {CellShape::Hex, 2, L};
        case 32:
            return {CellShape::Wedge, 2, L};
        case 71:
            return {CellShape::Tet, 3, L};
        case 72:
            return {CellShape::Hex, 2, L};
        case 73:
            return {CellShape::Wedge, 2, L};
    }
    return {CellShape::Tet, 0, L};
}

void CheckFixture(const std::string& name, bool ascii) {
    SCOPED_TRACE(name);
    const Mesh m = ReadVtkLegacy(std::string(HPRAY_TEST_DATA) + "/" + name, {});
    ASSERT_EQ(m.PointCount(), 204);
    std::vector<int> kept;  // file index of each mesh cell
    for (int c = 0; c < 16; ++c)
        if (kFixtureTypes[c] != 3 && kFixtureTypes[c] != 5) kept.push_back(c);
    ASSERT_EQ(m.CellCount(), static_cast<std::int64_t>(kept.size()));
    for (std::size_t c = 0; c < kept.size(); ++c) {
        const Kind k = ExpectedKind(kFixtureTypes[kept[c]]);
        EXPECT_EQ(m.cellShape[c], k.shape) << c;
        EXPECT_EQ(m.cellOrder[c], k.order) << c;
        EXPECT_EQ(m.cellFamily[c], k.family) << c;
    }
    // ASCII files carry 11 significant digits.
    const double tol = ascii ? 1e-8 : 1e-13;
    ExpectAffineCells(m, tol);

    auto point = [&](std::int64_t i) { return &m.points[3 * i]; };
    const Field* a = m.FindPointField("analytic");
    const Field* af = m.FindPointField("analytic_f");
    const Field* vel = m.FindPointField("vel");
    const Field* pair = m.FindPointField("pair");
    const Field* idx = m.FindPointField("idx");
    ASSERT_TRUE(a && af && vel && pair && idx);
    ASSERT_EQ(vel->components, 3);
    ASSERT_EQ(pair->components, 2);
    for (std::int64_t i = 0; i < m.PointCount(); ++i) {
        const double* x = point(i);
        const double f = Analytic(x[0], x[1], x[2]);
        ASSERT_NEAR(a->values[i], f, tol) << i;
        // Float arrays: VTK's ASCII writer keeps 6 significant digits.
        ASSERT_NEAR(af->values[i], f, 1e-5) << i;
        for (int c = 0; c < 3; ++c)
            ASSERT_NEAR(vel->values[3 * i + c], (c + 1) * x[c],
                        1e-5 * (1 + std::abs(x[c])) + tol);
        ASSERT_NEAR(pair->values[2 * i], x[0] + x[1], 2 * tol);
        ASSERT_NEAR(pair->values[2 * i + 1], x[0] - x[1], 2 * tol);
        ASSERT_EQ(idx->values[i], i);
    }
    const Field* id = m.FindCellField("cellid");
    const Field* weight = m.FindCellField("weight");
    ASSERT_TRUE(id && weight);
    for (std::size_t c = 0; c < kept.size(); ++c) {
        EXPECT_EQ(id->values[c],
                  kept[c]);  // the 2-D cells' values were dropped with them
        EXPECT_EQ(weight->values[c], 0.25 * kept[c]);
    }
}

TEST(VtkLegacy, VtkWrittenAscii42) { CheckFixture("legacy_ascii_42.vtk", true); }
TEST(VtkLegacy, VtkWrittenAscii51) { CheckFixture("legacy_ascii_51.vtk", true); }
TEST(VtkLegacy, VtkWrittenBinary42) { CheckFixture("legacy_binary_42.vtk", false); }
TEST(VtkLegacy, VtkWrittenBinary51) { CheckFixture("legacy_binary_51.vtk", false); }

// Version 4.2 stores VTK_LAGRANGE_HEXAHEDRON in the pre-VTK-9 order; both files describe
// the same mesh.
TEST(VtkLegacy, LegacyHexOrderDependsOnVersion) {
    const Mesh a =
        ReadVtkLegacy(std::string(HPRAY_TEST_DATA) + "/legacy_binary_42.vtk", {});
    const Mesh b =
        ReadVtkLegacy(std::string(HPRAY_TEST_DATA) + "/legacy_binary_51.vtk", {});
    EXPECT_EQ(a.points, b.points);
    EXPECT_EQ(a.connectivity, b.connectivity);
    EXPECT_EQ(a.cellOffsets, b.cellOffsets);
}

TEST(VtkLegacy, FieldsOption) {
    ReadOptions o;
    o.fields = std::set<std::string>{"vel.x", "weight", "nothing"};
    const Mesh m =
        ReadVtkLegacy(std::string(HPRAY_TEST_DATA) + "/legacy_binary_51.vtk", o);
    ASSERT_EQ(m.pointFields.size(), 1u);
    EXPECT_EQ(m.pointFields[0].name, "vel");
    ASSERT_EQ(m.cellFields.size(), 1u);
    EXPECT_EQ(m.cellFields[0].name, "weight");
    EXPECT_EQ(ReadMesh(std::string(HPRAY_TEST_DATA) + "/legacy_ascii_42.vtk").CellCount(),
              14);
}

// ---------------------------------------------------------------- files written here

// Writes legacy VTK: keyword lines as text, data as ASCII or big-endian binary.
class VtkWriter {
  public:
    explicit VtkWriter(bool binary) : binary_(binary) {}
    void Line(const std::string& s) { out_ += s + "\n"; }
    template <typename T>
    void Values(const std::vector<T>& v) {
        if (binary_) {
            for (T x : v) {
                char b[sizeof(T)];
                std::memcpy(b, &x, sizeof(T));
                std::reverse(b, b + sizeof(T));  // this machine is little-endian
                out_.append(b, sizeof(T));
            }
            out_ += "\n";
            return;
        }
        std::ostringstream os;
        os.precision(17);
        for (std::size_t i = 0; i < v.size(); ++i) os << (i ? " " : "") << +v[i];
        out_ += os.str() + "\n";
    }
    const std::string& str() const { return out_; }

  private:
    bool binary_;
    std::string out_;
};

struct RefCell {
    int type;
    int order;
    std::vector<Vec3> geometry;  // VTK node n, a valid (outward-faced) cell
};

// VTK's parametric coordinates of every cell type VTK 9.1 defines them for
// (tests/data/vtk_ref_coords.json, written from VTK), placed as VTK's valid geometry.
std::vector<RefCell> RefCells() {
    std::ifstream in(HPRAY_TEST_DATA "/vtk_ref_coords.json");
    const json j = json::parse(in);
    std::vector<RefCell> cells;
    for (const json& c : j.at("cells")) {
        RefCell r{c.at("vtk_type").get<int>(), c.at("order").get<int>(), {}};
        const bool mirror = c.at("valid_geometry").get<std::string>() == "mirror_rs";
        for (const json& p : c.at("pcoords")) {
            Vec3 x{p[0].get<double>(), p[1].get<double>(), p[2].get<double>()};
            if (mirror) std::swap(x[0], x[1]);
            r.geometry.push_back(x);
        }
        // VTK's parametric pyramid is a hex collapsed at the top: the parametric
        // coordinates of the quadratic pyramid's nodes 9..12 are not on the straight
        // edges (i, 4) that VTK documents them on. Put them at those edges' midpoints.
        if (r.type == kVtkQuadraticPyramid)
            for (int i = 0; i < 4; ++i)
                for (int k = 0; k < 3; ++k)
                    r.geometry[9 + i][k] = 0.5 * (r.geometry[i][k] + r.geometry[4][k]);
        cells.push_back(r);
    }
    return cells;
}

// VTK node m of an order-p VTK_LAGRANGE_HEXAHEDRON is file node LegacyHexNode(m) in a
// file older than VTK 9 (README: the node blocks of edges 10 and 11 are exchanged).
int LegacyHexNode(int m, int p) {
    const int e = p - 1, e10 = 8 + 10 * e, e11 = 8 + 11 * e;
    if (m >= e10 && m < e11) return m + e;
    if (m >= e11 && m < e11 + e) return m - e;
    return m;
}

TEST(VtkLegacy, LegacyHexRuleMatchesVtk) {
    std::ifstream in(HPRAY_TEST_DATA "/vtk_ref_coords.json");
    const json j = json::parse(in);
    for (const json& h : j.at("legacy_hex")) {
        const int p = h.at("order").get<int>();
        const std::vector<int> ids = h.at("ids").get<std::vector<int>>();
        for (int m = 0; m < static_cast<int>(ids.size()); ++m)
            EXPECT_EQ(LegacyHexNode(m, p), ids[m]) << p;
    }
}

enum class Layout { Old, New };

// One file with every reference cell (each affinely placed and shifted), a triangle and
// a line in between, the analytic field and a per-cell field.
std::string MakeAllCells(const std::vector<RefCell>& cells, bool binary, Layout layout,
                         const std::string& version, const std::string& idType,
                         std::vector<Vec3>* pointsOut) {
    std::vector<Vec3> points;
    std::vector<std::vector<std::int64_t>> conn;
    std::vector<int> types;
    const bool legacyHex = version < "5.1";
    for (std::size_t c = 0; c < cells.size(); ++c) {
        const RefCell& r = cells[c];
        // x = A xi + b with det A > 0 (a fixed shear and stretch).
        const double A[3][3] = {{1.1, 0.2, -0.1}, {0.1, 0.9, 0.15}, {-0.05, 0.1, 1.2}};
        std::vector<std::int64_t> ids(r.geometry.size());
        for (std::size_t n = 0; n < r.geometry.size(); ++n) {
            const Vec3& xi = r.geometry[n];
            Vec3 x;
            for (int i = 0; i < 3; ++i)
                x[i] = A[i][0] * xi[0] + A[i][1] * xi[1] + A[i][2] * xi[2] +
                       (i == 0 ? 2.0 * c : 0);
            const int fileNode = r.type == kVtkLagrangeHexahedron && legacyHex
                                     ? LegacyHexNode(n, r.order)
                                     : n;
            ids[fileNode] = static_cast<std::int64_t>(points.size());
            points.push_back(x);
        }
        conn.push_back(ids);
        types.push_back(r.type);
        if (c == 1) {  // a triangle on existing points
            conn.push_back({0, 1, 2});
            types.push_back(5);
        }
    }
    conn.push_back({0, 1});  // a line at the end
    types.push_back(3);

    VtkWriter w(binary);
    w.Line("# vtk DataFile Version " + version);
    w.Line("every cell type");
    w.Line(binary ? "BINARY" : "ASCII");
    w.Line("DATASET UNSTRUCTURED_GRID");
    w.Line("FIELD FieldData 1");
    w.Line("TIME 1 1 double");
    w.Values(std::vector<double>{2.5});
    w.Line("POINTS " + std::to_string(points.size()) + " double");
    std::vector<double> xyz;
    for (const Vec3& p : points) xyz.insert(xyz.end(), p.begin(), p.end());
    w.Values(xyz);
    std::size_t total = 0;
    for (const auto& c : conn) total += c.size();
    if (layout == Layout::Old) {
        w.Line("CELLS " + std::to_string(conn.size()) + " " +
               std::to_string(total + conn.size()));
        std::vector<std::int32_t> v;
        for (const auto& c : conn) {
            v.push_back(static_cast<std::int32_t>(c.size()));
            for (std::int64_t id : c) v.push_back(static_cast<std::int32_t>(id));
        }
        w.Values(v);
    } else {
        w.Line("CELLS " + std::to_string(conn.size() + 1) + " " + std::to_string(total));
        std::vector<std::int64_t> offsets{0}, ids;
        for (const auto& c : conn) {
            ids.insert(ids.end(), c.begin(), c.end());
            offsets.push_back(static_cast<std::int64_t>(ids.size()));
        }
        w.Line("OFFSETS " + idType);
        if (idType == "vtktypeint32") {
            w.Values(std::vector<std::int32_t>(offsets.begin(), offsets.end()));
        } else {
            w.Values(offsets);
        }
        w.Line("CONNECTIVITY " + idType);
        if (idType == "vtktypeint32") {
            w.Values(std::vector<std::int32_t>(ids.begin(), ids.end()));
        } else {
            w.Values(ids);
        }
    }
    w.Line("CELL_TYPES " + std::to_string(types.size()));
    w.Values(std::vector<std::int32_t>(types.begin(), types.end()));
    w.Line("CELL_DATA " + std::to_string(types.size()));
    w.Line("SCALARS type short 1");
    w.Line("LOOKUP_TABLE default");
    w.Values(std::vector<std::int16_t>(types.begin(), types.end()));
    w.Line("POINT_DATA " + std::to_string(points.size()));
    w.Line("SCALARS analytic double");
    w.Line("LOOKUP_TABLE default");
    std::vector<double> f;
    for (const Vec3& p : points) f.push_back(Analytic(p[0], p[1], p[2]));
    w.Values(f);
    w.Line("NORMALS n float");
    std::vector<float> n;
    for (const Vec3& p : points) n.insert(n.end(), {0.f, 0.f, static_cast<float>(p[2])});
    w.Values(n);
    *pointsOut = points;
    return w.str();
}

void CheckAllCells(const std::vector<RefCell>& cells, const std::string& path,
                   const std::vector<Vec3>& points) {
    SCOPED_TRACE(path);
    const Mesh m = ReadVtkLegacy(path, {});
    ASSERT_EQ(m.PointCount(), static_cast<std::int64_t>(points.size()));
    ASSERT_EQ(m.CellCount(), static_cast<std::int64_t>(cells.size()));
    for (std::size_t c = 0; c < cells.size(); ++c) {
        std::string why;
        const auto kind = ClassifyVtkCell(
            cells[c].type, static_cast<long long>(cells[c].geometry.size()), nullptr,
            &why);
        ASSERT_TRUE(kind) << why;
        EXPECT_EQ(m.cellShape[c], kind->shape);
        EXPECT_EQ(m.cellOrder[c], cells[c].order) << "type " << cells[c].type;
    }
    ExpectAffineCells(m, 1e-12);
    const Field* f = m.FindPointField("analytic");
    ASSERT_NE(f, nullptr);
    for (std::size_t i = 0; i < points.size(); ++i)
        ASSERT_EQ(f->values[i], Analytic(points[i][0], points[i][1], points[i][2]));
    const Field* t = m.FindCellField("type");
    ASSERT_NE(t, nullptr);
    for (std::size_t c = 0; c < cells.size(); ++c) EXPECT_EQ(t->values[c], cells[c].type);
    const Field* n = m.FindPointField("n");
    ASSERT_NE(n, nullptr);
    EXPECT_EQ(n->components, 3);
}

TEST(VtkLegacy, EveryCellTypeAsciiNewLayout) {
    const auto cells = RefCells();
    EXPECT_EQ(cells.size(), 28u);
    std::vector<Vec3> points;
    const std::string content =
        MakeAllCells(cells, false, Layout::New, "5.1", "vtktypeint64", &points);
    CheckAllCells(cells, WriteTemp("all_ascii_51.vtk", content), points);
}

TEST(VtkLegacy, EveryCellTypeAsciiOldLayout) {
    const auto cells = RefCells();
    std::vector<Vec3> points;
    const std::string content =
        MakeAllCells(cells, false, Layout::Old, "2.0", "", &points);
    CheckAllCells(cells, WriteTemp("all_ascii_20.vtk", content), points);
}

TEST(VtkLegacy, EveryCellTypeBinaryOldLayout) {
    const auto cells = RefCells();
    std::vector<Vec3> points;
    const std::string content =
        MakeAllCells(cells, true, Layout::Old, "4.2", "", &points);
    CheckAllCells(cells, WriteTemp("all_binary_42.vtk", content), points);
}

TEST(VtkLegacy, EveryCellTypeBinaryNewLayout) {
    const auto cells = RefCells();
    std::vector<Vec3> points;
    const std::string content =
        MakeAllCells(cells, true, Layout::New, "5.1", "vtktypeint32", &points);
    CheckAllCells(cells, WriteTemp("all_binary_51.vtk", content), points);
}

// A voxel is a hexahedron numbered like the lattice (i fastest).
TEST(VtkLegacy, Voxel) {
    const std::string content =
        "# vtk DataFile Version 3.0\nvoxel\nASCII\nDATASET UNSTRUCTURED_GRID\n"
        "POINTS 8 float\n0 0 0 1 0 0 0 2 0 1 2 0 0 0 3 1 0 3 0 2 3 1 2 3\n"
        "CELLS 1 9\n8 0 1 2 3 4 5 6 7\nCELL_TYPES 1\n11\n";
    const Mesh m = ReadVtkLegacy(WriteTemp("voxel.vtk", content), {});
    ASSERT_EQ(m.CellCount(), 1);
    EXPECT_EQ(m.cellShape[0], CellShape::Hex);
    ExpectAffineCells(m, 1e-15);
}

// ---------------------------------------------------------------- malformed input

const char* kSmall =
    "# vtk DataFile Version 4.2\n"     // 1
    "small\n"                          // 2
    "ASCII\n"                          // 3
    "DATASET UNSTRUCTURED_GRID\n"      // 4
    "POINTS 5 float\n"                 // 5
    "0 0 0 1 0 0 0 1 0 0 0 1 1 1 1\n"  // 6
    "CELLS 2 8\n"                      // 7
    "4 0 1 2 3\n"                      // 8
    "2 3 4\n"                          // 9
    "CELL_TYPES 2\n"                   // 10
    "10\n"                             // 11
    "3\n"                              // 12
    "CELL_DATA 2\n"                    // 13
    "SCALARS c int 1\n"                // 14
    "LOOKUP_TABLE default\n"           // 15
    "7 8\n"                            // 16
    "POINT_DATA 5\n"                   // 17
    "SCALARS u double\n"               // 18
    "LOOKUP_TABLE default\n"           // 19
    "1 2 3 4 5\n";                     // 20

TEST(VtkLegacy, SmallAscii) {
    const Mesh m = ReadVtkLegacy(WriteTemp("small.vtk", kSmall), {});
    EXPECT_EQ(m.PointCount(), 5);
    ASSERT_EQ(m.CellCount(), 1);
    EXPECT_EQ(m.cellShape[0], CellShape::Tet);
    ASSERT_NE(m.FindCellField("c"), nullptr);
    EXPECT_EQ(m.FindCellField("c")->values, std::vector<double>{7});
    EXPECT_EQ(m.FindPointField("u")->values, (std::vector<double>{1, 2, 3, 4, 5}));
}

std::string Replace(std::string s, const std::string& from, const std::string& to) {
    const std::size_t at = s.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    return s.replace(at, from.size(), to);
}

void ExpectInputError(const std::string& name, const std::string& content,
                      const std::string& mustContain, const std::string& where) {
    const std::string path = WriteTemp(name, content);
    try {
        ReadVtkLegacy(path, {});
        ADD_FAILURE() << name << ": no error";
    } catch (const InputError& e) {
        EXPECT_EQ(e.source(), path) << name;
        EXPECT_NE(std::string(e.what()).find(mustContain), std::string::npos)
            << name << ": " << e.what();
        EXPECT_EQ(e.where().rfind(where, 0), 0u) << name << ": " << e.what();
    }
}

TEST(VtkLegacy, MalformedAscii) {
    const std::string s = kSmall;
    ExpectInputError("truncated_points.vtk", s.substr(0, s.find("0 1 1 1 1")),
                     "more than the", "line 5");
    ExpectInputError("truncated_data.vtk", s.substr(0, s.find("4 5\n")) + "      ",
                     "unexpected end of file", "line 20");
    ExpectInputError("structured.vtk",
                     Replace(s, "DATASET UNSTRUCTURED_GRID", "DATASET STRUCTURED_POINTS"),
                     "dataset STRUCTURED_POINTS is not supported", "line 4");
    ExpectInputError("huge.vtk",
                     Replace(s, "POINTS 5 float", "POINTS 1000000000000 float"),
                     "1000000000000", "line 5");
    ExpectInputError("bad_id.vtk", Replace(s, "4 0 1 2 3", "4 0 1 2 9"),
                     "point index 9 is outside [0, 5)", "line 8");
    ExpectInputError("negative_id.vtk", Replace(s, "4 0 1 2 3", "4 0 1 -2 3"),
                     "point index -2", "line 8");
    ExpectInputError("polyhedron.vtk", Replace(s, "10\n3\n", "42\n3\n"), "cell 0",
                     "line 11");
    ExpectInputError("wrong_count.vtk",
                     Replace(s, "4 0 1 2 3\n2 3 4", "3 0 1 2\n3 2 3 4"), "cell 0",
                     "line 11");
    ExpectInputError("types_count.vtk", Replace(s, "CELL_TYPES 2", "CELL_TYPES 3"),
                     "CELL_TYPES has 3 entries for 2 cells", "line 10");
    ExpectInputError("cells_size.vtk", Replace(s, "CELLS 2 8", "CELLS 2 9"),
                     "CELLS size 9", "line 7");
    ExpectInputError("point_data_count.vtk", Replace(s, "POINT_DATA 5", "POINT_DATA 6"),
                     "POINT_DATA 6 for 5 points", "line 17");
    ExpectInputError("nan_point.vtk", Replace(s, "0 0 0 1 0 0", "0 0 0 1 nan 0"), "NaN",
                     "line 6");
    ExpectInputError("nan_field.vtk", Replace(s, "1 2 3 4 5", "1 2 inf 4 5"), "NaN",
                     "line 20");
    ExpectInputError("bad_type.vtk", Replace(s, "POINTS 5 float", "POINTS 5 quaternion"),
                     "data type 'quaternion'", "line 5");
    ExpectInputError("no_lut.vtk", Replace(s, "LOOKUP_TABLE default\n1 2", "1 2"),
                     "LOOKUP_TABLE", "line 19");
    ExpectInputError("not_vtk.vtk", "hello\n", "not a legacy VTK file", "line 1");
    ExpectInputError("version.vtk", Replace(s, "Version 4.2", "Version 9.9"),
                     "unsupported legacy VTK version", "line 1");
    ExpectInputError("keyword.vtk", Replace(s, "CELL_TYPES 2", "CELL_KINDS 2"),
                     "unexpected keyword 'CELL_KINDS'", "line 10");
    ExpectInputError("offsets.vtk",
                     Replace(s, "CELLS 2 8\n4 0 1 2 3\n2 3 4",
                             "CELLS 3 6\nOFFSETS vtktypeint64\n0 4 3\n"
                             "CONNECTIVITY vtktypeint64\n0 1 2 3 3 4"),
                     "OFFSETS decrease", "line 9");
}

TEST(VtkLegacy, MalformedBinary) {
    const std::string s =
        ReadFile(std::string(HPRAY_TEST_DATA) + "/legacy_binary_51.vtk");
    for (const char* marker : {"CELLS", "CELL_TYPES", "POINT_DATA"}) {
        const std::size_t at = s.find(marker);
        ASSERT_NE(at, std::string::npos);
        ExpectInputError(std::string("cut_") + marker + ".vtk", s.substr(0, at - 60), "",
                         "byte");
    }
    const std::size_t points = s.find("POINTS 204 double");
    ExpectInputError("binary_huge.vtk", Replace(s, "POINTS 204", "POINTS 100000000000"),
                     "100000000000", "byte " + std::to_string(points));
    ExpectInputError("binary_bad_type.vtk", Replace(s, "CELL_TYPES 16", "CELL_TYPES 15"),
                     "CELL_TYPES has 15 entries for 16 cells", "byte");
}

// Truncated and corrupted files: each read either succeeds or throws InputError.
TEST(VtkLegacy, FuzzedInputNeverCrashes) {
    const std::string ascii =
        ReadFile(std::string(HPRAY_TEST_DATA) + "/legacy_ascii_51.vtk");
    const std::string binary =
        ReadFile(std::string(HPRAY_TEST_DATA) + "/legacy_binary_42.vtk");
    std::uint64_t state = 777;
    auto next = [&state] {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return state >> 33;
    };
    int errors = 0;
    for (int i = 0; i < 300; ++i) {
        std::string s = (i % 2 ? binary : ascii);
        if (i % 3 == 0) s.resize(next() % s.size());
        for (int k = 0; k < 1 + i % 4; ++k)
            s[next() % s.size()] = static_cast<char>(next());
        const std::string path = WriteTemp("fuzz.vtk", s);
        try {
            ReadVtkLegacy(path, {});
        } catch (const InputError&) {
            ++errors;
        }
    }
    EXPECT_GT(errors, 50);
}

}  // namespace
}  // namespace hpray

// Cell geometry, inversion, fields and guaranteed bounds on random curved cells of every
// shape, order and family.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <vector>

#include "elements/basis.h"
#include "elements/bounds.h"
#include "elements/element_test_util.h"
#include "elements/field.h"
#include "elements/geometry.h"
#include "elements/mesh_geometry.h"
#include "io/mesh_io.h"
#include "util/check.h"

namespace hpray {
namespace {

using testing::AllCellKinds;
using testing::CellKind;
using testing::FamilyName;
using testing::RandomRefPoint;

std::string Name(const CellKind& k) {
    return std::string(ShapeName(k.shape)) + " p" + std::to_string(k.order) + " " +
           FamilyName(k.family);
}

// A random cell: an affine image of the reference cell (random rotation-like matrix with
// scales in [0.5, 2], positive determinant) plus a smooth perturbation of amplitude
// `bend` (a sum of sines of the reference coordinates) evaluated at the nodes.
struct RandomCell {
    std::vector<double> nodes;
    double a[9];
    double b[3];
};

RandomCell MakeRandomCell(const BasisTable& basis, std::mt19937_64& rng, double bend) {
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    RandomCell c;
    for (;;) {
        for (double& v : c.a) v = u(rng);
        for (int d = 0; d < 3; ++d) c.a[4 * d] += d == 0 ? 2.0 : 1.5;
        double inv[9];
        const double det = Invert3x3(c.a, inv);
        if (det > 0.5) break;
    }
    for (double& v : c.b) v = 10.0 * u(rng);
    double w[3][3], ph[3];
    for (int d = 0; d < 3; ++d) {
        for (int e = 0; e < 3; ++e) w[d][e] = 2.0 * u(rng);
        ph[d] = 3.0 * u(rng);
    }
    for (const auto& r : basis.refNodes)
        for (int d = 0; d < 3; ++d) {
            double x = c.b[d];
            for (int e = 0; e < 3; ++e) x += c.a[3 * d + e] * r[e];
            x += bend * std::sin(w[d][0] * r[0] + w[d][1] * r[1] + w[d][2] * r[2] + ph[d]);
            c.nodes.push_back(x);
        }
    return c;
}

// Minimum of det J over random points and the nodes (the sampled positivity check).
double MinDetJ(const CellGeometry& g, std::mt19937_64& rng, EvalWorkspace& ws) {
    double worst = 1e300;
    for (int q = 0; q < 300 + g.basis->nodeCount; ++q) {
        std::array<double, 3> r = q < g.basis->nodeCount ? g.basis->refNodes[q]
                                                         : RandomRefPoint(g.basis->shape, rng);
        if (g.basis->shape == CellShape::Pyramid) r[2] = std::min(r[2], 1.0 - 1e-9);
        double x[3], j[9], inv[9];
        WorldFromRef(g, r.data(), ws, x, j);
        worst = std::min(worst, Invert3x3(j, inv));
    }
    return worst;
}

// A curved cell with a positive Jacobian (checked by sampling); halves the bend until so.
RandomCell CurvedCell(const BasisTable& basis, std::mt19937_64& rng, EvalWorkspace& ws,
                      double bend = 0.15) {
    // A linear tet is always affine: there is no curved one.
    const bool canCurve = basis.shape != CellShape::Tet || basis.order > 1;
    for (int attempt = 0;; ++attempt, bend *= 0.5) {
        HPRAY_CHECK(attempt < 30);
        RandomCell c = MakeRandomCell(basis, rng, bend);
        CellGeometry g = MakeCellGeometry(basis, c.nodes.data());
        if (g.affine == !canCurve && MinDetJ(g, rng, ws) > 0.05) return c;
    }
}

// Reference points on the boundary: vertices, edge points and face points of the cell.
std::vector<std::array<double, 3>> BoundaryPoints(CellShape shape, std::mt19937_64& rng) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::vector<std::array<double, 3>> verts;
    for (const auto& v : VertexLattice(shape, 1)) verts.push_back(LatticeRefCoords(shape, 1, v));
    std::vector<std::array<double, 3>> pts = verts;
    // Edges and faces: convex combinations of two / three vertices of one face. Faces are
    // found as vertex triples sharing a face plane (every boundary point of these convex
    // cells is such a combination on some face).
    for (std::size_t i = 0; i < verts.size(); ++i)
        for (std::size_t j = i + 1; j < verts.size(); ++j) {
            const double l = u(rng);
            std::array<double, 3> x;
            for (int d = 0; d < 3; ++d) x[d] = (1 - l) * verts[i][d] + l * verts[j][d];
            double ref[3] = {x[0], x[1], x[2]};
            if (std::abs(RefOutsideDistance(shape, ref)) < 1e-14) pts.push_back(x);
            for (std::size_t k = j + 1; k < verts.size(); ++k) {
                double w0 = u(rng), w1 = u(rng), w2 = u(rng);
                const double s = w0 + w1 + w2;
                for (int d = 0; d < 3; ++d)
                    x[d] = (w0 * verts[i][d] + w1 * verts[j][d] + w2 * verts[k][d]) / s;
                double r2[3] = {x[0], x[1], x[2]};
                if (std::abs(RefOutsideDistance(shape, r2)) < 1e-14) pts.push_back(x);
            }
        }
    return pts;
}

double Dist(const double a[3], const double b[3]) {
    return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                     (a[2] - b[2]) * (a[2] - b[2]));
}

TEST(Geometry, AffineCellsAreDetectedAndInvertedInClosedForm) {
    EvalWorkspace ws;
    for (const CellKind& k : AllCellKinds()) {
        const BasisTable& basis = GetBasis(k.shape, k.order, k.family);
        std::mt19937_64 rng(21 + k.order);
        RandomCell c = MakeRandomCell(basis, rng, 0.0);
        CellGeometry g = MakeCellGeometry(basis, c.nodes.data());
        ASSERT_TRUE(g.affine) << Name(k);
        EXPECT_EQ(g.lineDegree, basis.lineDegree);
        // The same nodes through the Newton path give the same answer.
        CellGeometry curvedPath = MakeCellGeometry(basis, c.nodes.data(), -1.0);
        ASSERT_FALSE(curvedPath.affine);
        for (int q = 0; q < 20; ++q) {
            const auto r = RandomRefPoint(k.shape, rng);
            double x[3], expect[3];
            for (int d = 0; d < 3; ++d) {
                expect[d] = c.b[d];
                for (int e = 0; e < 3; ++e) expect[d] += c.a[3 * d + e] * r[e];
            }
            WorldFromRef(g, r.data(), ws, x, nullptr);
            EXPECT_LT(Dist(x, expect), 1e-13 * g.size) << Name(k);
            const InversionResult inv = RefFromWorld(g, x, ws);
            EXPECT_TRUE(inv.inside && inv.iterations == 0) << Name(k);
            const InversionResult newton = RefFromWorld(curvedPath, x, ws);
            EXPECT_TRUE(newton.inside) << Name(k);
            for (int d = 0; d < 3; ++d) {
                EXPECT_NEAR(inv.ref[d], r[d], 1e-12) << Name(k);
                EXPECT_NEAR(newton.ref[d], r[d], 1e-12) << Name(k);
            }
        }
        // A tiny bend makes the cell curved.
        std::mt19937_64 rng2(22);
        RandomCell bent = MakeRandomCell(basis, rng2, 1e-9);
        if (k.order > 1 || k.shape != CellShape::Tet) {
            EXPECT_FALSE(MakeCellGeometry(basis, bent.nodes.data()).affine) << Name(k);
        }
    }
}

// x -> ref -> x on random curved cells, interior points and points within 1e-10 of (and
// exactly on) faces, edges and vertices.
TEST(Geometry, InversionRoundTripsOnCurvedCells) {
    EvalWorkspace ws;
    for (const CellKind& k : AllCellKinds()) {
        const BasisTable& basis = GetBasis(k.shape, k.order, k.family);
        std::mt19937_64 rng(100 + 7 * k.order + static_cast<int>(k.shape));
        int maxIter = 0;
        double worst = 0.0;
        for (int cell = 0; cell < 2; ++cell) {
            RandomCell c = CurvedCell(basis, rng, ws);
            CellGeometry g = MakeCellGeometry(basis, c.nodes.data());
            std::vector<std::array<double, 3>> refs;
            for (int q = 0; q < 60; ++q) refs.push_back(RandomRefPoint(k.shape, rng));
            const auto centre = RefCenter(k.shape);
            for (const auto& b : BoundaryPoints(k.shape, rng)) {
                refs.push_back(b);
                for (double eps : {1e-10, 1e-12}) {  // pulled towards the centre
                    std::array<double, 3> in;
                    for (int d = 0; d < 3; ++d) in[d] = b[d] + eps * (centre[d] - b[d]);
                    refs.push_back(in);
                }
            }
            for (const auto& r : refs) {
                double x[3], x2[3];
                WorldFromRef(g, r.data(), ws, x, nullptr);
                const InversionResult inv = RefFromWorld(g, x, ws);
                ASSERT_TRUE(inv.converged) << Name(k) << " ref " << r[0] << " " << r[1] << " "
                                           << r[2] << " status " << int(inv.status);
                EXPECT_TRUE(inv.inside) << Name(k) << " dist " << inv.outsideDistance;
                WorldFromRef(g, inv.ref.data(), ws, x2, nullptr);
                worst = std::max(worst, Dist(x, x2) / g.size);
                maxIter = std::max(maxIter, inv.iterations);
            }
        }
        EXPECT_LT(worst, 1e-12) << Name(k);
        EXPECT_LT(maxIter, 30) << Name(k);
    }
}

// MFEM's order-9 spiral (shared data): 8 hexes swept around an axis, so curved that the
// least-squares affine fit (the first Newton start) is off by a third of a cell and
// Newton from it or from the centre leaves the cell for most interior points. Every
// interior point must still be found (from the nearest node) and map back to the
// reference point it came from.
TEST(Geometry, InversionInMfemOrderNineSpiral) {
    const std::string path = std::string(HPRAY_SHARED_DATA) + "/mfem_spiral_hex_p9.vtu";
    if (!std::filesystem::exists(path)) GTEST_SKIP() << "no shared data";
    const Mesh mesh = ReadMesh(path);
    const MeshGeometry geometry = MeshGeometry::Build(mesh);
    ASSERT_EQ(mesh.CellCount(), 8);
    EXPECT_EQ(geometry.derivedCells, 0);
    EvalWorkspace ws;
    std::mt19937_64 rng(99);
    double worst = 0, deviation = 0;
    CellScratch scratch;
    for (std::int64_t c = 0; c < mesh.CellCount(); ++c) {
        const CellGeometry& g = geometry.Cell(c, scratch);
        ASSERT_EQ(g.basis->order, 9);
        deviation = std::max(deviation, g.affineDeviation / g.size);
        ASSERT_GT(MinDetJ(g, rng, ws), 0.0);
        for (int q = 0; q < 100; ++q) {
            const auto r = RandomRefPoint(CellShape::Hex, rng);
            double x[3];
            WorldFromRef(g, r.data(), ws, x, nullptr);
            const InversionResult inv = RefFromWorld(g, x, ws);
            ASSERT_TRUE(inv.converged) << "ref " << r[0] << " " << r[1] << " " << r[2]
                                       << " status " << int(inv.status);
            EXPECT_TRUE(inv.inside) << inv.outsideDistance;
            for (int d = 0; d < 3; ++d) worst = std::max(worst, std::abs(inv.ref[d] - r[d]));
        }
    }
    EXPECT_GT(deviation, 0.25);  // the hard case it is meant to be
    EXPECT_LT(worst, 1e-10);
}

// Points 1e-6 (relative to the cell size) beyond a face along the outward world normal are
// outside; points the same distance inside are inside; far points are outside.
TEST(Geometry, PointsOutsideAreRecognised) {
    EvalWorkspace ws;
    for (const CellKind& k : AllCellKinds()) {
        const BasisTable& basis = GetBasis(k.shape, k.order, k.family);
        std::mt19937_64 rng(300 + 7 * k.order + static_cast<int>(k.shape));
        RandomCell c = CurvedCell(basis, rng, ws);
        CellGeometry g = MakeCellGeometry(basis, c.nodes.data());
        const auto centre = RefCenter(k.shape);
        int tested = 0;
        for (const auto& b : BoundaryPoints(k.shape, rng)) {
            // Interior of a face only: one face plane active, away from edges.
            double br[3] = {b[0], b[1], b[2]};
            // Outward reference normal by finite differences of the face distance.
            double nRef[3];
            for (int d = 0; d < 3; ++d) {
                double y[3] = {b[0], b[1], b[2]};
                y[d] += 1e-7;
                nRef[d] = (RefOutsideDistance(k.shape, y) - RefOutsideDistance(k.shape, br)) / 1e-7;
            }
            // Skip vertices/edges (the distance's gradient is not a face normal there).
            double nn = std::sqrt(nRef[0] * nRef[0] + nRef[1] * nRef[1] + nRef[2] * nRef[2]);
            if (std::abs(nn - 1.0) > 1e-3) continue;
            bool nearEdge = false;
            for (int d = 0; d < 3 && !nearEdge; ++d)
                for (double s : {-0.02, 0.02}) {
                    double y[3] = {b[0], b[1], b[2]};
                    y[d] += s;
                    double z[3];
                    for (int e = 0; e < 3; ++e) z[e] = y[e] - 0.05 * nRef[e];
                    if (RefOutsideDistance(k.shape, z) > -0.01) nearEdge = true;
                }
            if (nearEdge) continue;
            double x[3], jac[9], inv[9];
            WorldFromRef(g, br, ws, x, jac);
            ASSERT_NE(Invert3x3(jac, inv), 0.0);
            double n[3];  // world normal = J^-T nRef
            for (int i = 0; i < 3; ++i) n[i] = inv[i] * nRef[0] + inv[3 + i] * nRef[1] + inv[6 + i] * nRef[2];
            const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            for (double sign : {1.0, -1.0}) {
                double y[3];
                for (int d = 0; d < 3; ++d) y[d] = x[d] + sign * 1e-6 * g.size * n[d] / len;
                const InversionResult r = RefFromWorld(g, y, ws);
                ASSERT_TRUE(r.converged) << Name(k);
                EXPECT_EQ(r.inside, sign < 0) << Name(k) << " dist " << r.outsideDistance;
            }
            ++tested;
        }
        EXPECT_GT(tested, 0) << Name(k);
        std::uniform_real_distribution<double> u(-1.0, 1.0);
        for (int q = 0; q < 10; ++q) {
            double cx[3];
            WorldFromRef(g, centre.data(), ws, cx, nullptr);
            double y[3];
            for (int d = 0; d < 3; ++d) y[d] = cx[d] + 5.0 * g.size * u(rng);
            const InversionResult r = RefFromWorld(g, y, ws);
            double back[3];
            WorldFromRef(g, r.ref.data(), ws, back, nullptr);
            // Either recognised as outside, or a genuine preimage (a far point can only be
            // "inside" if it truly is the image of a reference point, which it is not).
            EXPECT_FALSE(r.inside) << Name(k);
        }
    }
}

// Point fields interpolating a world-linear function g(x) = c . x + d are exactly g on
// any cell (the geometry uses the same space), so value and world gradient are known.
TEST(Fields, WorldLinearFieldHasExactValueAndGradient) {
    EvalWorkspace ws;
    for (const CellKind& k : AllCellKinds()) {
        const BasisTable& basis = GetBasis(k.shape, k.order, k.family);
        std::mt19937_64 rng(500 + k.order + 13 * static_cast<int>(k.shape));
        RandomCell c = CurvedCell(basis, rng, ws);
        CellGeometry g = MakeCellGeometry(basis, c.nodes.data());
        const double cg[3] = {0.3, -1.7, 2.2}, d0 = 4.0;
        std::vector<double> nodal(basis.nodeCount);
        for (int m = 0; m < basis.nodeCount; ++m)
            nodal[m] = d0 + cg[0] * c.nodes[3 * m] + cg[1] * c.nodes[3 * m + 1] +
                       cg[2] * c.nodes[3 * m + 2];
        CellScalar field{nodal.data(), 0.0};
        for (int q = 0; q < 20; ++q) {
            const auto r = RandomRefPoint(k.shape, rng);
            double x[3];
            WorldFromRef(g, r.data(), ws, x, nullptr);
            const double expect = d0 + cg[0] * x[0] + cg[1] * x[1] + cg[2] * x[2];
            double v, grad[3];
            ASSERT_TRUE(FieldValueGradient(g, field, r.data(), ws, v, grad));
            EXPECT_NEAR(v, expect, 1e-12 * 40) << Name(k);
            EXPECT_NEAR(FieldValue(g, field, r.data(), ws), v, 1e-14 * 40);
            for (int d = 0; d < 3; ++d) EXPECT_NEAR(grad[d], cg[d], 1e-10) << Name(k);
            const FieldSample s = SampleFieldAtWorld(g, field, x, ws);
            ASSERT_TRUE(s.inversion.inside) << Name(k);
            EXPECT_NEAR(s.value, expect, 1e-12 * 40) << Name(k);
            for (int d = 0; d < 3; ++d) EXPECT_NEAR(s.gradient[d], cg[d], 1e-10) << Name(k);
        }
        CellScalar constant{nullptr, 2.5};
        double v, grad[3];
        const double r0[3] = {0.1, 0.1, 0.1};
        ASSERT_TRUE(FieldValueGradient(g, constant, r0, ws, v, grad));
        EXPECT_EQ(v, 2.5);
        EXPECT_EQ(grad[0], 0.0);
    }
}

// A quadratic world function on an affine cell is in every space of order >= 2 (and
// serendipity): exact world gradient 2 A x + c.
TEST(Fields, QuadraticFieldGradientOnAffineCells) {
    EvalWorkspace ws;
    for (const CellKind& k : AllCellKinds()) {
        if (k.order < 2) continue;
        const BasisTable& basis = GetBasis(k.shape, k.order, k.family);
        std::mt19937_64 rng(600 + k.order);
        RandomCell c = MakeRandomCell(basis, rng, 0.0);
        CellGeometry g = MakeCellGeometry(basis, c.nodes.data());
        ASSERT_TRUE(g.affine);
        auto f = [](const double* x) { return x[0] * x[0] - 0.5 * x[1] * x[2] + x[2]; };
        std::vector<double> nodal(basis.nodeCount);
        for (int m = 0; m < basis.nodeCount; ++m) nodal[m] = f(&c.nodes[3 * m]);
        CellScalar field{nodal.data(), 0.0};
        for (int q = 0; q < 10; ++q) {
            const auto r = RandomRefPoint(k.shape, rng);
            double x[3], v, grad[3];
            WorldFromRef(g, r.data(), ws, x, nullptr);
            ASSERT_TRUE(FieldValueGradient(g, field, r.data(), ws, v, grad));
            const double scale = 1.0 + x[0] * x[0] + std::abs(x[1] * x[2]);
            EXPECT_NEAR(v, f(x), 1e-13 * scale) << Name(k);
            EXPECT_NEAR(grad[0], 2 * x[0], 1e-11 * scale) << Name(k);
            EXPECT_NEAR(grad[1], -0.5 * x[2], 1e-11 * scale) << Name(k);
            EXPECT_NEAR(grad[2], -0.5 * x[1] + 1.0, 1e-11 * scale) << Name(k);
        }
    }
}

// Along a straight line through an affine cell, a generic field is a polynomial of
// exactly lineDegree (polynomial spaces): difference of order degree + 1 vanishes, of
// order degree does not.
TEST(Fields, LineDegreeOfAffineCells) {
    for (const CellKind& k : AllCellKinds()) {
        const BasisTable& basis = GetBasis(k.shape, k.order, k.family);
        if (!basis.polynomial || basis.lineDegree > 9) continue;
        std::mt19937_64 rng(700 + k.order);
        std::uniform_real_distribution<double> u(-1.0, 1.0);
        std::vector<double> nodal(basis.nodeCount), v(basis.nodeCount);
        for (double& x : nodal) x = u(rng);
        // The line through two vertices-ish interior points in general position.
        const auto a = RandomRefPoint(k.shape, rng), b = RandomRefPoint(k.shape, rng);
        const int deg = basis.lineDegree;
        std::vector<double> s;
        for (int i = 0; i <= deg + 1; ++i) {
            const double l = static_cast<double>(i) / (deg + 1);
            double x[3];
            for (int d = 0; d < 3; ++d) x[d] = a[d] + l * (b[d] - a[d]);
            EvalBasis(basis, x, v.data(), nullptr);
            double f = 0.0;
            for (int m = 0; m < basis.nodeCount; ++m) f += nodal[m] * v[m];
            s.push_back(f);
        }
        for (int o = 0; o < deg; ++o)
            for (std::size_t i = 0; i + 1 < s.size() - o; ++i) s[i] = s[i + 1] - s[i];
        // s[0], s[1]: differences of order deg (constant), s[0] of order deg + 1 next.
        EXPECT_GT(std::abs(s[0]), 1e-6) << Name(k);
        EXPECT_NEAR(s[1] - s[0], 0.0, 1e-9) << Name(k);
    }
}

// Guaranteed bounds: 1e5 samples per (shape, order, family) over random curved cells
// with a smooth and a rough (random nodal values) field all lie inside the field range
// and the geometry box. Records the tightness (bound width / sampled range).
TEST(Bounds, ContainEverySampleOfCurvedCells) {
    EvalWorkspace ws;
    std::printf("%-26s %12s %12s %12s\n", "cell", "smooth", "rough", "box");
    for (const CellKind& k : AllCellKinds()) {
        const BasisTable& basis = GetBasis(k.shape, k.order, k.family);
        const int n = basis.nodeCount;
        std::mt19937_64 rng(900 + 7 * k.order + static_cast<int>(k.shape));
        std::uniform_real_distribution<double> u(-1.0, 1.0);
        const int cells = 2;
        const int samples = (n > 300 ? 20000 : 100000) / cells;
        double ratio[3] = {0, 0, 0};
        for (int cell = 0; cell < cells; ++cell) {
            RandomCell c = CurvedCell(basis, rng, ws);
            std::vector<double> smooth(n), rough(n);
            for (int m = 0; m < n; ++m) {
                const double* x = &c.nodes[3 * m];
                smooth[m] = std::sin(0.7 * x[0]) * std::cos(0.5 * x[1]) + 0.2 * x[2];
                rough[m] = u(rng);
            }
            const Interval bs = FieldBounds(basis, smooth.data());
            const Interval br = FieldBounds(basis, rough.data());
            const Box box = GeometryBox(basis, c.nodes.data());
            double lo[5], hi[5];
            for (int i = 0; i < 5; ++i) {
                lo[i] = 1e300;
                hi[i] = -1e300;
            }
            std::vector<double>& v = ws.values;
            std::vector<std::array<double, 3>> boundary;
            for (int i = 0; i < 100; ++i)
                for (const auto& bp : BoundaryPoints(k.shape, rng)) boundary.push_back(bp);
            for (int q = 0; q < samples + n; ++q) {
                std::array<double, 3> r = q < n ? basis.refNodes[q] : RandomRefPoint(k.shape, rng);
                if (q >= n && q % 4 == 0)  // a share on the boundary, where extremes sit
                    r = boundary[(q / 4) % boundary.size()];
                EvalBasis(basis, r.data(), v.data(), nullptr);
                double vals[5] = {0, 0, 0, 0, 0};
                for (int m = 0; m < n; ++m) {
                    vals[0] += v[m] * smooth[m];
                    vals[1] += v[m] * rough[m];
                    for (int d = 0; d < 3; ++d) vals[2 + d] += v[m] * c.nodes[3 * m + d];
                }
                for (int i = 0; i < 5; ++i) {
                    lo[i] = std::min(lo[i], vals[i]);
                    hi[i] = std::max(hi[i], vals[i]);
                }
            }
            // The sampled values carry their own rounding (~1e-15 relative).
            const double tol = 1e-13;
            EXPECT_LE(bs.lo, lo[0] + tol) << Name(k);
            EXPECT_GE(bs.hi, hi[0] - tol) << Name(k);
            EXPECT_LE(br.lo, lo[1] + tol) << Name(k);
            EXPECT_GE(br.hi, hi[1] - tol) << Name(k);
            double boxRatio = 0.0;
            for (int d = 0; d < 3; ++d) {
                EXPECT_LE(box.lo[d], lo[2 + d] + tol * 20) << Name(k);
                EXPECT_GE(box.hi[d], hi[2 + d] - tol * 20) << Name(k);
                boxRatio = std::max(boxRatio, (box.hi[d] - box.lo[d]) / (hi[2 + d] - lo[2 + d]));
            }
            ratio[0] = std::max(ratio[0], (bs.hi - bs.lo) / (hi[0] - lo[0]));
            ratio[1] = std::max(ratio[1], (br.hi - br.lo) / (hi[1] - lo[1]));
            ratio[2] = std::max(ratio[2], boxRatio);
        }
        std::printf("%-26s %12.4f %12.4f %12.4f\n", Name(k).c_str(), ratio[0], ratio[1],
                    ratio[2]);
        // Convex-hull bounds of smooth data are close to the true range.
        EXPECT_LT(ratio[0], 2.0) << Name(k);
        EXPECT_LT(ratio[2], 1.5) << Name(k);
    }
}

// Bounds are exact for data whose extremes are Bernstein coefficients: a constant and a
// field linear in the reference coordinates (extremes at vertices).
TEST(Bounds, ExactForConstantAndLinearData) {
    for (const CellKind& k : AllCellKinds()) {
        const BasisTable& basis = GetBasis(k.shape, k.order, k.family);
        std::vector<double> c(basis.nodeCount, 3.25), lin(basis.nodeCount);
        for (int m = 0; m < basis.nodeCount; ++m)
            lin[m] = basis.refNodes[m][0] + 2 * basis.refNodes[m][1] - basis.refNodes[m][2];
        const Interval ic = FieldBounds(basis, c.data());
        EXPECT_NEAR(ic.lo, 3.25, 1e-13) << Name(k);
        EXPECT_NEAR(ic.hi, 3.25, 1e-13) << Name(k);
        EXPECT_LE(ic.lo, 3.25);
        EXPECT_GE(ic.hi, 3.25);
        double lo = 1e300, hi = -1e300;
        for (const auto& v : VertexLattice(k.shape, 1)) {
            const auto x = LatticeRefCoords(k.shape, 1, v);
            const double f = x[0] + 2 * x[1] - x[2];
            lo = std::min(lo, f);
            hi = std::max(hi, f);
        }
        const Interval il = FieldBounds(basis, lin.data());
        EXPECT_NEAR(il.lo, lo, 1e-12) << Name(k);
        EXPECT_NEAR(il.hi, hi, 1e-12) << Name(k);
        // A large offset costs no accuracy beyond the offset's own ulp.
        for (double& v : lin) v += 1e6;
        const Interval io = FieldBounds(basis, lin.data());
        EXPECT_LE(io.lo, 1e6 + lo) << Name(k);
        EXPECT_GE(io.hi, 1e6 + hi) << Name(k);
        EXPECT_NEAR(io.lo, 1e6 + lo, 1e-9) << Name(k);
        EXPECT_NEAR(io.hi, 1e6 + hi, 1e-9) << Name(k);
    }
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// Linear tetrahedra keep no per-cell geometry: what MeshGeometry derives on request is
// bitwise what MakeCellGeometry and GeometryBox give for the gathered corners, and every
// other cell (hexes, wedges, pyramids of MFEM's mixed Fichera mesh) is stored as before.
TEST(Geometry, DerivedLinearTetsEqualStoredGeometry) {
    const std::string path =
        std::string(HPRAY_SHARED_DATA) + "/mfem_fichera_mixed16_linear.vtu";
    if (!std::filesystem::exists(path)) GTEST_SKIP() << "no shared data";
    const Mesh mesh = ReadMesh(path);
    const MeshGeometry geometry = MeshGeometry::Build(mesh);
    std::int64_t tets = 0, affine = 0;
    CellScratch scratch;
    Box bounds{{INFINITY, INFINITY, INFINITY}, {-INFINITY, -INFINITY, -INFINITY}};
    for (std::int64_t c = 0; c < mesh.CellCount(); ++c) {
        tets += mesh.cellShape[c] == CellShape::Tet && mesh.cellOrder[c] == 1;
        const BasisTable& basis = GetBasis(mesh.cellShape[c], mesh.cellOrder[c],
                                           mesh.cellFamily[c]);
        ASSERT_EQ(&geometry.Basis(c), &basis);
        std::vector<double> xyz(3 * basis.nodeCount);
        for (int m = 0; m < basis.nodeCount; ++m)
            for (int d = 0; d < 3; ++d)
                xyz[3 * m + d] = mesh.points[3 * mesh.CellNodes(c)[m] + d];
        const CellGeometry expected = MakeCellGeometry(basis, xyz.data());
        const CellGeometry& got = geometry.Cell(c, scratch);
        EXPECT_EQ(got.basis, expected.basis);
        EXPECT_EQ(got.affine, expected.affine);
        EXPECT_EQ(got.linear, expected.linear) << c;
        EXPECT_EQ(got.origin, expected.origin) << c;
        EXPECT_EQ(got.inverseLinear, expected.inverseLinear) << c;
        EXPECT_EQ(got.size, expected.size);
        for (int k = 0; k < 3 * basis.nodeCount; ++k) ASSERT_EQ(got.nodes[k], xyz[k]);
        const Box box = geometry.CellBox(c), want = GeometryBox(basis, xyz.data());
        EXPECT_EQ(box.lo, want.lo);
        EXPECT_EQ(box.hi, want.hi);
        affine += got.affine;
        // The map sends each reference node to its node (to rounding).
        EvalWorkspace ws;
        for (int m = 0; m < basis.nodeCount; ++m) {
            double x[3];
            WorldFromRef(got, basis.refNodes[m].data(), ws, x, nullptr);
            for (int d = 0; d < 3; ++d)
                EXPECT_NEAR(x[d], xyz[3 * m + d], 1e-14 * (1 + got.size)) << c << " " << m;
        }
        for (int d = 0; d < 3; ++d) {
            bounds.lo[d] = std::min(bounds.lo[d], box.lo[d]);
            bounds.hi[d] = std::max(bounds.hi[d], box.hi[d]);
        }
    }
    EXPECT_GT(tets, 0);
    EXPECT_LT(tets, mesh.CellCount());  // a mixed mesh
    EXPECT_EQ(geometry.derivedCells, tets);
    EXPECT_EQ(geometry.AffineCells(), affine);
    EXPECT_EQ(geometry.bounds.lo, bounds.lo);
    EXPECT_EQ(geometry.bounds.hi, bounds.hi);
    // Only the other cells take memory.
    const Mesh cube = ReadMesh("builtin:cube-tets-4");
    const MeshGeometry allTets = MeshGeometry::Build(cube);
    EXPECT_EQ(allTets.Bytes(), 0u);
    EXPECT_EQ(allTets.derivedCells, cube.CellCount());
    EXPECT_EQ(allTets.AffineCells(), cube.CellCount());
}

// GeometryBoxEnclosure holds the exact box of Lagrange tetrahedra of every order it
// covers (perturbed lattices, far from the origin and near it, flat ones), and is
// infinite for other bases; MeshGeometry's bounds of a mesh of linear tetrahedra (which
// skip the exact box of cells whose enclosure is inside the bounds so far) are the union
// of every cell's exact box.
TEST(Geometry, BoxEnclosureHoldsTheGeometryBox) {
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> uni(-1, 1);
    for (int p = 1; p <= 4; ++p) {
        const BasisTable& basis = GetBasis(CellShape::Tet, p, CellFamily::Lagrange);
        for (int trial = 0; trial < 400; ++trial) {
            const double offset = trial % 4 == 0 ? 0 : (trial % 4 == 1 ? 1e6 : -3.5);
            const double scale = trial % 3 == 0 ? 1e-9 : 1;
            const double noise = trial % 5 == 0 ? 0 : 0.2 / p;
            std::vector<double> xyz(3 * basis.nodeCount);
            for (int m = 0; m < basis.nodeCount; ++m)
                for (int d = 0; d < 3; ++d) {
                    const double flat = trial % 7 == 0 && d == 2 ? 0 : 1;
                    xyz[3 * m + d] =
                        offset + scale * flat * (basis.refNodes[m][d] + noise * uni(rng));
                }
            const Box exact = GeometryBox(basis, xyz.data());
            const Box outer = GeometryBoxEnclosure(basis, xyz.data());
            for (int d = 0; d < 3; ++d) {
                EXPECT_LE(outer.lo[d], exact.lo[d]) << p << " " << trial;
                EXPECT_GE(outer.hi[d], exact.hi[d]) << p << " " << trial;
            }
        }
    }
    const BasisTable& hex = GetBasis(CellShape::Hex, 1, CellFamily::Lagrange);
    std::vector<double> xyz(3 * hex.nodeCount, 0.5);
    EXPECT_EQ(GeometryBoxEnclosure(hex, xyz.data()).lo[0], -INFINITY);
    EXPECT_EQ(GeometryBoxEnclosure(hex, xyz.data()).hi[2], INFINITY);

    const Mesh cube = ReadMesh("builtin:cube-tets-12");
    const MeshGeometry geometry = MeshGeometry::Build(cube);
    Box bounds{{INFINITY, INFINITY, INFINITY}, {-INFINITY, -INFINITY, -INFINITY}};
    for (std::int64_t c = 0; c < cube.CellCount(); ++c) {
        double corners[12];
        for (int m = 0; m < 4; ++m)
            for (int d = 0; d < 3; ++d)
                corners[3 * m + d] = cube.points[3 * cube.CellNodes(c)[m] + d];
        const Box box = GeometryBox(geometry.Basis(c), corners);
        for (int d = 0; d < 3; ++d) {
            bounds.lo[d] = std::min(bounds.lo[d], box.lo[d]);
            bounds.hi[d] = std::max(bounds.hi[d], box.hi[d]);
        }
    }
    EXPECT_EQ(geometry.bounds.lo, bounds.lo);
    EXPECT_EQ(geometry.bounds.hi, bounds.hi);
}

}  // namespace
}  // namespace hpray

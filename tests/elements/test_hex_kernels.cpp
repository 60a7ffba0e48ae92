// The kernel table of Lagrange hexahedra (elements/hex_kernels.h) against the generic
// sum-factorised code, and the reduced-order map of curved hexahedra against the full one.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>
#include <vector>

#include "elements/basis.h"
#include "elements/field.h"
#include "elements/geometry.h"
#include "elements/hex_kernels.h"
#include "elements/mesh_geometry.h"
#include "elements/tensor_eval.h"
#include "elements/tet_kernels.h"
#include "mesh/cell.h"
#include "mesh/mesh.h"

namespace hpray {
namespace {

// Every specialised kernel performs the generic code's operations in the same order, so
// the results must be bitwise equal, at points inside and outside the reference cell.
TEST(HexKernels, EverySpecialisedKernelEqualsTheGenericPathBitwise) {
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> value(-2, 2), point(-0.3, 1.3);
    for (int p = 1; p <= kMaxOrder; ++p) {
        const HexKernels& k = HexKernelsFor(p);
        ASSERT_EQ(k.order, p);
        const int n = (p + 1) * (p + 1) * (p + 1);
        std::vector<double> u(n), xyz(3 * n);
        for (double& v : u) v = value(rng);
        for (double& v : xyz) v = value(rng);
        std::vector<double> refs;
        for (int s = 0; s < 13; ++s) {
            const double ref[3] = {point(rng), point(rng), point(rng)};
            refs.insert(refs.end(), ref, ref + 3);
            EXPECT_EQ(k.value(u.data(), ref), HexFieldValue(p, u.data(), ref)) << "p " << p;
            double g1[3], g2[3];
            EXPECT_EQ(k.valueGradient(u.data(), ref, g1),
                      HexFieldValueGradient(p, u.data(), ref, g2));
            for (int d = 0; d < 3; ++d) EXPECT_EQ(g1[d], g2[d]) << "p " << p << " d " << d;
            double w1[3], w2[3], j1[9], j2[9];
            k.map(xyz.data(), ref, w1, j1);
            HexMapValueJacobian(p, xyz.data(), ref, w2, j2);
            for (int d = 0; d < 3; ++d) EXPECT_EQ(w1[d], w2[d]);
            for (int d = 0; d < 9; ++d) EXPECT_EQ(j1[d], j2[d]);
            k.map(xyz.data(), ref, w1, nullptr);
            for (int d = 0; d < 3; ++d) EXPECT_EQ(w1[d], w2[d]);
        }
        // The batched evaluation at arbitrary points (every padded size and the kernels
        // chosen by count) against the single-point path.
        for (int count : {1, 3, 4, 5, 8, 9, 12, 13}) {
            std::vector<double> out(count), scratch(HexLineScratchSize(p, count));
            HexFieldValuesAt(p, u.data(), refs.data(), count, out.data(), scratch.data());
            for (int s = 0; s < count; ++s)
                EXPECT_EQ(out[s], HexFieldValue(p, u.data(), &refs[3 * s]))
                    << "p " << p << " count " << count << " sample " << s;
        }
    }
}

// The tetrahedron kernels fuse the basis with the node sums; they must give bitwise what
// the generic path gives: EvalBasis into arrays, then the sums over the nodes in order
// (for the order-3 map, in the order its kernel sums them: see TetMapBlocked3).
TEST(TetKernels, EverySpecialisedKernelEqualsTheGenericPathBitwise) {
    std::mt19937_64 rng(13);
    std::uniform_real_distribution<double> value(-2, 2), point(-0.2, 0.6);
    for (int p = 1; p <= kMaxOrder; ++p) {
        const TetKernels& k = TetKernelsFor(p);
        ASSERT_EQ(k.order, p);
        const BasisTable& basis = GetBasis(CellShape::Tet, p, CellFamily::Lagrange);
        const int n = basis.nodeCount;
        ASSERT_EQ(n, (p + 1) * (p + 2) * (p + 3) / 6);
        std::vector<double> u(n), xyz(3 * n), v(n), d(3 * n);
        for (double& x : u) x = value(rng);
        for (double& x : xyz) x = value(rng);
        for (int s = 0; s < 13; ++s) {
            const double ref[3] = {point(rng), point(rng), point(rng)};
            EvalBasis(basis, ref, v.data(), d.data());
            double f = 0, g[3] = {0, 0, 0}, w[3] = {0, 0, 0}, jac[9] = {};
            for (int m = 0; m < n; ++m) {
                f += u[m] * v[m];
                for (int c = 0; c < 3; ++c) g[c] += u[m] * d[3 * m + c];
                for (int c = 0; c < 3; ++c) w[c] += v[m] * xyz[3 * m + c];
            }
            for (int m = 0; m < n; ++m)
                for (int i = 0; i < 3; ++i)
                    for (int j = 0; j < 3; ++j)
                        jac[3 * i + j] += xyz[3 * m + i] * d[3 * m + j];
            if (p == 3) {
                // Order 3 sums the map's nodes in four interleaved partial sums (node m
                // in sum m mod 4, by fused multiply-adds, added as (s0 + s1) + (s2 +
                // s3)).
                double sw[4][3] = {}, sj[4][9] = {};
                for (int m = 0; m < n; ++m)
                    for (int i = 0; i < 3; ++i) {
                        sw[m % 4][i] = std::fma(v[m], xyz[3 * m + i], sw[m % 4][i]);
                        for (int j = 0; j < 3; ++j)
                            sj[m % 4][3 * i + j] = std::fma(d[3 * m + j], xyz[3 * m + i],
                                                            sj[m % 4][3 * i + j]);
                    }
                for (int i = 0; i < 3; ++i)
                    w[i] = (sw[0][i] + sw[1][i]) + (sw[2][i] + sw[3][i]);
                for (int i = 0; i < 9; ++i)
                    jac[i] = (sj[0][i] + sj[1][i]) + (sj[2][i] + sj[3][i]);
                double w3[3], j3[9];
                TetMapBlocked3(xyz.data(), ref, w3, j3);
                for (int c = 0; c < 3; ++c) EXPECT_EQ(w3[c], w[c]);
                for (int c = 0; c < 9; ++c) EXPECT_EQ(j3[c], jac[c]);
            }
            EXPECT_EQ(k.value(u.data(), ref), f) << "p " << p;
            double g1[3];
            EXPECT_EQ(k.valueGradient(u.data(), ref, g1), f) << "p " << p;
            for (int c = 0; c < 3; ++c) EXPECT_EQ(g1[c], g[c]) << "p " << p;
            double w1[3], j1[9];
            k.map(xyz.data(), ref, w1, j1);
            for (int c = 0; c < 3; ++c) EXPECT_EQ(w1[c], w[c]) << "p " << p;
            for (int c = 0; c < 9; ++c) EXPECT_EQ(j1[c], jac[c]) << "p " << p;
            k.map(xyz.data(), ref, w1, nullptr);
            for (int c = 0; c < 3; ++c) EXPECT_EQ(w1[c], w[c]) << "p " << p;
        }
    }
}

// The tetrahedron kernels' values at many points (four at a time in vector lanes where
// the build has them) are bitwise their values one by one, for every order and count.
TEST(TetKernels, ValuesAtManyPointsEqualTheValueAtEachBitwise) {
    std::mt19937_64 rng(31);
    std::uniform_real_distribution<double> value(-2, 2), point(-0.2, 0.6);
    for (int p = 1; p <= kMaxOrder; ++p) {
        const TetKernels& k = TetKernelsFor(p);
        const int n = (p + 1) * (p + 2) * (p + 3) / 6;
        std::vector<double> u(n);
        for (double& x : u) x = value(rng);
        for (int count = 0; count <= 13; ++count) {
            std::vector<double> refs(3 * count), out(count + 1, -7.0);
            for (double& x : refs) x = point(rng);
            k.values(u.data(), refs.data(), count, out.data());
            for (int s = 0; s < count; ++s)
                EXPECT_EQ(out[s], k.value(u.data(), &refs[3 * s]))
                    << "p " << p << " count " << count << " point " << s;
            EXPECT_EQ(out[count], -7.0);  // nothing written past the points
        }
    }
}

// The linear wedge and pyramid values of field.h fuse the basis with the node sum:
// bitwise what the generic path gives (EvalBasis into an array, then the sum over the
// nodes in order), inside the cell, outside it, and on the pyramid's apex plane.
TEST(LinearWedgePyramid, FusedValuesEqualTheGenericPathBitwise) {
    std::mt19937_64 rng(29);
    std::uniform_real_distribution<double> value(-2, 2), point(-0.3, 1.2);
    for (const CellShape shape : {CellShape::Wedge, CellShape::Pyramid}) {
        const BasisTable& basis = GetBasis(shape, 1, CellFamily::Lagrange);
        const int n = basis.nodeCount;
        ASSERT_EQ(n, shape == CellShape::Wedge ? 6 : 5);
        std::vector<double> u(n), v(n);
        int checked = 0;
        for (int s = 0; s < 2000; ++s) {
            for (double& x : u) x = value(rng);
            double ref[3] = {point(rng), point(rng), point(rng)};
            if (s % 100 == 0) ref[2] = 1.0;  // the pyramid's apex plane (a limit there)
            if (s % 100 == 1) ref[0] = ref[1] = ref[2] = 0.0;
            EvalBasis(basis, ref, v.data(), nullptr);
            double f = 0;
            for (int m = 0; m < n; ++m) f += u[m] * v[m];
            const double fused = shape == CellShape::Wedge
                                     ? LinearWedgeValue(u.data(), ref)
                                     : LinearPyramidValue(u.data(), ref);
            // Bitwise: also the sign of a zero.
            EXPECT_EQ(std::signbit(fused), std::signbit(f));
            EXPECT_EQ(fused, f)
                << int(shape) << " at " << ref[0] << " " << ref[1] << " " << ref[2];
            ++checked;
        }
        EXPECT_EQ(checked, 2000);
    }
}

// A hexahedron of order p whose nodes are the image of the lattice under `map`.
std::vector<double> HexNodes(int p, const std::function<void(const double*, double*)>& map) {
    const BasisTable& basis = GetBasis(CellShape::Hex, p, CellFamily::Lagrange);
    std::vector<double> xyz(3 * basis.nodeCount);
    for (int m = 0; m < basis.nodeCount; ++m) map(basis.refNodes[m].data(), &xyz[3 * m]);
    return xyz;
}

TEST(HexKernels, ReducedMapOrderIsFoundAndIsTheSameMap) {
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> jitter(-0.08, 0.08), point(0, 1);
    for (int q : {1, 2, 3}) {
        // A map of exact order q per direction: x = r + a * r^q (1 - s) ... plus a trilinear
        // distortion of the corners.
        double c[8][3];
        for (int v = 0; v < 8; ++v)
            for (int d = 0; d < 3; ++d) c[v][d] = ((v >> d) & 1) + jitter(rng);
        auto map = [&](const double* r, double* x) {
            for (int d = 0; d < 3; ++d) {
                x[d] = 0;
                for (int v = 0; v < 8; ++v) {
                    double w = 1;
                    for (int e = 0; e < 3; ++e) w *= ((v >> e) & 1) ? r[e] : 1 - r[e];
                    x[d] += w * c[v][d];
                }
            }
            if (q >= 2) x[0] += 0.05 * std::pow(r[1], q) * r[2];
            if (q >= 3) x[2] += 0.03 * std::pow(r[0], q - 1) * std::pow(r[1], q);
        };
        for (int p : {2 * q, 8, 10}) {
            if (p < 2 * q) continue;
            const BasisTable& basis = GetBasis(CellShape::Hex, p, CellFamily::Lagrange);
            const std::vector<double> xyz = HexNodes(p, map);
            std::vector<double> reduced;
            const CellGeometry full = MakeCellGeometry(basis, xyz.data());
            ASSERT_FALSE(full.affine);
            const int found = ReducedHexMapOrder(basis, xyz.data(), kAffineTolerance * full.size,
                                                 p / 2, reduced);
            ASSERT_EQ(found, q) << "p " << p;
            for (int s = 0; s < 50; ++s) {
                const double ref[3] = {point(rng), point(rng), point(rng)};
                double w1[3], w2[3], j1[9], j2[9], exact[3];
                HexMapValueJacobian(q, reduced.data(), ref, w1, j1);
                HexMapValueJacobian(p, xyz.data(), ref, w2, j2);
                map(ref, exact);
                for (int d = 0; d < 3; ++d) {
                    EXPECT_NEAR(w1[d], exact[d], 1e-14);
                    EXPECT_NEAR(w1[d], w2[d], 1e-12);
                }
                for (int d = 0; d < 9; ++d) EXPECT_NEAR(j1[d], j2[d], 1e-11);
            }
        }
    }
    // A map of full order (a small order-p bump) is not reduced.
    for (int p : {2, 4, 8}) {
        auto bumped = [p](const double* r, double* x) {
            for (int d = 0; d < 3; ++d) x[d] = r[d];
            x[1] += 1e-9 * std::pow(r[0] * (1 - r[0]), p / 2) * r[2];
        };
        const BasisTable& basis = GetBasis(CellShape::Hex, p, CellFamily::Lagrange);
        const std::vector<double> xyz = HexNodes(p, bumped);
        std::vector<double> reduced;
        EXPECT_EQ(ReducedHexMapOrder(basis, xyz.data(), 1e-13 * std::sqrt(3.0), p / 2, reduced),
                  0)
            << "p " << p;
    }
}

// MeshGeometry stores the reduced map, and inversion through it finds the same reference
// points as through the full map.
TEST(HexKernels, MeshGeometryInvertsThroughTheReducedMap) {
    const int p = 8;
    const BasisTable& basis = GetBasis(CellShape::Hex, p, CellFamily::Lagrange);
    auto map = [](const double* r, double* x) {
        x[0] = r[0] + 0.1 * r[1] * r[2];
        x[1] = r[1] - 0.07 * r[0] * r[2];
        x[2] = r[2] + 0.05 * r[0] * r[1];
    };
    std::vector<double> xyz = HexNodes(p, map);
    Mesh mesh;
    mesh.points = xyz;
    std::vector<std::int64_t> nodes(basis.nodeCount);
    for (int m = 0; m < basis.nodeCount; ++m) nodes[m] = m;
    mesh.AddCell(CellShape::Hex, p, CellFamily::Lagrange, nodes.data(), basis.nodeCount);
    const MeshGeometry g = MeshGeometry::Build(mesh);
    EXPECT_EQ(g.reducedMapCells, 1);
    CellScratch scratch;
    const CellGeometry& cell = g.Cell(0, scratch);
    EXPECT_EQ(cell.mapOrder, 1);
    const CellGeometry full = MakeCellGeometry(basis, xyz.data());
    EXPECT_EQ(full.mapOrder, p);
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> point(0, 1);
    EvalWorkspace ws;
    for (int s = 0; s < 100; ++s) {
        const double ref[3] = {point(rng), point(rng), point(rng)};
        double world[3];
        map(ref, world);
        const InversionResult a = RefFromWorld(cell, world, ws);
        const InversionResult b = RefFromWorld(full, world, ws);
        ASSERT_TRUE(a.converged && b.converged);
        for (int d = 0; d < 3; ++d) {
            EXPECT_NEAR(a.ref[d], ref[d], 1e-13);
            EXPECT_NEAR(a.ref[d], b.ref[d], 1e-13);
        }
    }
}

// NewtonFullSteps is RefFromWorld's common path without its set-up: wherever it
// returns true, its result must be bitwise RefFromWorld's from the same start, and it
// must return true on most inversions from good starts (what ray sampling gives it).
TEST(HexKernels, NewtonFullStepsEqualsRefFromWorldBitwise) {
    std::mt19937_64 rng(17);
    std::uniform_real_distribution<double> jitter(-0.06, 0.06), point(0.02, 0.98),
        nudge(-1e-3, 1e-3);
    for (CellShape shape : {CellShape::Hex, CellShape::Tet}) {
        int agreed = 0, tried = 0;
        for (int p : {1, 2, 3, 4}) {
            double c[8][3];
            for (int v = 0; v < 8; ++v)
                for (int d = 0; d < 3; ++d) c[v][d] = ((v >> d) & 1) + jitter(rng);
            const double bend = jitter(rng);
            // A trilinear map plus, from order 2, a quadratic bend (the tetrahedron lies
            // in the corner r + s + t <= 1 of the same map).
            auto map = [&](const double* r, double* x) {
                for (int d = 0; d < 3; ++d) {
                    double s = 0;
                    for (int v = 0; v < 8; ++v) {
                        double w = 1;
                        for (int e = 0; e < 3; ++e) w *= (v >> e) & 1 ? r[e] : 1 - r[e];
                        s += w * c[v][d];
                    }
                    x[d] = s + (p > 1 ? bend * r[(d + 1) % 3] * r[(d + 1) % 3] : 0.0);
                }
            };
            if (shape == CellShape::Tet && p == 1) continue;  // affine: no Newton
            const BasisTable& basis = GetBasis(shape, p, CellFamily::Lagrange);
            std::vector<double> xyz(3 * basis.nodeCount);
            for (int m = 0; m < basis.nodeCount; ++m)
                map(basis.refNodes[m].data(), &xyz[3 * m]);
            const CellGeometry cell = MakeCellGeometry(basis, xyz.data());
            ASSERT_FALSE(cell.affine);
            ASSERT_TRUE(shape == CellShape::Hex ? cell.hexMap != nullptr
                                                : cell.tetMap != nullptr);
            EvalWorkspace ws;
            for (int k = 0; k < 200; ++k) {
                double truth[3] = {point(rng), point(rng), point(rng)};
                if (shape == CellShape::Tet)
                    for (double& x : truth) x /= 3;  // inside the tetrahedron
                double world[3];
                map(truth, world);
                const double start[3] = {truth[0] + nudge(rng), truth[1] + nudge(rng),
                                         truth[2] + nudge(rng)};
                InversionOptions options;
                options.initialGuess = start;
                options.contraction = k % 2 ? 4.0 : 0.0;
                const InversionResult r = RefFromWorld(cell, world, ws, options);
                double ref[3], inverse[9], contraction;
                int iterations;
                ++tried;
                if (!NewtonFullSteps(cell, world, start, options, ref, iterations,
                                     contraction, inverse))
                    continue;
                ++agreed;
                ASSERT_TRUE(r.converged);
                for (int d = 0; d < 3; ++d) EXPECT_EQ(ref[d], r.ref[d]) << "p " << p;
                for (int d = 0; d < 9; ++d) EXPECT_EQ(inverse[d], r.inverseJacobian[d]);
                EXPECT_EQ(iterations, r.iterations);
                EXPECT_EQ(contraction, r.contraction);
            }
        }
        EXPECT_GT(agreed, tried * 9 / 10) << int(shape);
    }
}

}  // namespace
}  // namespace hpray

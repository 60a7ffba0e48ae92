// Built-in data sets: counts, exact geometry and the analytic fields they promise.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>

#include "mesh/builtin.h"
#include "util/error.h"

namespace hpray {
namespace {

double TetVolume(const Mesh& m, std::int64_t c) {
    const std::int64_t* n = m.CellNodes(c);
    // Vertices of an order-p tet: lattice (0,0,0), (p,0,0), (0,p,0), (0,0,p).
    const int p = m.cellOrder[c];
    const int idx[4] = {InternalNodeIndex(CellShape::Tet, p, CellFamily::Lagrange, {0, 0, 0}),
                        InternalNodeIndex(CellShape::Tet, p, CellFamily::Lagrange, {p, 0, 0}),
                        InternalNodeIndex(CellShape::Tet, p, CellFamily::Lagrange, {0, p, 0}),
                        InternalNodeIndex(CellShape::Tet, p, CellFamily::Lagrange, {0, 0, p})};
    double e[3][3];
    for (int q = 0; q < 3; ++q)
        for (int d = 0; d < 3; ++d)
            e[q][d] = m.points[3 * n[idx[q + 1]] + d] - m.points[3 * n[idx[0]] + d];
    return (e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) -
            e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
            e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0])) / 6.0;
}

TEST(Builtin, CubeTetsCountsVolumeAndField) {
    for (int N : {1, 2, 5}) {
        Mesh m = MakeBuiltin("builtin:cube-tets-" + std::to_string(N));
        EXPECT_EQ(m.CellCount(), 5 * N * N * N);
        EXPECT_EQ(m.PointCount(), (N + 1) * (N + 1) * (N + 1));
        double volume = 0;
        for (std::int64_t c = 0; c < m.CellCount(); ++c) {
            const double v = TetVolume(m, c);
            EXPECT_GT(v, 0) << c;
            volume += v;
        }
        EXPECT_NEAR(volume, 1.0, 1e-14);
        const Field* u = m.FindPointField("u");
        ASSERT_NE(u, nullptr);
        for (std::int64_t i = 0; i < m.PointCount(); ++i)
            EXPECT_DOUBLE_EQ(u->values[i], m.points[3 * i] + 2 * m.points[3 * i + 1] +
                                               3 * m.points[3 * i + 2]);
    }
}

// Conformity: every triangular face is shared by exactly two tets or lies on the boundary.
TEST(Builtin, CubeTetsIsConforming) {
    Mesh m = MakeBuiltin("builtin:cube-tets-3");
    std::map<std::array<std::int64_t, 3>, int> faces;
    for (std::int64_t c = 0; c < m.CellCount(); ++c) {
        const std::int64_t* n = m.CellNodes(c);
        const std::int64_t v[4] = {n[0], n[1], n[2], n[3]};  // order 1: nodes = vertices
        for (int skip = 0; skip < 4; ++skip) {
            std::array<std::int64_t, 3> f;
            int k = 0;
            for (int q = 0; q < 4; ++q)
                if (q != skip) f[k++] = v[q];
            std::sort(f.begin(), f.end());
            faces[f]++;
        }
    }
    int boundary = 0;
    for (const auto& [f, count] : faces) {
        EXPECT_LE(count, 2);
        if (count == 1) {
            ++boundary;
            // A boundary face lies in one cube face plane.
            bool onPlane = false;
            for (int d = 0; d < 3; ++d)
                for (double plane : {0.0, 1.0})
                    onPlane |= m.points[3 * f[0] + d] == plane &&
                               m.points[3 * f[1] + d] == plane && m.points[3 * f[2] + d] == plane;
            EXPECT_TRUE(onPlane);
        }
    }
    EXPECT_EQ(boundary, 6 * 2 * 3 * 3);
}

TEST(Builtin, BallP2IsQuadraticTetsWithExactSquareField) {
    Mesh m = MakeBuiltin("builtin:ball-p2");
    EXPECT_EQ(m.CellCount(), 5 * 4 * 4 * 4);
    // Vertices of the 4^3 cube grid, midpoints of its 300 edges and of the 240 face
    // diagonals (the 5-tet split has no edge inside a cube).
    EXPECT_EQ(m.PointCount(), 125 + 300 + 240);
    double volume = 0;
    for (std::int64_t c = 0; c < m.CellCount(); ++c) {
        EXPECT_EQ(m.cellOrder[c], 2);
        EXPECT_EQ(m.CellNodeCount(c), 10);
        volume += TetVolume(m, c);
    }
    EXPECT_NEAR(volume, 8.0, 1e-13);
    const Field* u = m.FindPointField("u");
    for (std::int64_t i = 0; i < m.PointCount(); ++i) {
        const double x = m.points[3 * i], y = m.points[3 * i + 1], z = m.points[3 * i + 2];
        EXPECT_DOUBLE_EQ(u->values[i], x * x + y * y + z * z);
    }
    auto b = m.Bounds();
    EXPECT_EQ(b.lo, (std::array<double, 3>{-1, -1, -1}));
    EXPECT_EQ(b.hi, (std::array<double, 3>{1, 1, 1}));
}

TEST(Builtin, NkSincIsFiveCubedOrderEightHexes) {
    Mesh m = MakeBuiltin("builtin:nk-sinc");
    EXPECT_EQ(m.CellCount(), 125);
    EXPECT_EQ(m.PointCount(), 41 * 41 * 41);
    for (std::int64_t c = 0; c < m.CellCount(); ++c) {
        EXPECT_EQ(m.cellShape[c], CellShape::Hex);
        EXPECT_EQ(m.cellOrder[c], 8);
    }
    const Field* u = m.FindPointField("u");
    const double pi = std::acos(-1.0);
    for (std::int64_t i = 0; i < m.PointCount(); i += 97) {
        const double x = m.points[3 * i], y = m.points[3 * i + 1], z = m.points[3 * i + 2];
        const double r = std::hypot(x - 0.5, z - 0.5);
        const double sinc = r == 0 ? 1 : std::sin(pi * r) / (pi * r);
        EXPECT_NEAR(u->values[i], 2 * (y - 0.3) - sinc, 1e-15);
    }
    // Axis-aligned cells: node (i,j,k) of an order-p cell sits on the tensor grid of its
    // vertices (an independent check of the lattice ordering of the generator).
    for (std::int64_t c = 0; c < m.CellCount(); c += 7) {
        const std::int64_t* n = m.CellNodes(c);
        const auto& lat = LatticeNodes(CellShape::Hex, 8);
        const double* x0 = &m.points[3 * n[0]];
        const double* x1 = &m.points[3 * n[lat.size() - 1]];
        for (std::size_t k = 0; k < lat.size(); ++k)
            for (int d = 0; d < 3; ++d)
                EXPECT_NEAR(m.points[3 * n[k] + d], x0[d] + (x1[d] - x0[d]) * lat[k][d] / 8.0,
                            1e-15);
    }
    EXPECT_EQ(MakeBuiltin("builtin:nk-sinc?order=3").cellOrder[0], 3);
}

TEST(Builtin, NkQuarticFillsTheUnitCubeWithDisplacedInteriorVertices) {
    Mesh m = MakeBuiltin("builtin:nk-quartic?order=4");
    EXPECT_EQ(m.CellCount(), 8);
    auto b = m.Bounds();
    EXPECT_EQ(b.lo, (std::array<double, 3>{0, 0, 0}));
    EXPECT_EQ(b.hi, (std::array<double, 3>{1, 1, 1}));
    // The centre vertex (global lattice index (p, p, p)) is displaced off (0.5, 0.5, 0.5).
    const std::int64_t centre = 4 + 9 * (4 + 9 * 4);
    double off = 0;
    for (int d = 0; d < 3; ++d) off += std::abs(m.points[3 * centre + d] - 0.5);
    EXPECT_GT(off, 0.05);
    const Field* u = m.FindPointField("u");
    for (std::int64_t i = 0; i < m.PointCount(); ++i) {
        double expect = 0;
        for (int d = 0; d < 3; ++d) {
            const double q = (0.5 - m.points[3 * i + d]) * (0.5 - m.points[3 * i + d]);
            expect += q * (q - 0.169);
        }
        EXPECT_NEAR(u->values[i], expect, 1e-16);
    }
}

TEST(Builtin, BadSpecsAreInputErrors) {
    for (const char* spec : {"builtin:nope", "builtin:cube-tets-", "builtin:cube-tets-x",
                             "builtin:cube-tets-0", "builtin:nk-sinc?order=11",
                             "builtin:nk-sinc?order=abc", "builtin:nk-sinc?colour=3",
                             "builtin:ball-p2?n"}) {
        try {
            MakeBuiltin(spec);
            ADD_FAILURE() << spec;
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find("builtin:"), std::string::npos) << e.what();
        }
    }
}

}  // namespace
}  // namespace hpray

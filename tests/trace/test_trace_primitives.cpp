// Tests of the traversal primitives: exact edge signs, the watertight triangle test, the
// ray-bilinear patch closed form and the face bases.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "trace/bilinear_patch.h"
#include "trace/face_map.h"
#include "trace/ray_frame.h"

namespace hpray::trace {
namespace {

TEST(RayFrame, EdgeSignIsExactAndAntisymmetric) {
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> uni(-1, 1);
    for (int i = 0; i < 20000; ++i) {
        ShearedPoint p{uni(rng), uni(rng), 0}, q{uni(rng), uni(rng), 0};
        if (i % 3 == 0) q = {p.x * 3, p.y * 3, 0};       // collinear with the origin
        if (i % 5 == 0) q = {p.x, uni(rng), 0};          // vertical edge
        if (i % 7 == 0) p = {0, 0, 0};                   // through the origin
        const int s = EdgeSign(p, q);
        EXPECT_EQ(EdgeSign(q, p), -s) << i;
        const bool same = p.x == q.x && p.y == q.y;
        EXPECT_EQ(s == 0, same) << i;
    }
    // (1 + 2^-30)(1 - 2^-30) - 1 = -2^-60: the rounded product difference is 0.
    const double a = 1.0 + std::ldexp(1.0, -30), b = 1.0 - std::ldexp(1.0, -30);
    ASSERT_EQ(a * b - 1.0, 0.0);
    EXPECT_EQ(ExactCrossSign(a, 1.0, 1.0, b), -1);
    EXPECT_EQ(ExactCrossSign(1.0, b, a, 1.0), 1);
    EXPECT_EQ(ExactCrossSign(a, b, a, b), 0);
}

TEST(RayFrame, TriangleSideFollowsNormalAndTIsExactForPlanes) {
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> uni(-1, 1);
    int hits = 0;
    for (int i = 0; i < 5000; ++i) {
        double A[3], B[3], C[3];
        for (int d = 0; d < 3; ++d) {
            A[d] = uni(rng);
            B[d] = uni(rng);
            C[d] = uni(rng);
        }
        // Ray through a point of the triangle with barycentrics (w0, w1, w2).
        double w1 = 0.5 * (1 + uni(rng)), w2 = 0.5 * (1 + uni(rng));
        if (w1 + w2 > 1) {
            w1 = 1 - w1;
            w2 = 1 - w2;
        }
        double X[3], dir[3];
        for (int d = 0; d < 3; ++d) X[d] = A[d] + w1 * (B[d] - A[d]) + w2 * (C[d] - A[d]);
        double len = 0;
        for (int d = 0; d < 3; ++d) {
            dir[d] = uni(rng);
            len += dir[d] * dir[d];
        }
        len = std::sqrt(len);
        Ray ray;
        for (int d = 0; d < 3; ++d) {
            ray.dir[d] = dir[d] / len;
            ray.origin[d] = X[d] - 2.0 * ray.dir[d];
        }
        const RayFrame frame(ray);
        TriangleCrossing x;
        if (!CrossTriangle(frame.Transform(A), frame.Transform(B), frame.Transform(C), x))
            continue;  // only possible within rounding of an edge
        ++hits;
        double n[3] = {(B[1] - A[1]) * (C[2] - A[2]) - (B[2] - A[2]) * (C[1] - A[1]),
                       (B[2] - A[2]) * (C[0] - A[0]) - (B[0] - A[0]) * (C[2] - A[2]),
                       (B[0] - A[0]) * (C[1] - A[1]) - (B[1] - A[1]) * (C[0] - A[0])};
        const double dn = n[0] * ray.dir[0] + n[1] * ray.dir[1] + n[2] * ray.dir[2];
        EXPECT_EQ(x.side, dn > 0 ? 1 : -1) << i;
        // t: the crossing of the plane, independent formula, well-conditioned cases.
        const double nlen = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (std::fabs(dn) > 0.2 * nlen) {
            EXPECT_NEAR(x.t, 2.0, 1e-13) << i;
        }
        // The opposite winding gives the opposite side and the same t.
        TriangleCrossing y;
        ASSERT_TRUE(CrossTriangle(frame.Transform(A), frame.Transform(C), frame.Transform(B), y));
        EXPECT_EQ(y.side, -x.side);
    }
    EXPECT_GT(hits, 4900);
}

TEST(RayFrame, FanAroundAVertexIsHitExactlyOnce) {
    // A closed fan of triangles around a vertex the ray passes through exactly: the
    // perturbed ray must cross exactly one of them (no leak, no double count).
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> uni(-1, 1);
    for (int i = 0; i < 2000; ++i) {
        const double V[3] = {uni(rng), uni(rng), uni(rng)};
        const int m = 4 + i % 7;  // angular gaps stay below pi: V projects inside
        std::vector<std::array<double, 3>> ring(m);
        for (int k = 0; k < m; ++k) {
            const double ang = 2 * M_PI * (k + 0.3 * uni(rng)) / m;
            ring[k] = {V[0] + std::cos(ang), V[1] + std::sin(ang), V[2] + 0.3 * uni(rng)};
        }
        Ray ray;
        double len = 0, dir[3] = {0.3 * uni(rng), 0.3 * uni(rng), 1};
        for (double d : dir) len += d * d;
        for (int d = 0; d < 3; ++d) {
            ray.dir[d] = dir[d] / std::sqrt(len);
            ray.origin[d] = V[d] - 5 * ray.dir[d];
        }
        const RayFrame frame(ray);
        int count = 0;
        TriangleCrossing x;
        for (int k = 0; k < m; ++k)
            count += CrossTriangle(frame.Transform(V), frame.Transform(ring[k].data()),
                                   frame.Transform(ring[(k + 1) % m].data()), x);
        EXPECT_EQ(count, 1) << i;
    }
}

TEST(BilinearPatch, RootsLieOnPatchAndRay) {
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> uni(-1, 1);
    int found = 0;
    for (int i = 0; i < 5000; ++i) {
        double q[4][3];
        for (int k = 0; k < 4; ++k)
            for (int d = 0; d < 3; ++d) q[k][d] = (k == 1 || k == 2 ? 1 : 0) * (d == 0) +
                                                  (k >= 2 ? 1 : 0) * (d == 1) + 0.4 * uni(rng);
        // Ray through P(u0, v0).
        const double u0 = 0.5 * (1 + uni(rng)), v0 = 0.5 * (1 + uni(rng));
        double X[3], dir[3], len = 0;
        for (int d = 0; d < 3; ++d) {
            X[d] = (1 - u0) * (1 - v0) * q[0][d] + u0 * (1 - v0) * q[1][d] + u0 * v0 * q[2][d] +
                   (1 - u0) * v0 * q[3][d];
            dir[d] = uni(rng) + (d == 2 ? 2 : 0);
            len += dir[d] * dir[d];
        }
        double o[3];
        for (int d = 0; d < 3; ++d) {
            dir[d] /= std::sqrt(len);
            o[d] = X[d] - 1.5 * dir[d];
        }
        PatchRoot roots[2];
        const int n = IntersectBilinearPatch(o, dir, q[0], q[1], q[3 - 1], q[3], roots);
        bool matched = false;
        for (int r = 0; r < n; ++r) {
            double P[3];
            const double u = roots[r].u, v = roots[r].v;
            for (int d = 0; d < 3; ++d)
                P[d] = (1 - u) * (1 - v) * q[0][d] + u * (1 - v) * q[1][d] + u * v * q[2][d] +
                       (1 - u) * v * q[3][d];
            double err = 0;
            for (int d = 0; d < 3; ++d) err = std::max(err, std::fabs(P[d] - (o[d] + roots[r].t * dir[d])));
            if (std::fabs(u) < 10 && std::fabs(v) < 10) {
                EXPECT_LT(err, 1e-12) << i;
            }
            if (std::fabs(u - u0) < 1e-9 && std::fabs(v - v0) < 1e-9) {
                matched = true;
                EXPECT_NEAR(roots[r].t, 1.5, 1e-12) << i;
            }
        }
        found += matched;
    }
    EXPECT_EQ(found, 5000);
}

TEST(FaceBasis, KroneckerPartitionOfUnityAndDerivatives) {
    for (FaceBasis basis : {FaceBasis::Triangle, FaceBasis::Quad, FaceBasis::QuadSerendipity}) {
        for (int p = 1; p <= 10; ++p) {
            if (basis == FaceBasis::QuadSerendipity && p != 2) continue;
            const int n = FaceNodeCount(basis, p);
            std::vector<double> N(n), Nu(n), Nv(n), Np(n), Nm(n);
            for (int m = 0; m < n; ++m) {
                const auto ij = FaceNodeLattice(basis, p, m);
                EvalFaceBasis(basis, p, double(ij[0]) / p, double(ij[1]) / p, N.data(), nullptr,
                              nullptr);
                for (int k = 0; k < n; ++k) EXPECT_NEAR(N[k], k == m ? 1 : 0, 1e-11) << p;
            }
            const double u = 0.23, v = 0.31, h = 1e-6;
            EvalFaceBasis(basis, p, u, v, N.data(), Nu.data(), Nv.data());
            double sum = 0, sumU = 0;
            for (int k = 0; k < n; ++k) {
                sum += N[k];
                sumU += Nu[k];
            }
            EXPECT_NEAR(sum, 1, 1e-12);
            EXPECT_NEAR(sumU, 0, 1e-9);
            EvalFaceBasis(basis, p, u + h, v, Np.data(), nullptr, nullptr);
            EvalFaceBasis(basis, p, u - h, v, Nm.data(), nullptr, nullptr);
            for (int k = 0; k < n; ++k)
                EXPECT_NEAR(Nu[k], (Np[k] - Nm[k]) / (2 * h), 1e-5 * (1 + std::fabs(Nu[k])));
            EvalFaceBasis(basis, p, u, v + h, Np.data(), nullptr, nullptr);
            EvalFaceBasis(basis, p, u, v - h, Nm.data(), nullptr, nullptr);
            for (int k = 0; k < n; ++k)
                EXPECT_NEAR(Nv[k], (Np[k] - Nm[k]) / (2 * h), 1e-5 * (1 + std::fabs(Nv[k])));
        }
    }
}

}  // namespace
}  // namespace hpray::trace

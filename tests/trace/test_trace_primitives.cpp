// Tests of the traversal primitives: exact edge signs, the watertight triangle test, the
// ray-bilinear patch closed form, the face bases, and curved faces (Bernstein nets, exact
// crossings and their edge rule).
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <functional>
#include <random>
#include <vector>

#include "trace/bilinear_patch.h"
#include "trace/curved_face.h"
#include "trace/face_map.h"
#include "trace/face_point.h"
#include "trace/ray_frame.h"

namespace hpray::trace {
namespace {

TEST(RayFrame, EdgeSignIsExactAndAntisymmetric) {
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> uni(-1, 1);
    for (int i = 0; i < 20000; ++i) {
        ShearedPoint p{uni(rng), uni(rng), 0}, q{uni(rng), uni(rng), 0};
        if (i % 3 == 0) q = {p.x * 3, p.y * 3, 0};  // collinear with the origin
        if (i % 5 == 0) q = {p.x, uni(rng), 0};     // vertical edge
        if (i % 7 == 0) p = {0, 0, 0};              // through the origin
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
        ASSERT_TRUE(
            CrossTriangle(frame.Transform(A), frame.Transform(C), frame.Transform(B), y));
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

// MakeFacePoint against its definition written out in scalar arithmetic (the build may
// vectorise the sums): bitwise the same point, weights and bounds, on random crossings
// of triangles of every scale and sign (and corners exactly on the ray's axes).
TEST(FacePoint, MakeFacePointIsItsDefinitionBitwise) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> unit(-1.0, 1.0), mag(-12.0, 4.0);
    const double kU = 0.5 * std::numeric_limits<double>::epsilon();
    const double kEps = std::numeric_limits<double>::epsilon();
    int checked = 0;
    for (int trial = 0; trial < 20000; ++trial) {
        ShearedPoint p[3];
        const double scale = std::pow(10.0, mag(rng));
        for (auto& q : p) {
            q.x = trial % 7 == 0 ? 0.0 : scale * unit(rng);
            q.y = trial % 11 == 0 ? -0.0 : scale * unit(rng);
            q.z = scale * unit(rng);
        }
        TriangleCrossing x;
        if (!CrossTriangle(p[0], p[1], p[2], x)) continue;
        const std::int32_t ids[3] = {trial, trial + 1, trial + 2};
        const double dirKz = 0.5 + 0.5 * std::abs(unit(rng));
        FacePoint fp;
        MakeFacePoint(ids, p[0], p[1], p[2], x, dirKz, fp);
        double err = 0, dx = 0, dy = 0, ax = 0, ay = 0, az = 0;
        for (int k = 0; k < 3; ++k) {
            err = std::max(
                err, std::abs(p[k].x) + std::abs(p[k].y) + 2 * std::abs(p[k].z) * dirKz);
            dx += x.bary[k] * p[k].x;
            dy += x.bary[k] * p[k].y;
            ax += x.bary[k] * std::abs(p[k].x);
            ay += x.bary[k] * std::abs(p[k].y);
            az += x.bary[k] * std::abs(p[k].z);
        }
        const double cornerError = 4 * kU * err;
        ASSERT_TRUE(fp.Valid());
        for (int k = 0; k < 3; ++k) {
            EXPECT_EQ(fp.v[k], ids[k]);
            EXPECT_EQ(fp.w[k], x.bary[k]);
        }
        EXPECT_EQ(fp.t, x.t);
        EXPECT_EQ(fp.cornerError, cornerError);
        EXPECT_EQ(fp.off[0], std::abs(dx) + 4 * kEps * ax + cornerError) << trial;
        EXPECT_EQ(fp.off[1], std::abs(dy) + 4 * kEps * ay + cornerError) << trial;
        EXPECT_EQ(fp.off[2], 4 * kEps * az) << trial;
        ++checked;
    }
    EXPECT_GT(checked, 1000);
}

TEST(BilinearPatch, RootsLieOnPatchAndRay) {
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> uni(-1, 1);
    int found = 0;
    for (int i = 0; i < 5000; ++i) {
        double q[4][3];
        for (int k = 0; k < 4; ++k)
            for (int d = 0; d < 3; ++d)
                q[k][d] = (k == 1 || k == 2 ? 1 : 0) * (d == 0) +
                          (k >= 2 ? 1 : 0) * (d == 1) + 0.4 * uni(rng);
        // Ray through P(u0, v0).
        const double u0 = 0.5 * (1 + uni(rng)), v0 = 0.5 * (1 + uni(rng));
        double X[3], dir[3], len = 0;
        for (int d = 0; d < 3; ++d) {
            X[d] = (1 - u0) * (1 - v0) * q[0][d] + u0 * (1 - v0) * q[1][d] +
                   u0 * v0 * q[2][d] + (1 - u0) * v0 * q[3][d];
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
                P[d] = (1 - u) * (1 - v) * q[0][d] + u * (1 - v) * q[1][d] +
                       u * v * q[2][d] + (1 - u) * v * q[3][d];
            double err = 0;
            for (int d = 0; d < 3; ++d)
                err = std::max(err, std::fabs(P[d] - (o[d] + roots[r].t * dir[d])));
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
    for (FaceBasis basis :
         {FaceBasis::Triangle, FaceBasis::Quad, FaceBasis::QuadSerendipity}) {
        for (int p = 1; p <= 10; ++p) {
            if (basis == FaceBasis::QuadSerendipity && p != 2) continue;
            const int n = FaceNodeCount(basis, p);
            std::vector<double> N(n), Nu(n), Nv(n), Np(n), Nm(n);
            for (int m = 0; m < n; ++m) {
                const auto ij = FaceNodeLattice(basis, p, m);
                EvalFaceBasis(basis, p, double(ij[0]) / p, double(ij[1]) / p, N.data(),
                              nullptr, nullptr);
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
                EXPECT_NEAR(Nu[k], (Np[k] - Nm[k]) / (2 * h),
                            1e-5 * (1 + std::fabs(Nu[k])));
            EvalFaceBasis(basis, p, u, v + h, Np.data(), nullptr, nullptr);
            EvalFaceBasis(basis, p, u, v - h, Nm.data(), nullptr, nullptr);
            for (int k = 0; k < n; ++k)
                EXPECT_NEAR(Nv[k], (Np[k] - Nm[k]) / (2 * h),
                            1e-5 * (1 + std::fabs(Nv[k])));
        }
    }
}

// ---------------------------------------------------------------------------------------
// Curved faces

// A polynomial map of degree p (total degree for triangles, per variable for quads).
struct PolyMap {
    bool triangle;
    int p;
    std::vector<std::array<double, 3>> c;  // coefficient of u^a v^b, a, b <= p

    PolyMap(bool tri, int order, std::mt19937_64& rng) : triangle(tri), p(order) {
        std::uniform_real_distribution<double> uni(-1, 1);
        c.resize((p + 1) * (p + 1));
        for (int b = 0; b <= p; ++b)
            for (int a = 0; a <= p; ++a)
                for (int d = 0; d < 3; ++d)
                    c[b * (p + 1) + a][d] =
                        (tri && a + b > p) ? 0 : uni(rng) / (1 + a + b);
    }
    void Eval(double u, double v, double* f, double* fu, double* fv) const {
        for (int d = 0; d < 3; ++d) f[d] = fu[d] = fv[d] = 0;
        for (int b = 0; b <= p; ++b)
            for (int a = 0; a <= p; ++a)
                for (int d = 0; d < 3; ++d) {
                    const double k = c[b * (p + 1) + a][d];
                    f[d] += k * std::pow(u, a) * std::pow(v, b);
                    if (a > 0) fu[d] += k * a * std::pow(u, a - 1) * std::pow(v, b);
                    if (b > 0) fv[d] += k * b * std::pow(u, a) * std::pow(v, b - 1);
                }
    }
};

TEST(CurvedFace, BernsteinNetsReproducePolynomialMaps) {
    std::mt19937_64 rng(19);
    std::uniform_real_distribution<double> uni(0, 1);
    for (bool tri : {true, false})
        for (int p = 1; p <= 10; ++p) {
            const PolyMap map(tri, p, rng);
            const int n = NetSize(tri, p);
            std::vector<double> nodal(3 * n), net(3 * n);
            const FaceBasis basis = tri ? FaceBasis::Triangle : FaceBasis::Quad;
            ASSERT_EQ(n, FaceNodeCount(basis, p));
            for (int m = 0; m < n; ++m) {
                const auto ij = FaceNodeLattice(basis, p, m);
                double f[3], fu[3], fv[3];
                map.Eval(double(ij[0]) / p, double(ij[1]) / p, f, fu, fv);
                for (int d = 0; d < 3; ++d) nodal[3 * m + d] = f[d];
            }
            FaceBernstein(tri, p, nodal.data(), net.data());
            std::vector<ShearedPoint> pts(n);
            for (int m = 0; m < n; ++m)
                pts[m] = {net[3 * m], net[3 * m + 1], net[3 * m + 2]};
            const double tol = p <= 4 ? 1e-13 : 1e-10;
            for (int i = 0; i < 50; ++i) {
                double u = uni(rng), v = uni(rng);
                if (tri && u + v > 1) u = 1 - u, v = 1 - v;
                double f[3], fu[3], fv[3], g[3], gu[3], gv[3];
                map.Eval(u, v, f, fu, fv);
                EvalNet(tri, p, pts.data(), u, v, g, gu, gv);
                for (int d = 0; d < 3; ++d) {
                    EXPECT_NEAR(g[d], f[d], tol) << tri << " p " << p;
                    EXPECT_NEAR(gu[d], fu[d], 20 * tol) << tri << " p " << p;
                    EXPECT_NEAR(gv[d], fv[d], 20 * tol) << tri << " p " << p;
                }
            }
            // The boundary rows are the edges' own Bernstein points (what neighbouring
            // faces are given for a shared edge), and the corners are the corner nodes.
            for (int e = 0; e < (tri ? 3 : 4); ++e) {
                std::vector<double> en(3 * (p + 1)), eb(3 * (p + 1));
                for (int k = 0; k <= p; ++k)
                    for (int d = 0; d < 3; ++d)
                        en[3 * k + d] = nodal[3 * EdgeLatticeIndex(tri, p, e, k) + d];
                EdgeBernstein(p, en.data(), eb.data());
                for (int k = 0; k <= p; ++k)
                    for (int d = 0; d < 3; ++d)
                        EXPECT_NEAR(eb[3 * k + d],
                                    net[3 * EdgeLatticeIndex(tri, p, e, k) + d], tol);
                for (int d = 0; d < 3; ++d) {
                    EXPECT_EQ(eb[d], en[d]);
                    EXPECT_EQ(net[3 * EdgeLatticeIndex(tri, p, e, 0) + d], en[d]);
                }
            }
        }
}

// A surface z = h(x, y) cut into faces over a fan of parameter-plane polygons around a
// centre, built as the traversal builds them: nodes on the surface, Bernstein nets, every
// boundary row replaced by the edge's points computed from its nodes in a canonical order
// (straight edges: points on the segment).
struct Fan {
    std::vector<std::vector<double>> nets;
    std::vector<CurvedFace> faces;
    std::vector<bool> planar;  // a planar triangle: crossed by CrossTriangle instead
    std::vector<std::array<std::array<double, 3>, 3>> triangles;
};

void AddFace(Fan& fan, const std::function<double(double, double)>& h,
             const std::vector<std::array<double, 2>>& corners, int p) {
    const bool tri = corners.size() == 3;
    const int n = NetSize(tri, p);
    const FaceBasis basis = tri ? FaceBasis::Triangle : FaceBasis::Quad;
    std::vector<double> nodal(3 * n), net(3 * n);
    for (int m = 0; m < n; ++m) {
        const auto ij = FaceNodeLattice(basis, p, m);
        const double u = double(ij[0]) / p, v = double(ij[1]) / p;
        double xy[2];
        for (int d = 0; d < 2; ++d)
            xy[d] = tri ? corners[0][d] + u * (corners[1][d] - corners[0][d]) +
                              v * (corners[2][d] - corners[0][d])
                        : (1 - u) * (1 - v) * corners[0][d] +
                              u * (1 - v) * corners[1][d] + u * v * corners[2][d] +
                              (1 - u) * v * corners[3][d];
        nodal[3 * m] = xy[0];
        nodal[3 * m + 1] = xy[1];
    }
    // Nodes on an edge are computed from the edge's end points in a canonical order, so
    // the faces sharing it hold bitwise the same nodes, as merged mesh nodes are.
    const int nc = tri ? 3 : 4;
    for (int e = 0; e < nc; ++e) {
        std::array<double, 2> a = corners[e], b = corners[(e + 1) % nc];
        const bool flip = b < a;
        if (flip) std::swap(a, b);
        for (int k = 0; k <= p; ++k) {
            const int m = EdgeLatticeIndex(tri, p, e, flip ? p - k : k);
            for (int d = 0; d < 2; ++d)
                nodal[3 * m + d] = k == 0   ? a[d]
                                   : k == p ? b[d]
                                            : a[d] + (double(k) / p) * (b[d] - a[d]);
        }
    }
    for (int m = 0; m < n; ++m) nodal[3 * m + 2] = h(nodal[3 * m], nodal[3 * m + 1]);
    FaceBernstein(tri, p, nodal.data(), net.data());
    std::uint8_t straight = 0;
    for (int e = 0; e < (tri ? 3 : 4); ++e) {
        std::vector<std::array<double, 3>> en(p + 1);
        for (int k = 0; k <= p; ++k)
            for (int d = 0; d < 3; ++d)
                en[k][d] = nodal[3 * EdgeLatticeIndex(tri, p, e, k) + d];
        const bool reversed = en[p] < en[0];
        if (reversed) std::reverse(en.begin(), en.end());
        std::vector<double> row(3 * (p + 1));
        bool isStraight = true;
        for (int k = 1; k < p; ++k)
            for (int d = 0; d < 3; ++d)
                isStraight =
                    isStraight &&
                    std::fabs(en[k][d] - (en[0][d] + (double(k) / p) *
                                                         (en[p][d] - en[0][d]))) < 1e-13;
        if (isStraight) {
            straight = std::uint8_t(straight | (1u << e));
            for (int k = 0; k <= p; ++k)
                for (int d = 0; d < 3; ++d)
                    row[3 * k + d] =
                        k == 0   ? en[0][d]
                        : k == p ? en[p][d]
                                 : en[0][d] + (double(k) / p) * (en[p][d] - en[0][d]);
        } else {
            EdgeBernstein(p, en[0].data(), row.data());
        }
        for (int k = 0; k <= p; ++k)
            for (int d = 0; d < 3; ++d)
                net[3 * EdgeLatticeIndex(tri, p, e, k) + d] =
                    row[3 * (reversed ? p - k : k) + d];
    }
    fan.nets.push_back(net);
    CurvedFace face;
    face.triangle = tri;
    face.order = p;
    face.straightEdges = straight;
    face.size = 1;
    fan.faces.push_back(face);
    fan.planar.push_back(false);
    fan.triangles.push_back({});
}

void AddPlanarTriangle(Fan& fan, const std::function<double(double, double)>& h,
                       const std::vector<std::array<double, 2>>& corners) {
    std::array<std::array<double, 3>, 3> t;
    for (int k = 0; k < 3; ++k)
        t[k] = {corners[k][0], corners[k][1], h(corners[k][0], corners[k][1])};
    fan.nets.emplace_back();
    fan.faces.emplace_back();
    fan.planar.push_back(true);
    fan.triangles.push_back(t);
}

// Crossings of the ray with all faces of the fan: count, t and side of the last one.
int CrossFan(const Fan& fan, const Ray& ray, double& t, int& side) {
    const RayFrame frame(ray);
    int count = 0;
    for (std::size_t f = 0; f < fan.faces.size(); ++f) {
        if (fan.planar[f]) {
            TriangleCrossing x;
            if (CrossTriangle(frame.Transform(fan.triangles[f][0].data()),
                              frame.Transform(fan.triangles[f][1].data()),
                              frame.Transform(fan.triangles[f][2].data()), x)) {
                ++count;
                t = x.t;
                side = x.side;
            }
            continue;
        }
        CurvedFace face = fan.faces[f];
        face.net = fan.nets[f].data();
        std::vector<FaceCrossing> xs;
        EXPECT_EQ(CrossCurvedFace(face, frame, CurvedFaceOptions{}, xs), 0);
        for (const auto& x : xs) {
            ++count;
            t = x.t;
            side = x.side;
        }
    }
    return count;
}

// Rays through points of the surface on the fan's shared edges and vertices (and inside
// faces) must cross the fan exactly once, at t = 3 (the ray starts 3 before the point),
// on the side of the upward normal.
void CheckFan(const Fan& fan, const std::function<double(double, double)>& h,
              const std::function<std::array<double, 2>(std::mt19937_64&)>& target,
              const std::string& what) {
    std::mt19937_64 rng(23);
    std::uniform_real_distribution<double> uni(-1, 1);
    for (int i = 0; i < 4000; ++i) {
        const auto xy = target(rng);
        const double X[3] = {xy[0], xy[1], h(xy[0], xy[1])};
        double dir[3] = {0.5 * uni(rng), 0.5 * uni(rng), i % 2 ? 1.0 : -1.0}, len = 0;
        for (double d : dir) len += d * d;
        Ray ray;
        for (int d = 0; d < 3; ++d) {
            ray.dir[d] = dir[d] / std::sqrt(len);
            ray.origin[d] = X[d] - 3 * ray.dir[d];
        }
        double t = 0;
        int side = 0;
        ASSERT_EQ(CrossFan(fan, ray, t, side), 1) << what << " ray " << i;
        EXPECT_NEAR(t, 3, 1e-12) << what << " ray " << i;
        // Upward normal (-h_x, -h_y, 1); h's slopes here are below 1 while |dir_z| > 0.8.
        EXPECT_EQ(side, ray.dir[2] > 0 ? 1 : -1) << what << " ray " << i;
    }
}

// Fans on dyadic parameter-plane corners, so that every node a face computes (corners,
// and lattice points at multiples of 1/2 or 1/4 along edges) is bitwise the node its
// neighbour computes, as merged mesh nodes are.
TEST(CurvedFace, FansAroundCurvedVerticesAreCrossedExactlyOnce) {
    const double cx = 0.125, cy = -0.1875, r = 0.25;
    const auto paraboloid = [](double x, double y) { return x * x + y * y; };
    const auto cubic = [](double x, double y) {
        return x * x + 0.5 * y * y + 0.4 * x * x * x;
    };
    // The ring of 8 corners around the centre, counter-clockwise.
    const double ring[8][2] = {{1, 0},  {1, 1},   {0, 1},  {-1, 1},
                               {-1, 0}, {-1, -1}, {0, -1}, {1, -1}};
    // Points on the fan: the centre, a random point on a spoke (a shared curved edge), or
    // anywhere inside.
    auto target = [&](int step) {
        return [=](std::mt19937_64& rng) {
            std::uniform_real_distribution<double> uni(0, 1);
            const int kind = int(3 * uni(rng));
            if (kind == 0) return std::array<double, 2>{cx, cy};
            const double s = 0.95 * uni(rng);
            if (kind == 1) {
                const int k = step * (int(8 * uni(rng)) / step);
                return std::array<double, 2>{cx + s * r * ring[k][0],
                                             cy + s * r * ring[k][1]};
            }
            const double ang = 2 * M_PI * uni(rng);
            return std::array<double, 2>{cx + s * r * std::cos(ang),
                                         cy + s * r * std::sin(ang)};
        };
    };
    for (int p : {2, 4}) {
        const auto h = p == 2 ? std::function<double(double, double)>(paraboloid)
                              : std::function<double(double, double)>(cubic);
        Fan tris;  // eight triangles around the centre
        for (int k = 0; k < 8; ++k)
            AddFace(tris, h,
                    {{cx, cy},
                     {cx + r * ring[k][0], cy + r * ring[k][1]},
                     {cx + r * ring[(k + 1) % 8][0], cy + r * ring[(k + 1) % 8][1]}},
                    p);
        CheckFan(tris, h, target(1), "triangles p" + std::to_string(p));
        Fan quads;  // four quadrilaterals around the centre
        for (int k = 0; k < 8; k += 2)
            AddFace(quads, h,
                    {{cx, cy},
                     {cx + r * ring[k][0], cy + r * ring[k][1]},
                     {cx + r * ring[k + 1][0], cy + r * ring[k + 1][1]},
                     {cx + r * ring[(k + 2) % 8][0], cy + r * ring[(k + 2) % 8][1]}},
                    p);
        CheckFan(quads, h, target(2), "quads p" + std::to_string(p));
    }
}

TEST(CurvedFace, StraightEdgeSharedWithPlanarFacesIsCrossedExactlyOnce) {
    // A tilted plane for y <= 0 (planar triangles), the same plus y^2 for y >= 0 (curved
    // faces whose edges on y = 0 are straight), on non-dyadic corners: rays through the
    // straight shared edges and their vertices pass within rounding of them.
    const auto h = [](double x, double y) {
        return 0.3 * x + 0.1 * y + (y > 0 ? y * y : 0.0);
    };
    const double xs[4] = {-0.6, -0.1, 0.35, 0.7};
    Fan fan;
    for (int k = 0; k + 1 < 4; ++k) {
        const double x0 = xs[k], x1 = xs[k + 1];
        AddPlanarTriangle(fan, h, {{x0, 0}, {x0, -0.5}, {x1, 0}});
        AddPlanarTriangle(fan, h, {{x1, 0}, {x0, -0.5}, {x1, -0.5}});
        AddFace(fan, h, {{x0, 0}, {x1, 0}, {x1, 0.5}}, 2);
        AddFace(fan, h, {{x0, 0}, {x1, 0.5}, {x0, 0.5}}, 2);
    }
    for (std::size_t f = 0; f < fan.faces.size(); f += 4)
        EXPECT_EQ(fan.faces[f + 2].straightEdges, 1);
    CheckFan(
        fan, h,
        [&](std::mt19937_64& rng) {
            std::uniform_real_distribution<double> uni(0, 1);
            const double x =
                uni(rng) < 0.3 ? xs[1 + int(2 * uni(rng))] : -0.5 + 1.1 * uni(rng);
            return std::array<double, 2>{x, uni(rng) < 0.7 ? 0.0 : 0.4 * uni(rng) - 0.2};
        },
        "planar and curved");
}

}  // namespace
}  // namespace hpray::trace

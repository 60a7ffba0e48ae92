// Nodal bases: exact reproduction of each cell's space, partition of unity, Kronecker
// property, gradients against analytic derivatives and finite differences, traces.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cmath>
#include <random>
#include <vector>

#include "elements/basis.h"
#include "elements/element_test_util.h"

namespace hpray {
namespace {

using testing::AllCellKinds;
using testing::CellKind;
using testing::FamilyName;
using testing::RandomRefPoint;
using testing::SpaceOf;

std::string Name(const CellKind& k) {
    return std::string(ShapeName(k.shape)) + " p" + std::to_string(k.order) + " " +
           FamilyName(k.family);
}

TEST(Basis, DimensionEqualsNodeCount) {
    for (const CellKind& k : AllCellKinds()) {
        const BasisTable& b = GetBasis(k.shape, k.order, k.family);
        EXPECT_EQ(static_cast<int>(SpaceOf(k).size()), b.nodeCount) << Name(k);
        EXPECT_EQ(b.nodeCount, NodeCount(k.shape, k.order, k.family)) << Name(k);
    }
}

TEST(Basis, KroneckerAtNodes) {
    for (const CellKind& k : AllCellKinds()) {
        const BasisTable& b = GetBasis(k.shape, k.order, k.family);
        std::vector<double> v(b.nodeCount);
        double worst = 0.0;
        for (int n = 0; n < b.nodeCount; ++n) {
            const auto x = LatticeRefCoords(k.shape, k.order, b.lattice[n]);
            EvalBasis(b, x.data(), v.data(), nullptr);
            for (int m = 0; m < b.nodeCount; ++m)
                worst = std::max(worst, std::abs(v[m] - (m == n ? 1.0 : 0.0)));
        }
        EXPECT_LT(worst, 1e-13) << Name(k);
    }
}

// Interpolating every function of the declared space at the nodes and evaluating anywhere
// must give the function back (values and reference gradients): this pins the space.
TEST(Basis, ReproducesItsSpaceExactly) {
    for (const CellKind& k : AllCellKinds()) {
        const BasisTable& b = GetBasis(k.shape, k.order, k.family);
        const int n = b.nodeCount;
        std::mt19937_64 rng(1000 + 17 * static_cast<int>(k.shape) + k.order);
        const int kPoints = 12;
        std::vector<std::array<double, 3>> pts;
        std::vector<double> vals(kPoints * n), grads(3 * kPoints * n);
        for (int q = 0; q < kPoints; ++q) {
            pts.push_back(RandomRefPoint(k.shape, rng));
            EvalBasis(b, pts[q].data(), vals.data() + q * n, grads.data() + 3 * q * n);
        }
        double worstValue = 0.0, worstGrad = 0.0;
        std::vector<double> nodal(n);
        for (const auto& f : SpaceOf(k)) {
            double scale = 1.0;
            for (int m = 0; m < n; ++m) {
                const auto x = LatticeRefCoords(k.shape, k.order, b.lattice[m]);
                nodal[m] = f.Value(x);
                scale = std::max(scale, std::abs(nodal[m]));
            }
            for (int q = 0; q < kPoints; ++q) {
                double v = 0.0, g[3] = {0, 0, 0};
                for (int m = 0; m < n; ++m) {
                    v += nodal[m] * vals[q * n + m];
                    for (int d = 0; d < 3; ++d) g[d] += nodal[m] * grads[3 * (q * n + m) + d];
                }
                worstValue = std::max(worstValue, std::abs(v - f.Value(pts[q])) / scale);
                const auto ge = f.Gradient(pts[q]);
                for (int d = 0; d < 3; ++d)
                    worstGrad = std::max(worstGrad, std::abs(g[d] - ge[d]) / scale);
            }
        }
        EXPECT_LT(worstValue, 1e-13) << Name(k);
        // Gradients of degree-p interpolants carry a factor ~p^2 more rounding.
        EXPECT_LT(worstGrad, 1e-11) << Name(k);
        char buf[64];
        std::snprintf(buf, sizeof buf, "%.2e %.2e", worstValue, worstGrad);
        RecordProperty(("reproduction_" + Name(k)).c_str(), buf);
    }
}

// The space must not be larger than declared: a function outside it (one degree up) is
// not reproduced. Guards against a basis that interpolates a wrong, bigger space.
TEST(Basis, DoesNotReproduceTheNextDegree) {
    for (const CellKind& k : AllCellKinds()) {
        const BasisTable& b = GetBasis(k.shape, k.order, k.family);
        testing::SpaceFunction f{{0, 0, 0, 0}, 0.0};
        if (k.family == CellFamily::Serendipity) f.e[0] = f.e[1] = 2;  // r^2 s^2
        else if (k.shape == CellShape::Hex || k.shape == CellShape::Wedge) f.e[2] = k.order + 1;
        else if (k.shape == CellShape::Tet) f.e[0] = k.order + 1;
        else f.e[0] = k.order + 1;
        std::vector<double> v(b.nodeCount);
        double worst = 0.0;
        std::mt19937_64 rng(5);
        for (int q = 0; q < 20; ++q) {
            const auto x = RandomRefPoint(k.shape, rng);
            EvalBasis(b, x.data(), v.data(), nullptr);
            double s = 0.0;
            for (int m = 0; m < b.nodeCount; ++m)
                s += v[m] * f.Value(LatticeRefCoords(k.shape, k.order, b.lattice[m]));
            worst = std::max(worst, std::abs(s - f.Value(x)));
        }
        EXPECT_GT(worst, 1e-6) << Name(k);
    }
}

TEST(Basis, PartitionOfUnity) {
    for (const CellKind& k : AllCellKinds()) {
        const BasisTable& b = GetBasis(k.shape, k.order, k.family);
        std::vector<double> v(b.nodeCount), d(3 * b.nodeCount);
        std::mt19937_64 rng(7);
        for (int q = 0; q < 50; ++q) {
            auto x = RandomRefPoint(k.shape, rng);
            if (q == 0 && k.shape == CellShape::Pyramid) x = {0.5, 0.5, 1.0};  // apex
            EvalBasis(b, x.data(), v.data(), d.data());
            double s = 0.0, g[3] = {0, 0, 0};
            for (int m = 0; m < b.nodeCount; ++m) {
                s += v[m];
                for (int c = 0; c < 3; ++c) g[c] += d[3 * m + c];
            }
            EXPECT_NEAR(s, 1.0, 1e-13) << Name(k) << " point " << q;
            for (int c = 0; c < 3; ++c) EXPECT_NEAR(g[c], 0.0, 1e-10) << Name(k) << " " << q;
        }
    }
}

// Sixth-order central differences of each basis function.
TEST(Basis, GradientsMatchFiniteDifferences) {
    for (const CellKind& k : AllCellKinds()) {
        const BasisTable& b = GetBasis(k.shape, k.order, k.family);
        const int n = b.nodeCount;
        std::vector<double> v(n), d(3 * n), vp(n);
        std::mt19937_64 rng(11);
        const double h = 1e-3;
        const double w[3] = {45.0 / 60.0, -9.0 / 60.0, 1.0 / 60.0};
        for (int q = 0; q < 4; ++q) {
            auto x = RandomRefPoint(k.shape, rng);
            if (k.shape == CellShape::Pyramid) x[2] = std::min(x[2], 0.9);
            EvalBasis(b, x.data(), v.data(), d.data());
            std::vector<double> fd(3 * n, 0.0);
            for (int c = 0; c < 3; ++c)
                for (int s = 1; s <= 3; ++s)
                    for (int sign : {1, -1}) {
                        auto y = x;
                        y[c] += sign * s * h;
                        EvalBasis(b, y.data(), vp.data(), nullptr);
                        for (int m = 0; m < n; ++m) fd[3 * m + c] += sign * w[s - 1] * vp[m] / h;
                    }
            double worst = 0.0, scale = 1.0;
            for (int i = 0; i < 3 * n; ++i) {
                worst = std::max(worst, std::abs(fd[i] - d[i]));
                scale = std::max(scale, std::abs(d[i]));
            }
            EXPECT_LT(worst / scale, 1e-7) << Name(k) << " point " << q;
        }
    }
}

// Conformity: on a face, the basis functions of nodes off that face vanish, and the
// trace of the space is P_p on triangles and Q_p (serendipity: S_2) on quads, which the
// reproduction test covers; here we check the vanishing, on random face points.
TEST(Basis, FunctionsOfNodesOffAFaceVanishOnIt) {
    std::mt19937_64 rng(13);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (const CellKind& k : AllCellKinds()) {
        const BasisTable& b = GetBasis(k.shape, k.order, k.family);
        std::vector<double> v(b.nodeCount);
        // Faces given by a point generator and a lattice predicate.
        struct Face {
            std::array<double, 3> (*point)(double, double);
            bool (*onFace)(const LatticeIndex&, int);
        };
        std::vector<Face> faces;
        faces.push_back({[](double a, double b) {  // bottom t = 0 (triangle or square)
                             return std::array<double, 3>{a, b, 0.0};
                         },
                         [](const LatticeIndex& x, int) { return x[2] == 0; }});
        if (k.shape == CellShape::Pyramid)
            faces.push_back({[](double a, double c) {  // slanted face s = t/2 (j = 0)
                                 return std::array<double, 3>{c / 2 + a * (1 - c), c / 2, c};
                             },
                             [](const LatticeIndex& x, int) { return x[1] == 0; }});
        else
            faces.push_back({[](double a, double c) {  // s = 0
                                 return std::array<double, 3>{a, 0.0, c};
                             },
                             [](const LatticeIndex& x, int) { return x[1] == 0; }});
        for (const Face& f : faces)
            for (int q = 0; q < 20; ++q) {
                auto x = f.point(u(rng), u(rng));
                if (!testing::InsideRef(k.shape, x)) continue;
                EvalBasis(b, x.data(), v.data(), nullptr);
                for (int m = 0; m < b.nodeCount; ++m) {
                    if (f.onFace(b.lattice[m], k.order)) continue;
                    EXPECT_NEAR(v[m], 0.0, 1e-13) << Name(k) << " node " << m;
                }
            }
    }
}

TEST(Basis, TablesReportDegrees) {
    EXPECT_EQ(GetBasis(CellShape::Tet, 4).lineDegree, 4);
    EXPECT_EQ(GetBasis(CellShape::Hex, 4).lineDegree, 12);
    EXPECT_EQ(GetBasis(CellShape::Wedge, 4).lineDegree, 8);
    EXPECT_FALSE(GetBasis(CellShape::Pyramid, 2).polynomial);
    EXPECT_EQ(GetBasis(CellShape::Hex, 2, CellFamily::Serendipity).lineDegree, 4);
    EXPECT_EQ(GetBasis(CellShape::Wedge, 2, CellFamily::Serendipity).lineDegree, 3);
}

// The linear pyramid's specialised evaluation gives bitwise what the path for every
// order gives, values and derivatives, inside, outside and on the apex line.
TEST(Basis, LinearPyramidEqualsTheAnyOrderPathBitwise) {
    const BasisTable& b = GetBasis(CellShape::Pyramid, 1);
    ASSERT_EQ(b.nodeCount, 5);
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> uni(-0.5, 1.5);
    std::vector<std::array<double, 3>> points = {
        {0, 0, 0}, {1, 1, 0}, {0.5, 0.5, 1}, {0.2, 0.7, 1}, {0.25, 0.25, 0.5}};
    for (int i = 0; i < 2000; ++i) points.push_back({uni(rng), uni(rng), uni(rng)});
    for (const auto& x : points) {
        double v[5], d[15], vg[5], dg[15];
        EvalBasis(b, x.data(), v, d);
        EvalPyramidAnyOrder(b, x.data(), vg, dg);
        for (int m = 0; m < 5; ++m)
            EXPECT_EQ(v[m], vg[m]) << x[0] << " " << x[1] << " " << x[2];
        for (int m = 0; m < 15; ++m)
            EXPECT_EQ(d[m], dg[m]) << x[0] << " " << x[1] << " " << x[2];
        double vo[5];
        EvalBasis(b, x.data(), vo, nullptr);
        for (int m = 0; m < 5; ++m) EXPECT_EQ(vo[m], vg[m]);
    }
}

// Along a line in an affine pyramid, (1 - t)^m f is a polynomial of the declared degree:
// its finite difference of order degree + 1 vanishes.
TEST(Basis, PyramidLineDegree) {
    for (int p = 1; p <= 6; ++p) {
        const BasisTable& b = GetBasis(CellShape::Pyramid, p);
        std::vector<double> v(b.nodeCount);
        std::mt19937_64 rng(17 + p);
        const int deg = b.lineDegree;
        for (int trial = 0; trial < 3; ++trial) {
            const auto a = RandomRefPoint(CellShape::Pyramid, rng);
            const auto c = RandomRefPoint(CellShape::Pyramid, rng);
            std::vector<std::vector<double>> samples;
            for (int s = 0; s <= deg + 1; ++s) {
                const double lambda = static_cast<double>(s) / (deg + 1);
                std::array<double, 3> x;
                for (int d = 0; d < 3; ++d) x[d] = a[d] + lambda * (c[d] - a[d]);
                EvalBasis(b, x.data(), v.data(), nullptr);
                const double w = std::pow(1.0 - x[2], b.lineDenominatorPower);
                std::vector<double> row(b.nodeCount);
                for (int m = 0; m < b.nodeCount; ++m) row[m] = v[m] * w;
                samples.push_back(row);
            }
            for (int m = 0; m < b.nodeCount; ++m) {
                std::vector<double> col;
                for (auto& r : samples) col.push_back(r[m]);
                for (int o = 0; o <= deg; ++o)
                    for (std::size_t i = 0; i + 1 < col.size() - o; ++i)
                        col[i] = col[i + 1] - col[i];
                EXPECT_NEAR(col[0], 0.0, 1e-9) << "p" << p << " node " << m;
            }
        }
    }
}

}  // namespace
}  // namespace hpray

// Sub-cell bounds of Lagrange hexahedra (HexSubBounds) against closed forms: the exact
// range of monotone products over every box, and dense samples of random interpolants.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <vector>

#include "elements/basis.h"
#include "elements/bounds.h"
#include "elements/tensor_eval.h"
#include "mesh/cell.h"

namespace hpray {
namespace {

// Nodal values of f on the order-p lattice, internal order (i fastest).
template <typename F>
std::vector<double> Nodal(int p, F f) {
    std::vector<double> u;
    for (int k = 0; k <= p; ++k)
        for (int j = 0; j <= p; ++j)
            for (int i = 0; i <= p; ++i)
                u.push_back(f(double(i) / p, double(j) / p, double(k) / p));
    return u;
}

// f = (x + 1/2)^a (3/2 - y)^b (z + 1/4)^c: positive factors, each monotone, so its range
// over a box is [f at the corner of the lower ends, f at the corner of the upper ends];
// its Bernstein coefficients over the box are products of the factors' monotone ones,
// whose extremes are the end values: the bounds are exact up to rounding.
TEST(HexSubBounds, MonotoneProductsGiveTheExactRangeOfEveryBox) {
    for (int p = 1; p <= kMaxOrder; ++p)
        for (int n = 1; n <= kMaxSubdivision; ++n) {
            const int a = p, b = std::max(1, p - 1), c = p / 2;
            auto f = [&](double x, double y, double z) {
                return std::pow(x + 0.5, a) * std::pow(1.5 - y, b) *
                       std::pow(z + 0.25, c);
            };
            const std::vector<double> u = Nodal(p, f);
            double scale = 0;
            for (double v : u) scale = std::max(scale, std::abs(v));
            std::vector<Interval> out(n * n * n);
            HexSubBounds(p, n, u.data(), 1, out.data());
            for (int k2 = 0; k2 < n; ++k2)
                for (int k1 = 0; k1 < n; ++k1)
                    for (int k0 = 0; k0 < n; ++k0) {
                        const Interval& i = out[k0 + n * (k1 + n * k2)];
                        const double lo =
                            f(double(k0) / n, double(k1 + 1) / n, double(k2) / n);
                        const double hi =
                            f(double(k0 + 1) / n, double(k1) / n, double(k2 + 1) / n);
                        // The stored nodal values are rounded: their interpolant is
                        // within a few ulps of f (times the Lebesgue constant) of f
                        // itself.
                        const double slack = 1e-13 * scale;
                        EXPECT_LE(i.lo, lo + slack) << p << " " << n;
                        EXPECT_GE(i.hi, hi - slack) << p << " " << n;
                        // The margin for the coefficients' rounding, gamma R^3 max |u|,
                        // grows with the order through R, the transforms' largest row
                        // sum; at the subdivision the renderer uses (n = 4) it stays
                        // small: 7e-14 of the values at p = 3, 1.3e-10 at p = 8, 4.4e-9
                        // at p = 10.
                        if (n != kMaxSubdivision) continue;
                        const double margin = (p <= 3   ? 2e-13
                                               : p <= 6 ? 1e-11
                                               : p <= 8 ? 3e-10
                                                        : 1e-8) *
                                              scale;
                        EXPECT_GE(i.lo, lo - margin) << "loose, p " << p;
                        EXPECT_LE(i.hi, hi + margin) << "loose, p " << p;
                    }
        }
}

// Random interpolants with three interleaved components (a map's node coordinates):
// every value at a dense grid of each box lies in that box's interval of its component,
// and finer boxes give narrower intervals.
TEST(HexSubBounds, RandomInterpolantsStayInTheirBoxesIntervals) {
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> value(-3, 3);
    for (int p = 1; p <= kMaxOrder; ++p) {
        const int nodes = (p + 1) * (p + 1) * (p + 1);
        std::vector<double> xyz(3 * nodes);
        for (double& v : xyz) v = value(rng);
        std::vector<double> comp(nodes);
        double width1 = 0, width4 = 0;
        for (int n = 1; n <= kMaxSubdivision; ++n) {
            std::vector<Interval> out(3 * n * n * n);
            HexSubBounds(p, n, xyz.data(), 3, out.data());
            for (int d = 0; d < 3; ++d) {
                for (int m = 0; m < nodes; ++m) comp[m] = xyz[3 * m + d];
                for (int box = 0; box < n * n * n; ++box) {
                    const Interval& iv = out[3 * box + d];
                    if (n == 1) width1 += iv.hi - iv.lo;
                    if (n == 4) width4 += (iv.hi - iv.lo) / (n * n * n);
                    const int k[3] = {box % n, (box / n) % n, box / (n * n)};
                    constexpr int s = 6;
                    for (int c = 0; c <= s; ++c)
                        for (int b = 0; b <= s; ++b)
                            for (int a = 0; a <= s; ++a) {
                                const double ref[3] = {(k[0] + double(a) / s) / n,
                                                       (k[1] + double(b) / s) / n,
                                                       (k[2] + double(c) / s) / n};
                                const double v = HexFieldValue(p, comp.data(), ref);
                                EXPECT_GE(v, iv.lo)
                                    << "p " << p << " n " << n << " d " << d;
                                EXPECT_LE(v, iv.hi)
                                    << "p " << p << " n " << n << " d " << d;
                            }
                }
            }
        }
        EXPECT_LT(width4, width1) << "p " << p;
    }
}

TEST(HexSubBounds, NonFiniteValuesGiveUnboundedIntervals) {
    std::vector<double> u(27, 1.0);
    u[13] = std::nan("");
    std::vector<Interval> out(8);
    HexSubBounds(2, 2, u.data(), 1, out.data());
    for (const Interval& i : out) {
        EXPECT_EQ(i.lo, -std::numeric_limits<double>::infinity());
        EXPECT_EQ(i.hi, std::numeric_limits<double>::infinity());
    }
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// The corners of TetSubBounds' sub-tetrahedra, in its order (uniform refinement: the 4
// corner tetrahedra, then the inner octahedron's 4 around the diagonal x02 - x13).
std::vector<std::array<std::array<double, 3>, 4>> SubTets(int levels) {
    using C = std::array<double, 3>;
    std::vector<std::array<C, 4>> tets = {
        {C{0, 0, 0}, C{1, 0, 0}, C{0, 1, 0}, C{0, 0, 1}}};
    for (int l = 0; l < levels; ++l) {
        std::vector<std::array<C, 4>> next;
        for (const auto& t : tets) {
            auto mid = [&](int a, int b) {
                return C{(t[a][0] + t[b][0]) / 2, (t[a][1] + t[b][1]) / 2,
                         (t[a][2] + t[b][2]) / 2};
            };
            const C x01 = mid(0, 1), x02 = mid(0, 2), x03 = mid(0, 3), x12 = mid(1, 2),
                    x13 = mid(1, 3), x23 = mid(2, 3);
            next.push_back({t[0], x01, x02, x03});
            next.push_back({x01, t[1], x12, x13});
            next.push_back({x02, x12, t[2], x23});
            next.push_back({x03, x13, x23, t[3]});
            next.push_back({x01, x02, x03, x13});
            next.push_back({x01, x02, x12, x13});
            next.push_back({x02, x03, x13, x23});
            next.push_back({x02, x12, x13, x23});
        }
        tets = next;
    }
    return tets;
}

// f = (x + 2 y + 3 z + 1/2)^p: a positive linear form L to the power p. Over a simplex
// its Bernstein coefficients are products of p values of L at the corners, so their
// extremes are the extremes of f at the corners: the bounds are exact up to rounding, on
// every sub-tetrahedron, and the sub-tetrahedra cover the cell (their volumes add up to
// it).
TEST(TetSubBounds, PowersOfALinearFormGiveTheExactRangeOfEverySubTetrahedron) {
    for (int p = 1; p <= 7; ++p)
        for (int levels = 0; levels <= TetSubLevels(p); ++levels) {
            const BasisTable& basis = GetBasis(CellShape::Tet, p, CellFamily::Lagrange);
            auto L = [](const std::array<double, 3>& x) {
                return x[0] + 2 * x[1] + 3 * x[2] + 0.5;
            };
            std::vector<double> u(basis.nodeCount);
            double scale = 0;
            for (int m = 0; m < basis.nodeCount; ++m) {
                u[m] = std::pow(L(basis.refNodes[m]), p);
                scale = std::max(scale, std::abs(u[m]));
            }
            const auto tets = SubTets(levels);
            ASSERT_EQ(int(tets.size()), TetSubCount(levels));
            std::vector<Interval> out(tets.size());
            TetSubBounds(basis, levels, u.data(), 1, out.data());
            double volume = 0;
            for (std::size_t s = 0; s < tets.size(); ++s) {
                double lo = INFINITY, hi = -INFINITY;
                for (const auto& c : tets[s]) {
                    lo = std::min(lo, std::pow(L(c), p));
                    hi = std::max(hi, std::pow(L(c), p));
                }
                double e[3][3];
                for (int a = 0; a < 3; ++a)
                    for (int d = 0; d < 3; ++d)
                        e[a][d] = tets[s][a + 1][d] - tets[s][0][d];
                volume += std::abs(e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) -
                                   e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
                                   e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0])) /
                          6;
                const double slack = 1e-12 * scale;
                EXPECT_LE(out[s].lo, lo + slack) << "p " << p << " levels " << levels;
                EXPECT_GE(out[s].hi, hi - slack) << "p " << p << " levels " << levels;
                if (p <= 4) {  // the rounding margin grows with the transform's row sums
                    EXPECT_GE(out[s].lo, lo - 1e-11 * scale) << "loose, p " << p;
                    EXPECT_LE(out[s].hi, hi + 1e-11 * scale) << "loose, p " << p;
                }
            }
            EXPECT_NEAR(volume, 1.0 / 6, 1e-14);
        }
}

// Random interpolants, four interleaved components (coordinates and a field packed as the
// renderer does): every value at points spread over each sub-tetrahedron lies in its
// interval.
TEST(TetSubBounds, RandomInterpolantsStayInTheirSubTetrahedraIntervals) {
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> value(-2, 2), unit(0, 1);
    for (int p : {1, 2, 3, 4, 6}) {
        const BasisTable& basis = GetBasis(CellShape::Tet, p, CellFamily::Lagrange);
        const int n = basis.nodeCount;
        std::vector<double> u(4 * n);
        for (double& v : u) v = value(rng);
        const int levels = TetSubLevels(p);
        const auto tets = SubTets(levels);
        std::vector<Interval> out(4 * tets.size());
        TetSubBounds(basis, levels, u.data(), 4, out.data());
        std::vector<double> phi(n), dphi(3 * n);
        for (std::size_t s = 0; s < tets.size(); ++s)
            for (int k = 0; k < 40; ++k) {
                // A random point of the sub-tetrahedron (barycentric weights).
                double w[4], sum = 0;
                for (double& x : w) sum += (x = -std::log(unit(rng) + 1e-300));
                double ref[3] = {0, 0, 0};
                for (int c = 0; c < 4; ++c)
                    for (int d = 0; d < 3; ++d) ref[d] += w[c] / sum * tets[s][c][d];
                EvalBasis(basis, ref, phi.data(), dphi.data());
                for (int comp = 0; comp < 4; ++comp) {
                    double v = 0;
                    for (int m = 0; m < n; ++m) v += phi[m] * u[4 * m + comp];
                    const double tol = 1e-13 * 2 * n;  // the evaluation's own rounding
                    EXPECT_GE(v, out[4 * s + comp].lo - tol) << "p " << p << " sub " << s;
                    EXPECT_LE(v, out[4 * s + comp].hi + tol) << "p " << p << " sub " << s;
                }
            }
    }
}

}  // namespace
}  // namespace hpray

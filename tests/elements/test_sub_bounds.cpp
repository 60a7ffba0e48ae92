// Sub-cell bounds of Lagrange hexahedra (HexSubBounds) against closed forms: the exact
// range of monotone products over every box, and dense samples of random interpolants.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

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

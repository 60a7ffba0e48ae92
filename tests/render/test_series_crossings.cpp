// SeriesCrossings (the breakpoint crossings of an exact field series along a ray segment)
// against crossings found in long double: every crossing of random series, including
// those of levels a few ulps from a value at an end of the segment or at a critical point
// (where Newton's step points out of the bracket), to the requested tolerance.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "render/legendre.h"
#include "render/volume_ray.h"

namespace hpray {
namespace {

using LD = long double;
constexpr double kEps = std::numeric_limits<double>::epsilon();

/// p(t) in long double by the three-term recurrence.
LD EvalLong(const LegendreSeries& p, LD t) {
    const LD x = (2 * t - LD(p.a) - LD(p.b)) / (LD(p.b) - LD(p.a));
    LD p0 = 1, p1 = x, v = p.c[0];
    if (p.Degree() >= 1) v += LD(p.c[1]) * x;
    for (int k = 1; k < p.Degree(); ++k) {
        const LD p2 = ((2 * k + 1) * x * p1 - k * p0) / (k + 1);
        v += LD(p.c[k + 1]) * p2;
        p0 = p1;
        p1 = p2;
    }
    return v;
}

/// The crossings of `level` in (a, b): sign changes on a fine grid, bisected in long
/// double.
std::vector<LD> ReferenceCrossings(const LegendreSeries& p, double level) {
    std::vector<LD> out;
    constexpr int kGrid = 5000;
    LD lo = p.a, flo = EvalLong(p, lo) - level;
    for (int i = 1; i <= kGrid; ++i) {
        const LD hi = i == kGrid ? LD(p.b) : p.a + (LD(p.b) - p.a) * i / kGrid;
        const LD fhi = EvalLong(p, hi) - level;
        if (flo != 0 && fhi != 0 && (flo < 0) != (fhi < 0)) {
            LD l = lo, h = hi, fl = flo;
            for (int it = 0; it < 200; ++it) {
                const LD m = (l + h) / 2;
                if (m <= l || m >= h) break;
                const LD fm = EvalLong(p, m) - level;
                if ((fm < 0) == (fl < 0)) {
                    l = m;
                    fl = fm;
                } else {
                    h = m;
                }
            }
            out.push_back((l + h) / 2);
        }
        lo = hi;
        flo = fhi;
    }
    return out;
}

TEST(SeriesCrossings, RandomSeriesAgainstLongDoubleIncludingLevelsAtTheEnds) {
    int checked = 0, nearEnds = 0;
    for (int seed = 0; seed < 300; ++seed) {
        std::mt19937_64 rng(seed);
        std::uniform_real_distribution<double> u(-1, 1);
        LegendreSeries p;
        p.a = 2 + u(rng);
        p.b = p.a + 0.05 + 0.5 * (1 + u(rng));
        const int degree = 3 + seed % 22;
        p.c.resize(degree + 1);
        for (int k = 0; k <= degree; ++k) p.c[k] = u(rng) * std::pow(0.6, k);
        // Levels: random ones, and ones a few ulps of |p| inside the values at the ends.
        std::vector<double> levels;
        for (int k = 0; k < 3; ++k) levels.push_back(p.c[0] + 0.8 * u(rng));
        const double scale = std::abs(p.c[0]) + p.Tail();
        for (const double t : {p.a, p.b}) {
            const double v = double(EvalLong(p, t));
            double slope, value;
            p.Eval(t, value, slope);
            // Just inside the segment the series moves towards sign(slope) (at a) or
            // away from it (at b).
            const double inward = t == p.a ? (slope > 0 ? 1 : -1) : (slope > 0 ? -1 : 1);
            levels.push_back(v + inward * (64 + seed % 50) * kEps * scale);
        }
        std::sort(levels.begin(), levels.end());
        levels.erase(std::unique(levels.begin(), levels.end()), levels.end());
        const double tol = std::max(1e-14 * (p.b - p.a), 4 * kEps * std::abs(p.b));
        // The samples a segment passes: the series at its LGL nodes.
        const LglRule& rule = LglNodes(degree);
        std::vector<double> sampleT, sampleV;
        for (int i = 0; i <= degree; ++i) {
            sampleT.push_back(0.5 * (p.a + p.b) + 0.5 * (p.b - p.a) * rule.nodes[i]);
            sampleV.push_back(p(sampleT.back()));
        }
        std::vector<double> scratch, points, found;
        LegendreSeries derivative;
        SeriesCrossings(p, levels.data(), int(levels.size()), tol, sampleT.data(),
                        sampleV.data(), int(sampleT.size()), scratch, points, derivative,
                        found);
        // Each reference crossing where the series is steep enough to tell it apart
        // from its rounding is found to within tol plus that rounding's reach in t.
        const double rounding = 16 * kEps * scale;
        for (const double level : levels) {
            for (const LD ref : ReferenceCrossings(p, level)) {
                double value, slope;
                p.Eval(double(ref), value, slope);
                if (std::abs(slope) * (p.b - p.a) < 1e-6 * scale) continue;  // tangential
                const double reach = tol + 4 * rounding / std::abs(slope);
                const bool nearEnd = std::min(ref - LD(p.a), LD(p.b) - ref) < 1e-9L;
                double best = std::numeric_limits<double>::infinity();
                for (const double t : found)
                    best = std::min(best, double(std::abs(t - ref)));
                // A crossing within the reach of an end may be taken as the end itself.
                if (nearEnd && std::min(ref - LD(p.a), LD(p.b) - ref) <= reach) {
                    ++nearEnds;
                    if (!(best <= reach)) continue;
                }
                EXPECT_LE(best, reach)
                    << "seed " << seed << " level " << level << " at " << double(ref);
                ++checked;
            }
        }
        for (const double t : found) {
            EXPECT_GT(t, p.a) << seed;
            EXPECT_LT(t, p.b) << seed;
        }
    }
    EXPECT_GT(checked, 500);
    EXPECT_GT(nearEnds, 50);
}

}  // namespace
}  // namespace hpray

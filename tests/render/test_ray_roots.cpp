// Legendre machinery and the ray root finder against closed forms and known roots.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "render/legendre.h"
#include "render/ray_roots.h"

namespace hpray {
namespace {

TEST(Legendre, LobattoRuleIntegratesPolynomialsExactly) {
    for (int n = 1; n <= kMaxLegendreDegree; ++n) {
        const LglRule& r = LglNodes(n);
        EXPECT_EQ(r.nodes.front(), -1.0);
        EXPECT_EQ(r.nodes.back(), 1.0);
        // Exact for degree <= 2n - 1: integral of x^k over [-1, 1] is 2/(k+1) for even k.
        for (int k = 0; k <= std::min(2 * n - 1, 40); ++k) {
            double q = 0;
            for (int i = 0; i <= n; ++i) q += r.weights[i] * std::pow(r.nodes[i], k);
            const double exact = (k % 2 == 0) ? 2.0 / (k + 1) : 0.0;
            EXPECT_NEAR(q, exact, 1e-14) << "n=" << n << " k=" << k;
        }
    }
}

TEST(Legendre, InterpolationReproducesLegendrePolynomials) {
    // P_k itself must come out as the unit vector e_k for k <= n.
    for (int n : {1, 2, 5, 10, 25, 48}) {
        const LglRule& r = LglNodes(n);
        for (int k = 0; k <= n; ++k) {
            std::vector<double> v(n + 1);
            for (int i = 0; i <= n; ++i) v[i] = std::legendre(k, r.nodes[i]);
            LegendreSeries s = InterpolateLgl(v.data(), n, -1, 1);
            for (int j = 0; j <= n; ++j)
                EXPECT_NEAR(s.c[j], j == k ? 1.0 : 0.0, 1e-13) << n << " " << k << " " << j;
        }
    }
}

TEST(Legendre, ChebyshevLobattoNodesNestAndInterpolateExactly) {
    for (int n = 1; n <= kMaxLegendreDegree; ++n) {
        const ChebyshevLobattoRule& r = ChebyshevLobattoNodes(n);
        ASSERT_EQ(r.nodes.size(), std::size_t(n + 1));
        EXPECT_EQ(r.nodes.front(), -1.0);
        EXPECT_EQ(r.nodes.back(), 1.0);
        for (int j = 0; j <= n; ++j) {
            EXPECT_NEAR(r.nodes[j], -std::cos(M_PI * j / n), 1e-15) << n << " " << j;
            EXPECT_EQ(r.nodes[j], -r.nodes[n - j]) << n << " " << j;
        }
        // Level n's nodes are bitwise level 2n's even ones: a raised projection keeps
        // them.
        if (2 * n <= kMaxLegendreDegree) {
            const ChebyshevLobattoRule& r2 = ChebyshevLobattoNodes(2 * n);
            for (int j = 0; j <= n; ++j)
                EXPECT_EQ(r.nodes[j], r2.nodes[2 * j]) << n << " " << j;
        }
    }
    // P_k itself comes out as the unit vector e_k for k <= n.
    for (int n : {1, 2, 3, 6, 12, 24, 48, 64}) {
        const ChebyshevLobattoRule& r = ChebyshevLobattoNodes(n);
        for (int k = 0; k <= n; ++k) {
            std::vector<double> v(n + 1);
            for (int i = 0; i <= n; ++i) v[i] = std::legendre(k, r.nodes[i]);
            LegendreSeries s;
            InterpolateChebyshevLobatto(v.data(), n, -1, 1, s);
            for (int j = 0; j <= n; ++j)
                EXPECT_NEAR(s.c[j], j == k ? 1.0 : 0.0, 1e-13)
                    << n << " " << k << " " << j;
        }
    }
    // exp on [0.5, 2] at degree 30, against the closed form between the nodes.
    const int n = 30;
    const ChebyshevLobattoRule& r = ChebyshevLobattoNodes(n);
    std::vector<double> v(n + 1);
    for (int i = 0; i <= n; ++i) v[i] = std::exp(1.25 + 0.75 * r.nodes[i]);
    LegendreSeries s;
    InterpolateChebyshevLobatto(v.data(), n, 0.5, 2.0, s);
    for (double t = 0.5; t <= 2.0; t += 0.0137)
        EXPECT_NEAR(s(t), std::exp(t), (n + 1) * (n + 1) * 2.2e-16 * std::exp(t)) << t;
}

TEST(Legendre, EvaluationDerivativeAndRestriction) {
    // p(t) = exp(t) on [0.5, 2] interpolated at degree 30 is exact to rounding.
    const int n = 30;
    const double a = 0.5, b = 2.0;
    const LglRule& r = LglNodes(n);
    std::vector<double> v(n + 1);
    for (int i = 0; i <= n; ++i) v[i] = std::exp(0.5 * (a + b) + 0.5 * (b - a) * r.nodes[i]);
    LegendreSeries s = InterpolateLgl(v.data(), n, a, b);
    LegendreSeries d = s.Derivative();
    std::vector<double> scratch;
    LegendreSeries sub = Restrict(s, 0.9, 1.3, scratch);
    // Differentiation amplifies the coefficients' rounding by at most the Markov factor
    // n^2 * 2 / (b - a) (|p'| <= n^2 max|p| on [-1, 1]).
    const double derivTol = 8 * n * n * 2 / (b - a) * 2.2e-16 * std::exp(b);
    for (double t = a; t <= b; t += 0.0137) {
        double val, der;
        s.Eval(t, val, der);
        // Interpolation error is below rounding at degree 30. Rounding: each coefficient is
        // a sum of n + 1 terms and the value a sum of n + 1 coefficients, so the worst case
        // is (n + 1)^2 eps relative (observed: about 2 (n + 1) eps).
        const double roundTol = (n + 1) * (n + 1) * 2.2e-16 * std::exp(t);
        EXPECT_NEAR(val, std::exp(t), roundTol);
        EXPECT_NEAR(der, std::exp(t), derivTol);
        EXPECT_NEAR(d(t), std::exp(t), derivTol);
        if (t >= 0.9 && t <= 1.3) {
            EXPECT_NEAR(sub(t), std::exp(t), roundTol);
        }
    }
}

struct Finder {
    ProjectionOptions projection;
    RootOptions roots;
    std::vector<ProjectedPiece> pieces;
    ProjectionStats stats;
    std::vector<double> scratch;

    template <typename F>
    RootResult First(F&& f, double a, double b, double C) {
        ProjectSegment(f, a, b, projection, pieces, stats, scratch);
        return FirstRoot(f, pieces, C, roots, scratch);
    }
};

TEST(RayRoots, SimpleRootOfTranscendentalField) {
    Finder finder;
    auto f = [](double t) { return std::sin(t); };
    RootResult r = finder.First(f, 0.0, 3.0, 0.5);
    ASSERT_EQ(r.kind, RootKind::Simple);
    EXPECT_NEAR(r.t, M_PI / 6, 1e-14);
    EXPECT_LE(r.residual, 1e-15);
    EXPECT_LE(finder.stats.maxDegree, 48);
}

TEST(RayRoots, NearestOfManyRootsIsNeverSkipped) {
    // sin(50 t) = 0.999 has its roots in pairs 0.0009 apart; the first is asin(0.999)/50.
    Finder finder;
    auto f = [](double t) { return std::sin(50 * t); };
    for (double a : {0.0, 0.05, 0.1, 0.2}) {
        RootResult r = finder.First(f, a, a + 1.0, 0.999);
        ASSERT_EQ(r.kind, RootKind::Simple) << a;
        // First root at or after a.
        const double base = std::asin(0.999) / 50, period = 2 * M_PI / 50;
        double expect = base;
        while (expect < a) {
            const double second = M_PI / 50 - base + (expect - base);  // mirror root
            if (second >= a) {
                expect = second;
                break;
            }
            expect += period;
        }
        EXPECT_NEAR(r.t, expect, 1e-13) << a;
    }
}

TEST(RayRoots, TangentDoubleRootIsFoundAndNearMissIsNot) {
    Finder finder;
    finder.projection.exactDegree = 2;
    auto touch = [](double t) { return (t - 0.3) * (t - 0.3); };
    RootResult r = finder.First(touch, 0.0, 1.0, 0.0);
    ASSERT_EQ(r.kind, RootKind::Tangent);
    EXPECT_NEAR(r.t, 0.3, 1e-12);
    EXPECT_LE(r.residual, 1e-20);

    auto miss = [](double t) { return (t - 0.3) * (t - 0.3) + 1e-6; };
    EXPECT_EQ(finder.First(miss, 0.0, 1.0, 0.0).kind, RootKind::None);

    // Two simple roots 1e-9 apart: their dip (-2.5e-19) is below the projection error, so
    // the guarantee reports the pair as one tangency between them, with its true residual.
    auto pair = [](double t) { return (t - 0.3) * (t - 0.3 - 1e-9); };
    r = finder.First(pair, 0.0, 1.0, 0.0);
    ASSERT_NE(r.kind, RootKind::None);
    EXPECT_GE(r.t, 0.3 - 1e-15);
    EXPECT_LE(r.t, 0.3 + 1e-9 + 1e-15);
    EXPECT_LE(r.residual, 3e-19);
    // 1e-4 apart the dip (-2.5e-9) is resolved: two simple roots, the first reported.
    auto wide = [](double t) { return (t - 0.3) * (t - 0.3 - 1e-4); };
    r = finder.First(wide, 0.0, 1.0, 0.0);
    ASSERT_EQ(r.kind, RootKind::Simple);
    EXPECT_NEAR(r.t, 0.3, 1e-14);
}

TEST(RayRoots, IsovalueAtSegmentEndAndNoRoot) {
    Finder finder;
    finder.projection.exactDegree = 1;
    auto line = [](double t) { return 2 * t - 1; };
    RootResult r = finder.First(line, 0.5, 2.0, 0.0);
    ASSERT_NE(r.kind, RootKind::None);
    EXPECT_EQ(r.t, 0.5);
    r = finder.First(line, 0.0, 0.5, 0.0);
    ASSERT_NE(r.kind, RootKind::None);
    EXPECT_EQ(r.t, 0.5);
    EXPECT_EQ(finder.First(line, 0.6, 2.0, 0.0).kind, RootKind::None);
}

TEST(RayRoots, LargeOffsetAndNearConstantFields) {
    Finder finder;
    auto offset = [](double t) { return 1e6 + std::sin(t); };
    RootResult r = finder.First(offset, 0.0, 3.0, 1e6 + 0.5);
    ASSERT_EQ(r.kind, RootKind::Simple);
    // The field is known to |1e6| * 2^-52 ~ 2e-10, so t is known to about that / cos(t).
    EXPECT_NEAR(r.t, M_PI / 6, 1e-9);

    auto flat = [](double t) { return 1e-12 * (t - 0.4) + 1e-13 * (t - 0.4) * (t - 0.4); };
    r = finder.First(flat, 0.0, 1.0, 0.0);
    ASSERT_EQ(r.kind, RootKind::Simple);
    EXPECT_NEAR(r.t, 0.4, 1e-12);
}

TEST(RayRoots, RandomPolynomialsWithKnownRoots) {
    Finder finder;
    for (int trial = 0; trial < 300; ++trial) {
        std::mt19937 rng(trial);
        std::uniform_real_distribution<double> U(0.0, 1.0);
        const int degree = 1 + trial % 10;
        std::vector<double> roots(degree);
        for (double& x : roots) x = -0.5 + 2.0 * U(rng);
        const double scale = std::pow(10.0, -3 + 6 * U(rng));
        auto f = [&](double t) {
            double v = scale;
            for (double x : roots) v *= (t - x);
            return v;
        };
        double first = std::numeric_limits<double>::infinity();
        for (double x : roots)
            if (x >= 0 && x <= 1) first = std::min(first, x);
        finder.projection.exactDegree = (trial % 2 == 0) ? degree : 0;
        RootResult r = finder.First(f, 0.0, 1.0, 0.0);
        if (std::isinf(first)) {
            EXPECT_EQ(r.kind, RootKind::None) << trial;
        } else {
            ASSERT_NE(r.kind, RootKind::None) << trial;
            // Clustered roots are ill-conditioned; accept the root within the spacing.
            double nearestOther = 1;
            for (double x : roots)
                if (x != first) nearestOther = std::min(nearestOther, std::abs(x - first));
            EXPECT_NEAR(r.t, first, std::max(1e-12, 1e-6 * (nearestOther < 1e-3))) << trial;
        }
    }
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// A field that stays within rounding of the level over a whole interval (a flat contact
// of high multiplicity, or a field equal to the level along the ray: nodal values that
// sit exactly on a transfer-function breakpoint, as deal.II's material_ids do) has no
// isolated roots there. Root isolation must treat such an interval as one contact rather
// than bisect it down to the root tolerance (which took minutes per ray), and report it.
TEST(RayRoots, FieldEqualToTheLevelOverAnIntervalIsOneContact) {
    for (int power : {12, 0}) {
        long evaluations = 0;
        auto f = [&](double t) {
            ++evaluations;
            return 0.7 + (power > 0 ? std::pow(t - 0.5, power) : 0.0);
        };
        Finder finder;
        const std::vector<ProjectedPiece>& pieces = finder.pieces;
        ProjectSegment(f, 0.0, 1.0, finder.projection, finder.pieces, finder.stats,
                       finder.scratch);
        std::vector<RootResult> found;
        const int failures = FindRoots(f, pieces, 0.7, finder.roots, finder.scratch,
                                       [&](const RootResult& r) {
                                           found.push_back(r);
                                           return false;
                                       });
        SCOPED_TRACE(power);
        EXPECT_EQ(failures, 0);
        ASSERT_FALSE(found.empty());
        EXPECT_LT(found.size(), 200u);
        EXPECT_LT(evaluations, 100000);
        double eps = 0;
        for (const ProjectedPiece& piece : pieces) eps = std::max(eps, piece.eps);
        EXPECT_LT(eps, 1e-12);
        for (const RootResult& r : found) {
            // Every contact lies where the field is within its error of the level, and
            // reports that residual.
            EXPECT_LE(std::abs(f(r.t) - 0.7), 2 * eps + 1e-16) << r.t;
            EXPECT_EQ(r.residual, std::abs(f(r.t) - 0.7)) << r.t;
        }
        // One contact per run: the flat interval is not reported piece by piece.
        EXPECT_EQ(found.size(), 1u);
        // Without stopping, FirstRoot gives the first contact.
        const RootResult first = FirstRoot(f, pieces, 0.7, finder.roots, finder.scratch);
        EXPECT_NE(first.kind, RootKind::None);
        EXPECT_EQ(first.t, found.front().t);
    }
}

TEST(RayRoots, RaisedProjectionKeepsItsSamples) {
    // A quartic converges at level 6 of 3, 6, 12, ... (the tail test wants the last two
    // coefficients negligible): 4 samples at level 3, the 3 new nodes of level 6, then 4
    // checks between those; resampling from scratch at each level would take 4 + 7 + 4.
    long evaluations = 0;
    auto f = [&](double t) {
        ++evaluations;
        return 0.3 + t * (1 - t) * (t - 0.25) * (t + 2);
    };
    ProjectionOptions projection;
    ASSERT_EQ(projection.startDegree, 3);
    std::vector<ProjectedPiece> pieces;
    ProjectionStats stats;
    std::vector<double> scratch;
    ProjectSegment(f, 0.0, 1.0, projection, pieces, stats, scratch);
    ASSERT_EQ(pieces.size(), 1u);
    EXPECT_EQ(pieces[0].p.Degree(), 6);
    EXPECT_TRUE(pieces[0].converged);
    EXPECT_EQ(evaluations, 11);
    EXPECT_EQ(stats.evaluations, 11);
    // The interpolant is the quartic: the error claimed is the rounding floor, 2 * 64
    // (n + 1) eps times the largest sample (below 0.6).
    EXPECT_LE(pieces[0].eps, 2 * 64 * 7 * 2.3e-16 * 0.6);
    for (double t = 0; t <= 1; t += 0.01) {
        const double expect = 0.3 + t * (1 - t) * (t - 0.25) * (t + 2);
        EXPECT_NEAR(pieces[0].p(t), expect, 1e-15) << t;
    }
    // exp(8 t) needs a higher level: every level's samples are kept, so the evaluations
    // are the final level's nodes and its checks.
    evaluations = 0;
    auto g = [&](double t) {
        ++evaluations;
        return std::exp(8 * t);
    };
    stats = ProjectionStats{};
    ProjectSegment(g, 0.0, 1.0, projection, pieces, stats, scratch);
    ASSERT_EQ(pieces.size(), 1u);
    const int n = pieces[0].p.Degree();
    EXPECT_EQ(n, 24);
    EXPECT_EQ(evaluations, n + 1 + 4);
    for (double t = 0; t <= 1; t += 0.01)
        EXPECT_NEAR(pieces[0].p(t), std::exp(8 * t), 1e-12 * std::exp(8.0));
}

TEST(RayRoots, ProjectionFarFromTheIsovaluesStopsEarly) {
    // exp(t) on [0, 1] converges at 1e-12 only beyond level 6. Far from the level 0.5
    // (below its range [1, e]), level 6 already proves that it is not crossed: 7 samples
    // and 4 checks. Near a crossed level nothing stops early.
    long evaluations = 0;
    auto g = [&](double t) {
        ++evaluations;
        return std::exp(t);
    };
    ProjectionOptions projection;
    std::vector<ProjectedPiece> pieces;
    ProjectionStats stats;
    std::vector<double> scratch;
    ProjectSegment(g, 0.0, 1.0, projection, pieces, stats, scratch);
    ASSERT_EQ(pieces.size(), 1u);
    const int converged = pieces[0].p.Degree();
    EXPECT_GT(converged, 6);
    EXPECT_EQ(evaluations, converged + 1 + 4);

    const double far = 0.5, crossed = 2.0;
    projection.exclude = &far;
    projection.excludeCount = 1;
    evaluations = 0;
    stats = ProjectionStats{};
    ProjectSegment(g, 0.0, 1.0, projection, pieces, stats, scratch);
    ASSERT_EQ(pieces.size(), 1u);
    EXPECT_EQ(stats.excluded, 1);
    EXPECT_EQ(pieces[0].p.Degree(), 6);
    EXPECT_EQ(evaluations, 7 + 4);
    // Its error is an honest bound of |f - p| on the piece (checked densely), and the
    // root finder excludes the level with it.
    double worst = 0;
    for (double t = 0; t <= 1; t += 1e-3)
        worst = std::max(worst, std::abs(pieces[0].p(t) - std::exp(t)));
    EXPECT_LE(worst, pieces[0].eps);
    RootOptions roots;
    EXPECT_EQ(FirstRoot(g, pieces, far, roots, scratch).kind, RootKind::None);

    stats = ProjectionStats{};
    projection.exclude = &crossed;
    ProjectSegment(g, 0.0, 1.0, projection, pieces, stats, scratch);
    EXPECT_EQ(stats.excluded, 0);
    EXPECT_EQ(pieces[0].p.Degree(), converged);
    const RootResult r = FirstRoot(g, pieces, crossed, roots, scratch);
    ASSERT_EQ(r.kind, RootKind::Simple);
    EXPECT_NEAR(r.t, std::log(crossed), 1e-14);
}

TEST(RayRoots, EarlyStopMeasuresBetweenTheNodes) {
    // A narrow bump between the nodes of levels 3 and 6 (both interpolants are nearly
    // zero and agree): only the checks, one of which lands on it, show that the level
    // 0.9 is crossed. Its first root must be found (pieces away from the bump, after
    // splitting, may still stop early).
    auto f = [](double t) { return std::exp(-std::pow((t - 0.37) / 0.04, 2)); };
    Finder finder;
    const double C = 0.9;
    finder.projection.exclude = &C;
    finder.projection.excludeCount = 1;
    const RootResult r = finder.First(f, 0.0, 1.0, C);
    ASSERT_EQ(r.kind, RootKind::Simple);
    EXPECT_NEAR(r.t, 0.37 - 0.04 * std::sqrt(std::log(1 / C)), 1e-13);
}

TEST(RayRoots, PolishingNeedsFewSamplesAndReachesTheRootTolerance) {
    // Simple roots of smooth fields: Newton from the projection's root with its slope
    // ends within the root tolerance in one or two samples of the true field.
    for (double C : {0.1, 0.5, 0.9, -0.3}) {
        long evaluations = 0;
        auto f = [&](double t) {
            ++evaluations;
            return std::sin(2 * t) + 0.2 * t * t;
        };
        Finder finder;
        ProjectSegment(f, 0.0, 1.3, finder.projection, finder.pieces, finder.stats,
                       finder.scratch);
        const long projection = evaluations;
        const RootResult r = FirstRoot(f, finder.pieces, C, finder.roots, finder.scratch);
        if (C < 0) {  // no root: sin(2t) + 0.2 t^2 >= 0 on [0, 1.3]
            EXPECT_EQ(r.kind, RootKind::None);
            continue;
        }
        ASSERT_EQ(r.kind, RootKind::Simple) << C;
        EXPECT_LE(evaluations - projection, 3) << C;
        // The true root by bisection on the closed form, on the rising part (the field
        // peaks at about t = 0.82).
        double lo = 0, hi = 0.8;
        auto h = [&](double t) { return std::sin(2 * t) + 0.2 * t * t - C; };
        for (int it = 0; it < 200; ++it) {
            const double m = 0.5 * (lo + hi);
            ((h(lo) < 0) == (h(m) < 0) ? lo : hi) = m;
        }
        EXPECT_NEAR(r.t, lo, 1e-14 * 1.3) << C;
        EXPECT_EQ(r.residual, std::abs(h(r.t))) << C;
        EXPECT_LE(r.residual, 1e-15) << C;
    }
}

TEST(RayRoots, FindRootsReturnsEveryRootInOrder) {
    // sin(20 t) = 0.3 on [0.05, 2]: roots at (asin(0.3) + 2 pi k) / 20 and
    // (pi - asin(0.3) + 2 pi k) / 20.
    std::vector<double> expect;
    for (int k = 0; k < 10; ++k)
        for (double base : {std::asin(0.3), M_PI - std::asin(0.3)}) {
            const double t = (base + 2 * M_PI * k) / 20;
            if (t >= 0.05 && t <= 2.0) expect.push_back(t);
        }
    std::sort(expect.begin(), expect.end());
    auto f = [](double t) { return std::sin(20 * t); };
    ProjectionOptions projection;
    RootOptions options;
    std::vector<ProjectedPiece> pieces;
    ProjectionStats stats;
    std::vector<double> scratch;
    ProjectSegment(f, 0.05, 2.0, projection, pieces, stats, scratch);
    std::vector<double> found;
    FindRoots(f, pieces, 0.3, options, scratch, [&](const RootResult& r) {
        if (found.empty() || r.t > found.back() + 1e-12) found.push_back(r.t);
        return false;
    });
    ASSERT_EQ(found.size(), expect.size());
    for (std::size_t i = 0; i < found.size(); ++i) EXPECT_NEAR(found[i], expect[i], 1e-13) << i;
}

}  // namespace
}  // namespace hpray

// The vectorised Legendre series evaluations (series_eval_kernel.h) against the generic
// ones of render/legendre.h, bitwise, on random series, intervals and points.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "render/legendre.h"
#include "render/series_eval_kernel.h"

namespace hpray {
namespace {

bool SameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// EvalPair(p, q) and p.EvalMany at the points t, and the kernels' (the whole-block ones
// where `whole`): whether each value is bitwise the generic one, per point (p, q, many).
std::vector<std::array<bool, 3>> KernelsMatch(const LegendreSeries& p,
                                              const LegendreSeries& q,
                                              const std::vector<double>& t, bool whole) {
    const int count = int(t.size());
    std::vector<double> gp(count), gq(count), gm(count), kp(count, 7), kq(count, 7),
        km(count, 7);
    EvalPair(p, q, t.data(), count, gp.data(), gq.data());
    p.EvalMany(t.data(), count, gm.data());
    const bool ran =
        whole ? EvalPairKernelWhole(p, q, t.data(), count, kp.data(), kq.data()) &&
                    EvalManyKernelWhole(p, t.data(), count, km.data())
              : EvalPairKernel(p, q, t.data(), count, kp.data(), kq.data()) &&
                    EvalManyKernel(p, t.data(), count, km.data());
    std::vector<std::array<bool, 3>> same(count);
    for (int s = 0; s < count; ++s)
        same[s] = {ran && SameBits(gp[s], kp[s]), ran && SameBits(gq[s], kq[s]),
                   ran && SameBits(gm[s], km[s])};
    return same;
}

TEST(SeriesEvalKernel, BitwiseTheGenericEvaluations) {
#if !(defined(__AVX2__) && defined(__FMA__))
    GTEST_SKIP() << "the kernels are built with AVX2 and FMA only";
#endif
    int compared = 0;
    for (int seed = 0; seed < 2000; ++seed) {
        std::mt19937_64 rng(seed);
        std::uniform_real_distribution<double> u(-1, 1);
        LegendreSeries p, q;
        p.a = q.a = 3 * u(rng);
        p.b = q.b = p.a + 1e-3 + std::abs(u(rng));
        p.c.resize(1 + seed % 40);
        q.c.resize(1 + (seed / 40) % 42);
        for (double& c : p.c) c = u(rng);
        for (double& c : q.c) c = u(rng) * 1e3;
        const int count = 1 + seed % 37;
        std::vector<double> t(count);
        for (double& v : t)
            v = p.a + (p.b - p.a) * (0.5 + 0.55 * u(rng));  // some outside
        const auto same = KernelsMatch(p, q, t, false);
        for (int s = 0; s < count; ++s) {
            EXPECT_TRUE(same[s][0]) << seed << " " << s;
            EXPECT_TRUE(same[s][1]) << seed << " " << s;
            EXPECT_TRUE(same[s][2]) << seed << " " << s;
            ++compared;
        }
    }
    EXPECT_GT(compared, 30000);
}

// The whole-block kernels of the volume pieces, whose low degrees (a series and its
// antiderivative, one degree higher) run with their degrees known at compile time:
// bitwise EvalPair and EvalMany at every degree around those, and at random ones.
TEST(SeriesEvalKernel, WholeBlocksAtEveryLowDegreeAreTheGenericEvaluations) {
#if !(defined(__AVX2__) && defined(__FMA__))
    GTEST_SKIP() << "the kernels are built with AVX2 and FMA only";
#endif
    int compared = 0;
    for (int seed = 0; seed < 600; ++seed) {
        std::mt19937_64 rng(seed);
        std::uniform_real_distribution<double> u(-1, 1);
        LegendreSeries p, q;
        p.a = q.a = 3 * u(rng);
        p.b = q.b = p.a + 1e-3 + std::abs(u(rng));
        // Degrees 0..7 in turn with the antiderivative's one above (the specialised
        // pairs and their neighbours), then random pairs.
        const int np = seed < 400 ? seed % 8 : int(rng() % 30);
        const int nq = seed < 200   ? np + 1
                       : seed < 400 ? np + int(rng() % 3)
                                    : int(rng() % 30);
        p.c.resize(np + 1);
        q.c.resize(nq + 1);
        for (double& c : p.c) c = u(rng);
        for (double& c : q.c) c = u(rng) * 1e3;
        if (seed % 7 == 3) p.c.back() = -0.0;
        const int count = 8 * (1 + seed % 4);
        std::vector<double> t(count);
        for (double& v : t) v = p.a + (p.b - p.a) * (0.5 + 0.55 * u(rng));
        const auto same = KernelsMatch(p, q, t, true);
        for (int s = 0; s < count; ++s) {
            ASSERT_TRUE(same[s][0]) << seed << " " << np << " " << nq << " " << s;
            ASSERT_TRUE(same[s][1]) << seed << " " << np << " " << nq << " " << s;
            ASSERT_TRUE(same[s][2]) << seed << " " << np << " " << s;
            ++compared;
        }
    }
    EXPECT_GT(compared, 10000);
}

// Two points in the lanes of one vector: bitwise LegendreSeries::At at each.
TEST(SeriesEvalKernel, AtTwoIsAtAtEachPoint) {
    int compared = 0;
    for (int seed = 0; seed < 1000; ++seed) {
        std::mt19937_64 rng(seed);
        std::uniform_real_distribution<double> u(-1, 1);
        LegendreSeries p;
        p.a = 3 * u(rng);
        p.b = p.a + 1e-3 + std::abs(u(rng));
        p.c.resize(1 + seed % 41);
        for (double& c : p.c) c = u(rng) * (seed % 5 == 0 ? 1e-3 : 1.0);
        const double t0 = p.a + (p.b - p.a) * (0.5 + 0.55 * u(rng));
        const double t1 = seed % 9 == 0 ? t0 : p.a + (p.b - p.a) * (0.5 + 0.55 * u(rng));
        double v0 = 7, v1 = 7;
        AtTwo(p, t0, t1, v0, v1);
        ASSERT_TRUE(SameBits(v0, p.At(t0))) << seed;
        ASSERT_TRUE(SameBits(v1, p.At(t1))) << seed;
        ASSERT_TRUE(SameBits(v0, p(t0))) << seed;
        ++compared;
    }
    EXPECT_EQ(compared, 1000);
}

TEST(SeriesEvalKernel, RefusesSeriesOnDifferentIntervals) {
    LegendreSeries p, q;
    p.c = {1, 2};
    q.c = {3};
    q.b = 2;
    double t = 0.5, a = 0, b = 0;
    EXPECT_FALSE(EvalPairKernel(p, q, &t, 1, &a, &b));
}

// The interpolation transform of InterpolateLgl (register-blocked rows where the build
// has AVX2) gives bitwise the sums of its definition, coefficient k = sum_i value_i times
// row i of transformByNode, fused multiply-adds in the order of i, for every degree; and
// its interpolant reproduces the values at the nodes.
TEST(SeriesEvalKernel, LglTransformIsItsDefinitionBitwise) {
    std::mt19937_64 rng(17);
    std::uniform_real_distribution<double> value(-3, 3);
    for (int n = 1; n <= kMaxLegendreDegree; ++n) {
        const LglRule& rule = LglNodes(n);
        std::vector<double> v(n + 1);
        for (double& x : v) x = value(rng);
        LegendreSeries s;
        InterpolateLgl(v.data(), n, -0.5, 2.0, s);
        ASSERT_EQ(int(s.c.size()), n + 1);
        for (int k = 0; k <= n; ++k) {
            double c = 0;
            for (int i = 0; i <= n; ++i)
                c = std::fma(rule.transformByNode[i * rule.transformStride + k], v[i], c);
            EXPECT_EQ(s.c[k], c) << "n " << n << " k " << k;
        }
        for (int i = 0; i <= n; ++i)
            EXPECT_NEAR(s(-0.5 + 1.25 * (rule.nodes[i] + 1)), v[i], 1e-12) << n;
    }
}

TEST(LegendreAntiderivative, IsTheIntegralFromTheStart) {
    // Against the coefficient identity written as sums (integral of P_0 = P_1 + P_0,
    // integral of P_k = (P_{k+1} - P_{k-1}) / (2k + 1), times (b - a) / 2), bit for bit,
    // and against the integral from a by 20-point Gauss-Legendre quadrature in long
    // double (exact for these degrees) at points of the interval.
    const long double gx[10] = {
        0.0765265211334973337546404093988382L, 0.2277858511416450780804961953685746L,
        0.3737060887154195606725481770249272L, 0.5108670019508270980043640509552510L,
        0.6360536807265150254528366962262859L, 0.7463319064601507926143050703556416L,
        0.8391169718222188233945290617015207L, 0.9122344282513259058677524412032981L,
        0.9639719272779137912676661311972772L, 0.9931285991850949247861223884713203L};
    const long double gw[10] = {
        0.1527533871307258506980843319550976L, 0.1491729864726037467878287370019694L,
        0.1420961093183820513292983250671649L, 0.1316886384491766268984944997481631L,
        0.1181945319615184173123773777113823L, 0.1019301198172404350367501354803499L,
        0.0832767415767047487247581432220463L, 0.0626720483341090635695065351870128L,
        0.0406014298003869413310399522749140L, 0.0176140071391521183118619623518528L};
    auto valueLd = [](const LegendreSeries& p, long double t) {
        const long double x = (2 * t - p.a - p.b) / (p.b - p.a);
        long double v = 0, p0 = 1, p1 = x;
        for (std::size_t k = 0; k < p.c.size(); ++k) {
            const long double pk = k == 0   ? 1
                                   : k == 1 ? x
                                            : ((2 * k - 1) * x * p1 - (k - 1) * p0) / k;
            if (k >= 2) {
                p0 = p1;
                p1 = pk;
            }
            v += p.c[k] * pk;
        }
        return v;
    };
    int compared = 0;
    for (int seed = 0; seed < 300; ++seed) {
        std::mt19937_64 rng(seed);
        std::uniform_real_distribution<double> u(-1, 1);
        LegendreSeries p, r;
        p.a = 3 * u(rng);
        p.b = p.a + 1e-2 + 2 * std::abs(u(rng));
        p.c.resize(1 + seed % 19);
        for (double& c : p.c) c = u(rng) * (seed % 3 == 0 ? 0.0 : 1.0);
        if (seed % 5 == 1) p.c.back() = -0.0;
        r.c.assign(40, 7.0);  // stale contents must not leak into the result
        p.Antiderivative(r);
        const int n = p.Degree();
        std::vector<double> want(n + 2, 0.0);
        const double h = 0.5 * (p.b - p.a);
        want[0] += h * p.c[0];
        want[1] += h * p.c[0];
        for (int k = 1; k <= n; ++k) {
            const double q = h * p.c[k] / (2 * k + 1);
            want[k + 1] += q;
            want[k - 1] -= q;
        }
        ASSERT_EQ(r.c.size(), want.size());
        EXPECT_EQ(r.a, p.a);
        EXPECT_EQ(r.b, p.b);
        for (std::size_t k = 0; k < want.size(); ++k)
            ASSERT_TRUE(SameBits(r.c[k], want[k])) << "seed " << seed << " k " << k;
        // Without the mean: bitwise that of a copy whose c_0 is zero.
        LegendreSeries zeroMean = p, rz, rm;
        zeroMean.c[0] = 0;
        zeroMean.Antiderivative(rz);
        rm.c.assign(3, -5.0);
        p.Antiderivative(rm, /*withoutMean=*/true);
        ASSERT_EQ(rm.c.size(), rz.c.size());
        for (std::size_t k = 0; k < rz.c.size(); ++k)
            ASSERT_TRUE(SameBits(rm.c[k], rz.c[k])) << "seed " << seed << " k " << k;
        double scale = 0;
        for (double c : p.c) scale += std::abs(c);
        for (double frac : {0.0, 0.3, 0.77, 1.0}) {
            const long double t = p.a + frac * (p.b - p.a);
            long double integral = 0;
            const long double half = 0.5L * (t - p.a), mid = 0.5L * (t + p.a);
            for (int i = 0; i < 10; ++i)
                for (int sgn : {-1, 1})
                    integral += gw[i] * half * valueLd(p, mid + sgn * half * gx[i]);
            EXPECT_NEAR(double(valueLd(r, t)), double(integral),
                        64 * 2.2e-16 * scale * (p.b - p.a) + 1e-300)
                << "seed " << seed << " at " << frac;
            ++compared;
        }
    }
    EXPECT_EQ(compared, 1200);
}

}  // namespace
}  // namespace hpray

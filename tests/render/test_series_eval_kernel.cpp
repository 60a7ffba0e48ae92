// The vectorised Legendre series evaluations (series_eval_kernel.h) against the generic
// ones of render/legendre.h, bitwise, on random series, intervals and points.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "render/legendre.h"
#include "render/series_eval_kernel.h"

namespace hpray {
namespace {

bool SameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

TEST(SeriesEvalKernel, BitwiseTheGenericEvaluations) {
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
        std::vector<double> gp(count), gq(count), kp(count, 7), kq(count, 7),
            km(count, 7);
        EvalPair(p, q, t.data(), count, gp.data(), gq.data());
        ASSERT_TRUE(EvalPairKernel(p, q, t.data(), count, kp.data(), kq.data()));
        std::vector<double> gm(count);
        p.EvalMany(t.data(), count, gm.data());
        ASSERT_TRUE(EvalManyKernel(p, t.data(), count, km.data()));
        for (int s = 0; s < count; ++s) {
            EXPECT_TRUE(SameBits(gp[s], kp[s]))
                << seed << " " << s << " " << gp[s] - kp[s];
            EXPECT_TRUE(SameBits(gq[s], kq[s]))
                << seed << " " << s << " " << gq[s] - kq[s];
            EXPECT_TRUE(SameBits(gm[s], km[s]))
                << seed << " " << s << " " << gm[s] - km[s];
            ++compared;
        }
    }
    EXPECT_GT(compared, 30000);
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

}  // namespace
}  // namespace hpray

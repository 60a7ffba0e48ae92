// The vectorised Legendre series evaluations (series_eval_kernel.h) against the generic
// ones of render/legendre.h, bitwise, on random series, intervals and points.
#include <gtest/gtest.h>

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

}  // namespace
}  // namespace hpray
